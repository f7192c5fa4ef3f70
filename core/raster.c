/* raster.c — the DEM grid on the lattice and the rasterisation of TIN
 * triangles (gdt_raster.h).  Every geometric decision goes through the
 * half-lattice predicates of gdt_predicates.h; this file only does the
 * index arithmetic of the grid.
 *
 * Two ways through a face, with the same cells, values and runs (tested
 * call by call): a face inside a grid that spans under 2^32 doubled steps
 * (nearly every one) gets its cell bounds from one multiply-high each, and
 * when its box holds at most 2 x 2 centres (nearly every face of a grid
 * about as fine as the points) it is tested in 64-bit determinants
 * relative to its box; everything else takes general_triangle. */
#include "gdt_raster.h"

#include <math.h>
#include <string.h>

/* Vertices and centres are doubled lattice integers; the grid's own
 * arithmetic stays far inside int64 by the checks of grid_define. */
#define RASTER_VERTEX_LIMIT (INT64_C(1) << 53)
#define RASTER_SPAN_LIMIT (INT64_C(1) << 56)
#define RASTER_RUN 256
#define RASTER_SMALL 16 /* bounding boxes of at most this many centres: tested cell by cell */
#define RASTER_REL_TOL 1e-9
/* faces whose box spans at most this many doubled steps each way may take
 * tiny_triangle: coordinates relative to the box stay within
 * gdt_orient2d_small_det's range */
#define RASTER_TINY_SPAN GDT_SMALL_DET_MAX

static int64_t floor_div(int64_t n, int64_t d) /* d > 0 */
{
    int64_t q = n / d;
    return (n % d != 0 && n < 0) ? q - 1 : q;
}

/* floor(n / d) for d > 0, given inv ~ 1 / d: the quotient is estimated in
 * double and then corrected with exact products, so the result is the exact
 * floor (for |n| < 2^62, where the estimate is off by a few units at most
 * and q d cannot overflow).  A 64-bit integer division costs several times
 * more, and the rasteriser needs four per face. */
static int64_t floor_div_inv(int64_t n, int64_t d, double inv)
{
    int64_t q = (int64_t)((double)n * inv);
    while (q * d > n)
        q--;
    while ((q + 1) * d <= n)
        q++;
    return q;
}

static int64_t ceil_div_inv(int64_t n, int64_t d, double inv)
{
    return -floor_div_inv(-n, d, inv);
}

/* floor(n / d) for d > 0 with mag = floor((2^64 - 1) / d) + 1: for
 * 0 <= n < 2^32 and 2 <= d <= 2^32 the quotient is the high half of n mag,
 * exactly (Lemire, Kaser & Kurz, "Faster remainder by direct computation",
 * 2019); other n, or mag 0, go through floor_div_inv. */
static int64_t floor_div_mag(int64_t n, int64_t d, double inv, uint64_t mag)
{
    if (mag != 0 && n >= 0 && n < (INT64_C(1) << 32))
        return (int64_t)(((unsigned __int128)mag * (uint64_t)n) >> 64);
    return floor_div_inv(n, d, inv);
}

/* The high half of m n: floor(n / d) for m = floor((2^64 - 1) / d) + 1,
 * 0 <= n < 2^32 and 2 <= d <= 2^32 (see floor_div_mag). */
static int64_t mul_hi(uint64_t m, int64_t n)
{
    return (int64_t)(((unsigned __int128)m * (uint64_t)n) >> 64);
}

static int64_t ceil_div_mag(int64_t n, int64_t d, double inv, uint64_t mag)
{
    if (mag != 0 && n >= 0 && n + d - 1 < (INT64_C(1) << 32))
        return (int64_t)(((unsigned __int128)mag * (uint64_t)(n + d - 1)) >> 64);
    return ceil_div_inv(n, d, inv);
}

int gdt_raster_unit(const gdt_lattice *lat, int64_t *ux, int64_t *uy)
{
    if (lat->sx == lat->sy) {
        *ux = *uy = 1;
        return 1;
    }
    for (int64_t a = 1; a <= 10000; a++) {
        double u = (double)a * lat->sx;
        double b = nearbyint(u / lat->sy);
        if (b >= 1.0 && fabs(u - b * lat->sy) <= 1e-12 * u) {
            *ux = a;
            *uy = (int64_t)b;
            return 1;
        }
    }
    return 0;
}

double gdt_raster_default_res(const gdt_lattice *lat, int64_t min_x, int64_t min_y,
                              int64_t max_x, int64_t max_y, uint64_t npoints)
{
    int64_t ux, uy;
    double w = (double)(max_x - min_x) * lat->sx, h = (double)(max_y - min_y) * lat->sy;
    double s = 0.0, unit, k;

    if (!gdt_raster_unit(lat, &ux, &uy))
        return 0.0;
    unit = (double)ux * lat->sx;
    if (npoints >= 1 && w > 0.0 && h > 0.0)
        s = sqrt(w * h / (double)npoints);
    else if (npoints > 1)
        s = (w > h ? w : h) / (double)(npoints - 1);
    k = nearbyint(2.0 * s / unit);
    if (!(k >= 1.0))
        k = 1.0;
    if (k * (double)(ux > uy ? ux : uy) > (double)GDT_RASTER_MAX_M)
        k = floor((double)GDT_RASTER_MAX_M / (double)(ux > uy ? ux : uy));
    return k * unit;
}

/* Whether the lattice origin o is a multiple of the step s (then the grid
 * lines are exactly the CRS multiples of the cell size); *anchor is the
 * lattice coordinate of the line nearest to CRS 0. */
static int anchor_of(double o, double s, int64_t *anchor)
{
    double q = -o / s, r;
    if (!(fabs(q) < 4503599627370496.0)) { /* 2^52: no lattice line is near CRS 0 */
        *anchor = 0;
        return 0;
    }
    r = nearbyint(q);
    *anchor = (int64_t)r;
    return fabs(q - r) <= RASTER_REL_TOL;
}

gdt_status gdt_raster_grid_define(gdt_raster_grid *g, const gdt_lattice *lat, int64_t min_x,
                                  int64_t min_y, int64_t max_x, int64_t max_y,
                                  uint64_t npoints, double res, const char *opt,
                                  gdt_error *err)
{
    int64_t ux, uy, ax, ay, kc0, kc1, ks, kn;
    double mxd, myd;
    int al_x, al_y;

    memset(g, 0, sizeof *g);
    g->lattice = *lat;
    if (!gdt_raster_unit(lat, &ux, &uy))
        return gdt_error_set(err, GDT_EUSAGE, 2602,
                             "%s: the lattice steps %.17g (x) and %.17g (y) have no common "
                             "multiple of at most 10^4 steps, so square DEM cells cannot lie "
                             "on the lattice",
                             opt, lat->sx, lat->sy);
    if (res == 0.0) {
        res = gdt_raster_default_res(lat, min_x, min_y, max_x, max_y, npoints);
    } else {
        double unit = (double)ux * lat->sx;
        mxd = nearbyint(res / lat->sx);
        myd = nearbyint(res / lat->sy);
        if (!(mxd >= 1.0 && myd >= 1.0 && fabs(mxd * lat->sx - res) <= RASTER_REL_TOL * res &&
              fabs(myd * lat->sy - res) <= RASTER_REL_TOL * res)) {
            double lo = floor(res / unit) * unit, hi = ceil(res / unit) * unit;
            if (lo < unit)
                lo = unit;
            return gdt_error_set(err, GDT_EUSAGE, 2601,
                                 "%s %.17g: not a multiple of the lattice step (%.17g x %.17g "
                                 "CRS units): cells must be whole lattice steps; the nearest "
                                 "are %.17g and %.17g",
                                 opt, res, lat->sx, lat->sy, lo, hi > lo ? hi : lo + unit);
        }
    }
    mxd = nearbyint(res / lat->sx);
    myd = nearbyint(res / lat->sy);
    if (!(mxd <= (double)GDT_RASTER_MAX_M && myd <= (double)GDT_RASTER_MAX_M))
        return gdt_error_set(err, GDT_EUSAGE, 2603,
                             "%s %.17g: a cell of more than 2^31 lattice steps", opt, res);
    g->mx = (int64_t)mxd;
    g->my = (int64_t)myd;
    g->inv_dx = 1.0 / (double)(2 * g->mx);
    g->inv_dy = 1.0 / (double)(2 * g->my);
    g->mag_dx = UINT64_MAX / (uint64_t)(2 * g->mx) + 1;
    g->mag_dy = UINT64_MAX / (uint64_t)(2 * g->my) + 1;
    al_x = anchor_of(lat->ox, lat->sx, &ax);
    al_y = anchor_of(lat->oy, lat->sy, &ay);
    kc0 = floor_div(min_x - ax, g->mx);
    kc1 = floor_div(max_x - ax, g->mx);
    ks = floor_div(min_y - ay, g->my);
    kn = floor_div(max_y - ay, g->my) + 1;
    g->geo.ncols = kc1 - kc0 + 1;
    g->geo.nrows = kn - ks;
    if (g->geo.ncols > GDT_DEM_MAX_SIDE || g->geo.nrows > GDT_DEM_MAX_SIDE ||
        (double)g->geo.ncols * (double)g->geo.nrows > (double)GDT_DEM_MAX_CELLS ||
        (double)g->geo.ncols * (double)g->mx > (double)RASTER_SPAN_LIMIT ||
        (double)g->geo.nrows * (double)g->my > (double)RASTER_SPAN_LIMIT)
        return gdt_error_set(err, GDT_EUSAGE, 2603,
                             "%s %.17g: the DEM would have %lld x %lld cells, more than it "
                             "may (at most 2^31 - 1 per side and 2^40 in all): give a "
                             "larger %s",
                             opt, res, (long long)g->geo.ncols, (long long)g->geo.nrows, opt);
    g->x0 = ax + kc0 * g->mx;
    g->y0 = ay + kn * g->my;
    g->x1 = g->x0 + g->geo.ncols * g->mx;
    g->y1 = g->y0 - g->geo.nrows * g->my;
    /* the bounds' numerators of a box inside the grid are at most
     * (2 ncols + 1) mx and (2 nrows + 1) my */
    g->fast = (2 * g->geo.ncols + 1) * g->mx < (INT64_C(1) << 32) &&
              (2 * g->geo.nrows + 1) * g->my < (INT64_C(1) << 32);
    g->geo.res_x = g->geo.res_y = res;
    g->geo.west = al_x ? (double)kc0 * res : lat->ox + lat->sx * (double)g->x0;
    g->geo.north = al_y ? (double)kn * res : lat->oy + lat->sy * (double)g->y0;
    return GDT_OK;
}

gdt_hpt gdt_raster_centre(const gdt_raster_grid *g, int64_t row, int64_t col)
{
    gdt_hpt p;
    p.x = 2 * g->x0 + g->mx * (2 * col + 1);
    p.y = 2 * g->y0 - g->my * (2 * row + 1);
    return p;
}

/* The documented conversion of an exact weight: round to nearest double. */
static double weight(gdt_i128 w)
{
    if (w >= INT64_MIN && w <= INT64_MAX)
        return (double)(int64_t)w;
    return (double)w;
}

/* Whether the directed edge u -> v (of a counter-clockwise triangle) owns
 * a point whose determinant orient2d(u, v, p) is e: the rule of
 * gdt_edge_owns_half, given the determinant. */
static int owns(gdt_hpt u, gdt_hpt v, gdt_i128 e)
{
    return e > 0 || (e == 0 && (v.y < u.y || (v.y == u.y && v.x > u.x)));
}

/* The cells of a bounding box of at most RASTER_SMALL centres (what most
 * faces have when the grid is about as fine as the points): each centre is
 * tested against the three edges directly, which costs three determinants
 * instead of the three exact divisions per row of the edge ranges, and
 * owns exactly the same centres (gdt_edge_owned_range is the same rule
 * solved for a row).  a, b, c are counter-clockwise. */
static gdt_status small_triangle(const gdt_raster_grid *g, gdt_pred_stats *st, gdt_hpt a,
                                 gdt_hpt b, gdt_hpt c, double za, double zb, double zc, double dd,
                                 int64_t r_lo, int64_t r_hi, int64_t c_lo, int64_t c_hi,
                                 gdt_raster_sink sink, void *ctx, gdt_error *err)
{
    const int64_t xc0 = 2 * g->x0 + g->mx, dx = 2 * g->mx;
    float run[RASTER_SMALL];

    for (int64_t r = r_lo; r <= r_hi; r++) {
        int64_t y = 2 * g->y0 - g->my * (2 * r + 1), start = -1, n = 0;
        for (int64_t col = c_lo; col <= c_hi + 1; col++) {
            int in = 0;
            if (col <= c_hi) {
                gdt_hpt q;
                gdt_i128 ia, ib, ic;
                q.x = xc0 + dx * col;
                q.y = y;
                ia = gdt_orient2d_half_det(st, b, c, q);
                ib = gdt_orient2d_half_det(st, c, a, q);
                ic = gdt_orient2d_half_det(st, a, b, q);
                in = owns(b, c, ia) && owns(c, a, ib) && owns(a, b, ic);
                if (in) {
                    double wa = weight(ia), wb = weight(ib), wc = weight(ic);
                    if (n == 0)
                        start = col;
                    run[n++] = (float)(((wa * za + wb * zb) + wc * zc) / dd);
                }
            }
            if (!in && n > 0) {
                gdt_status s = sink(ctx, r, start, n, run, err);
                if (s != GDT_OK)
                    return s;
                n = 0;
            }
        }
    }
    return GDT_OK;
}

/* The cells of a face whose bounding box [ox, ox + RASTER_TINY_SPAN] x
 * [oy, oy + RASTER_TINY_SPAN] (doubled coordinates) holds at most 2 x 2
 * centres, columns c_lo..c_hi and rows r_lo..r_hi: nearly every face when
 * the grid is about as fine as the points.  Relative to (ox, oy) every
 * vertex and candidate centre lies in [0, RASTER_TINY_SPAN]^2, so
 * gdt_orient2d_small_det is exact, and the determinants of the other
 * centres follow by exact integer steps.  Owns exactly the centres
 * small_triangle owns, with the same values and the same runs: orientation
 * and ownership do not change under translation, and the weights are the
 * same integers. */
static gdt_status tiny_triangle(const gdt_raster_grid *g, gdt_pred_stats *st, const gdt_hpt p[3],
                                const double z[3], int64_t ox, int64_t oy, int64_t r_lo,
                                int64_t r_hi, int64_t c_lo, int64_t c_hi, gdt_raster_sink sink,
                                void *ctx, gdt_error *err)
{
    const int64_t qx = 2 * g->x0 + g->mx * (2 * c_lo + 1) - ox;
    const int64_t qy = 2 * g->y0 - g->my * (2 * r_lo + 1) - oy;
    const int64_t dx = 2 * g->mx, dy = 2 * g->my;
    int64_t det, ax, ay, bx, by, cx, cy, ea, eb, ec, sxa, sxb, sxc, sya, syb, syc;
    int oa, ob, oc, f;
    double za, zb, zc, dd, zr[3];

    det = gdt_orient2d_small_det(st, p[1].x - p[0].x, p[1].y - p[0].y, p[2].x - p[0].x,
                                 p[2].y - p[0].y);
    if (det == 0)
        return GDT_OK;
    /* a, b, c counter-clockwise */
    ax = p[0].x - ox;
    ay = p[0].y - oy;
    za = z[0];
    if (det > 0) {
        bx = p[1].x - ox, by = p[1].y - oy, zb = z[1];
        cx = p[2].x - ox, cy = p[2].y - oy, zc = z[2];
    } else {
        bx = p[2].x - ox, by = p[2].y - oy, zb = z[2];
        cx = p[1].x - ox, cy = p[1].y - oy, zc = z[1];
        det = -det;
    }
    /* the weight of a is e_a(q) = (c - b) x (q - b), of b (a - c) x (q - c),
     * of c (b - a) x (q - a), at the first centre q; a column east adds
     * sx, a row south sy; o: the edge owns centres on its line
     * (gdt_edge_owns_half), so it owns those with e + o > 0 */
    ea = gdt_orient2d_small_det(st, cx - bx, cy - by, qx - bx, qy - by);
    eb = gdt_orient2d_small_det(st, ax - cx, ay - cy, qx - cx, qy - cy);
    ec = gdt_orient2d_small_det(st, bx - ax, by - ay, qx - ax, qy - ay);
    sxa = -(cy - by) * dx, sya = (cx - bx) * dy;
    sxb = -(ay - cy) * dx, syb = (ax - cx) * dy;
    sxc = -(by - ay) * dx, syc = (bx - ax) * dy;
    oa = (cy < by) | ((cy == by) & (cx > bx));
    ob = (ay < cy) | ((ay == cy) & (ax > cx));
    oc = (by < ay) | ((by == ay) & (bx > ax));
    /* the value's sum starts at the lexicographically smallest vertex */
    f = (bx < ax || (bx == ax && by < ay)) ? 1 : 0;
    if (f == 0 ? (cx < ax || (cx == ax && cy < ay)) : (cx < bx || (cx == bx && cy < by)))
        f = 2;
    dd = (double)det;
    for (int64_t r = r_lo; r <= r_hi; r++) {
        float run[2];
        int in[2] = {0, 0};
        int64_t wa = ea, wb = eb, wc = ec;
        for (int k = 0; k <= (int)(c_hi - c_lo); k++) {
            if ((wa + oa > 0) & (wb + ob > 0) & (wc + oc > 0)) {
                zr[0] = (double)wa * za;
                zr[1] = (double)wb * zb;
                zr[2] = (double)wc * zc;
                in[k] = 1;
                run[k] = (float)(f == 0   ? ((zr[0] + zr[1]) + zr[2]) / dd
                                 : f == 1 ? ((zr[1] + zr[2]) + zr[0]) / dd
                                          : ((zr[2] + zr[0]) + zr[1]) / dd);
            }
            wa += sxa;
            wb += sxb;
            wc += sxc;
        }
        if (st != NULL)
            st->orient_calls += 3 * (uint64_t)(c_hi - c_lo + (r > r_lo));
        ea -= sya;
        eb -= syb;
        ec -= syc;
        if (in[0] | in[1]) {
            gdt_status s = sink(ctx, r, in[0] ? c_lo : c_lo + 1, in[0] + in[1],
                                in[0] ? run : run + 1, err);
            if (s != GDT_OK)
                return s;
        }
    }
    return GDT_OK;
}

/* gdt_raster_triangle for any face: exact for every vertex within
 * RASTER_VERTEX_LIMIT and any grid from gdt_raster_grid_define. */
__attribute__((noinline)) static gdt_status
general_triangle(const gdt_raster_grid *g, gdt_pred_stats *st, const gdt_raster_vertex v[3],
                 gdt_raster_sink sink, void *ctx, gdt_error *err)
{
    gdt_hpt p[3], a, b, c;
    double z[3], za, zb, zc, dd, inv_x, inv_y;
    int first = 0;
    gdt_i128 det;
    int64_t minx, maxx, miny, maxy, c_lo, c_hi, r_lo, r_hi, xc0, dx;
    float run[RASTER_RUN];

    for (int i = 0; i < 3; i++) {
        if (!(v[i].x > -RASTER_VERTEX_LIMIT && v[i].x < RASTER_VERTEX_LIMIT &&
              v[i].y > -RASTER_VERTEX_LIMIT && v[i].y < RASTER_VERTEX_LIMIT))
            return gdt_error_set(err, GDT_EINTERNAL, 7660,
                                 "rasterising a triangle: vertex (%lld, %lld) beyond 2^53 "
                                 "lattice steps",
                                 (long long)v[i].x, (long long)v[i].y);
        p[i].x = 2 * v[i].x;
        p[i].y = 2 * v[i].y;
        z[i] = v[i].z;
    }
    /* the cells the bounding box can hold first: most faces of a coarse grid
     * own no centre and need no exact orientation at all */
    minx = maxx = p[0].x;
    miny = maxy = p[0].y;
    for (int i = 0; i < 3; i++) {
        if (p[i].x < minx) minx = p[i].x;
        if (p[i].x > maxx) maxx = p[i].x;
        if (p[i].y < miny) miny = p[i].y;
        if (p[i].y > maxy) maxy = p[i].y;
    }
    xc0 = 2 * g->x0 + g->mx; /* doubled x of the centre of column 0 */
    dx = 2 * g->mx;
    /* columns first: most faces that own no centre are rejected there */
    inv_x = g->inv_dx > 0 ? g->inv_dx : 1.0 / (double)dx; /* a grid not from _define */
    inv_y = g->inv_dy > 0 ? g->inv_dy : 1.0 / (double)(2 * g->my);
    c_lo = ceil_div_mag(minx - xc0, dx, inv_x, g->mag_dx);
    c_hi = floor_div_mag(maxx - xc0, dx, inv_x, g->mag_dx);
    if (c_lo < 0) c_lo = 0;
    if (c_hi > g->geo.ncols - 1) c_hi = g->geo.ncols - 1;
    if (c_lo > c_hi)
        return GDT_OK;
    r_lo = ceil_div_mag(2 * g->y0 - g->my - maxy, 2 * g->my, inv_y, g->mag_dy);
    r_hi = floor_div_mag(2 * g->y0 - g->my - miny, 2 * g->my, inv_y, g->mag_dy);
    if (r_lo < 0) r_lo = 0;
    if (r_hi > g->geo.nrows - 1) r_hi = g->geo.nrows - 1;
    if (r_lo > r_hi)
        return GDT_OK;
    det = gdt_orient2d_half_det(st, p[0], p[1], p[2]);
    if (det == 0)
        return GDT_OK;
    if (det < 0) {
        gdt_hpt tp = p[1];
        double tz = z[1];
        p[1] = p[2];
        p[2] = tp;
        z[1] = z[2];
        z[2] = tz;
        det = -det;
    }
    for (int i = 1; i < 3; i++)
        if (p[i].x < p[first].x || (p[i].x == p[first].x && p[i].y < p[first].y))
            first = i;
    a = p[first];
    b = p[(first + 1) % 3];
    c = p[(first + 2) % 3];
    za = z[first];
    zb = z[(first + 1) % 3];
    zc = z[(first + 2) % 3];
    dd = weight(det);


    if ((r_hi - r_lo + 1) * (c_hi - c_lo + 1) <= RASTER_SMALL)
        return small_triangle(g, st, a, b, c, za, zb, zc, dd, r_lo, r_hi, c_lo, c_hi, sink, ctx,
                              err);
    for (int64_t r = r_lo; r <= r_hi; r++) {
        int64_t lo = c_lo, hi = c_hi, y = 2 * g->y0 - g->my * (2 * r + 1);
        gdt_edge_owned_range(st, a, b, xc0, dx, y, &lo, &hi);
        gdt_edge_owned_range(st, b, c, xc0, dx, y, &lo, &hi);
        gdt_edge_owned_range(st, c, a, xc0, dx, y, &lo, &hi);
        for (int64_t col = lo; col <= hi; col += RASTER_RUN) {
            int64_t n = hi - col + 1 < RASTER_RUN ? hi - col + 1 : RASTER_RUN;
            gdt_status s;
            /* The three weights are orient2d determinants of the centres
             * q_k = (xc0 + dx (col + k), y): exact at k = 0, then each
             * changes by the exact constant -(edge dy) dx per cell, so the
             * run holds the same integers as one determinant per cell. */
            gdt_hpt q;
            gdt_i128 ia, ib, ic;
            const gdt_i128 sa = -(gdt_i128)(c.y - b.y) * dx, sb = -(gdt_i128)(a.y - c.y) * dx,
                           sc = -(gdt_i128)(b.y - a.y) * dx;
            q.x = xc0 + dx * col;
            q.y = y;
            ia = gdt_orient2d_half_det(st, b, c, q);
            ib = gdt_orient2d_half_det(st, c, a, q);
            ic = gdt_orient2d_half_det(st, a, b, q);
            if (st != NULL)
                st->orient_calls += 3 * (uint64_t)(n - 1);
            for (int64_t k = 0; k < n; k++, ia += sa, ib += sb, ic += sc) {
                double wa = weight(ia), wb = weight(ib), wc = weight(ic);
                run[k] = (float)(((wa * za + wb * zb) + wc * zc) / dd);
            }
            s = sink(ctx, r, col, n, run, err);
            if (s != GDT_OK)
                return s;
        }
    }
    return GDT_OK;
}

gdt_status gdt_raster_triangle(const gdt_raster_grid *g, gdt_pred_stats *st,
                               const gdt_raster_vertex v[3], gdt_raster_sink sink, void *ctx,
                               gdt_error *err)
{
    int64_t minx, maxx, miny, maxy;

    if (!g->fast || g->mag_dx == 0 || g->mag_dy == 0)
        return general_triangle(g, st, v, sink, ctx, err);
    minx = v[0].x < v[1].x ? v[0].x : v[1].x;
    minx = minx < v[2].x ? minx : v[2].x;
    maxx = v[0].x > v[1].x ? v[0].x : v[1].x;
    maxx = maxx > v[2].x ? maxx : v[2].x;
    miny = v[0].y < v[1].y ? v[0].y : v[1].y;
    miny = miny < v[2].y ? miny : v[2].y;
    maxy = v[0].y > v[1].y ? v[0].y : v[1].y;
    maxy = maxy > v[2].y ? maxy : v[2].y;
    if (minx >= g->x0 && maxx <= g->x1 && miny >= g->y1 && maxy <= g->y0) {
        /* a box inside the grid's, which spans under 2^32 doubled steps
         * (g->fast): every numerator of the four cell bounds below is in
         * [0, 2^32), so the multiply-high quotients are exact, and the
         * bounds need no clamping (centres of columns 0..ncols - 1, rows
         * 0..nrows - 1 only) */
        const int64_t mx = g->mx, my = g->my, xc0 = 2 * g->x0 + mx, yc0 = 2 * g->y0 - my;
        const int64_t c_lo = mul_hi(g->mag_dx, 2 * minx - xc0 + 2 * mx - 1);
        const int64_t c_hi = mul_hi(g->mag_dx, 2 * maxx - xc0 + 2 * mx) - 1;
        const int64_t r_lo = mul_hi(g->mag_dy, yc0 - 2 * maxy + 2 * my - 1);
        const int64_t r_hi = mul_hi(g->mag_dy, yc0 - 2 * miny + 2 * my) - 1;
        if (c_lo > c_hi || r_lo > r_hi)
            return GDT_OK;
        if (c_hi - c_lo <= 1 && r_hi - r_lo <= 1 && 2 * (maxx - minx) <= RASTER_TINY_SPAN &&
            2 * (maxy - miny) <= RASTER_TINY_SPAN) {
            gdt_hpt p[3];
            double z[3];
            for (int i = 0; i < 3; i++) {
                p[i].x = 2 * v[i].x;
                p[i].y = 2 * v[i].y;
                z[i] = v[i].z;
            }
            return tiny_triangle(g, st, p, z, 2 * minx, 2 * miny, r_lo, r_hi, c_lo, c_hi, sink,
                                 ctx, err);
        }
    }
    /* (a face of more centres works its bounds out again there: a few
     * nanoseconds against at least five cells) */
    return general_triangle(g, st, v, sink, ctx, err);
}

gdt_status gdt_raster_faces(const gdt_raster_grid *g, gdt_pred_stats *st, const gdt_point *pts,
                            size_t npts, const int32_t *tri, size_t nfaces, gdt_raster_sink sink,
                            void *ctx, gdt_error *err)
{
    for (size_t f = 0; f < nfaces; f++) {
        gdt_raster_vertex v[3];
        for (int i = 0; i < 3; i++) {
            int32_t k = tri[3 * f + (size_t)i];
            if (k < 0 || (size_t)k >= npts)
                return gdt_error_set(err, GDT_EINTERNAL, 7663,
                                     "rasterising face %zu: vertex index %d out of range "
                                     "(%zu vertices)",
                                     f, (int)k, npts);
            v[i].x = pts[k].x;
            v[i].y = pts[k].y;
            v[i].z = pts[k].z;
        }
        gdt_status s = gdt_raster_triangle(g, st, v, sink, ctx, err);
        if (s != GDT_OK)
            return s;
    }
    return GDT_OK;
}
