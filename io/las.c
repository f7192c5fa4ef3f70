/* LAS 1.0–1.4 and LAZ point reader (point data formats 0–10), streamed.
 *
 * design:
 *   open:  read the fixed header (at most LAS_HEADER_MAX bytes), validate every
 *          field against the version and the file size, locate the point
 *          records (offset, count × record length, up to the EVLRs or the end
 *          of the file) before looking at any VLR, then walk the VLRs and
 *          EVLRs header by header, keeping only the CRS payloads (each at most
 *          64 KiB for a VLR, LAS_WKT_MAX for an EVLR).  Nothing is allocated
 *          from a header value that has not been checked against the file.
 *   read:  the point records are streamed through one buffer of
 *          opts.buffer_bytes; a record may straddle refills.  Only the first
 *          LAS_HEAD_BYTES bytes (X, Y, Z as int32, the same in every format
 *          0–10, then the return and class bytes) are decoded
 *          (las_record_to_point); the rest of the record, extra bytes
 *          included, is skipped.
 *   LAZ:   a point format byte with the compression bits (0x80 or 0x40)
 *          marks LASzip point data: the "laszip encoded" VLR 22204 is kept
 *          while walking the VLRs, the points region runs from the offset
 *          to point data to the EVLRs (or the end of the file), and the
 *          records come decoded from a LAZ stream (private/laz_stream.h)
 *          instead of the file; they go through the same
 *          las_record_to_point.
 *
 * Messages: GDT-31xx bad input, GDT-41xx I/O, GDT-3150.. warnings; LAZ:
 * GDT-3974 here, the rest in private/laz_stream.h and private/laz_chunk.h.
 */
#include "private/bytes.h"
#include "private/fd_io.h"
#include "private/las_crs.h"
#include "private/laz_stream.h"
#include "private/source_impl.h"

#include <errno.h>
#include <fcntl.h>
#include <inttypes.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <unistd.h>

#define LAS_HEADER_MIN 227u /* LAS 1.0–1.2 header size, the smallest legal one */
#define LAS_HEADER_MAX 375u /* LAS 1.4 header size: the last field we read */
#define LAS_VLR_HEADER 54u
#define LAS_EVLR_HEADER 60u
#define LAS_WKT_MAX ((uint64_t)1 << 20) /* largest WKT EVLR we keep */
/* Bytes of a record las_record_to_point looks at: 0-11 X Y Z, 12-13
 * intensity, formats 0-5: 14 returns, 15 class and flags; 6-10: 14 returns,
 * 15 flags, 16 class.  Every format's record is at least 20 bytes. */
#define LAS_HEAD_BYTES 17u

#define LAS_GE_WAVEFORM_INTERNAL 0x2u /* global encoding: waveform data after the points */
#define LAS_GE_WKT 0x10u              /* global encoding (1.4): the CRS is WKT */

/* Bytes of the standard part of point data formats 0..10. */
static const unsigned las_base_length[11] = {20, 28, 26, 34, 57, 63, 30, 36, 38, 59, 67};
/* Smallest header size of LAS 1.<minor>. */
static const unsigned las_min_header[5] = {227, 227, 227, 235, 375};

/* The header fields we use, decoded and validated. */
typedef struct las_header {
    unsigned major, minor;
    unsigned global_encoding;
    unsigned header_size;
    uint64_t offset_to_points;
    uint32_t vlr_claimed;
    unsigned format;         /* 0..10, the compression bits cleared */
    int compressed;          /* the point format byte had 0x80 or 0x40 set: LAZ */
    unsigned record_length;
    uint64_t point_count;
    double scale[3], offset[3], min[3], max[3];
    uint64_t waveform_start; /* 1.3+, else 0 */
    uint64_t evlr_start;     /* 1.4, else 0 */
    uint32_t evlr_claimed;   /* 1.4, else 0 */
} las_header;

/* Reader state.  Invariants while streaming: buf[buf_pos..buf_len) holds the
 * file bytes just before file_pos; file_pos <= points_end; next_point points
 * have been returned. */
typedef struct las_impl {
    int fd;
    unsigned char *buf;
    size_t buf_cap, buf_pos, buf_len;
    uint64_t file_pos, points_start, points_end;
    uint64_t next_point, point_count;
    unsigned record_length;
    unsigned point_format;
    double scale[3], offset[3];
    gdt_status failed; /* status of an earlier failed read, else GDT_OK */
    gdt_laz_stream *laz;        /* LAZ: the decoded records, else NULL */
    const unsigned char *lrec;  /* LAZ: the records the stream gave, not yet converted */
    size_t lrec_left;
    char *wkt;         /* OGC WKT of the file, NUL-terminated, or NULL */
    gdt_las_crs crs;
} las_impl;

/* CRS payloads (and the LASzip VLR) collected while walking the (E)VLRs;
 * all owned. */
typedef struct las_crs_payloads {
    unsigned char *geokeys;
    size_t geokeys_len;
    char *ascii;
    size_t ascii_len;
    char *wkt;
    size_t wkt_len;
    unsigned char *laszip; /* the 22204 "laszip encoded" VLR payload */
    size_t laszip_len;
} las_crs_payloads;

/* Reads exactly n bytes at offset off.  The caller has checked that the range
 * lies inside the file size seen at open, so a short read means the file
 * shrank: bad input.  what names the structure for the message. */
static gdt_status las_pread(int fd, const char *path, void *dst, size_t n, uint64_t off,
                            const char *what, gdt_error *err)
{
    size_t got;
    int e = gdt_fd_pread_all(fd, dst, n, off, &got);
    if (e != 0)
        return gdt_error_set(err, GDT_EIO, 4103, "%s: read error at byte %" PRIu64 " (%s): %s",
                             path, off + got, what, strerror(e));
    if (got < n)
        return gdt_error_set(err, GDT_EINPUT, 3130,
                             "%s: file ends at byte %" PRIu64
                             " inside the %s (it shrank while being read)",
                             path, off + got, what);
    return GDT_OK;
}

/* Decodes and validates the fixed header from its first n bytes
 * (n = min(file size, LAS_HEADER_MAX)). */
static gdt_status las_parse_header(const char *path, const unsigned char *b, size_t n,
                                   uint64_t file_size, las_header *h, gdt_error *err)
{
    static const char *const axis = "xyz";

    memset(h, 0, sizeof *h);
    if (n < 4 || memcmp(b, "LASF", 4) != 0)
        return gdt_error_set(err, GDT_EINPUT, 3105,
                             "%s: not a LAS file (the signature is not \"LASF\")", path);
    if (n < 26)
        return gdt_error_set(err, GDT_EINPUT, 3104,
                             "%s: file is %" PRIu64 " bytes, too short"
                             " for a LAS header (at least %u bytes)",
                             path, file_size, LAS_HEADER_MIN);
    h->major = b[24];
    h->minor = b[25];
    if (h->major != 1 || h->minor > 4)
        return gdt_error_set(err, GDT_EINPUT, 3106,
                             "%s: LAS version %u.%u is not supported"
                             " (1.0 to 1.4 are)",
                             path, h->major, h->minor);
    if (n < LAS_HEADER_MIN)
        return gdt_error_set(err, GDT_EINPUT, 3104,
                             "%s: file is %" PRIu64 " bytes, too short"
                             " for a LAS header (at least %u bytes)",
                             path, file_size, LAS_HEADER_MIN);
    h->global_encoding = gdt_le_get_u16(b + 6);
    h->header_size = gdt_le_get_u16(b + 94);
    if (h->header_size < las_min_header[h->minor])
        return gdt_error_set(err, GDT_EINPUT, 3107,
                             "%s: header size %u is smaller than the"
                             " %u bytes of a LAS %u.%u header",
                             path, h->header_size, las_min_header[h->minor], h->major, h->minor);
    if (h->header_size > file_size)
        return gdt_error_set(err, GDT_EINPUT, 3108,
                             "%s: header size is %u bytes but the file"
                             " holds only %" PRIu64 " (truncated?)",
                             path, h->header_size, file_size);
    h->offset_to_points = gdt_le_get_u32(b + 96);
    h->vlr_claimed = gdt_le_get_u32(b + 100);
    unsigned fmt_byte = b[104];
    h->compressed = (fmt_byte & 0xc0u) != 0;
    h->format = fmt_byte & 0x3fu;
    if (h->format > 10)
        return gdt_error_set(err, GDT_EINPUT, 3110,
                             "%s: unknown point data format %u"
                             " (0 to 10 are defined)",
                             path, h->format);
    h->record_length = gdt_le_get_u16(b + 105);
    if (h->record_length < las_base_length[h->format])
        return gdt_error_set(err, GDT_EINPUT, 3111,
                             "%s: point record length %u is shorter"
                             " than the %u bytes of point format %u",
                             path, h->record_length, las_base_length[h->format], h->format);
    for (int k = 0; k < 3; k++) {
        h->scale[k] = gdt_le_get_f64(b + 131 + 8 * k);
        h->offset[k] = gdt_le_get_f64(b + 155 + 8 * k);
        h->max[k] = gdt_le_get_f64(b + 179 + 16 * k);
        h->min[k] = gdt_le_get_f64(b + 187 + 16 * k);
        if (!isfinite(h->scale[k]) || h->scale[k] == 0.0)
            return gdt_error_set(err, GDT_EINPUT, 3112,
                                 "%s: %c scale factor %.17g is not a"
                                 " finite non-zero number",
                                 path, axis[k], h->scale[k]);
        if (!isfinite(h->offset[k]))
            return gdt_error_set(err, GDT_EINPUT, 3113,
                                 "%s: %c offset %.17g is not a finite"
                                 " number",
                                 path, axis[k], h->offset[k]);
    }
    uint64_t legacy = gdt_le_get_u32(b + 107);
    h->point_count = legacy;
    if (h->minor >= 3)
        h->waveform_start = gdt_le_get_u64(b + 227);
    if (h->minor >= 4) {
        uint64_t count64 = gdt_le_get_u64(b + 247);
        h->evlr_start = gdt_le_get_u64(b + 235);
        h->evlr_claimed = gdt_le_get_u32(b + 243);
        if (count64 != 0) {
            if (legacy != 0 && legacy != count64)
                return gdt_error_set(err, GDT_EINPUT, 3114,
                                     "%s: the legacy point count %" PRIu64
                                     " disagrees with the 64-bit point count %" PRIu64,
                                     path, legacy, count64);
            h->point_count = count64;
        }
    }
    return GDT_OK;
}

/* Checks that the point records lie where the header says and sets
 * *points_end.  Needs only the header, so it runs before any VLR is read. */
static gdt_status las_locate_points(const char *path, const las_header *h, uint64_t file_size,
                                    gdt_log *log, uint64_t *points_end, gdt_error *err)
{
    uint64_t data_end = file_size;

    if (h->offset_to_points < h->header_size)
        return gdt_error_set(err, GDT_EINPUT, 3115,
                             "%s: offset to point data %" PRIu64 " lies inside the %u-byte header",
                             path, h->offset_to_points, h->header_size);
    if (h->offset_to_points > file_size)
        return gdt_error_set(err, GDT_EINPUT, 3116,
                             "%s: offset to point data is %" PRIu64
                             " but the file holds only %" PRIu64 " bytes (truncated?)",
                             path, h->offset_to_points, file_size);
    /* A VLR count that cannot fit in the space before the points is a corrupt
     * header, not a miscount (those are recovered from in las_scan_vlrs). */
    uint64_t vlr_room = (h->offset_to_points - h->header_size) / LAS_VLR_HEADER;
    if (h->vlr_claimed > vlr_room)
        return gdt_error_set(err, GDT_EINPUT, 3122,
                             "%s: header claims %" PRIu32 " VLRs, but"
                             " at most %" PRIu64 " (of at least %u bytes each) fit between the"
                             " header and the point data at byte %" PRIu64 ": corrupt header",
                             path, h->vlr_claimed, vlr_room, LAS_VLR_HEADER, h->offset_to_points);
    if (h->evlr_claimed > 0) {
        if (h->evlr_start > file_size)
            return gdt_error_set(err, GDT_EINPUT, 3117,
                                 "%s: the first of %" PRIu32 " EVLRs"
                                 " starts at byte %" PRIu64 ", beyond the end of the file"
                                 " (%" PRIu64 " bytes; truncated?)",
                                 path, h->evlr_claimed, h->evlr_start, file_size);
        if (h->evlr_start < h->offset_to_points)
            return gdt_error_set(err, GDT_EINPUT, 3117,
                                 "%s: the first EVLR starts at byte %" PRIu64
                                 ", before the point data at %" PRIu64,
                                 path, h->evlr_start, h->offset_to_points);
        data_end = h->evlr_start;
    }
    if (h->compressed) {
        /* LASzip point data: its size is only known from the chunk table,
         * which the LAZ stream reads and checks against this region. */
        *points_end = data_end;
        return GDT_OK;
    }
    if (h->minor >= 3 && (h->global_encoding & LAS_GE_WAVEFORM_INTERNAL) &&
        h->waveform_start > h->offset_to_points && h->waveform_start < data_end)
        data_end = h->waveform_start;

    uint64_t room = data_end - h->offset_to_points;
    uint64_t fits = room / h->record_length;
    if (h->point_count > fits)
        return gdt_error_set(err, GDT_EINPUT, 3118,
                             "%s: header claims %" PRIu64 " points of"
                             " %u bytes from byte %" PRIu64 ", but only %" PRIu64 " bytes"
                             " (%" PRIu64 " records) are there: the file is truncated or the"
                             " point count or record length is wrong",
                             path, h->point_count, h->record_length, h->offset_to_points, room,
                             fits);
    uint64_t trailing = room - h->point_count * h->record_length;
    if (trailing >= h->record_length)
        return gdt_error_set(err, GDT_EINPUT, 3119,
                             "%s: %" PRIu64 " bytes follow the %" PRIu64
                             " points the header claims, room for %" PRIu64 " more"
                             " records of %u bytes: the point count or record length is"
                             " wrong",
                             path, trailing, h->point_count, trailing / h->record_length,
                             h->record_length);
    if (trailing > 0)
        gdt_log_warn(log, 3151,
                     "%s: %" PRIu64 " unexplained bytes follow the point records;"
                     " ignoring them",
                     path, trailing);
    *points_end = h->offset_to_points + h->point_count * h->record_length;
    return GDT_OK;
}

/* Keeps the payload of a CRS record (first one of each kind wins).  len has
 * been checked against the file and against the record kind's limit.  The
 * new buffer is stored through a pointer of its field's own type: geokeys is
 * unsigned char *, ascii and wkt are char *, and a store through an
 * lvalue of the other pointer type is one the optimiser may assume never
 * happened (the pointers are not character types, so no aliasing
 * exception covers them). */
static gdt_status las_keep_payload(int fd, const char *path, unsigned record_id, uint64_t off,
                                   size_t len, const char *what, las_crs_payloads *pl,
                                   gdt_error *err)
{
    int have;
    gdt_status st;

    if (record_id == 34735)
        have = pl->geokeys != NULL;
    else if (record_id == 34737)
        have = pl->ascii != NULL;
    else if (record_id == 2112)
        have = pl->wkt != NULL;
    else
        return GDT_OK;
    if (have)
        return GDT_OK;
    unsigned char *p = malloc(len + 1);
    if (p == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    st = las_pread(fd, path, p, len, off, what, err);
    if (st != GDT_OK) {
        free(p);
        return st;
    }
    p[len] = '\0';
    if (record_id == 34735) {
        pl->geokeys = p;
        pl->geokeys_len = len;
    } else if (record_id == 34737) {
        pl->ascii = (char *)p;
        pl->ascii_len = len;
    } else {
        pl->wkt = (char *)p;
        pl->wkt_len = len;
    }
    return GDT_OK;
}

static int las_is_projection(const unsigned char *user_id)
{
    return strncmp((const char *)user_id, "LASF_Projection", 16) == 0;
}

/* Walks the VLRs between the header and the point data.  A VLR count larger
 * than what lies there is recovered from (the points are located by the
 * offset to point data): warning, the rest ignored.  A VLR that starts
 * before the point data but runs into it is an error.  Precondition:
 * las_locate_points has bounded h->vlr_claimed by the space available. */
static gdt_status las_scan_vlrs(int fd, const char *path, const las_header *h, gdt_log *log,
                                las_crs_payloads *pl, unsigned *vlr_count, gdt_error *err)
{
    uint64_t pos = h->header_size;
    unsigned char vh[LAS_VLR_HEADER];
    gdt_status st;
    uint32_t i;

    *vlr_count = 0;
    for (i = 0; i < h->vlr_claimed; i++) {
        if (pos >= h->offset_to_points) {
            gdt_log_warn(log, 3150,
                         "%s: header claims %" PRIu32 " VLRs but only %" PRIu32
                         " lie before the point data at byte %" PRIu64 "; ignoring the rest",
                         path, h->vlr_claimed, i, h->offset_to_points);
            break;
        }
        if (h->offset_to_points - pos < LAS_VLR_HEADER)
            return gdt_error_set(err, GDT_EINPUT, 3120,
                                 "%s: VLR %" PRIu32 " of %" PRIu32 " at byte %" PRIu64
                                 " runs into the point data at byte %" PRIu64
                                 ": the VLR count or the offset to point data is wrong",
                                 path, i + 1, h->vlr_claimed, pos, h->offset_to_points);
        st = las_pread(fd, path, vh, sizeof vh, pos, "VLR header", err);
        if (st != GDT_OK)
            return st;
        uint64_t len = gdt_le_get_u16(vh + 20);
        uint64_t body = pos + LAS_VLR_HEADER;
        if (len > h->offset_to_points - body)
            return gdt_error_set(
                err, GDT_EINPUT, 3120,
                "%s: VLR %" PRIu32 " of %" PRIu32 " (record %u) at byte %" PRIu64
                " ends at byte %" PRIu64 ", past the start of the point data at byte %" PRIu64
                ": the VLR length or the offset to point data is wrong",
                path, i + 1, h->vlr_claimed, gdt_le_get_u16(vh + 18), pos, body + len, h->offset_to_points);
        if (las_is_projection(vh + 2)) {
            st = las_keep_payload(fd, path, gdt_le_get_u16(vh + 18), body, (size_t)len, "VLR", pl, err);
            if (st != GDT_OK)
                return st;
        } else if (h->compressed && pl->laszip == NULL && gdt_le_get_u16(vh + 18) == 22204 &&
                   strncmp((const char *)vh + 2, "laszip encoded", 16) == 0) {
            pl->laszip = malloc(len > 0 ? (size_t)len : 1);
            if (pl->laszip == NULL)
                return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
            pl->laszip_len = (size_t)len;
            st = las_pread(fd, path, pl->laszip, (size_t)len, body, "LASzip VLR", err);
            if (st != GDT_OK)
                return st;
        }
        pos = body + len;
    }
    *vlr_count = i;
    return GDT_OK;
}

/* Walks the EVLRs (LAS 1.4).  Their place was checked by las_locate_points;
 * an EVLR that runs past the end of the file means truncation: error. */
static gdt_status las_scan_evlrs(int fd, const char *path, const las_header *h, uint64_t file_size,
                                 gdt_log *log, las_crs_payloads *pl, unsigned *evlr_count,
                                 gdt_error *err)
{
    uint64_t pos = h->evlr_start;
    unsigned char eh[LAS_EVLR_HEADER];
    gdt_status st;

    *evlr_count = 0;
    for (uint32_t i = 0; i < h->evlr_claimed; i++) {
        if (file_size - pos < LAS_EVLR_HEADER)
            return gdt_error_set(err, GDT_EINPUT, 3121,
                                 "%s: EVLR %" PRIu32 " of %" PRIu32 " at byte %" PRIu64
                                 " runs past the end of the file (%" PRIu64 " bytes; truncated?)",
                                 path, i + 1, h->evlr_claimed, pos, file_size);
        st = las_pread(fd, path, eh, sizeof eh, pos, "EVLR header", err);
        if (st != GDT_OK)
            return st;
        uint64_t len = gdt_le_get_u64(eh + 20);
        uint64_t body = pos + LAS_EVLR_HEADER;
        if (len > file_size - body)
            return gdt_error_set(err, GDT_EINPUT, 3121,
                                 "%s: EVLR %" PRIu32 " of %" PRIu32 " at byte %" PRIu64
                                 " claims %" PRIu64 " bytes, past the end"
                                 " of the file (%" PRIu64 " bytes; truncated?)",
                                 path, i + 1, h->evlr_claimed, pos, len, file_size);
        if (las_is_projection(eh + 2)) {
            unsigned rid = gdt_le_get_u16(eh + 18);
            uint64_t limit = rid == 2112 ? LAS_WKT_MAX : 65535u;
            if (len > limit)
                gdt_log_warn(log, 3152,
                             "%s: ignoring CRS EVLR %u of %" PRIu64 " bytes (more"
                             " than %" PRIu64 ")",
                             path, rid, len, limit);
            else if ((st = las_keep_payload(fd, path, rid, body, (size_t)len, "EVLR", pl, err)) !=
                     GDT_OK)
                return st;
        }
        pos = body + len;
        *evlr_count = i + 1;
    }
    return GDT_OK;
}

static void las_payloads_free(las_crs_payloads *pl)
{
    free(pl->geokeys);
    free(pl->ascii);
    free(pl->wkt);
    free(pl->laszip);
    memset(pl, 0, sizeof *pl);
}

/* Fills buf from the point records.  Precondition: buf_pos == buf_len. */
static gdt_status las_refill(gdt_source *src, las_impl *im, gdt_error *err)
{
    size_t want = im->buf_cap;
    if (im->points_end - im->file_pos < want)
        want = (size_t)(im->points_end - im->file_pos);
    for (;;) {
        ssize_t got = want == 0 ? 0 : pread(im->fd, im->buf, want, (off_t)im->file_pos);
        if (got < 0 && errno == EINTR)
            continue;
        if (got < 0)
            return gdt_error_set(err, GDT_EIO, 4103,
                                 "%s: read error at byte %" PRIu64 " (point record %" PRIu64
                                 "): %s",
                                 src->path, im->file_pos, im->next_point + 1, strerror(errno));
        if (got == 0)
            return gdt_error_set(err, GDT_EINPUT, 3131,
                                 "%s: file ends at byte %" PRIu64 ", inside point record %" PRIu64
                                 " of %" PRIu64 " (it shrank while being read)",
                                 src->path, im->file_pos, im->next_point + 1, im->point_count);
        im->buf_pos = 0;
        im->buf_len = (size_t)got;
        im->file_pos += (uint64_t)got;
        return GDT_OK;
    }
}

/* Copies the next n bytes of the point stream to dst (or drops them when dst
 * is NULL), refilling the buffer as often as needed. */
static gdt_status las_take(gdt_source *src, las_impl *im, unsigned char *dst, size_t n,
                           gdt_error *err)
{
    while (n > 0) {
        if (im->buf_pos == im->buf_len) {
            gdt_status st = las_refill(src, im, err);
            if (st != GDT_OK)
                return st;
        }
        size_t k = im->buf_len - im->buf_pos;
        if (k > n)
            k = n;
        if (dst != NULL) {
            memcpy(dst, im->buf + im->buf_pos, k);
            dst += k;
        }
        im->buf_pos += k;
        n -= k;
    }
    return GDT_OK;
}

/* Converts the first LAS_HEAD_BYTES bytes of a record of point format
 * format to a point. */
static void las_record_to_point(const las_impl *im, const unsigned char *rec, gdt_src_point *p)
{
    p->X = gdt_le_get_i32(rec);
    p->Y = gdt_le_get_i32(rec + 4);
    p->Z = gdt_le_get_i32(rec + 8);
    p->x = (double)p->X * im->scale[0] + im->offset[0];
    p->y = (double)p->Y * im->scale[1] + im->offset[1];
    p->z = (double)p->Z * im->scale[2] + im->offset[2];
    if (im->point_format >= 6) {
        p->ret = rec[14] & 0x0Fu;
        p->nret = rec[14] >> 4;
        p->flags = rec[15] & 0x0Fu; /* synthetic, key point, withheld, overlap */
        p->cls = rec[16];
    } else {
        p->ret = rec[14] & 0x07u;
        p->nret = (rec[14] >> 3) & 0x07u;
        p->flags = rec[15] >> 5; /* synthetic, key point, withheld */
        p->cls = rec[15] & 0x1Fu;
    }
}

/* Both reads: raw, when not NULL, receives each record whole. */
static gdt_status las_read_records(gdt_source *src, gdt_src_point *out, unsigned char *raw,
                                   size_t cap, size_t *n, gdt_error *err)
{
    las_impl *im = src->impl;
    unsigned char head[LAS_HEAD_BYTES];
    gdt_status st = GDT_OK;

    *n = 0;
    if (im->failed != GDT_OK)
        return gdt_error_set(err, im->failed, gdt_error_code_in_class(im->failed, 132),
                             "%s: reading stopped after an earlier"
                             " error",
                             src->path);
    while (*n < cap && im->next_point < im->point_count) {
        const unsigned char *rec;
        if (im->laz != NULL) {
            if (im->lrec_left == 0) {
                st = gdt_laz_stream_next(im->laz, &im->lrec, &im->lrec_left, err);
                if (st != GDT_OK)
                    goto fail;
                if (im->lrec_left == 0) /* the stream gives point_count records */
                    break;
            }
            rec = im->lrec;
            im->lrec += im->record_length;
            im->lrec_left--;
        } else if (im->buf_len - im->buf_pos >= im->record_length) {
            rec = im->buf + im->buf_pos;
            im->buf_pos += im->record_length;
        } else if (raw != NULL) {
            /* a record across the buffer's end, wanted whole */
            st = las_take(src, im, raw + *n * im->record_length, im->record_length, err);
            if (st != GDT_OK)
                goto fail;
            rec = raw + *n * im->record_length;
        } else {
            st = las_take(src, im, head, LAS_HEAD_BYTES, err);
            if (st == GDT_OK)
                st = las_take(src, im, NULL, im->record_length - LAS_HEAD_BYTES, err);
            if (st != GDT_OK)
                goto fail;
            rec = head;
        }
        las_record_to_point(im, rec, &out[*n]);
        if (raw != NULL && rec != raw + *n * im->record_length)
            memcpy(raw + *n * im->record_length, rec, im->record_length);
        (*n)++;
        im->next_point++;
    }
    return GDT_OK;
fail:
    im->failed = st;
    *n = 0;
    return st;
}

static gdt_status las_read(gdt_source *src, gdt_src_point *out, size_t cap, size_t *n,
                           gdt_error *err)
{
    return las_read_records(src, out, NULL, cap, n, err);
}

/* Closes and frees im and everything it owns; NULL is allowed. */
static void las_impl_free(las_impl *im)
{
    if (im == NULL)
        return;
    gdt_laz_stream_close(im->laz);
    if (im->fd >= 0)
        close(im->fd);
    free(im->buf);
    free(im->wkt);
    free(im);
}

static void las_close(gdt_source *src)
{
    las_impl_free(src->impl);
    src->impl = NULL;
}

/* Before the first read: uncompressed records from any record; LAZ from
 * the first record of a chunk, decoding only the chunks up to end. */
static gdt_status las_seek(gdt_source *src, uint64_t rec, uint64_t end, gdt_error *err)
{
    las_impl *im = src->impl;
    if (im->next_point != 0 || im->buf_len != 0 || im->lrec_left != 0)
        return gdt_error_set(err, GDT_EINTERNAL, 7102,
                             "%s: seeking to point record %" PRIu64 " after reading", src->path,
                             rec);
    if (im->laz != NULL) {
        gdt_status st = gdt_laz_stream_seek(im->laz, rec, end, err);
        if (st != GDT_OK)
            return st;
        im->next_point = rec;
        return GDT_OK;
    }
    im->next_point = rec;
    im->file_pos = im->points_start + rec * im->record_length;
    return GDT_OK;
}

static uint64_t las_starts(const gdt_source *src, uint64_t *out, uint64_t cap)
{
    const las_impl *im = src->impl;
    return im->laz != NULL ? gdt_laz_stream_starts(im->laz, out, cap) : 0;
}

static const gdt_source_vtable las_vtable = {las_read, las_close, las_seek, las_starts,
                                             las_read_records};

/* LAZ: the records come from a LAZ stream over [offset to points,
 * points_end).  The LASzip VLR is required: without it the point data
 * cannot be decoded. */
static gdt_status las_open_laz(gdt_source *src, las_impl *im, const las_header *h,
                               const las_crs_payloads *pl, uint64_t points_end, gdt_error *err)
{
    const gdt_source_opts *o = &src->opts;
    gdt_laz_stream_params lp;

    if (pl->laszip == NULL)
        return gdt_error_set(err, GDT_EINPUT, 3974,
                             "%s: the point format byte says LAZ (compressed) but the file has"
                             " no LASzip VLR (user \"laszip encoded\", record 22204)"
                             " describing the compression",
                             src->path);
    memset(&lp, 0, sizeof lp);
    lp.fd = im->fd;
    lp.path = src->path;
    lp.points_start = h->offset_to_points;
    lp.region_end = points_end;
    lp.point_count = h->point_count;
    lp.point_format = h->format;
    lp.record_length = h->record_length;
    /* need 0 is every field; XYZ is always decoded. */
    lp.need = o->need == 0 ? GDT_LAZ_NEED_ALL
                           : GDT_LAZ_NEED_XYZ |
                                 ((o->need & GDT_SRC_NEED_CLASS) ? GDT_LAZ_NEED_CLASS : 0u) |
                                 ((o->need & GDT_SRC_NEED_FLAGS) ? GDT_LAZ_NEED_FLAGS : 0u);
    lp.threads = o->threads;
    lp.piece_bytes = o->buffer_bytes;
    memcpy(lp.scale, h->scale, sizeof lp.scale);
    memcpy(lp.offset, h->offset, sizeof lp.offset);
    memcpy(lp.min, h->min, sizeof lp.min);
    memcpy(lp.max, h->max, sizeof lp.max);
    lp.log = o->log;
    return gdt_laz_stream_open(&im->laz, pl->laszip, pl->laszip_len, &lp, err);
}

/* The LAZ fields of info, from the stream just opened. */
static void las_info_laz(gdt_source_info *in, const gdt_laz_stream *laz)
{
    gdt_laz_stream_desc d;
    gdt_laz_stream_describe(laz, &d);
    snprintf(in->format_name, sizeof in->format_name, "LAZ");
    in->compressed = 1;
    snprintf(in->compressor, sizeof in->compressor, "%s", d.compressor);
    snprintf(in->laz_items, sizeof in->laz_items, "%s", d.items);
    in->laz_chunk_size = d.chunk_size;
    in->laz_chunks = d.chunks;
}

gdt_status gdt_las_open(gdt_source *src, gdt_error *err)
{
    const char *path = src->path;
    las_impl *im = NULL;
    las_crs_payloads pl;
    las_header h;
    unsigned char hb[LAS_HEADER_MAX];
    struct stat sb;
    uint64_t file_size, points_end = 0;
    unsigned vlr_count = 0, evlr_count = 0;
    gdt_status st;

    memset(&pl, 0, sizeof pl);
    im = calloc(1, sizeof *im);
    if (im == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    im->fd = open(path, O_RDONLY | O_CLOEXEC);
    if (im->fd < 0) {
        /* A missing or unreadable file is the user's input; anything else is I/O. */
        int e = errno;
        int user = e == ENOENT || e == EACCES || e == EISDIR;
        st = gdt_error_set(err, user ? GDT_EINPUT : GDT_EIO, user ? 3101 : 4101,
                           "%s: cannot open: %s", path, strerror(e));
        goto fail;
    }
    if (fstat(im->fd, &sb) != 0) {
        st = gdt_error_set(err, GDT_EIO, 4102, "%s: cannot stat: %s", path, strerror(errno));
        goto fail;
    }
    if (!S_ISREG(sb.st_mode)) {
        st = gdt_error_set(err, GDT_EINPUT, 3103, "%s: not a regular file", path);
        goto fail;
    }
    file_size = (uint64_t)sb.st_size;

    size_t hn = file_size < LAS_HEADER_MAX ? (size_t)file_size : LAS_HEADER_MAX;
    st = las_pread(im->fd, path, hb, hn, 0, "header", err);
    if (st != GDT_OK)
        goto fail;
    st = las_parse_header(path, hb, hn, file_size, &h, err);
    if (st != GDT_OK)
        goto fail;
    st = las_locate_points(path, &h, file_size, src->opts.log, &points_end, err);
    if (st != GDT_OK)
        goto fail;
    st = las_scan_vlrs(im->fd, path, &h, src->opts.log, &pl, &vlr_count, err);
    if (st != GDT_OK)
        goto fail;
    st = las_scan_evlrs(im->fd, path, &h, file_size, src->opts.log, &pl, &evlr_count, err);
    if (st != GDT_OK)
        goto fail;

    {
        gdt_las_geokeys keys;
        int wkt_authoritative = h.minor >= 4 && (h.global_encoding & LAS_GE_WKT);
        gdt_las_geokeys_parse(pl.geokeys, pl.geokeys_len, pl.ascii, pl.ascii_len, &keys);
        if (keys.malformed)
            gdt_log_warn(src->opts.log, 3153,
                         "%s: the GeoTIFF key directory is malformed;"
                         " using the keys it holds",
                         path);
        gdt_las_crs_resolve(pl.geokeys != NULL ? &keys : NULL, pl.wkt, pl.wkt_len,
                            wkt_authoritative, &im->crs);
        if (pl.wkt != NULL) {
            /* The payload is NUL-terminated by las_keep_payload; it may be
             * NUL-padded, so the string ends at its first NUL. */
            im->wkt = pl.wkt;
            pl.wkt = NULL;
            if (im->wkt[0] == '\0') {
                free(im->wkt);
                im->wkt = NULL;
            }
        }
    }

    if (h.compressed) {
        st = las_open_laz(src, im, &h, &pl, points_end, err);
        if (st != GDT_OK)
            goto fail;
    } else {
        uint64_t point_bytes = points_end - h.offset_to_points;
        size_t cap = src->opts.buffer_bytes != 0 ? src->opts.buffer_bytes : (size_t)1 << 20;
        if (point_bytes < cap)
            cap = point_bytes > 0 ? (size_t)point_bytes : 1;
        im->buf = malloc(cap);
        if (im->buf == NULL) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
            goto fail;
        }
        im->buf_cap = cap;
    }
    im->file_pos = h.offset_to_points;
    im->points_start = h.offset_to_points;
    im->points_end = points_end;
    im->point_count = h.point_count;
    im->record_length = h.record_length;
    im->point_format = h.format;
    memcpy(im->scale, h.scale, sizeof im->scale);
    memcpy(im->offset, h.offset, sizeof im->offset);
    las_payloads_free(&pl);

    gdt_source_info *in = &src->info;
    memset(in, 0, sizeof *in);
    in->format = GDT_FORMAT_LAS;
    snprintf(in->format_name, sizeof in->format_name, "LAS");
    snprintf(in->version, sizeof in->version, "%u.%u", h.major, h.minor);
    snprintf(in->encoding, sizeof in->encoding, "point format %u", h.format);
    in->point_count = h.point_count;
    in->has_bounds = 1;
    in->has_lattice = 1;
    for (int k = 0; k < 3; k++) {
        in->min[k] = h.min[k];
        in->max[k] = h.max[k];
        in->scale[k] = h.scale[k];
        in->offset[k] = h.offset[k];
    }
    in->epsg = im->crs.epsg;
    in->crs_wkt = im->wkt;
    in->crs_geographic = im->crs.geographic;
    in->crs_desc = im->crs.desc;
    in->point_format = h.format;
    in->record_length = h.record_length;
    in->extra_bytes = h.record_length - las_base_length[h.format];
    in->vlr_count = vlr_count;
    in->evlr_count = evlr_count;
    in->file_size = file_size;
    if (im->laz != NULL)
        las_info_laz(in, im->laz);
    src->impl = im;
    src->vt = &las_vtable;
    return GDT_OK;

fail:
    las_payloads_free(&pl);
    las_impl_free(im);
    src->vt = NULL;
    src->impl = NULL;
    return st;
}
