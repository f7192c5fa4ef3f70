/* plan.c — from the pass-1 index to the tile plan: texel size, halo width,
 * and the tile table.
 *
 * design:
 *   voxels <- the density histogram (V = 2^shift steps per voxel)
 *   estimate level e: coarsen a copy of voxels until they hold 16 points on
 *     average (or one voxel is left); area = active * 4^e
 *   auto cell  c = sqrt(area / points) / 2 rounded (in ratio) to a multiple
 *     of q = max(1, V / N), at least q, so that V divides T = N c; then
 *     lowered by q while the densest tile (exact voxel sums) holds more
 *     than N^2/4 points, but not below c_real / sqrt 2 (at most about twice
 *     the tiles): the tile stage's memory follows the densest tile, so this
 *     keeps it a function of N rather than of the cloud
 *     then doubled while a thin cloud (a strip) makes more than 8 times the
 *     tiles its points need, the tiles shrink, the densest stays within
 *     N^2/4 and the texel within the spacing s (see THIN_SURPLUS)
 *   auto halo  H = ceil(8 s / c), s = 2^e / sqrt(median voxel count at e),
 *     clamped to [1, N/2] and to (N + 2H) c <= 2^31
 *   tiles      auto cell: sum of the voxels of each tile (exact, V | T);
 *              given cell: the counts made in pass 1
 * Every step is integer or a correctly rounded IEEE operation on integer
 * inputs, so the plan is the same on every run and every budget.  The
 * OpenVDB grids are filled from the result when the index is saved.
 */
#include "private/tiler_impl.h"
#include "private/tiler_io.h"

#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define LOCAL_LIMIT (INT64_C(1) << 31) /* (N + 2H) * c may not exceed this */
#define EST_MEAN 16                    /* points per voxel at the estimate level */
#define HALO_SPACINGS 8.0              /* auto halo, in point spacings */
#define THIN_SURPLUS 8                 /* auto cell: tiles per N^2/4 points before
                                          a thin cloud gets a coarser texel */

typedef struct vox {
    int64_t x, y;
    uint64_t n;
} vox;

typedef struct vox_list {
    vox *v;
    size_t n, cap;
} vox_list;

/* The histogram's voxels as a list.  Ownership: l->v is malloc'd. */
static gdt_status collect(const tl_density *d, vox_list *l, gdt_error *err)
{
    l->n = 0;
    l->cap = d->map.n > 0 ? d->map.n : 1;
    l->v = malloc(l->cap * sizeof *l->v);
    if (l->v == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory (density grid)");
    for (size_t s = 0; s < d->map.cap; s++)
        if (d->map.e[s].used) {
            l->v[l->n].x = d->map.e[s].i;
            l->v[l->n].y = d->map.e[s].j;
            l->v[l->n].n = d->map.e[s].v;
            l->n++;
        }
    return GDT_OK;
}

static int vox_cmp(const void *pa, const void *pb)
{
    const vox *a = pa, *b = pb;
    if (a->x != b->x)
        return a->x < b->x ? -1 : 1;
    if (a->y != b->y)
        return a->y < b->y ? -1 : 1;
    return 0;
}

static int u64_cmp(const void *pa, const void *pb)
{
    uint64_t a = *(const uint64_t *)pa, b = *(const uint64_t *)pb;
    return (a > b) - (a < b);
}

static int tile_cmp(const void *pa, const void *pb)
{
    const tl_tile *a = pa, *b = pb;
    if (a->j != b->j)
        return a->j < b->j ? -1 : 1;
    if (a->i != b->i)
        return a->i < b->i ? -1 : 1;
    return 0;
}

/* Halves the resolution of l in place (sum of merged voxels). */
static void vox_coarsen(vox_list *l)
{
    size_t out = 0;
    for (size_t k = 0; k < l->n; k++) {
        l->v[k].x = tl_floor_div(l->v[k].x, 2);
        l->v[k].y = tl_floor_div(l->v[k].y, 2);
    }
    qsort(l->v, l->n, sizeof *l->v, vox_cmp);
    for (size_t k = 0; k < l->n; k++) {
        if (out > 0 && l->v[out - 1].x == l->v[k].x && l->v[out - 1].y == l->v[k].y)
            l->v[out - 1].n += l->v[k].n;
        else
            l->v[out++] = l->v[k];
    }
    l->n = out;
}

/* Largest number of points in one tile of r x r voxels (r = T / V); the
 * number of non-empty tiles in *tiles when tiles is not NULL. */
static gdt_status densest_tile(const vox_list *base, int64_t r, uint64_t *max, size_t *tiles,
                               gdt_error *err)
{
    tl_map m = {0};
    gdt_status st = GDT_OK;
    *max = 0;
    for (size_t k = 0; k < base->n && st == GDT_OK; k++) {
        uint64_t *v;
        st = tl_map_upsert(&m, tl_floor_div(base->v[k].x, r), tl_floor_div(base->v[k].y, r), &v,
                           err);
        if (st == GDT_OK && (*v += base->v[k].n) > *max)
            *max = *v;
    }
    if (tiles != NULL)
        *tiles = m.n;
    tl_map_free(&m);
    return st;
}

/* Occupied area (lattice steps^2, as a double) and median spacing. */
static gdt_status estimate(const vox_list *base, int shift, uint64_t points, double *area,
                           double *spacing, gdt_error *err)
{
    vox_list l = {0};
    uint64_t *counts = NULL;
    int e = shift;
    gdt_status st = GDT_OK;

    *area = 0.0;
    *spacing = 0.0;
    if (base->n == 0 || points == 0)
        return GDT_OK;
    l.v = malloc(base->n * sizeof *l.v);
    counts = malloc(base->n * sizeof *counts);
    if (l.v == NULL || counts == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory (density estimate)");
        goto fail;
    }
    memcpy(l.v, base->v, base->n * sizeof *l.v);
    l.n = l.cap = base->n;
    while (l.n > 1 && points / EST_MEAN < (uint64_t)l.n && e < 62) {
        vox_coarsen(&l);
        e++;
    }
    for (size_t k = 0; k < l.n; k++)
        counts[k] = l.v[k].n;
    qsort(counts, l.n, sizeof *counts, u64_cmp);
    *area = ldexp((double)l.n, 2 * e);
    *spacing = ldexp(1.0, e) / sqrt((double)counts[(l.n - 1) / 2]);
fail:
    free(l.v);
    free(counts);
    return st;
}

gdt_status tl_plan_finish(gdt_tiler *t, gdt_error *err)
{
    gdt_tile_plan *p = &t->plan;
    const int64_t N = t->opts.tile;
    const int shift = t->density.shift;
    vox_list base = {0};
    uint64_t *counts = NULL;
    tl_map tmap = {0};
    double area = 0.0, spacing = 0.0;
    gdt_status st;

    p->density_shift = shift;
    p->density_voxels = t->density.map.n;
    st = collect(&t->density, &base, err);
    if (st != GDT_OK)
        goto fail;
    qsort(base.v, base.n, sizeof *base.v, vox_cmp);
    st = estimate(&base, shift, p->points, &area, &spacing, err);
    if (st != GDT_OK)
        goto fail;
    p->spacing = spacing;

    /* Texel size. */
    if (t->user_cell > 0) {
        p->cell = t->user_cell;
        p->cell_auto = 0;
    } else {
        int64_t q = shift > 0 && (INT64_C(1) << shift) > N ? (INT64_C(1) << shift) / N : 1;
        int64_t cmax = LOCAL_LIMIT / N, c = 1;
        double creal = p->points > 0 ? sqrt(area / (double)p->points) / 2.0 : 1.0;
        /* The multiple of q nearest to creal in ratio (points per tile go as
         * c^2): below the geometric mean of two neighbours take the lower. */
        if (creal >= (double)cmax) {
            c = cmax / q * q;
        } else {
            int64_t lo = (int64_t)(creal / (double)q) * q, hi = lo + q;
            c = lo >= 1 && creal * creal < (double)lo * (double)hi ? lo : hi;
            if (c > cmax)
                c = cmax / q * q;
        }
        /* The densest tile at most N^2/4 points, within a factor sqrt 2
         * of creal (V divides N c for every multiple c of q). */
        if (c >= 1 && p->points > 0) {
            const uint64_t cap = (uint64_t)N * (uint64_t)N / 4;
            double cfloor = creal / sqrt(2.0);
            while (c - q >= q && (double)(c - q) >= cfloor) {
                uint64_t densest;
                st = densest_tile(&base, (N * c) >> shift, &densest, NULL, err);
                if (st != GDT_OK)
                    goto fail;
                if (densest <= cap)
                    break;
                c -= q;
            }
        }
        /* A cloud thinner than a tile (a strip, a line) fills its tiles far
         * below N^2/4 points at that texel, and the tile count then follows
         * its length rather than its points.  Double the texel while the plan
         * makes more than THIN_SURPLUS times the tiles the points need, the
         * doubling cuts the tiles by a quarter at least, the densest tile
         * stays within N^2/4 and the texel within the median point spacing
         * (points sharing texels cost the core more than tiles do).  A
         * cloud that fills its tiles keeps its texel: at twice the texel its
         * densest tile would hold about four times N^2/4. */
        if (c >= 1 && p->points > 0) {
            const uint64_t cap = (uint64_t)N * (uint64_t)N / 4;
            const uint64_t need = (p->points + cap - 1) / cap;
            uint64_t densest;
            size_t tiles, tiles2;
            st = densest_tile(&base, (N * c) >> shift, &densest, &tiles, err);
            while (st == GDT_OK && tiles > THIN_SURPLUS * need && 2 * c <= cmax &&
                   (double)(2 * c) <= spacing) {
                st = densest_tile(&base, (N * 2 * c) >> shift, &densest, &tiles2, err);
                if (st != GDT_OK || densest > cap || 4 * tiles2 > 3 * tiles)
                    break;
                c *= 2;
                tiles = tiles2;
            }
            if (st != GDT_OK)
                goto fail;
        }
        if (c < 1) {
            st = gdt_error_set(err, GDT_EUSAGE, 2502,
                               "the cloud needs a density voxel of 2^%d lattice steps, wider "
                               "than a tile of %" PRId64 " texels can span within 2^31 steps; "
                               "give --cell",
                               shift, N);
            goto fail;
        }
        if (p->points > 0 && (c > 1.25 * creal + 1.0 || c < 0.7 * creal - 1.0))
            gdt_log_note(t->log, "tiler: texel of %" PRId64 " lattice steps (the density "
                                 "suggests %.1f; the density grid allows multiples of %" PRId64
                                 ")",
                         c, creal, q);
        p->cell = c;
        p->cell_auto = 1;
    }
    p->span = N * p->cell;

    /* Halo width. */
    {
        int64_t hmax = (LOCAL_LIMIT / p->cell - N) / 2;
        if (t->opts.halo >= 0) {
            if ((int64_t)t->opts.halo > hmax) {
                st = gdt_error_set(err, GDT_EUSAGE, 2502,
                                   "--halo %ld with --tile %" PRId64 " and a texel of %" PRId64
                                   " lattice steps gives tile-local coordinates beyond 2^31 - 1 "
                                   "(at most --halo %" PRId64 ")",
                                   t->opts.halo, N, p->cell, hmax < 0 ? 0 : hmax);
                goto fail;
            }
            p->halo = t->opts.halo;
            p->halo_auto = 0;
        } else {
            int64_t h = 1;
            if (spacing > 0.0) {
                double hr = ceil(HALO_SPACINGS * spacing / (double)p->cell);
                h = hr >= (double)(N / 2) ? N / 2 : (int64_t)hr;
            }
            if (h < 1)
                h = 1;
            if (h > hmax)
                h = hmax;
            p->halo = h;
            p->halo_auto = 1;
        }
    }

    /* The tile table. */
    if (t->user_cell > 0) {
        tmap = t->map;
        memset(&t->map, 0, sizeof t->map);
    } else {
        int64_t r = p->span >> shift; /* voxels per tile side; V divides T */
        for (size_t k = 0; k < base.n; k++) {
            uint64_t *v;
            st = tl_map_upsert(&tmap, tl_floor_div(base.v[k].x, r), tl_floor_div(base.v[k].y, r),
                               &v, err);
            if (st != GDT_OK)
                goto fail;
            *v += base.v[k].n;
        }
    }
    if (tmap.n > t->sz.tiles_bytes / (sizeof(tl_tile) + 2 * sizeof(tl_map_entry))) {
        st = gdt_error_set(err, GDT_EUSAGE, 2503,
                           "%zu non-empty tiles of %" PRId64 " x %" PRId64
                           " lattice steps do not fit in the memory budget of %" PRIu64
                           " bytes: use a larger --cell, a larger --tile or a larger "
                           "--mem-budget",
                           tmap.n, p->span, p->span, t->budget);
        goto fail;
    }
    t->tiles = calloc(tmap.n > 0 ? tmap.n : 1, sizeof *t->tiles);
    counts = malloc((tmap.n > 0 ? tmap.n : 1) * sizeof *counts);
    if (t->tiles == NULL || counts == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory (tile table)");
        goto fail;
    }
    t->ntiles = 0;
    for (size_t s = 0; s < tmap.cap; s++) {
        if (!tmap.e[s].used)
            continue;
        t->tiles[t->ntiles].i = tmap.e[s].i;
        t->tiles[t->ntiles].j = tmap.e[s].j;
        t->tiles[t->ntiles].count = tmap.e[s].v;
        t->ntiles++;
    }
    qsort(t->tiles, (size_t)t->ntiles, sizeof *t->tiles, tile_cmp);
    tl_map_free(&t->map);
    p->tiles = t->ntiles;
    p->nx = p->ny = 0;
    p->tile_i0 = p->tile_j0 = 0;
    if (t->ntiles > 0) {
        int64_t i0 = INT64_MAX, i1 = INT64_MIN, j0 = t->tiles[0].j,
                j1 = t->tiles[t->ntiles - 1].j;
        uint64_t sum = 0;
        for (uint64_t k = 0; k < t->ntiles; k++) {
            if (t->tiles[k].i < i0)
                i0 = t->tiles[k].i;
            if (t->tiles[k].i > i1)
                i1 = t->tiles[k].i;
            counts[k] = t->tiles[k].count;
            sum += t->tiles[k].count;
            uint64_t *v;
            st = tl_map_upsert(&t->map, t->tiles[k].i, t->tiles[k].j, &v, err);
            if (st != GDT_OK)
                goto fail;
            *v = k;
        }
        if (sum != p->points) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7501,
                               "tile counts sum to %" PRIu64 ", not to the %" PRIu64
                               " points read",
                               sum, p->points);
            goto fail;
        }
        if (i1 - i0 >= INT32_MAX || j1 - j0 >= INT32_MAX) {
            st = gdt_error_set(err, GDT_EUSAGE, 2503,
                               "the cloud spans more than 2^31 - 1 tiles of %" PRId64
                               " lattice steps along an axis: use a larger --cell",
                               p->span);
            goto fail;
        }
        p->tile_i0 = i0;
        p->tile_j0 = j0;
        p->nx = i1 - i0 + 1;
        p->ny = j1 - j0 + 1;
        qsort(counts, (size_t)t->ntiles, sizeof *counts, u64_cmp);
        p->min_points = counts[0];
        p->median_points = counts[(t->ntiles - 1) / 2];
        p->max_points = counts[t->ntiles - 1];
    }
    p->empty_tiles = (uint64_t)p->nx * (uint64_t)p->ny - t->ntiles;
    /* A given --cell far below the one the cloud needs: tiles with a few
     * points each, whose per-tile costs then dominate the run. */
    if (t->user_cell > 0 && p->points > 0) {
        const uint64_t cap = (uint64_t)N * (uint64_t)N / 4;
        const uint64_t need = (p->points + cap - 1) / cap;
        if (t->ntiles > THIN_SURPLUS * need)
            gdt_log_warn(t->log, 2508,
                         "--cell %.6g makes %" PRIu64 " tiles of %.1f points on average for "
                         "%" PRIu64 " points, where a tile of %" PRId64 " texels is planned "
                         "for %" PRIu64 ": leave --cell out (automatic), or give a larger "
                         "--cell or --tile",
                         (double)p->cell * p->lattice.sx, t->ntiles,
                         (double)p->points / (double)t->ntiles, p->points, N, cap);
    }
fail:
    free(base.v);
    free(counts);
    tl_map_free(&tmap);
    return st;
}

void gdt_tile_plan_print(FILE *out, const gdt_tile_plan *p)
{
    const gdt_lattice *L = &p->lattice;
    uint64_t target = (uint64_t)p->tile * (uint64_t)p->tile / 4;

    fprintf(out, "tile plan:\n");
    fprintf(out, "  tile         : %d x %d texels, %" PRId64 " x %" PRId64
                 " lattice steps = %.17g x %.17g CRS units\n",
            p->tile, p->tile, p->span, p->span, (double)p->span * L->sx,
            (double)p->span * L->sy);
    fprintf(out, "  texel        : %" PRId64 " lattice steps = %.17g x %.17g CRS units (%s)\n",
            p->cell, (double)p->cell * L->sx, (double)p->cell * L->sy,
            p->cell_auto ? "auto: about N^2/4 points per tile, finer while the densest holds "
                           "more, down to 1/sqrt 2 of that texel"
                         : "--cell");
    fprintf(out, "  halo         : %" PRId64 " texels = %" PRId64 " lattice steps (%s)\n",
            p->halo, p->halo * p->cell, p->halo_auto ? "auto, from the density" : "--halo");
    fprintf(out, "  grid         : %" PRId64 " x %" PRId64 " tiles", p->nx, p->ny);
    if (p->tiles > 0)
        fprintf(out, " from tile (%" PRId64 ", %" PRId64 ") at lattice (%" PRId64 ", %" PRId64
                     ")",
                p->tile_i0, p->tile_j0, p->tile_i0 * p->span, p->tile_j0 * p->span);
    fputc('\n', out);
    fprintf(out, "  tiles        : %" PRIu64 " with points, %" PRIu64 " empty\n", p->tiles,
            p->empty_tiles);
    fprintf(out, "  points/tile  : min %" PRIu64 ", median %" PRIu64 ", max %" PRIu64
                 " (target N^2/4 = %" PRIu64 ")\n",
            p->min_points, p->median_points, p->max_points, target);
    fprintf(out, "  points       : %" PRIu64 "\n", p->points);
    fprintf(out, "  density grid : voxel 2^%d lattice steps, %" PRIu64 " active voxels\n",
            p->density_shift, p->density_voxels);
    if (p->spacing > 0.0)
        fprintf(out, "  spacing      : %.4g lattice steps (median over occupied voxels)\n",
                p->spacing);
    fprintf(out, "  memory budget: %" PRIu64 " MiB\n", p->mem_budget >> 20);
}
