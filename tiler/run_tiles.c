/* run_tiles.c — the tile stage of a tiled run: per tile the OpenCL core,
 * then on the post thread certification, seam, trim section and the .tri
 * file, synced in batches and recorded in the journal (private/stages.h). */
#define _GNU_SOURCE /* syncfs */
#include "private/stages.h"

#include <errno.h>
#include <fcntl.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "private/tiled_files.h"

/* tr_reserve for a buffer of direct I/O (aligned to GDT_DIO_BLOCK); the
 * content is not kept when it grows. */
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
static gdt_status sort_faces(tr_run *c, gdt_mesh *m, size_t nf, unsigned char *out,
                             gdt_error *err)
{
    size_t nv = m->nverts, k = 0;
    uint32_t *tmp = (uint32_t *)(void *)m->tri, *sorted = (uint32_t *)(void *)out;

    if (tr_reserve(&c->count, &c->cap_count, nv + 1, sizeof *c->count) != 0)
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
static gdt_status trim_tile(tr_run *c, const gdt_mesh *m, size_t nf, uint64_t base,
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
static void put_trim(const tr_run *c, unsigned char *p)
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

void tr_core_counts_add(tr_run *c, const tr_core_counts *n)
{
    if (n->max_tile_points > c->s.max_tile_points)
        c->s.max_tile_points = n->max_tile_points;
    if (n->max_halo_points > c->s.max_halo_points)
        c->s.max_halo_points = n->max_halo_points;
    c->s.gcd_tiles += n->gcd_tiles;
    c->s.insert_tiles += n->insert_tiles;
    c->s.t_core += n->t_core;
}

/* The first half of tile k: loads it and runs the core on its own points
 * into sl (the halo goes beside it). */
gdt_status tr_core_tile(tr_run *c, gdt_core *core, gdt_point_buf *halo, tr_core_counts *counts,
                        uint64_t k, tr_slot *sl, gdt_error *err)
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
    if (st == GDT_OK && tr_reserve(&sl->z, &sl->cap_z, (size_t)d->points + 1, sizeof *sl->z) != 0)
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    if (st == GDT_OK)
        st = gdt_tiler_load_tile_local(c->tiler, k, d->local_x0, d->local_y0, sl->mesh.pts,
                                       sl->z, &n, halo, err);
    if (st != GDT_OK)
        return st;
    sl->n = n;
    nh = sl->nh = halo->n;
    if (n > counts->max_tile_points)
        counts->max_tile_points = n;
    if (nh > counts->max_halo_points)
        counts->max_halo_points = nh;
    if (tr_reserve(&sl->lh, &sl->cap_lh, nh + 1, sizeof *sl->lh) != 0)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    for (size_t i = 0; i < nh; i++) {
        sl->lh[i].x = halo->pts[i].x - d->local_x0;
        sl->lh[i].y = halo->pts[i].y - d->local_y0;
    }

    t0 = gdt_now();
    memset(&cs, 0, sizeof cs);
    st = gdt_core_triangulate(core, sl->mesh.pts, n, c->tile, &sl->mesh, &cs, err);
    if (st != GDT_OK)
        return st;
    if (strcmp(cs.path, "insert") == 0)
        counts->insert_tiles++;
    else
        counts->gcd_tiles++;
    counts->t_core += gdt_now() - t0;
    return GDT_OK;
}

/* Makes every pending tile file durable: one syncfs of the job's file
 * system (tiles come in batches), then the directory; pending[0, npending)
 * are then synced.  Run by the post stage, or where none runs. */
static gdt_status sync_tiles(tr_run *c, gdt_error *err)
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
static gdt_status post_tile_run(tr_run *c, tr_slot *sl, gdt_error *err)
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
    if (tr_reserve(&c->cert, &c->cap_cert, m->ntris + 1, 1) != 0)
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
        st = tr_write_atomic(path, c->fbuf, len, 1, c->tri_cached, err);
    free(path);
    if (st != GDT_OK)
        return st;
    if (tr_reserve(&c->pending, &c->cap_pending, c->npending + 1 + 64,
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
static gdt_status post_tile(tr_run *c, tr_slot *sl, gdt_error *err)
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
static void reclaim_start(tr_run *c)
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

void tr_reclaim_join(tr_run *c)
{
    if (c->reclaim.running)
        pthread_join(c->reclaim.tid, NULL);
    c->reclaim.running = 0;
}

static void *post_main(void *arg)
{
    tr_post *q = arg;
    q->st = post_tile(q->c, q->slot, &q->err);
    /* the writer and the merge may read the tile's file now, while the
     * core still works on the next tile */
    if (q->st == GDT_OK && q->announce) {
        if (q->c->out != NULL)
            tr_out_ready(q->c->out, q->slot->k + 1);
        tr_merge_ready(q->c, q->slot->k + 1);
    }
    return NULL;
}

gdt_status tr_post_join(tr_run *c, gdt_error *err)
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
static gdt_status post_start(tr_run *c, tr_slot *sl, int announce, gdt_error *err)
{
    tr_post *q = &c->post;
    q->c = c;
    q->slot = sl;
    q->announce = announce;
    q->st = GDT_OK;
    gdt_error_clear(&q->err);
    if (pthread_create(&q->tid, NULL, post_main, q) != 0)
        return post_tile(c, sl, err);
    q->running = 1;
    return GDT_OK;
}

/* Record the synced tiles (pending[0, nsynced)) in one transaction and
 * drop them from pending; set->done hears of each once it is committed.
 * Only where no post stage runs. */
static gdt_status record_synced(tr_run *c, const tr_tile_set *set, gdt_error *err)
{
    gdt_status st = GDT_OK;
    size_t n = c->nsynced;
    if (n == 0)
        return GDT_OK;
    if (set->record != NULL) {
        st = set->record(set->ctx, c->pending, n, err);
        goto recorded;
    }
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
recorded:
    for (size_t i = 0; st == GDT_OK && set->done != NULL && i < n; i++)
        set->done(set->ctx, c->pending[i].k);
    memmove(c->pending, c->pending + n, (c->npending - n) * sizeof *c->pending);
    c->npending -= n;
    c->nsynced = 0;
    return st;
}

/* Makes the finished tile files durable and records them: until then a
 * crash only costs redoing them.  Only where no post stage runs. */
static gdt_status flush_pending(tr_run *c, const tr_tile_set *set, gdt_error *err)
{
    gdt_status st = c->npending > c->nsynced ? sync_tiles(c, err) : GDT_OK;
    if (st == GDT_OK)
        st = record_synced(c, set, err);
    return st;
}

/* A tile recorded as finished: its .tri file is reused when its size and
 * checksum match the record (the merge reads its seam from there, as for a
 * tile computed now).  *ok = 0: the file is missing, damaged or another
 * job's; a warning names it and the reason, and the tile is redone. */
static gdt_status reuse_tile(tr_run *c, uint64_t k, uint64_t size, uint64_t sum, int *ok,
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

/* tr_post_join, then the joined post stage's slot (*posting) given back to
 * the lanes. */
static gdt_status post_join_slot(tr_run *c, tr_slot **posting, gdt_error *err)
{
    gdt_status st = tr_post_join(c, err);
    tr_lanes_posted(c, *posting);
    *posting = NULL;
    return st;
}

/* The n tiles of set in order (more as set->more gives them); counts takes
 * the figures of c->core.  With
 * one device the i-th tile uses slot[i & 1]: the core fills one slot while
 * the post stage empties the other; with several, the lanes' slots, each
 * given back once its post stage was joined. */
static gdt_status tiles_loop(tr_run *c, const tr_tile_set *set, uint64_t n,
                             tr_core_counts *counts, gdt_error *err)
{
    tr_slot *posting = NULL; /* the slot of the post stage started last */
    gdt_status st;

    for (uint64_t i = 0;; i++) {
        uint64_t k, size = 0, sum = 0;
        int found = 0, ok = 0;
        tr_slot *sl = &c->slot[i & 1];
        if (set->more == NULL && i >= n)
            break;
        if (tr_stopped(c)) {
            /* keep what is done: a rerun reuses it */
            gdt_error e2;
            gdt_error_clear(&e2);
            if (post_join_slot(c, &posting, &e2) == GDT_OK)
                flush_pending(c, set, &e2);
            st = tr_interrupted(c->job, "the tile stage", err);
            return st;
        }
        if (set->poll != NULL && (st = set->poll(set->ctx, err)) != GDT_OK)
            return st;
        if (set->more != NULL && (st = set->more(set->ctx, i, &n, err)) != GDT_OK)
            return st;
        if (i >= n)
            break;
        k = set->k != NULL ? set->k[i] : i;
        if (set->rec != NULL) {
            found = set->rec[i].found;
            size = set->rec[i].size;
            sum = set->rec[i].sum;
            st = GDT_OK;
        } else {
            st = gdt_job_get_tile(c->jobdb, k, &found, &size, &sum, err);
        }
        /* reuse_tile shares the post stage's buffers */
        if (st == GDT_OK && found && (st = post_join_slot(c, &posting, err)) == GDT_OK)
            st = reuse_tile(c, k, size, sum, &ok, err);
        /* the core on tile k while the post stage finishes the one before */
        if (st == GDT_OK && !ok)
            st = c->lanes != NULL
                     ? tr_lanes_take(c, i, &sl, counts, err)
                     : tr_core_tile(c, c->core, &c->halo, counts, k, sl, err);
        if (st == GDT_OK)
            st = post_join_slot(c, &posting, err);
        /* tiles before k have their .tri files, and tile k if reused; a
         * failed output is reported after the merge, once the tiles are
         * safe in the job for a rerun */
        if (st == GDT_OK && set->k == NULL) {
            if (c->out != NULL)
                tr_out_ready(c->out, k + (ok ? 1 : 0));
            tr_merge_ready(c, k + (ok ? 1 : 0));
        }
        /* no post stage runs: the tiles the post stages synced go to the
         * journal (a short transaction) */
        if (st == GDT_OK)
            st = record_synced(c, set, err);
        if (st == GDT_OK && !ok) {
            st = post_start(c, sl, set->k == NULL, err);
            posting = sl;
        }
        if (st != GDT_OK)
            return st;
        if (ok && set->done != NULL)
            set->done(set->ctx, k);
        if (ok)
            c->s.tiles_reused++;
        else
            c->s.tiles_redone++;
        if (set->k == NULL) /* a subset's caller shows the progress of all */
            gdt_progress_update(&c->prog, c->base[k + 1]);
    }
    st = post_join_slot(c, &posting, err);
    if (st == GDT_OK)
        st = flush_pending(c, set, err);
    if (st == GDT_OK && set->poll != NULL)
        st = set->poll(set->ctx, err);
    return st;
}

/* The busy time of every device of the tile stage so far, their number in
 * *ndev (waits for their queues: call it while no lane runs; a device with
 * several queues is counted once, by its first core). */
static double devices_busy(tr_run *c, size_t *ndev)
{
    double b = 0.0;
    *ndev = 0;
    if (c->core != NULL) {
        b += gdt_core_device_busy(c->core);
        ++*ndev;
    }
    for (size_t j = 0; j < c->cstart.nmore; j++)
        if (c->cstart.more[j] != NULL && !gdt_core_shares_device(c->cstart.more[j])) {
            b += gdt_core_device_busy(c->cstart.more[j]);
            ++*ndev;
        }
    return b;
}

gdt_status tr_run_tiles(tr_run *c, const tr_tile_set *set, gdt_error *err)
{
    size_t ndev;
    double busy0;
    static const tr_tile_set all = {NULL, 0, NULL, NULL, NULL, NULL, NULL, NULL};
    uint64_t ntiles = gdt_tiler_tile_count(c->tiler), n;
    tr_core_counts counts;
    double t0;
    gdt_status st;

    if (set == NULL)
        set = &all;
    n = set->k != NULL ? set->n : ntiles;
    if (set->more != NULL && c->cstart.nmore > 0)
        return gdt_error_set(err, GDT_EINTERNAL, 7832,
                             "the tile stage was given a growing set with lanes");
    busy0 = devices_busy(c, &ndev);
    t0 = gdt_now();
    memset(&counts, 0, sizeof counts);
    gdt_progress_stage(&c->prog, "tiles", c->s.vertices, "points");
    st = tr_lanes_start(c, set, n, err);
    if (st == GDT_OK)
        st = tiles_loop(c, set, n, &counts, err);
    if (c->lanes != NULL) {
        /* a post stage may still read a lane's slot */
        gdt_error e2;
        gdt_error_clear(&e2);
        if (tr_post_join(c, &e2) != GDT_OK && st == GDT_OK) {
            st = e2.status;
            *err = e2;
        }
        tr_lanes_stop(c);
    }
    tr_core_counts_add(c, &counts);
    if (st != GDT_OK)
        return st;
    c->s.t_tiles = gdt_now() - t0;
    c->s.t_device += devices_busy(c, &ndev) - busy0;
    c->s.t_device_span += c->s.t_tiles * (double)ndev;
    reclaim_start(c);
    return GDT_OK;
}
