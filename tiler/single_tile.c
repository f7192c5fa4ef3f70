/* gdt-tile INPUT... --tile N -o OUT.ply for a cloud that fits one tile: the
 * per-tile OpenCL core (gdt_core.h) on the whole cloud, in memory.
 *
 * It shares the readers, the lattice, the duplicate rule and the PLY layout
 * with --reference, so both outputs are directly comparable: for the same
 * inputs they are byte-identical (the triangulation is unique, and the
 * vertex and face orders depend only on the point set and the input order).
 * Memory: about 150 bytes per point on the host, plus the device buffers of
 * the core (about 60 bytes per texel and 250 per point). */
#include "private/single_tile.h"

#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_cloud.h"
#include "gdt_core.h"
#include "gdt_mesh.h"
#include "gdt_ply.h"
#include "gdt_predicates.h"
#include "private/json_out.h"
#include "private/run_stats.h"

#define ST_READ_CHUNK 65536
#define ST_WRITE_CHUNK 65536

typedef struct st_summary {
    uint64_t points_read, vertices, duplicates_merged, faces;
    double t_read, t_device, t_triangulate, t_check, t_write;
    gdt_core_stats cs;
    gdt_pred_stats pred;
    int checked;
    const char *device;
} st_summary;

static int st_cmp_ord(const void *a, const void *b)
{
    const gdt_point *p = a, *q = b;
    return (p->ord > q->ord) - (p->ord < q->ord);
}

/* Every point of the cloud in one growing array.
 * Ownership: *out is malloc'ed, the caller frees it. */
static gdt_status st_read_all(gdt_cloud *cloud, gdt_point **out, size_t *n_out, gdt_error *err)
{
    size_t n = 0, cap = ST_READ_CHUNK;
    gdt_point *pts = malloc(cap * sizeof *pts);
    gdt_status st = GDT_OK;

    if (pts == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    for (;;) {
        size_t got = 0;
        if (cap - n < ST_READ_CHUNK) {
            gdt_point *grown;
            if (cap > SIZE_MAX / 2 / sizeof *pts) {
                st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
                goto fail;
            }
            grown = realloc(pts, 2 * cap * sizeof *pts);
            if (grown == NULL) {
                st = gdt_error_set(err, GDT_EINTERNAL, 7001,
                                   "out of memory reading %zu points into one tile", n);
                goto fail;
            }
            pts = grown;
            cap *= 2;
        }
        st = gdt_cloud_read(cloud, pts + n, ST_READ_CHUNK, &got, err);
        if (st != GDT_OK)
            goto fail;
        if (got == 0)
            break;
        n += got;
    }
    *out = pts;
    *n_out = n;
    return GDT_OK;
fail:
    free(pts);
    return st;
}

static gdt_status st_write_mesh(const gdt_options *opts, const gdt_cloud_info *ci,
                                const gdt_point *verts, const gdt_mesh *mesh, gdt_error *err)
{
    gdt_ply_writer *w = NULL;
    gdt_ply_meta meta;
    int64_t *canon = NULL;
    double *xyz = NULL;
    int32_t *tri = NULL;
    gdt_status st;

    memset(&meta, 0, sizeof meta);
    meta.lattice = ci->lattice;
    meta.epsg = ci->epsg;
    meta.crs_wkt = ci->crs_wkt;
    xyz = malloc(3 * ST_WRITE_CHUNK * sizeof *xyz);
    tri = malloc(3 * ST_WRITE_CHUNK * sizeof *tri);
    canon = malloc((mesh->ntris > 0 ? 3 * mesh->ntris : 1) * sizeof *canon);
    if (xyz == NULL || tri == NULL || canon == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    st = gdt_ply_create(&w, opts->output, &meta, err);
    if (st != GDT_OK)
        goto fail;
    for (size_t i = 0; i < mesh->nverts; i += ST_WRITE_CHUNK) {
        size_t m = mesh->nverts - i < ST_WRITE_CHUNK ? mesh->nverts - i : ST_WRITE_CHUNK;
        for (size_t k = 0; k < m; k++) {
            const gdt_point *p = &verts[i + k];
            xyz[3 * k + 0] = ci->lattice.ox + ci->lattice.sx * (double)p->x;
            xyz[3 * k + 1] = ci->lattice.oy + ci->lattice.sy * (double)p->y;
            xyz[3 * k + 2] = p->z;
        }
        st = gdt_ply_write_vertices(w, xyz, m, err);
        if (st != GDT_OK)
            goto fail;
    }
    gdt_mesh_canonical(mesh, canon);
    for (size_t i = 0; i < mesh->ntris; i += ST_WRITE_CHUNK) {
        size_t m = mesh->ntris - i < ST_WRITE_CHUNK ? mesh->ntris - i : ST_WRITE_CHUNK;
        for (size_t k = 0; k < 3 * m; k++)
            tri[k] = (int32_t)canon[3 * i + k];
        st = gdt_ply_write_faces(w, tri, m, err);
        if (st != GDT_OK)
            goto fail;
    }
    st = gdt_ply_finish(w, err);
    w = NULL;
fail:
    gdt_ply_abort(w);
    free(canon);
    free(tri);
    free(xyz);
    return st;
}

static gdt_status st_write_summary(const gdt_options *opts, const gdt_cloud_info *ci,
                                   const st_summary *s, gdt_error *err)
{
    const gdt_core_stats *c = &s->cs;
    gdt_json j;
    gdt_status st = gdt_json_open(&j, opts->json, err);
    if (st != GDT_OK)
        return st;
    gdt_json_begin_object(&j, NULL);
    gdt_json_string(&j, "mode", "single-tile");
    gdt_json_string(&j, "output", opts->output);
    gdt_json_uint(&j, "inputs", ci->ninputs);
    gdt_json_uint(&j, "points", s->points_read);
    gdt_json_uint(&j, "vertices", s->vertices);
    gdt_json_uint(&j, "duplicates_merged", s->duplicates_merged);
    gdt_json_uint(&j, "faces", s->faces);
    gdt_json_string(&j, "crs", ci->crs_desc);
    gdt_json_string(&j, "device", s->device);
    gdt_json_begin_array(&j, "tiles");
    gdt_json_begin_object(&j, NULL);
    gdt_json_uint(&j, "tile", (uint64_t)opts->tile);
    gdt_json_uint(&j, "grid_w", c->grid_w);
    gdt_json_uint(&j, "grid_h", c->grid_h);
    gdt_json_int(&j, "cell_lattice", c->cell);
    gdt_json_double(&j, "cell_crs", (double)c->cell * ci->lattice.sx);
    gdt_json_string(&j, "path", c->path);
    gdt_json_string(&j, "path_reason", c->path_reason);
    gdt_json_begin_object(&j, "phase_times_s");
    gdt_json_double(&j, "upload", c->t_upload);
    gdt_json_double(&j, "phase1_voronoi", c->t_phase1);
    gdt_json_double(&j, "phase2_dual", c->t_phase2);
    gdt_json_double(&j, "phase3_shift", c->t_phase3);
    gdt_json_double(&j, "phase4_insert", c->t_phase4);
    gdt_json_double(&j, "phase5_flip", c->t_phase5);
    gdt_json_double(&j, "download", c->t_download);
    gdt_json_double(&j, "total", c->t_total);
    gdt_json_end_object(&j);
    gdt_json_begin_object(&j, "phase1");
    gdt_json_uint(&j, "kept", c->kept);
    gdt_json_uint(&j, "missing_points", c->missing_phase1);
    gdt_json_uint(&j, "debris_texels", c->debris_texels);
    gdt_json_end_object(&j);
    gdt_json_begin_object(&j, "phase2");
    gdt_json_uint(&j, "dual_triangles", c->dual_triangles);
    gdt_json_uint(&j, "fake_boundary_triangles", c->fake_triangles);
    gdt_json_end_object(&j);
    gdt_json_begin_object(&j, "phase3");
    gdt_json_uint(&j, "shifted", c->shifted);
    gdt_json_uint(&j, "bad_cases", c->bad_cases);
    gdt_json_uint(&j, "shift_iterations", c->shift_iterations);
    gdt_json_uint(&j, "delete_iterations", c->delete_iterations);
    gdt_json_end_object(&j);
    gdt_json_begin_object(&j, "phase4");
    gdt_json_uint(&j, "inserted", c->inserted);
    gdt_json_uint(&j, "iterations", c->insert_iterations);
    gdt_json_uint(&j, "walk_steps", c->walk_steps);
    gdt_json_uint(&j, "flips", c->insert_flips);
    gdt_json_end_object(&j);
    gdt_json_begin_object(&j, "phase5");
    gdt_json_uint(&j, "flips", c->flips);
    gdt_json_uint(&j, "iterations", c->flip_iterations);
    gdt_json_uint(&j, "incircle_tests", c->edges_tested);
    gdt_json_uint(&j, "exact_escalations", c->exact_escalations);
    gdt_json_uint(&j, "tiebreaks", c->tiebreaks);
    gdt_json_end_object(&j);
    gdt_json_end_object(&j);
    gdt_json_end_array(&j);
    gdt_json_begin_object(&j, "times_s");
    gdt_json_double(&j, "read", s->t_read);
    gdt_json_double(&j, "device_setup", s->t_device);
    gdt_json_double(&j, "triangulate", s->t_triangulate);
    if (s->checked)
        gdt_json_double(&j, "check", s->t_check);
    gdt_json_double(&j, "write", s->t_write);
    gdt_json_end_object(&j);
    gdt_json_bool(&j, "checked", s->checked);
    gdt_json_uint(&j, "peak_rss_bytes", gdt_peak_rss());
    gdt_json_end_object(&j);
    return gdt_json_close(&j, err);
}

gdt_status gdt_cli_single_tile(const gdt_options *opts, gdt_error *err)
{
    gdt_cloud *cloud = NULL;
    gdt_cloud_opts co;
    gdt_core_opts copt;
    gdt_core *core = NULL;
    gdt_log log;
    gdt_point *pts = NULL;
    gdt_ipt *local = NULL;
    gdt_mesh mesh;
    st_summary s;
    size_t n = 0, kept = 0;
    unsigned faults = 0;
    double t0;
    gdt_status st;

    memset(&s, 0, sizeof s);
    gdt_mesh_init(&mesh);
    gdt_log_init(&log, opts->verbosity);
    /* the filters' error analysis needs IEEE double without contraction */
    st = gdt_predicates_selftest(&faults, err);
    if (st != GDT_OK)
        return st;

    t0 = gdt_now();
    memset(&co, 0, sizeof co);
    co.log = &log;
    co.quantum = opts->quantum;
    st = gdt_cloud_open(&cloud, opts->inputs, opts->ninputs, &co, err);
    if (st != GDT_OK)
        goto fail;
    st = st_read_all(cloud, &pts, &n, err);
    if (st != GDT_OK)
        goto fail;
    st = gdt_points_dedup(pts, n, opts->dup, &kept, err);
    if (st != GDT_OK)
        goto fail;
    qsort(pts, kept, sizeof *pts, st_cmp_ord);
    s.points_read = n;
    s.vertices = kept;
    s.duplicates_merged = n - kept;
    s.t_read = gdt_now() - t0;

    local = malloc((kept > 0 ? kept : 1) * sizeof *local);
    if (local == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    if (kept > 0) {
        int64_t min_x = pts[0].x, min_y = pts[0].y, max_x = pts[0].x, max_y = pts[0].y;
        for (size_t i = 1; i < kept; i++) {
            if (pts[i].x < min_x) min_x = pts[i].x;
            if (pts[i].x > max_x) max_x = pts[i].x;
            if (pts[i].y < min_y) min_y = pts[i].y;
            if (pts[i].y > max_y) max_y = pts[i].y;
        }
        if (max_x - min_x > GDT_COORD_MAX || max_y - min_y > GDT_COORD_MAX) {
            st = gdt_error_set(err, GDT_EINPUT, 3603,
                               "%s: the cloud spans %" PRId64 " x %" PRId64 " lattice steps; "
                               "one tile holds at most 2^31-1 per axis (use a coarser "
                               "--quantum or the tiled pipeline)",
                               opts->inputs[0], max_x - min_x, max_y - min_y);
            goto fail;
        }
        for (size_t i = 0; i < kept; i++) {
            local[i].x = pts[i].x - min_x;
            local[i].y = pts[i].y - min_y;
        }
    }

    t0 = gdt_now();
    memset(&copt, 0, sizeof copt);
    copt.device = opts->device;
    copt.log = &log;
    st = gdt_core_create(&core, &copt, err);
    if (st != GDT_OK)
        goto fail;
    s.device = gdt_core_device_name(core);
    s.t_device = gdt_now() - t0;

    t0 = gdt_now();
    st = gdt_core_triangulate(core, local, kept, opts->tile, &mesh, &s.cs, err);
    if (st != GDT_OK)
        goto fail;
    s.faces = mesh.ntris;
    s.t_triangulate = gdt_now() - t0;
    free(local);
    local = NULL;

    if (opts->check) {
        t0 = gdt_now();
        st = gdt_check_mesh(&s.pred, &mesh, err);
        if (st == GDT_OK)
            st = gdt_check_delaunay(&s.pred, &mesh, err);
        if (st != GDT_OK)
            goto fail;
        s.checked = 1;
        s.t_check = gdt_now() - t0;
    }

    t0 = gdt_now();
    st = st_write_mesh(opts, gdt_cloud_get_info(cloud), pts, &mesh, err);
    if (st != GDT_OK)
        goto fail;
    s.t_write = gdt_now() - t0;

    if (opts->json != NULL) {
        st = st_write_summary(opts, gdt_cloud_get_info(cloud), &s, err);
        if (st != GDT_OK)
            goto fail;
    }
    if (opts->verbosity >= 0)
        fprintf(stderr,
                "gdt-tile: %s: %" PRIu64 " points, %" PRIu64 " vertices (%" PRIu64
                " duplicates merged), %" PRIu64 " faces on %s (%s path)%s\n",
                opts->output, s.points_read, s.vertices, s.duplicates_merged, s.faces, s.device,
                s.cs.path, s.checked ? ", checked exactly" : "");
    gdt_log_note(&log,
                 "tile %dx%d texels of %" PRId64 " lattice steps: %s; phases %.3f %.3f %.3f %.3f "
                 "%.3f s; missing %" PRIu64 ", bad cases %" PRIu64 ", flips %" PRIu64
                 ", exact escalations %" PRIu64,
                 (int)s.cs.grid_w, (int)s.cs.grid_h, s.cs.cell, s.cs.path_reason, s.cs.t_phase1,
                 s.cs.t_phase2, s.cs.t_phase3, s.cs.t_phase4, s.cs.t_phase5, s.cs.missing_phase1,
                 s.cs.bad_cases, s.cs.flips + s.cs.insert_flips, s.cs.exact_escalations);
fail:
    gdt_core_destroy(core);
    gdt_mesh_free(&mesh);
    free(local);
    free(pts);
    gdt_cloud_close(cloud);
    return st;
}
