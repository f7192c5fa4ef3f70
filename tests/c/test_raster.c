/* The DEM grid and the rasteriser (core/gdt_raster.h), and the streaming
 * DEM writer (io/gdt_dem.h):
 *   - the half-lattice predicates: gdt_edge_owned_range equals the
 *     cell-by-cell gdt_edge_owns_half at small and at huge coordinates;
 *   - every cell centre of random triangulations (points on a coarse
 *     lattice, cells of 1, 2 and 3 steps, so that centres fall on vertices
 *     and edges) belongs to exactly one face when it lies inside the hull
 *     (closed), to none outside, to at most one on the hull; whatever the
 *     face order, rotation and orientation, with the same value bits;
 *   - values: a plane z = 3x - 2y + 5 is reproduced at every centre;
 *   - faces of a dense cloud: the fast cell bounds and the small-face path
 *     make the same sink calls as the general path, at fine and coarse
 *     cell sizes, in either orientation;
 *   - vertices near 2^52 lattice steps: no overflow (UBSan in the sanitizer
 *     tree), the same coverage;
 *   - the grid rule: aligned corners, refused cell sizes, the default size;
 *   - the writer: a two-block cache (every block spilled and reloaded)
 *     writes the same bytes as a cache holding everything, for writes in
 *     shuffled order; a cell written twice is an error; abort leaves no
 *     file.
 * usage: test_raster WORKDIR */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include <gdal.h>

#include "gdt_check.h"
#include "gdt_dem.h"
#include "gdt_mesh.h"
#include "gdt_raster.h"
#include "gdt_reference.h"

static gdt_checks C;

/* ---- edge ranges against the point-by-point rule ---------------------- */

static int64_t rnd_in(uint64_t *s, int64_t lo, int64_t hi)
{
    return lo + (int64_t)(gdt_splitmix64(s) % (uint64_t)(hi - lo + 1));
}

static void test_edge_ranges(void)
{
    uint64_t s = 11;
    for (int t = 0; t < 20000; t++) {
        int64_t span = t % 2 ? 40 : (INT64_C(1) << 58);
        int64_t base = t % 3 == 0 ? 0 : (t % 3 == 1 ? -(INT64_C(1) << 59) : (INT64_C(1) << 58));
        gdt_hpt u = {base + rnd_in(&s, 0, span), base + rnd_in(&s, 0, span)};
        gdt_hpt v = {base + rnd_in(&s, 0, span), base + rnd_in(&s, 0, span)};
        int64_t dx = t % 2 ? rnd_in(&s, 1, 5) : rnd_in(&s, 1, span / 64);
        int64_t x0 = base + rnd_in(&s, -span / 8, span / 2);
        int64_t y = t % 5 == 0 ? u.y : base + rnd_in(&s, 0, span);
        int64_t lo = 0, hi = 40, blo = 1, bhi = 0;
        if (t % 7 == 0)
            v.y = u.y;
        if (t % 11 == 0)
            v.x = u.x;
        if (u.x == v.x && u.y == v.y)
            continue;
        gdt_edge_owned_range(NULL, u, v, x0, dx, y, &lo, &hi);
        for (int64_t k = 0; k <= 40; k++) {
            gdt_hpt p = {x0 + k * dx, y};
            if (gdt_edge_owns_half(NULL, u, v, p)) {
                if (blo > bhi)
                    blo = bhi = k;
                GDT_CHECK_QUIET_AFTER(&C, 10, k == bhi || k == bhi + 1,
                                      "owned columns not an interval (edge %d)", t);
                bhi = k;
            }
        }
        GDT_CHECK_QUIET_AFTER(&C, 10, (lo > hi && blo > bhi) || (lo == blo && hi == bhi),
                              "edge %d: range [%lld, %lld], point by point [%lld, %lld]", t,
                              (long long)lo, (long long)hi, (long long)blo, (long long)bhi);
    }
    /* exactly one of the two directions owns a point on the line */
    for (int t = 0; t < 2000; t++) {
        gdt_hpt u = {rnd_in(&s, -9, 9), rnd_in(&s, -9, 9)}, v = {rnd_in(&s, -9, 9), rnd_in(&s, -9, 9)};
        gdt_hpt p = {2 * u.x - v.x, 2 * u.y - v.y}; /* on the line */
        if (u.x == v.x && u.y == v.y)
            continue;
        GDT_CHECK(&C, gdt_edge_owns_half(NULL, u, v, p) + gdt_edge_owns_half(NULL, v, u, p) == 1,
                  "edge (%lld,%lld)-(%lld,%lld)", (long long)u.x, (long long)u.y,
                  (long long)v.x, (long long)v.y);
    }
}

/* ---- coverage of random triangulations -------------------------------- */

typedef struct cover {
    int64_t ncols, nrows;
    int *count;
    float *val;
} cover;

static gdt_status count_sink(void *ctx, int64_t row, int64_t col, int64_t n, const float *z,
                             gdt_error *err)
{
    cover *cv = ctx;
    (void)err;
    for (int64_t k = 0; k < n; k++) {
        size_t i = (size_t)(row * cv->ncols + col + k);
        cv->count[i]++;
        cv->val[i] = z[k];
    }
    return GDT_OK;
}

/* Whether p (doubled) lies in the closed triangle (a, b, c) counter-clockwise. */
static int closed_in(gdt_hpt a, gdt_hpt b, gdt_hpt c, gdt_hpt p)
{
    return gdt_orient2d_half_det(NULL, a, b, p) >= 0 && gdt_orient2d_half_det(NULL, b, c, p) >= 0 &&
           gdt_orient2d_half_det(NULL, c, a, p) >= 0;
}

/* On the closed segment a-b (doubled). */
static int on_segment(gdt_hpt a, gdt_hpt b, gdt_hpt p)
{
    if (gdt_orient2d_half_det(NULL, a, b, p) != 0)
        return 0;
    return p.x >= (a.x < b.x ? a.x : b.x) && p.x <= (a.x > b.x ? a.x : b.x) &&
           p.y >= (a.y < b.y ? a.y : b.y) && p.y <= (a.y > b.y ? a.y : b.y);
}

static gdt_hpt dbl(const gdt_point *p)
{
    gdt_hpt h = {2 * p->x, 2 * p->y};
    return h;
}

static void rasterise_all(const gdt_raster_grid *g, const gdt_point *pts, const gdt_mesh *m,
                          const size_t *order, int variant, cover *cv)
{
    gdt_error err;
    gdt_error_clear(&err);
    memset(cv->count, 0, (size_t)(cv->ncols * cv->nrows) * sizeof *cv->count);
    for (size_t i = 0; i < m->ntris; i++) {
        size_t f = order[i];
        gdt_raster_vertex v[3];
        for (int k = 0; k < 3; k++) {
            /* variant 1: rotated; variant 2: clockwise */
            int slot = variant == 0 ? k : variant == 1 ? (k + 1 + (int)(f % 2)) % 3 : (3 - k) % 3;
            const gdt_point *p = &pts[m->tri[3 * f + (size_t)slot]];
            v[k].x = p->x;
            v[k].y = p->y;
            v[k].z = p->z;
        }
        GDT_CHECK(&C, gdt_raster_triangle(g, NULL, v, count_sink, cv, &err) == GDT_OK, "%s",
                  err.msg);
    }
}

static void test_coverage(int64_t grid_span, int64_t base, int64_t m, int npts, uint64_t seed,
                          int plane)
{
    gdt_point *pts = calloc((size_t)npts, sizeof *pts);
    gdt_ipt *loc = calloc((size_t)npts, sizeof *loc);
    size_t *order;
    gdt_mesh mesh;
    gdt_raster_grid g;
    gdt_lattice lat = {0.5, 0.5, 0.0, 0.0};
    gdt_error err;
    cover cv, cv2;
    int64_t minx = INT64_MAX, miny = INT64_MAX, maxx = INT64_MIN, maxy = INT64_MIN;
    int n = 0;
    uint64_t s = seed;

    gdt_error_clear(&err);
    gdt_mesh_init(&mesh);
    /* distinct points of a coarse lattice (many collinear and co-circular) */
    while (n < npts) {
        int64_t x = rnd_in(&s, 0, grid_span), y = rnd_in(&s, 0, grid_span);
        int dup = 0;
        for (int i = 0; i < n && !dup; i++)
            dup = loc[i].x == x && loc[i].y == y;
        if (dup)
            continue;
        loc[n].x = x;
        loc[n].y = y;
        pts[n].x = base + x;
        pts[n].y = base + y;
        pts[n].z = plane ? 3.0 * (double)x - 2.0 * (double)y + 5.0
                         : (double)(gdt_splitmix64(&s) % 100000) / 7.0;
        if (pts[n].x < minx) minx = pts[n].x;
        if (pts[n].x > maxx) maxx = pts[n].x;
        if (pts[n].y < miny) miny = pts[n].y;
        if (pts[n].y > maxy) maxy = pts[n].y;
        n++;
    }
    GDT_CHECK(&C, gdt_reference_triangulate(NULL, loc, (size_t)n, &mesh, &err) == GDT_OK, "%s",
              err.msg);
    GDT_CHECK(&C, gdt_raster_grid_define(&g, &lat, minx, miny, maxx, maxy, (size_t)n,
                                         0.5 * (double)m, "--dem-res", &err) == GDT_OK,
              "%s", err.msg);
    cv.ncols = cv2.ncols = g.geo.ncols;
    cv.nrows = cv2.nrows = g.geo.nrows;
    cv.count = calloc((size_t)(cv.ncols * cv.nrows), sizeof *cv.count);
    cv.val = calloc((size_t)(cv.ncols * cv.nrows), sizeof *cv.val);
    cv2.count = calloc((size_t)(cv.ncols * cv.nrows), sizeof *cv.count);
    cv2.val = calloc((size_t)(cv.ncols * cv.nrows), sizeof *cv.val);
    order = malloc((mesh.ntris + 1) * sizeof *order);
    for (size_t i = 0; i < mesh.ntris; i++)
        order[i] = i;
    rasterise_all(&g, pts, &mesh, order, 0, &cv);

    for (int64_t r = 0; r < g.geo.nrows; r++)
        for (int64_t c = 0; c < g.geo.ncols; c++) {
            gdt_hpt p = gdt_raster_centre(&g, r, c);
            int closed = 0, on_hull = 0;
            size_t i = (size_t)(r * g.geo.ncols + c);
            for (size_t f = 0; f < mesh.ntris; f++) {
                gdt_hpt a = dbl(&pts[mesh.tri[3 * f]]), b = dbl(&pts[mesh.tri[3 * f + 1]]),
                        cc = dbl(&pts[mesh.tri[3 * f + 2]]);
                closed += closed_in(a, b, cc, p);
                for (int k = 0; k < 3; k++)
                    if (mesh.opp[3 * f + (size_t)k] == GDT_MESH_NONE) {
                        gdt_hpt e0 = dbl(&pts[mesh.tri[3 * f + (size_t)(k + 1) % 3]]);
                        gdt_hpt e1 = dbl(&pts[mesh.tri[3 * f + (size_t)(k + 2) % 3]]);
                        on_hull |= on_segment(e0, e1, p);
                    }
            }
            if (on_hull)
                GDT_CHECK_QUIET_AFTER(&C, 10, cv.count[i] <= 1, "hull centre (%lld, %lld): %d owners",
                                      (long long)r, (long long)c, cv.count[i]);
            else
                GDT_CHECK_QUIET_AFTER(&C, 10, cv.count[i] == (closed > 0),
                                      "centre (%lld, %lld) m=%lld: %d owners, in %d closed faces",
                                      (long long)r, (long long)c, (long long)m, cv.count[i],
                                      closed);
            if (plane && cv.count[i] == 1) {
                double x = (double)(p.x - 2 * base) / 2.0, y = (double)(p.y - 2 * base) / 2.0;
                float want = (float)(3.0 * x - 2.0 * y + 5.0);
                GDT_CHECK_QUIET_AFTER(&C, 10, fabsf(cv.val[i] - want) <= 1e-6f * (fabsf(want) + 1.0f),
                                      "plane at (%g, %g): %.9g, want %.9g", x, y, cv.val[i],
                                      want);
            }
        }
    /* the same owners and value bits in any order, rotation, orientation */
    for (int variant = 0; variant < 3; variant++) {
        for (size_t i = mesh.ntris; i > 1; i--) {
            size_t j = (size_t)(gdt_splitmix64(&s) % i), t = order[i - 1];
            order[i - 1] = order[j];
            order[j] = t;
        }
        rasterise_all(&g, pts, &mesh, order, variant, &cv2);
        GDT_CHECK(&C, memcmp(cv.count, cv2.count, (size_t)(cv.ncols * cv.nrows) * sizeof *cv.count) == 0,
                  "variant %d: other owners", variant);
        for (size_t i = 0; i < (size_t)(cv.ncols * cv.nrows); i++)
            if (cv.count[i] == 1)
                GDT_CHECK_QUIET_AFTER(&C, 5, memcmp(&cv.val[i], &cv2.val[i], sizeof(float)) == 0,
                                      "variant %d: cell %zu value %.9g vs %.9g", variant, i,
                                      cv.val[i], cv2.val[i]);
    }
    /* the cell ranges from the exact multiply-high quotients and from the
     * generic division are the same */
    {
        gdt_raster_grid g0 = g;
        g0.mag_dx = g0.mag_dy = 0;
        g0.fast = 0;
        for (size_t i = 0; i < mesh.ntris; i++)
            order[i] = i;
        rasterise_all(&g0, pts, &mesh, order, 0, &cv2);
        GDT_CHECK(&C, memcmp(cv.count, cv2.count, (size_t)(cv.ncols * cv.nrows) * sizeof *cv.count) == 0,
                  "without the multiply-high quotients: other owners");
        GDT_CHECK(&C, memcmp(cv.val, cv2.val, (size_t)(cv.ncols * cv.nrows) * sizeof *cv.val) == 0,
                  "without the multiply-high quotients: other values");
    }
    free(order);
    free(cv.count);
    free(cv.val);
    free(cv2.count);
    free(cv2.val);
    gdt_mesh_free(&mesh);
    free(pts);
    free(loc);
}

/* The sink calls of a rasterisation, in order: an FNV-1a hash of every
 * (row, col, n, value bits) and their count. */
typedef struct trace {
    uint64_t hash, calls, cells;
} trace;

static void trace_u64(trace *t, uint64_t v)
{
    for (int i = 0; i < 8; i++)
        t->hash = (t->hash ^ ((v >> (8 * i)) & 0xffu)) * UINT64_C(0x100000001b3);
}

static gdt_status trace_sink(void *ctx, int64_t row, int64_t col, int64_t n, const float *z,
                             gdt_error *err)
{
    trace *t = ctx;
    (void)err;
    trace_u64(t, (uint64_t)row);
    trace_u64(t, (uint64_t)col);
    trace_u64(t, (uint64_t)n);
    for (int64_t k = 0; k < n; k++) {
        uint32_t b;
        memcpy(&b, &z[k], sizeof b);
        trace_u64(t, b);
    }
    t->calls++;
    t->cells += (uint64_t)n;
    return GDT_OK;
}

/* Faces of a dense cloud at UTM-like magnitudes (lattice 0.01, spacing
 * about 0.3): at cell sizes near the spacing nearly every face holds at
 * most 2 x 2 centres, the path of small faces; at coarser ones few do.
 * Either way the grid's fast bounds and small-face path must make exactly
 * the sink calls of the general path (g.fast = 0): the same runs, cells and
 * value bits, in the same order, for faces in either orientation; with
 * terrain heights and with heights whose weighted sum cancels (there the
 * order of the value rule's sum decides the bits). */
static void test_small_faces(void)
{
    const int n = 10000;
    const int64_t side = 3000, bx = 48000000, by = 486000000;
    const double res[] = {0.01, 0.02, 0.07, 0.2, 0.3, 0.35, 0.5, 1.0, 3.0};
    gdt_lattice lat = {0.01, 0.01, 0.0, 0.0};
    gdt_point *pts = calloc((size_t)n, sizeof *pts);
    gdt_ipt *loc = calloc((size_t)n, sizeof *loc);
    gdt_mesh mesh;
    gdt_error err;
    uint64_t s = 77;
    int m = 0;
    unsigned char *used = calloc((size_t)((side + 1) * (side + 1) / 8 + 1), 1);

    gdt_error_clear(&err);
    gdt_mesh_init(&mesh);
    while (m < n) { /* distinct points (used: a bitmap of the box); some on centre lines */
        int64_t x = rnd_in(&s, 0, side), y = rnd_in(&s, 0, side);
        if (m % 7 == 0)
            x = x / 10 * 10 + 5 <= side ? x / 10 * 10 + 5 : x / 10 * 10 - 5;
        if (m % 11 == 0)
            y = y / 10 * 10 + 5 <= side ? y / 10 * 10 + 5 : y / 10 * 10 - 5;
        size_t bit = (size_t)(y * (side + 1) + x);
        if (used[bit / 8] & (1u << (bit % 8)))
            continue;
        used[bit / 8] |= (unsigned char)(1u << (bit % 8));
        loc[m].x = x;
        loc[m].y = y;
        pts[m].x = bx + x;
        pts[m].y = by + y;
        pts[m].z = 100.0 + (double)(gdt_splitmix64(&s) % 1000003) / 997.0;
        m++;
    }
    free(used);
    if (gdt_reference_triangulate(NULL, loc, (size_t)n, &mesh, &err) != GDT_OK) {
        GDT_CHECK(&C, 0, "small faces: %s", err.msg);
        goto done;
    }
    for (size_t k = 0; k < 2 * sizeof res / sizeof res[0]; k++) {
        gdt_raster_grid g, g0;
        trace fast[2] = {{UINT64_C(0xcbf29ce484222325), 0, 0}, {UINT64_C(0xcbf29ce484222325), 0, 0}};
        trace slow[2] = {{UINT64_C(0xcbf29ce484222325), 0, 0}, {UINT64_C(0xcbf29ce484222325), 0, 0}};
        const double r = res[k % (sizeof res / sizeof res[0])];
        if (k == sizeof res / sizeof res[0])
            /* then heights of +-1e17 and small ones: the three products of a
             * value cancel, so a sum in another order than the value rule's
             * gives other float bits */
            for (int i = 0; i < n; i++)
                pts[i].z = (double)((int)(gdt_splitmix64(&s) % 3) - 1) * 1e17 + (double)(i % 101);
        GDT_CHECK(&C, gdt_raster_grid_define(&g, &lat, bx, by, bx + side, by + side, (uint64_t)n,
                                             r, "--dem-res", &err) == GDT_OK,
                  "%s", err.msg);
        GDT_CHECK(&C, g.fast, "res %g: the grid takes no fast bounds", r);
        g0 = g;
        g0.fast = 0;
        for (size_t f = 0; f < mesh.ntris; f++)
            for (int cw = 0; cw < 2; cw++) {
                gdt_raster_vertex v[3];
                for (int i = 0; i < 3; i++) {
                    const gdt_point *p = &pts[mesh.tri[3 * f + (size_t)(cw ? 2 - i : i)]];
                    v[i].x = p->x;
                    v[i].y = p->y;
                    v[i].z = p->z;
                }
                GDT_CHECK(&C, gdt_raster_triangle(&g, NULL, v, trace_sink, &fast[cw], &err) ==
                                  GDT_OK, "%s", err.msg);
                GDT_CHECK(&C, gdt_raster_triangle(&g0, NULL, v, trace_sink, &slow[cw], &err) ==
                                  GDT_OK, "%s", err.msg);
            }
        for (int cw = 0; cw < 2; cw++)
            GDT_CHECK(&C, fast[cw].hash == slow[cw].hash && fast[cw].calls == slow[cw].calls &&
                              fast[cw].cells == slow[cw].cells,
                      "res %g%s: %llu runs, %llu cells; the general path %llu, %llu (or other "
                      "values)", r, cw ? ", clockwise" : "",
                      (unsigned long long)fast[cw].calls, (unsigned long long)fast[cw].cells,
                      (unsigned long long)slow[cw].calls, (unsigned long long)slow[cw].cells);
        GDT_CHECK(&C, fast[0].hash == fast[1].hash, "res %g: other calls for clockwise faces", r);
        GDT_CHECK(&C, fast[0].cells > 0, "res %g: no cells", r);
    }
done:
    gdt_mesh_free(&mesh);
    free(pts);
    free(loc);
}

/* A triangle spanning 2^31 lattice steps at 2^52: its centres, with huge
 * orientation values, must cover the cells a brute-force test finds. */
static void test_large_coordinates(void)
{
    gdt_lattice lat = {1.0, 1.0, 0.0, 0.0};
    gdt_raster_grid g;
    gdt_error err;
    int64_t B = (INT64_C(1) << 52) + 12345, L = INT64_C(2147483647);
    gdt_raster_vertex v[3] = {{B, B, 1.0}, {B + L, B + 7, 2.0}, {B + 3, B + L, 3.0}};
    cover cv;
    int64_t m = L / 37; /* about 37 x 37 cells */
    gdt_error_clear(&err);
    GDT_CHECK(&C, gdt_raster_grid_define(&g, &lat, B, B, B + L, B + L, 3, (double)m, "--dem-res",
                                         &err) == GDT_OK, "%s", err.msg);
    cv.ncols = g.geo.ncols;
    cv.nrows = g.geo.nrows;
    cv.count = calloc((size_t)(cv.ncols * cv.nrows), sizeof *cv.count);
    cv.val = calloc((size_t)(cv.ncols * cv.nrows), sizeof *cv.val);
    GDT_CHECK(&C, gdt_raster_triangle(&g, NULL, v, count_sink, &cv, &err) == GDT_OK, "%s", err.msg);
    {
        gdt_hpt a = {2 * v[0].x, 2 * v[0].y}, b = {2 * v[1].x, 2 * v[1].y}, c = {2 * v[2].x, 2 * v[2].y};
        long inside = 0;
        for (int64_t r = 0; r < cv.nrows; r++)
            for (int64_t k = 0; k < cv.ncols; k++) {
                gdt_hpt p = gdt_raster_centre(&g, r, k);
                int want = gdt_edge_owns_half(NULL, a, b, p) && gdt_edge_owns_half(NULL, b, c, p) &&
                           gdt_edge_owns_half(NULL, c, a, p);
                size_t i = (size_t)(r * cv.ncols + k);
                inside += want;
                GDT_CHECK_QUIET_AFTER(&C, 5, cv.count[i] == want, "large: cell (%lld, %lld)",
                                      (long long)r, (long long)k);
                if (want)
                    GDT_CHECK_QUIET_AFTER(&C, 5, cv.val[i] >= 1.0f && cv.val[i] <= 3.0f,
                                          "large: value %g", cv.val[i]);
            }
        GDT_CHECK(&C, inside > 500, "large: only %ld centres inside", inside);
    }
    free(cv.count);
    free(cv.val);
}

static void test_grid_rule(void)
{
    gdt_raster_grid g;
    gdt_error err;
    gdt_lattice las = {0.01, 0.01, 1000.0, -250.0};
    gdt_lattice odd = {0.01, 0.01, 0.005, 0.0};
    gdt_lattice mixed = {0.01, 0.001, 0.0, 0.0};
    gdt_lattice coprime = {1.0, 3.141592653589793, 0.0, 0.0};

    gdt_error_clear(&err);
    /* points from CRS x 1003.37 .. 1011.2: lattice 337 .. 1120 */
    GDT_CHECK(&C, gdt_raster_grid_define(&g, &las, 337, 100, 1120, 999, 1000, 0.5, "--dem-res",
                                         &err) == GDT_OK, "%s", err.msg);
    GDT_CHECK(&C, g.mx == 50 && g.my == 50, "m %lld %lld", (long long)g.mx, (long long)g.my);
    GDT_CHECK(&C, g.geo.west == 1003.0 && g.geo.north == -240.0, "corner %.17g %.17g", g.geo.west,
              g.geo.north);
    GDT_CHECK(&C, g.geo.ncols == 17 && g.geo.nrows == 18, "size %lld x %lld",
              (long long)g.geo.ncols, (long long)g.geo.nrows);
    {
        gdt_hpt p = gdt_raster_centre(&g, 0, 0);
        /* centre (1003.25, -240.25): lattice x 325, y 975, doubled */
        GDT_CHECK(&C, p.x == 650 && p.y == 1950, "centre %lld %lld", (long long)p.x, (long long)p.y);
    }
    GDT_CHECK(&C, gdt_raster_grid_define(&g, &las, 0, 0, 10, 10, 4, 0.015, "--dem-res", &err) ==
                      GDT_EUSAGE && err.code == 2601, "code %d", err.code);
    gdt_error_clear(&err);
    GDT_CHECK(&C, gdt_raster_grid_define(&g, &odd, 0, 0, 1000, 1000, 4, 1.0, "--dem-res", &err) ==
                      GDT_OK, "%s", err.msg);
    GDT_CHECK(&C, g.geo.west == 0.005 + 0.01 * (double)g.x0, "unaligned west %.17g", g.geo.west);
    GDT_CHECK(&C, gdt_raster_grid_define(&g, &mixed, 0, 0, 1000, 1000, 100, 0, "--dem-res", &err) ==
                      GDT_OK && g.my == 10 * g.mx, "mixed %lld %lld", (long long)g.mx, (long long)g.my);
    GDT_CHECK(&C, gdt_raster_grid_define(&g, &coprime, 0, 0, 10, 10, 4, 0, "--dem-res", &err) ==
                      GDT_EUSAGE && err.code == 2602, "code %d", err.code);
    gdt_error_clear(&err);
    /* default: 10000 points over 100 x 100 CRS units: spacing 1, R = 2 */
    GDT_CHECK(&C, gdt_raster_grid_define(&g, &las, 0, 0, 10000, 10000, 10000, 0, "--dem-res",
                                         &err) == GDT_OK && g.geo.res_x == 2.0 && g.mx == 200,
              "default res %.17g", g.geo.res_x);
    GDT_CHECK(&C, gdt_raster_grid_define(&g, &las, 0, 0, INT64_C(1) << 40, 10, 4, 0.01,
                                         "--dem-res", &err) == GDT_EUSAGE && err.code == 2603,
              "code %d", err.code);
}

/* ---- the writer ------------------------------------------------------- */

static long file_size(const char *p)
{
    struct stat sb;
    return stat(p, &sb) == 0 ? (long)sb.st_size : -1;
}

static unsigned char *slurp(const char *p, long *n)
{
    FILE *f = fopen(p, "rb");
    unsigned char *b;
    *n = file_size(p);
    if (f == NULL || *n < 0)
        return NULL;
    b = malloc((size_t)*n + 1);
    if (b != NULL && fread(b, 1, (size_t)*n, f) != (size_t)*n) {
        free(b);
        b = NULL;
    }
    fclose(f);
    return b;
}

static int count_entries(const char *dir)
{
    char cmd[4200];
    FILE *p;
    int n = -1;
    snprintf(cmd, sizeof cmd, "ls -A '%s' | wc -l", dir);
    p = popen(cmd, "r");
    if (p != NULL) {
        if (fscanf(p, "%d", &n) != 1)
            n = -1;
        pclose(p);
    }
    return n;
}

static void write_dem(const char *dir, const char *path, uint64_t budget, uint64_t seed,
                      gdt_dem_stats *stats)
{
    gdt_dem_geo geo = {1300, 1100, 500000.0, 4100000.0, 0.5, 0.5};
    gdt_dem_opts o;
    gdt_dem *w = NULL;
    gdt_error err;
    int64_t nruns = 0, cap = 1100 * 3 + 64;
    int64_t *runs = malloc((size_t)cap * 2 * sizeof *runs);
    uint64_t s = seed;
    float buf[433];

    memset(&o, 0, sizeof o);
    o.nodata = -9999.0;
    o.mem_budget = budget;
    o.epsg = 32610;
    o.scratch_dir = dir;
    gdt_error_clear(&err);
    GDT_CHECK(&C, gdt_dem_create(&w, &geo, path, &o, &err) == GDT_OK, "%s", err.msg);
    /* runs of 433 cells (across block borders) over the raster except a
     * hole (nodata) that holds whole blocks, shuffled; column 1299 is never
     * written */
    for (int64_t r = 0; r < geo.nrows; r++)
        for (int64_t c = 0; c + 433 <= geo.ncols; c += 433)
            if (!(r >= 500 && r <= 1050 && c >= 433) && nruns < cap) {
                runs[2 * nruns] = r;
                runs[2 * nruns + 1] = c;
                nruns++;
            }
    for (int64_t i = nruns; i > 1; i--) {
        int64_t j = (int64_t)(gdt_splitmix64(&s) % (uint64_t)i), t0 = runs[2 * (i - 1)],
                t1 = runs[2 * (i - 1) + 1];
        runs[2 * (i - 1)] = runs[2 * j];
        runs[2 * (i - 1) + 1] = runs[2 * j + 1];
        runs[2 * j] = t0;
        runs[2 * j + 1] = t1;
    }
    for (int64_t i = 0; i < nruns; i++) {
        for (int k = 0; k < 433; k++)
            buf[k] = (float)(100.0 + 0.01 * (double)runs[2 * i] + 0.001 * (double)(runs[2 * i + 1] + k));
        if (gdt_dem_put(w, runs[2 * i], runs[2 * i + 1], 433, buf, &err) != GDT_OK) {
            GDT_CHECK(&C, 0, "%s", err.msg);
            break;
        }
    }
    GDT_CHECK(&C, gdt_dem_finish(w, stats, &err) == GDT_OK, "%s", err.msg);
    free(runs);
}

/* Reads the DEM back through GDAL: every cell is its value or nodata. */
static void check_values(const char *path)
{
    GDALDatasetH ds;
    float *row = malloc(1300 * sizeof *row);
    double gt[6];
    int has = 0;
    long bad = 0;
    GDALAllRegister();
    ds = GDALOpen(path, GA_ReadOnly);
    GDT_CHECK(&C, ds != NULL, "cannot open %s", path);
    if (ds == NULL || row == NULL) {
        free(row);
        return;
    }
    GDT_CHECK(&C, GDALGetRasterXSize(ds) == 1300 && GDALGetRasterYSize(ds) == 1100, "%s", "size");
    GDT_CHECK(&C, GDALGetGeoTransform(ds, gt) == CE_None && gt[0] == 500000.0 && gt[1] == 0.5 &&
                      gt[3] == 4100000.0 && gt[5] == -0.5, "%s", "geotransform");
    GDT_CHECK(&C, GDALGetRasterNoDataValue(GDALGetRasterBand(ds, 1), &has) == -9999.0 && has,
              "%s", "nodata");
    for (int r = 0; r < 1100; r++) {
        if (GDALRasterIO(GDALGetRasterBand(ds, 1), GF_Read, 0, r, 1300, 1, row, 1300, 1,
                         GDT_Float32, 0, 0) != CE_None) {
            bad++;
            continue;
        }
        for (int c = 0; c < 1300; c++) {
            int hole = (r >= 500 && r <= 1050 && c >= 433) || c == 1299;
            float want = hole ? -9999.0f : (float)(100.0 + 0.01 * (double)r + 0.001 * (double)c);
            bad += memcmp(&row[c], &want, sizeof want) != 0;
        }
    }
    GDT_CHECK(&C, bad == 0, "%ld cells read back wrong", bad);
    GDALClose(ds);
    free(row);
}

static void test_writer(const char *work)
{
    char dir[4096], a[4200], b[4200], c[4200];
    gdt_dem_stats sa, sb;
    unsigned char *ba, *bb;
    long na = 0, nb = 0;
    gdt_error err;

    snprintf(dir, sizeof dir, "%s/raster-writer", work);
    mkdir(work, 0777);
    mkdir(dir, 0777);
    snprintf(a, sizeof a, "%s/small.tif", dir);
    snprintf(b, sizeof b, "%s/big.tif", dir);
    snprintf(c, sizeof c, "%s/dup.tif", dir);
    unlink(a);
    unlink(b);
    unlink(c);
    write_dem(dir, a, 1, 5, &sa);             /* two blocks: spills and reloads */
    write_dem(dir, b, (uint64_t)1 << 30, 6, &sb); /* everything cached, another order */
    GDT_CHECK(&C, sa.cache_blocks == 2 && sa.spills > 0 && sa.reloads > 0,
              "small cache %llu blocks, %llu spills, %llu reloads",
              (unsigned long long)sa.cache_blocks, (unsigned long long)sa.spills,
              (unsigned long long)sa.reloads);
    GDT_CHECK(&C, sb.spills == 0 && sb.blocks == 9, "big cache %llu spills of %llu blocks",
              (unsigned long long)sb.spills, (unsigned long long)sb.blocks);
    GDT_CHECK(&C, sa.cells_written == sb.cells_written, "%s", "cells");
    ba = slurp(a, &na);
    bb = slurp(b, &nb);
    GDT_CHECK(&C, ba != NULL && bb != NULL && na == nb && na > 1000 && memcmp(ba, bb, (size_t)na) == 0,
              "spilled and cached DEMs differ (%ld and %ld bytes)", na, nb);
    free(ba);
    free(bb);
    check_values(a);
    GDT_CHECK(&C, count_entries(dir) == 2, "leftover files in %s: %d entries", dir,
              count_entries(dir));

    /* a cell written twice; abort leaves nothing */
    {
        gdt_dem_geo geo = {10, 10, 0.0, 10.0, 1.0, 1.0};
        gdt_dem_opts o;
        gdt_dem *w = NULL;
        float z[3] = {1, 2, 3};
        memset(&o, 0, sizeof o);
        o.nodata = -9999.0;
        gdt_error_clear(&err);
        GDT_CHECK(&C, gdt_dem_create(&w, &geo, c, &o, &err) == GDT_OK, "%s", err.msg);
        GDT_CHECK(&C, gdt_dem_put(w, 2, 3, 3, z, &err) == GDT_OK, "%s", err.msg);
        GDT_CHECK(&C, gdt_dem_put(w, 2, 5, 1, z, &err) == GDT_EINTERNAL && err.code == 7662,
                  "code %d", err.code);
        gdt_error_clear(&err);
        GDT_CHECK(&C, gdt_dem_put(w, 2, 9, 2, z, &err) == GDT_EINTERNAL && err.code == 7661,
                  "code %d", err.code);
        gdt_dem_abort(w);
        GDT_CHECK(&C, file_size(c) < 0 && count_entries(dir) == 2, "%s", "abort left a file");
        o.nodata = 0.1;
        gdt_error_clear(&err);
        GDT_CHECK(&C, gdt_dem_create(&w, &geo, c, &o, &err) == GDT_EUSAGE && err.code == 2611,
                  "code %d", err.code);
    }
}

int main(int argc, char **argv)
{
    const char *work = argc > 1 ? argv[1] : ".";
    test_edge_ranges();
    test_coverage(12, 0, 1, 40, 1, 0);
    test_coverage(12, 0, 2, 60, 2, 0);
    test_coverage(30, -7, 3, 150, 3, 0);
    test_coverage(20, 5, 2, 120, 4, 1);
    test_coverage(60, 1000, 5, 300, 5, 1);
    test_coverage(40, (INT64_C(1) << 52) - 100, 2, 200, 6, 0);
    test_small_faces();
    test_large_coordinates();
    test_grid_rule();
    test_writer(work);
    return gdt_check_finish(&C, "test_raster");
}
