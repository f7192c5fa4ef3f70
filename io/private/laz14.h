/* laz14.h — the decoder of layered LASzip chunks (compressor 3), the
 * compression of LAS point formats 6-10: the items POINT14, RGB14,
 * RGBNIR14, WAVEPACKET14 and BYTE14, item versions 3 and 4.
 *
 * A layered chunk holds the first point raw (record_length bytes, every
 * item), a u32 point count, the byte size of every layer of every item (u32
 * each, in item order: POINT14 has nine, RGB14 one, RGBNIR14 two,
 * WAVEPACKET14 one, BYTE14 one per byte) and then the layers, in the same
 * order.  Every layer is an arithmetic-coded stream of its own, so a layer
 * the run does not need is skipped by its size, unread.  The models of
 * every item are kept per scanner channel (four contexts), and the POINT14
 * layer of changed values says when the channel changes.
 *
 * Version 3 and version 4 differ in how the other items follow the channel:
 * in version 3 they are told the new channel only on a point where it
 * changes and channel 0 on every other point, and when they switch to a
 * channel already in use they still predict that point from the previous
 * channel's last values and store it there; version 4 follows the channel
 * of every point.  Files written with version 3 depend on that behaviour,
 * so it is reproduced exactly.
 *
 * The functions mirror gdt_laz_chunk_* (laz_chunk.h), which calls them for
 * compressor 3; their contracts are those documented there.
 * Message numbers: 3940-3969 (bad input), 7395 (a caller bug).
 */
#ifndef GDT_LAZ14_H
#define GDT_LAZ14_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_error.h"
#include "laz_chunk.h"

typedef struct gdt_laz14 gdt_laz14;

/* A decoder of the layered chunks of vlr's stream, decoding the layers need
 * (GDT_LAZ_NEED_*) asks for.  It owns its models, which it allocates as the
 * chunks first use them and keeps for the next chunks; vlr must outlive it.
 * returns: GDT_EINPUT 3940 (items a layered stream cannot hold), GDT_EINTERNAL
 * 7001 (out of memory), or GDT_OK with *out to free with gdt_laz14_free. */
gdt_status gdt_laz14_new(gdt_laz14 **out, const gdt_laz_vlr *vlr, unsigned record_length,
                         unsigned need, gdt_error *err);
void gdt_laz14_free(gdt_laz14 *z);

/* Reads the raw first point, the count and the layer sizes of the chunk at
 * data[0 .. avail) and starts the layers the decoder needs.
 * returns: GDT_EINPUT 3941-3943 (the chunk cannot hold what it claims),
 * GDT_EINTERNAL 7001, or GDT_OK. */
gdt_status gdt_laz14_start(gdt_laz14 *z, const unsigned char *data, size_t avail, uint64_t npoints,
                           const char *path, uint64_t chunk_index, gdt_error *err);

/* Decodes the next n points into records (n * record_length bytes; the
 * bytes of fields not needed are zero).  returns: GDT_EINPUT 3944-3945 (a
 * layer runs past its bytes or holds a code no encoder writes, naming the
 * point), GDT_EINTERNAL 7001 or 7395 (more points than the chunk's), or
 * GDT_OK. */
gdt_status gdt_laz14_read(gdt_laz14 *z, unsigned char *records, size_t n, gdt_error *err);

/* Bytes of the current chunk: the raw point, the count, the layer sizes and
 * every layer, decoded or skipped. */
size_t gdt_laz14_used(const gdt_laz14 *z);

#endif
