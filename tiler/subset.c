/* subset.c — a subset of every tile's points replaces them after pass 2
 * (gdt_tiler.h: gdt_tiler_write_subset, gdt_tiler_take_subsets).
 *
 * Each tile's subset is written beside its pass-2 files (.gpts, .gedge),
 * so the pass-2 files of every tile stay readable for the other tiles'
 * reach until the last subset exists; only then are they renamed over
 * the .pts and .edge files, and the directory synced.  The subset files
 * carry the checksums of .pts and .edge files, so the journal records
 * them as pass 2's.
 */
#include "private/tiler_impl.h"
#include "private/tiler_io.h"
#include "private/job.h"

#include <errno.h>
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define SUBSET_BUF_RECS 4096

gdt_status gdt_tiler_write_subset(const gdt_tiler *t, uint64_t k, const gdt_point *own,
                                  size_t n, const uint8_t *keep, gdt_tiler_tile_files *out,
                                  gdt_error *err)
{
    const tl_tile *tl;
    const int64_t T = t->plan.span, h = t->plan.halo * t->plan.cell;
    char *pts_tmp, *pts, *edge_tmp, *edge;
    int64_t x0, y0;
    tl_wfile wp, we;
    gdt_status st = GDT_OK;

    memset(out, 0, sizeof *out);
    if (t->state != 2 || k >= t->ntiles)
        return gdt_error_set(err, GDT_EUSAGE, 2505,
                             "tile %" PRIu64 ": a subset needs pass 2 done", k);
    tl = &t->tiles[k];
    if ((uint64_t)n != tl->points)
        return gdt_error_set(err, GDT_EUSAGE, 2505,
                             "tile %" PRIu64 ": a subset of %zu points for a tile of %" PRIu64,
                             k, n, tl->points);
    x0 = tl->i * T;
    y0 = tl->j * T;
    memset(&wp, 0, sizeof wp);
    memset(&we, 0, sizeof we);
    wp.fd = we.fd = -1;
    pts_tmp = tl_tile_file(t, k, "gpts", 1);
    pts = tl_tile_file(t, k, "gpts", 0);
    edge_tmp = tl_tile_file(t, k, "gedge", 1);
    edge = tl_tile_file(t, k, "gedge", 0);
    if (pts_tmp == NULL || pts == NULL || edge_tmp == NULL || edge == NULL)
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    if (st == GDT_OK)
        st = tl_wfile_init(&wp, pts_tmp, pts, SUBSET_BUF_RECS, !t->opts.test_nosync, err);
    if (st == GDT_OK)
        st = tl_wfile_init(&we, edge_tmp, edge, SUBSET_BUF_RECS, !t->opts.test_nosync, err);
    if (st == GDT_OK) {
        tl_wfile_hash(&wp, gdt_job_file_seed(t->opts.file_id, k, GDT_JOB_FILE_PTS));
        tl_wfile_hash(&we, gdt_job_file_seed(t->opts.file_id, k, GDT_JOB_FILE_EDGE));
    }
    for (size_t i = 0; i < n && st == GDT_OK; i++) {
        const gdt_point *p = &own[i];
        if (!keep[i])
            continue;
        st = tl_wfile_put(&wp, p, err);
        if (st == GDT_OK && h > 0 && tl_on_edge(p, x0, y0, T, h))
            st = tl_wfile_put(&we, p, err);
    }
    if (st == GDT_OK) {
        out->points = wp.nrec;
        out->edge = we.nrec;
        st = tl_wfile_sum(&wp, &out->sum[0], err);
    }
    if (st == GDT_OK)
        st = tl_wfile_sum(&we, &out->sum[1], err);
    if (st == GDT_OK)
        st = tl_wfile_commit(&wp, err);
    if (st == GDT_OK)
        st = tl_wfile_commit(&we, err);
    tl_wfile_abort(&wp);
    tl_wfile_abort(&we);
    free(pts_tmp);
    free(pts);
    free(edge_tmp);
    free(edge);
    return st;
}

gdt_status gdt_tiler_take_subsets(gdt_tiler *t, const gdt_tiler_tile_files *files,
                                  gdt_error *err)
{
    gdt_status st = GDT_OK;

    if (t->state != 2 || files == NULL)
        return gdt_error_set(err, GDT_EUSAGE, 2505, "taking subsets needs pass 2 done");
    for (uint64_t k = 0; k < t->ntiles; k++)
        if (files[k].points > t->tiles[k].points || files[k].edge > files[k].points)
            return gdt_error_set(err, GDT_EINTERNAL, 7505,
                                 "tile %" PRIu64 ": a subset of %" PRIu64 " points (%" PRIu64
                                 " on the edge) of %" PRIu64,
                                 k, files[k].points, files[k].edge, t->tiles[k].points);
    for (uint64_t k = 0; k < t->ntiles && st == GDT_OK; k++) {
        static const char *const from[2] = {"gpts", "gedge"}, *const to[2] = {"pts", "edge"};
        tl_tile *tl = &t->tiles[k];
        for (int f = 0; f < 2 && st == GDT_OK; f++) {
            char *a = tl_tile_file(t, k, from[f], 0), *b = tl_tile_file(t, k, to[f], 0);
            if (a == NULL || b == NULL)
                st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
            else if (rename(a, b) != 0)
                st = gdt_error_set(err, GDT_EIO, 4505, "cannot rename %s to %s: %s", a, b,
                                   strerror(errno));
            free(a);
            free(b);
        }
        if (st != GDT_OK) {
            /* the tile files are now a mix: pass 2 must run again */
            t->state = -1;
            break;
        }
        tl->points = files[k].points;
        tl->edge = files[k].edge;
        tl->sum[0] = files[k].sum[0];
        tl->sum[1] = files[k].sum[1];
    }
    if (st == GDT_OK)
        st = tl_sync_dir(t->tiles_dir, err);
    if (st != GDT_OK)
        t->state = -1;
    t->stats.max_tile_points = 0;
    for (uint64_t k = 0; st == GDT_OK && k < t->ntiles; k++)
        if (t->tiles[k].points > t->stats.max_tile_points)
            t->stats.max_tile_points = t->tiles[k].points;
    return st;
}

gdt_status gdt_tiler_load_raw(const gdt_tiler *t, uint64_t k, uint64_t max_points,
                              gdt_point_buf *out, gdt_error *err)
{
    tl_rfile rf;
    char *path;
    size_t got = 0;
    uint64_t n;
    gdt_status st;

    out->n = 0;
    if (t->state != 2 || k >= t->ntiles || !t->opts.keep_spill)
        return gdt_error_set(err, GDT_EUSAGE, 2505,
                             "tile %" PRIu64 ": its pass-2 records are not kept", k);
    n = t->tiles[k].count;
    if (n > max_points)
        return gdt_error_set(err, GDT_EUSAGE, 2506,
                             "tile (%" PRId64 ", %" PRId64 ") holds %" PRIu64 " records, more "
                             "than its share of the memory budget takes (%" PRIu64 ")",
                             t->tiles[k].i, t->tiles[k].j, n, max_points);
    if (n > out->cap) {
        gdt_point *g = realloc(out->pts, (size_t)n * sizeof *g);
        if (g == NULL)
            return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory (%" PRIu64
                                 " records)", n);
        out->pts = g;
        out->cap = (size_t)n;
    }
    path = tl_tile_file(t, k, "raw", 0);
    if (path == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    st = tl_rfile_open(&rf, path, n, SUBSET_BUF_RECS, err);
    free(path);
    if (st != GDT_OK)
        return st;
    st = tl_rfile_read(&rf, out->pts, (size_t)n, &got, err);
    tl_rfile_close(&rf);
    if (st == GDT_OK && got != n)
        st = gdt_error_set(err, GDT_EIO, 4504, "tile %" PRIu64 ": %zu of %" PRIu64
                           " pass-2 records read", k, got, n);
    out->n = st == GDT_OK ? got : 0;
    return st;
}

void gdt_tiler_drop_raw(const gdt_tiler *t, uint64_t k)
{
    char *path = t->opts.keep_spill ? tl_tile_file(t, k, "raw", 0) : NULL;
    if (path != NULL)
        unlink(path);
    free(path);
}

gdt_status gdt_tiler_check_subset(const gdt_tiler *t, uint64_t k,
                                  const gdt_tiler_tile_files *want, gdt_point_buf *pts, int *ok,
                                  gdt_error *err)
{
    static const char *const ext[2] = {"gpts", "gedge"};
    static const int kind[2] = {GDT_JOB_FILE_PTS, GDT_JOB_FILE_EDGE};
    const uint64_t recs[2] = {want->points, want->edge};
    gdt_status st = GDT_OK;

    *ok = 0;
    if (t->state != 2 || k >= t->ntiles)
        return gdt_error_set(err, GDT_EUSAGE, 2505, "tile %" PRIu64 ": no pass 2", k);
    if (want->points > t->tiles[k].points || want->edge > want->points)
        return GDT_OK;
    for (int f = 0; f < 2; f++) {
        char *path = tl_tile_file(t, k, ext[f], 0);
        uint64_t size = 0, sum = 0;
        gdt_error e2;
        if (path == NULL)
            return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        gdt_error_clear(&e2);
        st = tl_file_sum(path, gdt_job_file_seed(t->opts.file_id, k, kind[f]), &size, &sum,
                         &e2);
        free(path);
        if (st == GDT_EINTERNAL) {
            *err = e2;
            return st;
        }
        if (st != GDT_OK || size != recs[f] * TL_REC || sum != want->sum[f])
            return GDT_OK; /* missing or another: written again */
    }
    if (pts != NULL) {
        tl_rfile rf;
        size_t got = 0;
        char *path = tl_tile_file(t, k, "gpts", 0);
        if (path == NULL)
            return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        if (want->points > pts->cap) {
            gdt_point *g = realloc(pts->pts, (size_t)want->points * sizeof *g);
            if (g == NULL) {
                free(path);
                return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
            }
            pts->pts = g;
            pts->cap = (size_t)want->points;
        }
        st = tl_rfile_open(&rf, path, want->points, SUBSET_BUF_RECS, err);
        free(path);
        if (st != GDT_OK)
            return st;
        st = tl_rfile_read(&rf, pts->pts, (size_t)want->points, &got, err);
        tl_rfile_close(&rf);
        if (st != GDT_OK)
            return st;
        pts->n = got;
        if (got != want->points)
            return GDT_OK;
    }
    *ok = 1;
    return GDT_OK;
}
