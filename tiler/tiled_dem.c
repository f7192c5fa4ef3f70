/* tiled_dem.c — --dem in the tiled run (see private/tiled_dem.h).
 *
 * Invariant: mu guards w (the writer) and nothing else. */
#include "private/tiled_dem.h"
#include "private/tiled_files.h"
#include "private/tiler_io.h"

#include <inttypes.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_grow.h"
#include "gdt_raster.h"

struct tr_dem {
    gdt_raster_grid grid;
    gdt_dem *w;
    pthread_mutex_t mu;
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
    if (d == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
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

gdt_status tr_dem_faces(tr_dem *d, const gdt_raster_vertex *v, size_t m, gdt_error *err)
{
    for (size_t f = 0; f < m; f++) {
        gdt_status st = gdt_raster_triangle(&d->grid, NULL, v + 3 * f, locked_put, d, err);
        if (st != GDT_OK)
            return st;
    }
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
    free(d);
}
