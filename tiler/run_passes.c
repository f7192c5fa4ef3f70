/* run_passes.c — the start of a tiled run: the OpenCL core created on a
 * thread of its own, pass 1 and pass 2 of the tiler, and the journal
 * records of pass 2 (private/stages.h). */
#define _GNU_SOURCE /* sigaltstack */
#include "private/stages.h"
#include "private/tiler_io.h"

#include <inttypes.h>
#include <pthread.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "gdt_dem.h"
#include "gdt_ocl.h"
#include "private/cli_modes.h"
#include "private/comm.h"
#include "private/tiled_files.h"

/* The tiler's progress hook: shows progress and carries the stop request. */
static int tiler_progress(void *ctx, int stage, uint64_t done, uint64_t total)
{
    tr_run *c = ctx;
    static const char *const names[] = {"", "pass 1", "pass 2", "dup merge"};
    const char *name = stage >= 1 && stage <= 3 ? names[stage] : "tiler";
    if (!c->prog.open || strcmp(c->prog.stage, name) != 0)
        gdt_progress_stage(&c->prog, name, total, stage == 3 ? "tiles" : "points");
    gdt_progress_update(&c->prog, done);
    return tr_stopped(c);
}

/* Records pass 2 as done together with the size and checksum of every
 * .pts and .edge file it wrote (one transaction). */
static gdt_status record_pass2(tr_run *c, gdt_error *err)
{
    uint64_t ntiles = gdt_tiler_tile_count(c->tiler);
    gdt_status st = gdt_job_begin(c->jobdb, err);
    for (uint64_t k = 0; st == GDT_OK && k < ntiles; k++) {
        gdt_tiler_file_sum fs[2];
        st = gdt_tiler_file_sums(c->tiler, k, fs, err);
        if (st == GDT_OK)
            st = gdt_job_put_file(c->jobdb, k, GDT_JOB_FILE_PTS, fs[0].size, fs[0].sum, err);
        if (st == GDT_OK)
            st = gdt_job_put_file(c->jobdb, k, GDT_JOB_FILE_EDGE, fs[1].size, fs[1].sum, err);
    }
    if (st == GDT_OK && c->opts->ground) {
        /* the classes the ground filter gave, for the reports of a resumed run */
        char counts[64];
        snprintf(counts, sizeof counts, "%" PRIu64 " %" PRIu64, c->s.ground_points,
                 c->s.nonground_points);
        st = gdt_job_set_meta(c->jobdb, "ground_counts", counts, err);
        if (st == GDT_OK && c->opts->ground_out != NULL) {
            /* J/ground.bits, the classes of the input ordinals */
            snprintf(counts, sizeof counts, "%" PRIu64 " %" PRIu64, c->s.ground_bits_size,
                     c->s.ground_bits_sum);
            st = gdt_job_set_meta(c->jobdb, "ground_bits", counts, err);
        }
    }
    if (st == GDT_OK)
        st = gdt_job_set_stage(c->jobdb, "pass2", 1, err);
    if (st == GDT_OK)
        st = gdt_job_commit(c->jobdb, err);
    return st;
}

/* --ground-out on a recorded pass 2: J/ground.bits must match the record
 * the ground filter left (a job classified without --ground-out has none:
 * *ad receives GDT_EJOB 6501 and pass 2 is redone). */
static gdt_status adopt_ground_bits(tr_run *c, gdt_status *ad, gdt_error *e2, gdt_error *err)
{
    char *rec = NULL;
    uint64_t size = 0, sum = 0, want_size = 0, want_sum = 0;
    gdt_error e3;
    gdt_status st = gdt_job_get_meta(c->jobdb, "ground_bits", &rec, err);
    if (st != GDT_OK)
        return st;
    gdt_error_clear(&e3);
    if (rec == NULL || sscanf(rec, "%" SCNu64 " %" SCNu64, &want_size, &want_sum) != 2)
        *ad = gdt_error_set(e2, GDT_EJOB, 6501,
                            "the job records no ground classes of the input points "
                            "(--ground-out)");
    else if (tl_file_sum(c->ground_bits, gdt_job_file_seed(c->job_id, 0, GDT_JOB_FILE_BITS), &size,
                         &sum, &e3) != GDT_OK ||
             size != want_size || sum != want_sum)
        *ad = gdt_error_set(e2, GDT_EJOB, 6501, "%s: missing or damaged", c->ground_bits);
    else {
        c->s.ground_bits_size = size;
        c->s.ground_bits_sum = sum;
    }
    free(rec);
    return GDT_OK;
}

/* Pass 2 recorded as done: its files are adopted if every one matches its
 * record (*ok = 1); otherwise a warning names the first that does not and
 * why, and pass 2 is redone (*ok = 0). */
static gdt_status adopt_pass2(tr_run *c, int *ok, gdt_error *err)
{
    uint64_t ntiles = gdt_tiler_tile_count(c->tiler);
    gdt_tiler_file_sum *fs = malloc((2 * ntiles + 1) * sizeof *fs);
    gdt_error e2;
    gdt_status st = GDT_OK, ad = GDT_OK;

    *ok = 0;
    if (fs == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    gdt_error_clear(&e2);
    /* fs[2k] .pts and fs[2k + 1] .edge of tile k */
    for (uint64_t i = 0; st == GDT_OK && ad == GDT_OK && i < 2 * ntiles; i++) {
        int found = 0;
        st = gdt_job_get_file(c->jobdb, i / 2, i % 2 ? GDT_JOB_FILE_EDGE : GDT_JOB_FILE_PTS, &found,
                              &fs[i].size, &fs[i].sum, err);
        if (st == GDT_OK && !found)
            ad = gdt_error_set(&e2, GDT_EJOB, 6501, "the job records no %s file of tile %" PRIu64,
                               i % 2 ? ".edge" : ".pts", i / 2);
    }
    /* the ground filter's records first: the tiler's adoption is final */
    if (st == GDT_OK && ad == GDT_OK && c->opts->ground) {
        char *counts = NULL;
        st = gdt_job_get_meta(c->jobdb, "ground_counts", &counts, err);
        if (st == GDT_OK &&
            (counts == NULL || sscanf(counts, "%" SCNu64 " %" SCNu64, &c->s.ground_points,
                                      &c->s.nonground_points) != 2))
            ad = gdt_error_set(&e2, GDT_EJOB, 6501, "the job records no ground counts");
        free(counts);
        if (st == GDT_OK && ad == GDT_OK && c->opts->ground_out != NULL)
            st = adopt_ground_bits(c, &ad, &e2, err);
    }
    if (st == GDT_OK && ad == GDT_OK)
        ad = gdt_tiler_adopt_pass2(c->tiler, fs, &e2);
    free(fs);
    if (st != GDT_OK)
        return st;
    if (ad == GDT_OK) {
        *ok = 1;
    } else if (ad == GDT_EJOB) {
        gdt_log_warn(&c->log, 6502, "redoing pass 2: %s", e2.msg);
    } else {
        *err = e2; /* out of memory: not a reason to redo */
        st = ad;
    }
    return st;
}

/* The command queues a device gets, given its first core: --queues, or,
 * on a device that is not a CPU, two when its memory holds the buffers of
 * two tiles (the bound gdt_core_auto_tile uses), so that one tile's
 * transfers and host work overlap another's kernels; a CPU device's
 * kernels already use every core. */
static int device_queues(const tr_core_start *cs, const gdt_core *core)
{
    uint64_t mem, need;
    if (cs->queues > 0)
        return cs->queues;
    if (gdt_core_on_cpu(core) || cs->tile <= 0)
        return 1;
    mem = gdt_core_device_memory(core);
    need = gdt_core_tile_bytes(cs->tile, (uint64_t)cs->tile * (uint64_t)cs->tile / 2);
    return mem != 0 && need <= mem / 8 * 3 ? 2 : 1;
}

/* A core on spec, a further queue of its device when one of the n cores in
 * all runs on it; added to more. */
static void add_core(tr_core_start *cs, const char *spec, gdt_core *const *all, size_t n)
{
    gdt_core_opts o = cs->opts;
    o.device = spec;
    o.share = all;
    o.nshare = n;
    if (cs->nmore == cs->cap_more) {
        cs->st = gdt_error_set(&cs->err, GDT_EINTERNAL, 7001, "too many cores");
        return;
    }
    cs->st = gdt_core_create(&cs->more[cs->nmore], &o, &cs->err);
    if (cs->st == GDT_OK)
        cs->nmore++;
}

static void *core_start_main(void *arg)
{
    tr_core_start *cs = arg;
    stack_t ss;
    int have = sigaltstack(NULL, &ss) == 0;
    gdt_core **all = NULL; /* core, then more: the cores made so far */
    const char **spec_of = NULL;
    size_t nall = 0, nfirst;

    cs->st = gdt_core_create(&cs->core, &cs->opts, &cs->err);
    if (cs->st == GDT_OK) {
        all = calloc(cs->cap_more + 1, sizeof *all);
        spec_of = calloc(cs->cap_more + 1, sizeof *spec_of);
        if (all == NULL || spec_of == NULL)
            cs->st = gdt_error_set(&cs->err, GDT_EINTERNAL, 7001, "out of memory");
        else {
            all[nall] = cs->core;
            spec_of[nall++] = cs->opts.device;
        }
    }
    /* several devices: a core on each of the others (a device named again
     * gets a further queue) */
    for (size_t j = 1; cs->st == GDT_OK && j < cs->nspecs; j++) {
        add_core(cs, cs->specs[j], all, nall);
        if (cs->st == GDT_OK) {
            all[nall] = cs->more[cs->nmore - 1];
            spec_of[nall++] = cs->specs[j];
        }
    }
    /* then every device's further queues, up to what it gets */
    nfirst = nall;
    for (size_t i = 0; cs->st == GDT_OK && i < nfirst; i++) {
        int want, got = 0;
        if (gdt_core_shares_device(all[i]))
            continue;
        want = device_queues(cs, all[i]);
        for (size_t k = 0; k < nall; k++)
            got += gdt_core_same_device(all[k], all[i]);
        for (; cs->st == GDT_OK && got < want; got++) {
            add_core(cs, spec_of[i], &all[i], 1);
            if (cs->st == GDT_OK)
                all[nall++] = cs->more[cs->nmore - 1];
        }
        if (cs->st == GDT_OK && got > 1)
            gdt_log_note(cs->opts.log, "%s: %d command queues in the tile stage",
                         gdt_core_device_name(all[i]), got);
    }
    free(all);
    free(spec_of);
    /* The compiler inside the OpenCL runtime gives the thread an alternate
     * signal stack of its own; put back the one the thread had, which
     * whoever set it up (a sanitizer's runtime) releases at thread exit. */
    if (have)
        sigaltstack(&ss, NULL);
    /* GDAL's hundred libraries load here too, beside pass 1, not on the
     * way of the tile stage */
    if (cs->preload_dem && !(cs->opts.stop != NULL && *cs->opts.stop != 0))
        gdt_dem_preload();
    return NULL;
}

static void core_start_begin(tr_core_start *cs)
{
    gdt_error_clear(&cs->err);
    /* setenv here, before pass 1 runs beside the thread (getenv in other
     * threads while setenv runs can crash) */
    gdt_ocl_prepare_env(cs->opts.cache_dir, cs->opts.log);
    cs->running = pthread_create(&cs->thread, NULL, core_start_main, cs) == 0;
    if (!cs->running)
        core_start_main(cs);
}

gdt_status tr_core_start_join(tr_core_start *cs, gdt_core **core, gdt_error *err)
{
    if (cs->running) {
        pthread_join(cs->thread, NULL);
        cs->running = 0;
    }
    if (cs->core != NULL) {
        *core = cs->core;
        cs->core = NULL;
    }
    if (cs->st != GDT_OK && err != NULL)
        *err = cs->err;
    return cs->st;
}

/* Without --tile: the tile side for the device the core will use
 * (gdt_core_auto_tile), from a look at the device that builds nothing.
 * When the device cannot be looked at, the CPU's side: the core's own
 * start-up then reports why. */
static void choose_tile(tr_run *c)
{
    const tr_core_start *cs = &c->cstart;
    uint64_t host = c->opts->mem_budget;
    long pages = sysconf(_SC_PHYS_PAGES), psize = sysconf(_SC_PAGESIZE);
    size_t ndev = cs->nspecs > 0 ? cs->nspecs : 1;

    if (host == 0 && pages > 0 && psize > 0)
        host = (uint64_t)pages * (uint64_t)psize;
    c->tile_auto = 1;
    c->tile = 16384;
    /* several devices: the side every one of them holds (the host keeps a
     * tile stage's slots for each) */
    for (size_t j = 0; j < ndev; j++) {
        gdt_ocl_opts oo;
        gdt_ocl_device_info info;
        gdt_error e;
        uint64_t q;
        int t;
        memset(&oo, 0, sizeof oo);
        oo.device = cs->nspecs > 0 ? cs->specs[j] : cs->opts.device;
        oo.local_rank = cs->opts.local_rank;
        oo.log = &c->log;
        gdt_error_clear(&e);
        if (gdt_ocl_probe(&oo, &info, &e) != GDT_OK) {
            c->tile = GDT_CORE_CPU_TILE;
            return;
        }
        /* every queue of the device holds a tile (auto: two on a GPU) */
        q = c->opts->queues > 0 ? (uint64_t)c->opts->queues : info.is_cpu ? 1 : 2;
        t = gdt_core_auto_tile(info.is_cpu, info.global_mem / q, info.max_alloc,
                               host / ndev / q);
        if (t < c->tile)
            c->tile = t;
        gdt_log_note(&c->log, "--tile %d for %s (%s, %.1f GiB of device memory)", t, info.name,
                     info.is_cpu ? "a CPU device" : "not a CPU device",
                     (double)info.global_mem / (double)((uint64_t)1 << 30));
    }
}

gdt_status tr_run_start_core(tr_run *c, gdt_error *err)
{
    /* the device while pass 1 runs */
    c->cstart.opts.device = c->opts->device;
    c->cstart.opts.local_rank = gdt_comm_local_rank(c->opts->comm);
    c->cstart.opts.log = &c->log;
    c->cstart.opts.stop = c->opts->stop;
    /* the environment first: a look at the devices starts OpenCL */
    gdt_ocl_prepare_env(c->cstart.opts.cache_dir, c->cstart.opts.log);
    if (gdt_ocl_spec_is_list(c->opts->device)) {
        gdt_status st =
            gdt_ocl_device_list(c->opts->device, &c->cstart.specs, &c->cstart.nspecs, err);
        if (st != GDT_OK)
            return st;
        c->cstart.opts.device = c->cstart.specs[0];
        gdt_log_note(&c->log, "--device %s: %zu cores in the tile stage", c->opts->device,
                     c->cstart.nspecs);
    }
    /* room for the other devices' cores and every device's further queues */
    c->cstart.cap_more =
        (c->cstart.nspecs > 0 ? c->cstart.nspecs : 1) * (size_t)GDT_CLI_MAX_QUEUES - 1;
    c->cstart.more = calloc(c->cstart.cap_more, sizeof *c->cstart.more);
    if (c->cstart.more == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    c->cstart.queues = c->opts->queues;
    if (!c->opts->tile_set)
        choose_tile(c);
    c->cstart.tile = c->tile;
    core_start_begin(&c->cstart);
    return gdt_certifier_create(&c->certifier, gdt_cli_threads(c->opts->threads), err);
}

/* The cloud's options of this run; replay: LAZ decoded once, in pass 1,
 * and replayed from the job directory in pass 2. */
static void cloud_opts(tr_run *c, gdt_cloud_opts *co, int replay)
{
    const gdt_options *opts = c->opts;
    memset(co, 0, sizeof *co);
    co->log = &c->log;
    co->quantum = opts->quantum;
    co->threads = gdt_cli_threads(opts->threads);
    co->replay_dir = replay ? c->job : NULL;
    co->filter = &opts->filter;
}

/* The tiler's options of this run (c->job_id seeds the tile files' sums). */
/* The tiler's options; cloud: the cloud it reads (its lattice fixes the
 * ground filter's reach). */
static void tiler_opts(tr_run *c, const gdt_cloud *cloud, gdt_tiler_opts *to)
{
    const gdt_options *opts = c->opts;
    memset(to, 0, sizeof *to);
    to->tile = c->tile;
    to->cell = opts->cell;
    to->halo = opts->halo;
    to->mem_budget = opts->mem_budget;
    to->dup = opts->dup;
    to->threads = gdt_cli_threads(opts->threads);
    to->job_dir = c->job;
    to->file_id[0] = c->job_id[0];
    to->file_id[1] = c->job_id[1];
    to->log = &c->log;
    to->progress = tiler_progress;
    to->progress_ctx = c;
    if (opts->ground) {
        /* the ground filter reads every point within its reach of a tile:
         * the .edge files are made that wide (the reach does not depend on
         * z0; the options were checked when parsed) */
        gdt_pmf f;
        gdt_error e;
        gdt_error_clear(&e);
        if (gdt_pmf_init(&f, &opts->pmf, &gdt_cloud_get_info(cloud)->lattice, 0.0, &e) == GDT_OK)
            to->edge_min = f.reach;
        to->subsets = 1;
        /* --ground-out: the pass-2 records (duplicates too) stay for the
         * classes of every input point */
        to->keep_spill = opts->ground_out != NULL;
    }
    to->last_read = tr_pass2_last_read(opts);
}

/* Pass 1 through c->p1share: this process's share, then the others'. */
static gdt_status pass1_shared(tr_run *c, gdt_error *err)
{
    const tr_pass1_share *ps = c->p1share;
    uint64_t first = 0, end = 0;
    int shared = 0;
    gdt_status st = ps->begin(ps->ctx, &shared, &first, &end, err);
    if (st != GDT_OK)
        return st;
    if (!shared) {
        /* rank 0 reads the whole cloud: all of pass 1 is its own */
        double t0 = gdt_now();
        st = gdt_tiler_pass1(c->tiler, err);
        c->s.t_pass1_own = gdt_now() - t0;
        return st;
    }
    {
        double t0 = gdt_now();
        st = gdt_cloud_set_range(c->cloud, first, end, 0, err);
        if (st == GDT_OK)
            st = gdt_tiler_pass1_part(c->tiler, err);
        c->s.t_pass1_own = gdt_now() - t0;
    }
    st = ps->collect(ps->ctx, st, err);
    if (st == GDT_OK)
        st = gdt_tiler_pass1_end(c->tiler, err);
    if (st == GDT_OK) {
        /* the progress line counts every share's points */
        gdt_progress_update(&c->prog, gdt_tiler_get_plan(c->tiler)->points);
        gdt_cloud_report_counts(c->cloud);
        /* pass 2 reads the whole cloud */
        st = gdt_cloud_set_range(c->cloud, 0, UINT64_MAX, 0, err);
    }
    return st;
}

gdt_status tr_run_pass1_share(tr_run *c, uint64_t first, uint64_t end, unsigned char **buf,
                              size_t *len, uint64_t *kept, gdt_error *err)
{
    gdt_cloud_opts co;
    gdt_tiler_opts to;
    gdt_cloud *cloud;
    gdt_tiler *t = NULL;
    gdt_status st = GDT_OK;

    *buf = NULL;
    *len = 0;
    /* the run's cloud, kept for pass 2: the LAZ chunks of this share are
     * decoded once, into a replay in the job directory, and pass 2 reads
     * the same share from it */
    cloud_opts(c, &co, 1);
    if (c->cloud == NULL)
        st = gdt_cloud_open(&c->cloud, c->opts->inputs, c->opts->ninputs, &co, err);
    cloud = c->cloud;
    if (st == GDT_OK) {
        tiler_opts(c, cloud, &to);
        to.job_dir = NULL; /* the planning rank saves the index */
        to.progress = NULL;
        st = gdt_tiler_create(&t, &to, cloud, err);
    }
    if (st == GDT_OK)
        st = gdt_cloud_set_range(cloud, first, end, 0, err);
    if (st == GDT_OK)
        st = gdt_tiler_pass1_part(t, err);
    if (st == GDT_OK)
        st = gdt_tiler_pass1_part_export(t, buf, len, err);
    *kept = st == GDT_OK ? gdt_cloud_total_counts(cloud).kept : 0;
    gdt_tiler_destroy(t);
    return st;
}

gdt_status tr_run_pass1(tr_run *c, gdt_error *err)
{
    const gdt_options *opts = c->opts;
    gdt_cloud_opts co;
    gdt_tiler_opts to;
    gdt_status st;

    cloud_opts(c, &co, 1);
    st = gdt_cloud_open(&c->cloud, opts->inputs, opts->ninputs, &co, err);
    if (st != GDT_OK)
        return st;
    tiler_opts(c, c->cloud, &to);
    st = gdt_tiler_create(&c->tiler, &to, c->cloud, err);
    if (st == GDT_OK && c->p1share != NULL)
        st = pass1_shared(c, err);
    else if (st == GDT_OK)
        st = gdt_tiler_pass1(c->tiler, err);
    if (st == GDT_EINTERRUPTED)
        st = tr_interrupted(c->job, "pass 1", err);
    if (st != GDT_OK)
        return st;
    st = tr_core_start_join(&c->cstart, &c->core, err);
    if (tr_stopped(c)) {
        /* a signal during the kernel build, reported now rather than at the
         * next check; when the build failed, the signal was the cause: the
         * kernel compiler removes its files on SIGINT/SIGTERM */
        gdt_error_clear(err);
        st = tr_interrupted(c->job, "the OpenCL start-up", err);
    }
    if (st != GDT_OK)
        return st;
    snprintf(c->s.device, sizeof c->s.device, "%s", gdt_core_device_name(c->core));
    c->plan = gdt_tiler_get_plan(c->tiler);
    c->s.t_pass1 = gdt_tiler_get_stats(c->tiler)->t_pass1;
    /* the seam merge's frame is the lattice minus the plan's minimum: a
     * wider cloud is refused before the tile stage, not at its end */
    if (c->plan->points > 0 && (st = gdt_cloud_check_span(c->cloud, c->plan->max_x - c->plan->min_x,
                                                          c->plan->max_y - c->plan->min_y,
                                                          "the tiled run", err)) != GDT_OK)
        return st;
    /* a --dem-res the lattice refuses (or a raster too large) is refused
     * now, before pass 2; the grid itself is defined with the distinct
     * point count after it */
    if (opts->dem != NULL) {
        gdt_raster_grid g;
        const gdt_cloud_info *ci = gdt_cloud_get_info(c->cloud);
        st = gdt_raster_grid_define(&g, &ci->lattice, c->plan->points > 0 ? c->plan->min_x : 0,
                                    c->plan->points > 0 ? c->plan->min_y : 0,
                                    c->plan->points > 0 ? c->plan->max_x : 0,
                                    c->plan->points > 0 ? c->plan->max_y : 0, c->plan->points,
                                    opts->dem_res, "--dem-res", err);
        if (st != GDT_OK)
            return st;
    }
    return GDT_OK;
}

/* c->base (each tile's first output vertex), c->s.tiles, c->s.vertices.
 * returns: GDT_OK; GDT_EINPUT 3801 (more than 2^31 - 1 vertices); 7001. */
static gdt_status set_bases(tr_run *c, gdt_error *err)
{
    const gdt_options *opts = c->opts;
    uint64_t ntiles;
    gdt_status st;

    ntiles = gdt_tiler_tile_count(c->tiler);
    c->s.tiles = ntiles;
    c->base = malloc((ntiles + 1) * sizeof *c->base);
    if (c->base == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        return st;
    }
    c->base[0] = 0;
    for (uint64_t k = 0; k < ntiles; k++) {
        gdt_tile_desc d;
        st = gdt_tiler_tile_info(c->tiler, k, &d, err);
        if (st != GDT_OK)
            return st;
        c->base[k + 1] = c->base[k] + d.points;
    }
    c->s.vertices = c->base[ntiles];
    if (c->s.vertices > (uint64_t)INT32_MAX) {
        st = gdt_error_set(err, GDT_EINPUT, 3801,
                           "%s: %" PRIu64 " distinct points; a face index of the output "
                           "holds at most 2^31 - 1",
                           opts->inputs[0], c->s.vertices);
        return st;
    }
    return GDT_OK;
}

gdt_status tr_run_pass2(tr_run *c, gdt_error *err)
{
    int done = 0;
    double t0;
    gdt_status st;

    t0 = gdt_now();
    st = gdt_job_stage_done(c->jobdb, "pass2", &done, err);
    if (st != GDT_OK)
        return st;
    if (done) {
        st = adopt_pass2(c, &done, err);
        if (st != GDT_OK)
            return st;
        c->s.pass2_reused = done;
    }
    if (!done) {
        st = gdt_job_set_stage(c->jobdb, "pass2", 0, err);
        if (st == GDT_OK)
            st = gdt_job_clear_tiles(c->jobdb, err);
        int whole = 0;
        if (st == GDT_OK && c->p2share != NULL && c->p2share->spill != NULL)
            st = c->p2share->spill(c->p2share->ctx, &whole, err);
        if (st == GDT_OK && whole) {
            /* pass 2 ran in shares */
        } else if (st == GDT_OK && c->p2share != NULL) {
            const tr_pass2_share *ps = c->p2share;
            double t_own = gdt_now();
            st = ps->begin(ps->ctx, err);
            if (st == GDT_OK)
                st = gdt_tiler_pass2_shared(c->tiler, &ps->sh, err);
            c->s.t_pass2_own = gdt_now() - t_own;
            if (st == GDT_OK)
                st = ps->collect(ps->ctx, err);
            if (st == GDT_OK)
                st = gdt_tiler_pass2_finish(c->tiler, err);
        } else if (st == GDT_OK) {
            st = gdt_tiler_pass2(c->tiler, err);
        }
        if (st == GDT_OK && c->opts->ground)
            st = tr_run_ground(c, err);
        if (st == GDT_EINTERRUPTED)
            st = tr_interrupted(c->job, "pass 2", err);
        if (st == GDT_OK)
            st = record_pass2(c, err);
        if (st != GDT_OK)
            return st;
    }
    c->s.t_pass2 = gdt_now() - t0;
    c->s.points_read = c->plan->points;

    return set_bases(c, err);
}

/* A new tiler from rank 0's state (the cloud opened first, headers only). */
static gdt_status replace_tiler(tr_run *c, const unsigned char *state, size_t len, gdt_error *err)
{
    const gdt_options *opts = c->opts;
    gdt_cloud_opts co;
    gdt_tiler_opts to;
    gdt_status st;

    if (c->cloud == NULL) {
        cloud_opts(c, &co, 0);
        st = gdt_cloud_open(&c->cloud, opts->inputs, opts->ninputs, &co, err);
        if (st != GDT_OK)
            return st;
    }
    gdt_tiler_destroy(c->tiler);
    c->tiler = NULL;
    c->plan = NULL;
    tiler_opts(c, c->cloud, &to);
    st = gdt_tiler_create(&c->tiler, &to, c->cloud, err);
    if (st == GDT_OK)
        st = gdt_tiler_import(c->tiler, state, len, err);
    return st;
}

gdt_status tr_run_attach_ground(tr_run *c, const unsigned char *state, size_t len, gdt_error *err)
{
    gdt_status st = replace_tiler(c, state, len, err);
    if (st != GDT_OK)
        return st;
    c->plan = gdt_tiler_get_plan(c->tiler);
    if (c->plan == NULL || !gdt_tiler_pass2_done(c->tiler) || c->base != NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7954,
                             "a rank was given the ground filter out of turn");
    return GDT_OK;
}

gdt_status tr_run_attach(tr_run *c, const uint64_t job_id[2], const unsigned char *state,
                         size_t len, gdt_error *err)
{
    const gdt_options *opts = c->opts;
    gdt_status st;

    c->job_id[0] = job_id[0];
    c->job_id[1] = job_id[1];
    st = replace_tiler(c, state, len, err);
    if (st != GDT_OK)
        return st;
    if (gdt_tiler_get_plan(c->tiler) == NULL || c->base != NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7954, "a rank attached twice after pass 2");
    c->plan = gdt_tiler_get_plan(c->tiler);
    /* rank 0 planned with its tile side: a rank whose own device chose
     * another would run the core on a grid of the wrong size */
    if (c->plan->tile != c->tile)
        return gdt_error_set(err, GDT_EUSAGE, 2953,
                             "rank %d chose --tile %d for its OpenCL device, rank 0 chose %d for "
                             "its own: give --tile to every rank",
                             gdt_comm_rank(c->opts->comm), c->tile, c->plan->tile);
    c->s.points_read = c->plan->points;
    if (!gdt_tiler_pass2_done(c->tiler))
        return GDT_OK; /* the state after pass 1: for the shared pass 2 */
    /* the tile stage needs the core (built meanwhile) */
    if (c->core == NULL)
        st = tr_core_start_join(&c->cstart, &c->core, err);
    if (st != GDT_OK)
        return st;
    snprintf(c->s.device, sizeof c->s.device, "%s", gdt_core_device_name(c->core));
    st = set_bases(c, err);
    if (st != GDT_OK)
        return st;
    c->trim = opts->trim;
    c->trim.sx = c->plan->lattice.sx;
    c->trim.sy = c->plan->lattice.sy;
    return GDT_OK;
}
