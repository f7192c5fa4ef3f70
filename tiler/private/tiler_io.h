/* tiler_io.h — spill records and buffered record files of the tiler.
 *
 * A record is 32 bytes little-endian: int64 x, int64 y, IEEE double z,
 * uint64 ord, whatever the host byte order.
 *
 * tl_wfile: a record file written through a caller-sized buffer.  The file
 * is created on the first flush (so a writer that never receives a record
 * costs no descriptor), under the temporary name; tl_wfile_commit flushes,
 * optionally fsyncs, closes and renames it to the final name (a writer
 * without a final name keeps its temporary name).  tl_wfile_abort closes and
 * unlinks.  With tl_wfile_hash, the writer also computes the file's
 * checksum (gdt_hash64_wide) over the bytes as they are written.  tl_rfile: sequential reads of a record file through a
 * caller-sized buffer.
 *
 * Errors: GDT_EIO 4502 (create), 4503 (write), 4504 (read), 4505 (fsync,
 * rename), GDT_EJOB 6503 (a record file of another size than written: the
 * job directory was changed under the run), GDT_EINTERNAL 7001.
 */
#ifndef GDT_TILER_IO_H
#define GDT_TILER_IO_H

#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "gdt_cloud.h"
#include "gdt_error.h"
#include "private/job.h"

#define TL_REC 32 /* bytes per record (GDT_TILER_REC_BYTES) */

static inline uint64_t tl_le64(uint64_t v)
{
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__
    return __builtin_bswap64(v);
#else
    return v;
#endif
}

static inline uint32_t tl_le32(uint32_t v)
{
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__
    return __builtin_bswap32(v);
#else
    return v;
#endif
}

static inline void tl_rec_put(unsigned char *dst, const gdt_point *p)
{
    uint64_t w[4];
    memcpy(&w[0], &p->x, 8);
    memcpy(&w[1], &p->y, 8);
    memcpy(&w[2], &p->z, 8);
    memcpy(&w[3], &p->ord, 8);
    for (int i = 0; i < 4; i++)
        w[i] = tl_le64(w[i]);
    memcpy(dst, w, sizeof w);
}

/* x, y and z of a record, without its ordinal. */
static inline void tl_rec_xyz(const unsigned char *src, int64_t *x, int64_t *y, double *z)
{
    uint64_t w[3];
    memcpy(w, src, sizeof w);
    w[0] = tl_le64(w[0]);
    w[1] = tl_le64(w[1]);
    w[2] = tl_le64(w[2]);
    memcpy(x, &w[0], 8);
    memcpy(y, &w[1], 8);
    memcpy(z, &w[2], 8);
}

static inline void tl_rec_get(gdt_point *p, const unsigned char *src)
{
    uint64_t w[4];
    memcpy(w, src, sizeof w);
    for (int i = 0; i < 4; i++)
        w[i] = tl_le64(w[i]);
    memcpy(&p->x, &w[0], 8);
    memcpy(&p->y, &w[1], 8);
    memcpy(&p->z, &w[2], 8);
    memcpy(&p->ord, &w[3], 8);
}

typedef struct tl_wfile {
    int fd;                /* -1 until the first flush */
    char *tmp_path;        /* owned */
    char *final_path;      /* owned; NULL: the file keeps tmp_path */
    unsigned char *buf;    /* cap records; owned unless borrowed */
    int borrowed;          /* buf belongs to the caller */
    size_t len, cap;       /* records */
    uint64_t nrec;         /* records written to the file so far (flushed or not) */
    int durable;           /* TL_SYNC_*: what the commit does for durability */
    int hashed;            /* hash holds the checksum of the bytes flushed */
    gdt_hash_wide hash;
} tl_wfile;

/* tl_wfile's durable: nothing; fsync before the rename; or only start the
 * writeback before the rename (the file is made durable later with the
 * others of its directory, tl_sync_files, while work goes on). */
enum { TL_SYNC_NONE = 0, TL_SYNC_NOW = 1, TL_SYNC_LATER = 2 };

/* Prepares a writer (no file yet).  final_path may be NULL.  cap >= 1.
 * Ownership: paths are copied; release with tl_wfile_commit or _abort. */
gdt_status tl_wfile_init(tl_wfile *w, const char *tmp_path, const char *final_path, size_t cap,
                         int durable, gdt_error *err);
/* The same with a caller-owned buffer of cap records (not freed here). */
gdt_status tl_wfile_init_buf(tl_wfile *w, const char *tmp_path, const char *final_path,
                             unsigned char *buf, size_t cap, int durable, gdt_error *err);
gdt_status tl_wfile_flush(tl_wfile *w, gdt_error *err);
/* Starts the checksum (before the first put). */
void tl_wfile_hash(tl_wfile *w, uint64_t seed);
/* The checksum of every record put so far (flushes first). */
gdt_status tl_wfile_sum(tl_wfile *w, uint64_t *sum, gdt_error *err);

static inline gdt_status tl_wfile_put(tl_wfile *w, const gdt_point *p, gdt_error *err)
{
    if (w->len == w->cap) {
        gdt_status st = tl_wfile_flush(w, err);
        if (st != GDT_OK)
            return st;
    }
    tl_rec_put(w->buf + w->len * TL_REC, p);
    w->len++;
    w->nrec++;
    return GDT_OK;
}

/* Flushes, creates the file if it received no record (an empty file),
 * fsyncs when durable, closes and renames; frees everything.  On failure the
 * file is removed and everything freed as well. */
gdt_status tl_wfile_commit(tl_wfile *w, gdt_error *err);
/* Closes, unlinks (temporary name) and frees; safe on a zeroed or released
 * writer. */
void tl_wfile_abort(tl_wfile *w);

typedef struct tl_rfile {
    int fd;
    char *path;            /* owned, for messages */
    unsigned char *buf;    /* owned unless borrowed */
    int borrowed;          /* buf is the caller's (tl_rfile_open_buf) */
    size_t pos, len, cap;  /* records */
    uint64_t left;         /* records not yet delivered */
} tl_rfile;

/* Opens path, which must hold exactly nrec records (checked against its
 * size).  cap >= 1.  Ownership: release with tl_rfile_close. */
gdt_status tl_rfile_open(tl_rfile *r, const char *path, uint64_t nrec, size_t cap,
                         gdt_error *err);
/* The same, reading through the caller's buffer buf of cap * TL_REC bytes,
 * which must outlive r: a caller that opens many files in turn keeps one
 * buffer instead of faulting in a fresh one per file. */
gdt_status tl_rfile_open_buf(tl_rfile *r, const char *path, uint64_t nrec, unsigned char *buf,
                             size_t cap, gdt_error *err);
/* Next record into *p; *got = 0 at the end. */
gdt_status tl_rfile_next(tl_rfile *r, gdt_point *p, int *got, gdt_error *err);
/* Up to cap records into out[]; *n = 0 at the end. */
gdt_status tl_rfile_read(tl_rfile *r, gdt_point *out, size_t cap, size_t *n, gdt_error *err);
/* Up to cap records as they are in the file (TL_REC bytes each, decode with
 * tl_rec_get or field by field): *rec points into r's buffer, valid until
 * the next read from r; *n = 0 at the end. */
gdt_status tl_rfile_raw(tl_rfile *r, const unsigned char **rec, size_t cap, size_t *n,
                        gdt_error *err);
void tl_rfile_close(tl_rfile *r);

/* A record file of exactly nrec records (checked against its size, as
 * tl_rfile_open does) mapped read-only at *map, *len bytes (NULL and 0 for
 * an empty file), read ahead as advice.  The records are read in place
 * (tl_rec_get, tl_rec_xyz); its pages are the page cache's, which the
 * kernel can take back under pressure.  A file cut short while it is
 * mapped would end the process with SIGBUS: job files are the run's own.
 * returns: GDT_OK; GDT_EIO 4504 (open, map); GDT_EJOB 6503 (its size).
 * Ownership: release with tl_unmap_records. */
gdt_status tl_map_records(const char *path, uint64_t nrec, const unsigned char **map,
                          size_t *len, gdt_error *err);
/* Advice only: the mapped records below record `below` are handed back
 * (their pages are mapped again from the page cache if read after all);
 * *released is the byte count handed back so far, 0 at the start. */
void tl_release_records(const unsigned char *map, size_t len, size_t *released, uint64_t below);
void tl_unmap_records(const unsigned char *map, size_t len);

/* Size of a file in records (GDT_EIO 4504 if it cannot be stat'ed or its
 * size is not a multiple of the record size). */
gdt_status tl_file_records(const char *path, uint64_t *nrec, gdt_error *err);

/* Reads the whole file path once: *size its bytes, *sum its gdt_hash64_wide
 * with seed.  returns: GDT_EIO 4504 (open, read), GDT_EINTERNAL 7001. */
gdt_status tl_file_sum(const char *path, uint64_t seed, uint64_t *size, uint64_t *sum,
                       gdt_error *err);

/* fsync of a directory (after renames); GDT_EIO 4505. */
gdt_status tl_sync_dir(const char *dir, gdt_error *err);

/* Every file written in dir made durable at once: syncfs of its file
 * system (all that this machine wrote there, one wait instead of one per
 * file), then the directory itself.  returns: GDT_EIO 4505. */
gdt_status tl_sync_files(const char *dir, gdt_error *err);

/* Writes all len bytes of p to fd (retrying short writes and EINTR).
 * returns: GDT_EIO 4503 naming path. */
gdt_status tl_write_all(int fd, const unsigned char *p, size_t len, const char *path,
                        gdt_error *err);

/* malloc'd "%s/%s" style path; NULL when out of memory. */
char *tl_path(const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 1, 2)))
#endif
    ;

/* Sorts a[0..n) by ord (ords need not be distinct; equal ords keep their
 * order).  LSD radix sort on ord - min(ord); tmp holds n records or is NULL
 * (then it is allocated).  returns: GDT_EINTERNAL 7001. */
gdt_status tl_sort_by_ord(gdt_point *a, size_t n, gdt_point *tmp, gdt_error *err);

/* Floor division, b > 0. */
static inline int64_t tl_floor_div(int64_t a, int64_t b)
{
    int64_t q = a / b;
    return (a % b != 0 && a < 0) ? q - 1 : q;
}

#endif
