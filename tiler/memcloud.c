/* The whole cloud in memory (see private/memcloud.h). */
#include "private/memcloud.h"

#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_mesh_out.h"
#include "gdt_ply.h"
#include "gdt_raster.h"
#include "private/filter_report.h"
#include "private/dem_report.h"
#include "private/ground_report.h"
#include "private/mesh_meta.h"
#include "private/trim_report.h"
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

/* --ground: classifies the kept points (the cloud's box: the whole
 * cloud's grid) and keeps the ground ones, in ordinal order. */
static gdt_status ground_filter(gdt_memcloud *mc, const gdt_options *opts, double z0,
                                int64_t max_x, int64_t max_y, gdt_error *err)
{
    const gdt_pmf_box box = {mc->min_x, max_x, mc->min_y, max_y};
    double t0 = gdt_now();
    uint8_t *g = malloc(mc->kept > 0 ? mc->kept : 1);
    gdt_pmf f;
    size_t n = 0;
    gdt_status st = g == NULL ? gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory")
                              : gdt_pmf_init(&f, &opts->pmf,
                                             &gdt_cloud_get_info(mc->cloud)->lattice, z0, err);
    if (st == GDT_OK)
        st = gdt_pmf_classify(&f, mc->pts, mc->kept, NULL, 0, &box, &box, g, 0, err);
    for (size_t i = 0; st == GDT_OK && i < mc->kept; i++)
        if (g[i])
            mc->pts[n++] = mc->pts[i];
    free(g);
    if (st != GDT_OK)
        return st;
    mc->ground = n;
    mc->nonground = mc->kept - n;
    mc->kept = n;
    mc->t_ground = gdt_now() - t0;
    return GDT_OK;
}

gdt_status gdt_memcloud_load(gdt_memcloud *mc, const gdt_options *opts, gdt_log *log,
                             const char *mode, gdt_error *err)
{
    gdt_cloud_opts co;
    int64_t max_x = 0, max_y = 0;
    double t0 = gdt_now(), z0 = 0.0;
    gdt_status st;

    memset(mc, 0, sizeof *mc);
    mc->log = log;
    memset(&co, 0, sizeof co);
    co.log = log;
    co.quantum = opts->quantum;
    co.filter = &opts->filter;
    co.threads = gdt_cli_threads(opts->threads);
    st = gdt_cloud_open(&mc->cloud, opts->inputs, opts->ninputs, &co, err);
    if (st == GDT_OK)
        st = read_all(mc, mode, err);
    for (size_t i = 0; i < mc->read; i++) /* --ground: pass 1's lowest z */
        if (i == 0 || mc->pts[i].z < z0)
            z0 = mc->pts[i].z;
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
    if (opts->ground) {
        /* the whole cloud in one call: the classes the tiled run gives */
        st = ground_filter(mc, opts, z0, max_x, max_y, err);
        if (st != GDT_OK)
            return st;
    }
    /* the DEM's grid: the cloud's box (all points), the spacing of the
     * points triangulated (the tiled run's vertices) */
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

/* The trimming of the faces canon (3 nf canonical vertex indices) on the
 * whole mesh: keep[f] (malloc'd in *keep_out, NULL when no rule is on). */
static gdt_status trim_faces(const gdt_memcloud *mc, const gdt_options *opts,
                             const int64_t *canon, size_t nf, uint8_t **keep_out,
                             gdt_trim_counts *tc, gdt_error *err)
{
    const gdt_cloud_info *ci = gdt_cloud_get_info(mc->cloud);
    gdt_trim_rule r = opts->trim;
    uint32_t *f;
    uint8_t *keep;
    gdt_status st;

    *keep_out = NULL;
    memset(tc, 0, sizeof *tc);
    tc->faces = nf;
    if (!gdt_trim_on(&r))
        return GDT_OK;
    r.sx = ci->lattice.sx;
    r.sy = ci->lattice.sy;
    f = malloc((3 * nf + 1) * sizeof *f);
    keep = malloc(nf + 1);
    if (f == NULL || keep == NULL) {
        free(f);
        free(keep);
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    }
    for (size_t i = 0; i < 3 * nf; i++)
        f[i] = (uint32_t)canon[i];
    st = gdt_trim_mesh(&r, f, nf, mc->local, keep, tc, err);
    free(f);
    if (st != GDT_OK) {
        free(keep);
        return st;
    }
    *keep_out = keep;
    return GDT_OK;
}

gdt_status gdt_memcloud_write(const gdt_memcloud *mc, const gdt_options *opts,
                              const gdt_mesh *mesh, gdt_trim_counts *tc, int32_t **kept,
                              size_t *nkept, gdt_error *err)
{
    const gdt_cloud_info *ci = gdt_cloud_get_info(mc->cloud);
    gdt_mesh_writer *w = NULL;
    gdt_mesh_meta meta;
    int64_t *canon = malloc((mesh->ntris > 0 ? 3 * mesh->ntris : 1) * sizeof *canon);
    double *xyz = malloc(3 * MC_CHUNK * sizeof *xyz);
    int32_t *tri = malloc(3 * MC_CHUNK * sizeof *tri);
    char filter[GDT_FILTER_COMMENT_MAX], trim[GDT_TRIM_TEXT_MAX], ground[256];
    const char *comments[3] = {filter, trim, ground};
    uint8_t *keep = NULL;
    gdt_status st;

    gdt_run_mesh_meta(mc->cloud, mc->log, &opts->trim, filter, sizeof filter, trim, sizeof trim,
                      comments, &meta);
    if (opts->ground) {
        gdt_pmf_describe(&opts->pmf, ground, sizeof ground);
        comments[meta.ncomments++] = ground;
    }
    if (xyz == NULL || tri == NULL || canon == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    gdt_mesh_canonical(mesh, canon);
    st = trim_faces(mc, opts, canon, mesh->ntris, &keep, tc, err);
    if (st == GDT_OK)
        st = gdt_mesh_create(&w, opts->output, gdt_mesh_format_of(opts->output), &meta, err);
    if (st == GDT_OK && kept != NULL) {
        *nkept = 0;
        *kept = malloc((3 * (mesh->ntris - tc->dropped) + 1) * sizeof **kept);
        if (*kept == NULL)
            st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    }
    for (size_t i = 0; st == GDT_OK && i < mesh->nverts; i += MC_CHUNK) {
        size_t m = mesh->nverts - i < MC_CHUNK ? mesh->nverts - i : MC_CHUNK;
        for (size_t k = 0; k < m; k++) {
            const gdt_point *p = &mc->pts[i + k];
            xyz[3 * k + 0] = ci->lattice.ox + ci->lattice.sx * (double)p->x;
            xyz[3 * k + 1] = ci->lattice.oy + ci->lattice.sy * (double)p->y;
            xyz[3 * k + 2] = p->z;
        }
        st = gdt_mesh_write_vertices(w, xyz, m, err);
    }
    for (size_t i = 0; st == GDT_OK && i < mesh->ntris; i += MC_CHUNK) {
        size_t m = mesh->ntris - i < MC_CHUNK ? mesh->ntris - i : MC_CHUNK, n = 0;
        for (size_t k = 0; k < m; k++) {
            if (keep != NULL && !keep[i + k])
                continue;
            for (int q = 0; q < 3; q++)
                tri[3 * n + q] = (int32_t)canon[3 * (i + k) + q];
            n++;
        }
        if (kept != NULL) {
            memcpy(*kept + 3 * *nkept, tri, 3 * n * sizeof *tri);
            *nkept += n;
        }
        st = gdt_mesh_write_faces(w, tri, n, err);
    }
    if (st == GDT_OK) {
        st = gdt_mesh_finish(w, err);
        w = NULL;
    }
fail:
    gdt_mesh_abort(w);
    free(keep);
    free(canon);
    free(tri);
    free(xyz);
    return st;
}

gdt_status gdt_memcloud_dem(gdt_memcloud *mc, const gdt_options *opts, const int32_t *tri,
                            size_t nf, gdt_pred_stats *pred, gdt_error *err)
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
        st = gdt_raster_faces(grid, pred, mc->pts, mc->kept, tri, nf, gdt_dem_sink, w, err);
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
    if (mc->dem_done)
        gdt_dem_report_line(opts, &mc->dem_geo, &mc->dem_stats);
}

gdt_status gdt_memcloud_finish(gdt_memcloud *mc, const gdt_options *opts,
                               const gdt_mesh *mesh, gdt_pred_stats *pred, double *t_check,
                               double *t_write, int *checked, gdt_trim_counts *tc,
                               gdt_error *err)
{
    int32_t *kept = NULL;
    size_t nkept = 0;
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
    st = gdt_memcloud_write(mc, opts, mesh, tc, opts->dem != NULL ? &kept : NULL, &nkept, err);
    *t_write = gdt_now() - t0;
    if (st == GDT_OK && opts->dem != NULL)
        st = gdt_memcloud_dem(mc, opts, kept, nkept, pred, err);
    free(kept);
    return st;
}

gdt_status gdt_memcloud_json_head(gdt_json *j, const gdt_memcloud *mc, const gdt_options *opts,
                                  const char *mode, uint64_t faces, const gdt_trim_counts *tc,
                                  gdt_error *err)
{
    const gdt_cloud_info *ci = gdt_cloud_get_info(mc->cloud);
    gdt_status st = gdt_json_open(j, opts->json, err);
    if (st != GDT_OK)
        return st;
    gdt_json_begin_object(j, NULL);
    gdt_json_string(j, "mode", mode);
    gdt_json_string(j, "output", opts->output);
    gdt_json_string(j, "output_format", gdt_mesh_format_name(gdt_mesh_format_of(opts->output)));
    gdt_json_uint(j, "inputs", ci->ninputs);
    gdt_json_uint(j, "points", mc->read);
    gdt_json_uint(j, "vertices", mc->kept);
    gdt_json_uint(j, "duplicates_merged", mc->read - mc->kept);
    gdt_json_uint(j, "faces", faces);
    gdt_json_string(j, "crs", ci->crs_desc);
    if (mc->dem_done)
        gdt_dem_report_json(j, opts, &mc->dem_geo, &mc->dem_stats, mc->t_dem);
    gdt_filter_report_json(j, mc->cloud);
    if (opts->ground)
        gdt_ground_report_json(j, &opts->pmf, mc->ground, mc->nonground, 1, 0, mc->t_ground);
    gdt_trim_report_json(j, &opts->trim, tc);
    return GDT_OK;
}
