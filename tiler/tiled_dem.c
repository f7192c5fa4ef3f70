/* tiled_dem.c — --dem in the tiled run (see private/tiled_dem.h).
 *
 * While the tile stage runs, a tile's faces are rasterised on the caller's
 * thread alone (measured on 2 cores: helpers then only took turns with the
 * OpenCL core and the run was 0.2 s slower).  Once it is over, the faces
 * become a job of parts of TD_PART faces that up to TD_HELPERS helper
 * threads (--threads - 1 of them) take one by one while the caller reads
 * and copies the next faces; the caller takes the parts still left when it
 * comes back with the next job (tr_dem_tile_faces) or waits
 * (tr_dem_tile_wait).  Each rasteriser collects its cell runs in its own
 * buffer and hands them to the writer in batches, so the writer's lock is
 * taken once per batch, not once per run.  The DEM does not depend on the
 * split: every cell centre is owned by one face, and the writer refuses a
 * second value.
 *
 * Invariants: mu guards w (the writer) and nothing else; job_mu serialises
 * the callers of tr_dem_tile_faces and tr_dem_tile_wait; jmu/jcv guard the
 * job fields (active, next, left, the failure, stop) the helpers wait on;
 * a job's tile and faces (jtri, its own copy) are not changed while it has
 * parts left. */
#include "private/tiled_dem.h"
#include "private/cli_modes.h"
#include "private/tiled_files.h"
#include "private/tiler_io.h"

#include <errno.h>
#include <inttypes.h>
#include <pthread.h>
#include <stdio.h>
#include <sys/stat.h>
#include <unistd.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_grow.h"
#include "gdt_raster.h"

#define TD_HELPERS 15       /* most helper threads */
#define TD_PART 4096        /* faces per part of a job */
#define TD_AHEAD 8          /* faces between a prefetch of points and their use */
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

/* One rasteriser: the caller (index 0) or a helper thread. */
typedef struct td_part {
    struct tr_dem *d;
    int index; /* 1 .. helpers (the caller is 0) */
    pthread_t thread;
    int started;
    gdt_error err; /* of its last part */
    td_batch batch;
} td_part;

/* Another rank's window: the cells [r0, r0 + h) x [c0, c0 + w) around one
 * tile, dense (each the bits of its float32 value plus one, 0: not
 * written, as in gdt_dem's blocks) or, past TD_DENSE_MAX cells, as runs. */
typedef struct td_window {
    int64_t r0, c0, h, w;
    uint32_t *cells; /* dense: h w cells */
    size_t cap;
    uint64_t set;
    FILE *runs; /* a window of over TD_DENSE_MAX cells: its runs, appended */
    char *path; /* the window's file */
    int failed; /* a write of runs failed (errno in err_no) */
    int err_no;
} td_window;

/* Largest window kept dense in memory by default (64 MiB); a larger one
 * (a raster much finer than the points) is written as it comes, run by
 * run.  The environment's GDT_DEM_WINDOW_CELLS sets another limit. */
#define TD_DENSE_MAX ((uint64_t)1 << 24)

struct tr_dem {
    gdt_raster_grid grid;
    gdt_dem *w;         /* NULL in window mode (tr_dem_create_windows) */
    td_window win;      /* window mode: the current tile's cells */
    uint64_t dense_max; /* window mode: the largest dense window, cells */
    pthread_mutex_t mu;
    /* the job the helpers work on: faces jtri[3 m] of tile at base, in
     * nparts parts of TD_PART faces; parts [next, nparts) are not taken
     * yet, left are not finished; fail_part is the first failing part in
     * face order (SIZE_MAX: none) with its error */
    pthread_mutex_t job_mu, jmu;
    pthread_cond_t jcv, done_cv;
    int active; /* a job was started and not yet waited for */
    size_t nparts, next, left, fail_part;
    gdt_status fail_st;
    gdt_error fail_err;
    int stop;
    int helpers; /* started helper threads */
    tr_dem_tile tile;
    size_t m;
    uint64_t base;
    int32_t *jtri; /* the job's own copy of the faces */
    size_t jcap;
    td_part *parts; /* [0 .. helpers], 0 the caller's */
};

/* Window mode: cells (row, col .. col + n - 1) get z[0 .. n) in the
 * current window, each once. */
static gdt_status window_put(tr_dem *d, int64_t row, int64_t col, int64_t n, const float *z,
                             gdt_error *err)
{
    td_window *wn = &d->win;
    if (row < wn->r0 || row >= wn->r0 + wn->h || col < wn->c0 || n < 0 || col + n > wn->c0 + wn->w)
        return gdt_error_set(err, GDT_EINTERNAL, 7664,
                             "DEM: cells (%" PRId64 ", %" PRId64 "..+%" PRId64
                             ") outside their tile's window",
                             row, col, n);
    if (wn->runs != NULL) { /* a run record: row, col, n, then n values' bits */
        unsigned char h[24];
        int ok;
        tr_put_u64(h, (uint64_t)row);
        tr_put_u64(h + 8, (uint64_t)col);
        tr_put_u64(h + 16, (uint64_t)n);
        ok = fwrite(h, 1, 24, wn->runs) == 24;
        for (int64_t i = 0; ok && i < n; i++) {
            unsigned char b[4];
            uint32_t bits;
            memcpy(&bits, &z[i], sizeof bits);
            tr_put_u32(b, bits);
            ok = fwrite(b, 1, 4, wn->runs) == 4;
        }
        if (!ok && !wn->failed) {
            wn->failed = 1;
            wn->err_no = errno;
        }
        wn->set += (uint64_t)n;
        return GDT_OK; /* a failed write is reported by the save */
    }
    for (int64_t i = 0; i < n; i++) {
        uint32_t *c = wn->cells + (size_t)((row - wn->r0) * wn->w + (col - wn->c0) + i);
        uint32_t bits;
        memcpy(&bits, &z[i], sizeof bits);
        if (*c != 0)
            return gdt_error_set(err, GDT_EINTERNAL, 7664,
                                 "DEM: cell (%" PRId64 ", %" PRId64 ") written twice", row,
                                 col + i);
        *c = bits + 1u;
    }
    wn->set += (uint64_t)n;
    return GDT_OK;
}

/* The writer's put, or the window's in window mode (mu held). */
static gdt_status put_cells(tr_dem *d, int64_t row, int64_t col, int64_t n, const float *z,
                            gdt_error *err)
{
    return d->w != NULL ? gdt_dem_put(d->w, row, col, n, z, err)
                        : window_put(d, row, col, n, z, err);
}

static gdt_status batch_flush(td_batch *b, gdt_error *err)
{
    gdt_status st = GDT_OK;
    size_t off = 0;

    if (b->nruns == 0)
        return GDT_OK;
    pthread_mutex_lock(&b->d->mu);
    for (size_t i = 0; i < b->nruns && st == GDT_OK; i++) {
        st = put_cells(b->d, b->row[i], b->col[i], b->len[i], b->z + off, err);
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
        st = put_cells(b->d, row, col, n, z, err);
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

/* Point k of tile t as the rasteriser takes it, decoded from its record;
 * GDT_EJOB 6802 when it lies
 * outside the tile's square (the differences taken unsigned: a damaged
 * record's coordinates may be anything). */
static gdt_status tile_vertex(const tr_dem_tile *t, uint64_t k, gdt_raster_vertex *v,
                              gdt_error *err)
{
    tl_rec_xyz(t->rec + k * TL_REC, &v->x, &v->y, &v->z);
    if ((uint64_t)v->x - (uint64_t)t->x0 >= (uint64_t)t->extent ||
        (uint64_t)v->y - (uint64_t)t->y0 >= (uint64_t)t->extent)
        return gdt_error_set(err, GDT_EJOB, 6802, "%s: point (%" PRId64 ", %" PRId64
                             ") outside its tile", t->path != NULL ? t->path : "(a tile)",
                             v->x, v->y);
    return GDT_OK;
}

/* Rasterises faces [lo, hi) of tri through batch b. */
static gdt_status raster_range(tr_dem *d, td_batch *b, const tr_dem_tile *t, uint64_t base,
                               const int32_t *tri, size_t lo, size_t hi, gdt_error *err)
{
    gdt_status st = GDT_OK;
    for (size_t f = lo; f < hi && st == GDT_OK; f++) {
        gdt_raster_vertex v[3];
        if (f + TD_AHEAD < hi) /* the points of a face a few ahead: they are scattered */
            for (int i = 0; i < 3; i++) {
                uint64_t k = (uint64_t)((int64_t)tri[3 * (f + TD_AHEAD) + (size_t)i] -
                                        (int64_t)base);
                if (k < t->n)
                    __builtin_prefetch(t->rec + k * TL_REC);
            }
        for (int i = 0; i < 3 && st == GDT_OK; i++) {
            int64_t k = (int64_t)tri[3 * f + (size_t)i] - (int64_t)base;
            if (k < 0 || (uint64_t)k >= t->n)
                st = gdt_error_set(err, GDT_EINTERNAL, 7663,
                                   "DEM: a certified face names vertex %d, outside its "
                                   "tile's %" PRIu64 "..%" PRIu64,
                                   (int)tri[3 * f + (size_t)i], base, base + t->n - 1);
            else
                st = tile_vertex(t, (uint64_t)k, &v[i], err);
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

/* Takes the next part of the job and rasterises it with p's batch.
 * Called and returns with jmu held; next < nparts. */
static void take_part(tr_dem *d, td_part *p)
{
    size_t i = d->next++, lo = i * TD_PART, hi = lo + TD_PART < d->m ? lo + TD_PART : d->m;
    gdt_status st;
    pthread_mutex_unlock(&d->jmu);
    st = raster_range(d, &p->batch, &d->tile, d->base, d->jtri, lo, hi, &p->err);
    pthread_mutex_lock(&d->jmu);
    if (st != GDT_OK && i < d->fail_part) {
        d->fail_part = i;
        d->fail_st = st;
        d->fail_err = p->err;
    }
    if (--d->left == 0)
        pthread_cond_broadcast(&d->done_cv);
}

static void *helper_main(void *arg)
{
    td_part *p = arg;
    tr_dem *d = p->d;

    pthread_mutex_lock(&d->jmu);
    for (;;) {
        while (!d->stop && !(d->active && d->next < d->nparts))
            pthread_cond_wait(&d->jcv, &d->jmu);
        if (d->stop)
            break;
        take_part(d, p);
    }
    pthread_mutex_unlock(&d->jmu);
    return NULL;
}

/* Finishes the job (the caller takes the parts still left, then waits for
 * the helpers' last ones) and returns its status: the first failing part's
 * in face order.  job_mu held; no job: GDT_OK. */
static gdt_status job_finish(tr_dem *d, gdt_error *err)
{
    gdt_status st = GDT_OK;
    pthread_mutex_lock(&d->jmu);
    if (d->active) {
        while (d->next < d->nparts)
            take_part(d, &d->parts[0]);
        while (d->left > 0)
            pthread_cond_wait(&d->done_cv, &d->jmu);
        d->active = 0;
        if (d->fail_part != SIZE_MAX) {
            st = d->fail_st;
            *err = d->fail_err;
        }
    }
    pthread_mutex_unlock(&d->jmu);
    return st;
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

/* Stops the helpers (after the part each is on) and frees the batches. */
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
    st = put_cells(d, row, col, n, z, err);
    pthread_mutex_unlock(&d->mu);
    return st;
}

/* A tr_dem with its locks, nothing else; NULL when out of memory. */
static tr_dem *dem_alloc(void)
{
    tr_dem *d = calloc(1, sizeof *d);
    if (d == NULL)
        return NULL;
    pthread_mutex_init(&d->mu, NULL);
    pthread_mutex_init(&d->job_mu, NULL);
    pthread_mutex_init(&d->jmu, NULL);
    pthread_cond_init(&d->jcv, NULL);
    pthread_cond_init(&d->done_cv, NULL);
    return d;
}

gdt_status tr_dem_create(tr_dem **out, const gdt_options *opts, const gdt_cloud_info *ci,
                         const gdt_tile_plan *pl, uint64_t vertices, const char *scratch_dir,
                         gdt_error *err)
{
    tr_dem *d;
    gdt_dem_opts dop;
    gdt_status st;

    *out = NULL;
    d = dem_alloc();
    if (d == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
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

gdt_status tr_dem_create_windows(tr_dem **out, const gdt_raster_grid *grid, gdt_error *err)
{
    tr_dem *d;
    gdt_status st;
    *out = NULL;
    d = dem_alloc();
    if (d == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    d->grid = *grid;
    d->dense_max = TD_DENSE_MAX;
    {
        const char *e = getenv("GDT_DEM_WINDOW_CELLS");
        char *end = NULL;
        unsigned long long v = e != NULL ? strtoull(e, &end, 10) : 0;
        if (e != NULL && end != e && *end == '\0' && v > 0)
            d->dense_max = (uint64_t)v;
    }
    st = start_helpers(d, 0, err); /* the caller's batch only */
    if (st != GDT_OK) {
        tr_dem_abort(d);
        return st;
    }
    *out = d;
    return GDT_OK;
}

int tr_dem_windowed(const tr_dem *d)
{
    return d != NULL && d->w == NULL;
}

const gdt_raster_grid *tr_dem_grid(const tr_dem *d)
{
    return &d->grid;
}

/* floor(n / q), q > 0 */
static int64_t fdiv(int64_t n, int64_t q)
{
    int64_t r = n / q;
    return (n % q != 0 && n < 0) ? r - 1 : r;
}

/* A window file: TD_WMAGIC (dense) or TD_RMAGIC (runs), then r0, c0, h,
 * w, the cells written (u64 LE); then, dense, the h w cells (u32 LE,
 * row-major, each the bits of its value plus one, 0: not written), or the
 * runs (row, col, n as u64 LE, then the n values' bits as u32 LE). */
#define TD_WMAGIC "GDTDWIN1"
#define TD_RMAGIC "GDTDRUN1"
#define TD_WHEADER 48

static void window_header(unsigned char *hdr, const td_window *wn)
{
    memcpy(hdr, wn->runs != NULL ? TD_RMAGIC : TD_WMAGIC, 8);
    tr_put_u64(hdr + 8, (uint64_t)wn->r0);
    tr_put_u64(hdr + 16, (uint64_t)wn->c0);
    tr_put_u64(hdr + 24, (uint64_t)wn->h);
    tr_put_u64(hdr + 32, (uint64_t)wn->w);
    tr_put_u64(hdr + 40, wn->set);
}

/* Closes a window left open (a failed tile): its file removed. */
static void window_drop(td_window *wn)
{
    if (wn->runs != NULL) {
        fclose(wn->runs);
        wn->runs = NULL;
        if (wn->path != NULL)
            unlink(wn->path);
    }
    free(wn->path);
    wn->path = NULL;
}

gdt_status tr_dem_window_begin(tr_dem *d, const tr_dem_tile *t, const char *path, gdt_error *err)
{
    const size_t n = t->n;
    const gdt_raster_grid *g = &d->grid;
    td_window *wn = &d->win;
    int64_t minx = 0, maxx = -1, miny = 0, maxy = -1, c_lo, c_hi, r_lo, r_hi;
    size_t cells;

    window_drop(wn);
    wn->set = 0;
    wn->h = wn->w = 0;
    wn->r0 = wn->c0 = 0;
    wn->failed = 0;
    wn->path = strdup(path);
    if (wn->path == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    for (size_t i = 0; i < n; i++) {
        gdt_raster_vertex v;
        int64_t x, y;
        gdt_status st = tile_vertex(t, i, &v, err);
        if (st != GDT_OK)
            return st;
        x = v.x;
        y = v.y;
        if (i == 0 || x < minx)
            minx = x;
        if (i == 0 || x > maxx)
            maxx = x;
        if (i == 0 || y < miny)
            miny = y;
        if (i == 0 || y > maxy)
            maxy = y;
    }
    if (n == 0)
        return GDT_OK;
    /* the centres inside the points' box, as gdt_raster_triangle bounds a
     * face (doubled coordinates: centre of column c at 2 x0 + mx (2c + 1),
     * of row r at 2 y0 - my (2r + 1)); every face of the tile lies in it */
    c_lo = -fdiv(-(2 * minx - (2 * g->x0 + g->mx)), 2 * g->mx);
    c_hi = fdiv(2 * maxx - (2 * g->x0 + g->mx), 2 * g->mx);
    r_lo = -fdiv(-(2 * g->y0 - g->my - 2 * maxy), 2 * g->my);
    r_hi = fdiv(2 * g->y0 - g->my - 2 * miny, 2 * g->my);
    if (c_lo < 0)
        c_lo = 0;
    if (c_hi > g->geo.ncols - 1)
        c_hi = g->geo.ncols - 1;
    if (r_lo < 0)
        r_lo = 0;
    if (r_hi > g->geo.nrows - 1)
        r_hi = g->geo.nrows - 1;
    if (c_lo > c_hi || r_lo > r_hi)
        return GDT_OK;
    wn->r0 = r_lo;
    wn->c0 = c_lo;
    wn->h = r_hi - r_lo + 1;
    wn->w = c_hi - c_lo + 1;
    if ((uint64_t)wn->h > d->dense_max / (uint64_t)wn->w) {
        unsigned char hdr[TD_WHEADER];
        wn->runs = fopen(path, "wb");
        window_header(hdr, wn); /* rewritten with the count by the save */
        if (wn->runs == NULL || fwrite(hdr, 1, TD_WHEADER, wn->runs) != TD_WHEADER) {
            int e = errno;
            window_drop(wn);
            return gdt_error_set(err, GDT_EIO, 4806, "%s: cannot write this DEM window: %s", path,
                                 strerror(e));
        }
        return GDT_OK;
    }
    cells = (size_t)wn->h * (size_t)wn->w;
    if (gdt_grow(&wn->cells, &wn->cap, cells, sizeof *wn->cells, 4096) != 0)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory (a DEM window of %zu cells)",
                             cells);
    memset(wn->cells, 0, cells * sizeof *wn->cells);
    return GDT_OK;
}

gdt_status tr_dem_window_save(tr_dem *d, gdt_error *err)
{
    td_window *wn = &d->win;
    unsigned char hdr[TD_WHEADER];
    const char *path = wn->path != NULL ? wn->path : "(no window)";
    FILE *f = wn->runs;
    int ok = wn->path != NULL && !wn->failed, e = wn->failed ? wn->err_no : EINVAL;

    window_header(hdr, wn);
    if (f != NULL) { /* runs: the header again, with the count */
        ok = ok && fseek(f, 0, SEEK_SET) == 0 && fwrite(hdr, 1, TD_WHEADER, f) == TD_WHEADER;
    } else if (ok) {
        size_t cells = (size_t)(wn->h * wn->w);
        f = fopen(path, "wb");
        ok = f != NULL && fwrite(hdr, 1, TD_WHEADER, f) == TD_WHEADER;
        for (size_t i = 0; ok && i < cells; i++) {
            unsigned char b[4];
            tr_put_u32(b, wn->cells[i]);
            ok = fwrite(b, 1, 4, f) == 4;
        }
    }
    if (!ok && !wn->failed)
        e = errno;
    if (f != NULL && fclose(f) != 0 && ok) {
        ok = 0;
        e = errno;
    }
    wn->runs = NULL;
    if (!ok) {
        gdt_status st = gdt_error_set(err, GDT_EIO, 4806, "%s: cannot write this DEM window: %s",
                                      path, strerror(e));
        if (wn->path != NULL)
            unlink(wn->path); /* nothing half-written is left */
        window_drop(wn);
        return st;
    }
    free(wn->path);
    wn->path = NULL;
    return GDT_OK;
}

gdt_status tr_dem_window_put(tr_dem *d, const char *path, gdt_error *err)
{
    unsigned char hdr[TD_WHEADER];
    FILE *f = fopen(path, "rb");
    gdt_status st = GDT_OK;
    int64_t r0, c0, h, w;
    uint64_t set, seen = 0, size;
    float *row = NULL;
    unsigned char *raw = NULL;
    struct stat sb;
    int runs;

    if (f == NULL || fstat(fileno(f), &sb) != 0) {
        st = gdt_error_set(err, GDT_EIO, 4805, "%s: cannot open: %s", path, strerror(errno));
        goto done;
    }
    if (fread(hdr, 1, TD_WHEADER, f) != TD_WHEADER ||
        (memcmp(hdr, TD_WMAGIC, 8) != 0 && memcmp(hdr, TD_RMAGIC, 8) != 0)) {
        st = gdt_error_set(err, GDT_EJOB, 6801, "%s: not a DEM window this run wrote", path);
        goto done;
    }
    runs = memcmp(hdr, TD_RMAGIC, 8) == 0;
    r0 = (int64_t)tr_get_u64(hdr + 8);
    c0 = (int64_t)tr_get_u64(hdr + 16);
    h = (int64_t)tr_get_u64(hdr + 24);
    w = (int64_t)tr_get_u64(hdr + 32);
    set = tr_get_u64(hdr + 40);
    size = (uint64_t)sb.st_size;
    if (h < 0 || w < 0 || r0 < 0 || c0 < 0 || h > d->grid.geo.nrows - r0 ||
        w > d->grid.geo.ncols - c0 ||
        (!runs && size != TD_WHEADER + 4 * (uint64_t)h * (uint64_t)w)) {
        st = gdt_error_set(err, GDT_EJOB, 6802,
                           "%s: its window does not fit the raster or the file", path);
        goto done;
    }
    row = malloc((size_t)(w > 0 ? w : 1) * sizeof *row);
    raw = malloc((size_t)(w > 0 ? w : 1) * 4);
    if (row == NULL || raw == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto done;
    }
    if (runs) {
        unsigned char rh[24];
        size_t got;
        while (st == GDT_OK && (got = fread(rh, 1, 24, f)) == 24) {
            int64_t r = (int64_t)tr_get_u64(rh), c = (int64_t)tr_get_u64(rh + 8);
            int64_t n = (int64_t)tr_get_u64(rh + 16);
            if (r < r0 || r >= r0 + h || c < c0 || n < 1 || n > w || c - c0 > w - n ||
                fread(raw, 4, (size_t)n, f) != (size_t)n) {
                st = gdt_error_set(err, GDT_EJOB, 6802,
                                   "%s: a run outside its window, or "
                                   "truncated",
                                   path);
                break;
            }
            for (int64_t i = 0; i < n; i++) {
                uint32_t bits = tr_get_u32(raw + 4 * i);
                memcpy(&row[i], &bits, sizeof bits);
            }
            seen += (uint64_t)n;
            st = locked_put(d, r, c, n, row, err);
        }
        if (st == GDT_OK && got != 0)
            st = gdt_error_set(err, GDT_EJOB, 6802, "%s: truncated", path);
    }
    for (int64_t r = 0; !runs && st == GDT_OK && r < h; r++) {
        int64_t start = -1;
        if (fread(raw, 4, (size_t)w, f) != (size_t)w) {
            st = gdt_error_set(err, GDT_EJOB, 6802, "%s: truncated", path);
            break;
        }
        /* the runs of written cells go to the writer as they stand */
        for (int64_t c = 0; st == GDT_OK && c <= w; c++) {
            uint32_t v = c < w ? tr_get_u32(raw + 4 * c) : 0;
            if (v != 0) {
                uint32_t bits = v - 1u;
                memcpy(&row[c], &bits, sizeof bits);
                if (start < 0)
                    start = c;
                seen++;
            } else if (start >= 0) {
                st = locked_put(d, r0 + r, c0 + start, c - start, row + start, err);
                start = -1;
            }
        }
    }
    if (st == GDT_OK && seen != set)
        st = gdt_error_set(err, GDT_EJOB, 6802,
                           "%s: %" PRIu64 " cells where %" PRIu64 " were written", path, seen, set);
done:
    if (f != NULL)
        fclose(f);
    free(row);
    free(raw);
    return st;
}

gdt_status tr_dem_tile_faces(tr_dem *d, const tr_dem_tile *t, uint64_t base, const int32_t *tri,
                             size_t m, int alone, gdt_error *err)
{
    gdt_status st;

    pthread_mutex_lock(&d->job_mu);
    st = job_finish(d, err);
    if (st == GDT_OK && (alone || d->helpers == 0 || m < TD_PART)) {
        st = raster_range(d, &d->parts[0].batch, t, base, tri, 0, m, err);
    } else if (st == GDT_OK && m > 0) {
        if (m > SIZE_MAX / (3 * sizeof *tri) ||
            gdt_grow(&d->jtri, &d->jcap, 3 * m, sizeof *d->jtri, 3 * 65536) != 0) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory (a DEM job of %zu faces)",
                               m);
        } else {
            memcpy(d->jtri, tri, 3 * m * sizeof *tri);
            pthread_mutex_lock(&d->jmu);
            d->tile = *t;
            d->base = base;
            d->m = m;
            d->nparts = d->left = (m + TD_PART - 1) / TD_PART;
            d->next = 0;
            d->fail_part = SIZE_MAX;
            d->active = 1;
            pthread_cond_broadcast(&d->jcv);
            pthread_mutex_unlock(&d->jmu);
        }
    }
    pthread_mutex_unlock(&d->job_mu);
    return st;
}

gdt_status tr_dem_tile_wait(tr_dem *d, gdt_error *err)
{
    gdt_status st;
    pthread_mutex_lock(&d->job_mu);
    st = job_finish(d, err);
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
    gdt_status st = tr_dem_tile_wait(d, err);
    stop_helpers(d); /* the rasterising is over */
    if (st != GDT_OK)
        return st;
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
    free(d->jtri);
    window_drop(&d->win);
    free(d->win.cells);
    gdt_dem_abort(d->w);
    pthread_mutex_destroy(&d->mu);
    pthread_mutex_destroy(&d->job_mu);
    pthread_mutex_destroy(&d->jmu);
    pthread_cond_destroy(&d->jcv);
    pthread_cond_destroy(&d->done_cv);
    free(d);
}
