/* env_guard — an LD_PRELOAD library for tests: reports every change of the
 * process environment that can crash another thread's getenv.
 *
 * glibc's getenv reads the environment array without a lock.  Adding a
 * variable (setenv or putenv of a name not set yet) reallocates that array
 * and frees the old one, removing one (unsetenv, clearenv) moves or drops
 * entries: a getenv running meanwhile on another thread reads freed or
 * shifted memory.  Such a change is only safe while no other thread runs,
 * which this shim approximates as "on the main thread" (the program's own
 * setenv calls happen there, before its worker threads start).  Replacing
 * the value of a variable that is already set only swaps one entry's
 * pointer, the array stays, and is not reported.
 *
 * Each change made on any other thread appends a line to the file named by
 * GDT_TEST_ENV_LOG (nothing is written without it), which a test expects to
 * hold only the line "loaded" the shim writes when it starts:
 *
 *   GDT_TEST_ENV_LOG=env.log LD_PRELOAD=libgdt_env_guard.so gdt-tile c.las --tile 64
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/syscall.h>
#include <unistd.h>

typedef int (*setenv_fn)(const char *, const char *, int);
typedef int (*putenv_fn)(char *);
typedef int (*unsetenv_fn)(const char *);
typedef int (*clearenv_fn)(void);

/* One line to the log, in one write (O_APPEND: lines of several threads or
 * processes do not interleave). */
static void log_line(const char *what, const char *name, size_t namelen)
{
    const char *path = getenv("GDT_TEST_ENV_LOG");
    char line[512];
    int fd, n;

    if (path == NULL || path[0] == '\0')
        return;
    if (namelen > 200)
        namelen = 200;
    n = snprintf(line, sizeof line, "%s(%.*s) on thread %ld of process %ld, not its main thread\n",
                 what, (int)namelen, name != NULL ? name : "", (long)syscall(SYS_gettid),
                 (long)getpid());
    fd = open(path, O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
    if (fd < 0)
        return;
    if (n > 0 && write(fd, line, (size_t)n) < 0) {
        /* nothing to do: the test then misses this line */
    }
    close(fd);
}

static int off_main(void)
{
    return (long)syscall(SYS_gettid) != (long)getpid();
}

/* 1 if a variable of that name (namelen bytes) is set now, 0 if not, -1
 * for a name too long to look up here (not judged, so never reported). */
static int is_set(const char *name, size_t namelen)
{
    char buf[256];
    if (namelen >= sizeof buf)
        return -1;
    memcpy(buf, name, namelen);
    buf[namelen] = '\0';
    return getenv(buf) != NULL;
}

__attribute__((constructor)) static void announce(void)
{
    const char *path = getenv("GDT_TEST_ENV_LOG");
    int fd;
    if (path == NULL || path[0] == '\0')
        return;
    fd = open(path, O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
    if (fd < 0)
        return;
    if (write(fd, "loaded\n", 7) < 0) {
        /* the test then finds no "loaded" line and fails */
    }
    close(fd);
}

int setenv(const char *name, const char *value, int replace)
{
    setenv_fn real = (setenv_fn)dlsym(RTLD_NEXT, "setenv");
    if (name != NULL && off_main() && is_set(name, strlen(name)) == 0)
        log_line("setenv", name, strlen(name));
    return real(name, value, replace);
}

int putenv(char *string)
{
    putenv_fn real = (putenv_fn)dlsym(RTLD_NEXT, "putenv");
    if (off_main()) {
        const char *eq = strchr(string, '=');
        size_t len = eq != NULL ? (size_t)(eq - string) : strlen(string);
        /* without '=' putenv removes the variable */
        if (is_set(string, len) == (eq == NULL ? 1 : 0))
            log_line("putenv", string, len);
    }
    return real(string);
}

int unsetenv(const char *name)
{
    unsetenv_fn real = (unsetenv_fn)dlsym(RTLD_NEXT, "unsetenv");
    if (off_main() && is_set(name, strlen(name)) == 1)
        log_line("unsetenv", name, strlen(name));
    return real(name);
}

int clearenv(void)
{
    clearenv_fn real = (clearenv_fn)dlsym(RTLD_NEXT, "clearenv");
    if (off_main())
        log_line("clearenv", "", 0);
    return real();
}
