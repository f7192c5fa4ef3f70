/* tiled_files.c — paths, messages and direct I/O shared by the stages of
 * the tiled run (see private/tiled_files.h). */
#include "private/tiled_files.h"

#include <errno.h>
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

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

gdt_status tr_open_tri(const char *tiles_dir, const gdt_tile_desc *d, uint64_t base, FILE **f,
                       unsigned char hdr[TR_HEADER], uint64_t *size, char **path,
                       gdt_error *err)
{
    struct stat sb;
    gdt_status st = tr_tile_path(tiles_dir, d, "tri", path, err);

    *f = NULL;
    if (st != GDT_OK)
        return st;
    *f = fopen(*path, "rb");
    if (*f == NULL || fstat(fileno(*f), &sb) != 0) {
        st = gdt_error_set(err, GDT_EIO, 4805, "%s: cannot open: %s", *path, strerror(errno));
    } else if (fread(hdr, 1, TR_HEADER, *f) != TR_HEADER || memcmp(hdr, TR_MAGIC, 8) != 0 ||
               tr_get_u64(hdr + 8) != base || tr_get_u64(hdr + 16) != d->points) {
        st = gdt_error_set(err, GDT_EJOB, 6801, "%s: not the tile file this run wrote", *path);
    } else {
        *size = (uint64_t)sb.st_size;
        return GDT_OK;
    }
    if (*f != NULL)
        fclose(*f);
    *f = NULL;
    return st;
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

gdt_status tr_dread_open(tr_dread *r, const char *path, size_t cap, gdt_error *err)
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
    r->fd = gdt_dio_open_read(path, &r->direct);
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
