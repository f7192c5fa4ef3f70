/* The whole cloud in memory (see private/memcloud.h). */
#include "private/memcloud.h"

#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_ply.h"
#include "gdt_raster.h"
#include "private/filter_report.h"
#include "private/cli_modes.h"
#include "private/run_stats.h"

#define MC_CHUNK 65536

static int cmp_ord(const void *a, const void *b)
{
    const gdt_point *p = a, *q = b;
    return (p->ord > q->ord) - (p->ord < q->ord);
}

static gdt_status read_all(gdt_memcloud *mc, const char *mode, gdt_error *err)
{
    size_t cap = MC_CHUNK;
    mc->pts = malloc(cap * sizeof *mc->pts);
    if (mc->pts == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    for (;;) {
        size_t got = 0;
        gdt_status st;
        if (cap - mc->read < MC_CHUNK) {
            gdt_point *grown = NULL;
            if (cap <= SIZE_MAX / 2 / sizeof *mc->pts)
                grown = realloc(mc->pts, 2 * cap * sizeof *mc->pts);
            if (grown == NULL)
                return gdt_error_set(err, GDT_EINTERNAL, 7001,
                                     "out of memory reading %zu points (%s holds the whole "
                                     "cloud in memory)",
                                     mc->read, mode);
            mc->pts = grown;
            cap *= 2;
        }
        st = gdt_cloud_read(mc->cloud, mc->pts + mc->read, MC_CHUNK, &got, err);
        if (st != GDT_OK)
            return st;
        if (got == 0)
            return GDT_OK;
        mc->read += got;
    }
}

gdt_status gdt_memcloud_load(gdt_memcloud *mc, const gdt_options *opts, gdt_log *log,
                             const char *mode, gdt_error *err)
{
    gdt_cloud_opts co;
    int64_t max_x = 0, max_y = 0;
    double t0 = gdt_now();
    gdt_status st;

    memset(mc, 0, sizeof *mc);
    memset(&co, 0, sizeof co);
    co.log = log;
    co.quantum = opts->quantum;
    co.filter = &opts->filter;
    co.threads = gdt_cli_threads(opts->threads);
    st = gdt_cloud_open(&mc->cloud, opts->inputs, opts->ninputs, &co, err);
    if (st == GDT_OK)
        st = read_all(mc, mode, err);
    if (st == GDT_OK)
        st = gdt_points_dedup(mc->pts, mc->read, opts->dup, &mc->kept, err);
    if (st != GDT_OK)
        return st;
    qsort(mc->pts, mc->kept, sizeof *mc->pts, cmp_ord);
    if (mc->kept > 0) {
        mc->min_x = max_x = mc->pts[0].x;
        mc->min_y = max_y = mc->pts[0].y;
    }
    for (size_t i = 1; i < mc->kept; i++) {
        const gdt_point *p = &mc->pts[i];
        if (p->x < mc->min_x) mc->min_x = p->x;
        if (p->x > max_x) max_x = p->x;
        if (p->y < mc->min_y) mc->min_y = p->y;
        if (p->y > max_y) max_y = p->y;
    }
    if (mc->kept > 0) {
        st = gdt_cloud_check_span(mc->cloud, max_x - mc->min_x, max_y - mc->min_y, mode, err);
        if (st != GDT_OK)
            return st;
    }
    if (opts->dem != NULL) {
        const gdt_cloud_info *ci = gdt_cloud_get_info(mc->cloud);
        st = gdt_raster_grid_define(&mc->dem_grid, &ci->lattice, mc->min_x, mc->min_y,
                                    max_x, max_y,
                                    mc->kept, opts->dem_res, "--dem-res", err);
        if (st != GDT_OK)
            return st;
    }
    mc->local = malloc((mc->kept > 0 ? mc->kept : 1) * sizeof *mc->local);
    if (mc->local == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    for (size_t i = 0; i < mc->kept; i++) {
        mc->local[i].x = mc->pts[i].x - mc->min_x;
        mc->local[i].y = mc->pts[i].y - mc->min_y;
    }
    mc->t_read = gdt_now() - t0;
    return GDT_OK;
}

void gdt_memcloud_free(gdt_memcloud *mc)
{
    free(mc->local);
    free(mc->pts);
    gdt_cloud_close(mc->cloud);
    memset(mc, 0, sizeof *mc);
}

gdt_status gdt_memcloud_write(const gdt_memcloud *mc, const gdt_options *opts,
                              const gdt_mesh *mesh, gdt_error *err)
{
    const gdt_cloud_info *ci = gdt_cloud_get_info(mc->cloud);
    gdt_ply_writer *w = NULL;
    gdt_ply_meta meta;
    int64_t *canon = malloc((mesh->ntris > 0 ? 3 * mesh->ntris : 1) * sizeof *canon);
    double *xyz = malloc(3 * MC_CHUNK * sizeof *xyz);
    int32_t *tri = malloc(3 * MC_CHUNK * sizeof *tri);
    char filter[GDT_FILTER_COMMENT_MAX];
    const char *comments[1] = {filter};
    gdt_status st;

    memset(&meta, 0, sizeof meta);
    meta.lattice = ci->lattice;
    meta.epsg = ci->epsg;
    meta.crs_wkt = ci->crs_wkt;
    gdt_filter_report_comment(mc->cloud, filter, sizeof filter);
    meta.comments = comments;
    meta.ncomments = 1;
    if (xyz == NULL || tri == NULL || canon == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    st = gdt_ply_create(&w, opts->output, &meta, err);
    for (size_t i = 0; st == GDT_OK && i < mesh->nverts; i += MC_CHUNK) {
        size_t m = mesh->nverts - i < MC_CHUNK ? mesh->nverts - i : MC_CHUNK;
        for (size_t k = 0; k < m; k++) {
            const gdt_point *p = &mc->pts[i + k];
            xyz[3 * k + 0] = ci->lattice.ox + ci->lattice.sx * (double)p->x;
            xyz[3 * k + 1] = ci->lattice.oy + ci->lattice.sy * (double)p->y;
            xyz[3 * k + 2] = p->z;
        }
        st = gdt_ply_write_vertices(w, xyz, m, err);
    }
    gdt_mesh_canonical(mesh, canon);
    for (size_t i = 0; st == GDT_OK && i < mesh->ntris; i += MC_CHUNK) {
        size_t m = mesh->ntris - i < MC_CHUNK ? mesh->ntris - i : MC_CHUNK;
        for (size_t k = 0; k < 3 * m; k++)
            tri[k] = (int32_t)canon[3 * i + k];
        st = gdt_ply_write_faces(w, tri, m, err);
    }
    if (st == GDT_OK) {
        st = gdt_ply_finish(w, err);
        w = NULL;
    }
fail:
    gdt_ply_abort(w);
    free(canon);
    free(tri);
    free(xyz);
    return st;
}

gdt_status gdt_memcloud_dem(gdt_memcloud *mc, const gdt_options *opts, const gdt_mesh *mesh,
                            gdt_pred_stats *pred, gdt_error *err)
{
    const gdt_cloud_info *ci = gdt_cloud_get_info(mc->cloud);
    const gdt_raster_grid *grid = &mc->dem_grid;
    gdt_dem_opts dop;
    gdt_dem *w = NULL;
    double t0 = gdt_now();
    gdt_status st;

    memset(&dop, 0, sizeof dop);
    dop.nodata = opts->dem_nodata;
    dop.mem_budget = opts->mem_budget;
    dop.epsg = ci->epsg;
    dop.crs_wkt = ci->crs_wkt;
    dop.preview = opts->preview;
    st = gdt_dem_create(&w, &grid->geo, opts->dem, &dop, err);
    if (st == GDT_OK)
        st = gdt_raster_faces(grid, pred, mc->pts, mc->kept, mesh->tri, mesh->ntris,
                              gdt_dem_sink, w, err);
    if (st == GDT_OK)
        st = gdt_cli_check_stop(opts, "the DEM", err);
    if (st != GDT_OK) {
        gdt_dem_abort(w);
        return st;
    }
    st = gdt_dem_finish(w, &mc->dem_stats, err);
    if (st != GDT_OK)
        return st;
    mc->dem_done = 1;
    mc->dem_geo = grid->geo;
    mc->t_dem = gdt_now() - t0;
    return GDT_OK;
}

void gdt_memcloud_print_dem(const gdt_memcloud *mc, const gdt_options *opts)
{
    if (!mc->dem_done || opts->verbosity < 0)
        return;
    fprintf(stderr,
            "gdt-tile: %s: DEM of %" PRId64 " x %" PRId64 " cells of %.17g, %" PRIu64
            " with a value%s%s\n",
            opts->dem, mc->dem_geo.ncols, mc->dem_geo.nrows, mc->dem_geo.res_x,
            mc->dem_stats.cells_written, opts->preview != NULL ? "; preview " : "",
            opts->preview != NULL ? opts->preview : "");
}

gdt_status gdt_memcloud_finish(gdt_memcloud *mc, const gdt_options *opts,
                               const gdt_mesh *mesh, gdt_pred_stats *pred, double *t_check,
                               double *t_write, int *checked, gdt_error *err)
{
    double t0 = gdt_now();
    gdt_status st;
    if (opts->check) {
        st = gdt_check_mesh(pred, mesh, err);
        if (st == GDT_OK)
            st = gdt_check_delaunay(pred, mesh, err);
        if (st != GDT_OK)
            return st;
        *checked = 1;
        *t_check = gdt_now() - t0;
    }
    t0 = gdt_now();
    st = gdt_memcloud_write(mc, opts, mesh, err);
    *t_write = gdt_now() - t0;
    if (st == GDT_OK && opts->dem != NULL)
        st = gdt_memcloud_dem(mc, opts, mesh, pred, err);
    return st;
}

gdt_status gdt_memcloud_json_head(gdt_json *j, const gdt_memcloud *mc, const gdt_options *opts,
                                  const char *mode, uint64_t faces, gdt_error *err)
{
    const gdt_cloud_info *ci = gdt_cloud_get_info(mc->cloud);
    gdt_status st = gdt_json_open(j, opts->json, err);
    if (st != GDT_OK)
        return st;
    gdt_json_begin_object(j, NULL);
    gdt_json_string(j, "mode", mode);
    gdt_json_string(j, "output", opts->output);
    gdt_json_uint(j, "inputs", ci->ninputs);
    gdt_json_uint(j, "points", mc->read);
    gdt_json_uint(j, "vertices", mc->kept);
    gdt_json_uint(j, "duplicates_merged", mc->read - mc->kept);
    gdt_json_uint(j, "faces", faces);
    gdt_json_string(j, "crs", ci->crs_desc);
    if (mc->dem_done) {
        gdt_json_begin_object(j, "dem");
        gdt_json_string(j, "path", opts->dem);
        if (opts->preview != NULL)
            gdt_json_string(j, "preview", opts->preview);
        gdt_json_double(j, "res", mc->dem_geo.res_x);
        gdt_json_uint(j, "cols", (uint64_t)mc->dem_geo.ncols);
        gdt_json_uint(j, "rows", (uint64_t)mc->dem_geo.nrows);
        gdt_json_double(j, "west", mc->dem_geo.west);
        gdt_json_double(j, "north", mc->dem_geo.north);
        gdt_json_uint(j, "cells_with_value", mc->dem_stats.cells_written);
        gdt_json_uint(j, "blocks", mc->dem_stats.blocks);
        gdt_json_uint(j, "cache_blocks", mc->dem_stats.cache_blocks);
        gdt_json_uint(j, "spills", mc->dem_stats.spills);
        gdt_json_double(j, "seconds", mc->t_dem);
        gdt_json_end_object(j);
    }
    gdt_filter_report_json(j, mc->cloud);
    return GDT_OK;
}
