/* run_merge.c — the seam merge of a tiled run by rows of tiles: the seams
 * read back from the .tri files; merge.faces and merge.dem in the job
 * directory (private/stages.h). */
#include "private/stages.h"

#include <errno.h>
#include <fcntl.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "private/tiled_files.h"

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

/* Appends the seam section of tile k's .tri file (seam vertices and barrier
 * edges) to c->seam, through tr_tri_read_seam: the counts of the header are
 * checked against the file's size before anything is allocated, every id
 * against the tile's vertex range and every coordinate against the merge
 * frame.
 * returns: GDT_EIO 4805 (open or read), GDT_EJOB 6801 (not the file this
 * run wrote), 6802 (its size or content does not match its header), 7001. */
static gdt_status read_seam(tr_run *c, uint64_t k, gdt_error *err)
{
    gdt_tile_desc d;
    char *path = NULL;
    FILE *f = NULL;
    uint64_t size = 0;
    gdt_status st = gdt_tiler_tile_info(c->tiler, k, &d, err);

    if (st == GDT_OK)
        st = tr_open_tri(c->tiles_dir, &d, &f, &size, &path, err);
    if (st == GDT_OK && tr_reserve(&c->mbuf, &c->cap_mbuf, TR_SEAM_VERTEX * (size_t)TR_CHUNK, 1) != 0)
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    if (st == GDT_OK) {
        tr_tri_expect ex = {c->base[k], d.points, c->job_id, c->tgraph != NULL};
        st = tr_tri_read_seam(f, size, &ex, &c->mseam, c->mbuf, path, err);
        /* the tile's open edges meet the merge faces in the trim graph */
        if (st == GDT_OK && ex.trim)
            st = tr_tri_read_open(f, size, &ex, &c->topen, &c->ntopen, &c->cap_topen, c->mbuf,
                                  path, err);
        if (st == GDT_OK && ex.trim)
            st = gdt_trim_graph_add_tile(c->tgraph, k, c->topen, c->ntopen, err);
    }
    if (f != NULL)
        fclose(f);
    free(path);
    return st;
}

/* With --dem: the round's nf faces' vertices (global lattice, z) appended
 * to merge.dem (dbuf holds *ndbuf bytes of MD_RECORD TR_CHUNK). */
static gdt_status put_merge_dem(tr_run *c, int fd, const char *tmp, const gdt_merger *m,
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

/* The merge thread: waits until tiles [0, need) have their files; 0 when
 * the run gave up. */
static int wait_ready(tr_run *c, uint64_t need)
{
    tr_merge_bg *b = &c->mbg;
    int go;
    pthread_mutex_lock(&b->mu);
    while (b->ready < need && !b->quit && !tr_stopped(c))
        pthread_cond_wait(&b->cv, &b->mu);
    go = !b->quit && !tr_stopped(c);
    pthread_mutex_unlock(&b->mu);
    return go;
}

/* The seam merge by rows of tiles (gdt_seam.h).  Each row's seam
 * is read from its tiles' .tri files; each round's final faces are appended
 * to <job>/merge.faces ("GDTMRG01", u64 face count, then 3 x u32 output
 * indices per face, little-endian), written under merge.faces.tmp, fsync'd
 * and renamed.  Holds one row of seams, the merger's band and a write
 * buffer. */
static gdt_status merge_rows(tr_run *c, int bg, gdt_error *err)
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
    if (!bg)
        gdt_progress_stage(&c->prog, "merge", c->seam_total, "points");
    while (k < ntiles) {
        gdt_tile_desc d;
        const uint64_t *f = NULL;
        size_t nf = 0;
        int64_t row, y_next = 0;
        uint64_t k1 = k;
        if (tr_stopped(c)) {
            st = tr_interrupted(c->job, "the seam merge", err);
            goto fail;
        }
        st = gdt_tiler_tile_info(c->tiler, k, &d, err);
        if (st != GDT_OK)
            goto fail;
        row = d.j;
        c->mseam.nv = 0;
        c->mseam.ne = 0;
        /* tiles are sorted by (j, i): a row is a run of equal j */
        while (k1 < ntiles) {
            st = gdt_tiler_tile_info(c->tiler, k1, &d, err);
            if (st != GDT_OK)
                goto fail;
            if (d.j != row) {
                y_next = d.y0 - pl->min_y;
                break;
            }
            if (bg && !wait_ready(c, k1 + 1)) {
                st = tr_interrupted(c->job, "the seam merge", err);
                goto fail;
            }
            st = read_seam(c, k1, err);
            if (st != GDT_OK)
                goto fail;
            k1++;
        }
        st = gdt_merger_round(m, &c->mseam, y_next, k1 == ntiles, &f, &nf, err);
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
        done_v += c->mseam.nv;
        if (!bg) /* the tile stage shows its progress meanwhile */
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
    st = tr_commit_tmp(&fd, tmp, path, 0, err);
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
        st = tr_commit_tmp(&dfd, dtmp, dpath, 1, err);
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

static void *merge_main(void *arg)
{
    tr_run *c = arg;
    gdt_error_clear(&c->mbg.err);
    c->mbg.st = merge_rows(c, 1, &c->mbg.err);
    c->mbg.t_end = gdt_now();
    return NULL;
}

gdt_status tr_run_merge_start(tr_run *c, gdt_error *err)
{
    tr_merge_bg *b = &c->mbg;
    (void)err;
    if (pthread_mutex_init(&b->mu, NULL) != 0)
        return GDT_OK; /* tr_run_merge merges itself */
    if (pthread_cond_init(&b->cv, NULL) != 0) {
        pthread_mutex_destroy(&b->mu);
        return GDT_OK;
    }
    b->sync_made = 1;
    b->running = pthread_create(&b->tid, NULL, merge_main, c) == 0;
    return GDT_OK;
}

void tr_merge_ready(tr_run *c, uint64_t prefix)
{
    tr_merge_bg *b = &c->mbg;
    if (!b->running)
        return;
    pthread_mutex_lock(&b->mu);
    if (prefix > b->ready)
        b->ready = prefix;
    pthread_cond_broadcast(&b->cv);
    pthread_mutex_unlock(&b->mu);
}

/* Stops the merge thread (if one runs) and waits for it; quit: the run
 * gives up (else every tile is ready). */
static void merge_join(tr_run *c, int quit)
{
    tr_merge_bg *b = &c->mbg;
    if (b->running) {
        pthread_mutex_lock(&b->mu);
        if (quit)
            b->quit = 1;
        else
            b->ready = UINT64_MAX;
        pthread_cond_broadcast(&b->cv);
        pthread_mutex_unlock(&b->mu);
        pthread_join(b->tid, NULL);
        b->running = 0;
    }
}

void tr_merge_abort(tr_run *c)
{
    merge_join(c, 1);
    if (c->mbg.sync_made) {
        pthread_cond_destroy(&c->mbg.cv);
        pthread_mutex_destroy(&c->mbg.mu);
        c->mbg.sync_made = 0;
    }
}

gdt_status tr_run_merge(tr_run *c, gdt_error *err)
{
    double t0 = gdt_now();
    gdt_status st;
    if (c->mbg.running) {
        /* the rows that wait for the last tiles: the merge stage of the
         * progress lines (the thread itself shows none) */
        gdt_progress_stage(&c->prog, "merge", c->seam_total, "points");
        merge_join(c, 0);
        st = c->mbg.st;
        if (st == GDT_OK)
            gdt_progress_update(&c->prog, c->seam_total);
        if (st != GDT_OK)
            *err = c->mbg.err;
    } else {
        st = merge_rows(c, 0, err);
    }
    if (st != GDT_OK)
        return st;
    gdt_seam_free(&c->mseam);
    c->s.faces = c->s.certified + c->s.merge_faces;
    c->s.t_merge = gdt_now() - t0;
    return GDT_OK;
}
