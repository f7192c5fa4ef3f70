/* halo.c — loading one tile and its halo for the tile stage.
 *
 * The halo of tile T is read from the .edge files of the tiles that meet
 * T's halo box: a point of tile U can lie in the halo box of another tile
 * only if it is within h of U's border, and .edge holds exactly those
 * points of U (all of them when h >= T/2).  Each candidate record is kept
 * iff it lies in the half-open halo box; the result is sorted by ordinal,
 * so it does not depend on the order in which the neighbours are read.
 */
#include "private/tiler_impl.h"
#include "private/tiler_io.h"

#include <inttypes.h>
#include <stdlib.h>
#include <string.h>

#define LOCAL_CHUNK 1024 /* records per read of gdt_tiler_load_tile_local */

static gdt_status reserve(gdt_point_buf *b, size_t n, gdt_error *err)
{
    gdt_point *g;
    size_t cap;
    if (n <= b->cap)
        return GDT_OK;
    cap = b->cap > 0 ? b->cap : 1024;
    while (cap < n)
        cap = cap > SIZE_MAX / 2 / sizeof *g ? n : 2 * cap;
    if (cap > SIZE_MAX / sizeof *g)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    g = realloc(b->pts, cap * sizeof *g);
    if (g == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory loading a tile (%zu points)",
                             n);
    b->pts = g;
    b->cap = cap;
    return GDT_OK;
}

static gdt_status too_large(const gdt_tiler *t, uint64_t k, uint64_t n, gdt_error *err)
{
    return gdt_error_set(err, GDT_EUSAGE, 2506,
                         "tile (%" PRId64 ", %" PRId64 ") with its halo holds more than %" PRIu64
                         " points, more than half the memory budget of %" PRIu64
                         " bytes: use a smaller --cell or --tile, or a larger --mem-budget",
                         t->tiles[k].i, t->tiles[k].j, n, t->budget);
}

/* Appends the points of tile u's .edge file inside [bx0, bx1) x [by0, by1). */
static gdt_status add_neighbour(const gdt_tiler *t, uint64_t k, uint64_t u, int64_t bx0, int64_t bx1,
                                int64_t by0, int64_t by1, uint64_t limit, gdt_point_buf *halo,
                                uint64_t tile_n, gdt_error *err)
{
    tl_rfile rf;
    char *path;
    gdt_point p;
    int got;
    gdt_status st;

    if (t->tiles[u].edge == 0)
        return GDT_OK;
    path = tl_tile_file(t, u, "edge", 0);
    if (path == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    st = tl_rfile_open(&rf, path, t->tiles[u].edge, t->sz.halo_read_recs, err);
    free(path);
    if (st != GDT_OK)
        return st;
    for (;;) {
        st = tl_rfile_next(&rf, &p, &got, err);
        if (st != GDT_OK || !got)
            break;
        if (p.x < bx0 || p.x >= bx1 || p.y < by0 || p.y >= by1)
            continue;
        if (tile_n + halo->n + 1 > limit) {
            st = too_large(t, k, limit, err);
            break;
        }
        st = reserve(halo, halo->n + 1, err);
        if (st != GDT_OK)
            break;
        halo->pts[halo->n++] = p;
    }
    tl_rfile_close(&rf);
    return st;
}

/* Tile k's own points from its .pts file (sorted by ordinal): into pts as
 * records or, when pts is NULL, into xy[0..points) as (x - x0, y - y0) and
 * z[0..points) (when z is not NULL), through a small chunk, so that the
 * records are never held whole.  *n receives their count. */
static gdt_status load_own(const gdt_tiler *t, uint64_t k, gdt_point_buf *pts, gdt_ipt *xy,
                           double *z, int64_t x0, int64_t y0, size_t *n, gdt_error *err)
{
    const tl_tile *tl = &t->tiles[k];
    gdt_point chunk[LOCAL_CHUNK];
    tl_rfile rf;
    char *path;
    gdt_status st = GDT_OK;

    *n = 0;
    if (pts != NULL && (st = reserve(pts, (size_t)tl->points, err)) != GDT_OK)
        return st;
    path = tl_tile_file(t, k, "pts", 0);
    if (path == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    st = tl_rfile_open(&rf, path, tl->points, t->sz.halo_read_recs, err);
    free(path);
    if (st != GDT_OK)
        return st;
    if (pts != NULL) {
        st = tl_rfile_read(&rf, pts->pts, (size_t)tl->points, n, err);
    } else {
        while (st == GDT_OK && *n < tl->points) {
            size_t m = 0, want = tl->points - *n < LOCAL_CHUNK ? (size_t)(tl->points - *n)
                                                                : LOCAL_CHUNK;
            st = tl_rfile_read(&rf, chunk, want, &m, err);
            if (st != GDT_OK || m == 0)
                break;
            for (size_t i = 0; i < m; i++) {
                xy[*n + i].x = chunk[i].x - x0;
                xy[*n + i].y = chunk[i].y - y0;
            }
            for (size_t i = 0; z != NULL && i < m; i++)
                z[*n + i] = chunk[i].z;
            *n += m;
        }
    }
    tl_rfile_close(&rf);
    return st;
}

/* Both loaders: the own points (see load_own; *nown their count), then the
 * halo. */
static gdt_status load(const gdt_tiler *t, uint64_t k, gdt_point_buf *pts, gdt_ipt *xy,
                       double *z, int64_t x0, int64_t y0, size_t *nown, gdt_point_buf *halo,
                       int64_t h, uint64_t limit, gdt_error *err)
{
    const int64_t T = t->plan.span;
    const tl_tile *tl;
    int64_t bx0, bx1, by0, by1, i0, i1, j0, j1;
    size_t n = 0;
    gdt_status st;

    *nown = 0;
    halo->n = 0;
    if (t->state != 2 || k >= t->ntiles)
        return gdt_error_set(err, GDT_EUSAGE, 2505,
                             "tile %" PRIu64 " cannot be loaded (pass 2 not done, or no such "
                             "tile)",
                             k);
    tl = &t->tiles[k];
    if (tl->points > limit)
        return too_large(t, k, limit, err);
    st = load_own(t, k, pts, xy, z, x0, y0, &n, err);
    if (st != GDT_OK)
        return st;
    *nown = n;
    if (h == 0)
        return GDT_OK;

    bx0 = tl->i * T - h;
    bx1 = tl->i * T + T + h;
    by0 = tl->j * T - h;
    by1 = tl->j * T + T + h;
    i0 = tl_floor_div(bx0, T);
    i1 = tl_floor_div(bx1 - 1, T);
    j0 = tl_floor_div(by0, T);
    j1 = tl_floor_div(by1 - 1, T);
    if ((uint64_t)(i1 - i0 + 1) * (uint64_t)(j1 - j0 + 1) <= 4 * t->ntiles) {
        for (int64_t j = j0; j <= j1 && st == GDT_OK; j++)
            for (int64_t i = i0; i <= i1 && st == GDT_OK; i++) {
                const uint64_t *u = tl_map_find(&t->map, i, j);
                if (u != NULL && *u != k)
                    st = add_neighbour(t, k, *u, bx0, bx1, by0, by1, limit, halo, n, err);
            }
    } else {
        /* A halo much wider than the grid is sparse in tiles: test them all. */
        for (uint64_t u = 0; u < t->ntiles && st == GDT_OK; u++) {
            const tl_tile *v = &t->tiles[u];
            if (u != k && v->i >= i0 && v->i <= i1 && v->j >= j0 && v->j <= j1)
                st = add_neighbour(t, k, u, bx0, bx1, by0, by1, limit, halo, n, err);
        }
    }
    if (st == GDT_OK)
        st = tl_sort_by_ord(halo->pts, halo->n, NULL, err);
    if (st != GDT_OK) {
        *nown = 0;
        halo->n = 0;
    }
    return st;
}

gdt_status gdt_tiler_load_tile(gdt_tiler *t, uint64_t k, gdt_point_buf *pts,
                               gdt_point_buf *halo, gdt_error *err)
{
    size_t n = 0;
    gdt_status st;
    pts->n = 0;
    st = load(t, k, pts, NULL, NULL, 0, 0, &n, halo, t->plan.halo * t->plan.cell,
              t->budget / 2 / sizeof(gdt_point), err);
    pts->n = n;
    return st;
}

gdt_status gdt_tiler_load_tile_local(gdt_tiler *t, uint64_t k, int64_t x0, int64_t y0,
                                     gdt_ipt *xy, double *z, size_t *n, gdt_point_buf *halo,
                                     gdt_error *err)
{
    return load(t, k, NULL, xy, z, x0, y0, n, halo, t->plan.halo * t->plan.cell,
                t->budget / 2 / sizeof(gdt_point), err);
}

gdt_status gdt_tiler_load_reach(const gdt_tiler *t, uint64_t k, int64_t reach,
                                uint64_t max_points, gdt_point_buf *own, gdt_point_buf *around,
                                gdt_error *err)
{
    size_t n = 0;
    gdt_status st;
    own->n = 0;
    around->n = 0;
    if (t->state != 2 || reach < 0 || reach > tl_edge_width(t))
        return gdt_error_set(err, GDT_EUSAGE, 2505,
                             "tile %" PRIu64 ": a reach of %" PRId64 " lattice steps needs pass "
                             "2 done with .edge files at least that wide (%" PRId64 ")",
                             k, reach, tl_edge_width(t));
    st = load(t, k, own, NULL, NULL, 0, 0, &n, around, reach, max_points, err);
    own->n = n;
    return st;
}
