/* predicates.c — host entry points of the exact predicates.
 *
 * All arithmetic lives in kernels/gdt_exact.clh, shared with the OpenCL
 * kernels; this file adds the counters, the precondition checks of debug
 * builds and the floating-point environment self-test.
 */
#include "gdt_predicates.h"

#include <assert.h>
#include <float.h>
#include <math.h>
#include <stddef.h>

#include "../kernels/gdt_exact.clh"

#define PRED_IN_RANGE(p) ((p).x >= 0 && (p).x <= GDT_COORD_MAX && (p).y >= 0 && (p).y <= GDT_COORD_MAX)
#define PRED_VEC_IN_RANGE(v)                                                                  \
    ((v).x >= -GDT_COORD_MAX && (v).x <= GDT_COORD_MAX && (v).y >= -GDT_COORD_MAX           \
     && (v).y <= GDT_COORD_MAX)

void gdt_pred_stats_add(gdt_pred_stats *dst, const gdt_pred_stats *src)
{
    dst->orient_calls += src->orient_calls;
    dst->incircle_calls += src->incircle_calls;
    dst->incircle_exact += src->incircle_exact;
    dst->tiebreak_calls += src->tiebreak_calls;
}

int gdt_orient2d(gdt_pred_stats *st, gdt_ipt a, gdt_ipt b, gdt_ipt c)
{
    assert(PRED_IN_RANGE(a) && PRED_IN_RANGE(b) && PRED_IN_RANGE(c));
    if (st != NULL)
        st->orient_calls++;
    return gdt_x_orient2d(a.x, a.y, b.x, b.y, c.x, c.y);
}

int gdt_incircle(gdt_pred_stats *st, gdt_ipt a, gdt_ipt b, gdt_ipt c, gdt_ipt d)
{
    assert(PRED_IN_RANGE(a) && PRED_IN_RANGE(b) && PRED_IN_RANGE(c) && PRED_IN_RANGE(d));
    int used_exact = 0;
    int s = gdt_x_incircle(a.x, a.y, b.x, b.y, c.x, c.y, d.x, d.y, &used_exact);
    if (st != NULL) {
        st->incircle_calls++;
        st->incircle_exact += (uint64_t)used_exact;
    }
    return s;
}

int gdt_prefer_diagonal(gdt_pred_stats *st, gdt_ipt e, gdt_ipt f)
{
    assert(PRED_VEC_IN_RANGE(e) && PRED_VEC_IN_RANGE(f));
    if (st != NULL)
        st->tiebreak_calls++;
    return gdt_x_prefer_diagonal(e.x, e.y, f.x, f.y);
}

int gdt_edge_needs_flip(gdt_pred_stats *st, gdt_ipt a, gdt_ipt b, gdt_ipt c, gdt_ipt d)
{
    assert(PRED_IN_RANGE(a) && PRED_IN_RANGE(b) && PRED_IN_RANGE(c) && PRED_IN_RANGE(d));
    unsigned code = gdt_x_edge_flip_code(a.x, a.y, b.x, b.y, c.x, c.y, d.x, d.y);
    if (st != NULL) {
        st->incircle_calls++;
        if (code & GDT_X_USED_EXACT)
            st->incircle_exact++;
        if (code & GDT_X_USED_CONVEX)
            st->orient_calls += 2;
        if (code & GDT_X_USED_TIEBREAK)
            st->tiebreak_calls++;
    }
    return (code & GDT_X_FLIP) != 0;
}

/* The circumdisk of the strictly counter-clockwise triangle (a, b, c) in
 * double: centre (*xc, *yc), radius *r and a slack *s with
 *   |true centre x - *xc|, |true centre y - *yc|, |true radius - *r| <= *s,
 * and with the sum of the centre's and the radius' errors per axis, plus the
 * rounding of xc +- r, still below *s (the error analysis is in
 * gdt_predicates.h, at gdt_circumdisk_bounds).  Returns 0 when (a, b, c) is
 * not strictly counter-clockwise (outputs untouched). */
static int disk_approx(gdt_ipt a, gdt_ipt b, gdt_ipt c, double *xc, double *yc, double *r,
                       double *s)
{
    const double u = DBL_EPSILON / 2.0;
    int64_t bx = b.x - a.x, by = b.y - a.y, cx = c.x - a.x, cy = c.y - a.y;
    /* |b'|, |c'| < 2^31: every product below is < 2^62 and the sums < 2^63 */
    int64_t det = bx * cy - by * cx;
    int64_t bb = bx * bx + by * by, cc = cx * cx + cy * cy;
    double d2, nx, ny, ux, uy, qx, qy;

    if (det <= 0)
        return 0;
    d2 = 2.0 * (double)det;
    nx = (double)cy * (double)bb - (double)by * (double)cc;
    ny = (double)bx * (double)cc - (double)cx * (double)bb;
    ux = nx / d2;
    uy = ny / d2;
    qx = (fabs((double)cy) * (double)bb + fabs((double)by) * (double)cc) / d2;
    qy = (fabs((double)bx) * (double)cc + fabs((double)cx) * (double)bb) / d2;
    *r = sqrt(ux * ux + uy * uy);
    *xc = (double)a.x + ux;
    *yc = (double)a.y + uy;
    *s = 32.0 * u * (qx + qy) + 8.0 * u * ((double)a.x + (double)a.y + fabs(ux) + fabs(uy) + *r) +
         8.0 * u;
    return 1;
}

int gdt_circumdisk_bounds(gdt_pred_stats *st, gdt_ipt a, gdt_ipt b, gdt_ipt c, double bounds[4])
{
    double xc, yc, r, slack;

    if (st != NULL)
        st->orient_calls++;
    if (!disk_approx(a, b, c, &xc, &yc, &r, &slack))
        return 0;
    bounds[0] = (xc - r) - slack;
    bounds[1] = (yc - r) - slack;
    bounds[2] = (xc + r) + slack;
    bounds[3] = (yc + r) + slack;
    return 1;
}

int gdt_circumdiameter_below(gdt_pred_stats *st, gdt_ipt a, gdt_ipt b, gdt_ipt c, int64_t m)
{
    const double u = DBL_EPSILON / 2.0;
    int64_t bx = b.x - a.x, by = b.y - a.y, cx = c.x - a.x, cy = c.y - a.y;
    int64_t det;
    double ex, ey, bb, cc, ee, dd, mm;

    assert(PRED_IN_RANGE(a) && PRED_IN_RANGE(b) && PRED_IN_RANGE(c));
    if (st != NULL)
        st->orient_calls++;
    if (m <= 0 || m >= (INT64_C(1) << 53))
        return 0;
    /* |b'|, |c'| < 2^31: the products are < 2^62, their difference exact */
    det = bx * cy - by * cx;
    if (det <= 0)
        return 0;
    /* differences below 2^32 in magnitude: exact in double */
    ex = (double)(bx - cx);
    ey = (double)(by - cy);
    bb = (double)bx * (double)bx + (double)by * (double)by;
    cc = (double)cx * (double)cx + (double)cy * (double)cy;
    ee = ex * ex + ey * ey;
    dd = (double)det;
    mm = (double)m;
    return (mm * mm) * (dd * dd) > ((bb * cc) * ee) * (1.0 + 64.0 * u);
}

/* design: Q = [x0, x1] x [y, +inf) is closed and convex, so the closed disk
 * of centre o and radius r misses it iff |o - p| > r for the point p of Q
 * nearest to o (o clamped into Q).
 *   1. The outer box of the disk (as gdt_circumdisk_bounds) misses Q: the
 *      disk does.  This decides every disk whose centre lies within the
 *      strip's x range (p is straight above o, or o itself), and every disk
 *      west of x0 or east of x1 that does not reach the strip, whatever its
 *      centre's y.
 *   2. The centre is certified west of x0 (xc + s < x0; fl is monotone and
 *      x0 is a double, so the real xc + s < x0) and south of y: p is the
 *      corner (x0, y), an integer point, and the exact in-circle test on it
 *      decides (on the circle counts as inside).  East of x1 alike with the
 *      corner (x1, y).
 *   Anything else: 0. */
int gdt_circumdisk_misses_strip(gdt_pred_stats *st, gdt_ipt a, gdt_ipt b, gdt_ipt c, int64_t x0,
                                int64_t x1, int64_t y)
{
    double xc, yc, r, slack, xlo, xhi, yhi;
    gdt_ipt corner, tmp;

    assert(PRED_IN_RANGE(a) && PRED_IN_RANGE(b) && PRED_IN_RANGE(c));
    if (x0 < 0 || x0 > x1 || x1 > GDT_COORD_MAX || y < 0 || y > GDT_COORD_MAX)
        return 0;
    if (st != NULL)
        st->orient_calls++;
    if (!disk_approx(a, b, c, &xc, &yc, &r, &slack)) {
        /* clockwise: the same disk, counter-clockwise from here on */
        tmp = b;
        b = c;
        c = tmp;
        if (!disk_approx(a, b, c, &xc, &yc, &r, &slack))
            return 0;
    }
    xlo = (xc - r) - slack;
    xhi = (xc + r) + slack;
    yhi = (yc + r) + slack;
    if (yhi < (double)y || xhi < (double)x0 || xlo > (double)x1)
        return 1;
    if (!(yc + slack < (double)y))
        return 0;
    if (xc + slack < (double)x0)
        corner.x = x0;
    else if (xc - slack > (double)x1)
        corner.x = x1;
    else
        return 0;
    corner.y = y;
    return gdt_incircle(st, a, b, c, corner) < 0;
}

/* ---------------------------------------------------------------------
 * Half-lattice points (gdt_predicates.h: doubled coordinates, 128 bits).
 * ------------------------------------------------------------------- */

#define HALF_IN_RANGE(p)                                                                      \
    ((p).x >= -GDT_HALF_MAX && (p).x <= GDT_HALF_MAX && (p).y >= -GDT_HALF_MAX              \
     && (p).y <= GDT_HALF_MAX)

static gdt_i128 half_det(gdt_hpt a, gdt_hpt b, gdt_hpt p)
{
    return (gdt_i128)(b.x - a.x) * (gdt_i128)(p.y - a.y) -
           (gdt_i128)(b.y - a.y) * (gdt_i128)(p.x - a.x);
}

/* Whether the directed edge u -> v owns the points of its line. */
static int edge_owned(gdt_hpt u, gdt_hpt v)
{
    return v.y < u.y || (v.y == u.y && v.x > u.x);
}

int gdt_edge_owns_half(gdt_pred_stats *st, gdt_hpt u, gdt_hpt v, gdt_hpt p)
{
    gdt_i128 d;
    assert(HALF_IN_RANGE(u) && HALF_IN_RANGE(v) && HALF_IN_RANGE(p));
    if (st != NULL)
        st->orient_calls++;
    d = half_det(u, v, p);
    return d > 0 || (d == 0 && edge_owned(u, v));
}

/* ceil(n / d) for d > 0.  Both usually fit 64 bits (an edge of a tile
 * and a row near it), and a 64-bit division is several times cheaper than
 * the 128-bit library call; the result is the same exact integer. */
static gdt_i128 ceil_div128(gdt_i128 n, gdt_i128 d)
{
    if (n > -(gdt_i128)INT64_MAX && n < (gdt_i128)INT64_MAX && d < (gdt_i128)INT64_MAX) {
        int64_t n64 = (int64_t)n, d64 = (int64_t)d, q64 = n64 / d64;
        return (n64 % d64 != 0 && n64 > 0) ? q64 + 1 : q64;
    }
    gdt_i128 q = n / d;
    return (n % d != 0 && n > 0) ? q + 1 : q;
}

/* E(k) = (v - u) x (p_k - u) = E0 - ey dx k with E0 = ex (y - u.y) -
 * ey (x0 - u.x): linear in k, so the owned k form one interval:
 *   ey == 0: E is constant; all k or none;
 *   ey < 0 (the edge is owned, E(k) >= 0 wanted): k >= ceil(-E0 / (-ey dx));
 *   ey > 0 (not owned, E(k) > 0 wanted): k < E0 / (ey dx), i.e.
 *           k <= ceil(E0 / (ey dx)) - 1. */
void gdt_edge_owned_range(gdt_pred_stats *st, gdt_hpt u, gdt_hpt v, int64_t x0, int64_t dx,
                          int64_t y, int64_t *lo, int64_t *hi)
{
    gdt_i128 ex = (gdt_i128)v.x - u.x, ey = (gdt_i128)v.y - u.y;
    gdt_i128 e0, a, bound;

    assert(HALF_IN_RANGE(u) && HALF_IN_RANGE(v) && dx > 0);
    if (st != NULL)
        st->orient_calls++;
    if (*lo > *hi)
        return;
    e0 = ex * ((gdt_i128)y - u.y) - ey * ((gdt_i128)x0 - u.x);
    if (ey == 0) {
        if (!(e0 > 0 || (e0 == 0 && edge_owned(u, v))))
            *hi = *lo - 1;
        return;
    }
    if (ey < 0) {
        a = -ey * dx;
        bound = ceil_div128(-e0, a);
        if (bound > *lo)
            *lo = bound > *hi ? *hi : (int64_t)bound;
        if (bound > *hi)
            *hi = *lo - 1;
    } else {
        a = ey * dx;
        bound = ceil_div128(e0, a) - 1;
        if (bound < *hi)
            *hi = bound < *lo ? *lo - 1 : (int64_t)bound;
    }
}

/* ---------------------------------------------------------------------
 * Floating-point environment self-test.
 *
 * Every probe reads its operands through volatile objects, so the compiler
 * must emit the arithmetic exactly as the flags of this translation unit
 * allow; algebraic rewriting (fast-math) and fusing (contraction) then show
 * up as wrong values at run time.
 * ------------------------------------------------------------------- */

/* a*b - c with c = fl(a*b): 0 when a*b is rounded on its own, the rounding
 * error 2^-60 when the product is fused into the subtraction.  Tried in the
 * one-expression form and in the named-temporaries form the filter uses. */
static unsigned probe_contraction(void)
{
    volatile double va = 1.0 + 0x1p-30, vb = 1.0 + 0x1p-30;
    volatile double vc = va * vb;
    double a = va, b = vb, c = vc;
    double r1 = a * b - c;
    double x = va, y = vb, z = va, w = vb;
    double p = x * y, q = z * w;
    double r2 = p - q;
    return (r1 != 0.0 || r2 != 0.0) ? GDT_FPENV_CONTRACTION : 0u;
}

/* (1 + 2^-60) - 1 is 0 in binary64; reassociation gives 2^-60 (so do
 * extended-precision intermediates).  The two-sum error-free transform of
 * 1 + 3 2^-54 must give s = 1 + 2^-52, err = -2^-54 exactly; simplifying
 * (x + y) - x to y destroys err. */
static unsigned probe_reassociation(void)
{
    volatile double vone = 1.0, vtiny = 0x1p-60;
    double one = vone, tiny = vtiny;
    double r = (one + tiny) - one;

    volatile double vx = 1.0, vy = 3.0 * 0x1p-54;
    double x = vx, y = vy;
    double s = x + y;
    double bv = s - x;
    double av = s - bv;
    double err = (x - av) + (y - bv);

    volatile double veps = 1.0;
    double eps = veps, check = 1.0, last;
    /* Halve until 1 + eps is no longer distinguishable from 1: in binary64
     * with round to nearest this stops at eps = 2^-53. */
    do {
        last = check;
        eps *= 0.5;
        check = vone + eps;
    } while (check != 1.0 && check != last);

    int bad = r != 0.0 || s != 1.0 + 0x1p-52 || err != -0x1p-54 || eps != 0x1p-53;
    return bad ? GDT_FPENV_REASSOC : 0u;
}

/* Round to nearest (ties to even) is assumed by the error bound. */
static unsigned probe_rounding(void)
{
    volatile double vone = 1.0, vabove = 0x1p-53 + 0x1p-60, vhalf = 0x1p-53;
    double one = vone, above = vabove, half = vhalf;
    double up = one + above;   /* nearest: 1 + 2^-52; towards zero or down: 1 */
    double down = -one - above; /* nearest: -(1 + 2^-52); towards zero or up: -1 */
    double tie = one + half;    /* ties to even: 1 */
    int bad = up != 1.0 + 0x1p-52 || down != -(1.0 + 0x1p-52) || tie != 1.0;
    return bad ? GDT_FPENV_ROUNDING : 0u;
}

/* Known 128-bit products, computed through the portable halves. */
static unsigned probe_int128(void)
{
    volatile gdt_x_u64 vmax = ~(gdt_x_u64)0;
    volatile gdt_x_u64 vg = UINT64_C(0x9e3779b97f4a7c15), vh = UINT64_C(0xc2b2ae3d27d4eb4f);
    volatile gdt_x_i64 vs = -((INT64_C(1) << 62) + 3), vt = (INT64_C(1) << 62) + 5;
    gdt_x128 m = gdt_x128_umul(vmax, vmax);
    gdt_x128 g = gdt_x128_umul(vg, vh);
    gdt_x128 s = gdt_x128_smul(vs, vt);
    int bad = m.hi != UINT64_C(0xfffffffffffffffe) || m.lo != 1
              || g.hi != UINT64_C(0x78547880b6031473) || g.lo != UINT64_C(0xf58d71ae9c47917b)
              || s.hi != UINT64_C(0xeffffffffffffffd) || s.lo != UINT64_C(0xfffffffffffffff1)
              || gdt_x128_sign(s) != -1;
    return bad ? GDT_FPENV_INT128 : 0u;
}

/* Near-degenerate in-circle cases at extreme coordinates: exactly
 * co-circular quads (box corners, Pythagorean points on circles of radius
 * about 2^30) and their +-1 perturbations, with their known signs.  The
 * integer path must give the known sign; the filter must either give it
 * too or stay undecided. */
#define PRED_L INT64_C(2147483647)
#define PRED_C (INT64_C(1) << 30)
#define PRED_K INT64_C(200000000)
#define PRED_M INT64_C(37000000)
static const gdt_x_i64 probe_cases[][9] = {
    {0, 0, PRED_L, 0, PRED_L, PRED_L, 0, PRED_L, 0},
    {0, 0, PRED_L, 0, PRED_L, PRED_L, 0, PRED_L - 1, 1},
    {0, 0, PRED_L, 0, PRED_L, PRED_L, 1, PRED_L, 1},
    {1, 1, PRED_L, 0, PRED_L, PRED_L, 0, PRED_L, -1},
    {0, 1, PRED_L, 0, PRED_L, PRED_L, 0, PRED_L, -1},
    {PRED_C + 3 * PRED_K, PRED_C + 4 * PRED_K, PRED_C - 4 * PRED_K, PRED_C + 3 * PRED_K,
     PRED_C - 5 * PRED_K, PRED_C, PRED_C, PRED_C - 5 * PRED_K, 0},
    {PRED_C + 3 * PRED_K, PRED_C + 4 * PRED_K, PRED_C - 4 * PRED_K, PRED_C + 3 * PRED_K,
     PRED_C - 5 * PRED_K, PRED_C, PRED_C, PRED_C - 5 * PRED_K + 1, 1},
    {PRED_C + 3 * PRED_K, PRED_C + 4 * PRED_K, PRED_C - 4 * PRED_K, PRED_C + 3 * PRED_K,
     PRED_C - 5 * PRED_K, PRED_C, PRED_C, PRED_C - 5 * PRED_K - 1, -1},
    {PRED_C + 20 * PRED_M, PRED_C + 21 * PRED_M, PRED_C - 21 * PRED_M, PRED_C + 20 * PRED_M,
     PRED_C - 20 * PRED_M, PRED_C - 21 * PRED_M, PRED_C + 21 * PRED_M, PRED_C - 20 * PRED_M, 0},
    {PRED_C + 20 * PRED_M, PRED_C + 21 * PRED_M, PRED_C - 21 * PRED_M, PRED_C + 20 * PRED_M,
     PRED_C - 20 * PRED_M, PRED_C - 21 * PRED_M, PRED_C + 21 * PRED_M - 1, PRED_C - 20 * PRED_M, 1},
    {PRED_C + 20 * PRED_M, PRED_C + 21 * PRED_M, PRED_C - 21 * PRED_M, PRED_C + 20 * PRED_M,
     PRED_C - 20 * PRED_M, PRED_C - 21 * PRED_M, PRED_C + 21 * PRED_M + 1, PRED_C - 20 * PRED_M, -1},
    {PRED_C + 20 * PRED_M + 1, PRED_C + 21 * PRED_M, PRED_C - 21 * PRED_M, PRED_C + 20 * PRED_M,
     PRED_C - 20 * PRED_M, PRED_C - 21 * PRED_M, PRED_C + 21 * PRED_M, PRED_C - 20 * PRED_M, 1},
};

static unsigned probe_filter(void)
{
    unsigned faults = 0;
    size_t n = sizeof probe_cases / sizeof probe_cases[0];
    for (size_t i = 0; i < n; i++) {
        volatile const gdt_x_i64 *v = probe_cases[i];
        gdt_x_i64 adx = v[0] - v[6], ady = v[1] - v[7];
        gdt_x_i64 bdx = v[2] - v[6], bdy = v[3] - v[7];
        gdt_x_i64 cdx = v[4] - v[6], cdy = v[5] - v[7];
        int want = (int)v[8];
        int exact = gdt_x_incircle_exact_d(adx, ady, bdx, bdy, cdx, cdy);
        int filt = gdt_x_incircle_filter_d(adx, ady, bdx, bdy, cdx, cdy);
        if (exact != want)
            faults |= GDT_FPENV_INT128;
        if (filt != GDT_X_UNDECIDED && filt != want)
            faults |= GDT_FPENV_FILTER;
    }
    return faults;
}

gdt_status gdt_predicates_selftest(unsigned *faults, gdt_error *err)
{
    unsigned f = probe_contraction() | probe_reassociation() | probe_rounding() | probe_int128()
                 | probe_filter();
    if (faults != NULL)
        *faults = f;
    if (f != 0)
        return gdt_error_set(
            err, GDT_EINTERNAL, 7601,
            "core/predicates.c: floating-point environment breaks the exact predicates "
            "(faults 0x%x:%s%s%s%s%s); rebuild without fast-math or FP contraction options and "
            "run with the default rounding mode",
            f, (f & GDT_FPENV_CONTRACTION) ? " contraction" : "",
            (f & GDT_FPENV_REASSOC) ? " reassociation-or-extended-precision" : "",
            (f & GDT_FPENV_ROUNDING) ? " rounding-mode" : "",
            (f & GDT_FPENV_FILTER) ? " filter-disagrees" : "",
            (f & GDT_FPENV_INT128) ? " integer-arithmetic" : "");
    return GDT_OK;
}
