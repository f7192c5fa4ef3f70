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
#include "private/memcloud.h"
#include "private/json_out.h"
#include "private/run_stats.h"
#include "private/trim_report.h"

#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_cloud.h"
#include "gdt_mesh.h"
#include "gdt_ply.h"
#include "gdt_reference.h"

typedef struct ref_summary {
    uint64_t points_read;
    uint64_t vertices;
    uint64_t duplicates_merged;
    uint64_t faces;
    double t_read, t_triangulate, t_check, t_write;
    gdt_reference_stats rs;
    int checked;
    gdt_trim_counts trim;
} ref_summary;

static gdt_status write_summary(const gdt_options *opts, const gdt_memcloud *mc,
                                const ref_summary *s, gdt_error *err)
{
    gdt_json j;
    gdt_status st = gdt_memcloud_json_head(&j, mc, opts, "reference", s->faces, &s->trim, err);
    if (st != GDT_OK)
        return st;
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
    gdt_memcloud mc;
    gdt_log log;
    gdt_mesh mesh;
    ref_summary s;
    gdt_filter_counts fc;
    char ftext[160], ttext[GDT_TRIM_TEXT_MAX];
    double t0;
    gdt_status st;

    memset(&s, 0, sizeof s);
    gdt_mesh_init(&mesh);
    gdt_log_init(&log, opts->verbosity);
    st = gdt_memcloud_load(&mc, opts, &log, "--reference", err);
    if (st == GDT_OK)
        st = gdt_cli_check_stop(opts, "the reading", err);
    if (st != GDT_OK)
        goto fail;
    s.points_read = mc.read;
    s.vertices = mc.kept;
    s.duplicates_merged = mc.read - mc.kept;
    s.t_read = mc.t_read;

    t0 = gdt_now();
    st = gdt_reference_triangulate(&s.rs, mc.local, mc.kept, &mesh, err);
    if (st != GDT_OK)
        goto fail;
    s.faces = mesh.ntris;
    s.t_triangulate = gdt_now() - t0;
    st = gdt_cli_check_stop(opts, "the triangulation", err);
    if (st != GDT_OK)
        goto fail;

    st = gdt_memcloud_finish(&mc, opts, &mesh, &s.rs.pred, &s.t_check, &s.t_write, &s.checked,
                             &s.trim, err);
    if (st != GDT_OK)
        goto fail;
    s.faces = s.trim.faces - s.trim.dropped;

    if (opts->json != NULL) {
        st = write_summary(opts, &mc, &s, err);
        if (st != GDT_OK)
            goto fail;
    }
    fc = gdt_cloud_total_counts(mc.cloud);
    gdt_filter_counts_text(&opts->filter, &fc, ftext, sizeof ftext);
    gdt_trim_report_text(&opts->trim, &s.trim, ttext, sizeof ttext);
    if (opts->verbosity >= 0)
        fprintf(stderr,
                "gdt-tile: %s: %" PRIu64 " points%s, %" PRIu64 " vertices (%" PRIu64
                " duplicates merged), %" PRIu64 " faces%s%s\n",
                opts->output, s.points_read, ftext, s.vertices, s.duplicates_merged, s.faces,
                ttext, s.checked ? ", checked exactly" : "");
    gdt_memcloud_print_dem(&mc, opts);
    gdt_log_note(&log,
                 "predicates: orient2d %" PRIu64 ", incircle %" PRIu64 " (%" PRIu64
                 " exact), tie-breaks %" PRIu64 "; flips %" PRIu64 "; times: read %.3fs, "
                 "triangulate %.3fs, check %.3fs, write %.3fs",
                 s.rs.pred.orient_calls, s.rs.pred.incircle_calls, s.rs.pred.incircle_exact,
                 s.rs.pred.tiebreak_calls, s.rs.insert_flips + s.rs.final.flips, s.t_read,
                 s.t_triangulate, s.t_check, s.t_write);
fail:
    gdt_mesh_free(&mesh);
    gdt_memcloud_free(&mc);
    return st;
}
