/* fail_write — an LD_PRELOAD library for tests: positional writes (pwrite,
 * pwrite64, copy_file_range into it) to a file whose path contains
 * GDT_TEST_FAIL_WRITE_MATCH fail
 * with ENOSPC, as on a full disk, after the first GDT_TEST_FAIL_WRITE_AFTER
 * of them (0 when unset) have succeeded; fsync of a file whose path
 * contains GDT_TEST_FAIL_FSYNC_MATCH fails with EIO, as when the disk
 * reports a lost write, and so does syncfs through a descriptor whose path
 * contains GDT_TEST_FAIL_SYNCFS_MATCH.  Other calls are untouched.  When
 * GDT_TEST_FAIL_WRITE_LOG names a file, each refusal appends a line to it,
 * so a test can tell that the shim was in effect.
 *
 *   GDT_TEST_FAIL_WRITE_MATCH=.ply.tmp- LD_PRELOAD=libgdt_fail_write.so gdt-tile ...
 */
#undef _FILE_OFFSET_BITS /* pwrite and pwrite64 are two symbols here */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <limits.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/types.h>
#include <unistd.h>

typedef ssize_t (*pwrite_fn)(int, const void *, size_t, off_t);
typedef int (*fsync_fn)(int);

static atomic_long matched;

/* Whether fd is a file whose path contains the value of the variable var. */
static int matches(int fd, const char *var, char *path, size_t size)
{
    const char *match = getenv(var);
    char link[64];
    ssize_t n;

    if (match == NULL || *match == '\0')
        return 0;
    snprintf(link, sizeof link, "/proc/self/fd/%d", fd);
    n = readlink(link, path, size - 1);
    if (n <= 0)
        return 0;
    path[n] = '\0';
    return strstr(path, match) != NULL;
}

static void log_refusal(const char *path)
{
    const char *log = getenv("GDT_TEST_FAIL_WRITE_LOG");
    FILE *f = log != NULL ? fopen(log, "a") : NULL;
    if (f != NULL) {
        fprintf(f, "refused %s\n", path);
        fclose(f);
    }
}

/* Whether this write to fd is to be refused. */
static int refuse(int fd)
{
    const char *after = getenv("GDT_TEST_FAIL_WRITE_AFTER");
    char path[PATH_MAX];

    if (!matches(fd, "GDT_TEST_FAIL_WRITE_MATCH", path, sizeof path))
        return 0;
    if (atomic_fetch_add(&matched, 1) < (after != NULL ? strtol(after, NULL, 10) : 0))
        return 0;
    log_refusal(path);
    return 1;
}

static ssize_t forward(const char *name, int fd, const void *buf, size_t n, off_t off)
{
    pwrite_fn real;
    if (refuse(fd)) {
        errno = ENOSPC;
        return -1;
    }
    real = (pwrite_fn)dlsym(RTLD_NEXT, name);
    if (real == NULL) {
        errno = ENOSYS;
        return -1;
    }
    return real(fd, buf, n, off);
}

ssize_t pwrite(int fd, const void *buf, size_t n, off_t off)
{
    return forward("pwrite", fd, buf, n, off);
}

ssize_t pwrite64(int fd, const void *buf, size_t n, off_t off)
{
    return forward("pwrite64", fd, buf, n, off);
}

ssize_t copy_file_range(int in, off_t *in_off, int out, off_t *out_off, size_t n, unsigned flags)
{
    typedef ssize_t (*copy_fn)(int, off_t *, int, off_t *, size_t, unsigned);
    copy_fn real;
    if (refuse(out)) {
        errno = ENOSPC;
        return -1;
    }
    real = (copy_fn)dlsym(RTLD_NEXT, "copy_file_range");
    if (real == NULL) {
        errno = ENOSYS;
        return -1;
    }
    return real(in, in_off, out, out_off, n, flags);
}

/* fsync or syncfs (name) of fd: EIO when fd's path contains the value of
 * var, else the real call. */
static int sync_call(const char *name, const char *var, int fd)
{
    char path[PATH_MAX];
    fsync_fn real;
    if (matches(fd, var, path, sizeof path)) {
        log_refusal(path);
        errno = EIO;
        return -1;
    }
    real = (fsync_fn)dlsym(RTLD_NEXT, name);
    if (real == NULL) {
        errno = ENOSYS;
        return -1;
    }
    return real(fd);
}

int fsync(int fd)
{
    return sync_call("fsync", "GDT_TEST_FAIL_FSYNC_MATCH", fd);
}

int syncfs(int fd)
{
    return sync_call("syncfs", "GDT_TEST_FAIL_SYNCFS_MATCH", fd);
}
