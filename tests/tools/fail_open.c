/* fail_open — an LD_PRELOAD library for tests: open, openat and fopen of a path
 * that contains GDT_TEST_FAIL_OPEN_MATCH fail with EIO, as on a disk that
 * lost a file's blocks, when the calling thread's name (pthread_getname_np)
 * is GDT_TEST_FAIL_OPEN_THREAD (any thread when that is unset).  So a test
 * can fail the work of one kind of thread only, such as a further device's
 * lane of the tile stage ("gdt-lane").  Other calls are untouched.  When
 * GDT_TEST_FAIL_OPEN_LOG names a file, each refusal appends a line to it,
 * so a test can tell that the shim was in effect.
 *
 *   GDT_TEST_FAIL_OPEN_MATCH=.pts GDT_TEST_FAIL_OPEN_THREAD=gdt-lane \
 *   LD_PRELOAD=libgdt_fail_open.so gdt-tile ... --device 0,0
 */
#undef _FILE_OFFSET_BITS /* open and open64 are two symbols here */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <fcntl.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/types.h>

typedef int (*open_fn)(const char *, int, ...);
typedef int (*openat_fn)(int, const char *, int, ...);

/* Whether opening path is to be refused. */
static int refuse(const char *path)
{
    const char *match = getenv("GDT_TEST_FAIL_OPEN_MATCH");
    const char *thread = getenv("GDT_TEST_FAIL_OPEN_THREAD");
    const char *log = getenv("GDT_TEST_FAIL_OPEN_LOG");
    char name[32];
    FILE *f;

    if (match == NULL || *match == '\0' || path == NULL || strstr(path, match) == NULL)
        return 0;
    if (thread != NULL && *thread != '\0' &&
        (pthread_getname_np(pthread_self(), name, sizeof name) != 0 || strcmp(name, thread) != 0))
        return 0;
    f = log != NULL ? fopen(log, "a") : NULL;
    if (f != NULL) {
        fprintf(f, "refused %s\n", path);
        fclose(f);
    }
    return 1;
}

/* The mode argument, present when flags create a file. */
static mode_t mode_of(int flags, va_list ap)
{
    return (flags & (O_CREAT | O_TMPFILE)) != 0 ? (mode_t)va_arg(ap, int) : 0;
}

static int forward_open(const char *name, const char *path, int flags, mode_t mode)
{
    open_fn real;
    if (refuse(path)) {
        errno = EIO;
        return -1;
    }
    real = (open_fn)dlsym(RTLD_NEXT, name);
    if (real == NULL) {
        errno = ENOSYS;
        return -1;
    }
    return real(path, flags, mode);
}

static int forward_openat(const char *name, int dir, const char *path, int flags, mode_t mode)
{
    openat_fn real;
    if (refuse(path)) {
        errno = EIO;
        return -1;
    }
    real = (openat_fn)dlsym(RTLD_NEXT, name);
    if (real == NULL) {
        errno = ENOSYS;
        return -1;
    }
    return real(dir, path, flags, mode);
}

int open(const char *path, int flags, ...)
{
    va_list ap;
    mode_t mode;
    va_start(ap, flags);
    mode = mode_of(flags, ap);
    va_end(ap);
    return forward_open("open", path, flags, mode);
}

int open64(const char *path, int flags, ...)
{
    va_list ap;
    mode_t mode;
    va_start(ap, flags);
    mode = mode_of(flags, ap);
    va_end(ap);
    return forward_open("open64", path, flags, mode);
}

int openat(int dir, const char *path, int flags, ...)
{
    va_list ap;
    mode_t mode;
    va_start(ap, flags);
    mode = mode_of(flags, ap);
    va_end(ap);
    return forward_openat("openat", dir, path, flags, mode);
}

int openat64(int dir, const char *path, int flags, ...)
{
    va_list ap;
    mode_t mode;
    va_start(ap, flags);
    mode = mode_of(flags, ap);
    va_end(ap);
    return forward_openat("openat64", dir, path, flags, mode);
}

typedef FILE *(*fopen_fn)(const char *, const char *);

static FILE *forward_fopen(const char *name, const char *path, const char *mode)
{
    fopen_fn real;
    if (refuse(path)) {
        errno = EIO;
        return NULL;
    }
    real = (fopen_fn)dlsym(RTLD_NEXT, name);
    if (real == NULL) {
        errno = ENOSYS;
        return NULL;
    }
    return real(path, mode);
}

FILE *fopen(const char *path, const char *mode)
{
    return forward_fopen("fopen", path, mode);
}

FILE *fopen64(const char *path, const char *mode)
{
    return forward_fopen("fopen64", path, mode);
}
