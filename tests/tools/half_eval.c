/* half_eval — evaluates the half-lattice predicates of gdt_predicates.h on
 * cases read from stdin, for the test that compares them with Python's big
 * integers (tests/python/test_dem.py).
 *
 * usage: half_eval
 * Input, one case per line (signed decimal integers):
 *   0 ax ay bx by px py                  -> gdt_orient2d_half_det, in decimal
 *   1 ux uy vx vy px py                  -> gdt_edge_owns_half, 0 or 1
 *   2 ux uy vx vy x0 dx y lo hi          -> gdt_edge_owned_range: "lo hi"
 * One output line per case.  Exit 0, or 3 on a malformed line or a
 * coordinate beyond GDT_HALF_MAX. */
#include <inttypes.h>
#include <stdio.h>
#include <string.h>

#include "gdt_predicates.h"

static void put_i128(gdt_i128 v)
{
    char buf[64];
    int n = 0, neg = v < 0;
    unsigned __int128 u = neg ? (unsigned __int128)0 - (unsigned __int128)v : (unsigned __int128)v;
    do {
        buf[n++] = (char)('0' + (int)(u % 10));
        u /= 10;
    } while (u != 0);
    if (neg)
        putchar('-');
    while (n > 0)
        putchar(buf[--n]);
    putchar('\n');
}

static int ok(int64_t v)
{
    return v >= -GDT_HALF_MAX && v <= GDT_HALF_MAX;
}

int main(void)
{
    char line[1024];
    while (fgets(line, sizeof line, stdin) != NULL) {
        int64_t v[10];
        int op, n;
        n = sscanf(line, "%d %" SCNd64 " %" SCNd64 " %" SCNd64 " %" SCNd64 " %" SCNd64
                   " %" SCNd64 " %" SCNd64 " %" SCNd64 " %" SCNd64 " %" SCNd64,
                   &op, &v[0], &v[1], &v[2], &v[3], &v[4], &v[5], &v[6], &v[7], &v[8], &v[9]);
        if (n < 1 || (op < 2 && n != 7) || (op == 2 && n != 10) || op < 0 || op > 2) {
            fprintf(stderr, "half_eval: malformed line: %s", line);
            return 3;
        }
        if (op == 2 && v[5] <= 0) {
            fprintf(stderr, "half_eval: dx must be positive: %s", line);
            return 3;
        }
        for (int i = 0; i < (op == 2 ? 5 : 6); i++)
            if (!ok(v[i]) || (op == 2 && i == 4 && !ok(v[6]))) {
                fprintf(stderr, "half_eval: coordinate out of range: %s", line);
                return 3;
            }
        {
            gdt_hpt a = {v[0], v[1]}, b = {v[2], v[3]}, p = {v[4], v[5]};
            if (op == 0) {
                put_i128(gdt_orient2d_half_det(NULL, a, b, p));
            } else if (op == 1) {
                printf("%d\n", gdt_edge_owns_half(NULL, a, b, p));
            } else {
                int64_t lo = v[7], hi = v[8];
                gdt_edge_owned_range(NULL, a, b, v[4], v[5], v[6], &lo, &hi);
                printf("%" PRId64 " %" PRId64 "\n", lo, hi);
            }
        }
    }
    return 0;
}
