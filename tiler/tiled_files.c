/* tiled_files.c — paths and messages shared by the stages of the tiled run
 * (see private/tiled_files.h). */
#include "private/tiled_files.h"

#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

char *tr_path_join(const char *a, const char *b)
{
    size_t la = strlen(a), lb = strlen(b);
    char *p = malloc(la + lb + 2);
    if (p == NULL)
        return NULL;
    memcpy(p, a, la);
    p[la] = '/';
    memcpy(p + la + 1, b, lb + 1);
    return p;
}

gdt_status tr_tile_path(const char *tiles_dir, const gdt_tile_desc *d, const char *ext,
                        char **out, gdt_error *err)
{
    char name[96];
    snprintf(name, sizeof name, "tile_%" PRId64 "_%" PRId64 ".%s", d->i, d->j, ext);
    *out = tr_path_join(tiles_dir, name);
    return *out == NULL ? gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory") : GDT_OK;
}

gdt_status tr_interrupted(const char *job, const char *where, gdt_error *err)
{
    return gdt_error_set(err, GDT_EINTERRUPTED, 1302,
                         "stopped by a signal during %s; rerun the same command (or "
                         "gdt-tile --resume %s) to continue",
                         where, job);
}
