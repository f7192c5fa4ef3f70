/* test_laz14.c — the layered chunk decoder's contracts on hand-made chunks
 * (io/private/laz14.h through laz_chunk.h): a one-point chunk is its raw
 * record (masked by the need), used() counts the raw record, the count, the
 * layer sizes and every layer; chunks that cannot hold their first point,
 * count and sizes, that claim layers past their end, or fewer points than
 * the caller's are refused with their numbers; after a refused start no
 * point can be read; items a layered stream cannot hold are refused.  The
 * decoding of real streams is tested against laspy's writers in
 * tests/python/test_laz14_decode.py. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_check.h"
#include "private/bytes.h"
#include "private/laz_chunk.h"

enum { RL = 30 + 8 + 29 + 3, NLAYERS = 9 + 2 + 1 + 3, HEAD = RL + 4 + 4 * NLAYERS };

static void format10_vlr(gdt_laz_vlr *v, unsigned version)
{
    memset(v, 0, sizeof *v);
    v->compressor = GDT_LAZ_COMPRESSOR_LAYERED_CHUNKED;
    v->chunk_size = 50000;
    v->nitems = 4;
    v->items[0] = (gdt_laz_item){GDT_LAZ_POINT14, 30, (uint16_t)version};
    v->items[1] = (gdt_laz_item){GDT_LAZ_RGBNIR14, 8, (uint16_t)version};
    v->items[2] = (gdt_laz_item){GDT_LAZ_WAVEPACKET14, 29, (uint16_t)version};
    v->items[3] = (gdt_laz_item){GDT_LAZ_BYTE14, 3, (uint16_t)version};
}

/* A one-point chunk: a record of every byte distinct, count, layer sizes
 * (all zero but layer spare_layer, of spare bytes that follow). */
static size_t one_point_chunk(unsigned char *buf, uint32_t count, unsigned spare_layer,
                              uint32_t spare)
{
    for (unsigned b = 0; b < RL; b++)
        buf[b] = (unsigned char)(0x11 + 7 * b);
    gdt_le_put_u32(buf + RL, count);
    for (unsigned l = 0; l < NLAYERS; l++)
        gdt_le_put_u32(buf + RL + 4 + 4 * l, l == spare_layer ? spare : 0);
    memset(buf + HEAD, 0xA5, spare);
    return HEAD + spare;
}

/* Checks that starting chunk[0 .. n) of npoints fails with GDT_EINPUT code
 * and a message naming the file, the chunk and what. */
static void start_refused(gdt_checks *c, gdt_laz_chunk *dec, const unsigned char *chunk, size_t n,
                          uint64_t npoints, int code, const char *what)
{
    gdt_error err;
    gdt_status st;

    gdt_error_clear(&err);
    st = gdt_laz_chunk_start(dec, chunk, n, npoints, "t.laz", 3, &err);
    GDT_CHECK(c,
              st == GDT_EINPUT && err.code == code && strstr(err.msg, "t.laz") &&
                  strstr(err.msg, "chunk 3") && strstr(err.msg, what),
              "code %d: %s", err.code, err.msg);
}

int main(void)
{
    gdt_checks c = {0, 0};
    unsigned char chunk[HEAD + 64], rec[2 * RL];
    gdt_laz_vlr vlr;
    gdt_laz_chunk *all = NULL, *sel = NULL, *bad = NULL;
    gdt_error err;
    size_t n;

    for (unsigned version = 3; version <= 4; version++) {
        format10_vlr(&vlr, version);
        gdt_error_clear(&err);
        GDT_CHECK(&c, gdt_laz_chunk_new(&all, &vlr, RL, GDT_LAZ_NEED_ALL, &err) == GDT_OK, "%s",
                  err.msg);
        GDT_CHECK(&c,
                  gdt_laz_chunk_new(&sel, &vlr, RL, GDT_LAZ_NEED_XYZ | GDT_LAZ_NEED_FLAGS, &err) ==
                      GDT_OK,
                  "%s", err.msg);
        if (!all || !sel)
            break;

        /* One point, with bytes in a layer nobody reads: all used. */
        n = one_point_chunk(chunk, 1, 10, 40);
        GDT_CHECK(&c, gdt_laz_chunk_start(all, chunk, n, 1, "t.laz", 0, &err) == GDT_OK, "%s",
                  err.msg);
        GDT_CHECK(&c, gdt_laz_chunk_read(all, rec, 1, &err) == GDT_OK, "%s", err.msg);
        GDT_CHECK(&c, memcmp(rec, chunk, RL) == 0, "%s", "the record is not the raw point");
        GDT_CHECK(&c, gdt_laz_chunk_used(all) == n, "used %zu of %zu", gdt_laz_chunk_used(all), n);
        GDT_CHECK(&c, gdt_laz_chunk_read(all, rec, 1, &err) == GDT_EINTERNAL && err.code == 7395,
                  "a second point of one: code %d", err.code);

        memset(rec, 0x5A, RL);
        gdt_error_clear(&err);
        GDT_CHECK(&c, gdt_laz_chunk_start(sel, chunk, n, 1, "t.laz", 0, &err) == GDT_OK, "%s",
                  err.msg);
        GDT_CHECK(&c, gdt_laz_chunk_read(sel, rec, 1, &err) == GDT_OK, "%s", err.msg);
        for (unsigned b = 0; b < RL; b++) {
            int kept = b < 12 || b == 14 || b == 15;
            GDT_CHECK(&c, rec[b] == (kept ? chunk[b] : 0), "byte %u: %u", b, rec[b]);
        }
        GDT_CHECK(&c, gdt_laz_chunk_used(sel) == n, "used %zu", gdt_laz_chunk_used(sel));

        /* Too short for the layer sizes; then nothing to read. */
        GDT_CHECK(&c,
                  gdt_laz_chunk_start(all, chunk, HEAD - 1, 1, "t.laz", 5, &err) == GDT_EINPUT &&
                      err.code == 3941 && strstr(err.msg, "t.laz") && strstr(err.msg, "chunk 5"),
                  "code %d: %s", err.code, err.msg);
        gdt_error_clear(&err);
        GDT_CHECK(&c, gdt_laz_chunk_read(all, rec, 1, &err) == GDT_EINTERNAL && err.code == 7395,
                  "read after a refused start: code %d", err.code);

        /* A layer (a skipped one too) past the chunk; fewer points than
         * the caller's; two points with an empty changed-values layer. */
        n = one_point_chunk(chunk, 1, 13, 40);
        start_refused(&c, sel, chunk, n - 1, 1, 3943, "extra byte layer");
        n = one_point_chunk(chunk, 1, 0, 0);
        start_refused(&c, all, chunk, n, 2, 3942, "1 points");
        n = one_point_chunk(chunk, 2, 0, 0);
        start_refused(&c, all, chunk, n, 2, 3943, "changed-values");

        /* A changed-values layer of garbage runs out of bytes. */
        gdt_error_clear(&err);
        n = one_point_chunk(chunk, 64, 0, 6);
        GDT_CHECK(&c, gdt_laz_chunk_start(sel, chunk, n, 64, "t.laz", 0, &err) == GDT_OK, "%s",
                  err.msg);
        {
            unsigned char many[64 * RL];
            gdt_status st = gdt_laz_chunk_read(sel, many, 64, &err);
            GDT_CHECK(&c, st == GDT_EINPUT && (err.code == 3944 || err.code == 3945), "code %d: %s",
                      err.code, err.msg);
        }
        gdt_laz_chunk_free(all);
        gdt_laz_chunk_free(sel);
        all = sel = NULL;
    }

    /* Items a layered stream cannot hold. */
    format10_vlr(&vlr, 3);
    vlr.items[1].type = GDT_LAZ_RGB12;
    gdt_error_clear(&err);
    GDT_CHECK(&c,
              gdt_laz_chunk_new(&bad, &vlr, RL - 2, GDT_LAZ_NEED_ALL, &err) == GDT_EINPUT &&
                  err.code == 3940 && bad == NULL,
              "code %d", err.code);
    return gdt_check_finish(&c, "test_laz14");
}
