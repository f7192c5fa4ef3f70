/* plugin.c — modules loaded on first use (private/plugin.h).
 *
 * Invariant: mu guards the table of loaded modules; a handle, once in the
 * table, stays valid for the life of the process (never dlclose'd: the
 * module's code may still be on a thread's stack, and its libraries may
 * have registered exit handlers). */
#define _GNU_SOURCE /* dladdr */
#include "private/plugin.h"

#include <dlfcn.h>
#include <limits.h>
#include <pthread.h>
#include <stdio.h>
#include <string.h>

#define PLUGIN_MAX 8

static pthread_mutex_t mu = PTHREAD_MUTEX_INITIALIZER;
static struct {
    char file[64];
    void *handle;
} loaded[PLUGIN_MAX];
static int nloaded;
static int beside_only; /* under mu */

void gdt_plugin_beside_only(void)
{
    pthread_mutex_lock(&mu);
    beside_only = 1;
    pthread_mutex_unlock(&mu);
}

/* The directory of the object that holds this function, in buf. */
static int own_dir(char *buf, size_t cap)
{
    Dl_info info;
    const char *slash;
    size_t n;
    if (dladdr((void *)&own_dir, &info) == 0 || info.dli_fname == NULL)
        return -1;
    slash = strrchr(info.dli_fname, '/');
    if (slash == NULL)
        return -1;
    n = (size_t)(slash - info.dli_fname);
    if (n + 1 > cap)
        return -1;
    memcpy(buf, info.dli_fname, n);
    buf[n] = '\0';
    return 0;
}

/* dlopen of dir/file; NULL with the loader's reason in why. */
static void *open_in(const char *dir, const char *file, char *why, size_t cap)
{
    char path[PATH_MAX + 80];
    void *h;
    if ((size_t)snprintf(path, sizeof path, "%s/%s", dir, file) >= sizeof path) {
        snprintf(why, cap, "%.300s/%.60s: path too long", dir, file);
        return NULL;
    }
    h = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (h == NULL) {
        const char *e = dlerror();
        snprintf(why, cap, "%.580s", e != NULL ? e : path);
    }
    return h;
}

gdt_status gdt_plugin_symbol(const char *file, const char *sym, const char *what, void **out,
                             gdt_error *err)
{
    void *h = NULL, *s;
    char dir[PATH_MAX], why1[600] = "", why2[600] = "";

    *out = NULL;
    if (strlen(file) >= sizeof loaded[0].file)
        return gdt_error_set(err, GDT_EINTERNAL, 7004, "plug-in name %s too long", file);
    pthread_mutex_lock(&mu);
    for (int i = 0; i < nloaded && h == NULL; i++)
        if (strcmp(loaded[i].file, file) == 0)
            h = loaded[i].handle;
    if (h == NULL) {
        if (own_dir(dir, sizeof dir) == 0)
            h = open_in(dir, file, why1, sizeof why1);
        else
            snprintf(why1, sizeof why1, "the program's own directory is unknown");
#ifdef GDT_PLUGIN_DIR
        if (h == NULL && !beside_only)
            h = open_in(GDT_PLUGIN_DIR, file, why2, sizeof why2);
#endif
        if (h != NULL && nloaded < PLUGIN_MAX) {
            snprintf(loaded[nloaded].file, sizeof loaded[nloaded].file, "%s", file);
            loaded[nloaded++].handle = h;
        }
    }
    pthread_mutex_unlock(&mu);
    if (h == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7004,
                             "cannot load %s, the module of %s (it must stay beside the "
                             "program's module libgdt-tile.so): %s%s%s",
                             file, what, why1, why2[0] != '\0' ? "; " : "", why2);
    dlerror();
    s = dlsym(h, sym);
    if (s == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7004, "%s, the module of %s, has no %s", file,
                             what, sym);
    *out = s;
    return GDT_OK;
}
