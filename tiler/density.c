/* density.c — the density histogram of pass 1, bounded whatever the cloud.
 *
 * Voxel (vx, vy) = (floor(x / V), floor(y / V)), V = 2^shift lattice steps,
 * counts the points in it.  The shift starts at 0 and grows by exact
 * coarsening (voxels are summed in fours) while any of these holds:
 *   (1) more than max_voxels voxels are active;
 *   (2) a voxel index reaches 2^30 in magnitude (OpenVDB indices are int32);
 *   (3) at the end of the pass: the OpenVDB tree of the voxels (8 x 8-voxel
 *       leaves, 128 x 128 and 4096 x 4096 internal nodes, as the default
 *       5-4-3 tree lays them out on the z = 0 plane) would exceed
 *       node_budget bytes.
 * Each rule is monotone (true for a finer shift if true for a coarser one,
 * and true for a point set if true for a subset), so the final shift is the
 * smallest satisfying all three for the whole cloud: it depends on the point
 * set only, not on the order, the batching or the memory budget.
 * Memory: the hash table (at most 2^ceil(log2(2 max_voxels)) entries of 32
 * bytes) plus, while coarsening, max_voxels records of 24 bytes.
 */
#include "private/tiler_impl.h"
#include "private/tiler_io.h"

#include <stdlib.h>
#include <string.h>

#define COORD_LIMIT (INT64_C(1) << 30)

static int64_t floor_shift(int64_t v, int s)
{
    return v >= 0 ? (v >> s) : ~((~v) >> s);
}

typedef struct vrec {
    int64_t x, y;
    uint64_t n;
} vrec;

static int vrec_cmp(const void *pa, const void *pb)
{
    const vrec *a = pa, *b = pb;
    if (a->x != b->x)
        return a->x < b->x ? -1 : 1;
    return (a->y > b->y) - (a->y < b->y);
}

/* Copies the voxels into a new array (*out, *n).  Ownership: caller frees.
 * *out and *n are set on every path (NULL and 0 on failure), so no caller
 * can read them uninitialised. */
static gdt_status extract(const tl_density *d, vrec **out, size_t *n, gdt_error *err)
{
    size_t k = 0;
    vrec *v = malloc((d->map.n > 0 ? d->map.n : 1) * sizeof *v);
    *out = NULL;
    *n = 0;
    if (v == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory (density grid)");
    for (size_t s = 0; s < d->map.cap; s++)
        if (d->map.e[s].used) {
            v[k].x = d->map.e[s].i;
            v[k].y = d->map.e[s].j;
            v[k].n = d->map.e[s].v;
            k++;
        }
    *out = v;
    *n = k;
    return GDT_OK;
}

/* Precondition: shift < 62 (at shift 54 every voxel index is -1 or 0, so
 * at most 4 voxels remain and no rule asks for more when max_voxels >= 4). */
static gdt_status coarsen(tl_density *d, gdt_error *err)
{
    vrec *v;
    size_t n;
    gdt_status st;
    if (d->shift >= 62)
        return gdt_error_set(err, GDT_EINTERNAL, 7501, "density grid cannot coarsen further");
    st = extract(d, &v, &n, err);
    if (st != GDT_OK)
        return st;
    if (d->map.e != NULL)
        memset(d->map.e, 0, d->map.cap * sizeof *d->map.e);
    d->map.n = 0;
    for (size_t k = 0; k < n && st == GDT_OK; k++) {
        uint64_t *c;
        st = tl_map_upsert(&d->map, floor_shift(v[k].x, 1), floor_shift(v[k].y, 1), &c, err);
        if (st == GDT_OK)
            *c += v[k].n;
    }
    free(v);
    d->shift++;
    return st;
}

gdt_status tl_density_add(tl_density *d, const gdt_point *pts, size_t n, gdt_error *err)
{
    size_t k = 0;
    while (k < n) {
        int64_t vx = floor_shift(pts[k].x, d->shift), vy = floor_shift(pts[k].y, d->shift);
        uint64_t run = 1, *c;
        gdt_status st;
        if (vx <= -COORD_LIMIT || vx >= COORD_LIMIT || vy <= -COORD_LIMIT || vy >= COORD_LIMIT) {
            st = coarsen(d, err);
            if (st != GDT_OK)
                return st;
            continue;
        }
        /* Points come in runs from one voxel: count the run, add it once. */
        while (k + run < n && floor_shift(pts[k + run].x, d->shift) == vx &&
               floor_shift(pts[k + run].y, d->shift) == vy)
            run++;
        st = tl_map_upsert(&d->map, vx, vy, &c, err);
        if (st != GDT_OK)
            return st;
        *c += run;
        k += run;
        while (d->map.n > d->max_voxels) {
            st = coarsen(d, err);
            if (st != GDT_OK)
                return st;
        }
    }
    return GDT_OK;
}

gdt_status tl_density_export(const tl_density *d, uint64_t **out, size_t *n, gdt_error *err)
{
    vrec *v;
    uint64_t *w;
    gdt_status st = extract(d, &v, n, err);
    *out = NULL;
    if (st != GDT_OK)
        return st;
    w = malloc((*n > 0 ? *n : 1) * 3 * sizeof *w);
    if (w == NULL) {
        free(v);
        *n = 0;
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory (density grid)");
    }
    for (size_t k = 0; k < *n; k++) {
        w[3 * k] = (uint64_t)v[k].x;
        w[3 * k + 1] = (uint64_t)v[k].y;
        w[3 * k + 2] = v[k].n;
    }
    free(v);
    *out = w;
    return GDT_OK;
}

/* The union's shift is at least either part's (a rule true for a part is
 * true for the union); from there on, rule (1) coarsens as tl_density_add
 * does, and rule (2) holds for both parts already (coarsening only shrinks
 * indices); rule (3) is tl_density_finish's. */
gdt_status tl_density_merge(tl_density *d, int s, const uint64_t *v, size_t n, gdt_error *err)
{
    gdt_status st = GDT_OK;
    if (s < 0 || s >= 62)
        return gdt_error_set(err, GDT_EINTERNAL, 7501, "density grid at shift %d", s);
    while (d->shift < s && st == GDT_OK)
        st = coarsen(d, err);
    for (size_t k = 0; k < n && st == GDT_OK; k++) {
        int64_t vx = floor_shift((int64_t)v[3 * k], d->shift - s);
        int64_t vy = floor_shift((int64_t)v[3 * k + 1], d->shift - s);
        uint64_t *c;
        st = tl_map_upsert(&d->map, vx, vy, &c, err);
        if (st != GDT_OK)
            break;
        *c += v[3 * k + 2];
        while (st == GDT_OK && d->map.n > d->max_voxels)
            st = coarsen(d, err);
    }
    return st;
}

/* Distinct (floor(x / 2^s), floor(y / 2^s)) among v[0..n) (sorts v). */
static size_t distinct_at(vrec *v, size_t n, int s)
{
    size_t count = 0;
    for (size_t k = 0; k < n; k++) {
        v[k].x = floor_shift(v[k].x, s);
        v[k].y = floor_shift(v[k].y, s);
    }
    qsort(v, n, sizeof *v, vrec_cmp);
    for (size_t k = 0; k < n; k++)
        if (k == 0 || v[k].x != v[k - 1].x || v[k].y != v[k - 1].y)
            count++;
    return count;
}

gdt_status tl_density_finish(tl_density *d, uint64_t node_budget, const size_t node_bytes[3],
                             gdt_error *err)
{
    for (;;) {
        vrec *v;
        size_t n;
        uint64_t bytes;
        gdt_status st = extract(d, &v, &n, err);
        if (st != GDT_OK)
            return st;
        /* Leaves: 8 voxels a side; internal nodes: 128 and 4096. */
        bytes = (uint64_t)distinct_at(v, n, 3) * node_bytes[0];
        bytes += (uint64_t)distinct_at(v, n, 4) * node_bytes[1];
        bytes += (uint64_t)distinct_at(v, n, 5) * node_bytes[2];
        free(v);
        d->tree_bytes = bytes;
        if (bytes <= node_budget || d->shift >= 62)
            return GDT_OK;
        st = coarsen(d, err);
        if (st != GDT_OK)
            return st;
    }
}

void tl_density_free(tl_density *d)
{
    tl_map_free(&d->map);
}
