/* Certification of a tile's triangles (see gdt_certify.h). */
#include "gdt_certify.h"

#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

#define CERT_MAX_THREADS 64
#define CERT_MIN_PER_THREAD 4096 /* fewer triangles: not worth a thread */

/* Halo points bucketed on a gs x gs grid over K (CSR layout: the points of
 * cell k are pts[start[k] .. start[k+1])). */
struct gdt_certifier {
    int64_t gs;          /* cells per side, >= 1 */
    int64_t ox, oy;      /* K's south-west corner */
    int64_t ex, ey;      /* K's extent in lattice steps (>= 1) */
    uint32_t *start;     /* gs * gs + 1 offsets */
    gdt_ipt *pts;        /* nhalo points in cell order */
    uint32_t *cell;      /* scratch: cell of each halo point */
    size_t cap_cells, cap_pts;
    int threads;         /* 1..CERT_MAX_THREADS */
};

gdt_status gdt_certifier_create(gdt_certifier **out, int threads, gdt_error *err)
{
    *out = calloc(1, sizeof **out);
    if (*out == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    (*out)->threads = threads < 1 ? 1 : threads > CERT_MAX_THREADS ? CERT_MAX_THREADS : threads;
    return GDT_OK;
}

void gdt_certifier_destroy(gdt_certifier *c)
{
    if (c == NULL)
        return;
    free(c->start);
    free(c->pts);
    free(c->cell);
    free(c);
}

static int64_t cell_of(int64_t v, int64_t o, int64_t e, int64_t gs)
{
    /* v - o in [0, e), e < 2^32 and gs <= 1024: the product fits */
    return (v - o) * gs / e;
}

static gdt_status build_grid(gdt_certifier *c, const gdt_ipt *halo, size_t nhalo,
                             const gdt_cert_region *r, gdt_error *err)
{
    int64_t gs = (int64_t)sqrt((double)nhalo / 2.0) + 1;
    size_t ncells;

    if (gs > 1024)
        gs = 1024;
    c->gs = gs;
    c->ox = r->known[0];
    c->oy = r->known[1];
    c->ex = r->known[2] - r->known[0] + 1;
    c->ey = r->known[3] - r->known[1] + 1;
    ncells = (size_t)(gs * gs);
    if (ncells + 1 > c->cap_cells) {
        uint32_t *s = realloc(c->start, (ncells + 1) * sizeof *s);
        if (s == NULL)
            return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        c->start = s;
        c->cap_cells = ncells + 1;
    }
    if (nhalo > c->cap_pts) {
        gdt_ipt *p = realloc(c->pts, nhalo * sizeof *p);
        uint32_t *k;
        if (p == NULL)
            return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        c->pts = p;
        k = realloc(c->cell, nhalo * sizeof *k);
        if (k == NULL)
            return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        c->cell = k;
        c->cap_pts = nhalo;
    }
    memset(c->start, 0, (ncells + 1) * sizeof *c->start);
    for (size_t i = 0; i < nhalo; i++) {
        gdt_ipt h = halo[i];
        int64_t cx, cy;
        int inside_own = h.x >= r->own[0] && h.x <= r->own[2] && h.y >= r->own[1] &&
                         h.y <= r->own[3];
        if (h.x < r->known[0] || h.x > r->known[2] || h.y < r->known[1] ||
            h.y > r->known[3] || inside_own)
            return gdt_error_set(err, GDT_EINTERNAL, 7801,
                                 "halo point %zu (%lld, %lld) is %s", i, (long long)h.x,
                                 (long long)h.y,
                                 inside_own ? "inside the tile's own box"
                                            : "outside the tile's known region");
        cx = cell_of(h.x, c->ox, c->ex, gs);
        cy = cell_of(h.y, c->oy, c->ey, gs);
        c->cell[i] = (uint32_t)(cy * gs + cx);
        c->start[c->cell[i] + 1]++;
    }
    for (size_t k = 0; k < ncells; k++)
        c->start[k + 1] += c->start[k];
    /* stable placement: start[k] walks forward, then is shifted back */
    for (size_t i = 0; i < nhalo; i++)
        c->pts[c->start[c->cell[i]]++] = halo[i];
    for (size_t k = ncells; k > 0; k--)
        c->start[k] = c->start[k - 1];
    c->start[0] = 0;
    return GDT_OK;
}

/* Cell range [lo, hi] covering [a, b] (lattice units, clamped to K). */
static int cell_range(double a, double b, int64_t o, int64_t e, int64_t gs, int64_t *lo,
                      int64_t *hi)
{
    double ka = (double)o, kb = (double)(o + e - 1);
    if (a < ka)
        a = ka;
    if (b > kb)
        b = kb;
    if (a > b)
        return 0;
    *lo = cell_of((int64_t)floor(a), o, e, gs);
    *hi = cell_of((int64_t)floor(b), o, e, gs);
    return 1;
}

/* 1 if a halo point lies inside or on the circle through a, b, c
 * (counter-clockwise), looking only at the cells under the disk's box. */
static int halo_in_disk(const gdt_certifier *c, gdt_ipt a, gdt_ipt b, gdt_ipt p,
                        const double box[4], gdt_cert_stats *cs)
{
    int64_t x0, x1, y0, y1;
    if (!cell_range(box[0], box[2], c->ox, c->ex, c->gs, &x0, &x1) ||
        !cell_range(box[1], box[3], c->oy, c->ey, c->gs, &y0, &y1))
        return 0;
    for (int64_t cy = y0; cy <= y1; cy++) {
        for (int64_t cx = x0; cx <= x1; cx++) {
            size_t k = (size_t)(cy * c->gs + cx);
            for (uint32_t i = c->start[k]; i < c->start[k + 1]; i++) {
                gdt_ipt h = c->pts[i];
                if ((double)h.x < box[0] || (double)h.x > box[2] || (double)h.y < box[1] ||
                    (double)h.y > box[3])
                    continue; /* outside the disk's outer box */
                cs->halo_tests++;
                if (gdt_incircle(&cs->pred, a, b, p, h) >= 0)
                    return 1;
            }
        }
    }
    return 0;
}

/* One slice [t0, t1) of the triangles; slices share only read-only data
 * and write disjoint parts of cert. */
typedef struct cert_job {
    const gdt_certifier *c;
    const gdt_mesh *m;
    const gdt_cert_region *r;
    size_t nhalo, t0, t1;
    uint8_t *cert;
    gdt_cert_stats cs;
} cert_job;

static void *certify_range(void *arg)
{
    cert_job *j = arg;
    const gdt_cert_region *r = j->r;
    const gdt_mesh *m = j->m;
    gdt_cert_stats *cs = &j->cs;
    /* integer points strictly beyond a side: the disk box must stay before it */
    const double own_lo_x = (double)(r->own[0] - 1), own_hi_x = (double)(r->own[2] + 1);
    const double own_lo_y = (double)(r->own[1] - 1), own_hi_y = (double)(r->own[3] + 1);
    const double k_lo_x = (double)(r->known[0] - 1), k_hi_x = (double)(r->known[2] + 1);
    const double k_lo_y = (double)(r->known[1] - 1), k_hi_y = (double)(r->known[3] + 1);

    for (size_t t = j->t0; t < j->t1; t++) {
        gdt_ipt a = m->pts[m->tri[3 * t]], b = m->pts[m->tri[3 * t + 1]],
                p = m->pts[m->tri[3 * t + 2]];
        double box[4];
        int64_t reach;
        j->cert[t] = 0;
        cs->triangles++;
        /* Most disks are tiny against the tile: when the circle's diameter
         * is below a's distance to the nearest integer line beyond the own
         * box, the closed disk stays strictly inside it (a is on the
         * circle), which is the inner case below without its divisions. */
        reach = a.x - (r->own[0] - 1);
        if (r->own[2] + 1 - a.x < reach)
            reach = r->own[2] + 1 - a.x;
        if (a.y - (r->own[1] - 1) < reach)
            reach = a.y - (r->own[1] - 1);
        if (r->own[3] + 1 - a.y < reach)
            reach = r->own[3] + 1 - a.y;
        if (gdt_circumdiameter_below(&cs->pred, a, b, p, reach)) {
            j->cert[t] = 1;
            cs->inner++;
            cs->certified++;
            continue;
        }
        if (!gdt_circumdisk_bounds(&cs->pred, a, b, p, box))
            continue;
        if (box[0] > own_lo_x && box[2] < own_hi_x && box[1] > own_lo_y && box[3] < own_hi_y) {
            j->cert[t] = 1;
            cs->inner++;
            cs->certified++;
            continue;
        }
        if ((!r->open[GDT_SIDE_WEST] && !(box[0] > k_lo_x)) ||
            (!r->open[GDT_SIDE_SOUTH] && !(box[1] > k_lo_y)) ||
            (!r->open[GDT_SIDE_EAST] && !(box[2] < k_hi_x)) ||
            (!r->open[GDT_SIDE_NORTH] && !(box[3] < k_hi_y))) {
            cs->outside_known++;
            continue;
        }
        if (j->nhalo > 0 && halo_in_disk(j->c, a, b, p, box, cs)) {
            cs->halo_hit++;
            continue;
        }
        j->cert[t] = 1;
        cs->certified++;
    }
    return NULL;
}

static void stats_add(gdt_cert_stats *to, const gdt_cert_stats *from)
{
    gdt_pred_stats_add(&to->pred, &from->pred);
    to->triangles += from->triangles;
    to->certified += from->certified;
    to->inner += from->inner;
    to->outside_known += from->outside_known;
    to->halo_hit += from->halo_hit;
    to->halo_tests += from->halo_tests;
}

gdt_status gdt_certify_tile(gdt_certifier *c, const gdt_mesh *m, const gdt_ipt *halo,
                            size_t nhalo, const gdt_cert_region *r, uint8_t *cert,
                            gdt_cert_stats *cs_out, gdt_error *err)
{
    cert_job jobs[CERT_MAX_THREADS];
    pthread_t tid[CERT_MAX_THREADS];
    size_t nt = (size_t)c->threads, started = 0;
    gdt_status st;

    st = build_grid(c, halo, nhalo, r, err);
    if (st != GDT_OK)
        return st;
    if (nt > m->ntris / CERT_MIN_PER_THREAD)
        nt = m->ntris / CERT_MIN_PER_THREAD;
    if (nt < 1)
        nt = 1;
    for (size_t k = 0; k < nt; k++) {
        memset(&jobs[k], 0, sizeof jobs[k]);
        jobs[k].c = c;
        jobs[k].m = m;
        jobs[k].r = r;
        jobs[k].nhalo = nhalo;
        jobs[k].cert = cert;
        jobs[k].t0 = m->ntris / nt * k;
        jobs[k].t1 = k + 1 == nt ? m->ntris : m->ntris / nt * (k + 1);
    }
    /* slice 0 runs here; a thread that cannot start leaves its slice to
     * this thread too (the result does not depend on the split) */
    for (size_t k = 1; k < nt; k++) {
        if (pthread_create(&tid[k], NULL, certify_range, &jobs[k]) != 0)
            break;
        started = k;
    }
    certify_range(&jobs[0]);
    for (size_t k = 1; k <= started; k++)
        pthread_join(tid[k], NULL);
    for (size_t k = started + 1; k < nt; k++)
        certify_range(&jobs[k]);
    if (cs_out != NULL)
        for (size_t k = 0; k < nt; k++)
            stats_add(cs_out, &jobs[k].cs);
    return GDT_OK;
}
