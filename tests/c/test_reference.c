/* test_reference — the CPU reference triangulator on the degenerate corpus.
 *
 *   test_reference            the corpus (seconds)
 *   test_reference --big N    N uniform points over the whole tile range,
 *                             timed and fully verified
 *
 * For every set: gdt_check_mesh and gdt_check_delaunay pass; on small sets
 * no point lies strictly inside any circumcircle (brute force); the output
 * does not depend on the input order (canonical triangle sets of shuffled
 * inputs are equal); on axis-aligned grids every cell is split by its (1,1)
 * diagonal; on points of one circle the result equals the paper's
 * polygon triangulation T_{d1,d2}(P) built by inserting diagonals in order
 * of their score (Dyken & Floater, section 3), an independent construction.
 * Preconditions are enforced: duplicates (7341) and coordinates out of
 * range (7340) are refused.
 */
#include <inttypes.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "gdt_reference.h"
#include "gen_degenerate.h"

static double clock_s(clockid_t id)
{
    struct timespec ts;
    clock_gettime(id, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static double now_s(void)
{
    return clock_s(CLOCK_MONOTONIC);
}

/* Triangulates pts, verifies, and (perms > 0) compares against shuffled
 * copies.  Returns the number of triangles, or (size_t)-1 on failure. */
static size_t run_case(tctx *t, const char *label, const gdt_ipt *pts, size_t n, gen_rng *r,
                       int perms, int brute, gdt_mesh *keep)
{
    gdt_mesh m, q;
    gdt_error err;
    gdt_reference_stats rs;
    size_t ntris = (size_t)-1;
    gdt_ipt *sh = NULL;
    int64_t *perm = NULL;
    char why[512];

    gdt_mesh_init(&m);
    gdt_mesh_init(&q);
    gdt_error_clear(&err);
    memset(&rs, 0, sizeof rs);
    gdt_status s = gdt_reference_triangulate(&rs, pts, n, &m, &err);
    CHECK(t, s == GDT_OK, "%s (%zu points): GDT-%04d %s", label, n, err.code, err.msg);
    if (s != GDT_OK)
        goto done;
    CHECK(t, m.nverts == n && (n == 0 || memcmp(m.pts, pts, n * sizeof *pts) == 0),
          "%s: output vertices are not the input points", label);
    if (gen_check_all(t, &m, label) != 0)
        goto done;
    if (brute) {
        CHECK(t, gen_brute_empty_circles(&m, why, sizeof why) == 0, "%s: %s", label, why);
    }
    sh = malloc((n > 0 ? n : 1) * sizeof *sh);
    perm = malloc((n > 0 ? n : 1) * sizeof *perm);
    if (sh == NULL || perm == NULL) {
        CHECK(t, 0, "%s: out of memory", label);
        goto done;
    }
    for (int k = 0; k < perms; k++) {
        if (n > 0)
            memcpy(sh, pts, n * sizeof *pts);
        gen_shuffle(r, sh, n, perm);
        s = gdt_reference_triangulate(NULL, sh, n, &q, &err);
        CHECK(t, s == GDT_OK, "%s shuffled: GDT-%04d %s", label, err.code, err.msg);
        if (s != GDT_OK)
            goto done;
        s = gdt_mesh_reserve(&q, n, 0, 1, &err);
        CHECK(t, s == GDT_OK, "%s: GDT-%04d %s", label, err.code, err.msg);
        if (s != GDT_OK)
            goto done;
        memcpy(q.ids, perm, n * sizeof *perm);
        CHECK(t, gen_same_triangles(&m, &q, why, sizeof why) == 0,
              "%s: shuffled input %d gives another triangulation: %s", label, k, why);
    }
    ntris = m.ntris;
    if (keep != NULL) {
        *keep = m;
        gdt_mesh_init(&m);
    }

done:
    free(sh);
    free(perm);
    gdt_mesh_free(&m);
    gdt_mesh_free(&q);
    return ntris;
}

/* Every triangle of an axis-aligned grid mesh is half a cell cut by its
 * (1,1) diagonal: exactly one edge with |dx| = |dy|, and there dx = dy. */
static void check_grid_diagonals(tctx *t, const gdt_mesh *m, const char *label)
{
    for (size_t k = 0; k < m->ntris; k++) {
        int diag = 0, good = 0;
        for (int i = 0; i < 3; i++) {
            gdt_ipt a = m->pts[m->tri[3 * k + (size_t)i]];
            gdt_ipt b = m->pts[m->tri[3 * k + (size_t)((i + 1) % 3)]];
            int64_t dx = b.x - a.x, dy = b.y - a.y;
            if (dx != 0 && (dx == dy || dx == -dy)) {
                diag++;
                good += dx == dy;
            }
        }
        if (diag != 1 || good != 1) {
            CHECK(t, 0, "%s: triangle %zu is not a (1,1) half cell", label, k);
            return;
        }
    }
}

static void grid_cases(tctx *t, gen_rng *r)
{
    static const struct {
        size_t nx, ny;
        int64_t x0, y0, step;
    } g[] = {
        {2, 2, 0, 0, 1},
        {40, 40, 0, 0, 1},
        {31, 17, 1000, 5000, 3},
        {30, 20, GDT_COORD_MAX - 29 * 7, GDT_COORD_MAX - 19 * 7, 7},
        {12, 12, 0, GDT_COORD_MAX - 11 * 195225786, 195225786},
    };
    for (size_t k = 0; k < sizeof g / sizeof g[0]; k++) {
        size_t n;
        char label[64];
        gdt_mesh m;
        gdt_ipt *p = gen_grid(g[k].nx, g[k].ny, g[k].x0, g[k].y0, g[k].step, &n);
        snprintf(label, sizeof label, "grid %zux%zu step %" PRId64, g[k].nx, g[k].ny, g[k].step);
        size_t f = run_case(t, label, p, n, r, 2, n <= 400, &m);
        CHECK(t, f == 2 * (g[k].nx - 1) * (g[k].ny - 1), "%s: %zu triangles", label, f);
        if (f != (size_t)-1) {
            check_grid_diagonals(t, &m, label);
            gdt_mesh_free(&m);
        }
        free(p);
    }
}

/* ---- independent T_{d1,d2}(P) of a strictly convex polygon ---- */

typedef struct chord {
    int32_t i, j;       /* positions along the polygon */
    const gdt_ipt *pts; /* polygon vertices in counter-clockwise order */
} chord;

static int chord_score_cmp(const void *x, const void *y)
{
    const chord *a = x, *b = y;
    gdt_ipt e = {a->pts[a->j].x - a->pts[a->i].x, a->pts[a->j].y - a->pts[a->i].y};
    gdt_ipt f = {b->pts[b->j].x - b->pts[b->i].x, b->pts[b->j].y - b->pts[b->i].y};
    return -gdt_prefer_diagonal(NULL, e, f);
}

static int between(int32_t a, int32_t x, int32_t b)
{
    return a < x && x < b;
}

static int chords_cross(const chord *a, const chord *b)
{
    if (a->i == b->i || a->i == b->j || a->j == b->i || a->j == b->j)
        return 0;
    return between(a->i, b->i, a->j) != between(a->i, b->j, a->j);
}

static const gdt_ipt *g_centre;

static int angle_cmp(const void *x, const void *y)
{
    const gdt_ipt *a = x, *b = y;
    int ua = a->y > g_centre->y || (a->y == g_centre->y && a->x > g_centre->x);
    int ub = b->y > g_centre->y || (b->y == g_centre->y && b->x > g_centre->x);
    if (ua != ub)
        return ua ? -1 : 1;
    return -gdt_orient2d(NULL, *g_centre, *a, *b);
}

/* Points of one circle around the lattice point c: the reference equals the
 * greedy insertion of non-crossing diagonals by increasing score. */
static void circle_case(tctx *t, gen_rng *r, int64_t cx, int64_t cy, int64_t radius)
{
    size_t n;
    char label[96];
    gdt_mesh m;
    gdt_ipt c = {cx, cy};
    gdt_ipt *p = gen_circle(cx, cy, radius, &n);
    chord *all = NULL, *in = NULL;

    snprintf(label, sizeof label, "circle r=%" PRId64 " (%zu points)", radius, n);
    gen_shuffle(r, p, n, NULL);
    size_t f = run_case(t, label, p, n, r, 2, n <= 200, &m);
    CHECK(t, f == n - 2, "%s: %zu triangles", label, f);
    if (f == (size_t)-1)
        goto done;
    /* Sort the polygon counter-clockwise, then build the greedy triangulation. */
    g_centre = &c;
    qsort(p, n, sizeof *p, angle_cmp);
    all = malloc(n * n / 2 * sizeof *all);
    in = malloc(n * sizeof *in);
    size_t na = 0, ni = 0;
    for (int32_t i = 0; i < (int32_t)n; i++)
        for (int32_t j = i + 2; j < (int32_t)n; j++)
            if (!(i == 0 && j == (int32_t)n - 1))
                all[na++] = (chord){i, j, p};
    qsort(all, na, sizeof *all, chord_score_cmp);
    for (size_t k = 0; k < na; k++) {
        size_t q = 0;
        while (q < ni && !chords_cross(&all[k], &in[q]))
            q++;
        if (q == ni)
            in[ni++] = all[k];
    }
    CHECK(t, ni == n - 3, "%s: greedy polygon triangulation has %zu diagonals", label, ni);
    /* Every greedy diagonal is an edge of the reference mesh. */
    size_t found = 0;
    for (size_t k = 0; k < ni; k++) {
        gdt_ipt a = p[in[k].i], b = p[in[k].j];
        int hit = 0;
        for (size_t tt = 0; tt < m.ntris && !hit; tt++)
            for (int s = 0; s < 3; s++) {
                gdt_ipt u = m.pts[m.tri[3 * tt + (size_t)s]];
                gdt_ipt v = m.pts[m.tri[3 * tt + (size_t)((s + 1) % 3)]];
                if ((u.x == a.x && u.y == a.y && v.x == b.x && v.y == b.y) ||
                    (u.x == b.x && u.y == b.y && v.x == a.x && v.y == a.y))
                    hit = 1;
            }
        found += (size_t)hit;
    }
    CHECK(t, found == n - 3, "%s: only %zu of the %zu diagonals of T_{d1,d2}(P) are edges", label,
          found, n - 3);
    gdt_mesh_free(&m);

done:
    free(all);
    free(in);
    free(p);
}

static void tiny_cases(tctx *t, gen_rng *r)
{
    const int64_t M = GDT_COORD_MAX;
    gdt_ipt p[4] = {{0, 0}, {M, 0}, {0, M}, {M, M}};
    gdt_mesh m;
    size_t f;

    CHECK(t, run_case(t, "0 points", p, 0, r, 1, 1, NULL) == 0, "0 points");
    CHECK(t, run_case(t, "1 point", p, 1, r, 1, 1, NULL) == 0, "1 point");
    CHECK(t, run_case(t, "2 points", p, 2, r, 1, 1, NULL) == 0, "2 points");
    f = run_case(t, "3 points ccw", p, 3, r, 2, 1, &m);
    CHECK(t, f == 1, "3 points: %zu triangles", f);
    if (f == 1) {
        gdt_mesh_free(&m);
    }
    gdt_ipt cw[3] = {{5, 5}, {5, 9}, {9, 5}};
    CHECK(t, run_case(t, "3 points cw", cw, 3, r, 2, 1, NULL) == 1, "3 points cw");
    gdt_ipt col[3] = {{0, 0}, {2, 2}, {1, 1}};
    CHECK(t, run_case(t, "3 collinear", col, 3, r, 2, 1, NULL) == 0, "3 collinear");
    f = run_case(t, "4 corners", p, 4, r, 3, 1, &m);
    CHECK(t, f == 2, "4 corners: %zu triangles", f);
    if (f == 2) {
        check_grid_diagonals(t, &m, "4 corners");
        gdt_mesh_free(&m);
    }
    /* Collinear points plus one apex: a fan of n-1 triangles, all line
     * points on the hull. */
    size_t n;
    gdt_ipt *l = gen_collinear(r, 60, 10, 20, 3, 5, 1000, &n);
    gdt_ipt *l2 = realloc(l, (n + 1) * sizeof *l);
    if (l2 != NULL) {
        l = l2;
        l[n].x = 5000, l[n].y = 10;
        f = run_case(t, "collinear + apex", l, n + 1, r, 2, 1, NULL);
        CHECK(t, f == n - 1, "collinear + apex: %zu triangles for %zu line points", f, n);
    }
    free(l);
}

static void collinear_cases(tctx *t, gen_rng *r)
{
    static const int64_t dir[][2] = {{1, 0}, {0, 1}, {3, 5}, {7, -2}, {1, 1}};
    for (size_t k = 0; k < sizeof dir / sizeof dir[0]; k++) {
        size_t n;
        char label[64];
        int64_t y0 = dir[k][1] < 0 ? 1 << 20 : 0;
        gdt_ipt *p = gen_collinear(r, 500, 0, y0, dir[k][0], dir[k][1], 100000, &n);
        snprintf(label, sizeof label, "collinear (%" PRId64 ", %" PRId64 ")", dir[k][0], dir[k][1]);
        CHECK(t, run_case(t, label, p, n, r, 1, 0, NULL) == 0, "%s gives triangles", label);
        free(p);
    }
}

static void refusal_cases(tctx *t, gen_rng *r)
{
    gdt_mesh m;
    gdt_error err;
    size_t n;
    gdt_mesh_init(&m);

    gdt_ipt *p = gen_with_duplicates(r, 5, 200, 77, 88, &n);
    gdt_error_clear(&err);
    gdt_status s = gdt_reference_triangulate(NULL, p, n, &m, &err);
    CHECK(t, s == GDT_EINTERNAL && err.code == 7341 && strstr(err.msg, "(77, 88)") != NULL,
          "duplicates: status %d GDT-%04d %s", (int)s, err.code, err.msg);
    gen_dedup(p, &n);
    CHECK(t, run_case(t, "duplicates removed", p, n, r, 1, 1, NULL) != (size_t)-1,
          "deduplicated set fails");
    free(p);

    /* All points equal, and equal points on a line. */
    gdt_ipt same[3] = {{4, 4}, {4, 4}, {4, 4}};
    gdt_error_clear(&err);
    s = gdt_reference_triangulate(NULL, same, 3, &m, &err);
    CHECK(t, s == GDT_EINTERNAL && err.code == 7341, "3 equal points: GDT-%04d", err.code);
    gdt_error_clear(&err);
    s = gdt_reference_triangulate(NULL, same, 2, &m, &err);
    CHECK(t, s == GDT_EINTERNAL && err.code == 7341, "2 equal points: GDT-%04d", err.code);
    gdt_ipt line[4] = {{1, 1}, {2, 2}, {3, 3}, {2, 2}};
    gdt_error_clear(&err);
    s = gdt_reference_triangulate(NULL, line, 4, &m, &err);
    CHECK(t, s == GDT_EINTERNAL && err.code == 7341 && strstr(err.msg, "input 1 and input 3"),
          "collinear duplicates: GDT-%04d %s", err.code, err.msg);

    gdt_ipt bad[3] = {{0, 0}, {5, 0}, {-1, 5}};
    gdt_error_clear(&err);
    s = gdt_reference_triangulate(NULL, bad, 3, &m, &err);
    CHECK(t, s == GDT_EINTERNAL && err.code == 7340 && strstr(err.msg, "point 2"),
          "negative coordinate: GDT-%04d %s", err.code, err.msg);
    bad[2].x = GDT_COORD_MAX + 1;
    gdt_error_clear(&err);
    s = gdt_reference_triangulate(NULL, bad, 3, &m, &err);
    CHECK(t, s == GDT_EINTERNAL && err.code == 7340, "coordinate 2^31: GDT-%04d", err.code);
    gdt_mesh_free(&m);
}

static void corpus(tctx *t, gen_rng *r)
{
    size_t n;
    gdt_ipt *p;
    const int64_t mid = 1 << 30;

    tiny_cases(t, r);
    grid_cases(t, r);
    collinear_cases(t, r);
    refusal_cases(t, r);

    /* Rotated integer grids: co-circular quads in every direction. */
    static const int64_t rot[][3] = {{15, 3, 4}, {20, 1, 2}, {8, 5, 12}, {25, 2, 1}};
    for (size_t k = 0; k < sizeof rot / sizeof rot[0]; k++) {
        char label[64];
        p = gen_rotated_grid(rot[k][0], rot[k][1], rot[k][2], mid, mid, &n);
        snprintf(label, sizeof label, "rotated grid (%" PRId64 ", %" PRId64 ")", rot[k][1],
                 rot[k][2]);
        run_case(t, label, p, n, r, 2, n <= 1000, NULL);
        free(p);
    }
    p = gen_rotated_grid(12, 3, 4, 0, 0, &n); /* clipped at the origin corner */
    run_case(t, "rotated grid at the origin", p, n, r, 2, 1, NULL);
    free(p);

    /* Points of one circle: 5^3 13 has 84 lattice points, 5^2 13 17 has 180. */
    circle_case(t, r, mid, mid, 1625);
    circle_case(t, r, 5525, 5525, 5525);
    circle_case(t, r, GDT_COORD_MAX - 1625, 1625, 1625);
    {
        p = gen_circle(mid, mid, 1625, &n);
        gdt_ipt *p2 = realloc(p, (n + 1) * sizeof *p);
        if (p2 != NULL) {
            p = p2;
            p[n].x = mid, p[n].y = mid;
            size_t f = run_case(t, "circle + centre", p, n + 1, r, 2, 1, NULL);
            CHECK(t, f == n, "circle + centre: %zu triangles for %zu circle points", f, n);
        }
        free(p);
    }
    p = gen_thin_circle(r, 3000, mid, mid, 1000000, 2, &n);
    run_case(t, "thin circle", p, n, r, 2, 0, NULL);
    free(p);
    p = gen_thin_circle(r, 600, 3000, 3000, 2900, 1, &n);
    run_case(t, "thin small circle", p, n, r, 2, 1, NULL);
    free(p);

    p = gen_clusters(r, 20, 400, 40, &n);
    run_case(t, "clusters", p, n, r, 2, 0, NULL);
    free(p);
    p = gen_clusters(r, 3, 150, 6, &n);
    run_case(t, "tight clusters", p, n, r, 2, 1, NULL);
    free(p);

    p = gen_extremes(r, &n);
    run_case(t, "extremes", p, n, r, 4, 1, NULL);
    free(p);

    p = gen_uniform(r, 1200, 0, 40, &n); /* dense: collinear and co-circular */
    run_case(t, "dense 41x41 sample", p, n, r, 3, 1, NULL);
    free(p);
    p = gen_uniform(r, 20000, 0, 300, &n);
    run_case(t, "dense 301x301 sample", p, n, r, 2, 0, NULL);
    free(p);
    p = gen_uniform(r, 800, 0, GDT_COORD_MAX, &n);
    run_case(t, "uniform small", p, n, r, 2, 1, NULL);
    free(p);
    p = gen_uniform(r, 50000, 0, GDT_COORD_MAX, &n);
    run_case(t, "uniform 50k", p, n, r, 1, 0, NULL);
    free(p);
}

static int big(tctx *t, size_t want)
{
    gen_rng r;
    size_t n;
    gdt_mesh m;
    gdt_error err;
    gdt_reference_stats rs;

    gen_seed(&r, 20240601);
    gdt_ipt *p = gen_uniform(&r, want, 0, GDT_COORD_MAX, &n);
    gdt_mesh_init(&m);
    gdt_error_clear(&err);
    memset(&rs, 0, sizeof rs);
    double c0 = clock_s(CLOCK_PROCESS_CPUTIME_ID), t0 = now_s();
    gdt_status s = gdt_reference_triangulate(&rs, p, n, &m, &err);
    double t1 = now_s(), c1 = clock_s(CLOCK_PROCESS_CPUTIME_ID);
    CHECK(t, s == GDT_OK, "big: GDT-%04d %s", err.code, err.msg);
    if (s == GDT_OK) {
        printf("reference: %zu points, %zu triangles in %.3f s CPU, %.3f s wall (%.0f "
               "points per CPU second); walk steps %.2f/point, insertion flips %.2f/point, "
               "closing pass %" PRIu64 " tests / %" PRIu64 " flips; incircle exact %" PRIu64
               " of %" PRIu64 "\n",
               n, m.ntris, c1 - c0, t1 - t0, (double)n / (c1 - c0),
               (double)rs.walk_steps / (double)n, (double)rs.insert_flips / (double)n,
               rs.final.edges_tested, rs.final.flips, rs.pred.incircle_exact,
               rs.pred.incircle_calls);
        double t2 = now_s();
        gen_check_all(t, &m, "big");
        printf("checks: %.3f s\n", now_s() - t2);
    }
    gdt_mesh_free(&m);
    free(p);
    return gen_finish(t, "test_reference --big");
}

int main(int argc, char **argv)
{
    tctx t = {0, 0};
    gen_rng r;

    if (argc == 3 && strcmp(argv[1], "--big") == 0)
        return big(&t, (size_t)strtoull(argv[2], NULL, 10));
    if (argc != 1) {
        fprintf(stderr, "usage: test_reference [--big N]\n");
        return 2;
    }
    gen_seed(&r, 7);
    corpus(&t, &r);
    return gen_finish(&t, "test_reference");
}
