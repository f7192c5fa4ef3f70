/* laz_stream.h — the point records of a LAZ file, in file order.
 *
 * The LAS reader (las.c) hands the records this stream yields to the same
 * record-to-point conversion it uses for LAS, so a LAZ file gives exactly
 * the points of the LAS file it compresses.
 *
 * design:
 *   open:  parses the LASzip VLR (laz_chunk.h), reads and checks the chunk
 *          table; nothing is decoded and no thread is started.
 *   read, threads <= 1 (or no chunk table, or a single chunk): the caller's
 *          thread decodes each chunk in pieces of about piece_bytes of
 *          records, holding the chunk's compressed bytes and one piece.
 *   read, threads > 1: on the first read, W = min(threads, chunks) workers
 *          (fewer if their slots would hold more than
 *          GDT_LAZ_STREAM_SLOTS_TOTAL bytes) start, each with its own
 *          decoder and compressed-byte buffer.
 *          They claim chunks in file order and decode each whole into one
 *          of 2 W record slots (chunk i goes to slot i mod 2 W, so at most
 *          2 W chunks are decoded or waiting); the caller's thread takes
 *          the slots in chunk order.  A chunk whose records would exceed
 *          GDT_LAZ_STREAM_SLOT_MAX bytes is left to the caller's thread,
 *          which decodes it in pieces.  The records, their order, the
 *          warnings and the first error are the same for every thread
 *          count: an error of chunk i is reported when the caller reaches
 *          chunk i, after every record of chunks 0 .. i-1.
 *   checks: a table chunk whose compressed size exceeds
 *          gdt_laz_stream_bytes_max(count, record_length) is refused at
 *          open; a table chunk whose decoding uses another number of bytes
 *          than the table gives is refused when reached; a record whose
 *          coordinates lie outside the header bounds by more than one
 *          scale step gives one warning per file, naming the chunk.
 *
 * Ownership: the stream owns the VLR description, the table, its decoders,
 * threads and buffers; fd and path are borrowed and must outlive it.
 * Not thread-safe per instance (its workers are its own business).
 *
 * Message numbers: GDT_EINPUT 3970..3999 (warnings 3990..), GDT_EIO 4103
 * (a read error, as for LAS records).
 */
#ifndef GDT_LAZ_STREAM_H
#define GDT_LAZ_STREAM_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_error.h"
#include "laz_chunk.h"

/* Largest record slot a worker fills (bytes of decoded records). */
#define GDT_LAZ_STREAM_SLOT_MAX ((uint64_t)64 << 20)
/* Most bytes all the slots of a stream may hold: fewer workers start when
 * 2 W slots of the file's largest slot-sized chunk would exceed it. */
#define GDT_LAZ_STREAM_SLOTS_TOTAL ((uint64_t)1 << 30)
/* Most compressed bytes a chunk of count records of len bytes may take:
 * twice the records, plus room for a tiny chunk's coder start-up (no
 * LASzip encoder comes near it; a table claiming more is corrupt);
 * saturates at UINT64_MAX. */
static inline uint64_t gdt_laz_stream_bytes_max(uint64_t count, unsigned len)
{
    uint64_t per = 2u * (uint64_t)len;
    if (per != 0 && count > (UINT64_MAX - 65536u) / per)
        return UINT64_MAX;
    return count * per + 65536u;
}

typedef struct gdt_laz_stream_params {
    int fd;                /* the open LAZ file (borrowed) */
    const char *path;      /* for messages (borrowed) */
    uint64_t points_start; /* the header's offset to the point data */
    uint64_t region_end;   /* end of what the point data may use: the EVLR
                              start, else the file size */
    uint64_t point_count;  /* the header's count: the number of records */
    unsigned point_format; /* 0..10 (compression bits cleared) */
    unsigned record_length;
    unsigned need;                              /* GDT_LAZ_NEED_* */
    int threads;                                /* decoder threads; <= 1: the caller's thread */
    size_t piece_bytes;                         /* records per decoding step in the caller's
                                                   thread; 0 = 1 MiB */
    double scale[3], offset[3], min[3], max[3]; /* the header's lattice and bounds */
    gdt_log *log;                               /* warnings; may be NULL */
} gdt_laz_stream_params;

typedef struct gdt_laz_stream gdt_laz_stream;

/* Parses the LASzip VLR payload vlr[0 .. vlr_len) against p's point format
 * and record length and reads the chunk table.  On success *out is a new
 * stream (close with gdt_laz_stream_close); on failure *out is NULL.
 * returns: GDT_EINPUT (39xx, naming p->path), GDT_EIO, GDT_EINTERNAL 7001. */
gdt_status gdt_laz_stream_open(gdt_laz_stream **out, const unsigned char *vlr, size_t vlr_len,
                               const gdt_laz_stream_params *p, gdt_error *err);

/* The next records in file order: *recs points at *n >= 1 records of
 * record_length bytes, valid until the next call or close; *n == 0 once
 * point_count records have been given (and after).  Errors are sticky:
 * after one, every call fails again. */
gdt_status gdt_laz_stream_next(gdt_laz_stream *s, const unsigned char **recs, size_t *n,
                               gdt_error *err);

/* The records where reading can start: the first record of every chunk
 * of the table, ascending (out[0] = 0), up to cap of them; returns their
 * number (0 without a table: the stream starts at record 0 only). */
uint64_t gdt_laz_stream_starts(const gdt_laz_stream *s, uint64_t *out, uint64_t cap);

/* Before the first read: the stream gives the records [first, end') of
 * the file, first one of gdt_laz_stream_starts (or end, or 0) and end'
 * the end of the chunk holding record end - 1 (end > point count: the
 * last record); chunks outside them are never decoded.
 * Without a table only first = 0 is possible, and every chunk up to the
 * one holding record end - 1 is decoded (the caller stops reading there).
 * returns: GDT_EINTERNAL 7102 (after a read; first not a chunk's first
 * record; no table and first > 0). */
gdt_status gdt_laz_stream_seek(gdt_laz_stream *s, uint64_t first, uint64_t end, gdt_error *err);

/* Stops and joins the workers and frees everything; s may be NULL. */
void gdt_laz_stream_close(gdt_laz_stream *s);

/* What --info shows: the compressor ("pointwise chunked", ...), the item
 * list ("POINT10 v2, GPSTIME11 v2"), the points per chunk (0: variable)
 * and the number of chunks (0: unknown, the file has no usable table). */
typedef struct gdt_laz_stream_desc {
    const char *compressor; /* static string */
    char items[256];
    uint32_t chunk_size;
    uint64_t chunks;
} gdt_laz_stream_desc;

void gdt_laz_stream_describe(const gdt_laz_stream *s, gdt_laz_stream_desc *d);

#endif
