/* The tiled pipeline (see private/tiled_run.h). */
#define _GNU_SOURCE /* syncfs */
#include "private/tiled_run.h"

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <inttypes.h>
#include <math.h>
#include <pthread.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "gdt_certify.h"
#include "gdt_cloud.h"
#include "gdt_core.h"
#include "gdt_grow.h"
#include "gdt_mesh.h"
#include "gdt_ocl.h"
#include "gdt_mesh_out.h"
#include "gdt_ply.h"
#include "gdt_plycheck.h"
#include "gdt_seam.h"
#include "gdt_tiler.h"
#include "private/dem_report.h"
#include "private/filter_report.h"
#include "private/cli_modes.h"
#include "private/job.h"
#include "private/mesh_meta.h"
#include "private/json_out.h"
#include "private/outpaths.h"
#include "private/progress.h"
#include "private/run_stats.h"
#include "private/tiled_files.h"
#include "private/tiled_dem.h"
#include "gdt_raster.h"
#include "private/tiled_out.h"
#include "private/trim_report.h"
#include "private/tiler_io.h"

typedef struct tr_summary {
    uint64_t points_read, vertices, tiles, faces, certified, merge_faces;
    uint64_t max_tile_points, max_halo_points, gcd_tiles, insert_tiles;
    double t_pass1, t_pass2, t_tiles, t_core, t_certify, t_post, t_merge, t_write, t_check, t_total;
    gdt_cert_stats cert;
    gdt_merge_stats merge;
    int checked;
    char device[256];
    int resumed, pass2_reused;
    uint64_t tiles_reused, tiles_redone;
    gdt_trim_counts trim; /* faces before trimming and the drops (with a rule on) */
    int dem_done;
    gdt_dem_geo dem_geo;
    gdt_dem_stats dem_stats;
    double t_dem;
} tr_summary;

/* A finished tile file waiting for its journal record. */
typedef struct tr_pending {
    uint64_t k, size, checksum;
} tr_pending;

/* One triangulated tile on its way from the core to its .tri file.  The
 * main thread owns a slot until it hands it to the post stage, the post
 * stage until it is joined. */
typedef struct tr_slot {
    uint64_t k;
    gdt_tile_desc d;
    size_t n, nh;       /* own points, halo points */
    gdt_ipt *lh;        /* nh halo points, tile-local; owned */
    size_t cap_lh;
    gdt_mesh mesh;      /* the core's triangulation of the own points */
    double *z;          /* their z, by vertex; owned */
    size_t cap_z;
} tr_slot;

typedef struct tr_ctx tr_ctx;

/* The post stage of a tile (certification, seam, sorted faces, .tri file,
 * pending record) runs on its own thread while the main thread loads the
 * next tile and runs the core on it.  While it runs it alone touches cert,
 * count, fbuf, seam, seam_total, pending/npending/nsynced, t_flushed, ttile and
 * s.cert, s.certified, s.t_certify, s.t_post; the main thread reads them only
 * after post_join. */
typedef struct tr_post {
    pthread_t tid;
    int running;        /* a thread was started and not yet joined */
    tr_ctx *c;
    tr_slot *slot;
    gdt_status st;
    gdt_error err;
} tr_post;

/* What the tile stage leaves behind (the core with its device memory, the
 * slots' meshes, the post stage's arrays: about the memory of a tile),
 * released on a thread of its own while the merge and the output go on;
 * unmapping it takes a tenth of a second per GB. */
typedef struct tr_reclaim {
    pthread_t tid;
    int running;        /* a thread was started and not yet joined */
    gdt_core *core;
    gdt_mesh mesh[2];
    void *bufs[5];
} tr_reclaim;

struct tr_ctx {
    const gdt_options *opts;
    gdt_log log;
    char *job;          /* owned */
    char *tiles_dir;    /* owned */
    gdt_cloud *cloud;
    gdt_tiler *tiler;
    gdt_core *core;
    gdt_certifier *certifier;
    const gdt_tile_plan *plan;
    uint64_t *base;     /* ntiles + 1 output index of each tile's first vertex */
    gdt_point_buf halo; /* the current tile's halo */
    tr_slot slot[2];    /* tile k uses slot[k & 1] */
    tr_post post;
    tr_reclaim reclaim;
    tr_out *out;        /* the mesh writer, from the tile stage on */
    char *check_ply;    /* --check of a text output: the PLY copy in the job; owned */
    tr_dem *dem;        /* --dem: fed by the mesh writer */
    uint8_t *cert;
    size_t cap_cert;
    uint32_t *count;    /* bucket counts for the face sort */
    size_t cap_count;
    unsigned char *fbuf; /* the .tri file image */
    size_t cap_fbuf;
    gdt_seam seam;      /* one tile's seam (tile stage), one row's (merge) */
    gdt_trim_rule trim; /* --max-edge, --concavity with the lattice steps */
    gdt_trim_tile ttile; /* one tile's trim section (post stage) */
    gdt_trim_graph *tgraph; /* the run's long edges (merge), with a rule on */
    gdt_trim_open *topen; /* one tile's open edges (merge) */
    size_t ntopen, cap_topen;
    uint64_t seam_total; /* seam vertices of all tiles (merge progress) */
    gdt_job *jobdb;
    uint64_t job_id[2];   /* seeds every checksum the journal records */
    int lock_fd;          /* the job directory's lock (gdt_job_lock), or -1 */
    tr_pending *pending;  /* finished tiles not yet recorded */
    size_t npending, cap_pending;
    size_t nsynced;       /* pending[0, nsynced) are on disk, to be recorded */
    double t_flushed;
    gdt_progress prog;
    tr_summary s;
};

static int stopped(const tr_ctx *c)
{
    return c->opts->stop != NULL && *c->opts->stop != 0;
}

/* Grows an array to at least need elements (gdt_grow.h: doubling, the
 * pointer moved without a void ** cast). */
static int reserve(void *pp, size_t *cap, size_t need, size_t elem)
{
    return gdt_grow(pp, cap, need, elem, need);
}

/* reserve for a buffer of direct I/O (aligned to GDT_DIO_BLOCK); the content
 * is not kept when it grows. */
static int reserve_blocks(unsigned char **p, size_t *cap, size_t need)
{
    void *q;
    if (need <= *cap)
        return 0;
    free(*p);
    *p = NULL;
    *cap = 0;
    if (posix_memalign(&q, GDT_DIO_BLOCK, need) != 0)
        return -1;
    *p = q;
    *cap = need;
    return 0;
}

/* *created = 1 when this call made the directory. */
static gdt_status make_dir(const char *path, int *created, gdt_error *err)
{
    struct stat sb;
    *created = mkdir(path, 0777) == 0;
    if (*created)
        return GDT_OK;
    if (errno == EEXIST && stat(path, &sb) == 0 && S_ISDIR(sb.st_mode))
        return GDT_OK;
    return gdt_error_set(err, GDT_EIO, 4801, "%s: cannot create the job directory: %s", path,
                         strerror(errno));
}

/* Writes all of buf to fd (path names it in errors); GDT_EIO 4803. */
static gdt_status write_all(int fd, const unsigned char *buf, size_t len, const char *path,
                            gdt_error *err)
{
    size_t done = 0;
    while (done < len) {
        ssize_t w = write(fd, buf + done, len - done);
        if (w < 0 && errno == EINTR)
            continue;
        if (w <= 0)
            return gdt_error_set(err, GDT_EIO, 4803, "%s: write failed: %s", path,
                                 w < 0 ? strerror(errno) : "no progress");
        done += (size_t)w;
    }
    return GDT_OK;
}

/* Finishes a file written through tmp: fsync (unless nosync), close, then
 * rename to path.  *fd is closed and set to -1 whatever happens; on failure
 * the caller removes tmp. */
static gdt_status commit_tmp(int *fd, const char *tmp, const char *path, int nosync,
                             gdt_error *err)
{
    gdt_status st = GDT_OK;
    if (!nosync && fsync(*fd) != 0)
        st = gdt_error_set(err, GDT_EIO, 4804, "%s: fsync failed: %s", tmp, strerror(errno));
    if (close(*fd) != 0 && st == GDT_OK)
        st = gdt_error_set(err, GDT_EIO, 4803, "%s: write failed: %s", tmp, strerror(errno));
    *fd = -1;
    if (st == GDT_OK && rename(tmp, path) != 0)
        st = gdt_error_set(err, GDT_EIO, 4804, "%s: rename failed: %s", path, strerror(errno));
    return st;
}

/* Writes buf (aligned to GDT_DIO_BLOCK) to path through path.tmp, with
 * direct I/O where allowed (tr_write_direct), then fsync (unless nosync)
 * and rename.  On failure nothing is left at either name. */
static gdt_status write_atomic(const char *path, const unsigned char *buf, size_t len,
                               int nosync, gdt_error *err)
{
    int direct;
    size_t lp = strlen(path);
    char *tmp = malloc(lp + 5);
    int fd = -1;
    gdt_status st = GDT_OK;

    if (tmp == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    memcpy(tmp, path, lp);
    memcpy(tmp + lp, ".tmp", 5);
    fd = gdt_dio_create(tmp, 0644, &direct);
    if (fd < 0) {
        st = gdt_error_set(err, GDT_EIO, 4802, "%s: cannot create: %s", tmp, strerror(errno));
        goto fail;
    }
    st = tr_write_direct(fd, &direct, buf, len, tmp, err);
    if (st == GDT_OK)
        st = commit_tmp(&fd, tmp, path, nosync, err);
    if (st != GDT_OK)
        goto fail;
    free(tmp);
    return GDT_OK;
fail:
    if (fd >= 0)
        close(fd);
    unlink(tmp);
    free(tmp);
    return st;
}

#define SORT_AHEAD 16 /* faces between a prefetch and its use */

/* Certified faces of the current tile as output indices, each rotated to
 * start at its smallest index, in sorted order: a counting sort on the first
 * index, then insertion sort inside each (short) bucket.  The order depends
 * only on the face set, not on the order the core produced them in.
 * The mesh's triangle array is the sort's scratch: the certified faces are
 * compacted into its front, rotated (face k is written after triangle t >= k
 * is read), so the slot's triangles are consumed.  The 3 * nf sorted values
 * go to out as the tile's vertex indices in host order; faces_to_output
 * makes them the .tri file image. */
static gdt_status sort_faces(tr_ctx *c, gdt_mesh *m, size_t nf, unsigned char *out,
                             gdt_error *err)
{
    size_t nv = m->nverts, k = 0;
    uint32_t *tmp = (uint32_t *)(void *)m->tri, *sorted = (uint32_t *)(void *)out;

    if (reserve(&c->count, &c->cap_count, nv + 1, sizeof *c->count) != 0)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    memset(c->count, 0, (nv + 1) * sizeof *c->count);
    for (size_t t = 0; t < m->ntris; t++) {
        const int32_t v[3] = {m->tri[3 * t], m->tri[3 * t + 1], m->tri[3 * t + 2]};
        int r = 0;
        if (!c->cert[t])
            continue;
        if (v[1] < v[r])
            r = 1;
        if (v[2] < v[r])
            r = 2;
        tmp[3 * k + 0] = (uint32_t)v[r];
        tmp[3 * k + 1] = (uint32_t)v[(r + 1) % 3];
        tmp[3 * k + 2] = (uint32_t)v[(r + 2) % 3];
        c->count[tmp[3 * k] + 1]++;
        k++;
    }
    for (size_t i = 0; i < nv; i++)
        c->count[i + 1] += c->count[i];
    /* the scatter misses the cache twice per face (count[], then the
     * target row): prefetch the count 2 SORT_AHEAD faces ahead and the row
     * SORT_AHEAD ahead (its count may still move by a few rows) */
    for (size_t f = 0; f < nf; f++) {
        uint32_t d;
        if (f + 2 * SORT_AHEAD < nf)
            __builtin_prefetch(&c->count[tmp[3 * (f + 2 * SORT_AHEAD)]], 1);
        if (f + SORT_AHEAD < nf)
            __builtin_prefetch(&sorted[3 * (size_t)c->count[tmp[3 * (f + SORT_AHEAD)]]], 1);
        d = c->count[tmp[3 * f]]++;
        memcpy(&sorted[3 * (size_t)d], &tmp[3 * f], 3 * sizeof *tmp);
    }
    /* count[i] is now the end of bucket i; insertion sort on (b, c) */
    for (size_t i = 0, lo = 0; i < nv; lo = c->count[i], i++) {
        for (size_t a = lo + 1; a < c->count[i]; a++) {
            uint32_t f[3];
            size_t b = a;
            memcpy(f, &sorted[3 * a], sizeof f);
            while (b > lo && (sorted[3 * (b - 1) + 1] > f[1] ||
                              (sorted[3 * (b - 1) + 1] == f[1] &&
                               sorted[3 * (b - 1) + 2] > f[2]))) {
                memcpy(&sorted[3 * b], &sorted[3 * (b - 1)], sizeof f);
                b--;
            }
            memcpy(&sorted[3 * b], f, sizeof f);
        }
    }
    return GDT_OK;
}

/* The nf sorted faces at out (tile vertex indices) to output indices,
 * little-endian in place (a plain vector add on a little-endian host). */
static void faces_to_output(unsigned char *out, size_t nf, uint32_t base)
{
    uint32_t *f = (uint32_t *)(void *)out;
    for (size_t i = 0; i < 3 * nf; i++) {
        uint32_t v = f[i] + base;
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__
        v = __builtin_bswap32(v);
#endif
        f[i] = v;
    }
}

/* reserve_blocks that keeps the first keep bytes. */
static int reserve_blocks_keep(unsigned char **p, size_t *cap, size_t need, size_t keep)
{
    void *q;
    if (need <= *cap)
        return 0;
    if (posix_memalign(&q, GDT_DIO_BLOCK, need) != 0)
        return -1;
    memcpy(q, *p, keep);
    free(*p);
    *p = q;
    *cap = need;
    return 0;
}

/* The trim section of the tile whose faces (sorted, tile vertex indices)
 * are at c->fbuf + TR_HEADER: computed into c->ttile; *bytes its size in
 * the file. */
static gdt_status trim_tile(tr_ctx *c, const gdt_mesh *m, size_t nf, uint64_t base,
                            size_t *bytes, gdt_error *err)
{
    const uint32_t *f = (const uint32_t *)(const void *)(c->fbuf + TR_HEADER);
    gdt_status st;
    *bytes = 0;
    if (!gdt_trim_on(&c->trim))
        return GDT_OK;
    st = gdt_trim_tile_run(&c->ttile, &c->trim, f, nf, m->pts, base, err);
    if (st == GDT_OK)
        *bytes = TT_HEADER + 4 * c->ttile.ncut + 8 * c->ttile.ncand + 20 * c->ttile.nopen;
    return st;
}

/* Writes c->ttile as the trim section at p. */
static void put_trim(const tr_ctx *c, unsigned char *p)
{
    const gdt_trim_tile *t = &c->ttile;
    memcpy(p, TT_MAGIC, 8);
    tr_put_u64(p + 8, t->ncut);
    tr_put_u64(p + 16, t->ncand);
    tr_put_u64(p + 24, t->nopen);
    p += TT_HEADER;
    for (size_t i = 0; i < t->ncut; i++, p += 4)
        tr_put_u32(p, t->cut[i]);
    for (size_t i = 0; i < 2 * t->ncand; i++, p += 4)
        tr_put_u32(p, t->cand[i]);
    for (size_t i = 0; i < t->nopen; i++, p += 20) {
        tr_put_u64(p, t->open[i].a);
        tr_put_u64(p + 8, t->open[i].b);
        tr_put_u32(p + 16, t->open[i].label);
    }
}

/* --threads K, 0 = the online cores. */
static int host_threads(int k) { return gdt_cli_threads(k); }

/* The first half of tile k, on the main thread: loads it and runs the core
 * on its own points into sl (the halo goes beside it). */
static gdt_status core_tile(tr_ctx *c, uint64_t k, tr_slot *sl, gdt_error *err)
{
    gdt_tile_desc *d = &sl->d;
    gdt_core_stats cs;
    size_t n, nh;
    double t0;
    gdt_status st;

    sl->k = k;
    st = gdt_tiler_tile_info(c->tiler, k, d, err);
    if (st != GDT_OK)
        return st;
    /* the own points go straight into the slot's mesh, which the core
     * leaves them in (kept from tile to tile: fresh pages cost more than
     * the memory) */
    st = gdt_mesh_reserve(&sl->mesh, (size_t)d->points + 1, 0, 0, err);
    if (st == GDT_OK && reserve(&sl->z, &sl->cap_z, (size_t)d->points + 1, sizeof *sl->z) != 0)
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    if (st == GDT_OK)
        st = gdt_tiler_load_tile_local(c->tiler, k, d->local_x0, d->local_y0, sl->mesh.pts,
                                       sl->z, &n, &c->halo, err);
    if (st != GDT_OK)
        return st;
    sl->n = n;
    nh = sl->nh = c->halo.n;
    if (n > c->s.max_tile_points)
        c->s.max_tile_points = n;
    if (nh > c->s.max_halo_points)
        c->s.max_halo_points = nh;
    if (reserve(&sl->lh, &sl->cap_lh, nh + 1, sizeof *sl->lh) != 0)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    for (size_t i = 0; i < nh; i++) {
        sl->lh[i].x = c->halo.pts[i].x - d->local_x0;
        sl->lh[i].y = c->halo.pts[i].y - d->local_y0;
    }

    t0 = gdt_now();
    memset(&cs, 0, sizeof cs);
    st = gdt_core_triangulate(c->core, sl->mesh.pts, n, c->opts->tile, &sl->mesh, &cs, err);
    if (st != GDT_OK)
        return st;
    if (strcmp(cs.path, "insert") == 0)
        c->s.insert_tiles++;
    else
        c->s.gcd_tiles++;
    c->s.t_core += gdt_now() - t0;
    return GDT_OK;
}

/* Makes every pending tile file durable: one syncfs of the job's file
 * system (tiles come in batches), then the directory; pending[0, npending)
 * are then synced.  Run by the post stage, or where none runs. */
static gdt_status sync_tiles(tr_ctx *c, gdt_error *err)
{
    int fd = open(c->tiles_dir, O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    gdt_status st;
    if (fd < 0 || syncfs(fd) != 0) {
        st = gdt_error_set(err, GDT_EIO, 4804, "%s: cannot sync the tile files: %s",
                           c->tiles_dir, strerror(errno));
        if (fd >= 0)
            close(fd);
        return st;
    }
    close(fd);
    st = tl_sync_dir(c->tiles_dir, err);
    if (st == GDT_OK)
        c->nsynced = c->npending;
    c->t_flushed = gdt_now();
    return st;
}

/* The second half of a tile (the post stage): certification, seam, the
 * .tri file and its pending record.  The slot's triangle array is the face
 * sort's scratch: the slot holds no mesh afterwards (the next core run
 * into it refills it). */
static gdt_status post_tile_run(tr_ctx *c, tr_slot *sl, gdt_error *err)
{
    const gdt_tile_plan *pl = c->plan;
    const gdt_tile_desc *d = &sl->d;
    const gdt_mesh *m = &sl->mesh;
    uint64_t k = sl->k;
    gdt_cert_region r;
    size_t nf, len, tbytes = 0;
    int64_t h = pl->halo * pl->cell;
    char *path = NULL;
    unsigned char *p;
    double t0 = gdt_now();
    gdt_status st;

    r.own[0] = h;
    r.own[1] = h;
    r.own[2] = h + pl->span - 1;
    r.own[3] = h + pl->span - 1;
    r.known[0] = 0;
    r.known[1] = 0;
    r.known[2] = d->local_extent - 1;
    r.known[3] = d->local_extent - 1;
    r.open[GDT_SIDE_WEST] = d->local_x0 <= pl->min_x;
    r.open[GDT_SIDE_SOUTH] = d->local_y0 <= pl->min_y;
    r.open[GDT_SIDE_EAST] = d->local_x0 + d->local_extent - 1 >= pl->max_x;
    r.open[GDT_SIDE_NORTH] = d->local_y0 + d->local_extent - 1 >= pl->max_y;
    if (reserve(&c->cert, &c->cap_cert, m->ntris + 1, 1) != 0)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    st = gdt_certify_tile(c->certifier, m, sl->lh, sl->nh, &r, c->cert, &c->s.cert, err);
    c->s.t_certify += gdt_now() - t0;
    if (st != GDT_OK)
        return st;
    nf = 0;
    for (size_t t = 0; t < m->ntris; t++)
        nf += c->cert[t];
    c->seam.nv = 0;
    c->seam.ne = 0;
    st = gdt_seam_extract(&c->seam, m, c->cert, sl->z, c->base[k], d->local_x0 - pl->min_x,
                          d->local_y0 - pl->min_y, err);
    if (st != GDT_OK)
        return st;
    c->seam_total += c->seam.nv;
    len = TR_HEADER + 12 * nf + TR_SEAM_VERTEX * c->seam.nv + 16 * c->seam.ne;
    if (reserve_blocks(&c->fbuf, &c->cap_fbuf, len) != 0)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    /* the sorted faces go straight into the file image (64-byte aligned
     * offset); the slot's triangles are not needed after this */
    st = sort_faces(c, &sl->mesh, nf, c->fbuf + TR_HEADER, err);
    if (st == GDT_OK)
        st = trim_tile(c, m, nf, c->base[k], &tbytes, err);
    if (st != GDT_OK)
        return st;
    faces_to_output(c->fbuf + TR_HEADER, nf, (uint32_t)c->base[k]);
    if (reserve_blocks_keep(&c->fbuf, &c->cap_fbuf, len + tbytes, TR_HEADER + 12 * nf) != 0)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    c->s.certified += nf;

    p = c->fbuf;
    memset(p, 0, TR_HEADER);
    memcpy(p, TR_MAGIC, 8);
    tr_put_u64(p + 8, c->base[k]);
    tr_put_u64(p + 16, sl->n);
    tr_put_u64(p + 24, nf);
    tr_put_u64(p + 32, c->seam.nv);
    tr_put_u64(p + 40, c->seam.ne);
    tr_put_u64(p + 48, c->job_id[0]);
    tr_put_u64(p + 56, c->job_id[1]);
    p += TR_HEADER + 12 * nf;
    for (size_t i = 0; i < c->seam.nv; i++, p += TR_SEAM_VERTEX) {
        uint64_t zb;
        memcpy(&zb, &c->seam.v[i].z, sizeof zb);
        tr_put_u64(p, c->seam.v[i].id);
        tr_put_u64(p + 8, (uint64_t)c->seam.v[i].x);
        tr_put_u64(p + 16, (uint64_t)c->seam.v[i].y);
        tr_put_u64(p + 24, zb);
    }
    for (size_t i = 0; i < c->seam.ne; i++, p += 16) {
        tr_put_u64(p, c->seam.e[i].a);
        tr_put_u64(p + 8, c->seam.e[i].b);
    }
    if (tbytes > 0)
        put_trim(c, p);
    len += tbytes;
    st = tr_tile_path(c->tiles_dir, d, "tri", &path, err);
    /* durability comes in batches: see sync_tiles */
    if (st == GDT_OK)
        st = write_atomic(path, c->fbuf, len, 1, err);
    free(path);
    if (st != GDT_OK)
        return st;
    if (reserve(&c->pending, &c->cap_pending, c->npending + 1 + 64,
                sizeof *c->pending) != 0)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    c->pending[c->npending].k = k;
    c->pending[c->npending].size = len;
    c->pending[c->npending].checksum =
        gdt_hash64_wide(c->fbuf, len, gdt_job_file_seed(c->job_id, k, GDT_JOB_FILE_TRI));
    c->npending++;
    /* the wait for the disk is taken here, beside the next tile's core,
     * not on the thread that drives the core */
    if (c->npending - c->nsynced >= 256 || gdt_now() - c->t_flushed > 1.0)
        return sync_tiles(c, err);
    return GDT_OK;
}

/* post_tile_run, timed (s.t_post: the whole post stage, of which
 * s.t_certify is the certification). */
static gdt_status post_tile(tr_ctx *c, tr_slot *sl, gdt_error *err)
{
    double t0 = gdt_now();
    gdt_status st = post_tile_run(c, sl, err);
    c->s.t_post += gdt_now() - t0;
    return st;
}

static void *reclaim_main(void *arg)
{
    tr_reclaim *r = arg;
    gdt_core_destroy(r->core);
    for (int i = 0; i < 2; i++)
        gdt_mesh_free(&r->mesh[i]);
    for (int i = 0; i < 5; i++)
        free(r->bufs[i]);
    return NULL;
}

/* Hands the tile stage's memory to the reclaim thread (or frees it here if
 * none can be started). */
static void reclaim_start(tr_ctx *c)
{
    tr_reclaim *r = &c->reclaim;
    r->core = c->core;
    c->core = NULL;
    for (int i = 0; i < 2; i++) {
        r->mesh[i] = c->slot[i].mesh;
        gdt_mesh_init(&c->slot[i].mesh);
    }
    r->bufs[0] = c->fbuf;
    r->bufs[1] = c->count;
    r->bufs[2] = c->cert;
    r->bufs[3] = c->slot[0].z;
    r->bufs[4] = c->slot[1].z;
    c->slot[0].z = c->slot[1].z = NULL;
    c->slot[0].cap_z = c->slot[1].cap_z = 0;
    c->fbuf = NULL;
    c->count = NULL;
    c->cert = NULL;
    c->cap_fbuf = c->cap_count = c->cap_cert = 0;
    r->running = pthread_create(&r->tid, NULL, reclaim_main, r) == 0;
    if (!r->running)
        reclaim_main(r);
}

static void reclaim_join(tr_ctx *c)
{
    if (c->reclaim.running)
        pthread_join(c->reclaim.tid, NULL);
    c->reclaim.running = 0;
}

static void *post_main(void *arg)
{
    tr_post *q = arg;
    q->st = post_tile(q->c, q->slot, &q->err);
    return NULL;
}

/* Waits for the post stage (if one runs) and returns its status; its error,
 * if any, is copied to *err. */
static gdt_status post_join(tr_ctx *c, gdt_error *err)
{
    tr_post *q = &c->post;
    if (!q->running)
        return GDT_OK;
    pthread_join(q->tid, NULL);
    q->running = 0;
    if (q->st != GDT_OK)
        *err = q->err;
    return q->st;
}

/* Starts the post stage of sl; the caller has joined the previous one.  If
 * no thread can be started it runs here. */
static gdt_status post_start(tr_ctx *c, tr_slot *sl, gdt_error *err)
{
    tr_post *q = &c->post;
    q->c = c;
    q->slot = sl;
    q->st = GDT_OK;
    gdt_error_clear(&q->err);
    if (pthread_create(&q->tid, NULL, post_main, q) != 0)
        return post_tile(c, sl, err);
    q->running = 1;
    return GDT_OK;
}

/* Record the synced tiles (pending[0, nsynced)) in one transaction and
 * drop them from pending.  Only where no post stage runs. */
static gdt_status record_synced(tr_ctx *c, gdt_error *err)
{
    gdt_status st = GDT_OK;
    size_t n = c->nsynced;
    if (n == 0)
        return GDT_OK;
    st = gdt_job_begin(c->jobdb, err);
    for (size_t i = 0; st == GDT_OK && i < n; i++) {
        gdt_tile_desc d;
        char *path = NULL;
        st = gdt_tiler_tile_info(c->tiler, c->pending[i].k, &d, err);
        if (st == GDT_OK)
            st = tr_tile_path(c->tiles_dir, &d, "tri", &path, err);
        if (st == GDT_OK)
            st = gdt_job_put_tile(c->jobdb, c->pending[i].k, path, c->pending[i].size,
                                  c->pending[i].checksum, err);
        free(path);
    }
    if (st == GDT_OK)
        st = gdt_job_commit(c->jobdb, err);
    memmove(c->pending, c->pending + n, (c->npending - n) * sizeof *c->pending);
    c->npending -= n;
    c->nsynced = 0;
    return st;
}

/* Makes the finished tile files durable and records them: until then a
 * crash only costs redoing them.  Only where no post stage runs. */
static gdt_status flush_pending(tr_ctx *c, gdt_error *err)
{
    gdt_status st = c->npending > c->nsynced ? sync_tiles(c, err) : GDT_OK;
    if (st == GDT_OK)
        st = record_synced(c, err);
    return st;
}

/* A tile recorded as finished: its .tri file is reused when its size and
 * checksum match the record (the merge reads its seam from there, as for a
 * tile computed now).  *ok = 0: the file is missing, damaged or another
 * job's; a warning names it and the reason, and the tile is redone. */
static gdt_status reuse_tile(tr_ctx *c, uint64_t k, uint64_t size, uint64_t sum, int *ok,
                             gdt_error *err)
{
    gdt_tile_desc d;
    char *path = NULL;
    FILE *f = NULL;
    const char *why = NULL;
    uint64_t nf, nv, ne;
    gdt_status st = gdt_tiler_tile_info(c->tiler, k, &d, err);

    *ok = 0;
    if (st == GDT_OK)
        st = tr_tile_path(c->tiles_dir, &d, "tri", &path, err);
    if (st != GDT_OK)
        return st;
    if (size >= TR_HEADER && size <= SIZE_MAX &&
        reserve_blocks(&c->fbuf, &c->cap_fbuf, (size_t)size) != 0) {
        free(path);
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    }
    if (size < TR_HEADER || size > SIZE_MAX)
        why = "its record is impossible";
    else if ((f = fopen(path, "rb")) == NULL)
        why = strerror(errno);
    else if (fread(c->fbuf, 1, (size_t)size, f) != size || fgetc(f) != EOF)
        why = "its size differs from the one recorded";
    else if (gdt_hash64_wide(c->fbuf, (size_t)size,
                             gdt_job_file_seed(c->job_id, k, GDT_JOB_FILE_TRI)) != sum)
        why = "damaged or not this job's (its checksum differs from the one recorded)";
    if (f != NULL)
        fclose(f);
    if (why == NULL) {
        tr_tri_expect ex = {c->base[k], d.points, c->job_id, gdt_trim_on(&c->trim)};
        tr_tri_verdict v = tr_tri_check_header(c->fbuf, size, &ex, &nf, &nv, &ne);
        tr_trim_counts tc;
        if (v == TR_TRI_FOREIGN || v == TR_TRI_SIZE)
            why = "its header does not fit the tile";
        else if (v == TR_TRI_JOB)
            why = "its header names another job";
        else if (ex.trim &&
                 tr_trim_check(c->fbuf + TR_HEADER + 12 * nf + TR_SEAM_VERTEX * nv + 16 * ne,
                               TR_HEADER + 12 * nf + TR_SEAM_VERTEX * nv + 16 * ne, size, nf,
                               &tc) != 0)
            why = "its trim section does not fit the file";
    }
    if (why != NULL) {
        gdt_log_warn(&c->log, 6803, "%s: redoing the tile: %s", path, why);
        free(path);
        return GDT_OK;
    }
    free(path);
    c->seam_total += nv;
    c->s.certified += nf;
    *ok = 1;
    return GDT_OK;
}

/* Appends the seam section of tile k's .tri file (seam vertices and barrier
 * edges) to c->seam, through tr_tri_read_seam: the counts of the header are
 * checked against the file's size before anything is allocated, every id
 * against the tile's vertex range and every coordinate against the merge
 * frame.
 * returns: GDT_EIO 4805 (open or read), GDT_EJOB 6801 (not the file this
 * run wrote), 6802 (its size or content does not match its header), 7001. */
static gdt_status read_seam(tr_ctx *c, uint64_t k, gdt_error *err)
{
    gdt_tile_desc d;
    char *path = NULL;
    FILE *f = NULL;
    uint64_t size = 0;
    gdt_status st = gdt_tiler_tile_info(c->tiler, k, &d, err);

    if (st == GDT_OK)
        st = tr_open_tri(c->tiles_dir, &d, &f, &size, &path, err);
    if (st == GDT_OK && reserve(&c->fbuf, &c->cap_fbuf, TR_SEAM_VERTEX * (size_t)TR_CHUNK, 1) != 0)
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    if (st == GDT_OK) {
        tr_tri_expect ex = {c->base[k], d.points, c->job_id, c->tgraph != NULL};
        st = tr_tri_read_seam(f, size, &ex, &c->seam, c->fbuf, path, err);
        /* the tile's open edges meet the merge faces in the trim graph */
        if (st == GDT_OK && ex.trim)
            st = tr_tri_read_open(f, size, &ex, &c->topen, &c->ntopen, &c->cap_topen, c->fbuf,
                                  path, err);
        if (st == GDT_OK && ex.trim)
            st = gdt_trim_graph_add_tile(c->tgraph, k, c->topen, c->ntopen, err);
    }
    if (f != NULL)
        fclose(f);
    free(path);
    return st;
}

/* Stage 3: the seam merge by rows of tiles (gdt_seam.h).  Each row's seam
 * is read from its tiles' .tri files; each round's final faces are appended
 * to <job>/merge.faces ("GDTMRG01", u64 face count, then 3 x u32 output
 * indices per face, little-endian), written under merge.faces.tmp, fsync'd
 * and renamed.  Holds one row of seams, the merger's band and a write
 * buffer. */
/* With --dem: the round's nf faces' vertices (global lattice, z) appended
 * to merge.dem (dbuf holds *ndbuf bytes of MD_RECORD TR_CHUNK). */
static gdt_status put_merge_dem(tr_ctx *c, int fd, const char *tmp, const gdt_merger *m,
                                size_t nf, unsigned char *dbuf, size_t *ndbuf, gdt_error *err)
{
    const gdt_ipt *p = gdt_merger_face_points(m);
    const double *z = gdt_merger_face_z(m);
    for (size_t i = 0; i < 3 * nf; i++) {
        uint64_t zb;
        unsigned char *r;
        if (i % 3 == 0 && *ndbuf + MD_RECORD > MD_RECORD * (size_t)TR_CHUNK) {
            gdt_status st = write_all(fd, dbuf, *ndbuf, tmp, err);
            if (st != GDT_OK)
                return st;
            *ndbuf = 0;
        }
        r = dbuf + *ndbuf;
        memcpy(&zb, &z[i], sizeof zb);
        tr_put_u64(r, (uint64_t)(p[i].x + c->plan->min_x));
        tr_put_u64(r + 8, (uint64_t)(p[i].y + c->plan->min_y));
        tr_put_u64(r + 16, zb);
        *ndbuf += 24;
    }
    return GDT_OK;
}

static gdt_status merge_rows(tr_ctx *c, gdt_error *err)
{
    const gdt_tile_plan *pl = c->plan;
    uint64_t ntiles = gdt_tiler_tile_count(c->tiler), k = 0, nmf = 0, done_v = 0;
    gdt_merger *m = NULL;
    char *path = tr_path_join(c->job, MF_NAME), *tmp = tr_path_join(c->job, MF_NAME ".tmp");
    char *dpath = NULL, *dtmp = NULL;
    unsigned char *buf = malloc(12 * (size_t)TR_CHUNK), *dbuf = NULL;
    size_t nbuf = 0, ndbuf = 0;
    int fd = -1, dfd = -1;
    gdt_status st = GDT_OK;

    if (path == NULL || tmp == NULL || buf == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    /* with --dem the faces' vertices go beside them to merge.dem */
    if (c->dem != NULL) {
        dpath = tr_path_join(c->job, MD_NAME);
        dtmp = tr_path_join(c->job, MD_NAME ".tmp");
        dbuf = malloc(MD_RECORD * (size_t)TR_CHUNK);
        if (dpath == NULL || dtmp == NULL || dbuf == NULL) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
            goto fail;
        }
        dfd = open(dtmp, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
        if (dfd < 0) {
            st = gdt_error_set(err, GDT_EIO, 4802, "%s: cannot create: %s", dtmp,
                               strerror(errno));
            goto fail;
        }
        memset(dbuf, 0, MF_HEADER);
        memcpy(dbuf, MD_MAGIC, 8);
        ndbuf = MF_HEADER;
    }
    /* the merge frame is lattice minus the plan's minimum, so the cloud's x
     * range is [0, max_x - min_x]; read_seam refuses any seam vertex beyond
     * GDT_COORD_MAX, so clamping there keeps every vertex in the range */
    st = gdt_merger_create(
        &m, 0, pl->max_x - pl->min_x < GDT_COORD_MAX ? pl->max_x - pl->min_x : GDT_COORD_MAX, err);
    if (st != GDT_OK)
        goto fail;
    fd = open(tmp, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (fd < 0) {
        st = gdt_error_set(err, GDT_EIO, 4802, "%s: cannot create: %s", tmp, strerror(errno));
        goto fail;
    }
    memset(buf, 0, MF_HEADER);
    memcpy(buf, MF_MAGIC, 8);
    nbuf = MF_HEADER;
    gdt_progress_stage(&c->prog, "merge", c->seam_total, "points");
    while (k < ntiles) {
        gdt_tile_desc d;
        const uint64_t *f = NULL;
        size_t nf = 0;
        int64_t row, y_next = 0;
        uint64_t k1 = k;
        if (stopped(c)) {
            st = tr_interrupted(c->job, "the seam merge", err);
            goto fail;
        }
        st = gdt_tiler_tile_info(c->tiler, k, &d, err);
        if (st != GDT_OK)
            goto fail;
        row = d.j;
        c->seam.nv = 0;
        c->seam.ne = 0;
        /* tiles are sorted by (j, i): a row is a run of equal j */
        while (k1 < ntiles) {
            st = gdt_tiler_tile_info(c->tiler, k1, &d, err);
            if (st != GDT_OK)
                goto fail;
            if (d.j != row) {
                y_next = d.y0 - pl->min_y;
                break;
            }
            st = read_seam(c, k1, err);
            if (st != GDT_OK)
                goto fail;
            k1++;
        }
        st = gdt_merger_round(m, &c->seam, y_next, k1 == ntiles, &f, &nf, err);
        if (st == GDT_OK && c->tgraph != NULL)
            st = gdt_trim_graph_add_faces(c->tgraph, f, gdt_merger_face_points(m), nf, err);
        if (st == GDT_OK && dfd >= 0)
            st = put_merge_dem(c, dfd, dtmp, m, nf, dbuf, &ndbuf, err);
        if (st != GDT_OK)
            goto fail;
        for (size_t i = 0; i < nf; i++) {
            if (nbuf + 12 > 12 * (size_t)TR_CHUNK) {
                st = write_all(fd, buf, nbuf, tmp, err);
                if (st != GDT_OK)
                    goto fail;
                nbuf = 0;
            }
            for (int q = 0; q < 3; q++)
                tr_put_u32(buf + nbuf + 4 * q, (uint32_t)f[3 * i + q]);
            nbuf += 12;
        }
        nmf += nf;
        done_v += c->seam.nv;
        gdt_progress_update(&c->prog, done_v);
        k = k1;
    }
    st = write_all(fd, buf, nbuf, tmp, err);
    if (st != GDT_OK)
        goto fail;
    tr_put_u64(buf, nmf);
    if (pwrite(fd, buf, 8, 8) != 8) {
        st = gdt_error_set(err, GDT_EIO, 4803, "%s: write failed: %s", tmp, strerror(errno));
        goto fail;
    }
    st = commit_tmp(&fd, tmp, path, 0, err);
    if (st != GDT_OK)
        goto fail;
    if (dfd >= 0) {
        /* rebuilt by every run: no sync of its own */
        st = write_all(dfd, dbuf, ndbuf, dtmp, err);
        if (st != GDT_OK)
            goto fail;
        tr_put_u64(dbuf, nmf);
        if (pwrite(dfd, dbuf, 8, 8) != 8) {
            st = gdt_error_set(err, GDT_EIO, 4803, "%s: write failed: %s", dtmp,
                               strerror(errno));
            goto fail;
        }
        st = commit_tmp(&dfd, dtmp, dpath, 1, err);
        if (st != GDT_OK)
            goto fail;
    }
    st = tl_sync_dir(c->job, err);
    if (st == GDT_OK && c->tgraph != NULL)
        st = gdt_trim_graph_resolve(c->tgraph, err);
    c->s.merge = *gdt_merger_stats(m);
    c->s.merge_faces = nmf;
fail:
    if (fd >= 0)
        close(fd);
    if (dfd >= 0)
        close(dfd);
    if (st != GDT_OK && tmp != NULL)
        unlink(tmp);
    if (st != GDT_OK && dtmp != NULL)
        unlink(dtmp);
    gdt_merger_destroy(m);
    free(buf);
    free(dbuf);
    free(tmp);
    free(path);
    free(dtmp);
    free(dpath);
    return st;
}

/* --check: the exact streaming validator on the written mesh (bounded
 * memory, temporary files in the job directory).  A PLY output is read
 * back itself; an OBJ or LandXML output through the PLY copy of the same
 * records that the writer thread wrote beside it (every number of the text
 * was verified to read back as the same double when written).  A mesh
 * that fails is renamed to OUT.rejected, so no invalid file stays at the
 * output path. */
static gdt_status check_output(tr_ctx *c, gdt_error *err)
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
                           "%s: holds %" PRIu64 " vertices and %" PRIu64 " faces, the run made %"
                           PRIu64 " and %" PRIu64,
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

static gdt_status write_summary(const tr_ctx *c, gdt_error *err)
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
    gdt_json_string(&j, "output_format",
                    gdt_mesh_format_name(gdt_mesh_format_of(c->opts->output)));
    gdt_json_string(&j, "device", s->device);
    if (s->dem_done)
        gdt_dem_report_json(&j, c->opts, &s->dem_geo, &s->dem_stats, s->t_dem);
    gdt_json_uint(&j, "points_read", s->points_read);
    gdt_filter_report_json(&j, c->cloud);
    gdt_json_uint(&j, "vertices", s->vertices);
    gdt_json_uint(&j, "faces", s->faces - s->trim.dropped);
    gdt_trim_report_json(&j, &c->opts->trim, &s->trim);
    gdt_json_uint(&j, "tiles", s->tiles);
    gdt_json_uint(&j, "tile", (uint64_t)pl->tile);
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
    gdt_json_double(&j, "tiles", s->t_tiles);
    gdt_json_double(&j, "core", s->t_core);
    gdt_json_double(&j, "certify", s->t_certify);
    gdt_json_double(&j, "post", s->t_post);
    gdt_json_double(&j, "merge", s->t_merge);
    gdt_json_double(&j, "write", s->t_write);
    if (s->checked)
        gdt_json_double(&j, "check", s->t_check);
    gdt_json_double(&j, "total", s->t_total);
    gdt_json_end_object(&j);
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

static char *default_job(const char *output)
{
    size_t l = strlen(output);
    char *p = malloc(l + 9);
    if (p != NULL) {
        memcpy(p, output, l);
        memcpy(p + l, ".gdt-job", 9);
    }
    return p;
}

/* A growing text buffer. */
typedef struct tr_text {
    char *s;
    size_t len, cap;
    int failed;
} tr_text;

static void text_add(tr_text *t, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void text_add(tr_text *t, const char *fmt, ...)
{
    va_list ap;
    int n;
    if (t->failed)
        return;
    va_start(ap, fmt);
    n = vsnprintf(NULL, 0, fmt, ap);
    va_end(ap);
    if (n < 0 || reserve(&t->s, &t->cap, t->len + (size_t)n + 1 + 256, 1) != 0) {
        t->failed = 1;
        return;
    }
    va_start(ap, fmt);
    vsnprintf(t->s + t->len, t->cap - t->len, fmt, ap);
    va_end(ap);
    t->len += (size_t)n;
}

/* Absolute form of a path (the current directory prefixed to a relative
 * one), so that a job keeps meaning the same files from any directory. */
static void text_abs(tr_text *t, const char *key, const char *path)
{
    char cwd[4096];
    if (path[0] == '/' || getcwd(cwd, sizeof cwd) == NULL)
        text_add(t, "%s=%s\n", key, path);
    else
        text_add(t, "%s=%s/%s\n", key, cwd, path);
}

/* The options and inputs that fix the output, one "key=value" per line
 * (not the output path: finished work serves any -o). */
static gdt_status build_params(const gdt_options *o, char **out, gdt_error *err)
{
    tr_text t = {NULL, 0, 0, 0};
    char filter[GDT_FILTER_COMMENT_MAX];
    text_add(&t, "tile=%d\ncell=%.17g\nhalo=%ld\ndup=%d\nquantum=%.17g\n", o->tile, o->cell,
             o->halo, (int)o->dup, o->quantum);
    gdt_filter_describe(&o->filter, filter, sizeof filter);
    text_add(&t, "filter=%s\n", filter);
    if (gdt_trim_on(&o->trim))
        text_add(&t, "trim=%.17g %.17g\n", o->trim.max_edge, o->trim.concavity);
    text_add(&t, "inputs=%zu\n", o->ninputs);
    for (size_t i = 0; i < o->ninputs; i++) {
        if (strchr(o->inputs[i], '\n') != NULL) {
            free(t.s);
            return gdt_error_set(err, GDT_EUSAGE, 2106, "input path with a line break: %s",
                                 o->inputs[i]);
        }
        text_abs(&t, "input", o->inputs[i]);
    }
    if (t.failed) {
        free(t.s);
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    }
    *out = t.s;
    return GDT_OK;
}

/* Per input: size, modification time and a hash of its first and last
 * 64 KiB (the header and the tail of the records). */
static gdt_status build_fingerprint(const gdt_options *o, char **out, gdt_error *err)
{
    enum { PART = 65536 };
    tr_text t = {NULL, 0, 0, 0};
    unsigned char *buf = malloc(PART);
    gdt_status st = GDT_OK;

    if (buf == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    for (size_t i = 0; i < o->ninputs && st == GDT_OK; i++) {
        struct stat sb;
        uint64_t h1 = 0, h2 = 0;
        FILE *f = fopen(o->inputs[i], "rb");
        if (f == NULL || fstat(fileno(f), &sb) != 0) {
            st = gdt_error_set(err, GDT_EINPUT, 3802, "%s: cannot read: %s", o->inputs[i],
                               strerror(errno));
        } else {
            size_t n = fread(buf, 1, PART, f);
            h1 = gdt_hash64(buf, n, 1);
            if (sb.st_size > PART && fseeko(f, sb.st_size - PART, SEEK_SET) == 0) {
                n = fread(buf, 1, PART, f);
                h2 = gdt_hash64(buf, n, 2);
            }
            text_add(&t, "input %zu: size %lld, mtime %lld.%09ld, hash %016llx %016llx\n", i,
                     (long long)sb.st_size, (long long)sb.st_mtim.tv_sec,
                     (long)sb.st_mtim.tv_nsec, (unsigned long long)h1,
                     (unsigned long long)h2);
        }
        if (f != NULL)
            fclose(f);
    }
    free(buf);
    if (st == GDT_OK && t.failed)
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    if (st != GDT_OK) {
        free(t.s);
        return st;
    }
    *out = t.s != NULL ? t.s : strdup("");
    return *out != NULL ? GDT_OK : gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
}

/* The first line where a and b differ, as "was X, now Y". */
static void first_difference(const char *a, const char *b, char *msg, size_t len)
{
    while (*a != '\0' || *b != '\0') {
        size_t la = strcspn(a, "\n"), lb = strcspn(b, "\n");
        if (la != lb || memcmp(a, b, la) != 0) {
            snprintf(msg, len, "was '%.*s', now '%.*s'", (int)(la < 200 ? la : 200), a,
                     (int)(lb < 200 ? lb : 200), b);
            return;
        }
        a += la + (a[la] == '\n');
        b += lb + (b[lb] == '\n');
    }
    snprintf(msg, len, "no difference");
}

/* Removes the files a job directory holds (job.db and its WAL files,
 * index.vdb, merge.faces, tiles/ with our tile files) and tiles/ if empty.
 * With final (the end of the run that holds the lock), the lock file goes
 * last, then the job directory itself if it is empty and own_dir (a run of
 * this job created it, gdt_job_lock); otherwise (--restart) the lock file
 * and the directory stay.
 * Never removes anything else: --job may name a directory the user owns. */
static void remove_job_files(const char *job, int final, int own_dir)
{
    static const char *const names[] = {"job.db", "job.db-wal", "job.db-shm", "job.db-journal",
                                        "index.vdb", "index.vdb.tmp", MF_NAME,
                                        MF_NAME ".tmp", MD_NAME, MD_NAME ".tmp",
                                        CHECK_PLY_NAME};
    char *tiles = tr_path_join(job, "tiles");
    /* the journal first: a removal cut short by a crash must not leave a
     * journal that vouches for files already gone */
    for (size_t i = 0; i < sizeof names / sizeof names[0]; i++) {
        char *p = tr_path_join(job, names[i]);
        if (p != NULL)
            unlink(p);
        free(p);
    }
    if (tiles != NULL) {
        DIR *d = opendir(tiles);
        struct dirent *e;
        if (d != NULL) {
            while ((e = readdir(d)) != NULL)
                if (strncmp(e->d_name, "tile_", 5) == 0 ||
                    strncmp(e->d_name, "bucket_", 7) == 0 ||
                    strncmp(e->d_name, "merge_", 6) == 0)
                    unlinkat(dirfd(d), e->d_name, 0);
            closedir(d);
        }
        rmdir(tiles);
        free(tiles);
    }
    if (!final)
        return;
    {
        char *lock = tr_path_join(job, "lock");
        if (lock != NULL)
            unlink(lock);
        free(lock);
    }
    if (own_dir)
        rmdir(job);
}

/* The tiler's progress hook: shows progress and carries the stop request. */
static int tiler_progress(void *ctx, int stage, uint64_t done, uint64_t total)
{
    tr_ctx *c = ctx;
    static const char *const names[] = {"", "pass 1", "pass 2", "dup merge"};
    const char *name = stage >= 1 && stage <= 3 ? names[stage] : "tiler";
    if (!c->prog.open || strcmp(c->prog.stage, name) != 0)
        gdt_progress_stage(&c->prog, name, total, stage == 3 ? "tiles" : "points");
    gdt_progress_update(&c->prog, done);
    return stopped(c);
}

/* Opens or creates the journal and checks that it belongs to this command.
 * A journal without finished work (gdt_job_has_work) is taken over: its
 * params and fingerprint are rewritten.  The output path is recorded for
 * --resume but not compared.
 * returns GDT_EJOB 6903 (options differ), 6904 (an input changed). */
static gdt_status open_journal(tr_ctx *c, gdt_error *err)
{
    char *params = NULL, *fp = NULL, *old_params = NULL, *old_fp = NULL;
    char diff[512];
    int is_new = 0, has_work = 0;
    tr_text out = {NULL, 0, 0, 0}, products = {NULL, 0, 0, 0};
    gdt_status st = build_params(c->opts, &params, err);

    if (st == GDT_OK)
        st = build_fingerprint(c->opts, &fp, err);
    if (st == GDT_OK) {
        text_abs(&out, "output", c->opts->output);
        if (!out.failed)
            out.s[--out.len] = '\0'; /* the line break */
        /* the products beside the mesh, for --resume (not in params: they
         * do not change the job's files) */
        if (c->opts->dem != NULL) {
            text_abs(&products, "dem", c->opts->dem);
            text_add(&products, "dem_res=%.17g\ndem_nodata=%.17g\n", c->opts->dem_res,
                     c->opts->dem_nodata);
            if (c->opts->preview != NULL)
                text_abs(&products, "preview", c->opts->preview);
        }
        if (out.failed || products.failed)
            st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    }
    if (st == GDT_OK)
        st = gdt_job_open(&c->jobdb, c->job, 1, &is_new, err);
    if (st == GDT_OK) {
        gdt_job_id(c->jobdb, c->job_id);
        if (!is_new)
            st = gdt_job_has_work(c->jobdb, &has_work, err);
    }
    if (st == GDT_OK && !is_new)
        st = gdt_job_get_meta(c->jobdb, "params", &old_params, err);
    if (st == GDT_OK && !is_new)
        st = gdt_job_get_meta(c->jobdb, "fingerprint", &old_fp, err);
    if (st != GDT_OK)
        goto done;
    if (!has_work && old_params != NULL && old_fp != NULL &&
        (strcmp(old_params, params) != 0 || strcmp(old_fp, fp) != 0)) {
        /* nothing finished there: the job becomes this command's */
        gdt_log_note(&c->log, "%s: taking over a job without finished work", c->job);
        free(old_params);
        free(old_fp);
        old_params = old_fp = NULL;
    }
    if (old_params != NULL && strcmp(old_params, params) != 0) {
        first_difference(old_params, params, diff, sizeof diff);
        st = gdt_error_set(err, GDT_EJOB, 6903,
                           "%s: the job there was started with other options or paths (%s); "
                           "rerun with --restart to discard it, or use another --job",
                           c->job, diff);
        goto done;
    }
    if (old_params != NULL && old_fp != NULL && strcmp(old_fp, fp) != 0) {
        size_t i = 0;
        const char *a = old_fp, *b = fp;
        while (*a != '\0' && *a == *b) {
            if (*a == '\n')
                i++;
            a++;
            b++;
        }
        first_difference(old_fp, fp, diff, sizeof diff);
        st = gdt_error_set(err, GDT_EJOB, 6904,
                           "%s: input changed since the job in %s started (%s); rerun with "
                           "--restart to start again",
                           i < c->opts->ninputs ? c->opts->inputs[i] : c->opts->inputs[0],
                           c->job, diff);
        goto done;
    }
    st = gdt_job_begin(c->jobdb, err);
    if (st == GDT_OK && (old_params == NULL || old_fp == NULL)) {
        st = gdt_job_set_meta(c->jobdb, "fingerprint", fp, err);
        if (st == GDT_OK)
            st = gdt_job_set_meta(c->jobdb, "params", params, err);
    } else if (st == GDT_OK) {
        c->s.resumed = 1;
    }
    if (st == GDT_OK)
        st = gdt_job_set_meta(c->jobdb, "output", out.s + strlen("output="), err);
    if (st == GDT_OK)
        st = gdt_job_set_meta(c->jobdb, "products", products.s != NULL ? products.s : "", err);
    if (st == GDT_OK)
        st = gdt_job_commit(c->jobdb, err);
done:
    free(out.s);
    free(products.s);
    free(params);
    free(fp);
    free(old_params);
    free(old_fp);
    return st;
}

/* Records pass 2 as done together with the size and checksum of every
 * .pts and .edge file it wrote (one transaction). */
static gdt_status record_pass2(tr_ctx *c, gdt_error *err)
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
    if (st == GDT_OK)
        st = gdt_job_set_stage(c->jobdb, "pass2", 1, err);
    if (st == GDT_OK)
        st = gdt_job_commit(c->jobdb, err);
    return st;
}

/* Pass 2 recorded as done: its files are adopted if every one matches its
 * record (*ok = 1); otherwise a warning names the first that does not and
 * why, and pass 2 is redone (*ok = 0). */
static gdt_status adopt_pass2(tr_ctx *c, int *ok, gdt_error *err)
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
        st = gdt_job_get_file(c->jobdb, i / 2, i % 2 ? GDT_JOB_FILE_EDGE : GDT_JOB_FILE_PTS,
                              &found, &fs[i].size, &fs[i].sum, err);
        if (st == GDT_OK && !found)
            ad = gdt_error_set(&e2, GDT_EJOB, 6501,
                               "the job records no %s file of tile %" PRIu64,
                               i % 2 ? ".edge" : ".pts", i / 2);
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

/* The core is created (OpenCL context, kernels from the cache: about 0.2 s
 * on a CPU device) on a thread of its own while pass 1 reads the input, and
 * joined after it.  When pass 1 fails first, its error is the one reported:
 * the device's may be a consequence (the compiler inside the OpenCL
 * runtime removes its temporary files on SIGXFSZ, which a write beyond
 * the file size limit raises on the thread that made it). */
typedef struct core_start {
    gdt_core_opts opts;
    gdt_core *core;
    gdt_error err;
    gdt_status st;
    pthread_t thread;
    int running;
} core_start;

static void *core_start_main(void *arg)
{
    core_start *cs = arg;
    stack_t ss;
    int have = sigaltstack(NULL, &ss) == 0;
    cs->st = gdt_core_create(&cs->core, &cs->opts, &cs->err);
    /* The compiler inside the OpenCL runtime gives the thread an alternate
     * signal stack of its own; put back the one the thread had, which
     * whoever set it up (a sanitizer's runtime) releases at thread exit. */
    if (have)
        sigaltstack(&ss, NULL);
    return NULL;
}

static void core_start_begin(core_start *cs)
{
    gdt_error_clear(&cs->err);
    /* setenv here, before pass 1 runs beside the thread (getenv in other
     * threads while setenv runs can crash) */
    gdt_ocl_prepare_env(cs->opts.cache_dir, cs->opts.log);
    cs->running = pthread_create(&cs->thread, NULL, core_start_main, cs) == 0;
    if (!cs->running)
        core_start_main(cs);
}

/* Joins the creation (if it runs) and hands the core to *core.  Returns the
 * creation's status; on failure its error replaces *err. */
static gdt_status core_start_join(core_start *cs, gdt_core **core, gdt_error *err)
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

gdt_status gdt_cli_tiled(const gdt_options *opts, gdt_error *err)
{
    tr_ctx c;
    gdt_cloud_opts co;
    gdt_tiler_opts to;
    core_start cstart;
    uint64_t ntiles, hull;
    int done = 0, created = 0, own_dir = 0;
    double t_start = gdt_now(), t0;
    /* the PLY header's filter line: lives until the writer is done */
    char filter_comment[GDT_FILTER_COMMENT_MAX], ftext[160];
    char trim_comment[GDT_TRIM_TEXT_MAX], ttext[GDT_TRIM_TEXT_MAX];
    const char *filter_comments[2] = {filter_comment, trim_comment};
    gdt_filter_counts fcounts;
    gdt_status st;

    memset(&c, 0, sizeof c);
    memset(&cstart, 0, sizeof cstart);
    c.opts = opts;
    c.lock_fd = -1;
    c.t_flushed = gdt_now();
    gdt_mesh_init(&c.slot[0].mesh);
    gdt_mesh_init(&c.slot[1].mesh);
    gdt_log_init(&c.log, opts->verbosity);
    gdt_progress_init(&c.prog, opts->verbosity);
    c.job = opts->job != NULL ? strdup(opts->job) : default_job(opts->output);
    c.tiles_dir = c.job != NULL ? tr_path_join(c.job, "tiles") : NULL;
    if (c.job == NULL || c.tiles_dir == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    /* every path (those the job recorded, for --resume) before any work */
    st = gdt_cli_check_paths(opts, c.job, err);
    if (st != GDT_OK)
        goto fail;

    /* the device while pass 1 runs */
    cstart.opts.device = opts->device;
    cstart.opts.log = &c.log;
    core_start_begin(&cstart);
    st = gdt_certifier_create(&c.certifier, host_threads(opts->threads), err);
    if (st != GDT_OK)
        goto fail;
    /* one run per job: the lock comes before anything in the directory is
     * read or removed (--restart must not remove a running job's files) */
    st = make_dir(c.job, &created, err);
    if (st == GDT_OK)
        st = gdt_job_lock(c.job, created, &c.lock_fd, &own_dir, err);
    if (st == GDT_OK && opts->restart)
        remove_job_files(c.job, 0, 0);
    if (st == GDT_OK)
        st = open_journal(&c, err);
    if (st != GDT_OK)
        goto fail;

    memset(&co, 0, sizeof co);
    co.log = &c.log;
    co.quantum = opts->quantum;
    co.threads = host_threads(opts->threads);
    co.replay_dir = c.job; /* LAZ is decoded once, in pass 1 */
    co.filter = &opts->filter;
    st = gdt_cloud_open(&c.cloud, opts->inputs, opts->ninputs, &co, err);
    if (st != GDT_OK)
        goto fail;
    memset(&to, 0, sizeof to);
    to.tile = opts->tile;
    to.cell = opts->cell;
    to.halo = opts->halo;
    to.mem_budget = opts->mem_budget;
    to.dup = opts->dup;
    to.threads = host_threads(opts->threads);
    to.job_dir = c.job;
    to.file_id[0] = c.job_id[0];
    to.file_id[1] = c.job_id[1];
    to.log = &c.log;
    to.progress = tiler_progress;
    to.progress_ctx = &c;
    st = gdt_tiler_create(&c.tiler, &to, c.cloud, err);
    if (st == GDT_OK)
        st = gdt_tiler_pass1(c.tiler, err);
    if (st == GDT_EINTERRUPTED)
        st = tr_interrupted(c.job, "pass 1", err);
    if (st != GDT_OK)
        goto fail;
    st = core_start_join(&cstart, &c.core, err);
    if (stopped(&c)) {
        /* a signal during the kernel build, reported now rather than at the
         * next check; when the build failed, the signal was the cause: the
         * kernel compiler removes its files on SIGINT/SIGTERM */
        gdt_error_clear(err);
        st = tr_interrupted(c.job, "the OpenCL start-up", err);
    }
    if (st != GDT_OK)
        goto fail;
    snprintf(c.s.device, sizeof c.s.device, "%s", gdt_core_device_name(c.core));
    c.plan = gdt_tiler_get_plan(c.tiler);
    c.s.t_pass1 = gdt_tiler_get_stats(c.tiler)->t_pass1;
    /* the seam merge's frame is the lattice minus the plan's minimum: a
     * wider cloud is refused before the tile stage, not at its end */
    if (c.plan->points > 0 &&
        (st = gdt_cloud_check_span(c.cloud, c.plan->max_x - c.plan->min_x,
                                   c.plan->max_y - c.plan->min_y, "the tiled run",
                                   err)) != GDT_OK)
        goto fail;
    /* a --dem-res the lattice refuses (or a raster too large) is refused
     * now, before pass 2; the grid itself is defined with the distinct
     * point count after it */
    if (opts->dem != NULL) {
        gdt_raster_grid g;
        const gdt_cloud_info *ci = gdt_cloud_get_info(c.cloud);
        st = gdt_raster_grid_define(&g, &ci->lattice, c.plan->points > 0 ? c.plan->min_x : 0,
                                    c.plan->points > 0 ? c.plan->min_y : 0,
                                    c.plan->points > 0 ? c.plan->max_x : 0,
                                    c.plan->points > 0 ? c.plan->max_y : 0, c.plan->points,
                                    opts->dem_res, "--dem-res", err);
        if (st != GDT_OK)
            goto fail;
    }
    t0 = gdt_now();
    st = gdt_job_stage_done(c.jobdb, "pass2", &done, err);
    if (st != GDT_OK)
        goto fail;
    if (done) {
        st = adopt_pass2(&c, &done, err);
        if (st != GDT_OK)
            goto fail;
        c.s.pass2_reused = done;
    }
    if (!done) {
        st = gdt_job_set_stage(c.jobdb, "pass2", 0, err);
        if (st == GDT_OK)
            st = gdt_job_clear_tiles(c.jobdb, err);
        if (st == GDT_OK)
            st = gdt_tiler_pass2(c.tiler, err);
        if (st == GDT_EINTERRUPTED)
            st = tr_interrupted(c.job, "pass 2", err);
        if (st == GDT_OK)
            st = record_pass2(&c, err);
        if (st != GDT_OK)
            goto fail;
    }
    c.s.t_pass2 = gdt_now() - t0;
    c.s.points_read = c.plan->points;

    ntiles = gdt_tiler_tile_count(c.tiler);
    c.s.tiles = ntiles;
    c.base = malloc((ntiles + 1) * sizeof *c.base);
    if (c.base == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    c.base[0] = 0;
    for (uint64_t k = 0; k < ntiles; k++) {
        gdt_tile_desc d;
        st = gdt_tiler_tile_info(c.tiler, k, &d, err);
        if (st != GDT_OK)
            goto fail;
        c.base[k + 1] = c.base[k] + d.points;
    }
    c.s.vertices = c.base[ntiles];
    if (c.s.vertices > (uint64_t)INT32_MAX) {
        st = gdt_error_set(err, GDT_EINPUT, 3801,
                           "%s: %" PRIu64 " distinct points; a face index of the output "
                           "holds at most 2^31 - 1",
                           opts->inputs[0], c.s.vertices);
        goto fail;
    }

    {
        const gdt_cloud_info *ci = gdt_cloud_get_info(c.cloud);
        tr_out_src os;
        c.trim = opts->trim;
        c.trim.sx = ci->lattice.sx;
        c.trim.sy = ci->lattice.sy;
        if (gdt_trim_on(&c.trim) && (st = gdt_trim_graph_create(&c.tgraph, &c.trim, err)) != GDT_OK)
            goto fail;
        memset(&os, 0, sizeof os);
        os.output = opts->output;
        gdt_run_mesh_meta(c.cloud, &c.log, &opts->trim, filter_comment, sizeof filter_comment,
                          trim_comment, sizeof trim_comment, filter_comments, &os.meta);
        os.trim = c.tgraph != NULL;
        os.concavity = c.trim.concavity > 0;
        if (opts->check && gdt_mesh_format_of(opts->output) != GDT_MESH_PLY) {
            c.check_ply = tr_path_join(c.job, CHECK_PLY_NAME);
            if (c.check_ply == NULL) {
                st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
                goto fail;
            }
            os.check_ply = c.check_ply;
        }
        os.tiler = c.tiler;
        os.tiles_dir = c.tiles_dir;
        os.job = c.job;
        os.base = c.base;
        os.ntiles = ntiles;
        os.stop = opts->stop;
        if (opts->dem != NULL) {
            st = tr_dem_create(&c.dem, opts, ci, c.plan, c.s.vertices, c.job, err);
            if (st != GDT_OK)
                goto fail;
        }
        os.dem = c.dem;
        st = tr_out_start(&c.out, &os, err);
        if (st != GDT_OK)
            goto fail;
    }

    t0 = gdt_now();
    gdt_progress_stage(&c.prog, "tiles", c.s.vertices, "points");
    for (uint64_t k = 0; k < ntiles; k++) {
        uint64_t size = 0, sum = 0;
        int found = 0, ok = 0;
        if (stopped(&c)) {
            /* keep what is done: a rerun reuses it */
            gdt_error e2;
            gdt_error_clear(&e2);
            if (post_join(&c, &e2) == GDT_OK)
                flush_pending(&c, &e2);
            st = tr_interrupted(c.job, "the tile stage", err);
            goto fail;
        }
        st = gdt_job_get_tile(c.jobdb, k, &found, &size, &sum, err);
        /* reuse_tile shares the post stage's buffers */
        if (st == GDT_OK && found && (st = post_join(&c, err)) == GDT_OK)
            st = reuse_tile(&c, k, size, sum, &ok, err);
        /* the core on tile k while the post stage finishes tile k - 1 */
        if (st == GDT_OK && !ok)
            st = core_tile(&c, k, &c.slot[k & 1], err);
        if (st == GDT_OK)
            st = post_join(&c, err);
        /* tiles before k have their .tri files, and tile k if reused; a
         * failed output is reported after the merge, once the tiles are
         * safe in the job for a rerun */
        if (st == GDT_OK)
            tr_out_ready(c.out, k + (ok ? 1 : 0));
        /* no post stage runs: the tiles the post stages synced go to the
         * journal (a short transaction) */
        if (st == GDT_OK)
            st = record_synced(&c, err);
        if (st == GDT_OK && !ok)
            st = post_start(&c, &c.slot[k & 1], err);
        if (st != GDT_OK)
            goto fail;
        if (ok)
            c.s.tiles_reused++;
        else
            c.s.tiles_redone++;
        gdt_progress_update(&c.prog, c.base[k + 1]);
    }
    st = post_join(&c, err);
    if (st == GDT_OK)
        st = flush_pending(&c, err);
    if (st != GDT_OK)
        goto fail;
    c.s.t_tiles = gdt_now() - t0;
    reclaim_start(&c);
    t0 = gdt_now();
    st = merge_rows(&c, err);
    if (st != GDT_OK)
        goto fail;
    gdt_seam_free(&c.seam);
    c.s.faces = c.s.certified + c.s.merge_faces;
    c.s.t_merge = gdt_now() - t0;
    /* the writer may copy trimmed faces from now on */
    if (c.tgraph != NULL)
        tr_out_set_trim(c.out, c.tgraph);

    /* Euler: a triangulation of V points with h on the hull has 2V - h - 2
     * faces (none when the points are collinear: then the seam holds them
     * all and has no triangle). */
    hull = c.s.merge.hull_vertices;
    if (c.s.merge.seam_triangles == 0 && c.s.certified == 0 ? c.s.faces != 0
                                                            : c.s.faces + hull + 2 !=
                                                                  2 * c.s.vertices) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7820,
                           "the tiled mesh has %" PRIu64 " faces for %" PRIu64
                           " vertices with %" PRIu64 " on the hull (Euler: %" PRIu64 ")",
                           c.s.faces, c.s.vertices, hull, 2 * c.s.vertices - hull - 2);
        goto fail;
    }

    t0 = gdt_now();
    gdt_progress_stage(&c.prog, "write", 1, "files");
    {
        char *mf = tr_path_join(c.job, MF_NAME);
        char *md = c.dem != NULL ? tr_path_join(c.job, MD_NAME) : NULL;
        st = mf == NULL || (c.dem != NULL && md == NULL)
                 ? gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory")
                 : tr_out_finish(c.out, mf, md, c.s.merge_faces, &c.s.trim, err);
        if (mf == NULL || (c.dem != NULL && md == NULL))
            tr_out_abort(c.out);
        c.out = NULL;
        free(md);
        free(mf);
    }
    if (st == GDT_OK && c.dem != NULL) {
        double t1 = gdt_now();
        st = tr_dem_finish(c.dem, &c.s.dem_geo, &c.s.dem_stats, err);
        c.dem = NULL;
        c.s.dem_done = st == GDT_OK;
        c.s.t_dem = gdt_now() - t1;
    }
    if (st == GDT_OK)
        gdt_progress_update(&c.prog, 1);
    if (st == GDT_OK)
        st = gdt_job_set_stage(c.jobdb, "ply", 1, err);
    if (st != GDT_OK)
        goto fail;
    gdt_progress_end(&c.prog);
    c.s.t_write = gdt_now() - t0;
    if (opts->check) {
        t0 = gdt_now();
        st = check_output(&c, err);
        if (st != GDT_OK)
            goto fail;
        c.s.checked = 1;
        c.s.t_check = gdt_now() - t0;
    }
    c.s.t_total = gdt_now() - t_start;
    if (opts->json != NULL) {
        st = write_summary(&c, err);
        if (st != GDT_OK)
            goto fail;
    }
    fcounts = gdt_cloud_total_counts(c.cloud);
    gdt_filter_counts_text(&opts->filter, &fcounts, ftext, sizeof ftext);
    gdt_trim_report_text(&opts->trim, &c.s.trim, ttext, sizeof ttext);
    if (opts->verbosity >= 0)
        fprintf(stderr,
                "gdt-tile: %s: %" PRIu64 " points%s, %" PRIu64 " vertices, %" PRIu64
                " faces%s in %" PRIu64 " tiles (%.1f%% certified, %" PRIu64
                " seam vertices) on %s, %.2f s%s%s\n",
                opts->output, c.s.points_read, ftext, c.s.vertices,
                c.s.faces - c.s.trim.dropped, ttext, c.s.tiles,
                c.s.faces > 0 ? 100.0 * (double)c.s.certified / (double)c.s.faces : 100.0,
                c.s.merge.seam_vertices, c.s.device, c.s.t_total,
                c.s.resumed ? ", resumed" : "", c.s.checked ? ", checked exactly" : "");
    if (c.s.dem_done)
        gdt_dem_report_line(opts, &c.s.dem_geo, &c.s.dem_stats);
    gdt_log_note(&c.log,
                 "times: pass 1 %.2f s, pass 2 %.2f s, tiles %.2f s (core %.2f, post %.2f, of which "
                 "certify %.2f), "
                 "merge %.2f s, write %.2f s; tiles reused %" PRIu64 ", computed %" PRIu64,
                 c.s.t_pass1, c.s.t_pass2, c.s.t_tiles, c.s.t_core, c.s.t_post, c.s.t_certify,
                 c.s.t_merge,
                 c.s.t_write, c.s.tiles_reused, c.s.tiles_redone);
    if (!opts->keep_job) {
        gdt_tiler_destroy(c.tiler);
        c.tiler = NULL;
        gdt_job_close(c.jobdb);
        c.jobdb = NULL;
        remove_job_files(c.job, 1, own_dir);
    }
fail:
    {
        /* the first error stands */
        gdt_error e2;
        gdt_error_clear(&e2);
        core_start_join(&cstart, &c.core, &e2);
        post_join(&c, &e2);
        tr_out_abort(c.out); /* its thread feeds the DEM: first */
        tr_dem_abort(c.dem);
        reclaim_join(&c);
    }
    if (st == GDT_OK)
        gdt_progress_end(&c.prog);
    else
        gdt_progress_abort(&c.prog);
    free(c.pending);
    gdt_seam_free(&c.seam);
    gdt_trim_graph_destroy(c.tgraph);
    gdt_trim_tile_free(&c.ttile);
    free(c.topen);
    free(c.fbuf);
    free(c.count);
    free(c.cert);
    for (int i = 0; i < 2; i++) {
        gdt_mesh_free(&c.slot[i].mesh);
        free(c.slot[i].lh);
        free(c.slot[i].z);
    }
    gdt_point_buf_free(&c.halo);
    free(c.base);
    gdt_certifier_destroy(c.certifier);
    gdt_core_destroy(c.core);
    gdt_tiler_destroy(c.tiler);
    gdt_cloud_close(c.cloud);
    /* A run refused for its input or its options, of a job that holds no
     * finished work, leaves nothing behind: there is nothing to resume, and
     * the corrected command is another job.  Its files go, and the
     * directory too if a run of this job made it.  An interrupted run or
     * one stopped by the disk or the device keeps its job: the same command
     * resumes it.  A journal that cannot be asked counts as work. */
    if ((st == GDT_EINPUT || st == GDT_EUSAGE) && c.lock_fd >= 0) {
        int has = 1;
        gdt_error e3;
        gdt_error_clear(&e3);
        if (c.jobdb == NULL)
            has = gdt_job_exists(c.job);
        else if (gdt_job_has_work(c.jobdb, &has, &e3) != GDT_OK)
            has = 1;
        gdt_job_close(c.jobdb);
        c.jobdb = NULL;
        if (!has)
            remove_job_files(c.job, 1, own_dir);
    }
    gdt_job_close(c.jobdb);
    gdt_job_unlock(c.job, c.lock_fd, 0);
    if (c.check_ply != NULL)
        unlink(c.check_ply); /* a second copy of the mesh is no state to keep */
    free(c.check_ply);
    free(c.tiles_dir);
    free(c.job);
    return st;
}

/* Reads one "key=value" line of params (the first match); NULL if absent. */
static char *param_get(const char *params, const char *key, const char **next)
{
    size_t kl = strlen(key);
    const char *p = next != NULL && *next != NULL ? *next : params;
    while (*p != '\0') {
        size_t l = strcspn(p, "\n");
        if (l > kl && memcmp(p, key, kl) == 0 && p[kl] == '=') {
            char *v = malloc(l - kl);
            if (v != NULL) {
                memcpy(v, p + kl + 1, l - kl - 1);
                v[l - kl - 1] = '\0';
            }
            if (next != NULL)
                *next = p + l + (p[l] == '\n');
            return v;
        }
        p += l + (p[l] == '\n');
    }
    return NULL;
}

gdt_status gdt_cli_resume(const gdt_options *opts, gdt_error *err)
{
    gdt_options o = *opts;
    gdt_job *j = NULL;
    char *params = NULL, *v = NULL, *output = NULL, *products = NULL, *dem = NULL;
    char *preview = NULL;
    char **inputs = NULL;
    size_t n = 0;
    gdt_status st = gdt_job_open(&j, opts->resume, 0, NULL, err);

    if (st == GDT_OK)
        st = gdt_job_get_meta(j, "params", &params, err);
    if (st == GDT_OK)
        st = gdt_job_get_meta(j, "output", &output, err);
    if (st == GDT_OK)
        st = gdt_job_get_meta(j, "products", &products, err);
    gdt_job_close(j);
    /* the DEM the job's command asked for (jobs of earlier versions: none) */
    if (st == GDT_OK && products != NULL && (dem = param_get(products, "dem", NULL)) != NULL) {
        char *r = param_get(products, "dem_res", NULL), *nd = param_get(products, "dem_nodata", NULL);
        char *e1 = NULL, *e2 = NULL;
        o.dem = dem;
        o.preview = preview = param_get(products, "preview", NULL);
        if (r != NULL)
            o.dem_res = strtod(r, &e1);
        if (nd != NULL)
            o.dem_nodata = strtod(nd, &e2);
        o.dem_res_set = o.dem_res > 0;
        o.dem_nodata_set = 1;
        if (r == NULL || nd == NULL || *e1 != '\0' || *e2 != '\0' || !(o.dem_res >= 0) ||
            !isfinite(o.dem_res) || !isfinite(o.dem_nodata))
            st = gdt_error_set(err, GDT_EJOB, 6905, "%s: job record has a bad DEM entry",
                               opts->resume);
        free(r);
        free(nd);
    }
    free(products);
    if (st == GDT_OK && params == NULL)
        st = gdt_error_set(err, GDT_EJOB, 6905,
                           "%s: the job there never recorded its options; start it again "
                           "with the original command",
                           opts->resume);
    if (st != GDT_OK) {
        free(output);
        free(params);
        free(dem);
        free(preview);
        return st;
    }
#define NEED(key)                                                                            \
    do {                                                                                     \
        free(v);                                                                             \
        v = param_get(params, key, NULL);                                                    \
        if (v == NULL) {                                                                     \
            st = gdt_error_set(err, GDT_EJOB, 6905, "%s: job record lacks '%s'",             \
                               opts->resume, key);                                           \
            goto done;                                                                       \
        }                                                                                    \
    } while (0)
    NEED("tile");
    o.tile = atoi(v);
    NEED("cell");
    o.cell = strtod(v, NULL);
    NEED("halo");
    o.halo = strtol(v, NULL, 10);
    NEED("dup");
    o.dup = (gdt_dup_policy)atoi(v);
    NEED("quantum");
    o.quantum = strtod(v, NULL);
    NEED("filter");
    if (gdt_filter_from_description(&o.filter, v) != 0) {
        st = gdt_error_set(err, GDT_EJOB, 6905, "%s: job record has a bad filter '%s'",
                           opts->resume, v);
        goto done;
    }
    free(v);
    v = param_get(params, "trim", NULL);
    if (v != NULL) {
        char *end = NULL;
        o.trim.max_edge = strtod(v, &end);
        o.trim.concavity = strtod(end, &end);
        if (*end != '\0' || !(o.trim.max_edge >= 0) || !(o.trim.concavity >= 0) ||
            !isfinite(o.trim.max_edge) || !isfinite(o.trim.concavity)) {
            st = gdt_error_set(err, GDT_EJOB, 6905, "%s: job record has a bad trim '%s'",
                               opts->resume, v);
            goto done;
        }
    }
    NEED("inputs");
    n = (size_t)strtoull(v, NULL, 10);
#undef NEED
    /* Each input is a line of params, so a count beyond its length is a
     * damaged record (and would overflow n + 1 below). */
    if (n > strlen(params)) {
        st = gdt_error_set(err, GDT_EJOB, 6905, "%s: job record counts %s inputs",
                           opts->resume, v);
        goto done;
    }
    inputs = calloc(n + 1, sizeof *inputs);
    if (inputs == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto done;
    }
    {
        const char *next = NULL;
        for (size_t i = 0; i < n; i++) {
            inputs[i] = param_get(params, "input", &next);
            if (inputs[i] == NULL) {
                st = gdt_error_set(err, GDT_EJOB, 6905, "%s: job record lacks input %zu",
                                   opts->resume, i + 1);
                goto done;
            }
        }
    }
    free(v);
    v = output;
    output = NULL;
    if (v == NULL || n == 0) {
        st = gdt_error_set(err, GDT_EJOB, 6905, "%s: job record lacks the output or inputs",
                           opts->resume);
        goto done;
    }
    o.output = v;
    o.inputs = (const char **)inputs;
    o.ninputs = n;
    o.job = opts->resume;
    o.mode = GDT_MODE_RUN;
    st = gdt_cli_tiled(&o, err);
done:
    for (size_t i = 0; inputs != NULL && i < n; i++)
        free(inputs[i]);
    free(inputs);
    free(v);
    free(output);
    free(params);
    free(dem);
    free(preview);
    return st;
}
