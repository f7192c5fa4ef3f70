/* tiled_files.h — the job files of the tiled run shared by its stages:
 * names, magic strings, little-endian codecs and paths.  Layouts are
 * described in tiled_run.h. */
#ifndef GDT_TILED_FILES_H
#define GDT_TILED_FILES_H

#include <stdint.h>
#include <stdio.h>

#include "gdt_error.h"
#include "gdt_tiler.h"

#define TR_MAGIC "GDTTRI01"
#define TR_HEADER 64
#define TR_CHUNK 65536 /* records per read or write */
#define MF_NAME "merge.faces"
#define MF_MAGIC "GDTMRG01"
#define MF_HEADER 16

static inline void tr_put_u64(unsigned char *p, uint64_t v)
{
    for (int i = 0; i < 8; i++)
        p[i] = (unsigned char)(v >> (8 * i));
}

static inline void tr_put_u32(unsigned char *p, uint32_t v)
{
    for (int i = 0; i < 4; i++)
        p[i] = (unsigned char)(v >> (8 * i));
}

static inline uint64_t tr_get_u64(const unsigned char *p)
{
    uint64_t v = 0;
    for (int i = 7; i >= 0; i--)
        v = (v << 8) | p[i];
    return v;
}

static inline uint32_t tr_get_u32(const unsigned char *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

/* "a/b", malloc'd; NULL when out of memory. */
char *tr_path_join(const char *a, const char *b);

/* tiles_dir/tile_<i>_<j>.<ext> in *out (malloc'd).
 * returns: GDT_OK; GDT_EINTERNAL 7001. */
gdt_status tr_tile_path(const char *tiles_dir, const gdt_tile_desc *d, const char *ext,
                        char **out, gdt_error *err);

/* Opens tile k's .tri file (tiles_dir, d from gdt_tiler_tile_info) and
 * checks its header against the tile: magic, vertex base `base`, d's point
 * count.  On success *f is positioned after the header (close it with
 * fclose), hdr holds the header, *size the file's size and *path its name
 * (free it; also set on failure, NULL if out of memory).
 * returns: GDT_EIO 4805 (cannot open), GDT_EJOB 6801 (not the file this run
 * wrote), GDT_EINTERNAL 7001. */
gdt_status tr_open_tri(const char *tiles_dir, const gdt_tile_desc *d, uint64_t base, FILE **f,
                       unsigned char hdr[TR_HEADER], uint64_t *size, char **path,
                       gdt_error *err);

/* The error of a run stopped by a signal during `where` (GDT_EINTERRUPTED
 * 1302), telling how to continue the job. */
gdt_status tr_interrupted(const char *job, const char *where, gdt_error *err);

#endif
