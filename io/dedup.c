/* dedup.c — in-memory duplicate merge of lattice points (--dup policy). */
#include "gdt_cloud.h"

#include <stdlib.h>
#include <string.h>

int gdt_dup_policy_parse(const char *s, gdt_dup_policy *out)
{
    if (s == NULL)
        return -1;
    if (strcmp(s, "first") == 0)
        *out = GDT_DUP_FIRST;
    else if (strcmp(s, "min-z") == 0)
        *out = GDT_DUP_MIN_Z;
    else if (strcmp(s, "max-z") == 0)
        *out = GDT_DUP_MAX_Z;
    else
        return -1;
    return 0;
}

const char *gdt_dup_policy_name(gdt_dup_policy p)
{
    switch (p) {
    case GDT_DUP_FIRST: return "first";
    case GDT_DUP_MIN_Z: return "min-z";
    case GDT_DUP_MAX_Z: return "max-z";
    }
    return "unknown";
}

/* Monotone integer image of a non-NaN double (-0.0 sorts before +0.0), so
 * that the sort key is a total order even when ordinals repeat. */
static int64_t z_key(double z)
{
    int64_t b;
    memcpy(&b, &z, sizeof b);
    return b < 0 ? (int64_t)((uint64_t)b ^ INT64_MAX) : b;
}

/* Strict weak order on (x, y, ord, z); total for distinct records. */
static int point_less(const gdt_point *a, const gdt_point *b)
{
    if (a->x != b->x)
        return a->x < b->x;
    if (a->y != b->y)
        return a->y < b->y;
    if (a->ord != b->ord)
        return a->ord < b->ord;
    return z_key(a->z) < z_key(b->z);
}

/* Stable merge of the sorted runs src[lo..mid) and src[mid..hi) into dst. */
static void merge_runs(const gdt_point *src, gdt_point *dst, size_t lo, size_t mid, size_t hi)
{
    size_t i = lo, j = mid, o = lo;
    while (i < mid && j < hi)
        dst[o++] = point_less(&src[j], &src[i]) ? src[j++] : src[i++];
    while (i < mid)
        dst[o++] = src[i++];
    while (j < hi)
        dst[o++] = src[j++];
}

/* Bottom-up merge sort of pts[0..n) with tmp[0..n) as scratch; insertion
 * sort makes runs of RUN first.  Result is in pts. */
#define RUN 16
static void sort_points(gdt_point *pts, gdt_point *tmp, size_t n)
{
    gdt_point *src = pts, *dst = tmp;

    for (size_t lo = 0; lo < n; lo += RUN) {
        size_t hi = lo + RUN < n ? lo + RUN : n;
        for (size_t i = lo + 1; i < hi; i++) {
            gdt_point v = pts[i];
            size_t j = i;
            while (j > lo && point_less(&v, &pts[j - 1])) {
                pts[j] = pts[j - 1];
                j--;
            }
            pts[j] = v;
        }
    }
    for (size_t w = RUN; w < n; w = w > (SIZE_MAX >> 1) ? n : 2 * w) {
        for (size_t lo = 0; lo < n; lo += 2 * w) {
            size_t mid = lo + w < n ? lo + w : n;
            size_t hi = mid + w < n ? mid + w : n;
            merge_runs(src, dst, lo, mid, hi);
            if (hi == n)
                break;
        }
        gdt_point *t = src;
        src = dst;
        dst = t;
    }
    if (src != pts)
        memcpy(pts, src, n * sizeof *pts);
}

gdt_status gdt_points_dedup(gdt_point *pts, size_t n, gdt_dup_policy policy, size_t *kept,
                            gdt_error *err)
{
    gdt_point *tmp = NULL;
    size_t out = 0;

    *kept = 0;
    if ((pts == NULL && n > 0) ||
        (policy != GDT_DUP_FIRST && policy != GDT_DUP_MIN_Z && policy != GDT_DUP_MAX_Z))
        return gdt_error_set(err, GDT_EINTERNAL, 7401, "gdt_points_dedup: bad argument");
    if (n < 2) {
        *kept = n;
        return GDT_OK;
    }
    if (n > SIZE_MAX / sizeof *tmp)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    tmp = malloc(n * sizeof *tmp);
    if (tmp == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory (%zu points to merge)",
                             n);
    sort_points(pts, tmp, n);
    free(tmp);
    /* Each group is sorted by ordinal: its first record has the lowest one,
     * and a strict comparison keeps the lowest ordinal among equal z. */
    for (size_t i = 0; i < n;) {
        gdt_point best = pts[i];
        size_t j = i + 1;
        for (; j < n && pts[j].x == best.x && pts[j].y == best.y; j++) {
            if ((policy == GDT_DUP_MIN_Z && pts[j].z < best.z) ||
                (policy == GDT_DUP_MAX_Z && pts[j].z > best.z))
                best.z = pts[j].z;
        }
        pts[out++] = best;
        i = j;
    }
    *kept = out;
    return GDT_OK;
}
