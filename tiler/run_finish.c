/* run_finish.c — the output of a tiled run: the mesh writer and the DEM,
 * started before the tile stage and completed after the merge (Euler
 * check), --check, --json and the summary, and the release of the run
 * (private/stages.h). */
#include "private/ground_out.h"
#include "private/stages.h"

#include <inttypes.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "gdt_ocl.h"
#include "gdt_plycheck.h"
#include "private/dem_report.h"
#include "private/ground_report.h"
#include "private/json_out.h"
#include "private/mesh_meta.h"
#include "private/tiled_files.h"

/* --check: the exact streaming validator on the written mesh (bounded
 * memory, temporary files in the job directory).  A PLY output is read
 * back itself; an OBJ or LandXML output through the PLY copy of the same
 * records that the writer thread wrote beside it (every number of the text
 * was verified to read back as the same double when written).  A mesh
 * that fails is renamed to OUT.rejected, so no invalid file stays at the
 * output path. */
static gdt_status check_output(tr_run *c, gdt_error *err)
{
    gdt_plycheck_opts po;
    gdt_plycheck_result res;
    gdt_status st;
    const char *path = c->check_ply != NULL ? c->check_ply : c->opts->output;

    gdt_plycheck_opts_init(&po);
    if (c->opts->mem_budget != 0)
        po.mem_budget = (size_t)c->opts->mem_budget;
    po.temp_dir = c->job;
    st = gdt_ply_check(&po, path, &res, err);
    if (st == GDT_OK && (res.vertices != c->s.vertices || res.faces != c->s.faces))
        st = gdt_error_set(err, GDT_EINTERNAL, 7821,
                           "%s: holds %" PRIu64 " vertices and %" PRIu64
                           " faces, the run made %" PRIu64 " and %" PRIu64,
                           path, res.vertices, res.faces, c->s.vertices, c->s.faces);
    if (st == GDT_EINTERNAL) {
        size_t l = strlen(c->opts->output);
        char *bad = malloc(l + 10);
        if (bad != NULL) {
            memcpy(bad, c->opts->output, l);
            memcpy(bad + l, ".rejected", 10);
            if (rename(c->opts->output, bad) == 0)
                gdt_log_warn(&c->log, 7822, "the mesh that failed --check is kept as %s", bad);
            free(bad);
        }
    }
    if (c->check_ply != NULL)
        unlink(c->check_ply);
    return st;
}

/* The DEM's build on a thread of its own, started when the mesh has every
 * face (and the DEM every cell), so that its CPU work runs beside the
 * mesh's sync, which waits for the disk.  Only the commit puts the DEM in
 * place, after the mesh is: a failed mesh leaves no new DEM either. */
typedef struct dem_bg {
    tr_run *c;
    pthread_t tid;
    int started; /* a thread runs the build */
    int built;   /* the build ran (on the thread or here): st and err hold its result */
    gdt_status st;
    gdt_error err;
    double t; /* its seconds */
} dem_bg;

static void *dem_build_main(void *arg)
{
    dem_bg *b = arg;
    double t0 = gdt_now();
    gdt_error_clear(&b->err);
    b->st = tr_dem_build(b->c->dem, &b->c->s.dem_geo, &b->c->s.dem_stats, &b->err);
    b->t = gdt_now() - t0;
    b->built = 1;
    return NULL;
}

/* tr_out_on_complete: the build starts; without a thread it runs later,
 * in dem_finish. */
static void dem_build_start(void *arg)
{
    dem_bg *b = arg;
    b->started = pthread_create(&b->tid, NULL, dem_build_main, b) == 0;
}

/* After the mesh (its status st): the build joined or run, then the commit
 * when both succeeded, else the DEM dropped.  returns: the first failure. */
static gdt_status dem_finish(tr_run *c, dem_bg *b, gdt_status st, gdt_error *err)
{
    double t0;
    if (b->started)
        pthread_join(b->tid, NULL);
    else if (st == GDT_OK)
        dem_build_main(b);
    t0 = gdt_now();
    if (st == GDT_OK && b->built && b->st != GDT_OK) {
        st = b->st;
        *err = b->err;
    }
    if (st == GDT_OK) {
        st = tr_dem_commit(c->dem, err);
        c->s.dem_done = st == GDT_OK;
    } else {
        tr_dem_abort(c->dem);
    }
    c->dem = NULL;
    c->s.t_dem = b->t + (gdt_now() - t0);
    return st;
}

static gdt_status write_summary(const tr_run *c, gdt_error *err)
{
    const tr_summary *s = &c->s;
    const gdt_tile_plan *pl = c->plan;
    gdt_json j;
    gdt_status st = gdt_json_open(&j, c->opts->json, err);
    if (st != GDT_OK)
        return st;
    gdt_json_begin_object(&j, NULL);
    gdt_json_string(&j, "mode", "tiled");
    gdt_json_string(&j, "output", c->opts->output);
    gdt_json_string(&j, "output_format", gdt_mesh_format_name(gdt_mesh_format_of(c->opts->output)));
    gdt_json_string(&j, "device", s->device);
    if (s->dem_done)
        gdt_dem_report_json(&j, c->opts, &s->dem_geo, &s->dem_stats, s->t_dem);
    gdt_json_uint(&j, "points_read", s->points_read);
    gdt_filter_report_json(&j, c->cloud);
    if (c->opts->ground) /* the counts are recorded with pass 2 */
        gdt_ground_report_json(&j, &c->opts->pmf, s->ground_points, s->nonground_points,
                               s->t_ground > 0, s->ground_tiles_reused, s->t_ground);
    gdt_json_uint(&j, "vertices", s->vertices);
    gdt_json_uint(&j, "faces", s->faces - s->trim.dropped);
    gdt_trim_report_json(&j, &c->opts->trim, &s->trim);
    gdt_json_uint(&j, "tiles", s->tiles);
    gdt_json_uint(&j, "tile", (uint64_t)pl->tile);
    gdt_json_bool(&j, "tile_auto", c->tile_auto);
    gdt_json_int(&j, "cell", pl->cell);
    gdt_json_int(&j, "halo", pl->halo);
    gdt_json_uint(&j, "gcd_tiles", s->gcd_tiles);
    gdt_json_uint(&j, "insert_tiles", s->insert_tiles);
    gdt_json_uint(&j, "max_tile_points", s->max_tile_points);
    gdt_json_uint(&j, "max_halo_points", s->max_halo_points);
    gdt_json_uint(&j, "certified_faces", s->certified);
    gdt_json_uint(&j, "merge_faces", s->merge_faces);
    gdt_json_double(&j, "certified_fraction",
                    s->faces > 0 ? (double)s->certified / (double)s->faces : 1.0);
    gdt_json_uint(&j, "seam_vertices", s->merge.seam_vertices);
    gdt_json_uint(&j, "barrier_edges", s->merge.barrier_edges);
    gdt_json_uint(&j, "seam_triangles", s->merge.seam_triangles);
    gdt_json_uint(&j, "hull_vertices", s->merge.hull_vertices);
    gdt_json_uint(&j, "merge_rounds", s->merge.rounds);
    gdt_json_uint(&j, "merge_deferred_rounds", s->merge.deferred);
    gdt_json_uint(&j, "merge_max_band_vertices", s->merge.max_band_vertices);
    gdt_json_uint(&j, "merge_peak_bytes", s->merge.peak_bytes);
    /* the band triangulations' Lawson flips (insertion and closing pass) */
    gdt_json_uint(&j, "merge_flips", s->merge.ref.insert_flips + s->merge.ref.final.flips);
    gdt_json_begin_object(&j, "certification");
    gdt_json_uint(&j, "triangles", s->cert.triangles);
    gdt_json_uint(&j, "inner", s->cert.inner);
    gdt_json_uint(&j, "outside_known", s->cert.outside_known);
    gdt_json_uint(&j, "halo_hit", s->cert.halo_hit);
    gdt_json_uint(&j, "halo_tests", s->cert.halo_tests);
    gdt_json_end_object(&j);
    gdt_json_begin_object(&j, "times");
    gdt_json_double(&j, "pass1", s->t_pass1);
    gdt_json_double(&j, "pass2", s->t_pass2);
    if (c->opts->ground)
        gdt_json_double(&j, "ground", s->t_ground);
    gdt_json_double(&j, "tiles", s->t_tiles);
    gdt_json_double(&j, "core", s->t_core);
    gdt_json_double(&j, "certify", s->t_certify);
    gdt_json_double(&j, "post", s->t_post);
    gdt_json_double(&j, "device_busy", s->t_device);
    gdt_json_double(&j, "device_busy_share",
                    s->t_device_span > 0.0 ? s->t_device / s->t_device_span : 0.0);
    gdt_json_double(&j, "merge", s->t_merge);
    gdt_json_double(&j, "write", s->t_write);
    if (s->nranks > 1 && c->out_parts) /* beside the merge, not after it */
        gdt_json_double(&j, "parts", s->t_parts);
    if (s->checked)
        gdt_json_double(&j, "check", s->t_check);
    gdt_json_double(&j, "total", s->t_total);
    gdt_json_end_object(&j);
    if (s->nranks > 1) {
        double sum = 0, max = 0;
        for (int r = 0; r < s->nranks; r++) {
            sum += s->ranks[r].t_tiles;
            if (s->ranks[r].t_tiles > max)
                max = s->ranks[r].t_tiles;
        }
        gdt_json_begin_object(&j, "mpi");
        gdt_json_int(&j, "ranks", s->nranks);
        /* the slowest rank's tile stage over the mean: 1 is perfect */
        gdt_json_double(&j, "load_balance", sum > 0 ? max * s->nranks / sum : 1.0);
        /* a plain PLY's blocks are written by the ranks owning their tiles */
        gdt_json_string(&j, "mesh_written_by", c->out_parts ? "tile owners" : "rank 0");
        /* with the mesh in parts, each rank rasterises its tiles for the DEM */
        if (c->opts->dem != NULL)
            gdt_json_string(&j, "dem_rasterised_by", c->out_parts ? "tile owners" : "rank 0");
        if (c->opts->ground_out != NULL)
            gdt_json_string(&j, "ground_out_written_by",
                            s->ground_out_shared ? "ranks in shares" : "rank 0");
        gdt_json_begin_array(&j, "per_rank");
        for (int r = 0; r < s->nranks; r++) {
            const tr_rank_stats *q = &s->ranks[r];
            gdt_json_begin_object(&j, NULL);
            gdt_json_int(&j, "rank", r);
            gdt_json_string(&j, "device", q->device);
            gdt_json_uint(&j, "tiles", q->tiles);
            gdt_json_uint(&j, "tiles_on_demand", q->on_demand);
            gdt_json_uint(&j, "tiles_reused", q->reused);
            gdt_json_uint(&j, "vertices", q->vertices);
            gdt_json_uint(&j, "certified_faces", q->certified);
            /* its own parts of the passes (0: adopted from an earlier run) */
            gdt_json_double(&j, "pass1_s", q->t_pass1);
            gdt_json_double(&j, "pass2_s", q->t_pass2);
            gdt_json_double(&j, "tiles_s", q->t_tiles);
            gdt_json_double(&j, "core_s", q->t_core);
            gdt_json_double(&j, "certify_s", q->t_certify);
            gdt_json_double(&j, "post_s", q->t_post);
            gdt_json_double(&j, "device_busy_s", q->t_device);
            gdt_json_double(&j, "device_busy_share",
                            q->t_device_span > 0.0 ? q->t_device / q->t_device_span : 0.0);
            gdt_json_uint(&j, "replayed_inputs", q->replayed);
            if (c->out_parts) {
                gdt_json_double(&j, "write_s", q->t_write);
                gdt_json_uint(&j, "tiles_placed_early", q->placed_early);
            }
            if (c->opts->ground) {
                /* 0 when a resumed job took the classes of an earlier run */
                gdt_json_uint(&j, "ground_tiles", q->ground_tiles);
                gdt_json_double(&j, "ground_s", q->t_ground);
            }
            gdt_json_end_object(&j);
        }
        gdt_json_end_array(&j);
        gdt_json_end_object(&j);
    }
    gdt_json_bool(&j, "checked", s->checked);
    gdt_json_bool(&j, "resumed", s->resumed);
    gdt_json_begin_object(&j, "reused");
    gdt_json_bool(&j, "pass2", s->pass2_reused);
    gdt_json_uint(&j, "tiles", s->tiles_reused);
    gdt_json_end_object(&j);
    gdt_json_begin_object(&j, "redone");
    gdt_json_bool(&j, "pass2", !s->pass2_reused);
    gdt_json_uint(&j, "tiles", s->tiles_redone);
    gdt_json_end_object(&j);
    gdt_json_uint(&j, "peak_rss_bytes", gdt_peak_rss());
    gdt_json_end_object(&j);
    return gdt_json_close(&j, err);
}

gdt_status tr_run_output_start(tr_run *c, gdt_error *err)
{
    const gdt_options *opts = c->opts;
    const gdt_cloud_info *ci = gdt_cloud_get_info(c->cloud);
    uint64_t ntiles = gdt_tiler_tile_count(c->tiler);
    tr_out_src os;
    gdt_status st;

    c->trim = opts->trim;
    c->trim.sx = ci->lattice.sx;
    c->trim.sy = ci->lattice.sy;
    if (gdt_trim_on(&c->trim) && (st = gdt_trim_graph_create(&c->tgraph, &c->trim, err)) != GDT_OK)
        return st;
    memset(&os, 0, sizeof os);
    os.output = opts->output;
    gdt_run_mesh_meta(c->cloud, &c->log, &opts->trim, c->filter_comment, sizeof c->filter_comment,
                      c->trim_comment, sizeof c->trim_comment, c->filter_comments, &os.meta);
    if (opts->ground) {
        /* the ground filter and its parameters (--ground pmf) */
        gdt_pmf_describe(&opts->pmf, c->ground_comment, sizeof c->ground_comment);
        c->filter_comments[os.meta.ncomments++] = c->ground_comment;
    }
    os.trim = c->tgraph != NULL;
    os.concavity = c->trim.concavity > 0;
    if (opts->check && gdt_mesh_format_of(opts->output) != GDT_MESH_PLY) {
        c->check_ply = tr_path_join(c->job, CHECK_PLY_NAME);
        if (c->check_ply == NULL) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
            return st;
        }
        os.check_ply = c->check_ply;
    }
    os.tiler = c->tiler;
    os.tiles_dir = c->tiles_dir;
    os.job = c->job;
    os.base = c->base;
    os.ntiles = ntiles;
    os.stop = opts->stop;
    if (opts->dem != NULL) {
        st = tr_dem_create(&c->dem, opts, ci, c->plan, c->s.vertices, c->job, err);
        if (st != GDT_OK)
            return st;
    }
    os.dem = c->dem;
    os.parts = c->out_parts && os.check_ply == NULL;
    c->out_parts = os.parts;
    st = tr_out_start(&c->out, &os, err);
    if (st != GDT_OK)
        return st;
    return GDT_OK;
}

gdt_status tr_run_finish(tr_run *c, gdt_error *err)
{
    const gdt_options *opts = c->opts;
    uint64_t hull;
    double t0;
    char ftext[160], ttext[GDT_TRIM_TEXT_MAX];
    gdt_filter_counts fcounts;
    dem_bg bg;
    gdt_status st;

    /* the writer may copy trimmed faces from now on */
    if (c->tgraph != NULL)
        tr_out_set_trim(c->out, c->tgraph);

    /* Euler: a triangulation of V points with h on the hull has 2V - h - 2
     * faces (none when the points are collinear: then the seam holds them
     * all and has no triangle). */
    hull = c->s.merge.hull_vertices;
    if (c->s.merge.seam_triangles == 0 && c->s.certified == 0
            ? c->s.faces != 0
            : c->s.faces + hull + 2 != 2 * c->s.vertices) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7820,
                           "the tiled mesh has %" PRIu64 " faces for %" PRIu64
                           " vertices with %" PRIu64 " on the hull (Euler: %" PRIu64 ")",
                           c->s.faces, c->s.vertices, hull, 2 * c->s.vertices - hull - 2);
        return st;
    }

    t0 = gdt_now();
    gdt_progress_stage(&c->prog, "write", 1, "files");
    memset(&bg, 0, sizeof bg);
    bg.c = c;
    if (c->dem != NULL && c->out != NULL)
        tr_out_on_complete(c->out, dem_build_start, &bg);
    {
        char *mf = tr_path_join(c->job, MF_NAME);
        char *md = c->dem != NULL ? tr_path_join(c->job, MD_NAME) : NULL;
        st = mf == NULL || (c->dem != NULL && md == NULL)
                 ? gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory")
                 : tr_out_finish(c->out, mf, md, c->s.merge_faces, &c->s.trim, err);
        if (mf == NULL || (c->dem != NULL && md == NULL))
            tr_out_abort(c->out);
        c->out = NULL;
        free(md);
        free(mf);
    }
    if (c->dem != NULL)
        st = dem_finish(c, &bg, st, err);
    if (st == GDT_OK && opts->ground_out != NULL)
        st = tr_ground_out_write(c, err);
    if (st == GDT_OK)
        gdt_progress_update(&c->prog, 1);
    if (st == GDT_OK)
        st = gdt_job_set_stage(c->jobdb, "ply", 1, err);
    if (st != GDT_OK)
        return st;
    gdt_progress_end(&c->prog);
    c->s.t_write = gdt_now() - t0;
    if (opts->check) {
        t0 = gdt_now();
        st = check_output(c, err);
        if (st != GDT_OK)
            return st;
        c->s.checked = 1;
        c->s.t_check = gdt_now() - t0;
    }
    c->s.t_total = gdt_now() - c->t_start;
    if (opts->json != NULL) {
        st = write_summary(c, err);
        if (st != GDT_OK)
            return st;
    }
    fcounts = gdt_cloud_total_counts(c->cloud);
    gdt_filter_counts_text(&opts->filter, &fcounts, ftext, sizeof ftext);
    gdt_trim_report_text(&opts->trim, &c->s.trim, ttext, sizeof ttext);
    if (opts->verbosity >= 0)
        fprintf(stderr,
                "gdt-tile: %s: %" PRIu64 " points%s, %" PRIu64 " vertices, %" PRIu64
                " faces%s in %" PRIu64 " tiles (%.1f%% certified, %" PRIu64
                " seam vertices) on %s, %.2f s%s%s\n",
                opts->output, c->s.points_read, ftext, c->s.vertices,
                c->s.faces - c->s.trim.dropped, ttext, c->s.tiles,
                c->s.faces > 0 ? 100.0 * (double)c->s.certified / (double)c->s.faces : 100.0,
                c->s.merge.seam_vertices, c->s.device, c->s.t_total,
                c->s.resumed ? ", resumed" : "", c->s.checked ? ", checked exactly" : "");
    if (c->s.dem_done)
        gdt_dem_report_line(opts, &c->s.dem_geo, &c->s.dem_stats);
    gdt_log_note(
        &c->log,
        "times: pass 1 %.2f s, pass 2 %.2f s, tiles %.2f s (core %.2f, post %.2f, of which "
        "certify %.2f; device busy %.2f s, %.0f%% of the stage), "
        "merge %.2f s, write %.2f s; tiles reused %" PRIu64 ", computed %" PRIu64,
        c->s.t_pass1, c->s.t_pass2, c->s.t_tiles, c->s.t_core, c->s.t_post, c->s.t_certify,
        c->s.t_device,
        c->s.t_device_span > 0.0 ? 100.0 * c->s.t_device / c->s.t_device_span : 0.0,
        c->s.t_merge, c->s.t_write, c->s.tiles_reused, c->s.tiles_redone);
    if (!opts->keep_job) {
        gdt_tiler_destroy(c->tiler);
        c->tiler = NULL;
        gdt_job_close(c->jobdb);
        c->jobdb = NULL;
        /* several processes: the journal now, the tile files by each of
         * them (their unlinking waits for the file system's metadata more
         * than it works), the rest when they are done */
        if (c->removal_parts > 1) {
            tr_remove_job_journal(c->job);
            c->removal_due = 1;
        } else {
            tr_remove_job_files(c->job, 1, c->own_dir);
        }
    }
    return GDT_OK;
}

gdt_status tr_run_close(tr_run *c, gdt_status st)
{
    /* the first error stands */
    gdt_error e2;
    gdt_error_clear(&e2);
    tr_core_start_join(&c->cstart, &c->core, &e2);
    tr_post_join(c, &e2);
    tr_merge_abort(c);
    tr_out_abort(c->out); /* its thread feeds the DEM: first */
    tr_dem_abort(c->dem);
    tr_reclaim_join(c);
    if (st == GDT_OK)
        gdt_progress_end(&c->prog);
    else
        gdt_progress_abort(&c->prog);
    free(c->pending);
    free(c->s.ranks);
    gdt_seam_free(&c->seam);
    gdt_seam_free(&c->mseam);
    free(c->mbuf);
    gdt_trim_graph_destroy(c->tgraph);
    gdt_trim_tile_free(&c->ttile);
    free(c->topen);
    free(c->fbuf);
    free(c->count);
    free(c->cert);
    for (int i = 0; i < 2; i++) {
        gdt_mesh_free(&c->slot[i].mesh);
        free(c->slot[i].lh);
        free(c->slot[i].z);
    }
    gdt_point_buf_free(&c->halo);
    free(c->base);
    gdt_certifier_destroy(c->certifier);
    gdt_core_destroy(c->core);
    for (size_t j = 0; j < c->cstart.nmore; j++)
        gdt_core_destroy(c->cstart.more[j]);
    free(c->cstart.more);
    gdt_ocl_device_list_free(c->cstart.specs, c->cstart.nspecs);
    gdt_tiler_destroy(c->tiler);
    gdt_cloud_close(c->cloud);
    /* A run refused for its input or its options, of a job that holds no
     * finished work, leaves nothing behind: there is nothing to resume, and
     * the corrected command is another job.  Its files go, and the
     * directory too if a run of this job made it.  An interrupted run or
     * one stopped by the disk or the device keeps its job: the same command
     * resumes it.  A journal that cannot be asked counts as work. */
    if ((st == GDT_EINPUT || st == GDT_EUSAGE) && c->lock_fd >= 0) {
        int has = 1;
        gdt_error e3;
        gdt_error_clear(&e3);
        if (c->jobdb == NULL)
            has = gdt_job_exists(c->job);
        else if (gdt_job_has_work(c->jobdb, &has, &e3) != GDT_OK)
            has = 1;
        gdt_job_close(c->jobdb);
        c->jobdb = NULL;
        if (!has)
            tr_remove_job_files(c->job, 1, c->own_dir);
    }
    gdt_job_close(c->jobdb);
    gdt_job_unlock(c->job, c->lock_fd, 0);
    if (c->check_ply != NULL)
        unlink(c->check_ply); /* a second copy of the mesh is no state to keep */
    free(c->check_ply);
    free(c->tiles_dir);
    free(c->ground_bits);
    free(c->job);
    return st;
}
