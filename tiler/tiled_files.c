/* tiled_files.c — paths and messages shared by the stages of the tiled run
 * (see private/tiled_files.h). */
#include "private/tiled_files.h"

#include <errno.h>
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

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

gdt_status tr_open_tri(const char *tiles_dir, const gdt_tile_desc *d, uint64_t base, FILE **f,
                       unsigned char hdr[TR_HEADER], uint64_t *size, char **path,
                       gdt_error *err)
{
    struct stat sb;
    gdt_status st = tr_tile_path(tiles_dir, d, "tri", path, err);

    *f = NULL;
    if (st != GDT_OK)
        return st;
    *f = fopen(*path, "rb");
    if (*f == NULL || fstat(fileno(*f), &sb) != 0) {
        st = gdt_error_set(err, GDT_EIO, 4805, "%s: cannot open: %s", *path, strerror(errno));
    } else if (fread(hdr, 1, TR_HEADER, *f) != TR_HEADER || memcmp(hdr, TR_MAGIC, 8) != 0 ||
               tr_get_u64(hdr + 8) != base || tr_get_u64(hdr + 16) != d->points) {
        st = gdt_error_set(err, GDT_EJOB, 6801, "%s: not the tile file this run wrote", *path);
    } else {
        *size = (uint64_t)sb.st_size;
        return GDT_OK;
    }
    if (*f != NULL)
        fclose(*f);
    *f = NULL;
    return st;
}

gdt_status tr_interrupted(const char *job, const char *where, gdt_error *err)
{
    return gdt_error_set(err, GDT_EINTERRUPTED, 1302,
                         "stopped by a signal during %s; rerun the same command (or "
                         "gdt-tile --resume %s) to continue",
                         where, job);
}
