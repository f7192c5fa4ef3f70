/* tiled_dem.c — --dem in the tiled run (see private/tiled_dem.h).
 *
 * A tile's faces are rasterised by the caller and up to TD_HELPERS helper
 * threads (--threads - 1 of them), each taking one contiguous part of the
 * faces, once the tile stage is over (while it runs, the caller works alone:
 * measured on 2 cores, helpers then only took turns with the OpenCL core
 * and the run was 0.2 s slower).  Each rasteriser collects its cell runs in its own buffer and
 * hands them to the writer in batches, so the writer's lock is taken once
 * per batch, not once per run.  The DEM does not depend on the split: every
 * cell centre is owned by one face, and the writer refuses a second value.
 *
 * Invariants: mu guards w (the writer) and nothing else; job_mu serialises
 * the callers of tr_dem_tile_faces; jmu/jcv guard the job fields (gen,
 * pending, stop) the helpers wait on. */
#include "private/tiled_dem.h"
#include "private/cli_modes.h"
#include "private/tiled_files.h"
#include "private/tiler_io.h"

#include <inttypes.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_grow.h"
#include "gdt_raster.h"

#define TD_HELPERS 15       /* most helper threads */
#define TD_MIN_PART 4096    /* fewer faces per part are not worth a thread */
#define TD_BATCH_RUNS 2048  /* runs per batch */
#define TD_BATCH_CELLS 8192 /* cells per batch (a run has at most 256) */

struct tr_dem;

/* One rasteriser's batch of cell runs for the writer. */
typedef struct td_batch {
    struct tr_dem *d;
    size_t nruns, ncells;
    int64_t row[TD_BATCH_RUNS], col[TD_BATCH_RUNS], len[TD_BATCH_RUNS];
    float z[TD_BATCH_CELLS];
} td_batch;

/* One part of a job: faces [lo, hi) of the current job. */
typedef struct td_part {
    struct tr_dem *d;
    int index; /* 1 .. helpers (the caller is part 0) */
    pthread_t thread;
    int started;
    gdt_status st;
    gdt_error err;
    td_batch batch;
} td_part;

struct tr_dem {
    gdt_raster_grid grid;
    gdt_dem *w;
    pthread_mutex_t mu;
    /* the job the helpers work on */
    pthread_mutex_t job_mu, jmu;
    pthread_cond_t jcv, done_cv;
    uint64_t gen;  /* job number: a helper works once per new value */
    int pending;   /* helpers still working on job gen */
    int stop;
    int helpers;   /* started helper threads */
    const gdt_raster_vertex *pts;
    size_t npts, m;
    uint64_t base;
    const int32_t *tri;
    td_part *parts; /* [0 .. helpers], part 0 the caller's */
};

static gdt_status batch_flush(td_batch *b, gdt_error *err)
{
    gdt_status st = GDT_OK;
    size_t off = 0;

    if (b->nruns == 0)
        return GDT_OK;
    pthread_mutex_lock(&b->d->mu);
    for (size_t i = 0; i < b->nruns && st == GDT_OK; i++) {
        st = gdt_dem_put(b->d->w, b->row[i], b->col[i], b->len[i], b->z + off, err);
        off += (size_t)b->len[i];
    }
    pthread_mutex_unlock(&b->d->mu);
    b->nruns = 0;
    b->ncells = 0;
    return st;
}

/* The raster sink: appends a run to the batch (ctx), flushing it first
 * when the run would not fit. */
static gdt_status batch_put(void *ctx, int64_t row, int64_t col, int64_t n, const float *z,
                            gdt_error *err)
{
    td_batch *b = ctx;
    if (b->nruns == TD_BATCH_RUNS || b->ncells + (size_t)n > TD_BATCH_CELLS) {
        gdt_status st = batch_flush(b, err);
        if (st != GDT_OK)
            return st;
    }
    if ((size_t)n > TD_BATCH_CELLS) { /* not from gdt_raster_triangle (runs of <= 256) */
        gdt_status st;
        pthread_mutex_lock(&b->d->mu);
        st = gdt_dem_put(b->d->w, row, col, n, z, err);
        pthread_mutex_unlock(&b->d->mu);
        return st;
    }
    b->row[b->nruns] = row;
    b->col[b->nruns] = col;
    b->len[b->nruns] = n;
    memcpy(b->z + b->ncells, z, (size_t)n * sizeof *z);
    b->nruns++;
    b->ncells += (size_t)n;
    return GDT_OK;
}

/* Rasterises faces [lo, hi) of tri through batch b. */
static gdt_status raster_range(tr_dem *d, td_batch *b, const gdt_raster_vertex *pts, size_t n,
                               uint64_t base, const int32_t *tri, size_t lo, size_t hi,
                               gdt_error *err)
{
    gdt_status st = GDT_OK;
    for (size_t f = lo; f < hi && st == GDT_OK; f++) {
        gdt_raster_vertex v[3];
        for (int i = 0; i < 3; i++) {
            int64_t k = (int64_t)tri[3 * f + (size_t)i] - (int64_t)base;
            if (k < 0 || (uint64_t)k >= n) {
                st = gdt_error_set(err, GDT_EINTERNAL, 7663,
                                   "DEM: a certified face names vertex %d, outside its "
                                   "tile's %" PRIu64 "..%" PRIu64,
                                   (int)tri[3 * f + (size_t)i], base, base + n - 1);
                break;
            }
            v[i] = pts[k];
        }
        if (st == GDT_OK)
            st = gdt_raster_triangle(&d->grid, NULL, v, batch_put, b, err);
    }
    if (st == GDT_OK)
        st = batch_flush(b, err);
    else
        b->nruns = b->ncells = 0;
    return st;
}

/* Part p of the current job (of parts parts). */
static void run_part(tr_dem *d, td_part *p, int parts)
{
    size_t lo = d->m * (size_t)p->index / (size_t)parts;
    size_t hi = d->m * (size_t)(p->index + 1) / (size_t)parts;
    p->st = raster_range(d, &p->batch, d->pts, d->npts, d->base, d->tri, lo, hi, &p->err);
}

static void *helper_main(void *arg)
{
    td_part *p = arg;
    tr_dem *d = p->d;
    uint64_t seen = 0;

    pthread_mutex_lock(&d->jmu);
    for (;;) {
        while (!d->stop && d->gen == seen)
            pthread_cond_wait(&d->jcv, &d->jmu);
        if (d->stop)
            break;
        seen = d->gen;
        pthread_mutex_unlock(&d->jmu);
        run_part(d, p, d->helpers + 1);
        pthread_mutex_lock(&d->jmu);
        if (--d->pending == 0)
            pthread_cond_signal(&d->done_cv);
    }
    pthread_mutex_unlock(&d->jmu);
    return NULL;
}

/* Starts up to want helpers; fewer (even none) when threads cannot be
 * created: the caller's part then covers more.  returns: GDT_EINTERNAL 7001
 * when not even the caller's batch can be allocated. */
static gdt_status start_helpers(tr_dem *d, int want, gdt_error *err)
{
    if (want > TD_HELPERS)
        want = TD_HELPERS;
    if (want < 0)
        want = 0;
    d->parts = calloc((size_t)want + 1, sizeof *d->parts);
    if (d->parts == NULL && want > 0) {
        want = 0;
        d->parts = calloc(1, sizeof *d->parts);
    }
    if (d->parts == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory (the DEM's batches)");
    for (int i = 0; i <= want; i++) {
        d->parts[i].d = d;
        d->parts[i].index = i;
        d->parts[i].batch.d = d;
    }
    for (int i = 1; i <= want; i++) {
        if (pthread_create(&d->parts[i].thread, NULL, helper_main, &d->parts[i]) != 0)
            break;
        d->parts[i].started = 1;
        d->helpers = i;
    }
    return GDT_OK;
}

static void stop_helpers(tr_dem *d)
{
    pthread_mutex_lock(&d->jmu);
    d->stop = 1;
    pthread_cond_broadcast(&d->jcv);
    pthread_mutex_unlock(&d->jmu);
    for (int i = 1; d->parts != NULL && i <= d->helpers; i++)
        if (d->parts[i].started)
            pthread_join(d->parts[i].thread, NULL);
    d->helpers = 0;
    free(d->parts);
    d->parts = NULL;
}

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
    pthread_mutex_init(&d->job_mu, NULL);
    pthread_mutex_init(&d->jmu, NULL);
    pthread_cond_init(&d->jcv, NULL);
    pthread_cond_init(&d->done_cv, NULL);
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
    if (st == GDT_OK)
        st = start_helpers(d, gdt_cli_threads(opts->threads) - 1, err);
    if (st != GDT_OK) {
        tr_dem_abort(d);
        return st;
    }
    *out = d;
    return GDT_OK;
}

gdt_status tr_dem_tile_faces(tr_dem *d, const gdt_raster_vertex *pts, size_t n, uint64_t base,
                             const int32_t *tri, size_t m, int alone, gdt_error *err)
{
    gdt_status st;
    int parts;

    pthread_mutex_lock(&d->job_mu);
    if (alone || d->helpers == 0 || m < 2 * (size_t)TD_MIN_PART) {
        st = raster_range(d, &d->parts[0].batch, pts, n, base, tri, 0, m, err);
        pthread_mutex_unlock(&d->job_mu);
        return st;
    }
    parts = d->helpers + 1;
    pthread_mutex_lock(&d->jmu);
    d->pts = pts;
    d->npts = n;
    d->base = base;
    d->tri = tri;
    d->m = m;
    d->pending = d->helpers;
    d->gen++;
    pthread_cond_broadcast(&d->jcv);
    pthread_mutex_unlock(&d->jmu);
    run_part(d, &d->parts[0], parts);
    pthread_mutex_lock(&d->jmu);
    while (d->pending > 0)
        pthread_cond_wait(&d->done_cv, &d->jmu);
    pthread_mutex_unlock(&d->jmu);
    /* the first failing part in face order names the error */
    st = GDT_OK;
    for (int i = 0; i < parts; i++)
        if (d->parts[i].st != GDT_OK) {
            st = d->parts[i].st;
            *err = d->parts[i].err;
            break;
        }
    pthread_mutex_unlock(&d->job_mu);
    return st;
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

gdt_status tr_dem_build(tr_dem *d, gdt_dem_geo *geo, gdt_dem_stats *stats, gdt_error *err)
{
    stop_helpers(d); /* the rasterising is over */
    if (geo != NULL)
        *geo = d->grid.geo;
    return gdt_dem_build(d->w, stats, err);
}

gdt_status tr_dem_commit(tr_dem *d, gdt_error *err)
{
    gdt_status st = gdt_dem_commit(d->w, err);
    d->w = NULL;
    tr_dem_abort(d);
    return st;
}

void tr_dem_abort(tr_dem *d)
{
    if (d == NULL)
        return;
    stop_helpers(d);
    gdt_dem_abort(d->w);
    pthread_mutex_destroy(&d->mu);
    pthread_mutex_destroy(&d->job_mu);
    pthread_mutex_destroy(&d->jmu);
    pthread_cond_destroy(&d->jcv);
    pthread_cond_destroy(&d->done_cv);
    free(d);
}
