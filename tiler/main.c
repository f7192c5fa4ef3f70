/* gdt-tile — the executable: a small launcher that loads the program.
 *
 * The program proper (every stage, and the libraries it links: OpenVDB,
 * TBB, GeographicLib, SQLite, the OpenCL loader) lives in the module
 * GDT_CLI_MODULE beside this executable.  Loading and relocating those
 * libraries takes tens of milliseconds, longer on a busy machine; had the
 * executable linked them, a SIGINT or SIGTERM in that window would kill by
 * its default action, without a word.  This launcher links only the C
 * library, so its handlers are in place within a millisecond of exec; a
 * signal that arrives while the module loads sets the flag, and the run
 * stops at its first check with exit 130.
 *
 * Exit codes: the program's; 7 when the module cannot be loaded. */
#define _GNU_SOURCE /* readlink of /proc/self/exe */
#include <dlfcn.h>
#include <limits.h>
#include <signal.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

#include "private/cli_entry.h"

#ifndef GDT_CLI_MODULE
#define GDT_CLI_MODULE "libgdt-tile.so"
#endif

static volatile sig_atomic_t g_stop;

static void on_signal(int sig)
{
    g_stop = sig;
}

/* The module's path: GDT_CLI_MODULE in the directory of this executable.
 * Returns 0, or -1 when it does not fit in len. */
static int module_path(char *buf, size_t len)
{
    char self[PATH_MAX];
    ssize_t n = readlink("/proc/self/exe", self, sizeof self - 1);
    const char *slash;
    int w;
    if (n <= 0)
        return snprintf(buf, len, "%s", GDT_CLI_MODULE) < (int)len ? 0 : -1;
    self[n] = '\0';
    slash = strrchr(self, '/');
    w = snprintf(buf, len, "%.*s/%s", (int)(slash != NULL ? slash - self : 1),
                 slash != NULL ? self : ".", GDT_CLI_MODULE);
    return w >= 0 && (size_t)w < len ? 0 : -1;
}

int main(int argc, char **argv)
{
    struct sigaction sa;
    char path[PATH_MAX + 64];
    void *h;
    gdt_cli_entry_fn entry;

    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigemptyset(&sa.sa_mask);
    sa.sa_flags = SA_RESTART | SA_RESETHAND;
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);

    if (module_path(path, sizeof path) != 0) {
        fprintf(stderr, "gdt-tile: error GDT-7003 (internal): the path of the program's "
                        "module is too long\n");
        return 7;
    }
    h = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (h == NULL) {
        fprintf(stderr, "gdt-tile: error GDT-7003 (internal): cannot load the program's "
                        "module %s (it must stay beside the gdt-tile executable): %s\n",
                path, dlerror());
        return 7;
    }
    {
        /* a data pointer to a function pointer: POSIX guarantees the two
         * have one representation */
        void *sym = dlsym(h, GDT_CLI_ENTRY_SYMBOL);
        memcpy(&entry, &sym, sizeof entry);
    }
    if (entry == NULL) {
        fprintf(stderr, "gdt-tile: error GDT-7003 (internal): %s: no entry point %s\n", path,
                GDT_CLI_ENTRY_SYMBOL);
        return 7;
    }
    /* the module is never unloaded: its threads and atexit handlers may
     * outlive main */
    return entry(argc, argv, &g_stop);
}
