/* gdt_source.h — streaming point sources (LAS, LAZ, PCD).
 *
 * A source yields the points of one input file in file order, in chunks the
 * caller sizes; it never holds more than one bounded read buffer, whatever
 * the file size.  Every header field that could lie is checked against the
 * file before the first point is returned; a file that ends early or holds a
 * different number of points than it claims is a GDT_EINPUT error when the
 * discrepancy is met.
 *
 * Not thread-safe per instance; separate instances are independent.
 */
#ifndef GDT_SOURCE_H
#define GDT_SOURCE_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_error.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef enum gdt_format {
    GDT_FORMAT_UNKNOWN = 0,
    GDT_FORMAT_LAS,
    GDT_FORMAT_PCD
} gdt_format;

/* Point attribute flags (gdt_src_point.flags), as LAS stores them. */
enum {
    GDT_PT_SYNTHETIC = 1u << 0, /* created by a process other than the scan */
    GDT_PT_KEYPOINT = 1u << 1,  /* model key point: keep when thinning */
    GDT_PT_WITHHELD = 1u << 2,  /* to be treated as deleted (LAS spec) */
    GDT_PT_OVERLAP = 1u << 3    /* formats 6-10: overlap of flight lines */
};

/* One point as stored in the file.  The attributes are those of the LAS
 * record (formats 0-5: class is the low 5 bits of the classification byte,
 * the flags its top 3 bits; formats 6-10: the full class byte and the four
 * class flags); they are zero for formats without them (PCD). */
typedef struct gdt_src_point {
    double x, y, z;     /* CRS units; for LAS x = X * scale_x + offset_x (in double) */
    int32_t X, Y, Z;    /* LAS record integers (exact); 0 for formats without a lattice */
    uint8_t cls;        /* ASPRS classification code */
    uint8_t ret;        /* return number (formats 0-5: 0..7, 6-10: 0..15) */
    uint8_t nret;       /* number of returns of the pulse */
    uint8_t flags;      /* GDT_PT_* */
} gdt_src_point;

/* What the file's header says, after validation.  Strings are owned by the
 * source and live until gdt_source_close. */
typedef struct gdt_source_info {
    gdt_format format;
    char format_name[16];      /* "LAS", "LAZ" (format LAS, compressed), "PCD" */
    int compressed;            /* 1: decoding costs far more than reading (LAZ) */
    char version[16];          /* "1.4", "0.7" */
    char encoding[32];         /* LAS: "point format 3"; PCD: "ascii" / "binary" / "binary_compressed" */
    uint64_t point_count;      /* header count, verified against the file size where possible */
    int has_bounds;            /* header carries bounds (LAS) */
    double min[3], max[3];
    int has_lattice;           /* coordinates are integers with scale/offset (LAS) */
    double scale[3], offset[3];
    int z_is_float32;          /* PCD: z stored as F4 */
    int xy_is_float32;         /* PCD: x/y stored as F4 (precision warning given) */
    /* Coordinate reference system as found in the file: */
    int epsg;                  /* EPSG code when known, else 0 */
    const char *crs_wkt;       /* OGC WKT (LAS WKT VLR), or NULL */
    int crs_geographic;        /* 1 when coordinates are longitude/latitude degrees */
    const char *crs_desc;      /* short human description, never NULL (may be "") */
    /* LAS details for --info */
    unsigned point_format;     /* LAS point data format 0..10 */
    unsigned record_length;    /* bytes per point record */
    unsigned extra_bytes;      /* bytes per record beyond the standard format */
    unsigned vlr_count;        /* VLRs actually read */
    unsigned evlr_count;       /* EVLRs actually read */
    uint64_t file_size;
    /* LAZ details for --info (all zero for an uncompressed file): */
    char compressor[24];       /* "pointwise chunked", "layered chunked", "pointwise" */
    char laz_items[256];       /* the LASzip items, "POINT10 v2, GPSTIME11 v2, RGB12 v2" */
    uint32_t laz_chunk_size;   /* points per chunk; 0: variable */
    uint64_t laz_chunks;       /* chunks in the chunk table; 0: the file has none */
} gdt_source_info;

typedef struct gdt_source gdt_source;

/* Point fields a reader must fill (gdt_source_opts.need); readers of
 * formats that store fields separately (LAZ point formats 6-10) skip the
 * others, which are then zero. */
enum {
    GDT_SRC_NEED_XYZ = 1u << 0,   /* x, y, z, X, Y, Z: always filled */
    GDT_SRC_NEED_CLASS = 1u << 1, /* cls */
    GDT_SRC_NEED_FLAGS = 1u << 2, /* ret, nret, flags */
    GDT_SRC_NEED_ATTRS = GDT_SRC_NEED_CLASS | GDT_SRC_NEED_FLAGS
};

typedef struct gdt_source_opts {
    gdt_log *log;             /* warnings go here; may be NULL */
    size_t buffer_bytes;      /* read-buffer size; 0 = default (1 MiB). Tests use tiny ones. */
    unsigned need;            /* GDT_SRC_NEED_* bits; 0 = every field */
    int threads;              /* decoder threads for compressed inputs; <= 1: none
                                 (the caller's thread decodes).  The points and their
                                 order never depend on it. */
} gdt_source_opts;

/* Opens path, sniffs its format from its content (not its name), reads and
 * validates the header.  On success *out is a new source the caller must
 * close with gdt_source_close.  On failure *out is NULL and err names the
 * file and the reason. */
gdt_status gdt_source_open(gdt_source **out, const char *path, const gdt_source_opts *opts,
                           gdt_error *err);

const gdt_source_info *gdt_source_get_info(const gdt_source *src);
const char *gdt_source_path(const gdt_source *src);

/* Reads up to cap points into buf; *n is the number read, 0 at the end of the
 * points.  Once it has returned 0 it keeps returning 0.  A file that holds
 * fewer points than its header says fails with GDT_EINPUT here. */
gdt_status gdt_source_read(gdt_source *src, gdt_src_point *buf, size_t cap, size_t *n,
                           gdt_error *err);

/* As gdt_source_read, and the records themselves: record i's
 * info.record_length bytes, exactly as the LAS file stores them (decoded,
 * for LAZ: with every field, so open the source with need 0), go to
 * raw + i * record_length.  LAS and LAZ sources only.
 * returns: as gdt_source_read; GDT_EUSAGE 2150 (not a LAS source). */
gdt_status gdt_source_read_raw(gdt_source *src, gdt_src_point *buf, unsigned char *raw,
                               size_t cap, size_t *n, gdt_error *err);

/* 1 when gdt_source_seek can start src at any record: fixed-size records
 * (uncompressed LAS, PCD DATA binary).  LAZ starts at its chunks
 * (gdt_source_starts); PCD ascii (text lines) and binary_compressed (one
 * compressed block) from their first record only. */
int gdt_source_can_seek(const gdt_source *src);

/* The records where a chunked source (LAZ with a chunk table) can start:
 * the first record of each chunk, ascending (out[0] = 0), up to cap of
 * them; returns their number, 0 for a source that starts at any record
 * (gdt_source_can_seek) or only at its first. */
uint64_t gdt_source_starts(const gdt_source *src, uint64_t *out, uint64_t cap);

/* Makes record rec (0 <= rec <= point count) the next one read, before the
 * first read only, and says that no record at or after end is wanted (a
 * LAZ source then decodes no chunk past the one holding end - 1, and the
 * caller stops reading there; a PCD binary source stops at end itself,
 * since the records it skips for invalid coordinates are not points).  rec is any record of a source that can
 * seek, or one of gdt_source_starts.  returns: GDT_EINTERNAL 7102 (the
 * format cannot, or rec is out of range or not a start, or points were
 * read already). */
gdt_status gdt_source_seek(gdt_source *src, uint64_t rec, uint64_t end, gdt_error *err);

/* Closes the file and frees everything; src may be NULL. */
void gdt_source_close(gdt_source *src);

/* Checks, without opening it (stat only: opening a FIFO blocks), that path
 * can be an input: an existing regular file (symbolic links followed).
 * returns: GDT_EINPUT 3001 (cannot be opened: missing, no permission),
 * 3004 (a directory), 3005 (a FIFO, device or socket: every input is read
 * more than once, so a stream cannot be one); GDT_EIO 4002 (stat failed
 * otherwise).  gdt_source_open and gdt_source_sniff check this first. */
gdt_status gdt_source_check_path(const char *path, gdt_error *err);

/* "a regular file", "a directory", "a FIFO (pipe)", "a character device",
 * ... for a st_mode of stat(2); a static string. */
const char *gdt_file_kind(unsigned mode);

/* Format sniffing only (reads at most the first 512 bytes). */
gdt_status gdt_source_sniff(const char *path, gdt_format *fmt, gdt_error *err);

#ifdef __cplusplus
}
#endif
#endif
