/* tiled_files.h — the job files of the tiled run shared by its stages:
 * names, magic strings, little-endian codecs and paths.  Layouts are
 * described in tiled_run.h. */
#ifndef GDT_TILED_FILES_H
#define GDT_TILED_FILES_H

#include <stdint.h>
#include <string.h>
#include <stdio.h>

#include "gdt_direct_io.h"
#include "gdt_error.h"
#include "gdt_seam.h"
#include "gdt_trim.h"
#include "gdt_tiler.h"
#include "private/tiler_io.h"

#define TR_MAGIC "GDTTRI02"
#define TR_HEADER 64
#define TR_SEAM_VERTEX 32 /* bytes of a seam vertex record */
#define TR_CHUNK 65536 /* records per read or write */
#define MF_NAME "merge.faces"
/* --check of an OBJ or LandXML output: the PLY copy the checker reads */
#define CHECK_PLY_NAME "check.ply"
#define MF_MAGIC "GDTMRG01"
#define MF_HEADER 16
/* With --dem, the merge's faces' vertices beside merge.faces, in the same
 * order: "GDTMDM01", u64 face count, then per face 3 x (i64 x, i64 y in
 * the global lattice, f64 z). */
#define MD_NAME "merge.dem"
#define MD_MAGIC "GDTMDM01"
#define MD_RECORD 72
/* The trim section that ends a .tri file in a job with --max-edge or
 * --concavity (gdt_trim.h), after the barrier edges: "GDTTRM01", u64 cut
 * faces, u64 candidates, u64 open edges; then the cut faces (u32, strictly
 * increasing), the candidates (u32 face, strictly increasing; u32 label, a
 * face number), the open edges (u64 a < u64 b, vertices of the tile; u32
 * label). */
#define TT_MAGIC "GDTTRM01"
#define TT_HEADER 32

/* Little-endian words (tl_le64/tl_le32 of tiler_io.h: whole-word memcpy,
 * since byte loops are not always merged by the compiler). */
static inline void tr_put_u64(unsigned char *p, uint64_t v)
{
    v = tl_le64(v);
    memcpy(p, &v, sizeof v);
}

static inline void tr_put_u32(unsigned char *p, uint32_t v)
{
    v = tl_le32(v);
    memcpy(p, &v, sizeof v);
}

static inline uint64_t tr_get_u64(const unsigned char *p)
{
    uint64_t v;
    memcpy(&v, p, sizeof v);
    return tl_le64(v);
}

static inline uint32_t tr_get_u32(const unsigned char *p)
{
    uint32_t v;
    memcpy(&v, p, sizeof v);
    return tl_le32(v);
}

/* "a/b", malloc'd; NULL when out of memory. */
char *tr_path_join(const char *a, const char *b);

/* tiles_dir/tile_<i>_<j>.<ext> in *out (malloc'd).
 * returns: GDT_OK; GDT_EINTERNAL 7001. */
gdt_status tr_tile_path(const char *tiles_dir, const gdt_tile_desc *d, const char *ext,
                        char **out, gdt_error *err);

/* What a reader expects of a tile's .tri file: the header must carry the
 * tile's vertex base and point count, and job_id[0..1] when job_id is not
 * NULL. */
typedef struct tr_tri_expect {
    uint64_t base;          /* id of the tile's first vertex */
    uint64_t points;        /* the tile's point count */
    const uint64_t *job_id; /* 2 words, or NULL: not checked */
    int trim;               /* the file ends with a trim section */
} tr_tri_expect;

/* The counts of a trim section. */
typedef struct tr_trim_counts {
    uint64_t ncut, ncand, nopen;
} tr_trim_counts;

/* Checks the trim section header th, at offset `at` of a .tri file of size
 * bytes with nf certified faces: magic, and the counts add up to the
 * file's end, without overflow.  Returns 0 and *tc when it fits. */
int tr_trim_check(const unsigned char th[TT_HEADER], uint64_t at, uint64_t size, uint64_t nf,
                  tr_trim_counts *tc);

/* The verdicts of tr_tri_check_header, in the order it tests them. */
typedef enum tr_tri_verdict {
    TR_TRI_FITS,    /* the header fits the tile and the file's size */
    TR_TRI_FOREIGN, /* magic, base or point count is not the tile's */
    TR_TRI_SIZE,    /* the counts do not add up to the file's size */
    TR_TRI_JOB      /* the header names another job */
} tr_tri_verdict;

/* Checks the header hdr (TR_HEADER bytes) of a .tri file of size bytes:
 * TR_HEADER + 12 nf + 32 nv + 16 ne == size (with ex->trim: that plus
 * TT_HEADER at most size; tr_trim_check then checks the rest), computed
 * without overflow
 * (each count is first bounded by size), and at most one seam vertex per
 * point.  The counts go to *nf, *nv, *ne (also on failure: for messages).
 * A tile whose base + points overflows is foreign: no run numbers its
 * vertices so. */
tr_tri_verdict tr_tri_check_header(const unsigned char hdr[TR_HEADER], uint64_t size,
                                   const tr_tri_expect *ex, uint64_t *nf, uint64_t *nv,
                                   uint64_t *ne);

/* Opens tile d's .tri file (tiles_dir, d from gdt_tiler_tile_info) for
 * tr_tri_read_seam: *f (close it with fclose), *size its size, *path its
 * name (free it; also set on failure, NULL if out of memory).
 * returns: GDT_EIO 4805 (cannot open), GDT_EINTERNAL 7001. */
gdt_status tr_open_tri(const char *tiles_dir, const gdt_tile_desc *d, FILE **f, uint64_t *size,
                       char **path, gdt_error *err);

/* The one parser of a .tri file's seam section: reads the header of f (a
 * file of size bytes, read from its start) and checks it against ex, then
 * appends the seam vertices and barrier edges to s (grown as needed; the
 * entries it had are kept).  Every vertex id and edge end must lie in
 * [ex->base, ex->base + ex->points) and every coordinate in the merge
 * frame [0, GDT_COORD_MAX].  scratch holds TR_SEAM_VERTEX * TR_CHUNK bytes.  On
 * failure s may hold some of the file's entries after its own.  path names
 * f in messages.
 * returns: GDT_OK; GDT_EIO 4805 (seek or read failed); GDT_EJOB 6801 (not
 * the tile file this run wrote: TR_TRI_FOREIGN, TR_TRI_JOB or a short
 * header), 6802 (its size or content does not match its header);
 * GDT_EINTERNAL 7001. */
gdt_status tr_tri_read_seam(FILE *f, uint64_t size, const tr_tri_expect *ex, gdt_seam *s,
                            unsigned char *scratch, const char *path, gdt_error *err);

/* With ex->trim, after tr_tri_read_seam on the same f: the open edges of the
 * trim section into *open (grown as needed, replacing what it held; *nopen
 * set).  Every edge must join two vertices of the tile in increasing order
 * and carry a label below the tile's face count.
 * returns: GDT_OK; GDT_EIO 4805; GDT_EJOB 6802 (section damaged);
 * GDT_EINTERNAL 7001. */
gdt_status tr_tri_read_open(FILE *f, uint64_t size, const tr_tri_expect *ex,
                            gdt_trim_open **open, size_t *nopen, size_t *cap_open,
                            unsigned char *scratch, const char *path, gdt_error *err);

/* Direct I/O for the large tile files, which are written once and read
 * once (gdt_direct_io.h): whole blocks bypass the page cache where the file
 * system allows it. */
#define TR_DREAD_BYTES ((size_t)1 << 20) /* read buffer of the tile-file readers */

/* Writes all len bytes of buf (aligned to GDT_DIO_BLOCK when *direct) to fd
 * at its position: whole blocks directly, then the tail through the page
 * cache (fd leaves direct mode; *direct = 0).  path names fd in errors.
 * returns: GDT_OK; GDT_EIO 4803. */
gdt_status tr_write_direct(int fd, int *direct, const unsigned char *buf, size_t len,
                           const char *path, gdt_error *err);

/* A sequential reader of a file, with direct I/O where allowed. */
typedef struct tr_dread {
    int fd;             /* -1: closed */
    int direct;
    unsigned char *buf; /* cap bytes, aligned to GDT_DIO_BLOCK; owned */
    size_t cap, pos, len;
    uint64_t off;       /* file offset of buf[len] */
    char *path;         /* owned, for messages */
} tr_dread;

/* Opens path; cap (a multiple of GDT_DIO_BLOCK) bytes of buffer.  cached:
 * through the page cache, read ahead (a file written with cached set and
 * read back soon, see tr_write_atomic), else direct where allowed.
 * returns: GDT_OK; GDT_EIO 4805 (cannot open); GDT_EINTERNAL 7001. */
gdt_status tr_dread_open(tr_dread *r, const char *path, size_t cap, int cached, gdt_error *err);
/* The next n bytes into dst; *got < n only at the end of the file.
 * returns: GDT_OK; GDT_EIO 4806 (read failed). */
gdt_status tr_dread_bytes(tr_dread *r, void *dst, size_t n, size_t *got, gdt_error *err);
/* Safe on a zeroed or closed reader. */
void tr_dread_close(tr_dread *r);

/* Finishes a file written through tmp: fsync (unless nosync), close, then
 * rename to path.  *fd is closed and set to -1 whatever happens; on failure
 * the caller removes tmp.
 * returns: GDT_OK; GDT_EIO 4803 (close), 4804 (fsync, rename). */
gdt_status tr_commit_tmp(int *fd, const char *tmp, const char *path, int nosync,
                         gdt_error *err);

/* Writes buf (aligned to GDT_DIO_BLOCK) to path through path.tmp, with
 * direct I/O where allowed (tr_write_direct) unless cached (the file is
 * read back soon: it stays in the page cache), then fsync (unless nosync)
 * and rename.  On failure nothing is left at either name.
 * returns: GDT_OK; GDT_EIO 4802 (cannot create), 4803, 4804; GDT_EINTERNAL
 * 7001. */
gdt_status tr_write_atomic(const char *path, const unsigned char *buf, size_t len, int nosync,
                           int cached, gdt_error *err);

/* The error of a run stopped by a signal during `where` (GDT_EINTERRUPTED
 * 1302), telling how to continue the job. */
gdt_status tr_interrupted(const char *job, const char *where, gdt_error *err);

#endif
