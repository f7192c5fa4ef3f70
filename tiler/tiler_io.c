/* tiler_io.c — record files of the tiler (see private/tiler_io.h). */
#define _GNU_SOURCE /* syncfs */
#include "private/tiler_io.h"

#include <errno.h>
#include <fcntl.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

char *tl_path(const char *fmt, ...)
{
    va_list ap;
    int n;
    char *s;

    va_start(ap, fmt);
    n = vsnprintf(NULL, 0, fmt, ap);
    va_end(ap);
    if (n < 0)
        return NULL;
    s = malloc((size_t)n + 1);
    if (s == NULL)
        return NULL;
    va_start(ap, fmt);
    vsnprintf(s, (size_t)n + 1, fmt, ap);
    va_end(ap);
    return s;
}

static gdt_status wfile_init(tl_wfile *w, const char *tmp_path, const char *final_path,
                             unsigned char *buf, size_t cap, int durable, gdt_error *err)
{
    memset(w, 0, sizeof *w);
    w->fd = -1;
    w->cap = cap > 0 ? cap : 1;
    w->durable = durable;
    w->tmp_path = strdup(tmp_path);
    w->final_path = final_path != NULL ? strdup(final_path) : NULL;
    w->borrowed = buf != NULL;
    w->buf = buf != NULL ? buf : malloc(w->cap * TL_REC);
    if (w->tmp_path == NULL || w->buf == NULL || (final_path != NULL && w->final_path == NULL)) {
        tl_wfile_abort(w);
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    }
    return GDT_OK;
}

gdt_status tl_wfile_init(tl_wfile *w, const char *tmp_path, const char *final_path, size_t cap,
                         int durable, gdt_error *err)
{
    return wfile_init(w, tmp_path, final_path, NULL, cap, durable, err);
}

gdt_status tl_wfile_init_buf(tl_wfile *w, const char *tmp_path, const char *final_path,
                             unsigned char *buf, size_t cap, int durable, gdt_error *err)
{
    return wfile_init(w, tmp_path, final_path, buf, cap, durable, err);
}

gdt_status tl_write_all(int fd, const unsigned char *p, size_t len, const char *path,
                        gdt_error *err)
{
    while (len > 0) {
        ssize_t w = write(fd, p, len);
        if (w < 0 && errno == EINTR)
            continue;
        if (w <= 0)
            return gdt_error_set(err, GDT_EIO, 4503, "cannot write %s: %s", path,
                                 w < 0 ? strerror(errno) : "no space written");
        p += w;
        len -= (size_t)w;
    }
    return GDT_OK;
}

static gdt_status wfile_create(tl_wfile *w, gdt_error *err)
{
    w->fd = open(w->tmp_path, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666);
    if (w->fd < 0)
        return gdt_error_set(err, GDT_EIO, 4502, "cannot create %s: %s", w->tmp_path,
                             strerror(errno));
    return GDT_OK;
}

gdt_status tl_wfile_flush(tl_wfile *w, gdt_error *err)
{
    gdt_status st;
    if (w->len == 0)
        return GDT_OK;
    if (w->fd < 0) {
        st = wfile_create(w, err);
        if (st != GDT_OK)
            return st;
    }
    if (w->hashed)
        gdt_hash_wide_update(&w->hash, w->buf, w->len * TL_REC);
    st = tl_write_all(w->fd, w->buf, w->len * TL_REC, w->tmp_path, err);
    w->len = 0;
    return st;
}

void tl_wfile_hash(tl_wfile *w, uint64_t seed)
{
    w->hashed = 1;
    gdt_hash_wide_init(&w->hash, seed);
}

gdt_status tl_wfile_sum(tl_wfile *w, uint64_t *sum, gdt_error *err)
{
    gdt_status st = tl_wfile_flush(w, err);
    *sum = gdt_hash_wide_final(&w->hash);
    return st;
}

gdt_status tl_wfile_commit(tl_wfile *w, gdt_error *err)
{
    gdt_status st = tl_wfile_flush(w, err);
    if (st != GDT_OK)
        goto fail;
    if (w->fd < 0) {
        st = wfile_create(w, err);
        if (st != GDT_OK)
            goto fail;
    }
    /* a refused sync_file_range (a file system without it) leaves the
     * writeback to tl_sync_files */
    if (w->durable == TL_SYNC_LATER)
        (void)sync_file_range(w->fd, 0, 0, SYNC_FILE_RANGE_WRITE);
    if (w->durable == TL_SYNC_NOW && fsync(w->fd) != 0) {
        st = gdt_error_set(err, GDT_EIO, 4505, "cannot fsync %s: %s", w->tmp_path,
                           strerror(errno));
        goto fail;
    }
    if (close(w->fd) != 0) {
        w->fd = -1;
        st = gdt_error_set(err, GDT_EIO, 4503, "cannot write %s: %s", w->tmp_path,
                           strerror(errno));
        goto fail;
    }
    w->fd = -1;
    if (w->final_path != NULL && rename(w->tmp_path, w->final_path) != 0) {
        st = gdt_error_set(err, GDT_EIO, 4505, "cannot rename %s to %s: %s", w->tmp_path,
                           w->final_path, strerror(errno));
        goto fail;
    }
    free(w->tmp_path);
    free(w->final_path);
    if (!w->borrowed)
        free(w->buf);
    memset(w, 0, sizeof *w);
    w->fd = -1;
    return GDT_OK;
fail:
    tl_wfile_abort(w);
    return st;
}

void tl_wfile_abort(tl_wfile *w)
{
    if (w->fd >= 0) {
        close(w->fd);
        w->fd = -1;
        if (w->tmp_path != NULL)
            unlink(w->tmp_path);
    }
    free(w->tmp_path);
    free(w->final_path);
    if (!w->borrowed)
        free(w->buf);
    memset(w, 0, sizeof *w);
    w->fd = -1;
}

gdt_status tl_file_records(const char *path, uint64_t *nrec, gdt_error *err)
{
    struct stat sb;
    if (stat(path, &sb) != 0)
        return gdt_error_set(err, GDT_EIO, 4504, "cannot read %s: %s", path, strerror(errno));
    if (sb.st_size < 0 || (uint64_t)sb.st_size % TL_REC != 0)
        return gdt_error_set(err, GDT_EIO, 4504,
                             "cannot read %s: its size is not a whole number of records", path);
    *nrec = (uint64_t)sb.st_size / TL_REC;
    return GDT_OK;
}

/* GDT_EJOB 6503 unless fd (open on path) holds exactly nrec records: a job
 * file that changed since it was written means a damaged job. */
static gdt_status check_records(int fd, const char *path, uint64_t nrec, uint64_t *size,
                                gdt_error *err)
{
    struct stat sb;
    if (fstat(fd, &sb) != 0 || sb.st_size < 0 || (uint64_t)sb.st_size / TL_REC != nrec ||
        (uint64_t)sb.st_size % TL_REC != 0)
        return gdt_error_set(err, GDT_EJOB, 6503,
                             "%s: it does not hold the %llu records written to it (the job "
                             "directory was changed; rerun with --restart)",
                             path, (unsigned long long)nrec);
    *size = (uint64_t)sb.st_size;
    return GDT_OK;
}

gdt_status tl_map_records(const char *path, uint64_t nrec, const unsigned char **map,
                          size_t *len, gdt_error *err)
{
    uint64_t size = 0;
    void *p;
    gdt_status st;
    int fd = open(path, O_RDONLY | O_CLOEXEC);

    *map = NULL;
    *len = 0;
    if (fd < 0)
        return gdt_error_set(err, GDT_EIO, 4504, "cannot open %s: %s", path, strerror(errno));
    st = check_records(fd, path, nrec, &size, err);
    if (st == GDT_OK && size > SIZE_MAX)
        st = gdt_error_set(err, GDT_EIO, 4504, "cannot map %s: larger than memory", path);
    if (st != GDT_OK || size == 0) {
        close(fd);
        return st;
    }
    p = mmap(NULL, (size_t)size, PROT_READ, MAP_PRIVATE, fd, 0);
    close(fd);
    if (p == MAP_FAILED)
        return gdt_error_set(err, GDT_EIO, 4504, "cannot map %s: %s", path, strerror(errno));
    (void)posix_madvise(p, (size_t)size, POSIX_MADV_WILLNEED); /* advice only */
    *map = p;
    *len = (size_t)size;
    return GDT_OK;
}

void tl_release_records(const unsigned char *map, size_t len, size_t *released, uint64_t below)
{
#ifdef MADV_DONTNEED
    const long page = sysconf(_SC_PAGESIZE);
    size_t end;
    if (map == NULL || page <= 0 || below > len / TL_REC)
        return;
    end = (size_t)below * TL_REC / (size_t)page * (size_t)page;
    if (end > *released) {
        (void)madvise((void *)(map + *released), end - *released, MADV_DONTNEED);
        *released = end;
    }
#else
    (void)map;
    (void)len;
    (void)released;
    (void)below;
#endif
}

void tl_unmap_records(const unsigned char *map, size_t len)
{
    if (map != NULL)
        munmap((void *)map, len);
}

static gdt_status rfile_open(tl_rfile *r, const char *path, uint64_t nrec, unsigned char *buf,
                             size_t cap, gdt_error *err)
{
    uint64_t size = 0;
    gdt_status st = GDT_OK;

    memset(r, 0, sizeof *r);
    r->fd = -1;
    r->cap = cap > 0 ? cap : 1;
    r->left = nrec;
    r->path = strdup(path);
    r->borrowed = buf != NULL;
    r->buf = buf != NULL ? buf : malloc(r->cap * TL_REC);
    if (r->path == NULL || r->buf == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    r->fd = open(path, O_RDONLY | O_CLOEXEC);
    if (r->fd < 0) {
        st = gdt_error_set(err, GDT_EIO, 4504, "cannot open %s: %s", path, strerror(errno));
        goto fail;
    }
    st = check_records(r->fd, path, nrec, &size, err);
    if (st != GDT_OK)
        goto fail;
    (void)posix_fadvise(r->fd, 0, 0, POSIX_FADV_SEQUENTIAL);
    return GDT_OK;
fail:
    tl_rfile_close(r);
    return st;
}

gdt_status tl_rfile_open(tl_rfile *r, const char *path, uint64_t nrec, size_t cap,
                         gdt_error *err)
{
    return rfile_open(r, path, nrec, NULL, cap, err);
}

gdt_status tl_rfile_open_buf(tl_rfile *r, const char *path, uint64_t nrec, unsigned char *buf,
                             size_t cap, gdt_error *err)
{
    return rfile_open(r, path, nrec, buf, cap, err);
}

static gdt_status rfile_fill(tl_rfile *r, gdt_error *err)
{
    size_t want = r->cap;
    size_t got = 0;
    if ((uint64_t)want > r->left)
        want = (size_t)r->left;
    while (got < want * TL_REC) {
        ssize_t n = read(r->fd, r->buf + got, want * TL_REC - got);
        if (n < 0 && errno == EINTR)
            continue;
        if (n < 0)
            return gdt_error_set(err, GDT_EIO, 4504, "cannot read %s: %s", r->path,
                                 strerror(errno));
        if (n == 0)
            return gdt_error_set(err, GDT_EJOB, 6503,
                                 "%s: shorter than written (the job directory was changed; "
                                 "rerun with --restart)",
                                 r->path);
        got += (size_t)n;
    }
    r->pos = 0;
    r->len = want;
    return GDT_OK;
}

gdt_status tl_rfile_raw(tl_rfile *r, const unsigned char **rec, size_t cap, size_t *n,
                        gdt_error *err)
{
    size_t k;
    *n = 0;
    *rec = NULL;
    if (r->pos == r->len) {
        gdt_status st;
        if (r->left == 0)
            return GDT_OK;
        st = rfile_fill(r, err);
        if (st != GDT_OK)
            return st;
    }
    k = r->len - r->pos < cap ? r->len - r->pos : cap;
    *rec = r->buf + r->pos * TL_REC;
    r->pos += k;
    r->left -= k;
    *n = k;
    return GDT_OK;
}

gdt_status tl_rfile_next(tl_rfile *r, gdt_point *p, int *got, gdt_error *err)
{
    const unsigned char *rec;
    size_t n;
    gdt_status st = tl_rfile_raw(r, &rec, 1, &n, err);
    *got = st == GDT_OK && n == 1;
    if (*got)
        tl_rec_get(p, rec);
    return st;
}

gdt_status tl_rfile_read(tl_rfile *r, gdt_point *out, size_t cap, size_t *n, gdt_error *err)
{
    size_t k = 0;
    *n = 0;
    while (k < cap) {
        const unsigned char *rec;
        size_t m;
        gdt_status st = tl_rfile_raw(r, &rec, cap - k, &m, err);
        if (st != GDT_OK)
            return st;
        if (m == 0)
            break;
        for (size_t i = 0; i < m; i++)
            tl_rec_get(&out[k + i], rec + i * TL_REC);
        k += m;
    }
    *n = k;
    return GDT_OK;
}

void tl_rfile_close(tl_rfile *r)
{
    if (r->fd >= 0)
        close(r->fd);
    free(r->path);
    if (!r->borrowed)
        free(r->buf);
    memset(r, 0, sizeof *r);
    r->fd = -1;
}

gdt_status tl_file_sum(const char *path, uint64_t seed, uint64_t *size, uint64_t *sum,
                       gdt_error *err)
{
    enum { CHUNK = 1 << 20 };
    unsigned char *buf = malloc(CHUNK);
    gdt_hash_wide h;
    gdt_status st = GDT_OK;
    int fd;

    if (buf == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    fd = open(path, O_RDONLY | O_CLOEXEC);
    if (fd < 0) {
        st = gdt_error_set(err, GDT_EIO, 4504, "cannot open %s: %s", path, strerror(errno));
        free(buf);
        return st;
    }
    (void)posix_fadvise(fd, 0, 0, POSIX_FADV_SEQUENTIAL);
    gdt_hash_wide_init(&h, seed);
    for (;;) {
        ssize_t n = read(fd, buf, CHUNK);
        if (n < 0 && errno == EINTR)
            continue;
        if (n < 0) {
            st = gdt_error_set(err, GDT_EIO, 4504, "cannot read %s: %s", path, strerror(errno));
            break;
        }
        if (n == 0)
            break;
        gdt_hash_wide_update(&h, buf, (size_t)n);
    }
    close(fd);
    free(buf);
    *size = h.n;
    *sum = gdt_hash_wide_final(&h);
    return st;
}

gdt_status tl_sync_files(const char *dir, gdt_error *err)
{
    int fd = open(dir, O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (fd < 0)
        return gdt_error_set(err, GDT_EIO, 4505, "cannot open directory %s: %s", dir,
                             strerror(errno));
    if (syncfs(fd) != 0) {
        int e = errno;
        close(fd);
        return gdt_error_set(err, GDT_EIO, 4505, "cannot sync the files of %s: %s", dir,
                             strerror(e));
    }
    close(fd);
    return tl_sync_dir(dir, err);
}

gdt_status tl_sync_dir(const char *dir, gdt_error *err)
{
    int fd = open(dir, O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (fd < 0)
        return gdt_error_set(err, GDT_EIO, 4505, "cannot open directory %s: %s", dir,
                             strerror(errno));
    if (fsync(fd) != 0 && errno != EINVAL) {
        int e = errno;
        close(fd);
        return gdt_error_set(err, GDT_EIO, 4505, "cannot fsync directory %s: %s", dir,
                             strerror(e));
    }
    close(fd);
    return GDT_OK;
}

gdt_status tl_sort_by_ord(gdt_point *a, size_t n, gdt_point *tmp, gdt_error *err)
{
    enum { BITS = 11, RADIX = 1 << BITS };
    size_t count[RADIX];
    uint64_t lo = UINT64_MAX, hi = 0, range;
    gdt_point *own = NULL, *src = a, *dst;

    if (n < 2)
        return GDT_OK;
    for (size_t i = 0; i < n; i++) {
        if (a[i].ord < lo)
            lo = a[i].ord;
        if (a[i].ord > hi)
            hi = a[i].ord;
    }
    range = hi - lo;
    if (range == 0)
        return GDT_OK;
    if (tmp == NULL) {
        if (n > SIZE_MAX / sizeof *tmp)
            return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        own = tmp = malloc(n * sizeof *tmp);
        if (own == NULL)
            return gdt_error_set(err, GDT_EINTERNAL, 7001,
                                 "out of memory sorting %zu points by ordinal", n);
    }
    dst = tmp;
    /* Each pass is a stable counting sort on one digit of ord - lo, so the
     * passes together sort by ord and keep equal ords in input order. */
    for (unsigned shift = 0; shift < 64 && (range >> shift) != 0; shift += BITS) {
        size_t sum = 0;
        memset(count, 0, sizeof count);
        for (size_t i = 0; i < n; i++)
            count[((src[i].ord - lo) >> shift) & (RADIX - 1)]++;
        for (size_t d = 0; d < RADIX; d++) {
            size_t c = count[d];
            count[d] = sum;
            sum += c;
        }
        for (size_t i = 0; i < n; i++)
            dst[count[((src[i].ord - lo) >> shift) & (RADIX - 1)]++] = src[i];
        gdt_point *t = src;
        src = dst;
        dst = t;
    }
    if (src != a)
        memcpy(a, src, n * sizeof *a);
    free(own);
    return GDT_OK;
}
