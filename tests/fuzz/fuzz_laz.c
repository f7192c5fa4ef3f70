/* Fuzz target of the LASzip decoder (io/private/laz_chunk.h): the VLR
 * parser and the pointwise chunk decoder, the parts that read compressed
 * bytes.  (The chunk table is read through the LAS source target.)
 *
 * Input framing:
 *   byte 0     point format (taken modulo 6, or 11 for a VLR input)
 *   byte 1     bit 7: the rest is a VLR payload, parsed for the format
 *              with the record length of bytes 2-3; otherwise bit 0: item
 *              version 1 (else 2), bits 1-3: extra bytes (0-7)
 *   bytes 2-3  little-endian: the chunk's points - 1, modulo 4096
 *   the rest   the chunk: the raw first record, then the coded stream
 *
 * Besides the sanitizers' findings, it aborts when a failure is reported
 * without its class and message, or when a decoded chunk claims to have
 * used more bytes than it was given.
 */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "fuzz_input.h"
#include "gdt_error.h"
#include "private/laz_chunk.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

/* Appends an item to the VLR payload p of *n bytes and *nitems items; adds
 * its size to *rl. */
static void put_item(unsigned char *p, size_t *n, unsigned *nitems, unsigned *rl, unsigned type,
                     unsigned size, unsigned version)
{
    const unsigned v[3] = {type, size, version};
    for (int f = 0; f < 3; f++) {
        p[*n + 2 * f] = (unsigned char)v[f];
        p[*n + 2 * f + 1] = (unsigned char)(v[f] >> 8);
    }
    *n += 6;
    (*nitems)++;
    *rl += size;
}

/* The VLR payload of a pointwise file of point format fmt (0-5). */
static size_t make_vlr(unsigned char *p, unsigned fmt, unsigned extra, unsigned version,
                       unsigned *record_length)
{
    size_t n = 34;
    unsigned nitems = 0, rl = 0;

    memset(p, 0, 34);
    p[0] = GDT_LAZ_COMPRESSOR_POINTWISE_CHUNKED;
    p[12] = 0x50; /* chunk size 50000 */
    p[13] = 0xC3;
    memset(p + 16, 0xFF, 16);
    put_item(p, &n, &nitems, &rl, GDT_LAZ_POINT10, 20, version);
    if (fmt == 1 || fmt >= 3)
        put_item(p, &n, &nitems, &rl, GDT_LAZ_GPSTIME11, 8, version);
    if (fmt == 2 || fmt == 3 || fmt == 5)
        put_item(p, &n, &nitems, &rl, GDT_LAZ_RGB12, 6, version);
    if (fmt >= 4)
        put_item(p, &n, &nitems, &rl, GDT_LAZ_WAVEPACKET13, 29, version);
    if (extra)
        put_item(p, &n, &nitems, &rl, GDT_LAZ_BYTE, extra, version);
    p[32] = (unsigned char)nitems;
    *record_length = rl;
    return n;
}

/* One decoder per framing, kept for the whole run: decoders are reused
 * for every chunk in the readers too, so state left over from an earlier
 * (possibly failed) chunk must not matter. */
static struct cached {
    gdt_laz_vlr vlr;
    gdt_laz_chunk *c;
    unsigned rl;
} cache[6][2][8];

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static unsigned char rec[64 * (63 + 7)];
    struct cached *k;
    gdt_error err;
    gdt_status st;
    uint64_t npoints;

    if (size < 4)
        return 0;
    gdt_error_clear(&err);
    if (data[1] & 0x80) {
        gdt_laz_vlr vlr;
        unsigned fmt = data[0] % 11, rl = (unsigned)data[2] | (unsigned)data[3] << 8;
        st = gdt_laz_vlr_parse("fuzz.laz", data + 4, size - 4, fmt, rl, &vlr, &err);
        if (st != GDT_OK)
            gdt_fuzz_check_error(st, &err);
        return 0;
    }
    k = &cache[data[0] % 6][data[1] & 1][(data[1] >> 1) & 7];
    if (!k->c) {
        unsigned char payload[34 + 5 * 6];
        unsigned fmt = data[0] % 6;
        size_t n = make_vlr(payload, fmt, (data[1] >> 1) & 7, data[1] & 1 ? 1 : 2, &k->rl);
        if (gdt_laz_vlr_parse("fuzz.laz", payload, n, fmt, k->rl, &k->vlr, &err) != GDT_OK ||
            gdt_laz_chunk_new(&k->c, &k->vlr, k->rl, GDT_LAZ_NEED_ALL, &err) != GDT_OK)
            gdt_fuzz_die("the target's own decoder");
    }
    npoints = 1 + (((unsigned)data[2] | (unsigned)data[3] << 8) % 4096);
    st = gdt_laz_chunk_start(k->c, data + 4, size - 4, npoints, "fuzz.laz", 0, &err);
    for (uint64_t done = 0; st == GDT_OK && done < npoints; done += 64) {
        size_t m = npoints - done < 64 ? (size_t)(npoints - done) : 64;
        st = gdt_laz_chunk_read(k->c, rec, m, &err);
    }
    if (st != GDT_OK)
        gdt_fuzz_check_error(st, &err);
    else if (gdt_laz_chunk_used(k->c) > size - 4)
        abort();
    return 0;
}
