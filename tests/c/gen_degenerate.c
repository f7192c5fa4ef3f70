/* gen_degenerate.c — seeded generators of degenerate point sets and the
 * shared helpers of the mesh tests. */
#include "gen_degenerate.h"

#include <inttypes.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

void gen_seed(gen_rng *r, uint64_t seed)
{
    r->s = seed * UINT64_C(0x9e3779b97f4a7c15) + UINT64_C(0x632be59bd9b4e019);
    if (r->s == 0)
        r->s = 1;
}

uint64_t gen_next(gen_rng *r)
{
    uint64_t x = r->s;
    x ^= x >> 12;
    x ^= x << 25;
    x ^= x >> 27;
    r->s = x;
    return x * UINT64_C(0x2545f4914f6cdd1d);
}

uint64_t gen_below(gen_rng *r, uint64_t n)
{
    return gen_next(r) % n;
}

int64_t gen_range(gen_rng *r, int64_t lo, int64_t hi)
{
    return lo + (int64_t)gen_below(r, (uint64_t)(hi - lo) + 1);
}

/* Appends (x, y) to p[*m] when it lies in [0, GDT_COORD_MAX]^2; p has room. */
static void push_in_range(gdt_ipt *p, size_t *m, int64_t x, int64_t y)
{
    if (x >= 0 && x <= GDT_COORD_MAX && y >= 0 && y <= GDT_COORD_MAX) {
        p[*m].x = x;
        p[*m].y = y;
        (*m)++;
    }
}

typedef struct keyed {
    gdt_ipt p;
    size_t idx;
} keyed;

static int keyed_cmp(const void *a, const void *b)
{
    const keyed *x = a, *y = b;
    if (x->p.x != y->p.x)
        return x->p.x < y->p.x ? -1 : 1;
    if (x->p.y != y->p.y)
        return x->p.y < y->p.y ? -1 : 1;
    return (x->idx > y->idx) - (x->idx < y->idx);
}

void gen_dedup(gdt_ipt *pts, size_t *n)
{
    size_t m = *n;
    if (m < 2)
        return;
    keyed *k = malloc(m * sizeof *k);
    unsigned char *drop = calloc(m, 1);
    if (k == NULL || drop == NULL) {
        free(k);
        free(drop);
        return;
    }
    for (size_t i = 0; i < m; i++)
        k[i].p = pts[i], k[i].idx = i;
    qsort(k, m, sizeof *k, keyed_cmp);
    for (size_t i = 1; i < m; i++)
        if (k[i].p.x == k[i - 1].p.x && k[i].p.y == k[i - 1].p.y)
            drop[k[i].idx] = 1;
    size_t w = 0;
    for (size_t i = 0; i < m; i++)
        if (!drop[i])
            pts[w++] = pts[i];
    *n = w;
    free(k);
    free(drop);
}

void gen_shuffle(gen_rng *r, gdt_ipt *pts, size_t n, int64_t *perm)
{
    if (perm != NULL)
        for (size_t i = 0; i < n; i++)
            perm[i] = (int64_t)i;
    for (size_t i = n; i > 1; i--) {
        size_t j = (size_t)gen_below(r, i);
        gdt_ipt x = pts[i - 1];
        pts[i - 1] = pts[j];
        pts[j] = x;
        if (perm != NULL) {
            int64_t q = perm[i - 1];
            perm[i - 1] = perm[j];
            perm[j] = q;
        }
    }
}

gdt_ipt *gen_uniform(gen_rng *r, size_t n, int64_t lo, int64_t hi, size_t *out_n)
{
    gdt_ipt *p = malloc((n > 0 ? n : 1) * sizeof *p);
    if (p == NULL)
        return NULL;
    for (size_t i = 0; i < n; i++) {
        p[i].x = gen_range(r, lo, hi);
        p[i].y = gen_range(r, lo, hi);
    }
    *out_n = n;
    gen_dedup(p, out_n);
    return p;
}

gdt_ipt *gen_grid(size_t nx, size_t ny, int64_t x0, int64_t y0, int64_t step, size_t *out_n)
{
    gdt_ipt *p = malloc((nx * ny > 0 ? nx * ny : 1) * sizeof *p);
    size_t k = 0;
    if (p == NULL)
        return NULL;
    for (size_t j = 0; j < ny; j++)
        for (size_t i = 0; i < nx; i++) {
            p[k].x = x0 + (int64_t)i * step;
            p[k].y = y0 + (int64_t)j * step;
            k++;
        }
    *out_n = k;
    return p;
}

gdt_ipt *gen_rotated_grid(int64_t k, int64_t a, int64_t b, int64_t cx, int64_t cy, size_t *out_n)
{
    size_t side = (size_t)(2 * k + 1);
    gdt_ipt *p = malloc(side * side * sizeof *p);
    size_t m = 0;
    if (p == NULL)
        return NULL;
    for (int64_t i = -k; i <= k; i++)
        for (int64_t j = -k; j <= k; j++) {
            int64_t x = cx + i * a - j * b, y = cy + i * b + j * a;
            push_in_range(p, &m, x, y);
        }
    *out_n = m;
    return p;
}

gdt_ipt *gen_circle(int64_t cx, int64_t cy, int64_t r, size_t *out_n)
{
    size_t cap = 64, m = 0;
    gdt_ipt *p = malloc(cap * sizeof *p);
    if (p == NULL)
        return NULL;
    for (int64_t x = 0; x <= r; x++) {
        int64_t y2 = r * r - x * x;
        int64_t y = (int64_t)sqrt((double)y2);
        while (y * y > y2)
            y--;
        while ((y + 1) * (y + 1) <= y2)
            y++;
        if (y * y != y2)
            continue;
        int64_t cand[4][2] = {{x, y}, {-x, y}, {x, -y}, {-x, -y}};
        for (int q = 0; q < 4; q++) {
            if (m + 1 > cap) {
                cap *= 2;
                gdt_ipt *np = realloc(p, cap * sizeof *p);
                if (np == NULL) {
                    free(p);
                    return NULL;
                }
                p = np;
            }
            int64_t px = cx + cand[q][0], py = cy + cand[q][1];
            push_in_range(p, &m, px, py);
        }
    }
    *out_n = m;
    gen_dedup(p, out_n);
    return p;
}

gdt_ipt *gen_thin_circle(gen_rng *r, size_t n, int64_t cx, int64_t cy, int64_t radius,
                         int64_t width, size_t *out_n)
{
    gdt_ipt *p = malloc((n > 0 ? n : 1) * sizeof *p);
    size_t m = 0;
    if (p == NULL)
        return NULL;
    for (size_t i = 0; i < n; i++) {
        double th = 6.283185307179586 * (double)gen_below(r, 1u << 30) / (double)(1u << 30);
        double rr = (double)(radius + gen_range(r, -width, width));
        int64_t x = cx + (int64_t)llround(rr * cos(th));
        int64_t y = cy + (int64_t)llround(rr * sin(th));
        push_in_range(p, &m, x, y);
    }
    *out_n = m;
    gen_dedup(p, out_n);
    return p;
}

gdt_ipt *gen_collinear(gen_rng *r, size_t n, int64_t x0, int64_t y0, int64_t dx, int64_t dy,
                       int64_t span, size_t *out_n)
{
    gdt_ipt *p = malloc((n > 0 ? n : 1) * sizeof *p);
    size_t m = 0;
    if (p == NULL)
        return NULL;
    for (size_t i = 0; i < n; i++) {
        int64_t t = gen_range(r, 0, span - 1);
        int64_t x = x0 + t * dx, y = y0 + t * dy;
        push_in_range(p, &m, x, y);
    }
    *out_n = m;
    gen_dedup(p, out_n);
    gen_shuffle(r, p, *out_n, NULL);
    return p;
}

gdt_ipt *gen_clusters(gen_rng *r, size_t nc, size_t per, int64_t spread, size_t *out_n)
{
    gdt_ipt *p = malloc((nc * per > 0 ? nc * per : 1) * sizeof *p);
    size_t m = 0;
    if (p == NULL)
        return NULL;
    for (size_t c = 0; c < nc; c++) {
        int64_t cx = gen_range(r, spread, GDT_COORD_MAX - spread);
        int64_t cy = gen_range(r, spread, GDT_COORD_MAX - spread);
        for (size_t i = 0; i < per; i++) {
            p[m].x = cx + gen_range(r, -spread, spread);
            p[m].y = cy + gen_range(r, -spread, spread);
            m++;
        }
    }
    *out_n = m;
    gen_dedup(p, out_n);
    return p;
}

gdt_ipt *gen_extremes(gen_rng *r, size_t *out_n)
{
    const int64_t M = GDT_COORD_MAX;
    size_t cap = 4 * 25 + 4 * 20, m = 0;
    gdt_ipt *p = malloc(cap * sizeof *p);
    if (p == NULL)
        return NULL;
    const int64_t corner[4][2] = {{0, 0}, {M, 0}, {0, M}, {M, M}};
    for (int c = 0; c < 4; c++)
        for (int64_t i = 0; i < 5; i++)
            for (int64_t j = 0; j < 5; j++) {
                p[m].x = corner[c][0] == 0 ? i : M - i;
                p[m].y = corner[c][1] == 0 ? j : M - j;
                m++;
            }
    for (int q = 0; q < 20; q++) {
        int64_t t = gen_range(r, 0, M);
        switch (q % 4) {
        case 0: p[m].x = t, p[m].y = 0; break;
        case 1: p[m].x = t, p[m].y = M; break;
        case 2: p[m].x = 0, p[m].y = t; break;
        default: p[m].x = M, p[m].y = t; break;
        }
        m++;
    }
    *out_n = m;
    gen_dedup(p, out_n);
    gen_shuffle(r, p, *out_n, NULL);
    return p;
}

gdt_ipt *gen_with_duplicates(gen_rng *r, size_t n, size_t m, int64_t x, int64_t y, size_t *out_n)
{
    gdt_ipt *p = malloc((n + m > 0 ? n + m : 1) * sizeof *p);
    if (p == NULL)
        return NULL;
    for (size_t i = 0; i < n; i++)
        p[i].x = x, p[i].y = y;
    for (size_t i = 0; i < m; i++) {
        p[n + i].x = gen_range(r, 0, 1 << 20);
        p[n + i].y = gen_range(r, 0, 1 << 20);
    }
    *out_n = n + m;
    gen_shuffle(r, p, n + m, NULL);
    return p;
}

int gen_brute_empty_circles(const gdt_mesh *m, char *why, size_t why_len)
{
    for (size_t t = 0; t < m->ntris; t++) {
        const int32_t *T = m->tri + 3 * t;
        for (size_t v = 0; v < m->nverts; v++) {
            if ((int32_t)v == T[0] || (int32_t)v == T[1] || (int32_t)v == T[2])
                continue;
            if (gdt_incircle(NULL, m->pts[T[0]], m->pts[T[1]], m->pts[T[2]], m->pts[v]) > 0) {
                snprintf(why, why_len,
                         "vertex %zu (%" PRId64 ", %" PRId64 ") lies strictly inside the "
                         "circumcircle of triangle %zu (%d, %d, %d)",
                         v, m->pts[v].x, m->pts[v].y, t, (int)T[0], (int)T[1], (int)T[2]);
                return -1;
            }
        }
    }
    return 0;
}

int64_t *gen_canonical(const gdt_mesh *m)
{
    int64_t *c = malloc((3 * m->ntris > 0 ? 3 * m->ntris : 1) * sizeof *c);
    if (c != NULL)
        gdt_mesh_canonical(m, c);
    return c;
}

int gen_same_triangles(const gdt_mesh *a, const gdt_mesh *b, char *why, size_t why_len)
{
    int rc = 0;
    int64_t *ca = gen_canonical(a), *cb = gen_canonical(b);
    if (ca == NULL || cb == NULL) {
        snprintf(why, why_len, "out of memory");
        rc = -1;
    } else if (a->ntris != b->ntris) {
        snprintf(why, why_len, "%zu triangles against %zu", a->ntris, b->ntris);
        rc = -1;
    } else {
        for (size_t t = 0; t < a->ntris; t++)
            if (memcmp(ca + 3 * t, cb + 3 * t, 3 * sizeof *ca) != 0) {
                snprintf(why, why_len,
                         "canonical triangle %zu differs: (%" PRId64 ", %" PRId64 ", %" PRId64
                         ") against (%" PRId64 ", %" PRId64 ", %" PRId64 ")",
                         t, ca[3 * t], ca[3 * t + 1], ca[3 * t + 2], cb[3 * t], cb[3 * t + 1],
                         cb[3 * t + 2]);
                rc = -1;
                break;
            }
    }
    free(ca);
    free(cb);
    return rc;
}

int gen_check_all(tctx *t, const gdt_mesh *m, const char *label)
{
    gdt_error err;
    gdt_error_clear(&err);
    gdt_status s = gdt_check_mesh(NULL, m, &err);
    CHECK(t, s == GDT_OK, "%s: gdt_check_mesh: GDT-%04d %s", label, err.code, err.msg);
    if (s != GDT_OK)
        return -1;
    s = gdt_check_delaunay(NULL, m, &err);
    CHECK(t, s == GDT_OK, "%s: gdt_check_delaunay: GDT-%04d %s", label, err.code, err.msg);
    return s == GDT_OK ? 0 : -1;
}

int gen_finish(const tctx *t, const char *name)
{
    return gdt_check_finish(t, name);
}
