/* tiled_files.c — paths, messages and direct I/O shared by the stages of
 * the tiled run (see private/tiled_files.h). */
#include "private/tiled_files.h"

#include <errno.h>
#include <fcntl.h>
#include <stdint.h>
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "gdt_grow.h"

char *tr_path_join(const char *a, const char *b)
{
    size_t la = strlen(a), lb = strlen(b);
    char *p = malloc(la + lb + 2);
    if (p == NULL)
        return NULL;
    memcpy(p, a, la);
    p[la] = '/';
    memcpy(p + la + 1, b, lb + 1);
    return p;
}

gdt_status tr_tile_path(const char *tiles_dir, const gdt_tile_desc *d, const char *ext,
                        char **out, gdt_error *err)
{
    char name[96];
    snprintf(name, sizeof name, "tile_%" PRId64 "_%" PRId64 ".%s", d->i, d->j, ext);
    *out = tr_path_join(tiles_dir, name);
    return *out == NULL ? gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory") : GDT_OK;
}

tr_tri_verdict tr_tri_check_header(const unsigned char hdr[TR_HEADER], uint64_t size,
                                   const tr_tri_expect *ex, uint64_t *nf, uint64_t *nv,
                                   uint64_t *ne)
{
    *nf = tr_get_u64(hdr + 24);
    *nv = tr_get_u64(hdr + 32);
    *ne = tr_get_u64(hdr + 40);
    if (memcmp(hdr, TR_MAGIC, 8) != 0 || tr_get_u64(hdr + 8) != ex->base ||
        tr_get_u64(hdr + 16) != ex->points || ex->points > UINT64_MAX - ex->base)
        return TR_TRI_FOREIGN;
    /* no overflow in the sum: with 12 nf, 32 nv and 16 ne each at most
     * size, and size at most 2^62, it is at most 64 + 3 size + 32 < 2^64 */
    if (size < TR_HEADER || size > UINT64_MAX / 4 || *nf > size / 12 ||
        *nv > size / TR_SEAM_VERTEX ||
        *ne > size / 16 || *nv > ex->points)
        return TR_TRI_SIZE;
    if (ex->trim ? TR_HEADER + 12 * *nf + TR_SEAM_VERTEX * *nv + 16 * *ne + TT_HEADER > size
                 : TR_HEADER + 12 * *nf + TR_SEAM_VERTEX * *nv + 16 * *ne != size)
        return TR_TRI_SIZE;
    if (ex->job_id != NULL &&
        (tr_get_u64(hdr + 48) != ex->job_id[0] || tr_get_u64(hdr + 56) != ex->job_id[1]))
        return TR_TRI_JOB;
    return TR_TRI_FITS;
}

int tr_trim_check(const unsigned char th[TT_HEADER], uint64_t at, uint64_t size, uint64_t nf,
                  tr_trim_counts *tc)
{
    uint64_t left;
    if (at > size || size - at < TT_HEADER || memcmp(th, TT_MAGIC, 8) != 0)
        return -1;
    tc->ncut = tr_get_u64(th + 8);
    tc->ncand = tr_get_u64(th + 16);
    tc->nopen = tr_get_u64(th + 24);
    left = size - at - TT_HEADER;
    /* each count is bounded first, so the sum cannot overflow */
    if (tc->ncut > nf || tc->ncand > nf || tc->nopen > 3 * nf || tc->ncut > left / 4 ||
        tc->ncand > left / 8 || tc->nopen > left / 20 ||
        4 * tc->ncut + 8 * tc->ncand + 20 * tc->nopen != left)
        return -1;
    return 0;
}

gdt_status tr_open_tri(const char *tiles_dir, const gdt_tile_desc *d, FILE **f, uint64_t *size,
                       char **path, gdt_error *err)
{
    struct stat sb;
    gdt_status st = tr_tile_path(tiles_dir, d, "tri", path, err);

    *f = NULL;
    if (st != GDT_OK)
        return st;
    *f = fopen(*path, "rb");
    if (*f == NULL || fstat(fileno(*f), &sb) != 0) {
        st = gdt_error_set(err, GDT_EIO, 4805, "%s: cannot open: %s", *path, strerror(errno));
        if (*f != NULL)
            fclose(*f);
        *f = NULL;
        return st;
    }
    *size = (uint64_t)sb.st_size;
    return GDT_OK;
}

gdt_status tr_tri_read_seam(FILE *f, uint64_t size, const tr_tri_expect *ex, gdt_seam *s,
                            unsigned char *scratch, const char *path, gdt_error *err)
{
    unsigned char hdr[TR_HEADER];
    uint64_t nf = 0, nv = 0, ne = 0, lo = ex->base, hi = ex->base + ex->points;
    tr_tri_verdict v = TR_TRI_FOREIGN;

    if (fseeko(f, 0, SEEK_SET) != 0)
        return gdt_error_set(err, GDT_EIO, 4805, "%s: cannot seek: %s", path, strerror(errno));
    if (fread(hdr, 1, TR_HEADER, f) == TR_HEADER)
        v = tr_tri_check_header(hdr, size, ex, &nf, &nv, &ne);
    if (v == TR_TRI_FOREIGN || v == TR_TRI_JOB)
        return gdt_error_set(err, GDT_EJOB, 6801, "%s: not the tile file this run wrote", path);
    if (v == TR_TRI_SIZE)
        return gdt_error_set(err, GDT_EJOB, 6802,
                             "%s: %" PRIu64 " bytes do not match its header (%" PRIu64
                             " faces, %" PRIu64 " seam vertices, %" PRIu64 " barrier edges)",
                             path, size, nf, nv, ne);
    /* the size check bounds the counts and the offset by size, a file's size */
    if (fseeko(f, (off_t)(TR_HEADER + 12 * nf), SEEK_SET) != 0)
        return gdt_error_set(err, GDT_EIO, 4805, "%s: cannot seek: %s", path, strerror(errno));
    if (nv > SIZE_MAX - s->nv || ne > SIZE_MAX - s->ne ||
        gdt_grow(&s->v, &s->cap_v, s->nv + (size_t)nv, sizeof *s->v, 1024) != 0 ||
        gdt_grow(&s->e, &s->cap_e, s->ne + (size_t)ne, sizeof *s->e, 1024) != 0)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    for (uint64_t done = 0; done < nv;) {
        size_t m = nv - done < TR_CHUNK ? (size_t)(nv - done) : TR_CHUNK;
        if (fread(scratch, TR_SEAM_VERTEX, m, f) != m)
            return gdt_error_set(err, GDT_EIO, 4805, "%s: read failed", path);
        for (size_t i = 0; i < m; i++) {
            gdt_seam_vertex *sv = &s->v[s->nv];
            const unsigned char *r = scratch + TR_SEAM_VERTEX * i;
            uint64_t zb = tr_get_u64(r + 24);
            sv->id = tr_get_u64(r);
            sv->x = (int64_t)tr_get_u64(r + 8);
            sv->y = (int64_t)tr_get_u64(r + 16);
            memcpy(&sv->z, &zb, sizeof sv->z);
            if (sv->id < lo || sv->id >= hi || sv->x < 0 || sv->y < 0 ||
                sv->x > GDT_COORD_MAX || sv->y > GDT_COORD_MAX)
                return gdt_error_set(err, GDT_EJOB, 6802,
                                     "%s: seam vertex %" PRIu64 " is not one of the tile's "
                                     "vertices in the merge frame",
                                     path, done + i);
            s->nv++;
        }
        done += m;
    }
    for (uint64_t done = 0; done < ne;) {
        size_t m = ne - done < TR_CHUNK ? (size_t)(ne - done) : TR_CHUNK;
        if (fread(scratch, 16, m, f) != m)
            return gdt_error_set(err, GDT_EIO, 4805, "%s: read failed", path);
        for (size_t i = 0; i < m; i++) {
            gdt_seam_edge *e = &s->e[s->ne];
            e->a = tr_get_u64(scratch + 16 * i);
            e->b = tr_get_u64(scratch + 16 * i + 8);
            if (e->a < lo || e->a >= hi || e->b < lo || e->b >= hi)
                return gdt_error_set(err, GDT_EJOB, 6802,
                                     "%s: barrier edge %" PRIu64 " names another tile's vertex",
                                     path, done + i);
            s->ne++;
        }
        done += m;
    }
    return GDT_OK;
}

gdt_status tr_tri_read_open(FILE *f, uint64_t size, const tr_tri_expect *ex,
                            gdt_trim_open **open, size_t *nopen, size_t *cap_open,
                            unsigned char *scratch, const char *path, gdt_error *err)
{
    unsigned char hdr[TR_HEADER], th[TT_HEADER];
    uint64_t nf, nv, ne, at, lo = ex->base, hi = ex->base + ex->points;
    tr_trim_counts tc;

    *nopen = 0;
    if (fseeko(f, 0, SEEK_SET) != 0 || fread(hdr, 1, TR_HEADER, f) != TR_HEADER)
        return gdt_error_set(err, GDT_EIO, 4805, "%s: read failed", path);
    if (tr_tri_check_header(hdr, size, ex, &nf, &nv, &ne) != TR_TRI_FITS)
        return gdt_error_set(err, GDT_EJOB, 6801, "%s: not the tile file this run wrote", path);
    at = TR_HEADER + 12 * nf + TR_SEAM_VERTEX * nv + 16 * ne;
    if (fseeko(f, (off_t)at, SEEK_SET) != 0 || fread(th, 1, TT_HEADER, f) != TT_HEADER)
        return gdt_error_set(err, GDT_EIO, 4805, "%s: read failed", path);
    if (tr_trim_check(th, at, size, nf, &tc) != 0)
        return gdt_error_set(err, GDT_EJOB, 6802, "%s: its trim section does not fit the file",
                             path);
    if (fseeko(f, (off_t)(at + TT_HEADER + 4 * tc.ncut + 8 * tc.ncand), SEEK_SET) != 0)
        return gdt_error_set(err, GDT_EIO, 4805, "%s: cannot seek: %s", path, strerror(errno));
    if (tc.nopen > SIZE_MAX || gdt_grow(open, cap_open, (size_t)tc.nopen, sizeof **open, 256) != 0)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    for (uint64_t done = 0; done < tc.nopen;) {
        size_t m = tc.nopen - done < TR_CHUNK ? (size_t)(tc.nopen - done) : TR_CHUNK;
        if (fread(scratch, 20, m, f) != m)
            return gdt_error_set(err, GDT_EIO, 4805, "%s: read failed", path);
        for (size_t i = 0; i < m; i++) {
            gdt_trim_open *e = &(*open)[*nopen];
            e->a = tr_get_u64(scratch + 20 * i);
            e->b = tr_get_u64(scratch + 20 * i + 8);
            e->label = tr_get_u32(scratch + 20 * i + 16);
            if (e->a < lo || e->b >= hi || e->a >= e->b || e->label >= nf)
                return gdt_error_set(err, GDT_EJOB, 6802,
                                     "%s: open edge %" PRIu64 " of its trim section is not "
                                     "an edge of the tile",
                                     path, done + i);
            (*nopen)++;
        }
        done += m;
    }
    return GDT_OK;
}

gdt_status tr_interrupted(const char *job, const char *where, gdt_error *err)
{
    return gdt_error_set(err, GDT_EINTERRUPTED, 1302,
                         "stopped by a signal during %s; rerun the same command (or "
                         "gdt-tile --resume %s) to continue",
                         where, job);
}

gdt_status tr_write_direct(int fd, int *direct, const unsigned char *buf, size_t len,
                           const char *path, gdt_error *err)
{
    size_t done = 0;
    int e = gdt_dio_write_blocks(fd, direct, buf, len, &done);

    if (e == 0 && *direct)
        e = gdt_dio_end(fd, direct); /* the tail through the page cache */
    while (e == 0 && done < len) {
        ssize_t w = write(fd, buf + done, len - done);
        if (w < 0 && errno == EINTR)
            continue;
        if (w <= 0)
            e = w < 0 ? errno : EIO;
        else
            done += (size_t)w;
    }
    if (e != 0)
        return gdt_error_set(err, GDT_EIO, 4803, "%s: write failed: %s", path, strerror(e));
    return GDT_OK;
}

gdt_status tr_dread_open(tr_dread *r, const char *path, size_t cap, int cached, gdt_error *err)
{
    void *buf = NULL;
    memset(r, 0, sizeof *r);
    r->fd = -1;
    r->path = strdup(path);
    if (r->path != NULL && cap != 0 && cap % GDT_DIO_BLOCK == 0 &&
        posix_memalign(&buf, GDT_DIO_BLOCK, cap) == 0)
        r->buf = buf;
    if (r->buf == NULL) {
        tr_dread_close(r);
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    }
    r->cap = cap;
    if (cached) {
        r->fd = open(path, O_RDONLY | O_CLOEXEC);
        if (r->fd >= 0) /* advice only: nothing to do when it is not taken */
            (void)posix_fadvise(r->fd, 0, 0, POSIX_FADV_SEQUENTIAL);
    } else {
        r->fd = gdt_dio_open_read(path, &r->direct);
    }
    if (r->fd < 0) {
        int e = errno;
        gdt_status st =
            gdt_error_set(err, GDT_EIO, 4805, "%s: cannot open: %s", path, strerror(e));
        tr_dread_close(r);
        return st;
    }
    return GDT_OK;
}

/* Refills buf from the file (len = 0 at its end).  While direct, off is a
 * multiple of GDT_DIO_BLOCK: a read that returns a partial block is the end of
 * the file, or else the reader leaves direct mode. */
static gdt_status dread_fill(tr_dread *r, gdt_error *err)
{
    r->pos = r->len = 0;
    for (;;) {
        ssize_t k = pread(r->fd, r->buf, r->cap, (off_t)r->off);
        if (k < 0 && errno == EINTR)
            continue;
        if (k < 0 && errno == EINVAL && r->direct) {
            if (gdt_dio_end(r->fd, &r->direct) != 0)
                break;
            continue;
        }
        if (k < 0)
            break;
        r->off += (uint64_t)k;
        r->len = (size_t)k;
        if (r->direct && (size_t)k % GDT_DIO_BLOCK != 0 && gdt_dio_end(r->fd, &r->direct) != 0)
            break;
        return GDT_OK;
    }
    return gdt_error_set(err, GDT_EIO, 4806, "%s: read failed: %s", r->path, strerror(errno));
}

gdt_status tr_dread_bytes(tr_dread *r, void *dst, size_t n, size_t *got, gdt_error *err)
{
    unsigned char *d = dst;
    *got = 0;
    while (*got < n) {
        size_t m;
        if (r->pos == r->len) {
            gdt_status st = dread_fill(r, err);
            if (st != GDT_OK)
                return st;
            if (r->len == 0)
                break;
        }
        m = n - *got < r->len - r->pos ? n - *got : r->len - r->pos;
        memcpy(d + *got, r->buf + r->pos, m);
        r->pos += m;
        *got += m;
    }
    return GDT_OK;
}

void tr_dread_close(tr_dread *r)
{
    if (r->fd >= 0)
        close(r->fd);
    r->fd = -1;
    free(r->buf);
    free(r->path);
    r->buf = NULL;
    r->path = NULL;
}

gdt_status tr_commit_tmp(int *fd, const char *tmp, const char *path, int nosync,
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

gdt_status tr_write_atomic(const char *path, const unsigned char *buf, size_t len, int nosync,
                           int cached, gdt_error *err)
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
    if (cached) {
        direct = 0;
        fd = open(tmp, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    } else {
        fd = gdt_dio_create(tmp, 0644, &direct);
    }
    if (fd < 0) {
        st = gdt_error_set(err, GDT_EIO, 4802, "%s: cannot create: %s", tmp, strerror(errno));
        goto fail;
    }
    st = tr_write_direct(fd, &direct, buf, len, tmp, err);
    if (st == GDT_OK)
        st = tr_commit_tmp(&fd, tmp, path, nosync, err);
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
