/* gcd_hull.c — the fake ring of Phase 2 (see private/gcd_hull.h).  All geometry goes through the shared exact
 * arithmetic: gcd_orient of kernels/gcd_geom.clh (real points reduce to
 * gdt_x_orient2d). */
#include "private/gcd_hull.h"

#include <stdlib.h>
#include <string.h>

#include "gcd_geom.clh"

void gcd_tri_list_free(gcd_tri_list *l)
{
    free(l->v);
    memset(l, 0, sizeof *l);
}

static int tl_push(gcd_tri_list *l, int32_t a, int32_t b, int32_t c)
{
    if (l->n == l->cap) {
        size_t nc = l->cap ? 2 * l->cap : 256;
        int32_t *g = realloc(l->v, 3 * nc * sizeof *g);
        if (g == NULL)
            return -1;
        l->v = g;
        l->cap = nc;
    }
    l->v[3 * l->n] = a;
    l->v[3 * l->n + 1] = b;
    l->v[3 * l->n + 2] = c;
    l->n++;
    return 0;
}

static int orient_pts(gdt_ipt a, gdt_ipt b, gdt_ipt c)
{
    return gdt_x_orient2d(a.x, a.y, b.x, b.y, c.x, c.y);
}

/* Symbolic point of vertex v at position p (fakes ignore p). */
static gcd_spt spt_of(const gcd_frame *fr, int32_t v, gdt_ipt p)
{
    if (v >= fr->nreal && v < fr->nreal + GCD_NFAKE)
        return gcd_spt_fake(v - fr->nreal);
    return gcd_spt_real(p.x, p.y, fr->cx, fr->cy);
}

/* Fake whose direction is closest to the outward normal of hull edge
 * a -> b (counter-clockwise hull): max u.n, n = (dy, -dx); of two equally
 * close (always neighbours) the clockwise one. */
static int fake_for_edge(gdt_ipt a, gdt_ipt b)
{
    int64_t nx = b.y - a.y, ny = -(b.x - a.x);
    int best = 0;
    int64_t bd = 0;
    for (int k = 0; k < GCD_NFAKE; k++) {
        int64_t d = GCD_FAKE_DX[k] * nx + GCD_FAKE_DY[k] * ny;
        if (k == 0 || d > bd) {
            best = k;
            bd = d;
        } else if (d == bd && best == (k + 1) % GCD_NFAKE) {
            best = k;
        }
    }
    return best;
}

/* Appends ring triangle (v0, v1, v2) after checking that it is
 * counter-clockwise in the symbolic plane (positions p0..p2 for real ones). */
static gdt_status ring_push(const gcd_frame *fr, gcd_tri_list *out, int32_t v0, gdt_ipt p0,
                            int32_t v1, gdt_ipt p1, int32_t v2, gdt_ipt p2, gdt_error *err)
{
    if (gcd_orient(spt_of(fr, v0, p0), spt_of(fr, v1, p1), spt_of(fr, v2, p2)) <= 0)
        return gdt_error_set(err, GDT_EINTERNAL, 7621,
                             "fake ring triangle (%d, %d, %d) is not counter-clockwise", v0, v1,
                             v2);
    if (tl_push(out, v0, v1, v2) != 0)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    return GDT_OK;
}

/* Ring of fake triangles around the hull cycle h[0..k) (counter-clockwise,
 * collinear hull points included; a doubled chain for collinear sets;
 * k = 1 for a single point). */
static gdt_status ring(const gcd_frame *fr, const int32_t *h, const gdt_ipt *hp, size_t k,
                       gcd_tri_list *out, size_t *nring, gdt_error *err)
{
    size_t before = out->n;
    const gdt_ipt z = {0, 0};
    int *f = NULL;
    int steps = 0;
    gdt_status st = GDT_OK;

    if (k == 1) {
        for (int j = 0; j < GCD_NFAKE && st == GDT_OK; j++)
            st = ring_push(fr, out, h[0], hp[0], fr->nreal + j, z,
                           fr->nreal + (j + 1) % GCD_NFAKE, z, err);
        *nring = out->n - before;
        return st;
    }
    f = malloc(k * sizeof *f);
    if (f == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    for (size_t j = 0; j < k; j++)
        f[j] = fake_for_edge(hp[j], hp[(j + 1) % k]);
    for (size_t j = 0; j < k && st == GDT_OK; j++) {
        size_t jn = (j + 1) % k;
        /* the edge's triangle, then the fan at h[jn] from the fake of edge j
         * to the fake of edge jn */
        st = ring_push(fr, out, h[jn], hp[jn], h[j], hp[j], fr->nreal + f[j], z, err);
        for (int q = f[j]; q != f[jn] && st == GDT_OK && steps <= GCD_NFAKE;
             q = (q + 1) % GCD_NFAKE, steps++)
            st = ring_push(fr, out, h[jn], hp[jn], fr->nreal + q, z,
                           fr->nreal + (q + 1) % GCD_NFAKE, z, err);
    }
    if (st == GDT_OK && steps != GCD_NFAKE)
        st = gdt_error_set(err, GDT_EINTERNAL, 7621,
                           "fake ring: the hull normals turn %d/%d times around", steps,
                           GCD_NFAKE);
    *nring = out->n - before;
    free(f);
    return st;
}

/* A point with its position in the input arrays, for sorting. */
typedef struct lex_pt {
    gdt_ipt p;
    size_t i;
} lex_pt;

static int cmp_lex(const void *a, const void *b)
{
    gdt_ipt p = ((const lex_pt *)a)->p, q = ((const lex_pt *)b)->p;
    if (p.x != q.x)
        return p.x < q.x ? -1 : 1;
    return (p.y > q.y) - (p.y < q.y);
}

/* ord[i] = index of the i-th point in lexicographic (x, y) order. */
static int sort_lex(const gdt_ipt *pos, size_t n, size_t *ord)
{
    lex_pt *t = malloc((n ? n : 1) * sizeof *t);
    if (t == NULL)
        return -1;
    for (size_t i = 0; i < n; i++) {
        t[i].p = pos[i];
        t[i].i = i;
    }
    qsort(t, n, sizeof *t, cmp_lex);
    for (size_t i = 0; i < n; i++)
        ord[i] = t[i].i;
    free(t);
    return 0;
}

gdt_status gcd_ring(const gcd_frame *fr, const int32_t *h, const gdt_ipt *hp, size_t k,
                    gcd_tri_list *out, size_t *nring, gdt_error *err)
{
    if (k == 0)
        return gdt_error_set(err, GDT_EINTERNAL, 7621, "fake ring around no vertex");
    return ring(fr, h, hp, k, out, nring, err);
}

gdt_status gcd_hull_degenerate(const gcd_frame *fr, int32_t *idx, gdt_ipt *pos, size_t m,
                               gcd_tri_list *out, size_t *nring, gdt_error *err)
{
    size_t *ord = malloc((m ? m : 1) * sizeof *ord);
    int32_t *hv = malloc((2 * m + 1) * sizeof *hv);
    gdt_ipt *hp = malloc((2 * m + 1) * sizeof *hp);
    size_t k = 0;
    gdt_status st;

    *nring = 0;
    if (ord == NULL || hv == NULL || hp == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto done;
    }
    if (sort_lex(pos, m, ord) != 0) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto done;
    }
    for (size_t i = 0; i < m; i++) {
        hv[k] = idx[ord[i]];
        hp[k++] = pos[ord[i]];
    }
    for (size_t i = m - 1; i-- > 1;) {
        hv[k] = idx[ord[i]];
        hp[k++] = pos[ord[i]];
    }
    for (size_t i = 2; i < m; i++) {
        if (orient_pts(hp[0], hp[1], hp[i]) != 0) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7621,
                               "degenerate hull: the kept points are not collinear");
            goto done;
        }
    }
    st = ring(fr, hv, hp, k, out, nring, err);
done:
    free(ord);
    free(hv);
    free(hp);
    return st;
}
