/* test_flip — the Lawson flip engine with the tie-break.
 *
 * Starting from deliberately bad but valid triangulations — a fan from one
 * hull vertex (radial sweep) and a zig-zag strip (sweep in x order) — of
 * 10^5 uniform points and of the degenerate corpus, the engine must reach
 * exactly the reference output (Thm 4.1: T_{d1,d2} does not depend on the
 * start).  A grid cut by the wrong diagonals flips once per cell.  Frozen
 * triangles are never touched, and every other edge ends locally optimal; in
 * general position, freezing triangles of the answer and scrambling the rest
 * still gives the answer.
 */
#include <inttypes.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "gdt_flip.h"
#include "gdt_reference.h"
#include "gen_degenerate.h"
#include "private/mesh_ops.h"

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* ---- sweep triangulations ---- */

static const gdt_ipt *g_pts;
static gdt_ipt g_apex;

static int lex_cmp(const void *x, const void *y)
{
    gdt_ipt a = g_pts[*(const int32_t *)x], b = g_pts[*(const int32_t *)y];
    if (a.x != b.x)
        return a.x < b.x ? -1 : 1;
    return (a.y > b.y) - (a.y < b.y);
}

/* Counter-clockwise around the lexicographically smallest point g_apex;
 * on one ray, nearer first. */
static int radial_cmp(const void *x, const void *y)
{
    gdt_ipt a = g_pts[*(const int32_t *)x], b = g_pts[*(const int32_t *)y];
    int o = gdt_orient2d(NULL, g_apex, a, b);
    if (o != 0)
        return -o;
    return lex_cmp(x, y);
}

/* Triangulates by adding the points in the given order, each joined to the
 * hull edges it sees strictly.  Precondition: every point lies outside the
 * hull of the earlier ones and sees an edge at the previous point (true for
 * lexicographic order, and for radial order around the first point).
 * Fills m->tri and links it.  Returns 0 on success. */
static int sweep(gdt_mesh *m, const int32_t *order, size_t n)
{
    const gdt_ipt *P = m->pts;
    int32_t *next = malloc(n * sizeof *next), *prev = malloc(n * sizeof *prev);
    size_t nt = 0, k = 2;
    gdt_error err;
    int rc = -1;

    if (next == NULL || prev == NULL || n < 3)
        goto done;
    while (k < n && gdt_orient2d(NULL, P[order[0]], P[order[1]], P[order[k]]) == 0)
        k++;
    if (k == n)
        goto done;
    int ccw = gdt_orient2d(NULL, P[order[0]], P[order[1]], P[order[k]]) > 0;
    int32_t apex = order[k];
    for (size_t i = 0; i + 1 < k; i++) {
        int32_t a = order[i], b = order[i + 1];
        int32_t *T = m->tri + 3 * nt++;
        T[0] = ccw ? a : b, T[1] = ccw ? b : a, T[2] = apex;
        /* hull: the line points in one direction, then the apex */
        if (ccw)
            next[a] = b, prev[b] = a;
        else
            next[b] = a, prev[a] = b;
    }
    {
        int32_t first = order[0], lastl = order[k - 1];
        if (ccw)
            next[lastl] = apex, prev[apex] = lastl, next[apex] = first, prev[first] = apex;
        else
            next[first] = apex, prev[apex] = first, next[apex] = lastl, prev[lastl] = apex;
    }
    int32_t last = apex;
    for (size_t i = k + 1; i < n; i++) {
        int32_t q = order[i], r = last, l = last;
        while (gdt_orient2d(NULL, P[r], P[next[r]], P[q]) < 0) {
            int32_t *T = m->tri + 3 * nt++;
            T[0] = next[r], T[1] = r, T[2] = q;
            r = next[r];
        }
        while (gdt_orient2d(NULL, P[prev[l]], P[l], P[q]) < 0) {
            int32_t *T = m->tri + 3 * nt++;
            T[0] = l, T[1] = prev[l], T[2] = q;
            l = prev[l];
        }
        if (l == r) /* sees no edge: precondition broken */
            goto done;
        next[l] = q, prev[q] = l, next[q] = r, prev[r] = q;
        last = q;
    }
    m->ntris = nt;
    gdt_error_clear(&err);
    rc = gdt_mesh_link(m, &err) == GDT_OK ? 0 : -1;

done:
    free(next);
    free(prev);
    return rc;
}

/* Builds a fan (radial) or strip (lexicographic) triangulation of pts. */
static int bad_triangulation(gdt_mesh *m, const gdt_ipt *pts, size_t n, int radial)
{
    gdt_error err;
    int32_t *order = malloc((n > 0 ? n : 1) * sizeof *order);
    int rc = -1;

    gdt_error_clear(&err);
    if (order == NULL || gdt_mesh_set_points(m, pts, n, &err) != GDT_OK ||
        gdt_mesh_reserve(m, n, 2 * n, 0, &err) != GDT_OK)
        goto done;
    for (size_t i = 0; i < n; i++)
        order[i] = (int32_t)i;
    g_pts = pts;
    qsort(order, n, sizeof *order, lex_cmp);
    if (radial) {
        g_apex = pts[order[0]];
        qsort(order + 1, n - 1, sizeof *order, radial_cmp);
    }
    rc = sweep(m, order, n);

done:
    free(order);
    return rc;
}

/* From a bad start to exactly the reference. */
static void from_bad(tctx *t, const char *label, const gdt_ipt *pts, size_t n, int radial,
                     int timed)
{
    gdt_mesh ref, m;
    gdt_error err;
    gdt_flip_stats fs = {0, 0};
    char why[512];

    gdt_mesh_init(&ref);
    gdt_mesh_init(&m);
    gdt_error_clear(&err);
    gdt_status s = gdt_reference_triangulate(NULL, pts, n, &ref, &err);
    CHECK(t, s == GDT_OK, "%s: reference: GDT-%04d %s", label, err.code, err.msg);
    int rc = bad_triangulation(&m, pts, n, radial);
    CHECK(t, rc == 0, "%s: could not build the %s triangulation", label, radial ? "fan" : "strip");
    if (s != GDT_OK || rc != 0)
        goto done;
    s = gdt_check_mesh(NULL, &m, &err);
    CHECK(t, s == GDT_OK, "%s: %s start is not a valid mesh: GDT-%04d %s", label,
          radial ? "fan" : "strip", err.code, err.msg);
    double t0 = now_s();
    s = gdt_flip_to_delaunay(NULL, &fs, &m, NULL, &err);
    double t1 = now_s();
    CHECK(t, s == GDT_OK, "%s: flip: GDT-%04d %s", label, err.code, err.msg);
    CHECK(t, gen_same_triangles(&ref, &m, why, sizeof why) == 0, "%s (%s): %s", label,
          radial ? "fan" : "strip", why);
    gen_check_all(t, &m, label);
    if (timed)
        printf("%s, %s start: %zu points, %" PRIu64 " flips, %" PRIu64 " tests, %.3f s\n", label,
               radial ? "fan" : "strip", n, fs.flips, fs.edges_tested, t1 - t0);
    /* Already optimal: nothing to do. */
    gdt_flip_stats again = {0, 0};
    s = gdt_flip_to_delaunay(NULL, &again, &m, NULL, &err);
    CHECK(t, s == GDT_OK && again.flips == 0, "%s: %" PRIu64 " flips on an optimal mesh", label,
          again.flips);

done:
    gdt_mesh_free(&ref);
    gdt_mesh_free(&m);
}

/* A grid cut by the (1,-1) diagonals: check_delaunay must object, and the
 * engine flips every cell once to the (1,1) diagonal. */
static void wrong_grid(tctx *t, size_t k)
{
    gdt_mesh m, ref;
    gdt_error err;
    gdt_flip_stats fs = {0, 0};
    size_t n;
    char why[512];
    gdt_ipt *p = gen_grid(k, k, 100, 200, 5, &n);

    gdt_mesh_init(&m);
    gdt_mesh_init(&ref);
    gdt_error_clear(&err);
    if (gdt_mesh_set_points(&m, p, n, &err) != GDT_OK ||
        gdt_mesh_reserve(&m, n, 2 * (k - 1) * (k - 1), 0, &err) != GDT_OK) {
        CHECK(t, 0, "wrong grid: GDT-%04d %s", err.code, err.msg);
        goto done;
    }
    for (size_t j = 0; j + 1 < k; j++)
        for (size_t i = 0; i + 1 < k; i++) {
            int32_t a = (int32_t)(j * k + i), b = a + 1, c = a + (int32_t)k + 1, d = a + (int32_t)k;
            int32_t *T = m.tri + 3 * m.ntris;
            T[0] = a, T[1] = b, T[2] = d, T[3] = b, T[4] = c, T[5] = d;
            m.ntris += 2;
        }
    CHECK(t, gdt_mesh_link(&m, &err) == GDT_OK, "wrong grid link: %s", err.msg);
    CHECK(t, gdt_check_mesh(NULL, &m, &err) == GDT_OK, "wrong grid mesh: %s", err.msg);
    gdt_error_clear(&err);
    gdt_status s = gdt_check_delaunay(NULL, &m, &err);
    CHECK(t, s == GDT_EINTERNAL && err.code == 7330 && strstr(err.msg, "co-circular"),
          "wrong diagonals not caught: GDT-%04d %s", err.code, err.msg);
    gdt_error_clear(&err);
    CHECK(t, gdt_flip_to_delaunay(NULL, &fs, &m, NULL, &err) == GDT_OK, "flip: %s", err.msg);
    CHECK(t, fs.flips == (k - 1) * (k - 1), "wrong grid: %" PRIu64 " flips for %zu cells", fs.flips,
          (k - 1) * (k - 1));
    CHECK(t, gdt_reference_triangulate(NULL, p, n, &ref, &err) == GDT_OK, "ref: %s", err.msg);
    CHECK(t, gen_same_triangles(&ref, &m, why, sizeof why) == 0, "wrong grid: %s", why);

done:
    gdt_mesh_free(&m);
    gdt_mesh_free(&ref);
    free(p);
}

/* Flips random flippable edges (strictly convex quads) that touch no
 * frozen triangle.  Returns the number of flips done. */
static size_t scramble(gen_rng *r, gdt_mesh *m, const uint8_t *frozen, size_t tries)
{
    size_t done = 0;
    for (size_t k = 0; k < tries; k++) {
        int32_t t = (int32_t)gen_below(r, m->ntris);
        int i = (int)gen_below(r, 3);
        int32_t o = m->opp[3 * (size_t)t + (size_t)i];
        if (o == GDT_MESH_NONE || frozen[t] || frozen[gdt_opp_tri(o)])
            continue;
        const int32_t *T = m->tri + 3 * (size_t)t;
        gdt_ipt c = m->pts[T[i]], a = m->pts[T[mesh_next(i)]], b = m->pts[T[mesh_prev(i)]];
        gdt_ipt d = m->pts[m->tri[3 * (size_t)gdt_opp_tri(o) + (size_t)gdt_opp_slot(o)]];
        if (gdt_orient2d(NULL, c, a, d) > 0 && gdt_orient2d(NULL, c, d, b) > 0) {
            mesh_flip(m->tri, m->opp, t, i);
            done++;
        }
    }
    return done;
}

/* Freezes the triangles whose vertices all lie left of x = cut (integer
 * comparisons only), scrambles the rest, flips, and checks: frozen
 * triangles untouched, valid mesh, every edge away from frozen triangles
 * locally optimal; with exact_answer, the result is the reference. */
static void frozen_case(tctx *t, gen_rng *r, const char *label, const gdt_ipt *pts, size_t n,
                        int64_t cut, int exact_answer)
{
    gdt_mesh m, ref;
    gdt_error err;
    uint8_t *frozen = NULL;
    int32_t *saved = NULL;
    char why[512];
    size_t nfrozen = 0;

    gdt_mesh_init(&m);
    gdt_mesh_init(&ref);
    gdt_error_clear(&err);
    if (gdt_reference_triangulate(NULL, pts, n, &ref, &err) != GDT_OK ||
        gdt_reference_triangulate(NULL, pts, n, &m, &err) != GDT_OK) {
        CHECK(t, 0, "%s: GDT-%04d %s", label, err.code, err.msg);
        goto done;
    }
    frozen = calloc(m.ntris, 1);
    saved = malloc(3 * m.ntris * sizeof *saved);
    if (frozen == NULL || saved == NULL) {
        CHECK(t, 0, "%s: out of memory", label);
        goto done;
    }
    for (size_t k = 0; k < m.ntris; k++) {
        const int32_t *T = m.tri + 3 * k;
        frozen[k] = m.pts[T[0]].x < cut && m.pts[T[1]].x < cut && m.pts[T[2]].x < cut;
        nfrozen += frozen[k];
    }
    memcpy(saved, m.tri, 3 * m.ntris * sizeof *saved);
    size_t sc = scramble(r, &m, frozen, 20 * m.ntris);
    CHECK(t, sc > m.ntris / 4, "%s: only %zu scrambling flips", label, sc);
    CHECK(t, gdt_check_mesh(NULL, &m, &err) == GDT_OK, "%s: scrambled mesh invalid: %s", label,
          err.msg);
    gdt_error_clear(&err);
    gdt_status s = gdt_check_delaunay(NULL, &m, &err);
    CHECK(t, s != GDT_OK, "%s: scrambling left the mesh optimal", label);
    gdt_flip_stats fs = {0, 0};
    gdt_error_clear(&err);
    s = gdt_flip_to_delaunay(NULL, &fs, &m, frozen, &err);
    CHECK(t, s == GDT_OK, "%s: GDT-%04d %s", label, err.code, err.msg);
    size_t moved = 0;
    for (size_t k = 0; k < m.ntris; k++)
        if (frozen[k] && memcmp(saved + 3 * k, m.tri + 3 * k, 3 * sizeof *saved) != 0)
            moved++;
    CHECK(t, moved == 0, "%s: %zu of %zu frozen triangles changed", label, moved, nfrozen);
    CHECK(t, gdt_check_mesh(NULL, &m, &err) == GDT_OK, "%s: result invalid: %s", label, err.msg);
    size_t bad = 0;
    for (size_t k = 0; k < m.ntris; k++)
        for (int i = 0; i < 3; i++) {
            int32_t o = m.opp[3 * k + (size_t)i];
            if (o == GDT_MESH_NONE || frozen[k] || frozen[gdt_opp_tri(o)])
                continue;
            const int32_t *T = m.tri + 3 * k;
            bad += (size_t)gdt_edge_needs_flip(
                NULL, m.pts[T[mesh_next(i)]], m.pts[T[mesh_prev(i)]], m.pts[T[i]],
                m.pts[m.tri[3 * (size_t)gdt_opp_tri(o) + (size_t)gdt_opp_slot(o)]]);
        }
    CHECK(t, bad == 0, "%s: %zu unfrozen edges not locally optimal", label, bad);
    if (exact_answer)
        CHECK(t, gen_same_triangles(&ref, &m, why, sizeof why) == 0, "%s: %s", label, why);
    CHECK(t, nfrozen > 0 && nfrozen < m.ntris, "%s: %zu of %zu frozen", label, nfrozen, m.ntris);

done:
    free(frozen);
    free(saved);
    gdt_mesh_free(&m);
    gdt_mesh_free(&ref);
}

int main(void)
{
    tctx t = {0, 0};
    gen_rng r;
    size_t n;
    gdt_ipt *p;
    const int64_t mid = 1 << 30;

    gen_seed(&r, 11);
    p = gen_uniform(&r, 100000, 0, GDT_COORD_MAX, &n);
    from_bad(&t, "uniform 1e5", p, n, 1, 1);
    from_bad(&t, "uniform 1e5", p, n, 0, 1);
    free(p);

    p = gen_uniform(&r, 20000, 0, 200, &n);
    from_bad(&t, "dense 201x201 sample", p, n, 1, 1);
    from_bad(&t, "dense 201x201 sample", p, n, 0, 1);
    free(p);
    p = gen_grid(60, 45, 7, 9, 3, &n);
    from_bad(&t, "grid 60x45", p, n, 1, 0);
    from_bad(&t, "grid 60x45", p, n, 0, 0);
    free(p);
    p = gen_rotated_grid(20, 3, 4, mid, mid, &n);
    from_bad(&t, "rotated grid", p, n, 1, 0);
    from_bad(&t, "rotated grid", p, n, 0, 0);
    free(p);
    p = gen_circle(mid, mid, 5525, &n);
    from_bad(&t, "circle", p, n, 1, 0);
    from_bad(&t, "circle", p, n, 0, 0);
    free(p);
    p = gen_extremes(&r, &n);
    from_bad(&t, "extremes", p, n, 1, 0);
    from_bad(&t, "extremes", p, n, 0, 0);
    free(p);
    p = gen_thin_circle(&r, 2000, mid, mid, 100000, 1, &n);
    from_bad(&t, "thin circle", p, n, 1, 0);
    from_bad(&t, "thin circle", p, n, 0, 0);
    free(p);

    wrong_grid(&t, 2);
    wrong_grid(&t, 50);

    p = gen_uniform(&r, 20000, 0, GDT_COORD_MAX, &n);
    frozen_case(&t, &r, "frozen, general position", p, n, mid, 1);
    free(p);
    p = gen_grid(70, 70, 0, 0, 1, &n);
    frozen_case(&t, &r, "frozen, grid", p, n, 35, 0);
    free(p);
    p = gen_uniform(&r, 5000, 0, 100, &n);
    frozen_case(&t, &r, "frozen, dense sample", p, n, 50, 0);
    free(p);
    return gen_finish(&t, "test_flip");
}
