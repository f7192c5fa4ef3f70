/* las_copy.c — the LAS file of copied records (gdt_las_copy.h).
 *
 * Header offsets (LAS 1.0-1.4): 6 global encoding, 24/25 version, 94 header
 * size, 96 offset to the points, 100 VLR count, 104 point format, 105
 * record length, 107 legacy point count, 111 legacy points by return (5 x
 * u32), 131 scales, 155 offsets, 179 bounds (max x, min x, max y, min y, max
 * z, min z); 1.3: 227 start of waveform data; 1.4: 235 start of the first
 * EVLR, 243 EVLR count, 247 point count, 255 points by return (15 x u64).
 */
#include "gdt_las_copy.h"
#include "gdt_outfile.h"
#include "private/bytes.h"
#include "private/cloud_lattice.h"
#include "private/fd_io.h"

#include <errno.h>
#include <fcntl.h>
#include <inttypes.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#define COPY_BUF (1u << 20)
#define VLR_HEAD 54
#define EVLR_HEAD 60
#define HEADER_14 375

struct gdt_las_copy {
    char *path, *tmp, *dir;
    int fd;
    unsigned char *head;      /* the header (hsize bytes), patched at the end */
    unsigned hsize;
    unsigned char *evlrs;     /* the template's EVLRs, copied after the records */
    size_t evlrs_len;
    uint32_t nevlr;
    unsigned format, reclen;
    double scale[3], offset[3];
    uint64_t count, by_return[15];
    int32_t lo[3], hi[3];
    uint64_t pos;             /* where buf goes in the file */
    unsigned char *buf;
    size_t blen;
    uint64_t points_at;       /* the first record's offset */
    int part;                 /* another process's part (gdt_las_copy_open_part) */
};

static void copy_free(gdt_las_copy *w)
{
    if (w == NULL)
        return;
    if (w->fd >= 0)
        close(w->fd);
    free(w->path);
    free(w->tmp);
    free(w->dir);
    free(w->head);
    free(w->evlrs);
    free(w->buf);
    free(w);
}

void gdt_las_copy_abort(gdt_las_copy *w)
{
    if (w == NULL)
        return;
    if (w->fd >= 0 && w->tmp != NULL && !w->part) /* a part's file is the owner's */
        unlink(w->tmp);
    copy_free(w);
}

/* The error of a failed write (w stays: the caller aborts it). */
static gdt_status fail(const gdt_las_copy *w, gdt_error *err, gdt_status st, int code,
                       const char *what, int e)
{
    if (w->part)
        return gdt_error_set(err, st, code, "%s: %s: %s", w->path, what, strerror(e));
    return gdt_error_set(err, st, code, "%s: %s: %s (temporary %s removed)", w->path, what,
                         strerror(e), w->tmp);
}

gdt_status gdt_las_copy_accepts(const gdt_source_info *t, const char *path,
                                const gdt_source_info *in, int64_t shift[3], gdt_error *err)
{
    if (in->format != GDT_FORMAT_LAS)
        return gdt_error_set(err, GDT_EUSAGE, 2151,
                             "%s: a %s file has no LAS records to copy into --ground-out", path,
                             in->format_name);
    if (in->point_format != t->point_format || in->record_length != t->record_length)
        return gdt_error_set(err, GDT_EUSAGE, 2151,
                             "%s: point format %u with %u-byte records, the first input's are "
                             "%u and %u: --ground-out copies records into one LAS file",
                             path, in->point_format, in->record_length, t->point_format,
                             t->record_length);
    for (int i = 0; i < 3; i++) {
        /* the cloud's rule for an input on another lattice (up to the
         * rounding noise of the decimal header values), with one step */
        int64_t m = 0, k = 0;
        if (!gdt_cloud_lattice_relation(in->scale[i], in->offset[i], t->scale[i], t->offset[i],
                                        &m, &k) ||
            m != 1 || k <= INT32_MIN || k >= INT32_MAX)
            return gdt_error_set(err, GDT_EUSAGE, 2151,
                                 "%s: the scale or offset of %c puts its records off the "
                                 "first input's lattice (scale %.17g, offset %.17g; first "
                                 "input: %.17g, %.17g): --ground-out copies records into one "
                                 "LAS file",
                                 path, "xyz"[i], in->scale[i], in->offset[i], t->scale[i],
                                 t->offset[i]);
        shift[i] = k;
    }
    return GDT_OK;
}

gdt_status gdt_las_copy_shift(unsigned char *recs, size_t n, unsigned rl, const int64_t shift[3],
                              const char *path, uint64_t first, gdt_error *err)
{
    if (shift[0] == 0 && shift[1] == 0 && shift[2] == 0)
        return GDT_OK;
    for (size_t i = 0; i < n; i++)
        for (int k = 0; k < 3; k++) {
            unsigned char *p = recs + i * rl + 4 * k;
            int64_t v = (int64_t)gdt_le_get_i32(p) + shift[k];
            if (v < INT32_MIN || v > INT32_MAX)
                return gdt_error_set(err, GDT_EUSAGE, 2152,
                                     "%s: record %" PRIu64 ": its %c on the first input's "
                                     "lattice leaves the LAS integer range",
                                     path, first + i, "XYZ"[k]);
            gdt_le_put_u32(p, (uint32_t)(int32_t)v);
        }
    return GDT_OK;
}

/* Reads the template's header, its VLRs without the LASzip one, and its
 * EVLRs into w; writes header and VLRs. */
static gdt_status read_template(gdt_las_copy *w, const char *tpath, gdt_error *err)
{
    unsigned char h[HEADER_14];
    unsigned char *vl = NULL;
    size_t got = 0, keep = 0;
    uint32_t nvlr, kept = 0, off;
    struct stat sb;
    gdt_status st = GDT_OK;
    int fd = open(tpath, O_RDONLY | O_CLOEXEC), e;

    if (fd < 0)
        return gdt_error_set(err, GDT_EINPUT, 3151, "%s: cannot open: %s", tpath,
                             strerror(errno));
    memset(h, 0, sizeof h);
    e = gdt_fd_pread_all(fd, h, sizeof h, 0, &got);
    w->hsize = got >= 227 ? gdt_le_get_u16(h + 94) : 0;
    off = got >= 227 ? gdt_le_get_u32(h + 96) : 0;
    nvlr = got >= 227 ? gdt_le_get_u32(h + 100) : 0;
    if (e != 0 || fstat(fd, &sb) != 0 || memcmp(h, "LASF", 4) != 0 || w->hsize < 227 ||
        w->hsize > got || off < w->hsize || (uint64_t)off > (uint64_t)sb.st_size) {
        st = gdt_error_set(err, GDT_EINPUT, 3151, "%s: not a readable LAS header", tpath);
        goto done;
    }
    w->head = malloc(w->hsize);
    vl = malloc(off - w->hsize + 1);
    if (w->head == NULL || vl == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto done;
    }
    memcpy(w->head, h, w->hsize);
    e = gdt_fd_pread_all(fd, vl, off - w->hsize, w->hsize, &got);
    if (e != 0 || got != off - w->hsize) {
        st = gdt_error_set(err, GDT_EINPUT, 3151, "%s: cannot read its VLRs", tpath);
        goto done;
    }
    /* the VLRs in place, the LASzip one dropped; bytes after the last VLR
     * (user data before the points) stay */
    {
        size_t at = 0, len = off - w->hsize;
        for (uint32_t i = 0; i < nvlr; i++) {
            size_t n;
            if (len - at < VLR_HEAD)
                break;
            n = VLR_HEAD + gdt_le_get_u16(vl + at + 20);
            if (n > len - at)
                break;
            if (!(memcmp(vl + at + 2, "laszip encoded", 14) == 0 &&
                  gdt_le_get_u16(vl + at + 18) == 22204)) {
                memmove(vl + keep, vl + at, n);
                keep += n;
                kept++;
            }
            at += n;
        }
        memmove(vl + keep, vl + at, len - at);
        keep += len - at;
    }
    if (w->hsize >= HEADER_14) {
        uint64_t start = gdt_le_get_u64(h + 235);
        uint32_t n = gdt_le_get_u32(h + 243);
        if (n > 0 && start > 0 && start < (uint64_t)sb.st_size &&
            (uint64_t)sb.st_size - start < ((uint64_t)1 << 32)) {
            size_t len = (size_t)((uint64_t)sb.st_size - start), at = 0;
            w->evlrs = malloc(len + 1);
            if (w->evlrs == NULL) {
                st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
                goto done;
            }
            e = gdt_fd_pread_all(fd, w->evlrs, len, start, &got);
            if (e != 0 || got != len) {
                st = gdt_error_set(err, GDT_EINPUT, 3151, "%s: cannot read its EVLRs", tpath);
                goto done;
            }
            for (uint32_t i = 0; i < n && len - at >= EVLR_HEAD; i++) {
                uint64_t m = gdt_le_get_u64(w->evlrs + at + 20);
                if (m > len - at - EVLR_HEAD)
                    break;
                at += EVLR_HEAD + (size_t)m;
                w->nevlr++;
            }
            w->evlrs_len = at;
        }
    }
    /* the header of the copy: VLRs kept, uncompressed, no waveform data */
    gdt_le_put_u32(w->head + 96, (uint32_t)(w->hsize + keep));
    gdt_le_put_u32(w->head + 100, kept);
    w->head[104] &= 0x3Fu;
    {
        uint16_t ge = gdt_le_get_u16(w->head + 6) & (uint16_t)~0x2u;
        w->head[6] = (unsigned char)(ge & 0xFFu);
        w->head[7] = (unsigned char)(ge >> 8);
    }
    if (w->hsize >= 235)
        gdt_le_put_u64(w->head + 227, 0);
    e = gdt_fd_write_all(w->fd, w->head, w->hsize, -1);
    if (e == 0)
        e = gdt_fd_write_all(w->fd, vl, keep, -1);
    if (e != 0)
        st = gdt_error_set(err, GDT_EIO, 4152, "%s: write failed: %s", w->tmp, strerror(e));
    w->pos = w->points_at = w->hsize + keep;
done:
    free(vl);
    close(fd);
    return st;
}

/* The writer's state and its temporary file, without a header yet. */
static gdt_status copy_start(gdt_las_copy **out, const char *path, gdt_error *err)
{
    gdt_las_copy *w = calloc(1, sizeof *w);
    gdt_status st;

    *out = NULL;
    if (w == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    w->fd = -1;
    w->path = strdup(path);
    w->tmp = gdt_outfile_temp(path);
    w->dir = gdt_outfile_dir(path);
    w->buf = malloc(COPY_BUF);
    if (w->path == NULL || w->tmp == NULL || w->dir == NULL || w->buf == NULL) {
        copy_free(w);
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    }
    st = gdt_outfile_check(path, err);
    if (st != GDT_OK) {
        copy_free(w);
        return st;
    }
    w->fd = open(w->tmp, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666);
    if (w->fd < 0) {
        st = gdt_error_set(err, GDT_EIO, 4151, "%s: cannot create %s: %s", path, w->tmp,
                           strerror(errno));
        copy_free(w);
        return st;
    }
    *out = w;
    return GDT_OK;
}

gdt_status gdt_las_copy_open_new(gdt_las_copy **out, const char *path, const double scale[3],
                                 const double offset[3], gdt_error *err)
{
    static const char name[] = "gdt-tile";
    gdt_las_copy *w = NULL;
    unsigned char *h;
    int e;
    gdt_status st = copy_start(&w, path, err);

    *out = NULL;
    if (st != GDT_OK)
        return st;
    w->hsize = 227;
    w->head = calloc(1, w->hsize);
    if (w->head == NULL) {
        gdt_las_copy_abort(w);
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    }
    h = w->head;
    memcpy(h, "LASF", 4);
    h[24] = 1; /* version 1.2 */
    h[25] = 2;
    memcpy(h + 26, name, sizeof name - 1);  /* system identifier */
    memcpy(h + 58, name, sizeof name - 1);  /* generating software */
    h[94] = (unsigned char)(w->hsize & 0xFFu);
    h[95] = (unsigned char)(w->hsize >> 8);
    gdt_le_put_u32(h + 96, w->hsize);
    h[104] = 0;
    h[105] = 20;
    for (int k = 0; k < 3; k++) {
        gdt_le_put_f64(h + 131 + 8 * k, scale[k]);
        gdt_le_put_f64(h + 155 + 8 * k, offset[k]);
    }
    w->format = 0;
    w->reclen = 20;
    memcpy(w->scale, scale, sizeof w->scale);
    memcpy(w->offset, offset, sizeof w->offset);
    e = gdt_fd_write_all(w->fd, h, w->hsize, -1);
    if (e != 0) {
        st = fail(w, err, GDT_EIO, 4152, "write failed", e);
        gdt_las_copy_abort(w);
        return st;
    }
    w->pos = w->points_at = w->hsize;
    *out = w;
    return GDT_OK;
}

gdt_status gdt_las_copy_open(gdt_las_copy **out, const char *path, const char *template_path,
                             const gdt_source_info *tinfo, gdt_error *err)
{
    gdt_las_copy *w = NULL;
    gdt_status st = copy_start(&w, path, err);

    *out = NULL;
    if (st != GDT_OK)
        return st;
    w->format = tinfo->point_format;
    w->reclen = tinfo->record_length;
    memcpy(w->scale, tinfo->scale, sizeof w->scale);
    memcpy(w->offset, tinfo->offset, sizeof w->offset);
    st = read_template(w, template_path, err);
    if (st != GDT_OK) {
        gdt_las_copy_abort(w);
        return st;
    }
    *out = w;
    return GDT_OK;
}

static gdt_status flush(gdt_las_copy *w, gdt_error *err)
{
    int e = w->blen > 0 ? gdt_fd_write_all(w->fd, w->buf, w->blen, (off_t)w->pos) : 0;
    if (e != 0)
        return fail(w, err, GDT_EIO, 4152, "write failed", e);
    w->pos += w->blen;
    w->blen = 0;
    return GDT_OK;
}

gdt_status gdt_las_copy_put(gdt_las_copy *w, const unsigned char *recs, size_t n,
                            gdt_error *err)
{
    for (size_t i = 0; i < n; i++) {
        const unsigned char *r = recs + i * w->reclen;
        int32_t v[3] = {gdt_le_get_i32(r), gdt_le_get_i32(r + 4), gdt_le_get_i32(r + 8)};
        unsigned ret = w->format >= 6 ? (r[14] & 0x0Fu) : (r[14] & 0x07u);
        for (int k = 0; k < 3; k++) {
            if (w->count == 0 || v[k] < w->lo[k])
                w->lo[k] = v[k];
            if (w->count == 0 || v[k] > w->hi[k])
                w->hi[k] = v[k];
        }
        if (ret >= 1 && ret <= 15)
            w->by_return[ret - 1]++;
        w->count++;
        if (COPY_BUF - w->blen < w->reclen) {
            gdt_status st = flush(w, err);
            if (st != GDT_OK)
                return st;
        }
        memcpy(w->buf + w->blen, r, w->reclen);
        w->blen += w->reclen;
    }
    return GDT_OK;
}

void gdt_las_copy_layout(const gdt_las_copy *w, const char **tmp, uint64_t *points_at)
{
    *tmp = w->tmp;
    *points_at = w->points_at;
}

gdt_status gdt_las_copy_open_part(gdt_las_copy **out, const char *tmp, uint64_t points_at,
                                  const gdt_source_info *tinfo, gdt_error *err)
{
    gdt_las_copy *w = calloc(1, sizeof *w);
    *out = NULL;
    if (w == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    w->fd = -1;
    w->part = 1;
    w->path = strdup(tmp);
    w->tmp = strdup(tmp);
    w->buf = malloc(COPY_BUF);
    if (w->path == NULL || w->tmp == NULL || w->buf == NULL) {
        copy_free(w);
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    }
    w->format = tinfo->point_format;
    w->reclen = tinfo->record_length;
    w->pos = w->points_at = points_at;
    w->fd = open(tmp, O_WRONLY | O_CLOEXEC);
    if (w->fd < 0) {
        gdt_status st = gdt_error_set(err, GDT_EIO, 4151, "%s: cannot open: %s", tmp,
                                      strerror(errno));
        copy_free(w);
        return st;
    }
    *out = w;
    return GDT_OK;
}

gdt_status gdt_las_copy_seek(gdt_las_copy *w, uint64_t rec, gdt_error *err)
{
    gdt_status st = flush(w, err);
    if (st == GDT_OK)
        w->pos = w->points_at + rec * w->reclen;
    return st;
}

void gdt_las_copy_get_stats(const gdt_las_copy *w, gdt_las_copy_stats *s)
{
    memset(s, 0, sizeof *s);
    s->count = w->count;
    memcpy(s->by_return, w->by_return, sizeof s->by_return);
    for (int k = 0; k < 3; k++) {
        s->lo[k] = w->lo[k];
        s->hi[k] = w->hi[k];
    }
}

void gdt_las_copy_stats_add(gdt_las_copy_stats *a, const gdt_las_copy_stats *s)
{
    if (s->count == 0)
        return;
    for (int k = 0; k < 3; k++) {
        if (a->count == 0 || s->lo[k] < a->lo[k])
            a->lo[k] = s->lo[k];
        if (a->count == 0 || s->hi[k] > a->hi[k])
            a->hi[k] = s->hi[k];
    }
    for (int i = 0; i < 15; i++)
        a->by_return[i] += s->by_return[i];
    a->count += s->count;
}

void gdt_las_copy_add_stats(gdt_las_copy *w, const gdt_las_copy_stats *s)
{
    gdt_las_copy_stats a;
    gdt_las_copy_get_stats(w, &a);
    gdt_las_copy_stats_add(&a, s);
    w->count = a.count;
    memcpy(w->by_return, a.by_return, sizeof w->by_return);
    for (int k = 0; k < 3; k++) {
        w->lo[k] = a.lo[k];
        w->hi[k] = a.hi[k];
    }
}

gdt_status gdt_las_copy_close_part(gdt_las_copy *w, gdt_las_copy_stats *s, gdt_error *err)
{
    gdt_status st = flush(w, err);
    if (st != GDT_OK) {
        gdt_las_copy_abort(w);
        return st;
    }
    gdt_las_copy_get_stats(w, s);
    if (fsync(w->fd) != 0 || close(w->fd) != 0) {
        st = gdt_error_set(err, GDT_EIO, 4153, "%s: fsync or close failed: %s", w->tmp,
                           strerror(errno));
        w->fd = -1;
        copy_free(w);
        return st;
    }
    w->fd = -1;
    copy_free(w);
    return GDT_OK;
}

gdt_status gdt_las_copy_finish(gdt_las_copy *w, gdt_error *err)
{
    unsigned char *h = w->head;
    const int legacy = w->format < 6 && w->count <= UINT32_MAX;
    uint64_t evlr_start;
    gdt_status st = flush(w, err);
    gdt_error e2;
    int e;

    if (st != GDT_OK) {
        gdt_las_copy_abort(w);
        return st;
    }
    evlr_start = w->pos;
    if (w->evlrs_len > 0) {
        e = gdt_fd_write_all(w->fd, w->evlrs, w->evlrs_len, (off_t)evlr_start);
        if (e != 0) {
            st = fail(w, err, GDT_EIO, 4152, "write failed", e);
            gdt_las_copy_abort(w);
            return st;
        }
    }
    gdt_le_put_u32(h + 107, legacy ? (uint32_t)w->count : 0);
    for (int i = 0; i < 5; i++)
        gdt_le_put_u32(h + 111 + 4 * i,
                       legacy && w->by_return[i] <= UINT32_MAX ? (uint32_t)w->by_return[i] : 0);
    for (int k = 0; k < 3; k++) {
        double lo = w->count ? (double)w->lo[k] * w->scale[k] + w->offset[k] : 0.0;
        double hi = w->count ? (double)w->hi[k] * w->scale[k] + w->offset[k] : 0.0;
        gdt_le_put_f64(h + 179 + 16 * k, hi);
        gdt_le_put_f64(h + 187 + 16 * k, lo);
    }
    if (w->hsize >= HEADER_14) {
        gdt_le_put_u64(h + 235, w->nevlr > 0 ? evlr_start : 0);
        gdt_le_put_u32(h + 243, w->nevlr);
        gdt_le_put_u64(h + 247, w->count);
        for (int i = 0; i < 15; i++)
            gdt_le_put_u64(h + 255 + 8 * i, w->by_return[i]);
    }
    e = gdt_fd_write_all(w->fd, h, w->hsize, 0);
    if (e == 0 && fsync(w->fd) != 0)
        st = fail(w, err, GDT_EIO, 4153, "fsync failed", errno);
    else if (e != 0)
        st = fail(w, err, GDT_EIO, 4152, "write failed", e);
    if (st != GDT_OK) {
        gdt_las_copy_abort(w);
        return st;
    }
    e = close(w->fd);
    w->fd = -1;
    if (e != 0) {
        e = errno;
        unlink(w->tmp);
        gdt_error_set(err, GDT_EIO, 4153, "%s: close failed: %s", w->path, strerror(e));
        copy_free(w);
        return GDT_EIO;
    }
    gdt_error_clear(&e2);
    if (gdt_outfile_check(w->path, &e2) != GDT_OK || rename(w->tmp, w->path) != 0) {
        e = errno;
        unlink(w->tmp);
        if (e2.status != GDT_OK)
            gdt_error_set(err, e2.status, e2.code, "%s (temporary %s removed)", e2.msg, w->tmp);
        else
            gdt_error_set(err, GDT_EIO, 4153, "%s: cannot rename %s to it: %s", w->path, w->tmp,
                          strerror(e));
        st = e2.status != GDT_OK ? e2.status : GDT_EIO;
        copy_free(w);
        return st;
    }
    e = gdt_outfile_sync_dir(w->dir);
    if (e != 0)
        st = gdt_error_set(err, GDT_EIO, 4153,
                           "%s: written, but syncing its directory failed: %s", w->path,
                           strerror(e));
    copy_free(w);
    return st;
}
