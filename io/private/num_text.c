/* num_text.c — see num_text.h. */
#include "num_text.h"

#include <math.h> /* fabs */
#include <stdint.h>
#include <string.h>

__extension__ typedef unsigned __int128 nt_u128;

#define NT_TEN19 UINT64_C(10000000000000000000)

/* 10^0 .. 10^21: the scales s = P - 1 - X can take (P <= 17, X >= -4,
 * and one more for an estimate of X one too small). */
static const nt_u128 nt_p10[22] = {
    1u,
    10u,
    100u,
    1000u,
    10000u,
    100000u,
    1000000u,
    10000000u,
    100000000u,
    1000000000u,
    UINT64_C(10000000000),
    UINT64_C(100000000000),
    UINT64_C(1000000000000),
    UINT64_C(10000000000000),
    UINT64_C(100000000000000),
    UINT64_C(1000000000000000),
    UINT64_C(10000000000000000),
    UINT64_C(100000000000000000),
    UINT64_C(1000000000000000000),
    NT_TEN19,
    (nt_u128)NT_TEN19 * 10u,
    (nt_u128)NT_TEN19 * 100u,
};

/* floor(m 10^s / 2^k), s <= 21, 6 <= k <= 66. */
static nt_u128 scaled_floor(uint64_t m, int s, int k)
{
    return ((nt_u128)m * nt_p10[s]) >> k;
}

size_t gdt_num_text(char *out, double d)
{
    uint64_t bits, m;
    int k, x, neg;
    double a = fabs(d);
    char dig[17];
    char *p = out;

    /* !(...) also refuses NaN */
    if (!(a >= 1e-4 && a < 1e14))
        return 0;
    memcpy(&bits, &d, sizeof bits);
    neg = (int)(bits >> 63);
    /* a normal double here: a = m 2^-k, 2^52 <= m < 2^53; a >= 1e-4 > 2^-14
     * gives k <= 66, a < 1e14 < 2^47 gives k >= 6 */
    m = (bits & ((UINT64_C(1) << 52) - 1)) | (UINT64_C(1) << 52);
    k = 1075 - (int)((bits >> 52) & 0x7ff);

    /* X = floor(log10 a) exactly: an estimate from the binary exponent
     * (a = m 2^-k lies in [2^(52-k), 2^(53-k)); 78913 / 2^18 is log10(2)
     * rounded down; the division truncates toward zero), within one of X,
     * corrected by the exact 17-digit floor, which must lie in
     * [10^16, 10^17) */
    x = (52 - k) * 78913 / 262144;
    for (;;) {
        int s = 16 - x;
        nt_u128 q;
        if (s < 0 || s > 21)
            return 0; /* not for an a in range; kept as a guard */
        q = scaled_floor(m, s, k);
        if (q < nt_p10[16])
            x--;
        else if (q >= nt_p10[17])
            x++;
        else
            break;
    }

    for (int prec = 15; prec <= 17; prec++) {
        int s = prec - 1 - x, xr = x;
        const nt_u128 v = (nt_u128)m * nt_p10[s];
        nt_u128 n = v >> k, rem = v - (n << k), half = (nt_u128)1 << (k - 1), lhs, lo, hi;
        int inside;

        if (rem > half || (rem == half && (n & 1u) != 0))
            n++;
        if (n == nt_p10[prec]) { /* rounded up to the next power of ten */
            n = nt_p10[prec - 1];
            xr++;
            s--;
        }
        /* does n 10^-s read back as a? */
        lhs = n << (k + 2);
        lo = ((nt_u128)4 * m - (m == (UINT64_C(1) << 52) ? 1u : 2u)) * nt_p10[s];
        hi = ((nt_u128)4 * m + 2u) * nt_p10[s];
        inside = (lhs > lo && lhs < hi) || ((lhs == lo || lhs == hi) && (m & 1u) == 0);
        if (!inside && prec < 17)
            continue;
        if (!inside)
            return 0; /* 17 digits always read back; kept as a guard */

        /* the prec digits of n, then the text */
        {
            uint64_t nn = (uint64_t)n;
            for (int i = prec - 1; i >= 0; i--) {
                dig[i] = (char)('0' + nn % 10u);
                nn /= 10u;
            }
        }
        if (neg)
            *p++ = '-';
        if (xr >= 0) {
            memcpy(p, dig, (size_t)xr + 1);
            p += xr + 1;
            *p++ = '.';
            memcpy(p, dig + xr + 1, (size_t)(prec - 1 - xr));
            p += prec - 1 - xr;
        } else {
            *p++ = '0';
            *p++ = '.';
            for (int i = 0; i < -xr - 1; i++)
                *p++ = '0';
            memcpy(p, dig, (size_t)prec);
            p += prec;
        }
        while (p[-1] == '0')
            p--;
        if (p[-1] == '.')
            p--;
        *p = '\0';
        return (size_t)(p - out);
    }
    return 0;
}
