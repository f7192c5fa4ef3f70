/* gdt-tile INPUT... --tile N -o OUT.ply for a cloud that fits one tile: the
 * per-tile OpenCL core (gdt_core.h) on the whole cloud, in memory.
 *
 * It shares the readers, the lattice, the duplicate rule and the PLY layout
 * with --reference, so both outputs are directly comparable: for the same
 * inputs they are byte-identical (the triangulation is unique, and the
 * vertex and face orders depend only on the point set and the input order).
 * Memory: about 150 bytes per point on the host, plus the device buffers of
 * the core (about 400 bytes per point, and up to 16 more per texel). */
#include "private/single_tile.h"
#include "private/cli_modes.h"
#include "private/memcloud.h"

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
#include "private/trim_report.h"

typedef struct st_summary {
    uint64_t points_read, vertices, duplicates_merged, faces;
    double t_read, t_device, t_triangulate, t_check, t_write;
    gdt_core_stats cs;
    gdt_pred_stats pred;
    int checked;
    gdt_trim_counts trim;
    const char *device;
} st_summary;

static gdt_status st_write_summary(const gdt_options *opts, const gdt_memcloud *mc,
                                   const st_summary *s, gdt_error *err)
{
    const gdt_core_stats *c = &s->cs;
    const gdt_cloud_info *ci = gdt_cloud_get_info(mc->cloud);
    gdt_json j;
    gdt_status st = gdt_memcloud_json_head(&j, mc, opts, "single-tile", s->faces, &s->trim, err);
    if (st != GDT_OK)
        return st;
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
    gdt_memcloud mc;
    gdt_core_opts copt;
    gdt_core *core = NULL;
    gdt_log log;
    gdt_mesh mesh;
    st_summary s;
    gdt_filter_counts fc;
    char ftext[160], ttext[GDT_TRIM_TEXT_MAX];
    unsigned faults = 0;
    double t0;
    gdt_status st;

    memset(&s, 0, sizeof s);
    gdt_mesh_init(&mesh);
    gdt_log_init(&log, opts->verbosity);
    /* the filters' error analysis needs IEEE double without contraction */
    memset(&mc, 0, sizeof mc);
    st = gdt_predicates_selftest(&faults, err);
    if (st != GDT_OK)
        return st;

    st = gdt_memcloud_load(&mc, opts, &log, "--single-tile", err);
    if (st == GDT_OK)
        st = gdt_cli_check_stop(opts, "the reading", err);
    /* Without a class or return filter the header counts were checked before
     * (check_one_tile in cli.c); with one, the points kept are checked here. */
    if (st == GDT_OK && gdt_filter_uses_attributes(&opts->filter) &&
        mc.read > (uint64_t)opts->tile * (uint64_t)opts->tile / 2)
        st = gdt_error_set(err, GDT_EUSAGE, 2109,
                           "--single-tile: the filter keeps %zu points, more than one tile "
                           "of %d x %d texels takes (%llu); use a larger --tile or the "
                           "tiled pipeline (without --single-tile)",
                           mc.read, opts->tile, opts->tile,
                           (unsigned long long)opts->tile * (unsigned long long)opts->tile / 2);
    if (st != GDT_OK)
        goto fail;
    s.points_read = mc.read;
    s.vertices = mc.kept;
    s.duplicates_merged = mc.read - mc.kept;
    s.t_read = mc.t_read;

    t0 = gdt_now();
    memset(&copt, 0, sizeof copt);
    copt.device = opts->device;
    copt.log = &log;
    copt.stop = opts->stop;
    st = gdt_core_create(&core, &copt, err);
    if (opts->stop != NULL && *opts->stop != 0) {
        /* a signal during the kernel build; when the build failed, the
         * signal was the cause (the compiler removes its files on it) */
        gdt_error_clear(err);
        st = gdt_cli_check_stop(opts, "the OpenCL start-up", err);
    }
    if (st != GDT_OK)
        goto fail;
    s.device = gdt_core_device_name(core);
    s.t_device = gdt_now() - t0;

    t0 = gdt_now();
    st = gdt_core_triangulate(core, mc.local, mc.kept, opts->tile, &mesh, &s.cs, err);
    if (st != GDT_OK)
        goto fail;
    s.faces = mesh.ntris;
    s.t_triangulate = gdt_now() - t0;
    st = gdt_cli_check_stop(opts, "the triangulation", err);
    if (st != GDT_OK)
        goto fail;

    st = gdt_memcloud_finish(&mc, opts, &mesh, &s.pred, &s.t_check, &s.t_write, &s.checked,
                             &s.trim, err);
    if (st != GDT_OK)
        goto fail;
    s.faces = s.trim.faces - s.trim.dropped;

    if (opts->json != NULL) {
        st = st_write_summary(opts, &mc, &s, err);
        if (st != GDT_OK)
            goto fail;
    }
    fc = gdt_cloud_total_counts(mc.cloud);
    gdt_filter_counts_text(&opts->filter, &fc, ftext, sizeof ftext);
    gdt_trim_report_text(&opts->trim, &s.trim, ttext, sizeof ttext);
    if (opts->verbosity >= 0)
        fprintf(stderr,
                "gdt-tile: %s: %" PRIu64 " points%s, %" PRIu64 " vertices (%" PRIu64
                " duplicates merged), %" PRIu64 " faces%s on %s (%s path)%s\n",
                opts->output, s.points_read, ftext, s.vertices, s.duplicates_merged, s.faces, ttext, s.device,
                s.cs.path, s.checked ? ", checked exactly" : "");
    gdt_memcloud_print_dem(&mc, opts);
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
    gdt_memcloud_free(&mc);
    return st;
}
