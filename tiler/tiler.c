/* tiler.c — the tiler's life cycle: options, pass 1, pass 2, the plan API.
 *
 * Pass 1 streams the cloud once: bounding box, z range, the density grid
 * (OpenVDB) and, with a given --cell, the per-tile counts.  plan.c turns
 * that into the plan and the tile table; the index is then saved as
 * <job>/index.vdb (temporary name, fsync, rename).  Pass 2 (spill.c) and
 * the --dup merge (merge_dup.c) write the tile files; halo.c loads tiles.
 */
#include "private/tiler_impl.h"
#include "private/tiler_io.h"
#include "private/run_stats.h"

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <inttypes.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

#define LOCAL_LIMIT (INT64_C(1) << 31)
#define MAX_FD_BUDGET 1024u

uint64_t gdt_tiler_budget(const gdt_tiler_opts *o)
{
    uint64_t n2;
    if (o->mem_budget != 0)
        return o->mem_budget;
    n2 = (uint64_t)(o->tile > 0 ? o->tile : 0) * (uint64_t)(o->tile > 0 ? o->tile : 0) * 64u;
    return n2 > GDT_TILER_DEFAULT_BUDGET ? n2 : GDT_TILER_DEFAULT_BUDGET;
}

/* Half the soft descriptor limit, at most MAX_FD_BUDGET, at least 4: the
 * other half stays for the inputs, the job database and the libraries. */
static unsigned probe_fd_budget(void)
{
    struct rlimit rl;
    rlim_t half;
    if (getrlimit(RLIMIT_NOFILE, &rl) != 0 || rl.rlim_cur == RLIM_INFINITY)
        return MAX_FD_BUDGET;
    half = rl.rlim_cur / 2;
    if (half > MAX_FD_BUDGET)
        return MAX_FD_BUDGET;
    return half < 4 ? 4u : (unsigned)half;
}

static void set_sizes(gdt_tiler *t)
{
    tl_sizes *s = &t->sz;
    uint64_t B = t->budget;

    s->tiles_bytes = (size_t)(B / 8);
    if (t->opts.test_tiny) {
        /* Odd, tiny sizes: every buffer boundary is crossed many times. */
        s->read_cap = 7;
        s->write_bytes = 8 * TL_REC;
        s->min_file_recs = 2;
        s->merge_cap = 64;
        s->merge_k = 2;
        s->part_recs = 2;
        s->merge_read_recs = 3;
        s->halo_read_recs = 5;
        return;
    }
    s->read_cap = 65536;
    /* A quarter of the budget, at most 64 KiB for each of 1024 files: more
     * would not make the writes any larger. */
    s->write_bytes = (size_t)(B / 4 < ((uint64_t)64 << 20) ? B / 4 : ((uint64_t)64 << 20));
    s->min_file_recs = (64u << 10) / TL_REC;
    s->merge_cap = (size_t)(B / 2 / (2 * sizeof(gdt_point)));
    s->merge_k = t->fd_budget - 2 < 16 ? t->fd_budget - 2 : 16;
    s->part_recs = (64u << 10) / TL_REC;
    s->merge_read_recs = (64u << 10) / TL_REC;
    s->halo_read_recs = (256u << 10) / TL_REC;
}

char *tl_tile_file(const gdt_tiler *t, uint64_t k, const char *kind, int tmp)
{
    if (t->tiles_dir == NULL || k >= t->ntiles)
        return NULL;
    return tl_path("%s/tile_%" PRId64 "_%" PRId64 ".%s%s%s", t->tiles_dir, t->tiles[k].i,
                   t->tiles[k].j, kind, tmp ? ".tmp" : "",
                   strcmp(kind, "raw") == 0 ? t->spill_part : "");
}

gdt_status tl_progress(gdt_tiler *t, int stage, uint64_t done, uint64_t total, gdt_error *err)
{
    static const char *names[4] = {"", "pass 1", "pass 2", "the --dup merge"};
    if (t->opts.progress == NULL || t->opts.progress(t->opts.progress_ctx, stage, done, total) == 0)
        return GDT_OK;
    return gdt_error_set(err, GDT_EINTERRUPTED, 1301, "tiler interrupted during %s",
                         names[stage >= 1 && stage <= 3 ? stage : 0]);
}

uint64_t tl_tile_of(const gdt_tiler *t, int64_t x, int64_t y)
{
    const uint64_t *v =
        tl_map_find(&t->map, tl_floor_div(x, t->plan.span), tl_floor_div(y, t->plan.span));
    return v != NULL ? *v : UINT64_MAX;
}

gdt_status gdt_tiler_create(gdt_tiler **out, const gdt_tiler_opts *opts, gdt_cloud *cloud,
                            gdt_error *err)
{
    gdt_tiler *t = NULL;
    const gdt_cloud_info *ci;
    gdt_status st = GDT_OK;
    int n = opts->tile;

    *out = NULL;
    if (n < GDT_TILER_MIN_TILE || n > GDT_TILER_MAX_TILE || (n & (n - 1)) != 0)
        return gdt_error_set(err, GDT_EUSAGE, 2501,
                             "--tile %d: must be a power of two in [%d, %d]", n,
                             GDT_TILER_MIN_TILE, GDT_TILER_MAX_TILE);
    if (!(opts->cell >= 0.0) || !isfinite(opts->cell))
        return gdt_error_set(err, GDT_EUSAGE, 2501, "--cell: must be a positive number");
    if (opts->dup != GDT_DUP_FIRST && opts->dup != GDT_DUP_MIN_Z && opts->dup != GDT_DUP_MAX_Z)
        return gdt_error_set(err, GDT_EUSAGE, 2501, "--dup: unknown rule");
    if (cloud == NULL)
        return gdt_error_set(err, GDT_EUSAGE, 2501, "the tiler needs a cloud");
    t = calloc(1, sizeof *t);
    if (t == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    t->opts = *opts;
    t->opts.job_dir = NULL;
    t->cloud = cloud;
    t->log = opts->log;
    t->budget = gdt_tiler_budget(opts);
    if (t->budget < GDT_TILER_MIN_BUDGET && !opts->test_tiny) {
        st = gdt_error_set(err, GDT_EUSAGE, 2504,
                           "--mem-budget %" PRIu64 " bytes is below the tiler's minimum of %"
                           PRIu64 " MiB",
                           t->budget, GDT_TILER_MIN_BUDGET >> 20);
        goto fail;
    }
    t->fd_budget = opts->fd_budget != 0 ? opts->fd_budget
                   : opts->test_tiny    ? 4u
                                        : probe_fd_budget();
    if (t->fd_budget < 4) {
        st = gdt_error_set(err, GDT_EUSAGE, 2501, "descriptor budget %u is below 4",
                           t->fd_budget);
        goto fail;
    }
    set_sizes(t);
    if (opts->job_dir != NULL) {
        struct stat sb;
        if (stat(opts->job_dir, &sb) != 0) {
            st = gdt_error_set(err, GDT_EIO, 4501, "job directory %s: %s", opts->job_dir,
                               strerror(errno));
            goto fail;
        }
        if (!S_ISDIR(sb.st_mode)) {
            st = gdt_error_set(err, GDT_EIO, 4501, "job directory %s: not a directory",
                               opts->job_dir);
            goto fail;
        }
        t->job_dir = strdup(opts->job_dir);
        t->tiles_dir = tl_path("%s/tiles", opts->job_dir);
        if (t->job_dir == NULL || t->tiles_dir == NULL) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
            goto fail;
        }
        t->opts.job_dir = t->job_dir;
    }
    ci = gdt_cloud_get_info(cloud);
    if (opts->cell > 0.0) {
        double c = opts->cell / ci->lattice.sx;
        double r = nearbyint(c);
        if (!(c < (double)(LOCAL_LIMIT / n) + 0.5)) {
            st = gdt_error_set(err, GDT_EUSAGE, 2502,
                               "--cell %.17g is %.6g lattice steps: a tile of %d texels would "
                               "span more than 2^31 steps",
                               opts->cell, c, n);
            goto fail;
        }
        /* a texel is a whole number of lattice steps: below one there is
         * no texel to round to that keeps the tiles the user asked for */
        if (c < 1.0 - 1e-9) {
            st = gdt_error_set(err, GDT_EUSAGE, 2507,
                               "--cell %.17g is %.6g lattice steps; the cloud's lattice step "
                               "is %.17g CRS units, the smallest --cell",
                               opts->cell, c, ci->lattice.sx);
            goto fail;
        }
        if (fabs(c - r) > 1e-9 * r)
            gdt_log_note(t->log, "tiler: --cell %.17g is %.17g lattice steps; using %.0f", opts->cell,
                         c, r);
        t->user_cell = (int64_t)r;
        if ((int64_t)n * t->user_cell > LOCAL_LIMIT) {
            st = gdt_error_set(err, GDT_EUSAGE, 2502,
                               "--cell %.17g: a tile of %d texels would span more than 2^31 "
                               "lattice steps",
                               opts->cell, n);
            goto fail;
        }
    }
    /* At least 4: four voxels meet at the origin, fewer cannot always be had. */
    t->density.max_voxels =
        opts->density_voxels != 0 ? opts->density_voxels : GDT_TILER_DEFAULT_DENSITY_VOXELS;
    if (t->density.max_voxels < 4)
        t->density.max_voxels = 4;
    t->plan.tile = n;
    t->plan.lattice = ci->lattice;
    t->plan.mem_budget = t->budget;
    t->stats.fd_budget = t->fd_budget;
    t->stats.mem_budget = t->budget;
    *out = t;
    return GDT_OK;
fail:
    gdt_tiler_destroy(t);
    return st;
}

void tl_free_resident(gdt_tiler *t)
{
    free(t->resident);
    free(t->res_off);
    t->resident = NULL;
    t->res_off = NULL;
}

void gdt_tiler_destroy(gdt_tiler *t)
{
    if (t == NULL)
        return;
    tl_density_free(&t->density);
    tl_map_free(&t->map);
    tl_free_resident(t);
    free(t->merge_mark);
    free(t->tiles);
    free(t->job_dir);
    free(t->tiles_dir);
    free(t);
}

/* Counts pts into the tile map (given --cell only). */
size_t tl_max_counted_tiles(const gdt_tiler *t)
{
    return t->sz.tiles_bytes / (sizeof(tl_tile) + 2 * sizeof(tl_map_entry));
}

gdt_status tl_count_tiles(gdt_tiler *t, const gdt_point *pts, size_t n, gdt_error *err)
{
    const int64_t T = (int64_t)t->opts.tile * t->user_cell;
    const size_t max_tiles = tl_max_counted_tiles(t);
    int64_t ci = 0, cj = 0;
    uint64_t run = 0;

    /* Points come in runs from one tile: count a run, then add it. */
    for (size_t k = 0; k <= n; k++) {
        int64_t i = 0, j = 0;
        if (k < n) {
            i = tl_floor_div(pts[k].x, T);
            j = tl_floor_div(pts[k].y, T);
            if (run > 0 && i == ci && j == cj) {
                run++;
                continue;
            }
        }
        if (run > 0) {
            uint64_t *v;
            gdt_status st = tl_map_upsert(&t->map, ci, cj, &v, err);
            if (st != GDT_OK)
                return st;
            *v += run;
            if (t->map.n > max_tiles)
                return gdt_error_set(err, GDT_EUSAGE, 2503,
                                     "more than %zu non-empty tiles of %" PRId64
                                     " lattice steps do not fit in the memory budget of %"
                                     PRIu64 " bytes: use a larger --cell or --mem-budget",
                                     max_tiles, T, t->budget);
        }
        ci = i;
        cj = j;
        run = 1;
    }
    return GDT_OK;
}

/* Fills the OpenVDB grids from the density histogram and the tile table
 * and saves them as <job>/index.vdb. */
static gdt_status save_index(gdt_tiler *t, gdt_error *err)
{
    gdt_vdb_meta m;
    gdt_vdb_index *ix = NULL;
    char *tmp = tl_path("%s/index.vdb.tmp", t->job_dir);
    char *fin = tl_path("%s/index.vdb", t->job_dir);
    gdt_status st = GDT_OK;
    int fd;

    if (tmp == NULL || fin == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    st = gdt_vdb_index_create(&ix, err);
    for (size_t s = 0; st == GDT_OK && s < t->density.map.cap; s++) {
        const tl_map_entry *e = &t->density.map.e[s];
        if (e->used)
            st = gdt_vdb_density_set(ix, e->i, e->j, e->v, err);
    }
    for (uint64_t k = 0; st == GDT_OK && k < t->ntiles; k++)
        st = gdt_vdb_tiles_set(ix, t->tiles[k].i - t->plan.tile_i0,
                               t->tiles[k].j - t->plan.tile_j0, t->tiles[k].count, err);
    if (st != GDT_OK)
        goto fail;
    memset(&m, 0, sizeof m);
    m.tile = t->plan.tile;
    m.cell = t->plan.cell;
    m.halo = t->plan.halo;
    m.span = t->plan.span;
    m.tile_i0 = t->plan.tile_i0;
    m.tile_j0 = t->plan.tile_j0;
    m.density_shift = t->plan.density_shift;
    m.points = (int64_t)t->plan.points;
    m.lattice = t->plan.lattice;
    m.dup = gdt_dup_policy_name(t->opts.dup);
    st = gdt_vdb_index_write(ix, &m, tmp, err);
    gdt_vdb_index_destroy(ix);
    ix = NULL;
    if (st != GDT_OK)
        goto fail;
    fd = open(tmp, O_RDONLY | O_CLOEXEC);
    if (fd < 0 || fsync(fd) != 0) {
        st = gdt_error_set(err, GDT_EIO, 4505, "cannot fsync %s: %s", tmp, strerror(errno));
        if (fd >= 0)
            close(fd);
        goto fail;
    }
    close(fd);
    if (rename(tmp, fin) != 0) {
        st = gdt_error_set(err, GDT_EIO, 4505, "cannot rename %s to %s: %s", tmp, fin,
                           strerror(errno));
        goto fail;
    }
    st = tl_sync_dir(t->job_dir, err);
fail:
    gdt_vdb_index_destroy(ix);
    if (st != GDT_OK && tmp != NULL)
        unlink(tmp);
    free(tmp);
    free(fin);
    return st;
}

/* Pass 1's reading: the bounds, counts and histograms of the points the
 * cloud gives (all of them, or the share it was set to). */
static gdt_status pass1_read(gdt_tiler *t, gdt_error *err)
{
    gdt_tile_plan *p = &t->plan;
    gdt_point *buf = NULL;
    gdt_status st;

    buf = malloc(t->sz.read_cap * sizeof *buf);
    if (buf == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    p->min_x = p->min_y = INT64_MAX;
    p->max_x = p->max_y = INT64_MIN;
    for (;;) {
        size_t n = 0;
        st = gdt_cloud_read(t->cloud, buf, t->sz.read_cap, &n, err);
        if (st != GDT_OK || n == 0)
            break;
        if (p->points == 0)
            p->min_z = p->max_z = buf[0].z;
        for (size_t k = 0; k < n; k++) {
            const gdt_point *q = &buf[k];
            if (q->x < p->min_x) p->min_x = q->x;
            if (q->x > p->max_x) p->max_x = q->x;
            if (q->y < p->min_y) p->min_y = q->y;
            if (q->y > p->max_y) p->max_y = q->y;
            if (q->z < p->min_z) p->min_z = q->z;
            if (q->z > p->max_z) p->max_z = q->z;
        }
        p->points += n;
        if (t->user_cell > 0) {
            st = tl_count_tiles(t, buf, n, err);
            if (st != GDT_OK)
                break;
        }
        st = tl_density_add(&t->density, buf, n, err);
        if (st == GDT_OK)
            st = tl_progress(t, 1, p->points, gdt_cloud_get_info(t->cloud)->point_count, err);
        if (st != GDT_OK)
            break;
    }
    free(buf);
    return st;
}

gdt_status gdt_tiler_pass1_part(gdt_tiler *t, gdt_error *err)
{
    gdt_status st;
    if (t->state != 0)
        return gdt_error_set(err, GDT_EUSAGE, 2505, "tiler pass 1 called twice");
    t->state = -1;
    t->pass1_t0 = gdt_now();
    st = pass1_read(t, err);
    if (st == GDT_OK)
        t->state = 4;
    return st;
}

gdt_status gdt_tiler_pass1_end(gdt_tiler *t, gdt_error *err)
{
    gdt_tile_plan *p = &t->plan;
    gdt_status st;

    if (t->state != 4)
        return gdt_error_set(err, GDT_EUSAGE, 2505, "tiler pass 1 ended before it was read");
    t->state = -1;
    if (p->points == 0)
        p->min_x = p->min_y = p->max_x = p->max_y = 0;
    {
        size_t nb[3];
        gdt_vdb_node_bytes(nb);
        st = tl_density_finish(&t->density, GDT_TILER_DENSITY_TREE_BYTES, nb, err);
        if (st != GDT_OK)
            return st;
    }
    st = tl_plan_finish(t, err);
    if (st != GDT_OK)
        return st;
    if (t->job_dir != NULL) {
        st = save_index(t, err);
        if (st != GDT_OK)
            return st;
    }
    tl_density_free(&t->density); /* pass 2 needs only the tile table */
    t->stats.points = p->points;
    t->stats.t_pass1 = gdt_now() - t->pass1_t0;
    gdt_log_note(t->log,
                 "tiler pass 1: %" PRIu64 " points in %.2f s, %" PRIu64 " tiles of %d texels "
                 "of %" PRId64 " steps, halo %" PRId64,
                 p->points, t->stats.t_pass1, p->tiles, p->tile, p->cell, p->halo);
    t->state = 1;
    return GDT_OK;
}

gdt_status gdt_tiler_pass1(gdt_tiler *t, gdt_error *err)
{
    gdt_status st = gdt_tiler_pass1_part(t, err);
    if (st == GDT_OK)
        st = gdt_tiler_pass1_end(t, err);
    return st;
}

const gdt_tile_plan *gdt_tiler_get_plan(const gdt_tiler *t)
{
    return tl_planned(t) ? &t->plan : NULL;
}

int gdt_tiler_pass2_done(const gdt_tiler *t)
{
    return t->state == 2;
}

uint64_t gdt_tiler_tile_count(const gdt_tiler *t)
{
    return tl_planned(t) ? t->ntiles : 0;
}

const gdt_tiler_stats *gdt_tiler_get_stats(const gdt_tiler *t)
{
    return &t->stats;
}

gdt_status gdt_tiler_tile_info(const gdt_tiler *t, uint64_t k, gdt_tile_desc *out,
                               gdt_error *err)
{
    const tl_tile *tl;
    int64_t h;
    if (!tl_planned(t) || k >= t->ntiles)
        return gdt_error_set(err, GDT_EUSAGE, 2505, "tile %" PRIu64 " does not exist", k);
    tl = &t->tiles[k];
    h = t->plan.halo * t->plan.cell;
    memset(out, 0, sizeof *out);
    out->index = k;
    out->i = tl->i;
    out->j = tl->j;
    out->x0 = tl->i * t->plan.span;
    out->y0 = tl->j * t->plan.span;
    out->local_x0 = out->x0 - h;
    out->local_y0 = out->y0 - h;
    out->local_extent = t->plan.span + 2 * h;
    out->raw_points = tl->count;
    out->points = tl->points;
    out->edge_points = tl->edge;
    return GDT_OK;
}

int gdt_tiler_tile_path(const gdt_tiler *t, uint64_t k, const char *kind, char *buf,
                        size_t len)
{
    char *p;
    int rc = -1;
    if (!tl_planned(t) || kind == NULL ||
        (strcmp(kind, "raw") != 0 && strcmp(kind, "pts") != 0 && strcmp(kind, "edge") != 0))
        return -1;
    p = tl_tile_file(t, k, kind, 0);
    if (p != NULL && strlen(p) < len) {
        memcpy(buf, p, strlen(p) + 1);
        rc = 0;
    }
    free(p);
    return rc;
}

/* Removes what an earlier (possibly interrupted) pass 2 left in tiles/. */
/* A file of a share of pass 2: "....tmp.p<digits>" (pass2_part.c). */
static int is_share_file(const char *nm)
{
    const char *p = strstr(nm, ".tmp.p");
    if (p == NULL || p[6] == '\0')
        return 0;
    for (p += 6; *p != '\0'; p++)
        if (*p < '0' || *p > '9')
            return 0;
    return 1;
}

static gdt_status prepare_tiles_dir(gdt_tiler *t, gdt_error *err)
{
    DIR *d;
    struct dirent *e;

    if (mkdir(t->tiles_dir, 0777) != 0 && errno != EEXIST)
        return gdt_error_set(err, GDT_EIO, 4501, "cannot create %s: %s", t->tiles_dir,
                             strerror(errno));
    d = opendir(t->tiles_dir);
    if (d == NULL)
        return gdt_error_set(err, GDT_EIO, 4501, "cannot open %s: %s", t->tiles_dir,
                             strerror(errno));
    while ((e = readdir(d)) != NULL) {
        const char *nm = e->d_name;
        size_t len = strlen(nm);
        int ours = strncmp(nm, "tile_", 5) == 0 || strncmp(nm, "bucket_", 7) == 0 ||
                   strncmp(nm, "merge_", 6) == 0;
        int kind = (len > 4 && strcmp(nm + len - 4, ".raw") == 0) ||
                   (len > 4 && strcmp(nm + len - 4, ".pts") == 0) ||
                   (len > 5 && strcmp(nm + len - 5, ".edge") == 0) ||
                   (len > 4 && strcmp(nm + len - 4, ".tmp") == 0) || is_share_file(nm);
        if (ours && kind && unlinkat(dirfd(d), nm, 0) != 0 && errno != ENOENT) {
            int en = errno;
            closedir(d);
            return gdt_error_set(err, GDT_EIO, 4501, "cannot remove %s/%s: %s", t->tiles_dir,
                                 nm, strerror(en));
        }
    }
    closedir(d);
    return GDT_OK;
}

/* Pass 2 up to the --dup merge: the spill and its count check; *t1 is
 * when the merge starts.  Leaves t->state -1 (in pass 2). */
static gdt_status pass2_spill(gdt_tiler *t, double *t1, gdt_error *err)
{
    double t0 = gdt_now();
    gdt_status st;

    if (t->state != 1)
        return gdt_error_set(err, GDT_EUSAGE, 2505,
                             "tiler pass 2 needs pass 1 first, and runs once");
    if (t->job_dir == NULL)
        return gdt_error_set(err, GDT_EUSAGE, 2505, "tiler pass 2 needs a job directory");
    t->state = -1;
    st = prepare_tiles_dir(t, err);
    if (st != GDT_OK)
        return st;
    st = gdt_cloud_rewind(t->cloud, err);
    if (st != GDT_OK)
        return st;
    st = tl_spill(t, err);
    if (st != GDT_OK)
        return st;
    if (t->opts.last_read)
        gdt_cloud_release_replay(t->cloud);
    for (uint64_t k = 0; k < t->ntiles; k++) {
        if (t->tiles[k].written != t->tiles[k].count)
            return gdt_error_set(err, GDT_EINPUT, 3501,
                                 "the input changed between the two passes: tile (%" PRId64
                                 ", %" PRId64 ") received %" PRIu64 " points, pass 1 counted %"
                                 PRIu64,
                                 t->tiles[k].i, t->tiles[k].j, t->tiles[k].written,
                                 t->tiles[k].count);
    }
    *t1 = gdt_now();
    t->stats.t_pass2 = *t1 - t0;
    if (t->stats.spill_in_memory)
        gdt_log_note(t->log, "tiler pass 2: %" PRIu64 " points in %.2f s (in memory)",
                     t->plan.points, t->stats.t_pass2);
    else
        gdt_log_note(t->log, "tiler pass 2: %" PRIu64 " points in %.2f s (%u bucket levels)",
                     t->plan.points, t->stats.t_pass2, t->stats.spill_levels);
    t->merge_t0 = *t1;
    return GDT_OK;
}

/* Every tile merged: the tile directory synced, the counters, state 2. */
static gdt_status pass2_done(gdt_tiler *t, gdt_error *err)
{
    gdt_status st = gdt_tiler_sync_files(t, err);
    if (st != GDT_OK)
        return st;
    t->stats.t_merge = gdt_now() - t->merge_t0;
    gdt_log_note(t->log, "tiler --dup merge: %" PRIu64 " duplicates merged in %.2f s (%" PRIu64
                         " tiles out of core)",
                 t->stats.merged_duplicates, t->stats.t_merge, t->stats.external_merges);
    t->state = 2;
    return GDT_OK;
}

gdt_status gdt_tiler_sync_files(const gdt_tiler *t, gdt_error *err)
{
    if (t->tiles_dir == NULL)
        return gdt_error_set(err, GDT_EUSAGE, 2505, "no tile directory to sync");
    return t->opts.test_nosync ? tl_sync_dir(t->tiles_dir, err)
                               : tl_sync_files(t->tiles_dir, err);
}

gdt_status gdt_tiler_pass2(gdt_tiler *t, gdt_error *err)
{
    double t1;
    gdt_status st = pass2_spill(t, &t1, err);
    if (st == GDT_OK)
        st = tl_merge_tiles(t, NULL, err);
    if (st == GDT_OK)
        st = pass2_done(t, err);
    return st;
}

gdt_status gdt_tiler_pass2_shared(gdt_tiler *t, const gdt_tiler_share *sh, gdt_error *err)
{
    double t1;
    gdt_status st = sh == NULL || sh->mine == NULL || sh->ship == NULL
                        ? gdt_error_set(err, GDT_EUSAGE, 2505, "a shared pass 2 needs its hooks")
                        : pass2_spill(t, &t1, err);
    if (st == GDT_OK)
        st = tl_merge_tiles(t, sh, err);
    if (st == GDT_OK)
        t->state = 3; /* waiting for the shipped tiles' files */
    return st;
}

uint64_t gdt_tiler_tile_of(const gdt_tiler *t, int64_t x, int64_t y)
{
    return tl_planned(t) ? tl_tile_of(t, x, y) : UINT64_MAX;
}

int gdt_tiler_pass2_in_memory(const gdt_tiler *t)
{
    return t->state == 1 && t->ntiles > 0 && tl_resident_workers(t) > 0;
}

gdt_status gdt_tiler_pass2_open(gdt_tiler *t, gdt_error *err)
{
    gdt_status st;
    if (t->state != 1 || t->job_dir == NULL)
        return gdt_error_set(err, GDT_EUSAGE, 2505,
                             "a pass 2 in shares needs the state after pass 1 and a job "
                             "directory");
    t->state = -1;
    st = prepare_tiles_dir(t, err);
    if (st != GDT_OK)
        return st;
    t->stats.spill_in_memory = 1;
    t->merge_t0 = gdt_now();
    t->state = 5;
    return GDT_OK;
}

gdt_status gdt_tiler_merge_shipped(gdt_tiler *t, uint64_t k, gdt_point *recs, uint64_t n,
                                   gdt_tiler_tile_files *out, gdt_error *err)
{
    gdt_status st;
    if ((t->state != 1 && t->state != 5) || t->job_dir == NULL || k >= t->ntiles)
        return gdt_error_set(err, GDT_EUSAGE, 2505,
                             "merging a shipped tile needs the state after pass 1 and a job "
                             "directory");
    st = tl_merge_one(t, k, recs, n, err);
    if (st != GDT_OK)
        return st;
    out->points = t->tiles[k].points;
    out->edge = t->tiles[k].edge;
    out->sum[0] = t->tiles[k].sum[0];
    out->sum[1] = t->tiles[k].sum[1];
    out->deepest = t->merge_mark[k] & TL_MARK_DEPTH;
    return GDT_OK;
}

gdt_status gdt_tiler_set_tile_files(gdt_tiler *t, uint64_t k, const gdt_tiler_tile_files *in,
                                    gdt_error *err)
{
    tl_tile *tl;
    if ((t->state != 3 && t->state != 5) || k >= t->ntiles)
        return gdt_error_set(err, GDT_EUSAGE, 2505, "tile %" PRIu64 ": no shared pass 2", k);
    tl = &t->tiles[k];
    if (tl_merge_marks(t, err) != GDT_OK)
        return GDT_EINTERNAL;
    if ((t->merge_mark[k] & TL_MARK_MERGED) || in->points == 0 || in->points > tl->count ||
        in->edge > in->points)
        return gdt_error_set(err, GDT_EINTERNAL, 7505,
                             "tile %" PRIu64 ": %" PRIu64 " points and %" PRIu64
                             " edge points reported for %" PRIu64 " records%s",
                             k, in->points, in->edge, tl->count,
                             (t->merge_mark[k] & TL_MARK_MERGED) ? ", merged already" : "");
    tl->points = in->points;
    tl->edge = in->edge;
    tl->sum[0] = in->sum[0];
    tl->sum[1] = in->sum[1];
    t->merge_mark[k] = (uint8_t)(TL_MARK_MERGED |
                                 (in->deepest < TL_MARK_DEPTH ? in->deepest : TL_MARK_DEPTH));
    return GDT_OK;
}

gdt_status gdt_tiler_pass2_finish(gdt_tiler *t, gdt_error *err)
{
    if (t->state != 3 && t->state != 5)
        return gdt_error_set(err, GDT_EUSAGE, 2505, "no shared pass 2 to finish");
    for (uint64_t k = 0; k < t->ntiles; k++)
        if (t->merge_mark == NULL || !(t->merge_mark[k] & TL_MARK_MERGED))
            return gdt_error_set(err, GDT_EUSAGE, 2505,
                                 "tile %" PRIu64 " of the shared pass 2 has no files", k);
    tl_merge_stats(t);
    return pass2_done(t, err);
}

gdt_status gdt_tiler_file_sums(const gdt_tiler *t, uint64_t k, gdt_tiler_file_sum out[2],
                               gdt_error *err)
{
    if (t->state != 2 || k >= t->ntiles)
        return gdt_error_set(err, GDT_EUSAGE, 2505,
                             "tile %" PRIu64 " has no files (pass 2 not done, or no such tile)",
                             k);
    out[0].size = t->tiles[k].points * TL_REC;
    out[0].sum = t->tiles[k].sum[0];
    out[1].size = t->tiles[k].edge * TL_REC;
    out[1].sum = t->tiles[k].sum[1];
    return GDT_OK;
}

/* Verifies the pass-2 file kind (0 .pts, 1 .edge) of tile k against its
 * record: one read.  *recs: its records, at most max (a .pts file holds at
 * least one).  returns: GDT_EJOB 6501 naming the file and what is wrong. */
static gdt_status verify_file(gdt_tiler *t, uint64_t k, int kind, const gdt_tiler_file_sum *want,
                              uint64_t max, uint64_t *recs, gdt_error *err)
{
    static const char *const ext[2] = {"pts", "edge"};
    const tl_tile *tl = &t->tiles[k];
    char *path = tl_tile_file(t, k, ext[kind], 0);
    uint64_t size = 0, sum = 0;
    gdt_error e2;
    gdt_status st;

    if (path == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    gdt_error_clear(&e2);
    if (tl_file_sum(path,
                    gdt_job_file_seed(t->opts.file_id, k,
                                      kind == 0 ? GDT_JOB_FILE_PTS : GDT_JOB_FILE_EDGE),
                    &size, &sum, &e2) != GDT_OK)
        st = gdt_error_set(err, GDT_EJOB, 6501, "%s: tile file missing or unreadable (%s)", path,
                           e2.msg);
    else if (size != want->size)
        st = gdt_error_set(err, GDT_EJOB, 6501,
                           "%s: tile file of %" PRIu64 " bytes, the job recorded %" PRIu64, path,
                           size, want->size);
    else if (sum != want->sum)
        st = gdt_error_set(err, GDT_EJOB, 6501,
                           "%s: tile file damaged or not this job's (its checksum differs from "
                           "the one recorded)",
                           path);
    else if (size % TL_REC != 0 || (kind == 0 && size == 0 && !t->opts.subsets) ||
             size / TL_REC > max)
        st = gdt_error_set(err, GDT_EJOB, 6501,
                           "%s: %" PRIu64 " bytes cannot be tile (%" PRId64 ", %" PRId64
                           ") of %" PRIu64 " points",
                           path, size, tl->i, tl->j, tl->count);
    else
        st = GDT_OK;
    *recs = size / TL_REC;
    free(path);
    return st;
}

gdt_status gdt_tiler_adopt_pass2(gdt_tiler *t, const gdt_tiler_file_sum *expect,
                                 gdt_error *err)
{
    uint64_t *points = NULL, *edges = NULL;
    gdt_status st = GDT_OK;

    if (t->state != 1 || t->job_dir == NULL || expect == NULL)
        return gdt_error_set(err, GDT_EUSAGE, 2505,
                             "adopting tile files needs pass 1, a job directory and their "
                             "records");
    /* every file is checked before any state changes: a refused adoption
     * leaves the tiler exactly after pass 1, ready for pass 2 */
    points = malloc((t->ntiles + 1) * sizeof *points);
    edges = malloc((t->ntiles + 1) * sizeof *edges);
    if (points == NULL || edges == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto done;
    }
    for (uint64_t k = 0; k < t->ntiles && st == GDT_OK; k++) {
        st = verify_file(t, k, 0, &expect[2 * k], t->tiles[k].count, &points[k], err);
        if (st == GDT_OK)
            st = verify_file(t, k, 1, &expect[2 * k + 1], points[k], &edges[k], err);
    }
    if (st != GDT_OK)
        goto done;
    for (uint64_t k = 0; k < t->ntiles; k++) {
        tl_tile *tl = &t->tiles[k];
        tl->points = points[k];
        tl->edge = edges[k];
        tl->sum[0] = expect[2 * k].sum;
        tl->sum[1] = expect[2 * k + 1].sum;
        tl->written = tl->count;
        t->stats.merged_duplicates += tl->count - tl->points;
        if (tl->points > t->stats.max_tile_points)
            t->stats.max_tile_points = tl->points;
    }
    t->state = 2;
done:
    free(points);
    free(edges);
    return st;
}

/* The state bytes: a magic with the layout's sizes (another build's bytes
 * are refused, never misread), the plan, the stats, the tile count and the
 * tile table, each as its in-memory image. */
#define TL_STATE_MAGIC UINT64_C(0x4744545354415431) /* "GDTSTAT1" */

static uint64_t state_layout(void)
{
    return ((uint64_t)sizeof(gdt_tile_plan) << 40) ^ ((uint64_t)sizeof(gdt_tiler_stats) << 20) ^
           (uint64_t)sizeof(tl_tile);
}

gdt_status gdt_tiler_export(const gdt_tiler *t, unsigned char **buf, size_t *len,
                            gdt_error *err)
{
    uint64_t head[4] = {TL_STATE_MAGIC, state_layout(), t->ntiles, (uint64_t)t->state};
    size_t n = sizeof head + sizeof t->plan + sizeof t->stats + t->ntiles * sizeof *t->tiles;
    unsigned char *p;

    *buf = NULL;
    *len = 0;
    if (t->state != 1 && t->state != 2)
        return gdt_error_set(err, GDT_EUSAGE, 2505,
                             "the tiler's state before pass 1 or inside pass 2");
    p = malloc(n);
    if (p == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    memcpy(p, head, sizeof head);
    memcpy(p + sizeof head, &t->plan, sizeof t->plan);
    memcpy(p + sizeof head + sizeof t->plan, &t->stats, sizeof t->stats);
    if (t->ntiles > 0)
        memcpy(p + sizeof head + sizeof t->plan + sizeof t->stats, t->tiles,
               t->ntiles * sizeof *t->tiles);
    *buf = p;
    *len = n;
    return GDT_OK;
}

gdt_status gdt_tiler_import(gdt_tiler *t, const unsigned char *buf, size_t len,
                            gdt_error *err)
{
    uint64_t head[4];
    size_t fixed = sizeof head + sizeof t->plan + sizeof t->stats;
    tl_tile *tiles = NULL;
    gdt_status st = GDT_OK;

    if (t->state != 0)
        return gdt_error_set(err, GDT_EUSAGE, 2505, "importing a state into a used tiler");
    if (len < fixed)
        return gdt_error_set(err, GDT_EINTERNAL, 7503, "tiler state of %zu bytes", len);
    memcpy(head, buf, sizeof head);
    if (head[0] != TL_STATE_MAGIC || head[1] != state_layout() || (head[3] != 1 && head[3] != 2) ||
        head[2] > (len - fixed) / sizeof(tl_tile) || len != fixed + head[2] * sizeof(tl_tile))
        return gdt_error_set(err, GDT_EINTERNAL, 7503,
                             "tiler state from another build of gdt-tile, or damaged");
    if (head[2] > 0) {
        tiles = malloc(head[2] * sizeof *tiles);
        if (tiles == NULL)
            return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        memcpy(tiles, buf + fixed, head[2] * sizeof *tiles);
    }
    memcpy(&t->plan, buf + sizeof head, sizeof t->plan);
    memcpy(&t->stats, buf + sizeof head + sizeof t->plan, sizeof t->stats);
    free(t->tiles);
    t->tiles = tiles;
    t->ntiles = head[2];
    tl_map_free(&t->map);
    for (uint64_t k = 0; st == GDT_OK && k < t->ntiles; k++) {
        uint64_t *v;
        st = tl_map_upsert(&t->map, t->tiles[k].i, t->tiles[k].j, &v, err);
        if (st == GDT_OK)
            *v = k;
    }
    t->state = st == GDT_OK ? (int)head[3] : -1;
    return st;
}

gdt_status gdt_tiler_plan(const gdt_tiler_opts *opts, gdt_cloud *cloud, gdt_tile_plan *out,
                          gdt_error *err)
{
    gdt_tiler *t = NULL;
    gdt_status st = gdt_tiler_create(&t, opts, cloud, err);
    if (st == GDT_OK)
        st = gdt_tiler_pass1(t, err);
    if (st == GDT_OK)
        *out = t->plan;
    gdt_tiler_destroy(t);
    return st;
}

void gdt_point_buf_free(gdt_point_buf *b)
{
    if (b == NULL)
        return;
    free(b->pts);
    memset(b, 0, sizeof *b);
}
