/* laz10.h — the decoder of pointwise LASzip chunks (compressor 2, point
 * formats 0-5): items POINT10, GPSTIME11, RGB12, WAVEPACKET13 and BYTE, in
 * their version 1 (LASzip 1.0) and version 2 (every later writer) codings.
 *
 * A chunk is the raw first record, then one arithmetic-coded stream in
 * which every following record is coded item after item, each item
 * predicted from the same item of the previous record.  The decoder keeps
 * one state per item of the VLR (a precomputed plan, walked with a switch
 * per item and point) and writes whole LAS records.
 *
 * Ownership: gdt_laz10_new allocates the decoder and every context model it
 * needs up front, except the models LASzip keys by a byte value (POINT10's
 * flags, classification and user data: 256 possible models each), which
 * are allocated on first use and kept for later chunks; gdt_laz10_free
 * releases all.  Not thread-safe; separate decoders are independent.
 */
#ifndef GDT_LAZ10_H
#define GDT_LAZ10_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_error.h"
#include "laz_chunk.h"

typedef struct gdt_laz10 gdt_laz10;

/* A decoder for the pointwise items of vlr (compressor 2, checked by
 * gdt_laz_vlr_parse); vlr must outlive it.  returns: GDT_EINTERNAL 7001 or
 * GDT_OK. */
gdt_status gdt_laz10_new(gdt_laz10 **out, const gdt_laz_vlr *vlr, unsigned record_length,
                         gdt_error *err);
void gdt_laz10_free(gdt_laz10 *z);

/* Starts a chunk of npoints (>= 1) points in data[0 .. avail): takes the
 * raw first record and starts the arithmetic decoder after it.  path and
 * chunk_index name the chunk in messages.  returns: GDT_EINPUT 3922 (fewer
 * bytes than one record) or GDT_OK. */
gdt_status gdt_laz10_start(gdt_laz10 *z, const unsigned char *data, size_t avail,
                           uint64_t npoints, const char *path, uint64_t chunk_index,
                           gdt_error *err);

/* Decodes the next n records of the chunk (the caller keeps the total
 * within npoints).  returns: GDT_EINPUT 3920 (the stream needs bytes past
 * avail) or 3921 (a code no encoder writes), naming the chunk and the
 * point; GDT_EINTERNAL 7001; or GDT_OK. */
gdt_status gdt_laz10_read(gdt_laz10 *z, unsigned char *records, size_t n, gdt_error *err);

/* Bytes of the chunk used so far: the raw record and what the arithmetic
 * decoder has taken. */
size_t gdt_laz10_used(const gdt_laz10 *z);

#endif
