/* tiled_dem.c — --dem in the tiled run (see private/tiled_dem.h).
 *
 * Invariants: band[0..nband) are the merger's band vertices W_r of the
 * round under way (after tr_dem_row) or the kept ones (after tr_dem_round),
 * by strictly increasing output index, with global lattice x, y and z; mu
 * guards w (the writer) and nothing else. */
#include "private/tiled_dem.h"
#include "private/tiled_files.h"
#include "private/tiler_io.h"

#include <inttypes.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_grow.h"
#include "gdt_raster.h"

typedef struct band_vertex {
    uint64_t id;
    int64_t x, y; /* global lattice */
    double z;
} band_vertex;

struct tr_dem {
    gdt_raster_grid grid;
    gdt_dem *w;
    pthread_mutex_t mu;
    band_vertex *band;
    size_t nband, cap_band;
    gdt_point *rec; /* TR_CHUNK records read from a .pts file */
};

static gdt_status locked_put(void *ctx, int64_t row, int64_t col, int64_t n, const float *z,
                             gdt_error *err)
{
    tr_dem *d = ctx;
    gdt_status st;
    pthread_mutex_lock(&d->mu);
    st = gdt_dem_put(d->w, row, col, n, z, err);
    pthread_mutex_unlock(&d->mu);
    return st;
}

gdt_status tr_dem_create(tr_dem **out, const gdt_options *opts, const gdt_cloud_info *ci,
                         const gdt_tile_plan *pl, uint64_t vertices, const char *scratch_dir,
                         gdt_error *err)
{
    tr_dem *d;
    gdt_dem_opts dop;
    gdt_status st;

    *out = NULL;
    d = calloc(1, sizeof *d);
    if (d == NULL || (d->rec = malloc(TR_CHUNK * sizeof *d->rec)) == NULL) {
        free(d);
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    }
    pthread_mutex_init(&d->mu, NULL);
    st = gdt_raster_grid_define(&d->grid, &ci->lattice, pl->points > 0 ? pl->min_x : 0,
                                pl->points > 0 ? pl->min_y : 0, pl->points > 0 ? pl->max_x : 0,
                                pl->points > 0 ? pl->max_y : 0, vertices, opts->dem_res,
                                "--dem-res", err);
    if (st == GDT_OK) {
        memset(&dop, 0, sizeof dop);
        dop.nodata = opts->dem_nodata;
        dop.scratch_dir = scratch_dir;
        dop.mem_budget = opts->mem_budget != 0 ? opts->mem_budget / 8 : 0;
        if (opts->mem_budget != 0 && dop.mem_budget < ((uint64_t)16 << 20))
            dop.mem_budget = (uint64_t)16 << 20;
        dop.epsg = ci->epsg;
        dop.crs_wkt = ci->crs_wkt;
        dop.preview = opts->preview;
        st = gdt_dem_create(&d->w, &d->grid.geo, opts->dem, &dop, err);
    }
    if (st != GDT_OK) {
        tr_dem_abort(d);
        return st;
    }
    *out = d;
    return GDT_OK;
}

gdt_status tr_dem_tile_faces(tr_dem *d, const gdt_point *pts, size_t n, uint64_t base,
                             const int32_t *tri, size_t m, gdt_error *err)
{
    for (size_t f = 0; f < m; f++) {
        gdt_raster_vertex v[3];
        gdt_status st;
        for (int i = 0; i < 3; i++) {
            int64_t k = (int64_t)tri[3 * f + (size_t)i] - (int64_t)base;
            if (k < 0 || (uint64_t)k >= n)
                return gdt_error_set(err, GDT_EINTERNAL, 7663,
                                     "DEM: a certified face names vertex %d, outside its "
                                     "tile's %" PRIu64 "..%" PRIu64,
                                     (int)tri[3 * f + (size_t)i], base, base + n - 1);
            v[i].x = pts[k].x;
            v[i].y = pts[k].y;
            v[i].z = pts[k].z;
        }
        st = gdt_raster_triangle(&d->grid, NULL, v, locked_put, d, err);
        if (st != GDT_OK)
            return st;
    }
    return GDT_OK;
}

/* The z of the seam vertices row->v[i0..i1) of tile k (output indices
 * base_k.., sorted), appended to the band. */
static gdt_status row_tile(tr_dem *d, const gdt_seam *row, size_t i0, size_t i1, int64_t dx,
                           int64_t dy, const gdt_tile_desc *td, const char *tiles_dir,
                           uint64_t base_k, gdt_error *err)
{
    tl_rfile rf;
    char *path = NULL;
    uint64_t at = 0; /* local index of rec[0] */
    size_t have = 0;
    gdt_status st;

    memset(&rf, 0, sizeof rf);
    rf.fd = -1;
    st = tr_tile_path(tiles_dir, td, "pts", &path, err);
    if (st == GDT_OK)
        st = tl_rfile_open(&rf, path, td->points, TR_CHUNK, err);
    for (size_t i = i0; st == GDT_OK && i < i1; i++) {
        const gdt_seam_vertex *sv = &row->v[i];
        uint64_t local = sv->id - base_k;
        band_vertex *bv;
        while (st == GDT_OK && local >= at + have) {
            at += have;
            have = 0;
            st = tl_rfile_read(&rf, d->rec, TR_CHUNK, &have, err);
            if (st == GDT_OK && have == 0)
                st = gdt_error_set(err, GDT_EINTERNAL, 7664,
                                   "DEM: seam vertex %" PRIu64 " beyond the points of %s",
                                   sv->id, path);
        }
        if (st != GDT_OK)
            break;
        if (d->rec[local - at].x - dx != sv->x || d->rec[local - at].y - dy != sv->y) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7664,
                               "DEM: seam vertex %" PRIu64 " is not point %" PRIu64 " of %s",
                               sv->id, local, path);
            break;
        }
        if (gdt_grow(&d->band, &d->cap_band, d->nband + 1, sizeof *d->band, 1024) != 0) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
            break;
        }
        bv = &d->band[d->nband++];
        bv->id = sv->id;
        bv->x = d->rec[local - at].x;
        bv->y = d->rec[local - at].y;
        bv->z = d->rec[local - at].z;
    }
    tl_rfile_close(&rf);
    free(path);
    return st;
}

gdt_status tr_dem_row(tr_dem *d, const gdt_seam *row, int64_t dx, int64_t dy,
                      const gdt_tiler *tiler, const char *tiles_dir, const uint64_t *base,
                      uint64_t k0, uint64_t k1, gdt_error *err)
{
    size_t i = 0;
    for (uint64_t k = k0; k < k1 && i < row->nv; k++) {
        gdt_tile_desc td;
        size_t j = i;
        gdt_status st;
        while (j < row->nv && row->v[j].id < base[k + 1])
            j++;
        if (j == i)
            continue;
        if (row->v[i].id < base[k])
            return gdt_error_set(err, GDT_EINTERNAL, 7664,
                                 "DEM: seam vertex %" PRIu64 " of no tile of its row",
                                 row->v[i].id);
        st = gdt_tiler_tile_info(tiler, k, &td, err);
        if (st == GDT_OK)
            st = row_tile(d, row, i, j, dx, dy, &td, tiles_dir, base[k], err);
        if (st != GDT_OK)
            return st;
        i = j;
    }
    if (i != row->nv)
        return gdt_error_set(err, GDT_EINTERNAL, 7664,
                             "DEM: seam vertex %" PRIu64 " of no tile of its row",
                             row->v[i].id);
    return GDT_OK;
}

static const band_vertex *find(const tr_dem *d, uint64_t id)
{
    size_t lo = 0, hi = d->nband;
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        if (d->band[mid].id < id)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo < d->nband && d->band[lo].id == id ? &d->band[lo] : NULL;
}

gdt_status tr_dem_round(tr_dem *d, const uint64_t *f, size_t nf, const gdt_seam_vertex *kept,
                        size_t nkept, gdt_error *err)
{
    size_t j = 0, n = 0;
    for (size_t t = 0; t < nf; t++) {
        gdt_raster_vertex v[3];
        gdt_status st;
        for (int i = 0; i < 3; i++) {
            const band_vertex *bv = find(d, f[3 * t + (size_t)i]);
            if (bv == NULL)
                return gdt_error_set(err, GDT_EINTERNAL, 7664,
                                     "DEM: merge face vertex %" PRIu64 " not in the band",
                                     f[3 * t + (size_t)i]);
            v[i].x = bv->x;
            v[i].y = bv->y;
            v[i].z = bv->z;
        }
        st = gdt_raster_triangle(&d->grid, NULL, v, locked_put, d, err);
        if (st != GDT_OK)
            return st;
    }
    /* keep what the merger keeps (both lists by increasing id) */
    for (size_t i = 0; i < nkept; i++) {
        while (j < d->nband && d->band[j].id < kept[i].id)
            j++;
        if (j == d->nband || d->band[j].id != kept[i].id)
            return gdt_error_set(err, GDT_EINTERNAL, 7664,
                                 "DEM: kept band vertex %" PRIu64 " unknown", kept[i].id);
        d->band[n++] = d->band[j++];
    }
    d->nband = n;
    return GDT_OK;
}

gdt_status tr_dem_finish(tr_dem *d, gdt_dem_geo *geo, gdt_dem_stats *stats, gdt_error *err)
{
    gdt_status st = gdt_dem_finish(d->w, stats, err);
    d->w = NULL;
    if (geo != NULL)
        *geo = d->grid.geo;
    tr_dem_abort(d);
    return st;
}

void tr_dem_abort(tr_dem *d)
{
    if (d == NULL)
        return;
    gdt_dem_abort(d->w);
    pthread_mutex_destroy(&d->mu);
    free(d->band);
    free(d->rec);
    free(d);
}
