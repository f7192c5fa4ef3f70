/* laz_chunk.h — the LASzip description of a compressed point stream and the
 * decoder of one chunk of it.
 *
 * A LAZ file is a LAS file whose point format byte has bit 7 (or 6) set, that
 * carries the LASzip VLR (user "laszip encoded", record 22204) describing the
 * compressed items, and whose point data is a sequence of chunks.  Every
 * chunk is independent: it restarts the arithmetic coder and every context
 * model from the raw first point, so chunks can be decoded in any order and
 * on any thread.
 *
 * The decoder turns the bytes of one chunk into uncompressed LAS point
 * records (record_length bytes each, the standard layout of the point format
 * followed by the extra bytes), exactly the bytes the LAS file would hold.
 * The LAS reader then converts records to points with the same code for LAS
 * and LAZ.
 *
 * Message numbers: 39xx (bad input; the class is 3).
 */
#ifndef GDT_LAZ_CHUNK_H
#define GDT_LAZ_CHUNK_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_error.h"

/* Item types of the LASzip VLR. */
enum {
    GDT_LAZ_BYTE = 0,
    GDT_LAZ_POINT10 = 6,
    GDT_LAZ_GPSTIME11 = 7,
    GDT_LAZ_RGB12 = 8,
    GDT_LAZ_WAVEPACKET13 = 9,
    GDT_LAZ_POINT14 = 10,
    GDT_LAZ_RGB14 = 11,
    GDT_LAZ_RGBNIR14 = 12,
    GDT_LAZ_WAVEPACKET14 = 13,
    GDT_LAZ_BYTE14 = 14
};

/* Compressor of the LASzip VLR. */
enum {
    GDT_LAZ_COMPRESSOR_NONE = 0,
    GDT_LAZ_COMPRESSOR_POINTWISE = 1,         /* LASzip 1.x: one stream, no chunks */
    GDT_LAZ_COMPRESSOR_POINTWISE_CHUNKED = 2, /* formats 0-5 */
    GDT_LAZ_COMPRESSOR_LAYERED_CHUNKED = 3    /* formats 6-10 */
};

#define GDT_LAZ_MAX_ITEMS 16
#define GDT_LAZ_VARIABLE_CHUNKS 0xFFFFFFFFu

typedef struct gdt_laz_item {
    uint16_t type;    /* GDT_LAZ_BYTE .. GDT_LAZ_BYTE14 */
    uint16_t size;    /* bytes of the record this item covers */
    uint16_t version; /* 1, 2 (pointwise) or 3, 4 (layered) */
} gdt_laz_item;

/* The LASzip VLR, validated against the header's point format and record
 * length by gdt_laz_vlr_parse. */
typedef struct gdt_laz_vlr {
    uint16_t compressor;
    uint16_t coder;              /* 0: arithmetic, the only one defined */
    uint8_t version_major, version_minor;
    uint16_t version_revision;
    uint32_t options;
    uint32_t chunk_size;         /* points per chunk, or GDT_LAZ_VARIABLE_CHUNKS */
    int64_t special_evlr_count;  /* -1 when unused */
    int64_t special_evlr_offset; /* -1 when unused */
    unsigned nitems;
    gdt_laz_item items[GDT_LAZ_MAX_ITEMS];
} gdt_laz_vlr;

/* "POINT10", "RGB14", ... for a GDT_LAZ_* item type; NULL when unknown. */
const char *gdt_laz_item_name(unsigned type);

/* Parses the payload of the 22204 VLR and checks that its items describe
 * records of point_format (0-10) and record_length bytes exactly, that every
 * item type and version is one the decoder knows, and that the compressor
 * and coder are known.  returns: GDT_EINPUT (39xx, naming path and the
 * offending field) or GDT_OK. */
gdt_status gdt_laz_vlr_parse(const char *path, const unsigned char *payload, size_t n,
                             unsigned point_format, unsigned record_length, gdt_laz_vlr *out,
                             gdt_error *err);

/* The chunk table: where each chunk starts and how many points it holds.
 * The point data of a chunked LAZ file starts with an int64 file offset of
 * the table (-1 when the writer could not seek back: the offset is then in
 * the file's last 8 bytes); the first chunk follows those 8 bytes.
 * Invariants after gdt_laz_table_read: nchunks >= 1 when point_count > 0;
 * start[0] = points_start + 8; start[i+1] = start[i] + bytes[i];
 * start[nchunks-1] + bytes[nchunks-1] = data_end <= table offset;
 * sum(count) = point_count (the header's count, which wins over a table
 * that claims more: the surplus chunks are dropped with a warning), every
 * count >= 1.  Arrays are owned; free with gdt_laz_table_free. */
typedef struct gdt_laz_table {
    uint64_t nchunks;
    uint64_t *start;  /* file offset of chunk i */
    uint64_t *bytes;  /* compressed bytes of chunk i */
    uint64_t *count;  /* points in chunk i */
    uint64_t data_end;
    int present;      /* 0: no usable table (the caller scans the chunks
                         in order, using gdt_laz_chunk_used); then only
                         data_end (the end of the point data) is set */
} gdt_laz_table;

/* Reads and checks the chunk table of the file open as fd.  points_start is
 * the header's offset to the point data, file_end the end of the region the
 * points may use (the EVLR start or the file size), point_count the
 * header's count.  A missing or unreadable table is not an error for a
 * fixed chunk size: present = 0 and a warning through log (may be NULL);
 * for variable chunks it is GDT_EINPUT (the counts are only in the table).
 * A table that contradicts the file (chunks past file_end, zero counts,
 * counts that disagree with the fixed chunk size) is GDT_EINPUT 39xx. */
gdt_status gdt_laz_table_read(gdt_laz_table *t, const gdt_laz_vlr *vlr, int fd,
                              const char *path, uint64_t points_start, uint64_t file_end,
                              uint64_t point_count, gdt_log *log, gdt_error *err);
void gdt_laz_table_free(gdt_laz_table *t);

/* The fields a run needs.  Layered chunks (formats 6-10) decode only the
 * layers these need and skip the others by their byte counts; in the
 * records returned, the bytes of fields not decoded are zero.  Pointwise
 * chunks always decode everything (their fields share one stream). */
enum {
    GDT_LAZ_NEED_XYZ = 1u << 0,     /* X, Y, Z (and, layered, the return layer XY needs) */
    GDT_LAZ_NEED_CLASS = 1u << 1,   /* classification */
    GDT_LAZ_NEED_FLAGS = 1u << 2,   /* return number, number of returns, class flags */
};
/* every byte of every record (tests, oracles); a macro, as an enum constant
 * must fit an int */
#define GDT_LAZ_NEED_ALL 0xFFFFFFFFu

typedef struct gdt_laz_chunk gdt_laz_chunk;

/* A decoder for chunks of the stream vlr describes; it owns its context
 * models and reuses them for every chunk it is given.  vlr must outlive it.
 * One decoder per thread: it is not thread-safe, separate ones are
 * independent. */
gdt_status gdt_laz_chunk_new(gdt_laz_chunk **out, const gdt_laz_vlr *vlr,
                             unsigned record_length, unsigned need, gdt_error *err);
void gdt_laz_chunk_free(gdt_laz_chunk *c);

/* Starts decoding one chunk of npoints points (npoints >= 1) whose bytes are
 * data[0 .. avail): avail is the chunk's size from the chunk table, or, with
 * no table, every byte up to the end of the point data.  The bytes must stay
 * valid and unchanged until the chunk is finished.  path and chunk_index
 * (0-based) only name the chunk in messages.  Layered chunks read and check
 * their layer sizes here (GDT_EINPUT when they exceed avail). */
gdt_status gdt_laz_chunk_start(gdt_laz_chunk *c, const unsigned char *data, size_t avail,
                               uint64_t npoints, const char *path, uint64_t chunk_index,
                               gdt_error *err);

/* Decodes the next n points of the current chunk into records
 * (n * record_length bytes).  The sum of n over the calls must not exceed
 * the chunk's npoints.  A stream that needs bytes beyond avail, or a
 * context model driven into a state no encoder produces, is GDT_EINPUT
 * (39xx) naming path, the chunk and the point within it; the decoder never
 * reads outside data[0 .. avail) and never allocates per point. */
gdt_status gdt_laz_chunk_read(gdt_laz_chunk *c, unsigned char *records, size_t n,
                              gdt_error *err);

/* After all npoints points are read: the number of bytes the chunk used,
 * counted from data.  For a chunk from the table the caller checks it
 * equals avail (a mismatch is a corrupt chunk); with no table it is where
 * the next chunk starts.  Layered: the raw first point, the count, the
 * layer sizes and every layer, decoded or not. */
size_t gdt_laz_chunk_used(const gdt_laz_chunk *c);

#endif
