/* Format dispatch for point sources. */
#include "gdt_source.h"
#include "private/source_impl.h"

#include <errno.h>
#include <fcntl.h>
#include <inttypes.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

const char *gdt_file_kind(unsigned mode)
{
    if (S_ISREG(mode))
        return "a regular file";
    if (S_ISDIR(mode))
        return "a directory";
    if (S_ISFIFO(mode))
        return "a FIFO (pipe)";
    if (S_ISCHR(mode))
        return "a character device";
    if (S_ISBLK(mode))
        return "a block device";
    if (S_ISSOCK(mode))
        return "a socket";
    if (S_ISLNK(mode))
        return "a symbolic link";
    return "not a regular file";
}

static gdt_status cannot_open(const char *path, int e, gdt_error *err)
{
    if (e == ENOENT || e == EACCES || e == ENOTDIR || e == ELOOP || e == ENAMETOOLONG)
        return gdt_error_set(err, GDT_EINPUT, 3001, "%s: cannot open: %s", path, strerror(e));
    return gdt_error_set(err, GDT_EIO, 4002, "%s: cannot open: %s", path, strerror(e));
}

static gdt_status check_mode(const char *path, mode_t mode, gdt_error *err)
{
    if (S_ISDIR(mode))
        return gdt_error_set(err, GDT_EINPUT, 3004,
                             "%s: is a directory, not a point cloud file", path);
    if (!S_ISREG(mode))
        return gdt_error_set(err, GDT_EINPUT, 3005,
                             "%s: is %s: gdt-tile reads each input more than once (its passes), "
                             "so an input must be a regular file; save the stream to a file "
                             "first",
                             path, gdt_file_kind(mode));
    return GDT_OK;
}

gdt_status gdt_source_check_path(const char *path, gdt_error *err)
{
    struct stat sb;
    if (stat(path, &sb) != 0)
        return cannot_open(path, errno, err);
    return check_mode(path, sb.st_mode, err);
}

gdt_status gdt_source_sniff(const char *path, gdt_format *fmt, gdt_error *err)
{
    unsigned char head[512];
    size_t n;
    struct stat sb;
    FILE *f = NULL;
    int fd;
    gdt_status st;

    *fmt = GDT_FORMAT_UNKNOWN;
    /* stat first, and open without blocking: opening a FIFO for reading
     * would wait for a writer */
    st = gdt_source_check_path(path, err);
    if (st != GDT_OK)
        return st;
    fd = open(path, O_RDONLY | O_NONBLOCK | O_CLOEXEC);
    if (fd < 0)
        return cannot_open(path, errno, err);
    if (fstat(fd, &sb) != 0 || (st = check_mode(path, sb.st_mode, err)) != GDT_OK) {
        int e = errno;
        close(fd);
        return st != GDT_OK ? st : cannot_open(path, e, err);
    }
    f = fdopen(fd, "rb");
    if (f == NULL) {
        int e = errno;
        close(fd);
        return cannot_open(path, e, err);
    }
    n = fread(head, 1, sizeof head, f);
    fclose(f);
    if (n >= 4 && memcmp(head, "LASF", 4) == 0) {
        *fmt = GDT_FORMAT_LAS;
        return GDT_OK;
    }
    /* PCD: optional comment lines starting with '#', then "VERSION" or "FIELDS". */
    {
        size_t i = 0;
        while (i < n && (head[i] == '#' || head[i] == ' ' || head[i] == '\t' ||
                         head[i] == '\r' || head[i] == '\n')) {
            if (head[i] == '#') {
                while (i < n && head[i] != '\n')
                    i++;
            } else {
                i++;
            }
        }
        if (i + 7 <= n && (memcmp(head + i, "VERSION", 7) == 0 ||
                           memcmp(head + i, "FIELDS ", 7) == 0)) {
            *fmt = GDT_FORMAT_PCD;
            return GDT_OK;
        }
    }
    if (n == 0)
        return gdt_error_set(err, GDT_EINPUT, 3002, "%s: file is empty", path);
    return gdt_error_set(err, GDT_EINPUT, 3003,
                         "%s: unknown format (neither LAS nor PCD by its content)", path);
}

gdt_status gdt_source_open(gdt_source **out, const char *path, const gdt_source_opts *opts,
                           gdt_error *err)
{
    gdt_format fmt;
    gdt_status st;
    gdt_source *src = NULL;

    *out = NULL;
    st = gdt_source_sniff(path, &fmt, err);
    if (st != GDT_OK)
        return st;
    src = calloc(1, sizeof *src);
    if (src == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    src->path = strdup(path);
    if (src->path == NULL) {
        free(src);
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    }
    if (opts != NULL)
        src->opts = *opts;
    if (src->opts.buffer_bytes == 0)
        src->opts.buffer_bytes = (size_t)1 << 20;
    st = fmt == GDT_FORMAT_LAS ? gdt_las_open(src, err) : gdt_pcd_open(src, err);
    if (st != GDT_OK) {
        free(src->path);
        free(src);
        return st;
    }
    *out = src;
    return GDT_OK;
}

const gdt_source_info *gdt_source_get_info(const gdt_source *src) { return &src->info; }

const char *gdt_source_path(const gdt_source *src) { return src->path; }

gdt_status gdt_source_read(gdt_source *src, gdt_src_point *buf, size_t cap, size_t *n,
                           gdt_error *err)
{
    *n = 0;
    if (cap == 0)
        return GDT_OK;
    return src->vt->read(src, buf, cap, n, err);
}

gdt_status gdt_source_read_raw(gdt_source *src, gdt_src_point *buf, unsigned char *raw,
                               size_t cap, size_t *n, gdt_error *err)
{
    *n = 0;
    if (src->vt->read_raw == NULL)
        return gdt_error_set(err, GDT_EUSAGE, 2150, "%s: a %s file has no LAS records to copy",
                             src->path, src->info.format_name);
    if (cap == 0)
        return GDT_OK;
    return src->vt->read_raw(src, buf, raw, cap, n, err);
}

int gdt_source_can_seek(const gdt_source *src)
{
    return src->vt->seek != NULL && !src->info.compressed &&
           (src->info.format == GDT_FORMAT_LAS ||
            (src->info.format == GDT_FORMAT_PCD && strcmp(src->info.encoding, "binary") == 0));
}

uint64_t gdt_source_starts(const gdt_source *src, uint64_t *out, uint64_t cap)
{
    return src->vt != NULL && src->vt->starts != NULL ? src->vt->starts(src, out, cap) : 0;
}

gdt_status gdt_source_seek(gdt_source *src, uint64_t rec, uint64_t end, gdt_error *err)
{
    if (src->vt->seek == NULL || rec > src->info.point_count ||
        (!gdt_source_can_seek(src) && src->vt->starts == NULL))
        return gdt_error_set(err, GDT_EINTERNAL, 7102,
                             "%s: cannot start reading at point record %" PRIu64, src->path,
                             rec);
    return src->vt->seek(src, rec, end, err);
}

void gdt_source_close(gdt_source *src)
{
    if (src == NULL)
        return;
    if (src->vt != NULL)
        src->vt->close(src);
    free(src->path);
    free(src);
}
