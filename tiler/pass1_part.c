/* pass1_part.c — pass 1 shared between processes: what one share of the
 * cloud gave (bounds, point count, density histogram, tiles counted under a
 * given --cell, the filter's counts per input) as bytes, and their sum into
 * the tiler that plans.
 *
 * Every quantity is a sum, a minimum or a maximum over the points, or (the
 * histogram) a function of the point set alone (density.c), so the sum of
 * the shares is what one pass over the whole cloud gives, whatever the
 * shares and the order they are added in; gdt_tiler_pass1_end then plans
 * exactly as gdt_tiler_pass1 does.
 *
 * Layout, little-endian u64 words: magic, inputs, points, min x, max x,
 * min y, max y, min z, max z (IEEE bits), shift, voxels V, counted tiles C;
 * then per input the five filter counts; V (x, y, n) voxels; C (i, j, n)
 * tiles.
 */
#include "private/tiler_impl.h"

#include <inttypes.h>
#include <stdlib.h>
#include <string.h>

#define PART_MAGIC UINT64_C(0x7031706172747331) /* "p1parts1" */
#define PART_HEAD 12
#define PART_COUNTS 5

static uint64_t bits_of(double d)
{
    uint64_t v;
    memcpy(&v, &d, sizeof v);
    return v;
}

static double double_of(uint64_t v)
{
    double d;
    memcpy(&d, &v, sizeof d);
    return d;
}

gdt_status gdt_tiler_pass1_part_export(const gdt_tiler *t, unsigned char **buf, size_t *len,
                                       gdt_error *err)
{
    const gdt_tile_plan *p = &t->plan;
    size_t nin = gdt_cloud_get_info(t->cloud)->ninputs, nv = 0, nt = 0, at = 0;
    uint64_t *vox = NULL, *w;
    gdt_status st;

    *buf = NULL;
    *len = 0;
    if (t->state != 4)
        return gdt_error_set(err, GDT_EUSAGE, 2505, "no share of pass 1 read to export");
    st = tl_density_export(&t->density, &vox, &nv, err);
    if (st != GDT_OK)
        return st;
    if (t->user_cell > 0)
        nt = t->map.n;
    w = malloc((PART_HEAD + PART_COUNTS * nin + 3 * nv + 3 * nt) * sizeof *w);
    if (w == NULL) {
        free(vox);
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    }
    w[at++] = PART_MAGIC;
    w[at++] = nin;
    w[at++] = p->points;
    w[at++] = (uint64_t)p->min_x;
    w[at++] = (uint64_t)p->max_x;
    w[at++] = (uint64_t)p->min_y;
    w[at++] = (uint64_t)p->max_y;
    w[at++] = bits_of(p->min_z);
    w[at++] = bits_of(p->max_z);
    w[at++] = (uint64_t)t->density.shift;
    w[at++] = nv;
    w[at++] = nt;
    for (size_t i = 0; i < nin; i++) {
        const gdt_filter_counts *k = gdt_cloud_input_counts(t->cloud, i);
        w[at++] = k->read;
        w[at++] = k->kept;
        w[at++] = k->drop_withheld;
        w[at++] = k->drop_class;
        w[at++] = k->drop_return;
    }
    if (nv > 0)
        memcpy(w + at, vox, 3 * nv * sizeof *w);
    at += 3 * nv;
    free(vox);
    for (size_t s = 0; nt > 0 && s < t->map.cap; s++)
        if (t->map.e[s].used) {
            w[at++] = (uint64_t)t->map.e[s].i;
            w[at++] = (uint64_t)t->map.e[s].j;
            w[at++] = t->map.e[s].v;
        }
    *buf = (unsigned char *)w;
    *len = at * sizeof *w;
    return GDT_OK;
}

gdt_status gdt_tiler_pass1_part_merge(gdt_tiler *t, const unsigned char *buf, size_t len,
                                      gdt_error *err)
{
    gdt_tile_plan *p = &t->plan;
    size_t nin = gdt_cloud_get_info(t->cloud)->ninputs, nw = len / sizeof(uint64_t);
    uint64_t *w = NULL, nv, nt, pts;
    size_t at = PART_HEAD;
    gdt_status st = GDT_OK;

    if (t->state != 4)
        return gdt_error_set(err, GDT_EUSAGE, 2505, "no share of pass 1 read to add to");
    if (len % sizeof(uint64_t) != 0 || nw < PART_HEAD)
        goto bad;
    /* a private aligned copy: buf may come straight from a message */
    w = malloc(len);
    if (w == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    memcpy(w, buf, len);
    nv = w[10];
    nt = w[11];
    if (w[0] != PART_MAGIC || w[1] != nin || w[9] >= 62 || nv > nw / 3 || nt > nw / 3 ||
        nw != PART_HEAD + PART_COUNTS * nin + 3 * nv + 3 * nt || (nt > 0 && t->user_cell <= 0))
        goto bad;
    pts = w[2];
    if (pts > 0) {
        int64_t x0 = (int64_t)w[3], x1 = (int64_t)w[4], y0 = (int64_t)w[5], y1 = (int64_t)w[6];
        double z0 = double_of(w[7]), z1 = double_of(w[8]);
        if (p->points == 0) {
            p->min_z = z0;
            p->max_z = z1;
        } else {
            if (z0 < p->min_z) p->min_z = z0;
            if (z1 > p->max_z) p->max_z = z1;
        }
        if (x0 < p->min_x) p->min_x = x0;
        if (x1 > p->max_x) p->max_x = x1;
        if (y0 < p->min_y) p->min_y = y0;
        if (y1 > p->max_y) p->max_y = y1;
        p->points += pts;
    }
    for (size_t i = 0; i < nin; i++, at += PART_COUNTS) {
        gdt_filter_counts k;
        k.read = w[at];
        k.kept = w[at + 1];
        k.drop_withheld = w[at + 2];
        k.drop_class = w[at + 3];
        k.drop_return = w[at + 4];
        gdt_cloud_add_counts(t->cloud, i, &k);
    }
    st = tl_density_merge(&t->density, (int)w[9], w + at, (size_t)nv, err);
    at += 3 * nv;
    for (uint64_t k = 0; st == GDT_OK && k < nt; k++, at += 3) {
        uint64_t *v;
        st = tl_map_upsert(&t->map, (int64_t)w[at], (int64_t)w[at + 1], &v, err);
        if (st == GDT_OK) {
            *v += w[at + 2];
            if (t->map.n > tl_max_counted_tiles(t))
                st = gdt_error_set(err, GDT_EUSAGE, 2503,
                                   "more than %zu non-empty tiles of %" PRId64
                                   " lattice steps do not fit in the memory budget of %" PRIu64
                                   " bytes: use a larger --cell or --mem-budget",
                                   tl_max_counted_tiles(t),
                                   (int64_t)t->opts.tile * t->user_cell, t->budget);
        }
    }
    free(w);
    if (st != GDT_OK)
        t->state = -1;
    return st;
bad:
    free(w);
    t->state = -1;
    return gdt_error_set(err, GDT_EINTERNAL, 7506,
                         "a share of pass 1 (%zu bytes) from another build, or damaged", len);
}
