/* fail_threads — an LD_PRELOAD library for tests: pthread_create succeeds
 * for the first GDT_TEST_THREADS_ALLOWED calls of the process (0 when the
 * variable is unset) and fails with EAGAIN after that, as it does when a
 * process reaches its thread or memory limit.  The code under test must
 * then do the work on the threads it has, with the same result.  When
 * GDT_TEST_THREADS_LOG names a file, each refusal appends a line to it, so
 * a test can tell that the shim was in effect.
 *
 *   GDT_TEST_THREADS_ALLOWED=1 LD_PRELOAD=libgdt_fail_threads.so gdt_dump --threads 4 F.laz
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>

typedef int (*create_fn)(pthread_t *, const pthread_attr_t *, void *(*)(void *), void *);

static atomic_long calls;

int pthread_create(pthread_t *t, const pthread_attr_t *attr, void *(*fn)(void *), void *arg)
{
    const char *env = getenv("GDT_TEST_THREADS_ALLOWED");
    long allowed = env != NULL ? strtol(env, NULL, 10) : 0;
    create_fn real;

    if (atomic_fetch_add(&calls, 1) >= allowed) {
        const char *log = getenv("GDT_TEST_THREADS_LOG");
        FILE *f = log != NULL ? fopen(log, "a") : NULL;
        if (f != NULL) {
            fputs("refused\n", f);
            fclose(f);
        }
        return EAGAIN;
    }
    real = (create_fn)dlsym(RTLD_NEXT, "pthread_create");
    if (real == NULL)
        return EAGAIN;
    return real(t, attr, fn, arg);
}
