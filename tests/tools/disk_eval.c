/* disk_eval — prints gdt_circumdisk_bounds for triangles read from stdin,
 * for the test that checks the bounds exactly with rational arithmetic.
 *
 * Input: one triangle per line, "ax ay bx by cx cy" (integers in
 * [0, 2^31 - 1]).  Output per line: "0" when the triangle is not strictly
 * counter-clockwise, else "1 xmin ymin xmax ymax" in C99 hexadecimal
 * floating point (exact).  Exit 0, or 3 on malformed or out-of-range input. */
#include <inttypes.h>
#include <stdio.h>

#include "gdt_predicates.h"

int main(void)
{
    int64_t v[6];
    unsigned long line = 0;
    int got;
    while ((got = scanf("%" SCNd64 " %" SCNd64 " %" SCNd64 " %" SCNd64 " %" SCNd64 " %" SCNd64, &v[0],
                 &v[1], &v[2], &v[3], &v[4], &v[5])) == 6) {
        gdt_ipt a = {v[0], v[1]}, b = {v[2], v[3]}, c = {v[4], v[5]};
        double box[4];
        line++;
        for (int i = 0; i < 6; i++) {
            if (v[i] < 0 || v[i] > GDT_COORD_MAX) {
                fprintf(stderr, "disk_eval: line %lu: coordinate out of range\n", line);
                return 3;
            }
        }
        if (!gdt_circumdisk_bounds(NULL, a, b, c, box))
            printf("0\n");
        else
            printf("1 %a %a %a %a\n", box[0], box[1], box[2], box[3]);
    }
    if (got != EOF || !feof(stdin)) {
        fprintf(stderr, "disk_eval: line %lu: malformed input\n", line + 1);
        return 3;
    }
    return 0;
}
