/* Fuzz target of the layered LASzip chunk decoder (io/private/laz14.c,
 * reached through laz_chunk.h as compressor 3): the layer sizes, the nine
 * POINT14 layers, RGB14 / RGBNIR14, WAVEPACKET14 and BYTE14, selective or
 * not.
 *
 * Input framing:
 *   byte 0     point format 6 + (byte modulo 5)
 *   byte 1     bit 0: POINT14 version 4 (else 3); bit 1: the other items
 *              version 4; bits 2-4: extra bytes (0-7); bits 5-7: the need
 *              mask (0 all, 1 xyz, 2 class, 3 flags, 4 xyz+class+flags,
 *              5 xyz+flags, 6-7 all)
 *   bytes 2-3  little-endian: the chunk's points - 1, modulo 4096
 *   the rest   the chunk: the raw first record, the count, the layer sizes
 *              and the layers
 *
 * Besides the sanitizers' findings, it aborts when a failure is reported
 * without its class and message, when a chunk decoded without error claims
 * more bytes than it was given, or when a selective decoding leaves a byte
 * of a field it does not need non-zero.
 */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "fuzz_input.h"
#include "gdt_error.h"
#include "private/laz_chunk.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

#define BATCH 64

static void add_item(gdt_laz_vlr *v, unsigned type, unsigned size, unsigned version)
{
    gdt_laz_item *it = &v->items[v->nitems++];
    it->type = (uint16_t)type;
    it->size = (uint16_t)size;
    it->version = (uint16_t)version;
}

/* Aborts when a selective record has a non-zero byte outside the fields of
 * need (X/Y/Z 0-11, returns and flags 14-15, classification 16). */
static void check_zeros(const unsigned char *r, unsigned rl, unsigned need)
{
    for (unsigned b = 0; b < rl; b++) {
        int kept = (b < 12 && (need & GDT_LAZ_NEED_XYZ)) ||
                   ((b == 14 || b == 15) && (need & GDT_LAZ_NEED_FLAGS)) ||
                   (b == 16 && (need & GDT_LAZ_NEED_CLASS));
        if (!kept && r[b] != 0)
            abort();
    }
}

/* One decoder per item layout and need mask, reused across inputs (as a
 * reader reuses one across chunks: stale models from earlier inputs must
 * not leak into a chunk); with the VLR each was made for, which must
 * outlive it.  Kept until the process ends. */
static gdt_laz_vlr vlrs[5][4][8][8];
static gdt_laz_chunk *decoders[5][4][8][8];

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static const unsigned needs[8] = {GDT_LAZ_NEED_ALL,
                                      GDT_LAZ_NEED_XYZ,
                                      GDT_LAZ_NEED_CLASS,
                                      GDT_LAZ_NEED_FLAGS,
                                      GDT_LAZ_NEED_XYZ | GDT_LAZ_NEED_CLASS | GDT_LAZ_NEED_FLAGS,
                                      GDT_LAZ_NEED_XYZ | GDT_LAZ_NEED_FLAGS,
                                      GDT_LAZ_NEED_ALL,
                                      GDT_LAZ_NEED_ALL};
    unsigned char records[BATCH * (67 + 7)];
    gdt_laz_vlr *vlr;
    gdt_laz_chunk **c;
    gdt_error err;
    gdt_status st;
    unsigned fmt, v_point, v_rest, extra, need, rl;
    uint64_t npoints, done = 0;

    if (size < 4)
        return 0;
    fmt = 6 + data[0] % 5;
    v_point = data[1] & 1 ? 4 : 3;
    v_rest = data[1] & 2 ? 4 : 3;
    extra = (data[1] >> 2) & 7;
    need = needs[data[1] >> 5];
    npoints = 1 + ((unsigned)data[2] | ((unsigned)data[3] << 8)) % 4096;
    vlr = &vlrs[fmt - 6][data[1] & 3][extra][data[1] >> 5];
    c = &decoders[fmt - 6][data[1] & 3][extra][data[1] >> 5];

    memset(&err, 0, sizeof err);
    if (!*c) {
        memset(vlr, 0, sizeof *vlr);
        vlr->compressor = GDT_LAZ_COMPRESSOR_LAYERED_CHUNKED;
        vlr->chunk_size = 50000;
        add_item(vlr, GDT_LAZ_POINT14, 30, v_point);
        if (fmt == 7)
            add_item(vlr, GDT_LAZ_RGB14, 6, v_rest);
        if (fmt == 8 || fmt == 10)
            add_item(vlr, GDT_LAZ_RGBNIR14, 8, v_rest);
        if (fmt == 9 || fmt == 10)
            add_item(vlr, GDT_LAZ_WAVEPACKET14, 29, v_rest);
        if (extra)
            add_item(vlr, GDT_LAZ_BYTE14, extra, v_rest);
    }
    rl = 0;
    for (unsigned i = 0; i < vlr->nitems; i++)
        rl += vlr->items[i].size;
    if (!*c && (st = gdt_laz_chunk_new(c, vlr, rl, need, &err)) != GDT_OK) {
        gdt_fuzz_check_error(st, &err);
        return 0;
    }
    st = gdt_laz_chunk_start(*c, data + 4, size - 4, npoints, "fuzz", 0, &err);
    while (st == GDT_OK && done < npoints) {
        size_t n = npoints - done < BATCH ? (size_t)(npoints - done) : BATCH;
        st = gdt_laz_chunk_read(*c, records, n, &err);
        if (st == GDT_OK && need != GDT_LAZ_NEED_ALL)
            for (size_t i = 0; i < n; i++)
                check_zeros(records + i * rl, rl, need);
        done += n;
    }
    if (st != GDT_OK)
        gdt_fuzz_check_error(st, &err);
    else if (gdt_laz_chunk_used(*c) > size - 4)
        abort();
    return 0;
}
