/* gdt-tile INPUT... --reference -o OUT.ply: the whole cloud as one tile,
 * triangulated in memory by the CPU reference triangulator.
 *
 * This is the oracle mode: simple and exact, with memory proportional to the
 * input (about 150 bytes per point).  It shares the readers, the lattice,
 * the duplicate rule and the PLY writer with the tiled pipeline, so its
 * output is directly comparable.
 *
 * Output order: vertices by the lowest input ordinal of their (x, y); faces
 * in canonical order (each rotated to start at its smallest vertex index,
 * then sorted), so the bytes depend only on the point set and the input
 * order, never on the triangulator's internal order. */
#include "private/cli_modes.h"
#include "private/json_out.h"
#include "private/run_stats.h"

#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_cloud.h"
#include "gdt_mesh.h"
#include "gdt_ply.h"
#include "gdt_reference.h"

#define READ_CHUNK 65536
#define WRITE_CHUNK 65536

typedef struct ref_summary {
    uint64_t points_read;
    uint64_t vertices;
    uint64_t duplicates_merged;
    uint64_t faces;
    double t_read, t_triangulate, t_check, t_write;
    gdt_reference_stats rs;
    int checked;
} ref_summary;

static int cmp_ord(const void *a, const void *b)
{
    const gdt_point *p = a, *q = b;
    return (p->ord > q->ord) - (p->ord < q->ord);
}

/* Reads every point of the cloud into one growing array.
 * Ownership: *out is malloc'd, the caller frees it. */
static gdt_status read_all(gdt_cloud *cloud, gdt_point **out, size_t *n_out, gdt_error *err)
{
    size_t n = 0, cap = READ_CHUNK;
    gdt_point *pts = malloc(cap * sizeof *pts);
    gdt_status st = GDT_OK;

    if (pts == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    for (;;) {
        size_t got = 0;
        if (cap - n < READ_CHUNK) {
            gdt_point *grown;
            if (cap > SIZE_MAX / 2 / sizeof *pts) {
                st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
                goto fail;
            }
            grown = realloc(pts, 2 * cap * sizeof *pts);
            if (grown == NULL) {
                st = gdt_error_set(err, GDT_EINTERNAL, 7001,
                                   "out of memory reading %zu points into memory (--reference "
                                   "holds the whole cloud)", n);
                goto fail;
            }
            pts = grown;
            cap *= 2;
        }
        st = gdt_cloud_read(cloud, pts + n, READ_CHUNK, &got, err);
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

static gdt_status write_mesh(const gdt_options *opts, const gdt_cloud_info *ci,
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
    xyz = malloc(3 * WRITE_CHUNK * sizeof *xyz);
    tri = malloc(3 * WRITE_CHUNK * sizeof *tri);
    canon = malloc((mesh->ntris > 0 ? 3 * mesh->ntris : 1) * sizeof *canon);
    if (xyz == NULL || tri == NULL || canon == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    st = gdt_ply_create(&w, opts->output, &meta, err);
    if (st != GDT_OK)
        goto fail;
    for (size_t i = 0; i < mesh->nverts; i += WRITE_CHUNK) {
        size_t m = mesh->nverts - i < WRITE_CHUNK ? mesh->nverts - i : WRITE_CHUNK;
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
    for (size_t i = 0; i < mesh->ntris; i += WRITE_CHUNK) {
        size_t m = mesh->ntris - i < WRITE_CHUNK ? mesh->ntris - i : WRITE_CHUNK;
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

static gdt_status write_summary(const gdt_options *opts, const gdt_cloud_info *ci,
                                const ref_summary *s, gdt_error *err)
{
    gdt_json j;
    gdt_status st = gdt_json_open(&j, opts->json, err);
    if (st != GDT_OK)
        return st;
    gdt_json_begin_object(&j, NULL);
    gdt_json_string(&j, "mode", "reference");
    gdt_json_string(&j, "output", opts->output);
    gdt_json_uint(&j, "inputs", ci->ninputs);
    gdt_json_uint(&j, "points", s->points_read);
    gdt_json_uint(&j, "vertices", s->vertices);
    gdt_json_uint(&j, "duplicates_merged", s->duplicates_merged);
    gdt_json_uint(&j, "faces", s->faces);
    gdt_json_string(&j, "crs", ci->crs_desc);
    gdt_json_begin_object(&j, "times_s");
    gdt_json_double(&j, "read", s->t_read);
    gdt_json_double(&j, "triangulate", s->t_triangulate);
    if (s->checked)
        gdt_json_double(&j, "check", s->t_check);
    gdt_json_double(&j, "write", s->t_write);
    gdt_json_end_object(&j);
    gdt_json_begin_object(&j, "predicates");
    gdt_json_uint(&j, "orient2d", s->rs.pred.orient_calls);
    gdt_json_uint(&j, "incircle", s->rs.pred.incircle_calls);
    gdt_json_uint(&j, "incircle_exact", s->rs.pred.incircle_exact);
    gdt_json_uint(&j, "tiebreak", s->rs.pred.tiebreak_calls);
    gdt_json_end_object(&j);
    gdt_json_uint(&j, "flips", s->rs.insert_flips + s->rs.final.flips);
    gdt_json_bool(&j, "checked", s->checked);
    gdt_json_uint(&j, "peak_rss_bytes", gdt_peak_rss());
    gdt_json_end_object(&j);
    return gdt_json_close(&j, err);
}

gdt_status gdt_cli_reference(const gdt_options *opts, gdt_error *err)
{
    gdt_cloud *cloud = NULL;
    gdt_cloud_opts co;
    gdt_log log;
    gdt_point *pts = NULL;
    gdt_ipt *local = NULL;
    gdt_mesh mesh;
    ref_summary s;
    size_t n = 0, kept = 0;
    int64_t min_x = 0, min_y = 0;
    double t0;
    gdt_status st;

    memset(&s, 0, sizeof s);
    gdt_mesh_init(&mesh);
    gdt_log_init(&log, opts->verbosity);
    memset(&co, 0, sizeof co);
    co.log = &log;
    co.quantum = opts->quantum;

    t0 = gdt_now();
    st = gdt_cloud_open(&cloud, opts->inputs, opts->ninputs, &co, err);
    if (st != GDT_OK)
        goto fail;
    st = read_all(cloud, &pts, &n, err);
    if (st != GDT_OK)
        goto fail;
    st = gdt_points_dedup(pts, n, opts->dup, &kept, err);
    if (st != GDT_OK)
        goto fail;
    qsort(pts, kept, sizeof *pts, cmp_ord);
    s.points_read = n;
    s.vertices = kept;
    s.duplicates_merged = n - kept;
    s.t_read = gdt_now() - t0;

    /* One tile: every coordinate relative to the lower-left corner must be a
     * legal predicate coordinate. */
    if (kept > 0) {
        int64_t max_x = pts[0].x, max_y = pts[0].y;
        min_x = pts[0].x;
        min_y = pts[0].y;
        for (size_t i = 1; i < kept; i++) {
            if (pts[i].x < min_x) min_x = pts[i].x;
            if (pts[i].x > max_x) max_x = pts[i].x;
            if (pts[i].y < min_y) min_y = pts[i].y;
            if (pts[i].y > max_y) max_y = pts[i].y;
        }
        if (max_x - min_x > GDT_COORD_MAX || max_y - min_y > GDT_COORD_MAX) {
            st = gdt_error_set(err, GDT_EINPUT, 3401,
                               "%s: the cloud spans %" PRId64 " x %" PRId64 " lattice steps; "
                               "--reference handles at most 2^31-1 per axis (use a coarser "
                               "--quantum or the tiled pipeline)",
                               opts->inputs[0], max_x - min_x, max_y - min_y);
            goto fail;
        }
    }
    local = malloc((kept > 0 ? kept : 1) * sizeof *local);
    if (local == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    for (size_t i = 0; i < kept; i++) {
        local[i].x = pts[i].x - min_x;
        local[i].y = pts[i].y - min_y;
    }

    t0 = gdt_now();
    st = gdt_reference_triangulate(&s.rs, local, kept, &mesh, err);
    if (st != GDT_OK)
        goto fail;
    s.faces = mesh.ntris;
    s.t_triangulate = gdt_now() - t0;
    free(local);
    local = NULL;

    if (opts->check) {
        t0 = gdt_now();
        st = gdt_check_mesh(&s.rs.pred, &mesh, err);
        if (st == GDT_OK)
            st = gdt_check_delaunay(&s.rs.pred, &mesh, err);
        if (st != GDT_OK)
            goto fail;
        s.checked = 1;
        s.t_check = gdt_now() - t0;
    }

    t0 = gdt_now();
    st = write_mesh(opts, gdt_cloud_get_info(cloud), pts, &mesh, err);
    if (st != GDT_OK)
        goto fail;
    s.t_write = gdt_now() - t0;

    if (opts->json != NULL) {
        st = write_summary(opts, gdt_cloud_get_info(cloud), &s, err);
        if (st != GDT_OK)
            goto fail;
    }
    if (opts->verbosity >= 0)
        fprintf(stderr,
                "gdt-tile: %s: %" PRIu64 " points, %" PRIu64 " vertices (%" PRIu64
                " duplicates merged), %" PRIu64 " faces%s\n",
                opts->output, s.points_read, s.vertices, s.duplicates_merged, s.faces,
                s.checked ? ", checked exactly" : "");
    gdt_log_note(&log,
                 "predicates: orient2d %" PRIu64 ", incircle %" PRIu64 " (%" PRIu64
                 " exact), tie-breaks %" PRIu64 "; flips %" PRIu64 "; times: read %.3fs, "
                 "triangulate %.3fs, check %.3fs, write %.3fs",
                 s.rs.pred.orient_calls, s.rs.pred.incircle_calls, s.rs.pred.incircle_exact,
                 s.rs.pred.tiebreak_calls, s.rs.insert_flips + s.rs.final.flips, s.t_read,
                 s.t_triangulate, s.t_check, s.t_write);
fail:
    gdt_mesh_free(&mesh);
    free(local);
    free(pts);
    gdt_cloud_close(cloud);
    return st;
}
