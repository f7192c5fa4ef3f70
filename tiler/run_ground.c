/* run_ground.c — the ground stage of a tiled run (--ground pmf): after the
 * --dup merge of pass 2, every tile's points are classified with the
 * progressive morphological filter (gdt_ground.h) and only the ground
 * points stay as the tile's points.
 *
 * A tile is classified with every point of the cloud within the filter's
 * reach of it (pass 2 wrote .edge files that wide), so each point gets the
 * class a whole-cloud run of the filter gives it, whatever the tiling.
 * The tiles are shared by up to --threads workers, each holding one tile
 * and its reach within its share of half the memory budget.  The subsets
 * replace the tile files only when every tile is classified (the others'
 * reach reads the full files until then), as part of pass 2: the journal
 * records pass 2 with the ground files, so a resumed run never classifies
 * again once pass 2 is recorded.
 */
#include "private/cli_modes.h"
#include "private/stages.h"

#include <inttypes.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

typedef struct ground_ctx {
    tr_run *c;
    const gdt_pmf *f;
    gdt_tiler_tile_files *files;
    uint64_t ntiles;
    uint64_t max_points, max_bytes;
    pthread_mutex_t mu;
    uint64_t next, done;
    uint64_t ground, nonground;
    gdt_status st;      /* the first failure */
    gdt_error err;
} ground_ctx;

typedef struct ground_worker {
    ground_ctx *g;
    pthread_t tid;
    int started, report;
    gdt_point_buf own, around;
    gdt_point *all;
    size_t cap_all;
    uint8_t *keep;
    size_t cap_keep;
} ground_worker;

static gdt_status classify_tile(ground_worker *w, uint64_t k, gdt_error *err)
{
    ground_ctx *g = w->g;
    const gdt_tile_plan *plan = g->c->plan;
    const gdt_pmf_box cloud = {plan->min_x, plan->max_x, plan->min_y, plan->max_y};
    gdt_pmf_box roi;
    gdt_tile_desc d;
    gdt_tiler_tile_files out;
    size_t n;
    gdt_status st = gdt_tiler_tile_info(g->c->tiler, k, &d, err);
    if (st != GDT_OK)
        return st;
    roi.x0 = d.x0;
    roi.x1 = d.x0 + plan->span - 1;
    roi.y0 = d.y0;
    roi.y1 = d.y0 + plan->span - 1;
    st = gdt_tiler_load_reach(g->c->tiler, k, g->f->reach, g->max_points, &w->own,
                                         &w->around, err);
    if (st != GDT_OK)
        return st;
    n = w->own.n + w->around.n;
    if (tr_reserve(&w->all, &w->cap_all, n, sizeof *w->all) != 0 ||
        tr_reserve(&w->keep, &w->cap_keep, n, 1) != 0)
        return gdt_error_set(err, GDT_EINTERNAL, 7001,
                             "out of memory (ground filter of %zu points)", n);
    /* own points first: the classes of the reach are not kept */
    if (w->own.n > 0)
        memcpy(w->all, w->own.pts, w->own.n * sizeof *w->all);
    if (w->around.n > 0)
        memcpy(w->all + w->own.n, w->around.pts, w->around.n * sizeof *w->all);
    st = gdt_pmf_classify(g->f, w->all, n, &cloud, &roi, w->keep, g->max_bytes, err);
    if (st == GDT_OK)
        st = gdt_tiler_write_subset(g->c->tiler, k, w->own.pts, w->own.n, w->keep, &out, err);
    if (st != GDT_OK)
        return st;
    pthread_mutex_lock(&g->mu);
    g->files[k] = out;
    g->ground += out.points;
    g->nonground += w->own.n - out.points;
    g->done++;
    pthread_mutex_unlock(&g->mu);
    return GDT_OK;
}

/* Takes tiles until none is left or one failed; worker 0 (the caller's
 * thread) reports progress. */
static void *worker_main(void *arg)
{
    ground_worker *w = arg;
    ground_ctx *g = w->g;
    for (;;) {
        gdt_error e;
        gdt_status st;
        uint64_t k;
        pthread_mutex_lock(&g->mu);
        k = g->next < g->ntiles && g->st == GDT_OK ? g->next++ : UINT64_MAX;
        pthread_mutex_unlock(&g->mu);
        if (k == UINT64_MAX)
            break;
        gdt_error_clear(&e);
        st = tr_stopped(g->c) ? gdt_error_set(&e, GDT_EINTERRUPTED, 1303,
                                              "stopped by a signal during the ground filter")
                              : classify_tile(w, k, &e);
        if (st != GDT_OK) {
            pthread_mutex_lock(&g->mu);
            if (g->st == GDT_OK) {
                g->st = st;
                g->err = e;
            }
            pthread_mutex_unlock(&g->mu);
            break;
        }
        if (w->report) {
            pthread_mutex_lock(&g->mu);
            uint64_t done = g->done;
            pthread_mutex_unlock(&g->mu);
            gdt_progress_update(&g->c->prog, done);
        }
    }
    return NULL;
}

gdt_status tr_run_ground(tr_run *c, gdt_error *err)
{
    const gdt_options *opts = c->opts;
    const uint64_t ntiles = gdt_tiler_tile_count(c->tiler);
    const gdt_tiler_stats *ts = gdt_tiler_get_stats(c->tiler);
    ground_ctx g;
    ground_worker *w = NULL;
    gdt_pmf f;
    unsigned nw;
    double t0 = gdt_now();
    gdt_status st;

    st = gdt_pmf_init(&f, &opts->pmf, &c->plan->lattice, c->plan->min_z, err);
    if (st != GDT_OK)
        return st;
    memset(&g, 0, sizeof g);
    g.c = c;
    g.f = &f;
    g.ntiles = ntiles;
    nw = (unsigned)gdt_cli_threads(opts->threads);
    if (nw > ntiles)
        nw = ntiles > 0 ? (unsigned)ntiles : 1;
    /* half the budget for the workers' tiles: points (own, reach, their
     * copy for the filter) and the filter's own arrays and grids */
    g.max_bytes = ts->mem_budget / 2 / nw;
    g.max_points = g.max_bytes / (3 * sizeof(gdt_point) + 48);
    g.files = calloc(ntiles > 0 ? ntiles : 1, sizeof *g.files);
    w = calloc(nw, sizeof *w);
    if (g.files == NULL || w == NULL) {
        free(g.files);
        free(w);
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    }
    pthread_mutex_init(&g.mu, NULL);
    gdt_progress_stage(&c->prog, "ground filter", ntiles, "tiles");
    for (unsigned i = 0; i < nw; i++) {
        w[i].g = &g;
        if (i > 0 && pthread_create(&w[i].tid, NULL, worker_main, &w[i]) == 0)
            w[i].started = 1;
    }
    /* the caller's thread is worker 0 (it takes every tile if no thread
     * could start) and reports progress between tiles */
    w[0].report = 1;
    worker_main(&w[0]);
    for (unsigned i = 1; i < nw; i++)
        if (w[i].started)
            pthread_join(w[i].tid, NULL);
    gdt_progress_update(&c->prog, g.done);
    gdt_progress_end(&c->prog);
    st = g.st;
    if (st != GDT_OK)
        *err = g.err;
    else
        st = gdt_tiler_take_subsets(c->tiler, g.files, err);
    if (st == GDT_OK) {
        c->s.ground_points = g.ground;
        c->s.nonground_points = g.nonground;
        c->s.t_ground = gdt_now() - t0;
        gdt_log_note(&c->log,
                     "ground filter: %" PRIu64 " ground and %" PRIu64 " other points in %.2f s "
                     "(%d windows, reach %" PRId64 " lattice steps, %u workers)",
                     g.ground, g.nonground, c->s.t_ground, f.rounds, f.reach, nw);
    }
    for (unsigned i = 0; i < nw; i++) {
        gdt_point_buf_free(&w[i].own);
        gdt_point_buf_free(&w[i].around);
        free(w[i].all);
        free(w[i].keep);
    }
    pthread_mutex_destroy(&g.mu);
    free(w);
    free(g.files);
    return st;
}
