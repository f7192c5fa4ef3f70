/* laz_vlr.c — parsing and validation of the LASzip VLR (record 22204).
 *
 * Payload layout (little-endian): u16 compressor, u16 coder, u8 version
 * major, u8 minor, u16 revision, u32 options, u32 chunk size, i64 special
 * EVLR count, i64 special EVLR offset, u16 item count, then per item u16
 * type, u16 size, u16 version.
 */
#include <inttypes.h>
#include <string.h>

#include "bytes.h"
#include "laz_chunk.h"

#define LAZ_VLR_FIXED 34u /* bytes before the items */

static int64_t get_i64(const unsigned char *p)
{
    uint64_t u = gdt_le_get_u64(p);
    return u <= (uint64_t)INT64_MAX ? (int64_t)u : (int64_t)(u - (uint64_t)INT64_MAX - 1) + INT64_MIN;
}

const char *gdt_laz_item_name(unsigned type)
{
    switch (type) {
    case GDT_LAZ_BYTE: return "BYTE";
    case GDT_LAZ_POINT10: return "POINT10";
    case GDT_LAZ_GPSTIME11: return "GPSTIME11";
    case GDT_LAZ_RGB12: return "RGB12";
    case GDT_LAZ_WAVEPACKET13: return "WAVEPACKET13";
    case GDT_LAZ_POINT14: return "POINT14";
    case GDT_LAZ_RGB14: return "RGB14";
    case GDT_LAZ_RGBNIR14: return "RGBNIR14";
    case GDT_LAZ_WAVEPACKET14: return "WAVEPACKET14";
    case GDT_LAZ_BYTE14: return "BYTE14";
    default: return NULL;
    }
}

/* The size every item but the extra bytes has. */
static unsigned item_size(unsigned type)
{
    switch (type) {
    case GDT_LAZ_POINT10: return 20;
    case GDT_LAZ_GPSTIME11: return 8;
    case GDT_LAZ_RGB12: return 6;
    case GDT_LAZ_WAVEPACKET13: return 29;
    case GDT_LAZ_POINT14: return 30;
    case GDT_LAZ_RGB14: return 6;
    case GDT_LAZ_RGBNIR14: return 8;
    case GDT_LAZ_WAVEPACKET14: return 29;
    default: return 0;
    }
}

/* The items of the standard fields of point_format, in record order. */
static unsigned format_items(unsigned point_format, uint16_t *types)
{
    static const uint16_t seq[11][4] = {
        {GDT_LAZ_POINT10},
        {GDT_LAZ_POINT10, GDT_LAZ_GPSTIME11},
        {GDT_LAZ_POINT10, GDT_LAZ_RGB12},
        {GDT_LAZ_POINT10, GDT_LAZ_GPSTIME11, GDT_LAZ_RGB12},
        {GDT_LAZ_POINT10, GDT_LAZ_GPSTIME11, GDT_LAZ_WAVEPACKET13},
        {GDT_LAZ_POINT10, GDT_LAZ_GPSTIME11, GDT_LAZ_RGB12, GDT_LAZ_WAVEPACKET13},
        {GDT_LAZ_POINT14},
        {GDT_LAZ_POINT14, GDT_LAZ_RGB14},
        {GDT_LAZ_POINT14, GDT_LAZ_RGBNIR14},
        {GDT_LAZ_POINT14, GDT_LAZ_WAVEPACKET14},
        {GDT_LAZ_POINT14, GDT_LAZ_RGBNIR14, GDT_LAZ_WAVEPACKET14},
    };
    static const unsigned len[11] = {1, 2, 2, 3, 3, 4, 1, 2, 2, 2, 3};
    memcpy(types, seq[point_format], len[point_format] * sizeof *types);
    return len[point_format];
}

gdt_status gdt_laz_vlr_parse(const char *path, const unsigned char *payload, size_t n,
                             unsigned point_format, unsigned record_length, gdt_laz_vlr *out,
                             gdt_error *err)
{
    uint16_t want[4];
    unsigned nwant, sum = 0, layered;

    memset(out, 0, sizeof *out);
    if (n < LAZ_VLR_FIXED)
        return gdt_error_set(err, GDT_EINPUT, 3900,
                             "%s: LASzip VLR of %zu bytes (at least %u expected)", path, n,
                             LAZ_VLR_FIXED);
    out->compressor = gdt_le_get_u16(payload);
    out->coder = gdt_le_get_u16(payload + 2);
    out->version_major = payload[4];
    out->version_minor = payload[5];
    out->version_revision = gdt_le_get_u16(payload + 6);
    out->options = gdt_le_get_u32(payload + 8);
    out->chunk_size = gdt_le_get_u32(payload + 12);
    out->special_evlr_count = get_i64(payload + 16);
    out->special_evlr_offset = get_i64(payload + 24);
    out->nitems = gdt_le_get_u16(payload + 32);

    if (out->compressor == GDT_LAZ_COMPRESSOR_POINTWISE)
        return gdt_error_set(err, GDT_EINPUT, 3901,
                             "%s: LAZ file of the non-chunked LASzip 1.x layout (compressor 1), "
                             "which is not supported; re-compress it with a current LASzip "
                             "(laszip -i in.laz -o out.laz) or laz-rs",
                             path);
    if (out->compressor != GDT_LAZ_COMPRESSOR_POINTWISE_CHUNKED &&
        out->compressor != GDT_LAZ_COMPRESSOR_LAYERED_CHUNKED)
        return gdt_error_set(err, GDT_EINPUT, 3902,
                             "%s: LASzip VLR names compressor %u (2, pointwise chunked, or 3, "
                             "layered chunked, expected)",
                             path, (unsigned)out->compressor);
    if (out->coder != 0)
        return gdt_error_set(err, GDT_EINPUT, 3903,
                             "%s: LASzip VLR names coder %u (0, arithmetic, expected)", path,
                             (unsigned)out->coder);
    if (out->chunk_size == 0)
        return gdt_error_set(err, GDT_EINPUT, 3904, "%s: LASzip VLR has a chunk size of 0",
                             path);
    if (out->nitems == 0 || out->nitems > GDT_LAZ_MAX_ITEMS ||
        n < LAZ_VLR_FIXED + 6 * (size_t)out->nitems)
        return gdt_error_set(err, GDT_EINPUT, 3900,
                             "%s: LASzip VLR of %zu bytes lists %u items (1 .. %u items of 6 "
                             "bytes expected)",
                             path, n, out->nitems, GDT_LAZ_MAX_ITEMS);
    if (point_format > 10)
        return gdt_error_set(err, GDT_EINPUT, 3905, "%s: LAZ point format %u (0 .. 10 expected)",
                             path, point_format);
    layered = point_format >= 6;
    if (layered != (out->compressor == GDT_LAZ_COMPRESSOR_LAYERED_CHUNKED))
        return gdt_error_set(err, GDT_EINPUT, 3905,
                             "%s: LASzip compressor %u does not code point format %u "
                             "(formats 0-5 use 2, formats 6-10 use 3)",
                             path, (unsigned)out->compressor, point_format);

    nwant = format_items(point_format, want);
    for (unsigned i = 0; i < out->nitems; i++) {
        gdt_laz_item *it = &out->items[i];
        const unsigned char *p = payload + LAZ_VLR_FIXED + 6 * (size_t)i;
        const char *name;
        int version_ok;
        unsigned expect;

        it->type = gdt_le_get_u16(p);
        it->size = gdt_le_get_u16(p + 2);
        it->version = gdt_le_get_u16(p + 4);
        name = gdt_laz_item_name(it->type);
        if (!name)
            return gdt_error_set(err, GDT_EINPUT, 3906, "%s: LASzip item %u has unknown type %u",
                                 path, i, (unsigned)it->type);
        /* The record's standard fields first, in their order, then at
         * most one item of extra bytes. */
        expect = i < nwant ? want[i] : layered ? GDT_LAZ_BYTE14 : GDT_LAZ_BYTE;
        if (it->type != expect || i > nwant)
            return gdt_error_set(err, GDT_EINPUT, 3907,
                                 "%s: LASzip item %u is %s where point format %u has %s", path, i,
                                 name, point_format,
                                 i > nwant ? "no further item" : gdt_laz_item_name(expect));
        if (it->type == GDT_LAZ_BYTE || it->type == GDT_LAZ_BYTE14) {
            if (it->size == 0)
                return gdt_error_set(err, GDT_EINPUT, 3907,
                                     "%s: LASzip item %u (%s) of 0 bytes", path, i, name);
        } else if (it->size != item_size(it->type)) {
            return gdt_error_set(err, GDT_EINPUT, 3907,
                                 "%s: LASzip item %u (%s) of %u bytes (%u expected)", path, i,
                                 name, (unsigned)it->size, item_size(it->type));
        }
        /* Pointwise items: version 1 (LASzip 1.0) and 2 (every later
         * writer); WAVEPACKET13 has one coding under both numbers.
         * Layered items: 3 and 4 (same coding, 4 a later writer). */
        version_ok = layered ? it->version == 3 || it->version == 4
                             : it->version == 1 || it->version == 2;
        if (!version_ok)
            return gdt_error_set(err, GDT_EINPUT, 3908,
                                 "%s: LASzip item %u (%s) has version %u (%s expected)", path, i,
                                 name, (unsigned)it->version, layered ? "3 or 4" : "1 or 2");
        sum += it->size;
    }
    if (out->nitems < nwant)
        return gdt_error_set(err, GDT_EINPUT, 3907,
                             "%s: LASzip VLR lists %u items where point format %u needs %u", path,
                             out->nitems, point_format, nwant);
    if (sum != record_length)
        return gdt_error_set(err, GDT_EINPUT, 3909,
                             "%s: LASzip items cover %u bytes but the point records have %u",
                             path, sum, record_length);
    return GDT_OK;
}
