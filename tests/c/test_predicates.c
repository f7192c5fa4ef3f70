/* test_predicates — unit tests of the exact predicates module.
 *
 * 1. The floating-point environment self-test passes (this build must be
 *    sane; a build with contraction or fast-math fails here).
 * 2. The portable 128-bit arithmetic of kernels/gdt_exact.clh equals the
 *    compiler's unsigned __int128 on seeded random and boundary values.
 * 3. orient2d and incircle equal an independent __int128 evaluation (another
 *    expansion of the determinant) on random, clustered, co-circular and
 *    extreme-coordinate cases; the double filter never contradicts the
 *    integer path and decides almost all random cases.
 * 4. The Dyken-Floater tie-break: square and rectangular grid cells keep the
 *    (1,1) diagonal, and for co-circular quads under all 8 symmetries of the
 *    square exactly one diagonal is stable and it is the one an angle
 *    computation prefers.
 * Deterministic: every generator is seeded.
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_check.h"
#include "gdt_predicates.h"

#include "../../kernels/gdt_exact.clh"

#if !defined(__SIZEOF_INT128__)
int main(void)
{
    printf("test_predicates: SKIP (the compiler has no __int128 reference)\n");
    return 77;
}
#else

typedef unsigned __int128 u128;
typedef __int128 i128;

#define L GDT_COORD_MAX

static gdt_checks checks;

#define CHECK(cond, ...) GDT_CHECK_QUIET_AFTER(&checks, 20, cond, __VA_ARGS__)

/* splitmix64: small, seedable, good enough to spread test values. */
typedef struct rng {
    uint64_t s;
} rng;

static uint64_t rng_next(rng *r) { return gdt_splitmix64(&r->s); }

/* Uniform in [lo, hi] (hi - lo < 2^63). */
static int64_t rng_range(rng *r, int64_t lo, int64_t hi)
{
    return lo + (int64_t)(rng_next(r) % (uint64_t)(hi - lo + 1));
}

/* A 64-bit value biased towards the boundaries of the arithmetic. */
static uint64_t rng_u64_edgy(rng *r)
{
    static const uint64_t special[] = {0,
                                       1,
                                       2,
                                       UINT64_C(0xffffffff),
                                       UINT64_C(0x100000000),
                                       UINT64_C(0x7fffffffffffffff),
                                       UINT64_C(0x8000000000000000),
                                       UINT64_C(0xfffffffffffffffe),
                                       UINT64_C(0xffffffffffffffff),
                                       UINT64_C(0xffffffff00000000),
                                       UINT64_C(0x00000000ffffffff)};
    uint64_t k = rng_next(r) % 8;
    if (k == 0)
        return special[rng_next(r) % (sizeof special / sizeof special[0])];
    if (k == 1)
        return rng_next(r) >> (rng_next(r) % 64);
    return rng_next(r);
}

static u128 to_u128(gdt_x128 v)
{
    return ((u128)v.hi << 64) | v.lo;
}

static gdt_x128 from_u128(u128 v)
{
    return gdt_x128_make((gdt_x_u64)(v >> 64), (gdt_x_u64)v);
}

static int sign_u128(u128 v)
{
    if (v >> 127)
        return -1;
    return v != 0;
}

static void test_selftest(void)
{
    unsigned faults = 0xffu;
    gdt_error err;
    gdt_error_clear(&err);
    gdt_status st = gdt_predicates_selftest(&faults, &err);
    printf("selftest: status %d faults 0x%x\n", (int)st, faults);
    if (st != GDT_OK)
        gdt_error_print(&err, stdout);
    CHECK(st == GDT_OK, "self-test: %s", err.msg);
    CHECK(faults == 0, "faults 0x%x", faults);
    CHECK(st == GDT_OK || err.code == 7601, "message number %d", err.code);
}

static void test_int128(void)
{
    rng r = {1};
    const int n = 1000000;
    for (int i = 0; i < n; i++) {
        uint64_t a = rng_u64_edgy(&r), b = rng_u64_edgy(&r);
        u128 p = (u128)a * b;
        CHECK(gdt_x_umul_hi(a, b) == (uint64_t)(p >> 64), "umul_hi %llx %llx",
              (unsigned long long)a, (unsigned long long)b);
        CHECK(to_u128(gdt_x128_umul(a, b)) == p, "umul");
        int64_t sa = (int64_t)a, sb = (int64_t)b;
        /* smul is specified for |a b| <= 2^126, i.e. not both INT64_MIN. */
        if (!(sa == INT64_MIN && sb == INT64_MIN)) {
            i128 sp = (i128)sa * sb;
            CHECK(to_u128(gdt_x128_smul(sa, sb)) == (u128)sp, "smul %lld %lld", (long long)sa,
                  (long long)sb);
        }
        CHECK(to_u128(gdt_x128_from_i64(sa)) == (u128)(i128)sa, "from_i64");
        CHECK(gdt_x_uabs(sa) == (sa < 0 ? (uint64_t)0 - (uint64_t)sa : (uint64_t)sa), "uabs");

        u128 x = ((u128)rng_u64_edgy(&r) << 64) | rng_u64_edgy(&r);
        u128 y = ((u128)rng_u64_edgy(&r) << 64) | rng_u64_edgy(&r);
        if (i % 16 == 0)
            y = x; /* equal operands for the comparisons */
        gdt_x128 gx = from_u128(x), gy = from_u128(y);
        CHECK(to_u128(gdt_x128_add(gx, gy)) == x + y, "add");
        CHECK(to_u128(gdt_x128_sub(gx, gy)) == x - y, "sub");
        CHECK(to_u128(gdt_x128_neg(gx)) == (u128)0 - x, "neg");
        CHECK(gdt_x128_sign(gx) == sign_u128(x), "sign");
        CHECK(gdt_x128_ucmp(gx, gy) == ((x > y) - (x < y)), "ucmp");
    }
    printf("int128: %d random cases against unsigned __int128\n", n);
}

/* Reference in-circle: expansion of the same 3x3 determinant along its first
 * column instead of the lifted column, in wrapping unsigned __int128; the
 * true value is below 2^127 in magnitude, so the wrapped result has its sign. */
static int ref_incircle(gdt_ipt a, gdt_ipt b, gdt_ipt c, gdt_ipt d)
{
    u128 adx = (u128)(i128)(a.x - d.x), ady = (u128)(i128)(a.y - d.y);
    u128 bdx = (u128)(i128)(b.x - d.x), bdy = (u128)(i128)(b.y - d.y);
    u128 cdx = (u128)(i128)(c.x - d.x), cdy = (u128)(i128)(c.y - d.y);
    u128 al = adx * adx + ady * ady, bl = bdx * bdx + bdy * bdy, cl = cdx * cdx + cdy * cdy;
    u128 det = adx * (bdy * cl - bl * cdy) - bdx * (ady * cl - al * cdy) + cdx * (ady * bl - al * bdy);
    return sign_u128(det);
}

static int ref_orient(gdt_ipt a, gdt_ipt b, gdt_ipt c)
{
    i128 det = (i128)(b.x - a.x) * (c.y - a.y) - (i128)(b.y - a.y) * (c.x - a.x);
    return (det > 0) - (det < 0);
}

static gdt_ipt pt(int64_t x, int64_t y)
{
    gdt_ipt p = {x, y};
    return p;
}

static int64_t clamp_coord(int64_t v)
{
    return v < 0 ? 0 : (v > L ? L : v);
}

/* Extreme coordinates: the two ends of the range and their neighbours. */
static int64_t rng_coord_edgy(rng *r)
{
    static const int64_t special[] = {0, 1, 2, L - 2, L - 1, L, (L + 1) / 2, (L - 1) / 2};
    return special[rng_next(r) % (sizeof special / sizeof special[0])];
}

/* The 8 symmetries of the square: swap x/y (bit 2), negate x (bit 0),
 * negate y (bit 1).  Returns whether the map reverses orientation. */
static int apply_sym(int t, int64_t x, int64_t y, int64_t *ox, int64_t *oy)
{
    if (t & 4) {
        int64_t s = x;
        x = y;
        y = s;
    }
    if (t & 1)
        x = -x;
    if (t & 2)
        y = -y;
    *ox = x;
    *oy = y;
    return ((t & 4) != 0) ^ ((t & 1) != 0) ^ ((t & 2) != 0);
}

/* All 36 lattice points of x^2 + y^2 = 65^2, counter-clockwise by angle
 * (from the images of the first-octant points under the square's symmetries). */
static int circle65(int64_t (*out)[2])
{
    static const int64_t oct[][2] = {{65, 0}, {63, 16}, {60, 25}, {56, 33}, {52, 39}};
    int n = 0;
    /* Build all sign/swap images, then sort by angle. */
    int64_t tmp[64][2];
    for (size_t i = 0; i < sizeof oct / sizeof oct[0]; i++) {
        for (int t = 0; t < 8; t++) {
            int64_t x, y;
            apply_sym(t, oct[i][0], oct[i][1], &x, &y);
            int dup = 0;
            for (int k = 0; k < n; k++)
                if (tmp[k][0] == x && tmp[k][1] == y)
                    dup = 1;
            if (!dup) {
                tmp[n][0] = x;
                tmp[n][1] = y;
                n++;
            }
        }
    }
    /* Insertion sort by angle (small integers: atan2 orders them exactly). */
    for (int i = 1; i < n; i++) {
        int64_t x = tmp[i][0], y = tmp[i][1];
        double ang = atan2((double)y, (double)x);
        int j = i - 1;
        while (j >= 0 && atan2((double)tmp[j][1], (double)tmp[j][0]) > ang) {
            tmp[j + 1][0] = tmp[j][0];
            tmp[j + 1][1] = tmp[j][1];
            j--;
        }
        tmp[j + 1][0] = x;
        tmp[j + 1][1] = y;
    }
    memcpy(out, tmp, sizeof(int64_t) * 2 * (size_t)n);
    return n;
}

static void test_orient_incircle(gdt_pred_stats *st)
{
    rng r = {2};
    const int n = 1200000;
    uint64_t undecided_random = 0, random_cases = 0, co_exact = 0, co_small = 0;
    for (int i = 0; i < n; i++) {
        gdt_ipt p[4];
        int kind = i % 6;
        if (kind == 0) { /* uniform over the whole range */
            for (int k = 0; k < 4; k++)
                p[k] = pt(rng_range(&r, 0, L), rng_range(&r, 0, L));
        } else if (kind == 1) { /* extreme coordinates */
            for (int k = 0; k < 4; k++)
                p[k] = pt(rng_coord_edgy(&r), rng_coord_edgy(&r));
        } else if (kind == 2) { /* clustered, anywhere in the range */
            int64_t cx = rng_range(&r, 0, L), cy = rng_range(&r, 0, L);
            int64_t w = rng_range(&r, 1, 100000);
            for (int k = 0; k < 4; k++)
                p[k] = pt(clamp_coord(cx + rng_range(&r, -w, w)), clamp_coord(cy + rng_range(&r, -w, w)));
        } else if (kind == 3) { /* near-collinear triple, long edges */
            gdt_ipt a = pt(rng_range(&r, 0, L), rng_range(&r, 0, L));
            gdt_ipt b = pt(rng_range(&r, 0, L), rng_range(&r, 0, L));
            double t = (double)(rng_next(&r) >> 11) * 0x1p-53;
            p[0] = a;
            p[1] = b;
            p[2] = pt(clamp_coord(a.x + (int64_t)(t * (double)(b.x - a.x)) + rng_range(&r, -1, 1)),
                      clamp_coord(a.y + (int64_t)(t * (double)(b.y - a.y)) + rng_range(&r, -1, 1)));
            p[3] = pt(rng_range(&r, 0, L), rng_range(&r, 0, L));
        } else { /* co-circular (scaled circle of radius 65), maybe perturbed by +-1 */
            static int64_t circ[64][2];
            static int nc = 0;
            if (nc == 0) {
                nc = circle65(circ);
                CHECK(nc == 36, "circle of radius 65 has %d lattice points", nc);
            }
            /* Half the time small enough (130 * 31 < 4096) for the filter's
             * exact double evaluation, else only the integer path can say 0. */
            int64_t scale = (i / 6) % 2 ? rng_range(&r, 1, 31) : rng_range(&r, 32, L / 130);
            int64_t span = 65 * scale;
            int64_t cx = rng_range(&r, span, L - span), cy = rng_range(&r, span, L - span);
            for (int k = 0; k < 4; k++) {
                int j = (int)(rng_next(&r) % (uint64_t)nc);
                p[k] = pt(cx + circ[j][0] * scale, cy + circ[j][1] * scale);
            }
            if (kind == 5) {
                int k = (int)(rng_next(&r) % 4);
                p[k].x = clamp_coord(p[k].x + rng_range(&r, -1, 1));
                p[k].y = clamp_coord(p[k].y + rng_range(&r, -1, 1));
            }
        }
        int ro = ref_orient(p[0], p[1], p[2]);
        CHECK(gdt_orient2d(st, p[0], p[1], p[2]) == ro, "orient case %d", i);
        CHECK(gdt_orient2d(st, p[1], p[0], p[2]) == -ro, "orient antisymmetry case %d", i);

        int ri = ref_incircle(p[0], p[1], p[2], p[3]);
        uint64_t exact_before = st->incircle_exact;
        CHECK(gdt_incircle(st, p[0], p[1], p[2], p[3]) == ri, "incircle case %d kind %d", i, kind);
        int escalated = st->incircle_exact != exact_before;
        CHECK(gdt_incircle(st, p[1], p[0], p[2], p[3]) == -ri, "incircle antisymmetry case %d", i);
        CHECK(gdt_incircle(st, p[1], p[2], p[0], p[3]) == ri, "incircle rotation case %d", i);

        int f = gdt_x_incircle_filter_d(p[0].x - p[3].x, p[0].y - p[3].y, p[1].x - p[3].x,
                                        p[1].y - p[3].y, p[2].x - p[3].x, p[2].y - p[3].y);
        CHECK(f == GDT_X_UNDECIDED || f == ri, "filter contradicts exact, case %d kind %d", i, kind);
        if (kind == 0) {
            random_cases++;
            undecided_random += f == GDT_X_UNDECIDED;
        }
        if (kind == 4 && ri == 0) {
            /* Exactly co-circular: decided without the integer path iff
             * every difference is below 2^12 (exact double evaluation). */
            int64_t m = 0;
            for (int k = 0; k < 3; k++) {
                int64_t dx = llabs(p[k].x - p[3].x), dy = llabs(p[k].y - p[3].y);
                m = dx > m ? dx : m;
                m = dy > m ? dy : m;
            }
            CHECK(escalated == (m >= 4096), "co-circular case %d: max diff %lld escalated %d", i,
                  (long long)m, escalated);
            co_exact += escalated;
            co_small += !escalated;
        }
    }
    printf("incircle: %d cases; filter undecided on %llu of %llu uniform random cases\n", n,
           (unsigned long long)undecided_random, (unsigned long long)random_cases);
    printf("incircle: exactly co-circular: %llu decided by the exact double evaluation, %llu by "
           "the integer path\n",
           (unsigned long long)co_small, (unsigned long long)co_exact);
    CHECK(undecided_random * 1000 < random_cases, "filter too weak: %llu undecided",
          (unsigned long long)undecided_random);
    CHECK(co_small > 10000 && co_exact > 10000, "co-circular generator degenerate");
}


/* Angle in [0, pi/2] between the line of v and the line of d. */
static double line_angle(double vx, double vy, double dx, double dy)
{
    const double pi = acos(-1.0);
    double a = fmod(fabs(atan2(vy, vx) - atan2(dy, dx)), pi);
    return a > pi / 2 ? pi - a : a;
}

/* Expected tie-break from angles: +1 if e wins (smaller angle to (1,0),
 * then smaller angle to (1,1)), -1 if f wins, 0 if indistinguishable.
 * Only used on vectors small enough that distinct angles differ by far more
 * than the tolerance. */
static int angle_winner(gdt_ipt e, gdt_ipt f)
{
    const double tol = 1e-9;
    double e1 = line_angle((double)e.x, (double)e.y, 1, 0), f1 = line_angle((double)f.x, (double)f.y, 1, 0);
    if (fabs(e1 - f1) > tol)
        return e1 < f1 ? 1 : -1;
    double e2 = line_angle((double)e.x, (double)e.y, 1, 1), f2 = line_angle((double)f.x, (double)f.y, 1, 1);
    if (fabs(e2 - f2) > tol)
        return e2 < f2 ? 1 : -1;
    return 0;
}

/* The rule in unsigned __int128 (independent of the portable halves). */
static int ref_prefer(gdt_ipt e, gdt_ipt f)
{
    u128 ex2 = (u128)((i128)e.x * e.x), fx2 = (u128)((i128)f.x * f.x);
    u128 ee = (u128)((i128)e.x * e.x + (i128)e.y * e.y), ff = (u128)((i128)f.x * f.x + (i128)f.y * f.y);
    u128 l = ex2 * ff, r = fx2 * ee;
    if (l != r)
        return l > r ? 1 : -1;
    i128 es = (i128)e.x + e.y, fs = (i128)f.x + f.y;
    l = (u128)(es * es) * ff;
    r = (u128)(fs * fs) * ee;
    return (l > r) - (l < r);
}

static gdt_ipt vsub(gdt_ipt a, gdt_ipt b)
{
    return pt(a.x - b.x, a.y - b.y);
}

static void test_grid_cells(gdt_pred_stats *st)
{
    static const int64_t sizes[][2] = {{1, 1}, {3, 3}, {4096, 4096}, {1 << 20, 1 << 20},
                                       {L / 16, L / 16}, {1, 2}, {7, 3}, {1000, 999},
                                       {L / 16, 5}, {2, L / 16}};
    int cells = 0;
    for (size_t k = 0; k < sizeof sizes / sizeof sizes[0]; k++) {
        int64_t sx = sizes[k][0], sy = sizes[k][1];
        int64_t origins[3][2] = {{0, 0}, {L - 16 * sx, L - 16 * sy}, {(L - 16 * sx) / 3, (L - 16 * sy) / 7}};
        for (int o = 0; o < 3; o++) {
            for (int i = 0; i < 16; i++) {
                for (int j = 0; j < 16; j++) {
                    int64_t x0 = origins[o][0] + i * sx, y0 = origins[o][1] + j * sy;
                    gdt_ipt ll = pt(x0, y0), lr = pt(x0 + sx, y0), ul = pt(x0, y0 + sy),
                            ur = pt(x0 + sx, y0 + sy);
                    uint64_t tb = st->tiebreak_calls;
                    /* Edge ll-ur (the (1,1) diagonal) with triangles (ll, ur, ul)
                     * and (ur, ll, lr): locally optimal. */
                    CHECK(gdt_edge_needs_flip(st, ll, ur, ul, lr) == 0,
                          "cell %lldx%lld at (%lld,%lld): (1,1) diagonal flipped", (long long)sx,
                          (long long)sy, (long long)x0, (long long)y0);
                    /* Edge lr-ul with triangles (lr, ul, ll) and (ul, lr, ur):
                     * must be flipped to ll-ur. */
                    CHECK(gdt_edge_needs_flip(st, lr, ul, ll, ur) == 1,
                          "cell %lldx%lld at (%lld,%lld): (1,-1) diagonal kept", (long long)sx,
                          (long long)sy, (long long)x0, (long long)y0);
                    CHECK(st->tiebreak_calls == tb + 2, "tie-break not counted");
                    CHECK(gdt_prefer_diagonal(NULL, vsub(ur, ll), vsub(ul, lr)) == 1, "prefer");
                    cells++;
                }
            }
        }
    }
    printf("tie-break: %d grid cells keep the (1,1) diagonal\n", cells);
}


/* Checks one convex co-circular quad q (counter-clockwise, small integer
 * coordinates) under all 8 symmetries, two scales and two placements.
 * Returns the number of configurations checked. */
static int check_cocircular_quad(gdt_pred_stats *st, const int64_t q[4][2])
{
    int checked = 0;
    for (int t = 0; t < 8; t++) {
        int64_t tq[4][2];
        int rev = 0;
        for (int k = 0; k < 4; k++)
            rev = apply_sym(t, q[k][0], q[k][1], &tq[k][0], &tq[k][1]);
        if (rev) { /* keep counter-clockwise order */
            int64_t s0 = tq[1][0], s1 = tq[1][1];
            tq[1][0] = tq[3][0];
            tq[1][1] = tq[3][1];
            tq[3][0] = s0;
            tq[3][1] = s1;
        }
        int64_t mnx = tq[0][0], mny = tq[0][1], mxx = tq[0][0], mxy = tq[0][1];
        for (int k = 1; k < 4; k++) {
            mnx = tq[k][0] < mnx ? tq[k][0] : mnx;
            mny = tq[k][1] < mny ? tq[k][1] : mny;
            mxx = tq[k][0] > mxx ? tq[k][0] : mxx;
            mxy = tq[k][1] > mxy ? tq[k][1] : mxy;
        }
        gdt_ipt e0 = pt(tq[3][0] - tq[1][0], tq[3][1] - tq[1][1]); /* diagonal p1-p3 */
        gdt_ipt f0 = pt(tq[2][0] - tq[0][0], tq[2][1] - tq[0][1]); /* diagonal p0-p2 */
        int want = angle_winner(e0, f0);
        CHECK(want != 0, "diagonals of a convex quad have equal scores");
        int64_t span = (mxx - mnx) > (mxy - mny) ? (mxx - mnx) : (mxy - mny);
        int64_t scales[2] = {1, span > 0 ? (L / 2) / span : 1};
        for (int sc = 0; sc < 2; sc++) {
            for (int place = 0; place < 2; place++) {
                int64_t scale = scales[sc];
                gdt_ipt p[4];
                for (int k = 0; k < 4; k++) {
                    int64_t x = (tq[k][0] - mnx) * scale, y = (tq[k][1] - mny) * scale;
                    if (place == 1) { /* push against the top of the range */
                        x += L - (mxx - mnx) * scale;
                        y += L - (mxy - mny) * scale;
                    }
                    p[k] = pt(x, y);
                }
                CHECK(ref_orient(p[0], p[1], p[2]) > 0 && ref_orient(p[0], p[2], p[3]) > 0,
                      "test quad not counter-clockwise");
                CHECK(ref_incircle(p[0], p[1], p[2], p[3]) == 0, "test quad not co-circular");
                /* Edge p0-p2 (triangles p0,p2,p3 and p2,p0,p1): flip iff p1-p3 wins. */
                int flip1 = gdt_edge_needs_flip(st, p[0], p[2], p[3], p[1]);
                /* Edge p1-p3 (triangles p1,p3,p0 and p3,p1,p2): flip iff p0-p2 wins. */
                int flip2 = gdt_edge_needs_flip(st, p[1], p[3], p[0], p[2]);
                CHECK(flip1 == (want > 0) && flip2 == (want < 0),
                      "sym %d scale %lld place %d: flips %d %d, angles prefer %s", t,
                      (long long)scale, place, flip1, flip2, want > 0 ? "p1-p3" : "p0-p2");
                gdt_ipt e = vsub(p[3], p[1]), f = vsub(p[2], p[0]);
                CHECK(gdt_prefer_diagonal(st, e, f) == want, "prefer_diagonal sym %d", t);
                CHECK(gdt_prefer_diagonal(st, f, e) == -want, "prefer_diagonal antisymmetry");
                checked++;
            }
        }
    }
    return checked;
}

static void test_cocircular_quads(gdt_pred_stats *st)
{
    int checked = 0;
    /* Rotated squares with side (p, q). */
    for (int64_t p = 0; p <= 6; p++) {
        for (int64_t q = 0; q <= 6; q++) {
            if (p == 0 && q == 0)
                continue;
            int64_t sq[4][2] = {{0, 0}, {p, q}, {p - q, q + p}, {-q, p}};
            checked += check_cocircular_quad(st, (const int64_t(*)[2])sq);
        }
    }
    /* A known case: the square with side (2, 1) keeps its more horizontal
     * diagonal, (-3, 1), in every image under the symmetries; those that swap
     * x and y make the other diagonal, the image of (1, 3), the horizontal one. */
    static const int64_t rot21[4][2] = {{0, 0}, {2, 1}, {1, 3}, {-1, 2}};
    checked += check_cocircular_quad(st, rot21);
    for (int t = 0; t < 8; t++) {
        int64_t a[4][2];
        for (int k = 0; k < 4; k++)
            apply_sym(t, rot21[k][0], rot21[k][1], &a[k][0], &a[k][1]);
        gdt_ipt d02 = pt(a[2][0] - a[0][0], a[2][1] - a[0][1]); /* (1,3) image */
        gdt_ipt d13 = pt(a[3][0] - a[1][0], a[3][1] - a[1][1]); /* (-3,1) image */
        CHECK(gdt_prefer_diagonal(st, d13, d02) == ((t & 4) ? -1 : 1),
              "rotated square (2,1), symmetry %d", t);
    }
    /* Rectangle diagonals: equal angle to (1,0), the one along (1,1) wins. */
    for (int64_t w = 1; w <= 9; w++)
        for (int64_t h = 1; h <= 9; h++)
            CHECK(gdt_prefer_diagonal(st, pt(w, h), pt(w, -h)) == 1
                      && gdt_prefer_diagonal(st, pt(-w, h), pt(-w, -h)) == -1,
                  "rectangle %lldx%lld", (long long)w, (long long)h);
    /* Random quads on the circle of radius 65. */
    int64_t circ[64][2];
    int nc = circle65(circ);
    rng r = {3};
    for (int it = 0; it < 3000; it++) {
        int idx[4];
        for (int k = 0; k < 4; k++) {
            int again;
            do {
                idx[k] = (int)(rng_next(&r) % (uint64_t)nc);
                again = 0;
                for (int j = 0; j < k; j++)
                    again |= idx[j] == idx[k];
            } while (again);
        }
        /* Sort the indices: circle65 lists the points counter-clockwise. */
        for (int a = 1; a < 4; a++)
            for (int b = a; b > 0 && idx[b - 1] > idx[b]; b--) {
                int s = idx[b];
                idx[b] = idx[b - 1];
                idx[b - 1] = s;
            }
        int64_t q[4][2];
        for (int k = 0; k < 4; k++) {
            q[k][0] = circ[idx[k]][0];
            q[k][1] = circ[idx[k]][1];
        }
        checked += check_cocircular_quad(st, (const int64_t(*)[2])q);
    }
    printf("tie-break: %d co-circular quad configurations (8 symmetries, 2 scales, 2 placements)\n",
           checked);
}

static void test_prefer_random(gdt_pred_stats *st)
{
    rng r = {4};
    const int n = 300000;
    int zero = 0;
    for (int i = 0; i < n; i++) {
        int64_t lim = (i % 3 == 0) ? 1000 : L;
        gdt_ipt e = pt(rng_range(&r, -lim, lim), rng_range(&r, -lim, lim));
        gdt_ipt f = pt(rng_range(&r, -lim, lim), rng_range(&r, -lim, lim));
        if (i % 7 == 0) /* mirror image: equal angle to (1,0) */
            f = pt(e.x, -e.y);
        if (i % 11 == 0) /* extreme components */
            e = pt(i % 2 ? L : -L, (i / 2) % 2 ? L : -L + 1);
        if (i % 13 == 0) { /* parallel */
            int64_t k = rng_range(&r, -3, 3);
            f = pt(e.x / 4 * k, e.y / 4 * k);
            e = pt(e.x / 4, e.y / 4);
        }
        int w = gdt_prefer_diagonal(st, e, f);
        CHECK(w == ref_prefer(e, f), "prefer vs __int128 case %d", i);
        CHECK(gdt_prefer_diagonal(st, f, e) == -w, "antisymmetry case %d", i);
        CHECK(gdt_prefer_diagonal(st, pt(-e.x, -e.y), f) == w, "direction invariance case %d", i);
        i128 cross = (i128)e.x * f.y - (i128)e.y * f.x;
        CHECK((w == 0) == (cross == 0), "zero iff parallel, case %d", i);
        int small = llabs(e.x) <= 1000 && llabs(e.y) <= 1000 && llabs(f.x) <= 1000 && llabs(f.y) <= 1000;
        if (small && cross != 0)
            CHECK(w == angle_winner(e, f), "prefer vs angles case %d: (%lld,%lld) (%lld,%lld) -> %d", i,
                  (long long)e.x, (long long)e.y, (long long)f.x, (long long)f.y, w);
        zero += w == 0;
    }
    printf("tie-break: %d random vector pairs (%d parallel)\n", n, zero);
    CHECK(zero > 1000, "parallel generator degenerate");
}

/* Off the circle the flip decision is the in-circle sign alone. */
static void test_flip_generic(gdt_pred_stats *st)
{
    rng r = {5};
    int n = 0;
    for (int it = 0; it < 100000; it++) {
        int64_t w = it % 2 ? 1000 : L;
        gdt_ipt p[4];
        for (int k = 0; k < 4; k++)
            p[k] = pt(rng_range(&r, 0, w), rng_range(&r, 0, w));
        /* Use the quad only when it is strictly convex in the order
         * a, d, b, c = p0, p1, p2, p3 (c-d crosses a-b). */
        gdt_ipt a = p[0], d = p[1], b = p[2], c = p[3];
        if (!(ref_orient(a, b, c) > 0 && ref_orient(b, a, d) > 0))
            continue;
        int ic = ref_incircle(a, b, c, d);
        if (ic == 0)
            continue;
        CHECK(gdt_edge_needs_flip(st, a, b, c, d) == (ic > 0), "flip vs incircle, case %d", it);
        n++;
    }
    printf("flip: %d generic edges agree with the in-circle sign\n", n);
    CHECK(n > 10000, "generic flip generator degenerate");
}

/* ---------------------------------------------------------------------
 * gdt_circumdisk_misses_strip against an exact oracle.
 * ------------------------------------------------------------------- */

/* r += v * 2^(64 k), r a 256-bit number in four 64-bit limbs (little end
 * first); the callers' sums stay below 2^256. */
static void acc64(uint64_t r[4], uint64_t v, int k)
{
    for (; k < 4 && v != 0; k++) {
        uint64_t s = r[k] + v;
        v = s < v;
        r[k] = s;
    }
}

static void acc128(uint64_t r[4], u128 v, int k)
{
    acc64(r, (uint64_t)v, k);
    acc64(r, (uint64_t)(v >> 64), k + 1);
}

/* r += v^2 for |v| < 2^127. */
static void acc_square(uint64_t r[4], i128 v)
{
    u128 m = v < 0 ? (u128)0 - (u128)v : (u128)v;
    uint64_t lo = (uint64_t)m, hi = (uint64_t)(m >> 64);
    acc128(r, (u128)lo * lo, 0);
    acc128(r, (u128)lo * hi, 1);
    acc128(r, (u128)lo * hi, 1);
    acc128(r, (u128)hi * hi, 2);
}

static int cmp256(const uint64_t a[4], const uint64_t b[4])
{
    for (int k = 3; k >= 0; k--)
        if (a[k] != b[k])
            return a[k] < b[k] ? -1 : 1;
    return 0;
}

/* p^2 + q^2 - (s^2 + t^2), as a sign. */
static int cmp_sums(i128 p, i128 q, i128 s, i128 t)
{
    uint64_t l[4] = {0, 0, 0, 0}, r[4] = {0, 0, 0, 0};
    acc_square(l, p);
    acc_square(l, q);
    acc_square(r, s);
    acc_square(r, t);
    return cmp256(l, r);
}

static i128 clamp128(i128 v, i128 lo, i128 hi)
{
    return v < lo ? lo : (v > hi ? hi : v);
}

/* Exact: does the closed circumdisk of a, b, c (not collinear) meet
 * Q = [x0, x1] x [y, +inf)?  With D = 2 det(b - a, c - a) (made positive)
 * the centre is O / D with O = a D + (n_x, n_y), the radius |(n_x, n_y)| / D;
 * the point of Q nearest to the centre is the centre clamped into Q, so the
 * disk meets Q iff |clamp(O) - O|^2 <= n_x^2 + n_y^2 (all scaled by D).
 * |O| < 2^96, so the squares need 256 bits.  Also checks that O / D is
 * equidistant from a, b and c (the oracle's own formula). */
static int oracle_meets(gdt_ipt a, gdt_ipt b, gdt_ipt c, int64_t x0, int64_t x1, int64_t y)
{
    i128 bx = b.x - a.x, by = b.y - a.y, cx = c.x - a.x, cy = c.y - a.y;
    i128 det = bx * cy - by * cx, bb = bx * bx + by * by, cc = cx * cx + cy * cy;
    i128 nx = cy * bb - by * cc, ny = bx * cc - cx * bb, d = 2 * det;
    i128 ox, oy;
    if (d < 0) {
        d = -d;
        nx = -nx;
        ny = -ny;
    }
    ox = (i128)a.x * d + nx;
    oy = (i128)a.y * d + ny;
    CHECK(cmp_sums((i128)b.x * d - ox, (i128)b.y * d - oy, nx, ny) == 0 &&
              cmp_sums((i128)c.x * d - ox, (i128)c.y * d - oy, nx, ny) == 0,
          "oracle centre not equidistant");
    return cmp_sums(clamp128(ox, (i128)x0 * d, (i128)x1 * d) - ox,
                    (oy > (i128)y * d ? oy : (i128)y * d) - oy, nx, ny) <= 0;
}

typedef struct strip_tally {
    uint64_t cases, meets, misses, proven, box_blind, box_blind_proven, lattice, lattice_proven;
} strip_tally;

/* One case: the predicate never claims a miss the oracle refutes; it does
 * not depend on the orientation; the tallies feed the strength checks. */
static void strip_case(gdt_pred_stats *st, strip_tally *t, gdt_ipt a, gdt_ipt b, gdt_ipt c,
                       int64_t x0, int64_t x1, int64_t y, int lattice, const char *kind)
{
    double box[4];
    int ccw, got, meets, box_misses;
    if (ref_orient(a, b, c) == 0) {
        CHECK(gdt_circumdisk_misses_strip(st, a, b, c, x0, x1, y) == 0, "%s: collinear", kind);
        return;
    }
    if (x0 > x1) {
        int64_t s = x0;
        x0 = x1;
        x1 = s;
    }
    got = gdt_circumdisk_misses_strip(st, a, b, c, x0, x1, y);
    meets = oracle_meets(a, b, c, x0, x1, y);
    CHECK(got == 0 || got == 1, "%s: result %d", kind, got);
    CHECK(!(got && meets),
          "%s: claims a miss, but the disk of (%lld %lld) (%lld %lld) (%lld %lld) meets "
          "[%lld, %lld] x [%lld, inf)",
          kind, (long long)a.x, (long long)a.y, (long long)b.x, (long long)b.y, (long long)c.x,
          (long long)c.y, (long long)x0, (long long)x1, (long long)y);
    CHECK(gdt_circumdisk_misses_strip(st, a, c, b, x0, x1, y) == got, "%s: orientation", kind);
    ccw = ref_orient(a, b, c) > 0;
    gdt_circumdisk_bounds(NULL, a, ccw ? b : c, ccw ? c : b, box);
    box_misses = box[3] < (double)y || box[2] < (double)x0 || box[0] > (double)x1;
    CHECK(!box_misses || got, "%s: the box misses Q, the predicate says %d", kind, got);
    t->cases++;
    t->meets += meets;
    if (!meets) {
        t->misses++;
        t->proven += got;
        t->box_blind += !box_misses;
        t->box_blind_proven += !box_misses && got;
        t->lattice += lattice;
        t->lattice_proven += lattice && got;
    }
}

/* v rounded to an integer, clamped to [-2, L + 2] first (centres of slivers
 * lie far outside the range). */
static int64_t round_near_range(double v)
{
    if (!(v > -2.0))
        return -2;
    if (v > (double)(L + 2))
        return L + 2;
    return (int64_t)llround(v);
}

/* A point of the circle of centre (ox, oy) and radius rad at angle th,
 * rounded, moved by up to j, clamped into the range. */
static gdt_ipt on_circle(rng *r, double ox, double oy, double rad, double th, int64_t j)
{
    return pt(clamp_coord(round_near_range(ox + rad * cos(th)) + rng_range(r, -j, j)),
              clamp_coord(round_near_range(oy + rad * sin(th)) + rng_range(r, -j, j)));
}

static void test_strip(gdt_pred_stats *st)
{
    const double pi = 3.14159265358979323846;
    rng r = {11};
    strip_tally t;
    const int n = 240000;
    memset(&t, 0, sizeof t);
    for (int i = 0; i < n; i++) {
        gdt_ipt p[3], q;
        int kind = i % 8;
        int64_t x0, x1, y, w;
        double ox, oy, rad, d, th;
        if (kind == 0) { /* uniform over the whole range */
            for (int k = 0; k < 3; k++)
                p[k] = pt(rng_range(&r, 0, L), rng_range(&r, 0, L));
        } else if (kind == 1) { /* small, anywhere, at the ends of the range too */
            int64_t bx =
                rng_next(&r) % 3 == 0 ? (rng_next(&r) % 2 ? 0 : L - 64) : rng_range(&r, 0, L - 64);
            int64_t by = rng_range(&r, 0, L - 64);
            for (int k = 0; k < 3; k++)
                p[k] = pt(bx + rng_range(&r, 0, 64), by + rng_range(&r, 0, 64));
        } else if (kind == 2 || kind == 3) { /* slivers: c next to the segment a-b */
            double s = (double)(rng_next(&r) >> 11) * 0x1p-53;
            int64_t ext = kind == 2 ? L : rng_range(&r, 100, 1 << 20);
            p[0] = pt(rng_range(&r, 0, L), rng_range(&r, 0, L));
            p[1] = pt(clamp_coord(p[0].x + rng_range(&r, -ext, ext)),
                      clamp_coord(p[0].y + rng_range(&r, -ext, ext)));
            p[2] = pt(clamp_coord(p[0].x + (int64_t)(s * (double)(p[1].x - p[0].x)) +
                                  rng_range(&r, -2, 2)),
                      clamp_coord(p[0].y + (int64_t)(s * (double)(p[1].y - p[0].y)) +
                                  rng_range(&r, -2, 2)));
        } else if (kind == 4) { /* a hull sliver on a west or east side: near-vertical */
            int64_t x = rng_next(&r) % 2 ? rng_range(&r, 0, 50) : rng_range(&r, L - 50, L);
            int64_t y0 = rng_range(&r, 0, L - 2000), len = rng_range(&r, 10, 1000);
            p[0] = pt(x, y0);
            p[1] = pt(clamp_coord(x + rng_range(&r, -3, 3)), y0 + 2 * len);
            p[2] = pt(clamp_coord(x + rng_range(&r, -3, 3)), y0 + rng_range(&r, 1, 2 * len - 1));
        } else { /* lattice circles: centre (cx, cy), radius 5k, points of 3-4-5 */
            int64_t k = kind == 5 ? rng_range(&r, 1, 1000) : rng_range(&r, 1, L / 12);
            int64_t cx = rng_range(&r, 5 * k, L - 5 * k), cy = rng_range(&r, 5 * k, L - 5 * k);
            int64_t a3 = 3 * k, a4 = 4 * k, a5 = 5 * k, e = rng_range(&r, -1, 1);
            if (kind == 7) { /* right angle: a diameter as an edge */
                p[0] = pt(cx - a5, cy);
                p[1] = pt(cx + a5, cy);
                p[2] = pt(cx - a3, cy - a4);
            } else {
                p[0] = pt(cx + a3, cy - a4);
                p[1] = pt(cx - a5, cy);
                p[2] = pt(cx + a4, cy - a3);
            }
            /* Q touching the circle at a lattice point, or 1 off */
            switch (rng_next(&r) % 4) {
            case 0: /* west corner (x0, y) = (cx + 4k, cy + 3k) */
                x0 = cx + a4 + (e > 0);
                y = cy + a3 + (e < 0);
                x1 = clamp_coord(x0 + rng_range(&r, 0, L / 4));
                break;
            case 1: /* east corner (x1, y) = (cx - 3k, cy + 4k) */
                x1 = cx - a3 - (e > 0);
                y = cy + a4 + (e < 0);
                x0 = clamp_coord(x1 - rng_range(&r, 0, L / 4));
                break;
            case 2: /* the top: (cx, cy + 5k) */
                y = cy + a5 + e;
                x0 = clamp_coord(cx - rng_range(&r, 0, a5));
                x1 = clamp_coord(cx + rng_range(&r, 0, a5));
                break;
            default: /* the east side: x0 = cx + 5k, y below the centre */
                x0 = cx + a5 + e;
                x1 = clamp_coord(x0 + rng_range(&r, 0, 1000));
                y = cy - rng_range(&r, 0, a5);
                break;
            }
            if (x0 >= 0 && x1 <= L && y >= 0 && y <= L)
                strip_case(st, &t, p[0], p[1], p[2], x0, x1, y, e != 0, "lattice circle");
            continue;
        }
        /* Q near the circle, from the double centre (only a generator) */
        {
            double bx = (double)(p[1].x - p[0].x), by = (double)(p[1].y - p[0].y);
            double cx = (double)(p[2].x - p[0].x), cy = (double)(p[2].y - p[0].y);
            double det = bx * cy - by * cx;
            if (det == 0.0)
                continue;
            ox = (double)p[0].x + (cy * (bx * bx + by * by) - by * (cx * cx + cy * cy)) / (2 * det);
            oy = (double)p[0].y + (bx * (cx * cx + cy * cy) - cx * (bx * bx + by * by)) / (2 * det);
            rad = hypot(ox - (double)p[0].x, oy - (double)p[0].y);
        }
        d = rad * (double)(rng_next(&r) % 2 ? 1e-3 : 1e-7) + 2.0;
        w = rng_range(&r, 0, L / 2);
        switch (rng_next(&r) % 5) {
        case 0: /* corner (x0, y) up and to the right of the centre */
            th = 0.5 * pi * (double)(rng_next(&r) >> 11) * 0x1p-53;
            q = on_circle(&r, ox, oy, rad + d * (double)rng_range(&r, -1, 1), th, 1);
            x0 = q.x;
            y = q.y;
            x1 = clamp_coord(x0 + w);
            break;
        case 1: /* corner (x1, y) up and to the left */
            th = 0.5 * pi * (1.0 + (double)(rng_next(&r) >> 11) * 0x1p-53);
            q = on_circle(&r, ox, oy, rad + d * (double)rng_range(&r, -1, 1), th, 1);
            x1 = q.x;
            y = q.y;
            x0 = clamp_coord(x1 - w);
            break;
        case 2: /* near the top */
            q = on_circle(&r, ox, oy, rad + d * (double)rng_range(&r, -1, 1), 0.5 * pi, 1);
            y = q.y;
            x0 = clamp_coord(q.x - w);
            x1 = clamp_coord(q.x + rng_range(&r, 0, L / 2));
            break;
        case 3: /* near the east or west side, the centre at or above y */
            th = rng_next(&r) % 2 ? 0.0 : pi;
            q = on_circle(&r, ox, oy, rad + d * (double)rng_range(&r, -1, 1), th, 1);
            y = clamp_coord(round_near_range(oy) - rng_range(&r, 0, (int64_t)fmin(rad, 1e9)));
            x0 = th == 0.0 ? q.x : clamp_coord(q.x - w);
            x1 = th == 0.0 ? clamp_coord(q.x + w) : q.x;
            break;
        default: /* anywhere */
            x0 = rng_range(&r, 0, L);
            x1 = rng_range(&r, 0, L);
            y = rng_range(&r, 0, L);
            break;
        }
        strip_case(st, &t, p[0], p[1], p[2], x0, x1, y, 0, "random");
    }
    printf("strip: %llu cases, %llu disks meet Q; of %llu misses %llu proven; %llu misses the "
           "box cannot see, %llu of them proven; %llu lattice misses 1 off the circle, %llu "
           "proven\n",
           (unsigned long long)t.cases, (unsigned long long)t.meets, (unsigned long long)t.misses,
           (unsigned long long)t.proven, (unsigned long long)t.box_blind,
           (unsigned long long)t.box_blind_proven, (unsigned long long)t.lattice,
           (unsigned long long)t.lattice_proven);
    /* the generator must produce both answers in bulk, and disks only the
     * corner test can separate from Q */
    CHECK(t.meets > t.cases / 5 && t.misses > t.cases / 5 && t.box_blind > t.cases / 20,
          "strip generator degenerate");
    CHECK(t.proven * 10 > t.misses * 9, "strip: too few misses proven");
    CHECK(t.box_blind_proven * 10 > t.box_blind * 9, "strip: the corner test proves too little");
    CHECK(t.lattice_proven * 100 > t.lattice * 99, "strip: lattice misses 1 off the circle");
    /* out-of-range arguments: undecided */
    CHECK(gdt_circumdisk_misses_strip(st, pt(0, 0), pt(10, 0), pt(0, 10), 100, 50, 1000) == 0 &&
              gdt_circumdisk_misses_strip(st, pt(0, 0), pt(10, 0), pt(0, 10), -1, 50, 1000) == 0 &&
              gdt_circumdisk_misses_strip(st, pt(0, 0), pt(10, 0), pt(0, 10), 0, L + 1, 1000) ==
                  0 &&
              gdt_circumdisk_misses_strip(st, pt(0, 0), pt(10, 0), pt(0, 10), 0, 50, L + 1) == 0 &&
              gdt_circumdisk_misses_strip(st, pt(0, 0), pt(10, 0), pt(0, 10), 0, 50, -1) == 0,
          "strip: arguments out of range");
    CHECK(gdt_circumdisk_misses_strip(st, pt(0, 0), pt(10, 0), pt(0, 10), 0, 50, 1000) == 1,
          "strip: a small disk far below Q");
}

/* ---------------------------------------------------------------------
 * gdt_circumdiameter_below against an exact oracle.
 * ------------------------------------------------------------------- */

/* Exact: 2R < m for the triangle (a, b, c), i.e. m^2 D^2 > |b'|^2 |c'|^2
 * |b' - c'|^2 with D = b' x c' > 0; 0 when D <= 0. */
static int oracle_diameter_below(gdt_ipt a, gdt_ipt b, gdt_ipt c, int64_t m)
{
    i128 bx = b.x - a.x, by = b.y - a.y, cx = c.x - a.x, cy = c.y - a.y;
    i128 det = bx * cy - by * cx;
    u128 bb, cc, ee, p;
    uint64_t l[4] = {0, 0, 0, 0}, r[4] = {0, 0, 0, 0};
    if (det <= 0 || m <= 0)
        return 0;
    bb = (u128)(bx * bx + by * by);
    cc = (u128)(cx * cx + cy * cy);
    ee = (u128)((bx - cx) * (bx - cx) + (by - cy) * (by - cy));
    p = bb * cc; /* < 2^126 */
    acc_square(l, (i128)m * det);
    acc128(r, (u128)(uint64_t)p * (uint64_t)ee, 0);
    acc128(r, (u128)(uint64_t)p * (uint64_t)(ee >> 64), 1);
    acc128(r, (u128)(uint64_t)(p >> 64) * (uint64_t)ee, 1);
    acc128(r, (u128)(uint64_t)(p >> 64) * (uint64_t)(ee >> 64), 2);
    return cmp256(l, r) > 0;
}

/* The filter never answers 1 where the oracle says 2R >= m (soundness), and
 * answers 1 wherever m exceeds 2R by a relative 1e-9 (it is not a filter that
 * gives up). */
static void test_circumdiameter(gdt_pred_stats *st)
{
    rng r = {UINT64_C(0x5eed0c1fc1e)};
    long sound = 0, decided = 0, boundary = 0;
    for (int i = 0; i < 400000; i++) {
        int64_t span = (int64_t)1 << rng_range(&r, 1, 31);
        int64_t x0 = rng_range(&r, 0, L), y0 = rng_range(&r, 0, L);
        gdt_ipt v[3];
        long double bx, by, cx, cy, d, dia;
        int64_t m0;
        for (int k = 0; k < 3; k++) {
            v[k].x = clamp_coord(x0 + rng_range(&r, -span, span));
            v[k].y = clamp_coord(y0 + rng_range(&r, -span, span));
        }
        if (i % 7 == 0)
            v[2] = v[1]; /* degenerate */
        bx = (long double)(v[1].x - v[0].x);
        by = (long double)(v[1].y - v[0].y);
        cx = (long double)(v[2].x - v[0].x);
        cy = (long double)(v[2].y - v[0].y);
        d = bx * cy - by * cx;
        if (d <= 0) {
            CHECK(gdt_circumdiameter_below(st, v[0], v[1], v[2], L) == 0,
                  "not counter-clockwise: answered 1");
            continue;
        }
        dia = sqrtl((bx * bx + by * by) * (cx * cx + cy * cy) *
                    ((bx - cx) * (bx - cx) + (by - cy) * (by - cy))) /
              d;
        if (dia > 4e15L)
            continue;
        m0 = (int64_t)dia;
        for (int64_t dm = -2; dm <= 3; dm++) {
            int64_t m = m0 + dm;
            int got = gdt_circumdiameter_below(st, v[0], v[1], v[2], m);
            int want = oracle_diameter_below(v[0], v[1], v[2], m);
            CHECK(!got || want, "(%lld,%lld) (%lld,%lld) (%lld,%lld) m %lld: 1, oracle 0",
                  (long long)v[0].x, (long long)v[0].y, (long long)v[1].x, (long long)v[1].y,
                  (long long)v[2].x, (long long)v[2].y, (long long)m);
            sound += want;
            if (m > 0 && (long double)m > dia * (1.0L + 1e-9L)) {
                CHECK(got, "m %lld, diameter %.6Lf: undecided", (long long)m, dia);
                decided += got;
            }
        }
    }
    /* Right triangles: the hypotenuse is the diameter, 10 s exactly. */
    for (int64_t s = 1; s <= (INT64_C(1) << 27); s = s * 3 + 1) {
        gdt_ipt a = pt(7, 11), b = pt(7 + 6 * s, 11), c = pt(7, 11 + 8 * s);
        CHECK(gdt_circumdiameter_below(st, a, b, c, 10 * s) == 0 &&
                  oracle_diameter_below(a, b, c, 10 * s) == 0,
              "right triangle, scale %lld: the diameter itself is not below", (long long)s);
        CHECK(gdt_circumdiameter_below(st, a, b, c, 10 * s + 1) == 1,
              "right triangle, scale %lld: 10 s + 1 is above", (long long)s);
        boundary++;
    }
    CHECK(gdt_circumdiameter_below(st, pt(0, 0), pt(10, 0), pt(0, 10), 0) == 0 &&
              gdt_circumdiameter_below(st, pt(0, 0), pt(10, 0), pt(0, 10), -5) == 0 &&
              gdt_circumdiameter_below(st, pt(0, 0), pt(10, 0), pt(0, 10), INT64_C(1) << 53) ==
                  0,
          "m out of range answered 1");
    printf("circumdiameter: %ld below by the oracle, %ld decided with margin, %ld boundary "
           "scales\n",
           sound, decided, boundary);
    CHECK(decided > 100000, "only %ld cases decided", decided);
}

int main(void)
{
    gdt_pred_stats st;
    memset(&st, 0, sizeof st);
    test_circumdiameter(&st);
    test_selftest();
    test_int128();
    test_orient_incircle(&st);
    test_grid_cells(&st);
    test_cocircular_quads(&st);
    test_prefer_random(&st);
    test_flip_generic(&st);
    test_strip(&st);
    printf("counters: orient %llu incircle %llu incircle_exact %llu tiebreak %llu\n",
           (unsigned long long)st.orient_calls, (unsigned long long)st.incircle_calls,
           (unsigned long long)st.incircle_exact, (unsigned long long)st.tiebreak_calls);
    return gdt_check_finish(&checks, "test_predicates");
}
#endif
