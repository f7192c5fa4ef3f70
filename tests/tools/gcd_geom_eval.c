/* gcd_geom_eval — evaluates the symbolic predicates of kernels/gcd_geom.clh
 * (the fake boundary at infinity) on the host, for the big-integer
 * comparison in tests/python/test_gcd.py.
 *
 * stdin, one case per line:  op cx cy P P P [P]
 *   op  o (orientation of 3 points) or i (in-circle of 4 points)
 *   cx cy  the centre of the fake boundary
 *   P   "f k" (fake k, 0..11) or "r x y" (a real point)
 * stdout: the sign, one line per case.  Exit 3 on malformed input. */
#include <stdio.h>

#include "gcd_geom.clh"

int main(void)
{
    char op[8];
    long long cx, cy;
    while (scanf("%7s %lld %lld", op, &cx, &cy) == 3) {
        gcd_spt p[4];
        int np = op[0] == 'o' ? 3 : 4;
        for (int i = 0; i < np; i++) {
            char kind[4];
            long long a, b;
            if (scanf("%3s", kind) != 1)
                return 3;
            if (kind[0] == 'f') {
                if (scanf("%lld", &a) != 1 || a < 0 || a >= GCD_NFAKE)
                    return 3;
                p[i] = gcd_spt_fake((int)a);
            } else {
                if (scanf("%lld %lld", &a, &b) != 2)
                    return 3;
                p[i] = gcd_spt_real(a, b, cx, cy);
            }
        }
        printf("%d\n", np == 3 ? gcd_orient(p[0], p[1], p[2]) : gcd_incircle(p[0], p[1], p[2], p[3]));
    }
    return 0;
}
