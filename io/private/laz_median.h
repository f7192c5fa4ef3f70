/* laz_median.h — the running median of five that the LASzip POINT10 v2 and
 * POINT14 decoders use to predict the X and Y differences.
 *
 * Invariant: v holds the last five values added (zeros before that) in
 * ascending order, so v[2] is their median.  The encoder does not keep the
 * true window: each insert drops an extreme, the largest while `high` is set
 * and the smallest otherwise; `high` is cleared by a value not below the
 * median and set again by a value not above it.  The decoder must drop exactly what the
 * encoder dropped, so this is the encoder's rule, not a sliding window. */
#ifndef GDT_LAZ_MEDIAN_H
#define GDT_LAZ_MEDIAN_H

#include <stdint.h>
#include <string.h>

typedef struct gdt_laz_median5 {
    int32_t v[5]; /* ascending */
    int high;     /* the next insert drops the largest value */
} gdt_laz_median5;

static inline void gdt_laz_median5_init(gdt_laz_median5 *m)
{
    memset(m->v, 0, sizeof m->v);
    m->high = 1;
}

static inline void gdt_laz_median5_add(gdt_laz_median5 *m, int32_t x)
{
    int32_t *v = m->v;

    if (m->high) {
        if (x < v[2]) {
            v[4] = v[3];
            v[3] = v[2];
            if (x < v[0]) {
                v[2] = v[1];
                v[1] = v[0];
                v[0] = x;
            } else if (x < v[1]) {
                v[2] = v[1];
                v[1] = x;
            } else {
                v[2] = x;
            }
        } else {
            if (x < v[3]) {
                v[4] = v[3];
                v[3] = x;
            } else {
                v[4] = x;
            }
            m->high = 0;
        }
    } else {
        if (v[2] < x) {
            v[0] = v[1];
            v[1] = v[2];
            if (v[4] < x) {
                v[2] = v[3];
                v[3] = v[4];
                v[4] = x;
            } else if (v[3] < x) {
                v[2] = v[3];
                v[3] = x;
            } else {
                v[2] = x;
            }
        } else {
            if (v[1] < x) {
                v[0] = v[1];
                v[1] = x;
            } else {
                v[0] = x;
            }
            m->high = 1;
        }
    }
}

#endif
