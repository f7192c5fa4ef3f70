/* Streaming binary little-endian PLY writer (see gdt_ply.h). */
#define _GNU_SOURCE 1 /* sync_file_range */
#include "gdt_ply.h"
#include "gdt_direct_io.h"
#include "gdt_outfile.h"
#include "private/bytes.h"
#include "private/fd_io.h"

#include <errno.h>
#include <fcntl.h>
#include <inttypes.h>
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#ifndef GDT_VERSION
#error "GDT_VERSION must be defined by the build"
#endif

#define PLY_VERTEX_BYTES 24u
#define PLY_FACE_BYTES 13u

/* Invariants:
 *  - the file holds `flushed` bytes, buf holds the next `fill` bytes;
 *  - fd >= 0 and tmp_exists == 1 while the writer is usable;
 *  - fail.status != GDT_OK once anything failed; the temporary is then
 *    already closed and removed, and every call returns fail again;
 *  - vcount_off/fcount_off are file offsets of the fixed-width count fields;
 *  - direct: fd was opened with O_DIRECT and flushed is a multiple of
 *    GDT_DIO_BLOCK.  The file is written once and not read back here,
 *    so the writer bypasses the page cache where the file system allows it:
 *    a buffered write first fills fresh page-cache pages, which on a large
 *    output costs more system time than the write itself.  The last partial
 *    block goes through the page cache (O_DIRECT cleared). */
struct gdt_ply_writer {
    char *path;
    char *tmp_path;
    char *dir_path;
    int fd;
    int tmp_exists;
    unsigned char *buf;
    size_t fill;
    uint64_t flushed;
    uint64_t nvert;
    uint64_t nface;
    uint64_t vcount_off;
    uint64_t fcount_off;
    int in_faces;
    int direct;
    int parts;  /* gdt_ply_begin_parts: the records are written by gdt_ply_part */
    gdt_error fail;
};

/* Closes and removes the temporary, if still there. */
static void ply_discard(gdt_ply_writer *w)
{
    if (w->fd >= 0) {
        close(w->fd);
        w->fd = -1;
    }
    if (w->tmp_exists) {
        unlink(w->tmp_path);
        w->tmp_exists = 0;
    }
}

static void ply_free(gdt_ply_writer *w)
{
    free(w->buf);
    free(w->path);
    free(w->tmp_path);
    free(w->dir_path);
    free(w);
}

/* Records the writer's first failure, discards the temporary, and reports
 * the first failure (the root cause) through err. */
static gdt_status ply_fail(gdt_ply_writer *w, gdt_error *err, gdt_status st, int code,
                           const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 5, 6)))
#endif
    ;

static gdt_status ply_fail(gdt_ply_writer *w, gdt_error *err, gdt_status st, int code,
                           const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    gdt_error_vset(&w->fail, st, code, fmt, ap);
    va_end(ap);
    ply_discard(w);
    return gdt_error_set(err, w->fail.status, w->fail.code, "%s", w->fail.msg);
}

/* Returns the sticky failure of a writer that failed before. */
static gdt_status ply_refail(const gdt_ply_writer *w, gdt_error *err)
{
    return gdt_error_set(err, w->fail.status, w->fail.code, "%s", w->fail.msg);
}

/* Writes out the buffer: all of it (all != 0), else at least the whole
 * blocks of a direct writer, whose partial block stays at the start of buf.
 * The last write (all) leaves direct mode: the tail, and the counts
 * patched in place, go through the page cache. */
static gdt_status ply_write_out(gdt_ply_writer *w, int all, gdt_error *err)
{
    size_t head = w->fill;
    int e = 0;

    if (w->direct) {
        e = gdt_dio_write_blocks(w->fd, &w->direct, w->buf, w->fill, &head);
        w->flushed += head;
        w->fill -= head;
        memmove(w->buf, w->buf + head, w->fill);
        if (e == 0 && w->direct && all)
            e = gdt_dio_end(w->fd, &w->direct);
        head = w->direct ? 0 : w->fill;
    }
    if (e == 0 && head > 0)
        e = gdt_fd_write_all(w->fd, w->buf, head, -1);
    if (e != 0)
        return ply_fail(w, err, GDT_EIO, 4702, "%s: write failed (temporary %s removed): %s",
                        w->path, w->tmp_path, strerror(e));
    if (head > 0) {
        w->flushed += head;
        w->fill -= head;
        memmove(w->buf, w->buf + head, w->fill);
    }
    return GDT_OK;
}

/* Makes room in the buffer (at least GDT_DIO_BLOCK bytes free after it). */
static gdt_status ply_flush(gdt_ply_writer *w, gdt_error *err)
{
    return ply_write_out(w, 0, err);
}

/* ply_flush for a loop that keeps the buffer's fill in *fill. */
static gdt_status ply_room(gdt_ply_writer *w, size_t *fill, gdt_error *err)
{
    gdt_status st;
    w->fill = *fill;
    st = ply_flush(w, err);
    *fill = w->fill;
    return st;
}

/* Appends raw bytes of any length through the buffer. */
static gdt_status ply_put(gdt_ply_writer *w, const void *data, size_t n, gdt_error *err)
{
    const unsigned char *p = data;
    while (n > 0) {
        size_t room = GDT_PLY_BUFFER_BYTES - w->fill;
        size_t k = n < room ? n : room;
        memcpy(w->buf + w->fill, p, k);
        w->fill += k;
        p += k;
        n -= k;
        if (w->fill == GDT_PLY_BUFFER_BYTES && ply_flush(w, err) != GDT_OK)
            return w->fail.status;
    }
    return GDT_OK;
}

static gdt_status ply_puts(gdt_ply_writer *w, const char *s, gdt_error *err)
{
    return ply_put(w, s, strlen(s), err);
}

/* Formats d with %.17g into out (>= 32 bytes) independently of LC_NUMERIC:
 * whatever the locale uses as decimal point becomes '.'.  d is finite. */
static void format_exact(char *out, size_t size, double d)
{
    char tmp[64];
    size_t j = 0;
    int in_point = 0;

    snprintf(tmp, sizeof tmp, "%.17g", d);
    for (size_t i = 0; tmp[i] != '\0' && j + 1 < size; i++) {
        char c = tmp[i];
        if ((c >= '0' && c <= '9') || c == '-' || c == '+' || c == 'e') {
            out[j++] = c;
            in_point = 0;
        } else if (!in_point) {
            out[j++] = '.';
            in_point = 1;
        }
    }
    out[j] = '\0';
}

/* A comment byte is acceptable when it is printable ASCII or a tab. */
static int comment_byte_ok(unsigned char c)
{
    return c == '\t' || (c >= 0x20 && c < 0x7f);
}

static gdt_status check_meta(const char *path, const gdt_ply_meta *meta, gdt_error *err)
{
    const gdt_lattice *l = &meta->lattice;

    if (meta->epsg < 0)
        return gdt_error_set(err, GDT_EINTERNAL, 7701, "%s: negative EPSG code %d", path,
                             meta->epsg);
    if (!isfinite(l->sx) || !isfinite(l->sy) || !isfinite(l->ox) || !isfinite(l->oy) ||
        !(l->sx > 0.0) || !(l->sy > 0.0))
        return gdt_error_set(err, GDT_EINTERNAL, 7703,
                             "%s: lattice (%g %g %g %g) must be finite with positive spacing", path,
                             l->sx, l->sy, l->ox, l->oy);
    if (meta->ncomments > 0 && meta->comments == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7701, "%s: %zu comments but no array", path,
                             meta->ncomments);
    for (size_t i = 0; i < meta->ncomments; i++) {
        const unsigned char *c = (const unsigned char *)meta->comments[i];
        if (c == NULL)
            return gdt_error_set(err, GDT_EINTERNAL, 7701, "%s: comment %zu is NULL", path, i);
        for (size_t k = 0; c[k] != '\0'; k++) {
            if (!comment_byte_ok(c[k]))
                return gdt_error_set(err, GDT_EINTERNAL, 7702,
                                     "%s: comment %zu has byte 0x%02x at offset %zu (%s); "
                                     "header comments must be one line of printable ASCII",
                                     path, i, c[k], k,
                                     c[k] == '\n' || c[k] == '\r' ? "line break"
                                                                  : "not printable ASCII");
        }
    }
    return GDT_OK;
}

/* Writes "comment crs ...\n". */
static gdt_status put_crs(gdt_ply_writer *w, const gdt_ply_meta *meta, gdt_error *err)
{
    char line[64];

    if (meta->epsg > 0) {
        snprintf(line, sizeof line, "comment crs EPSG:%d\n", meta->epsg);
        return ply_puts(w, line, err);
    }
    if (meta->crs_wkt == NULL || meta->crs_wkt[0] == '\0')
        return ply_puts(w, "comment crs unknown\n", err);
    if (ply_puts(w, "comment crs ", err) != GDT_OK)
        return w->fail.status;
    for (const unsigned char *p = (const unsigned char *)meta->crs_wkt; *p != '\0'; p++) {
        char c = (char)*p;
        if (*p >= 0x80)
            c = '?';
        else if (*p < 0x20 || *p == 0x7f)
            c = ' ';
        if (ply_put(w, &c, 1, err) != GDT_OK)
            return w->fail.status;
    }
    return ply_puts(w, "\n", err);
}

/* Writes "<prefix><count field>\n" and records the field's file offset. */
static gdt_status put_count_line(gdt_ply_writer *w, const char *prefix, uint64_t *off,
                                 gdt_error *err)
{
    char field[GDT_PLY_COUNT_WIDTH + 2];

    if (ply_puts(w, prefix, err) != GDT_OK)
        return w->fail.status;
    *off = w->flushed + w->fill;
    snprintf(field, sizeof field, "%-*d\n", GDT_PLY_COUNT_WIDTH, 0);
    return ply_puts(w, field, err);
}

static gdt_status put_header(gdt_ply_writer *w, const gdt_ply_meta *meta, gdt_error *err)
{
    char num[4][40];
    char line[256];

    if (ply_puts(w,
                 "ply\nformat binary_little_endian 1.0\n"
                 "comment generator gdt-tile " GDT_VERSION "\n",
                 err) != GDT_OK ||
        put_crs(w, meta, err) != GDT_OK)
        return w->fail.status;
    format_exact(num[0], sizeof num[0], meta->lattice.sx);
    format_exact(num[1], sizeof num[1], meta->lattice.sy);
    format_exact(num[2], sizeof num[2], meta->lattice.ox);
    format_exact(num[3], sizeof num[3], meta->lattice.oy);
    snprintf(line, sizeof line, "comment lattice %s %s %s %s\n", num[0], num[1], num[2], num[3]);
    if (ply_puts(w, line, err) != GDT_OK)
        return w->fail.status;
    for (size_t i = 0; i < meta->ncomments; i++) {
        if (ply_puts(w, "comment ", err) != GDT_OK ||
            ply_puts(w, meta->comments[i], err) != GDT_OK || ply_puts(w, "\n", err) != GDT_OK)
            return w->fail.status;
    }
    if (put_count_line(w, "element vertex ", &w->vcount_off, err) != GDT_OK ||
        ply_puts(w, "property double x\nproperty double y\nproperty double z\n", err) != GDT_OK ||
        put_count_line(w, "element face ", &w->fcount_off, err) != GDT_OK ||
        ply_puts(w, "property list uchar int vertex_indices\nend_header\n", err) != GDT_OK)
        return w->fail.status;
    return GDT_OK;
}

gdt_status gdt_ply_create(gdt_ply_writer **out, const char *path, const gdt_ply_meta *meta,
                          gdt_error *err)
{
    gdt_ply_writer *w = NULL;
    gdt_status st;
    struct stat sb;
    size_t len;

    if (out == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7701, "PLY writer: NULL output argument");
    *out = NULL;
    if (path == NULL || path[0] == '\0' || meta == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7701, "PLY writer: %s",
                             meta == NULL ? "NULL metadata" : "empty output path");
    st = check_meta(path, meta, err);
    if (st != GDT_OK)
        return st;
    len = strlen(path);
    if (path[len - 1] == '/' || (stat(path, &sb) == 0 && S_ISDIR(sb.st_mode)))
        return gdt_error_set(err, GDT_EIO, 4707, "%s: is a directory, not a file name", path);
    st = gdt_outfile_check(path, err);
    if (st != GDT_OK)
        return st;

    w = calloc(1, sizeof *w);
    if (w == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    w->fd = -1;
    gdt_error_clear(&w->fail);
    w->path = strdup(path);
    w->dir_path = gdt_outfile_dir(path);
    w->tmp_path = gdt_outfile_temp(path);
    {
        void *buf = NULL;
        w->buf = posix_memalign(&buf, GDT_DIO_BLOCK, GDT_PLY_BUFFER_BYTES) == 0 ? buf : NULL;
    }
    if (w->path == NULL || w->dir_path == NULL || w->tmp_path == NULL || w->buf == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    w->fd = gdt_dio_create(w->tmp_path, 0666, &w->direct);
    if (w->fd < 0) {
        st = gdt_error_set(err, GDT_EIO, 4701, "%s: cannot create temporary file %s: %s", path,
                           w->tmp_path, strerror(errno));
        goto fail;
    }
    w->tmp_exists = 1;
    st = put_header(w, meta, err);
    if (st != GDT_OK)
        goto fail;
    *out = w;
    return GDT_OK;

fail:
    ply_discard(w);
    ply_free(w);
    return st;
}

gdt_status gdt_ply_write_vertices(gdt_ply_writer *w, const double *xyz, size_t n, gdt_error *err)
{
    size_t fill;

    if (w == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7701, "PLY writer: NULL writer");
    if (w->fail.status != GDT_OK)
        return ply_refail(w, err);
    if (w->parts)
        return ply_fail(w, err, GDT_EINTERNAL, 7720, "%s: vertices appended to a file written in parts",
                        w->path);
    if (w->in_faces)
        return ply_fail(w, err, GDT_EINTERNAL, 7704,
                        "%s: vertices written after the first face (%" PRIu64 " faces so far)",
                        w->path, w->nface);
    if ((uint64_t)n > GDT_PLY_MAX_VERTICES - w->nvert)
        return ply_fail(w, err, GDT_EINPUT, 3701,
                        "%s: %" PRIu64 " + %zu vertices exceed the PLY limit of %" PRIu64
                        " (vertex indices are 32-bit signed integers)",
                        w->path, w->nvert, n, GDT_PLY_MAX_VERTICES);
    if (n > 0 && xyz == NULL)
        return ply_fail(w, err, GDT_EINTERNAL, 7701, "%s: NULL vertex array", w->path);
    /* fill is kept in a local: the byte stores could alias w->fill */
    fill = w->fill;
    for (size_t i = 0; i < n; i++) {
        const double *v = xyz + 3 * i;
        unsigned char *p;
        if (!isfinite(v[0]) || !isfinite(v[1]) || !isfinite(v[2]))
            return ply_fail(w, err, GDT_EINTERNAL, 7707,
                            "%s: vertex %" PRIu64 " is not finite (%g %g %g)", w->path,
                            w->nvert + i, v[0], v[1], v[2]);
        if (GDT_PLY_BUFFER_BYTES - fill < PLY_VERTEX_BYTES && ply_room(w, &fill, err) != GDT_OK)
            return w->fail.status;
        p = w->buf + fill;
        gdt_le_put_f64(p, v[0]);
        gdt_le_put_f64(p + 8, v[1]);
        gdt_le_put_f64(p + 16, v[2]);
        fill += PLY_VERTEX_BYTES;
    }
    w->fill = fill;
    w->nvert += n;
    return GDT_OK;
}

gdt_status gdt_ply_write_faces(gdt_ply_writer *w, const int32_t *tri, size_t n, gdt_error *err)
{
    size_t fill;
    uint64_t nvert;

    if (w == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7701, "PLY writer: NULL writer");
    if (w->fail.status != GDT_OK)
        return ply_refail(w, err);
    if (n > 0 && tri == NULL)
        return ply_fail(w, err, GDT_EINTERNAL, 7701, "%s: NULL face array", w->path);
    if (w->parts)
        return ply_fail(w, err, GDT_EINTERNAL, 7720, "%s: faces appended to a file written in parts",
                        w->path);
    w->in_faces = 1;
    /* fill and nvert are kept in locals: the byte stores could alias w */
    fill = w->fill;
    nvert = w->nvert;
    for (size_t i = 0; i < n; i++) {
        const int32_t *t = tri + 3 * i;
        unsigned char *p;
        for (int k = 0; k < 3; k++) {
            if (t[k] < 0 || (uint64_t)t[k] >= nvert)
                return ply_fail(w, err, GDT_EINTERNAL, 7705,
                                "%s: face %" PRIu64 " (%" PRId32 " %" PRId32 " %" PRId32
                                ") has an index outside [0, %" PRIu64 ")",
                                w->path, w->nface + i, t[0], t[1], t[2], w->nvert);
        }
        if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2])
            return ply_fail(w, err, GDT_EINTERNAL, 7706,
                            "%s: face %" PRIu64 " (%" PRId32 " %" PRId32 " %" PRId32
                            ") repeats a vertex",
                            w->path, w->nface + i, t[0], t[1], t[2]);
        if (GDT_PLY_BUFFER_BYTES - fill < PLY_FACE_BYTES && ply_room(w, &fill, err) != GDT_OK)
            return w->fail.status;
        p = w->buf + fill;
        p[0] = 3;
        gdt_le_put_u32(p + 1, (uint32_t)t[0]);
        gdt_le_put_u32(p + 5, (uint32_t)t[1]);
        gdt_le_put_u32(p + 9, (uint32_t)t[2]);
        fill += PLY_FACE_BYTES;
    }
    w->fill = fill;
    w->nface += n;
    return GDT_OK;
}

uint64_t gdt_ply_vertex_count(const gdt_ply_writer *w)
{
    return w != NULL ? w->nvert : 0;
}

uint64_t gdt_ply_face_count(const gdt_ply_writer *w)
{
    return w != NULL ? w->nface : 0;
}

const char *gdt_ply_temp_path(const gdt_ply_writer *w)
{
    return w != NULL ? w->tmp_path : NULL;
}

static gdt_status patch_count(gdt_ply_writer *w, uint64_t off, uint64_t count, gdt_error *err)
{
    char field[GDT_PLY_COUNT_WIDTH + 1];
    int e;

    snprintf(field, sizeof field, "%-*" PRIu64, GDT_PLY_COUNT_WIDTH, count);
    e = gdt_fd_write_all(w->fd, field, GDT_PLY_COUNT_WIDTH, (int64_t)off);
    if (e != 0)
        return ply_fail(w, err, GDT_EIO, 4702,
                        "%s: writing the element counts failed (temporary %s removed): %s", w->path,
                        w->tmp_path, strerror(e));
    return GDT_OK;
}

/* Patches the counts, syncs, closes and renames the temporary over the
 * path, syncs the directory; frees w (also on failure). */
static gdt_status ply_commit(gdt_ply_writer *w, gdt_error *err)
{
    gdt_status st;
    int e;

    st = patch_count(w, w->vcount_off, w->nvert, err);
    if (st != GDT_OK)
        goto fail;
    st = patch_count(w, w->fcount_off, w->nface, err);
    if (st != GDT_OK)
        goto fail;
    if (fsync(w->fd) != 0) {
        st = ply_fail(w, err, GDT_EIO, 4703, "%s: fsync failed (temporary %s removed): %s", w->path,
                      w->tmp_path, strerror(errno));
        goto fail;
    }
    e = close(w->fd);
    w->fd = -1;
    if (e != 0) {
        st = ply_fail(w, err, GDT_EIO, 4704, "%s: close failed (temporary %s removed): %s", w->path,
                      w->tmp_path, strerror(errno));
        goto fail;
    }
    {
        /* the path may have changed since the start: never rename over a
         * special file or a link */
        gdt_error e2;
        gdt_error_clear(&e2);
        if (gdt_outfile_check(w->path, &e2) != GDT_OK) {
            st = ply_fail(w, err, e2.status, e2.code, "%s (temporary %s removed)", e2.msg,
                          w->tmp_path);
            goto fail;
        }
    }
    if (rename(w->tmp_path, w->path) != 0) {
        st = ply_fail(w, err, GDT_EIO, 4705, "%s: cannot rename %s to it (temporary removed): %s",
                      w->path, w->tmp_path, strerror(errno));
        goto fail;
    }
    w->tmp_exists = 0;
    e = gdt_outfile_sync_dir(w->dir_path);
    if (e != 0) {
        st = gdt_error_set(err, GDT_EIO, 4706,
                           "%s: written, but syncing its directory %s failed: %s", w->path,
                           w->dir_path, strerror(e));
        goto fail;
    }
    ply_free(w);
    return GDT_OK;

fail:
    ply_discard(w);
    ply_free(w);
    return st;
}


gdt_status gdt_ply_finish(gdt_ply_writer *w, gdt_error *err)
{
    gdt_status st;

    if (w == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7701, "PLY writer: NULL writer");
    if (w->fail.status != GDT_OK)
        st = ply_refail(w, err);
    else if (w->parts)
        st = ply_fail(w, err, GDT_EINTERNAL, 7720,
                      "%s: a file written in parts is finished by gdt_ply_finish_parts", w->path);
    else
        st = ply_write_out(w, 1, err);
    if (st != GDT_OK) {
        ply_discard(w);
        ply_free(w);
        return st;
    }
    return ply_commit(w, err);
}

gdt_status gdt_ply_begin_parts(gdt_ply_writer *w, uint64_t nvert, uint64_t *header_bytes,
                               gdt_error *err)
{
    if (w == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7701, "PLY writer: NULL writer");
    if (w->fail.status != GDT_OK)
        return ply_refail(w, err);
    if (w->parts || w->nvert != 0 || w->in_faces)
        return ply_fail(w, err, GDT_EINTERNAL, 7720,
                        "%s: parts begun after records were written", w->path);
    if (nvert > GDT_PLY_MAX_VERTICES)
        return ply_fail(w, err, GDT_EINPUT, 3701,
                        "%s: %" PRIu64 " vertices exceed the PLY limit of %" PRIu64
                        " (vertex indices are 32-bit signed integers)",
                        w->path, nvert, GDT_PLY_MAX_VERTICES);
    if (ply_write_out(w, 1, err) != GDT_OK) /* the header, through the page cache */
        return w->fail.status;
    w->parts = 1;
    w->nvert = nvert;
    *header_bytes = w->flushed;
    return GDT_OK;
}

gdt_status gdt_ply_finish_parts(gdt_ply_writer *w, uint64_t nface, gdt_error *err)
{
    struct stat sb;
    gdt_status st = GDT_OK;

    if (w == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7701, "PLY writer: NULL writer");
    if (w->fail.status != GDT_OK)
        st = ply_refail(w, err);
    else if (!w->parts)
        st = ply_fail(w, err, GDT_EINTERNAL, 7720, "%s: not written in parts", w->path);
    else if (fstat(w->fd, &sb) != 0)
        st = ply_fail(w, err, GDT_EIO, 4702, "%s: cannot stat %s (temporary removed): %s",
                      w->path, w->tmp_path, strerror(errno));
    else if ((uint64_t)sb.st_size !=
             w->flushed + PLY_VERTEX_BYTES * w->nvert + PLY_FACE_BYTES * nface)
        st = ply_fail(w, err, GDT_EINTERNAL, 7721,
                      "%s: the parts hold %lld bytes, not the %" PRIu64 " of a header, %" PRIu64
                      " vertices and %" PRIu64 " faces (temporary %s removed)",
                      w->path, (long long)sb.st_size,
                      w->flushed + PLY_VERTEX_BYTES * w->nvert + PLY_FACE_BYTES * nface,
                      w->nvert, nface, w->tmp_path);
    if (st != GDT_OK) {
        ply_discard(w);
        ply_free(w);
        return st;
    }
    w->nface = nface;
    return ply_commit(w, err);
}

/* ---- one process's parts ----
 *
 * A part's records go to the disk from a writer thread of its own, with
 * direct I/O for the whole 4 KiB blocks of each chunk and through the page
 * cache for the partial blocks at its two ends, which it may share with
 * another part (another process's, or this part's previous chunk): the
 * caller formats chunk k + 1 while the disk takes chunk k, and no record is
 * copied into the page cache (two processes copying the whole mesh there
 * cost a second of system time on 10M points).  A block written directly
 * lies inside one chunk, so no other write ever touches it and the two
 * paths never meet in one block.
 *
 * Invariants: slots [head, head + queued) (mod PART_SLOTS) wait for the
 * writer, in submission order, the first of them being written while busy;
 * the caller fills slot (head + queued) % PART_SLOTS, so it waits only when
 * every slot is queued.  A chunk at file offset off starts at
 * mem + off % GDT_DIO_BLOCK of its slot, so file blocks and memory blocks
 * are aligned alike.  wr_errno is the first failed write (errno), sticky:
 * later chunks are dropped and every later call fails.  Without a thread
 * (threaded == 0: it could not be started) the caller writes each chunk at
 * once, the same way. */
#define PART_SLOTS 3
#define PART_CHUNK GDT_PLY_BUFFER_BYTES

typedef struct part_slot {
    unsigned char *mem; /* PART_CHUNK + GDT_DIO_BLOCK bytes, aligned to GDT_DIO_BLOCK */
    size_t n;           /* bytes of the chunk */
    uint64_t off;       /* its file offset */
} part_slot;

struct gdt_ply_part {
    char *path; /* the temporary */
    int fd;     /* through the page cache */
    int dfd;    /* O_DIRECT, or -1 (not accepted, or refused later) */
    uint64_t header, nvert;
    part_slot slot[PART_SLOTS];
    pthread_t tid;
    int threaded;
    pthread_mutex_t mu;
    pthread_cond_t cv;
    int head, queued, stop;
    int wr_errno;
    uint64_t direct_bytes; /* written directly by the chunks done */
};

/* Writes buf[0, n) at off through the page cache and starts its writeback
 * at once (where the system can), so that the sync at the end has little
 * left to wait for.  returns: 0 or errno. */
static int part_buffered(gdt_ply_part *p, const unsigned char *buf, size_t n, uint64_t off)
{
    int e = n > 0 ? gdt_fd_write_all(p->fd, buf, n, (int64_t)off) : 0;
#ifdef SYNC_FILE_RANGE_WRITE
    if (e == 0 && n > 0)
        (void)sync_file_range(p->fd, (off_t)off, (off_t)n, SYNC_FILE_RANGE_WRITE);
#endif
    return e;
}

/* Writes slot s's chunk: its whole blocks directly while the file system
 * takes them (a refusal, EINVAL, sends this and every later chunk through
 * the page cache), the rest through the page cache.  returns: 0 or errno. */
static int part_write_slot(gdt_ply_part *p, const part_slot *s, uint64_t *direct)
{
    const uint64_t B = GDT_DIO_BLOCK;
    const unsigned char *b = s->mem + s->off % B;
    uint64_t lo = (s->off + B - 1) / B * B, hi = (s->off + s->n) / B * B, at;
    int e;

    if (p->dfd < 0 || lo >= hi)
        return part_buffered(p, b, s->n, s->off);
    /* lo < hi: a whole block at least */
    e = part_buffered(p, b, (size_t)(lo - s->off), s->off);
    for (at = lo; e == 0 && at < hi;) {
        ssize_t k = pwrite(p->dfd, b + (at - s->off), (size_t)(hi - at), (off_t)at);
        if (k < 0 && errno == EINTR)
            continue;
        if ((k < 0 && errno == EINVAL) || (k > 0 && (uint64_t)k % B != 0)) {
            if (k > 0)
                at += (uint64_t)k;
            close(p->dfd);
            p->dfd = -1;
            break;
        }
        if (k <= 0)
            e = k < 0 ? errno : EIO;
        else
            at += (uint64_t)k;
    }
    *direct += at - lo;
    if (e == 0)
        e = part_buffered(p, b + (at - s->off), (size_t)(s->off + s->n - at), at);
    return e;
}

static void *part_writer_main(void *arg)
{
    gdt_ply_part *p = arg;
    pthread_mutex_lock(&p->mu);
    for (;;) {
        while (p->queued == 0 && !p->stop)
            pthread_cond_wait(&p->cv, &p->mu);
        if (p->queued == 0)
            break;
        {
            const part_slot *s = &p->slot[p->head];
            int drop = p->wr_errno != 0, e = 0;
            uint64_t direct = 0;
            pthread_mutex_unlock(&p->mu);
            if (!drop)
                e = part_write_slot(p, s, &direct);
            pthread_mutex_lock(&p->mu);
            p->direct_bytes += direct;
            if (e != 0 && p->wr_errno == 0)
                p->wr_errno = e;
        }
        p->head = (p->head + 1) % PART_SLOTS;
        p->queued--;
        pthread_cond_broadcast(&p->cv);
    }
    pthread_mutex_unlock(&p->mu);
    return NULL;
}

static gdt_status part_failed(const gdt_ply_part *p, int e, gdt_error *err)
{
    return gdt_error_set(err, GDT_EIO, 4721, "%s: write failed: %s", p->path, strerror(e));
}

/* The slot to format the chunk at file offset off into: *q is where the
 * chunk's first byte goes.  Waits while every slot is queued.
 * returns: GDT_OK; GDT_EIO 4721 (an earlier chunk failed). */
static gdt_status part_take(gdt_ply_part *p, uint64_t off, unsigned char **q, gdt_error *err)
{
    int e, i;
    if (!p->threaded) {
        *q = p->slot[0].mem + off % GDT_DIO_BLOCK;
        return GDT_OK;
    }
    pthread_mutex_lock(&p->mu);
    while (p->queued == PART_SLOTS && p->wr_errno == 0)
        pthread_cond_wait(&p->cv, &p->mu);
    e = p->wr_errno;
    i = (p->head + p->queued) % PART_SLOTS;
    pthread_mutex_unlock(&p->mu);
    if (e != 0)
        return part_failed(p, e, err);
    *q = p->slot[i].mem + off % GDT_DIO_BLOCK;
    return GDT_OK;
}

/* Hands the chunk formatted by part_take (n bytes at off) to the writer,
 * or writes it now without one.  returns: GDT_OK; GDT_EIO 4721. */
static gdt_status part_submit(gdt_ply_part *p, size_t n, uint64_t off, gdt_error *err)
{
    part_slot *s;
    int e;
    if (!p->threaded) {
        p->slot[0].n = n;
        p->slot[0].off = off;
        e = part_write_slot(p, &p->slot[0], &p->direct_bytes);
        return e != 0 ? part_failed(p, e, err) : GDT_OK;
    }
    pthread_mutex_lock(&p->mu);
    s = &p->slot[(p->head + p->queued) % PART_SLOTS];
    s->n = n;
    s->off = off;
    p->queued++;
    pthread_cond_broadcast(&p->cv);
    e = p->wr_errno;
    pthread_mutex_unlock(&p->mu);
    return e != 0 ? part_failed(p, e, err) : GDT_OK;
}

/* Lets the writer finish the queued chunks and stops it.  returns: its
 * first failure (errno), 0 when none. */
static int part_drain(gdt_ply_part *p)
{
    int e;
    if (!p->threaded)
        return 0;
    pthread_mutex_lock(&p->mu);
    p->stop = 1;
    pthread_cond_broadcast(&p->cv);
    pthread_mutex_unlock(&p->mu);
    pthread_join(p->tid, NULL);
    p->threaded = 0;
    pthread_cond_destroy(&p->cv);
    pthread_mutex_destroy(&p->mu);
    e = p->wr_errno;
    return e;
}

static void part_free(gdt_ply_part *p)
{
    for (int i = 0; i < PART_SLOTS; i++)
        free(p->slot[i].mem);
    free(p->path);
    free(p);
}

gdt_status gdt_ply_part_open(gdt_ply_part **out, const char *tmp_path, uint64_t header_bytes,
                             uint64_t nvert, gdt_error *err)
{
    gdt_ply_part *p = calloc(1, sizeof *p);
    *out = NULL;
    if (p == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    p->fd = p->dfd = -1;
    p->path = strdup(tmp_path);
    int missing = p->path == NULL;
    for (int i = 0; i < PART_SLOTS; i++)
        if (posix_memalign((void **)&p->slot[i].mem, GDT_DIO_BLOCK, PART_CHUNK + GDT_DIO_BLOCK) !=
            0) {
            p->slot[i].mem = NULL;
            missing = 1;
        }
    if (missing) {
        part_free(p);
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    }
    p->header = header_bytes;
    p->nvert = nvert;
    p->fd = open(tmp_path, O_WRONLY | O_CLOEXEC);
    if (p->fd < 0) {
        gdt_status st = gdt_error_set(err, GDT_EIO, 4720, "%s: cannot open to write a part: %s",
                                      tmp_path, strerror(errno));
        part_free(p);
        return st;
    }
    p->dfd = open(tmp_path, O_WRONLY | O_CLOEXEC | O_DIRECT); /* -1: the page cache only */
    if (pthread_mutex_init(&p->mu, NULL) == 0) {
        if (pthread_cond_init(&p->cv, NULL) == 0) {
            p->threaded = pthread_create(&p->tid, NULL, part_writer_main, p) == 0;
            if (!p->threaded)
                pthread_cond_destroy(&p->cv);
        }
        if (!p->threaded)
            pthread_mutex_destroy(&p->mu);
    }
    *out = p;
    return GDT_OK;
}

gdt_status gdt_ply_part_vertices(gdt_ply_part *p, uint64_t first, const double *xyz, size_t n,
                                 gdt_error *err)
{
    const size_t per = GDT_PLY_BUFFER_BYTES / PLY_VERTEX_BYTES;
    if (first > p->nvert || (uint64_t)n > p->nvert - first)
        return gdt_error_set(err, GDT_EINTERNAL, 7722,
                             "%s: vertices %" PRIu64 "..+%zu outside the %" PRIu64 " of the file",
                             p->path, first, n, p->nvert);
    for (size_t done = 0; done < n;) {
        size_t m = n - done < per ? n - done : per;
        const uint64_t off = p->header + PLY_VERTEX_BYTES * (first + done);
        unsigned char *q0 = NULL;
        if (part_take(p, off, &q0, err) != GDT_OK)
            return err->status;
        for (size_t i = 0; i < m; i++) {
            const double *v = xyz + 3 * (done + i);
            unsigned char *q = q0 + PLY_VERTEX_BYTES * i;
            if (!isfinite(v[0]) || !isfinite(v[1]) || !isfinite(v[2]))
                return gdt_error_set(err, GDT_EINTERNAL, 7707,
                                     "%s: vertex %" PRIu64 " is not finite (%g %g %g)", p->path,
                                     first + done + i, v[0], v[1], v[2]);
            gdt_le_put_f64(q, v[0]);
            gdt_le_put_f64(q + 8, v[1]);
            gdt_le_put_f64(q + 16, v[2]);
        }
        if (part_submit(p, PLY_VERTEX_BYTES * m, off, err) != GDT_OK)
            return err->status;
        done += m;
    }
    return GDT_OK;
}

gdt_status gdt_ply_part_faces(gdt_ply_part *p, uint64_t first, const int32_t *tri, size_t n,
                              gdt_error *err)
{
    const size_t per = GDT_PLY_BUFFER_BYTES / PLY_FACE_BYTES;
    const uint64_t at = p->header + PLY_VERTEX_BYTES * p->nvert;
    for (size_t done = 0; done < n;) {
        size_t m = n - done < per ? n - done : per;
        const uint64_t off = at + PLY_FACE_BYTES * (first + done);
        unsigned char *q0 = NULL;
        if (part_take(p, off, &q0, err) != GDT_OK)
            return err->status;
        for (size_t i = 0; i < m; i++) {
            const int32_t *t = tri + 3 * (done + i);
            unsigned char *q = q0 + PLY_FACE_BYTES * i;
            for (int k = 0; k < 3; k++)
                if (t[k] < 0 || (uint64_t)t[k] >= p->nvert)
                    return gdt_error_set(err, GDT_EINTERNAL, 7705,
                                         "%s: face %" PRIu64 " (%" PRId32 " %" PRId32 " %" PRId32
                                         ") has an index outside [0, %" PRIu64 ")",
                                         p->path, first + done + i, t[0], t[1], t[2], p->nvert);
            if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2])
                return gdt_error_set(err, GDT_EINTERNAL, 7706,
                                     "%s: face %" PRIu64 " (%" PRId32 " %" PRId32 " %" PRId32
                                     ") repeats a vertex",
                                     p->path, first + done + i, t[0], t[1], t[2]);
            q[0] = 3;
            gdt_le_put_u32(q + 1, (uint32_t)t[0]);
            gdt_le_put_u32(q + 5, (uint32_t)t[1]);
            gdt_le_put_u32(q + 9, (uint32_t)t[2]);
        }
        if (part_submit(p, PLY_FACE_BYTES * m, off, err) != GDT_OK)
            return err->status;
        done += m;
    }
    return GDT_OK;
}

gdt_status gdt_ply_part_flush(gdt_ply_part *p, gdt_error *err)
{
    int e = 0;
    if (p->threaded) {
        pthread_mutex_lock(&p->mu);
        while (p->queued > 0)
            pthread_cond_wait(&p->cv, &p->mu);
        e = p->wr_errno;
        pthread_mutex_unlock(&p->mu);
    }
    return e != 0 ? part_failed(p, e, err) : GDT_OK;
}

uint64_t gdt_ply_part_direct_bytes(gdt_ply_part *p)
{
    uint64_t n;
    if (!p->threaded)
        return p->direct_bytes;
    pthread_mutex_lock(&p->mu);
    n = p->direct_bytes;
    pthread_mutex_unlock(&p->mu);
    return n;
}

gdt_status gdt_ply_part_close(gdt_ply_part *p, gdt_error *err)
{
    gdt_status st;
    int e;
    if (p == NULL)
        return GDT_OK;
    e = part_drain(p);
    if (p->dfd >= 0)
        close(p->dfd);
    p->dfd = -1;
    if (e != 0) {
        st = part_failed(p, e, err);
        gdt_ply_part_abort(p);
        return st;
    }
    /* one file: its sync covers the direct writes too */
    st = gdt_fd_sync_close_part(p->fd, p->path, err);
    p->fd = -1;
    gdt_ply_part_abort(p);
    return st;
}

void gdt_ply_part_abort(gdt_ply_part *p)
{
    if (p == NULL)
        return;
    (void)part_drain(p);
    if (p->dfd >= 0)
        close(p->dfd);
    if (p->fd >= 0)
        close(p->fd);
    part_free(p);
}

void gdt_ply_abort(gdt_ply_writer *w)
{
    if (w == NULL)
        return;
    ply_discard(w);
    ply_free(w);
}
