/* test_laz_v1.c — the version 1 codings of RGB12 and BYTE, which no encoder
 * at hand writes as LASzip does (lazrs's differ), against chunks encoded
 * here as LASzip 1.x's writer defines them: RGB12 codes a mask of the six
 * colour bytes that changed, then each changed byte with an 8-bit integer
 * compressor predicted by its previous value (context: the byte's index);
 * BYTE codes every extra byte so (context: the byte's index).  The POINT10
 * fields stay constant, which POINT10 version 1 codes as zero x, y
 * differences, the same z and an empty change mask. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_check.h"
#include "laz_test_enc.h"
#include "private/bytes.h"
#include "private/laz_chunk.h"

enum { NEXTRA = 3, RL = 20 + 6 + NEXTRA };

typedef struct encoder_models {
    gdt_laz_intdec dx, dy, z, rgb, bytes;
    gdt_laz_symmodel changed, used;
} encoder_models;

static void make_records(unsigned char *rec, size_t n, uint64_t seed)
{
    uint64_t rng = seed;
    for (size_t i = 0; i < n; i++) {
        unsigned char *r = rec + i * RL;
        if (i == 0) {
            for (int b = 0; b < RL; b++)
                r[b] = (unsigned char)gdt_splitmix64(&rng);
            continue;
        }
        memcpy(r, r - RL, RL);
        for (int b = 20; b < RL; b++) {
            uint64_t u = gdt_splitmix64(&rng);
            if (u % 3 == 0)
                r[b] = (unsigned char)(r[b] + (int)((u >> 8) % 9) - 4);
            else if (u % 7 == 0)
                r[b] = (unsigned char)(u >> 16);
        }
    }
}

/* The chunk of records rec[0 .. n): the raw first record, then the stream. */
static size_t encode_chunk(const unsigned char *rec, size_t n, encoder_models *m,
                           unsigned char **out)
{
    enc e = {NULL, 0, 0, 0, 0xFFFFFFFFu};
    int32_t z = (int32_t)gdt_le_get_u32(rec + 8);

    gdt_laz_intdec_init(&m->dx);
    gdt_laz_intdec_init(&m->dy);
    gdt_laz_intdec_init(&m->z);
    gdt_laz_intdec_init(&m->rgb);
    gdt_laz_intdec_init(&m->bytes);
    gdt_laz_symmodel_init(&m->changed);
    gdt_laz_symmodel_init(&m->used);
    for (size_t i = 1; i < n; i++) {
        const unsigned char *r = rec + i * RL, *l = r - RL;
        uint32_t sym = 0;
        enc_int(&e, &m->dx, 0, 0, 0);
        enc_int(&e, &m->dy, 0, 0, 0);
        enc_int(&e, &m->z, z, z, 0);
        enc_symbol(&e, &m->changed, 0);
        for (int b = 0; b < 6; b++)
            sym |= (uint32_t)(r[20 + b] != l[20 + b]) << b;
        enc_symbol(&e, &m->used, sym);
        for (int b = 0; b < 6; b++)
            if (sym & (1u << b))
                enc_int(&e, &m->rgb, l[20 + b], r[20 + b], (uint32_t)b);
        for (int b = 0; b < NEXTRA; b++)
            enc_int(&e, &m->bytes, l[26 + b], r[26 + b], (uint32_t)b);
    }
    enc_done(&e);
    *out = malloc(RL + e.n);
    if (!*out)
        abort();
    memcpy(*out, rec, RL);
    memcpy(*out + RL, e.buf, e.n);
    free(e.buf);
    return RL + e.n;
}

int main(void)
{
    gdt_checks c = {0, 0};
    encoder_models m;
    gdt_laz_vlr vlr;
    gdt_laz_chunk *dec = NULL;
    gdt_error err;
    static const size_t sizes[] = {1, 2, 500};

    memset(&m, 0, sizeof m);
    gdt_error_clear(&err);
    GDT_CHECK(&c,
              gdt_laz_intdec_new(&m.dx, 32, 1, 8, 0, NULL) == GDT_OK &&
                  gdt_laz_intdec_new(&m.dy, 32, 20, 8, 0, NULL) == GDT_OK &&
                  gdt_laz_intdec_new(&m.z, 32, 20, 8, 0, NULL) == GDT_OK &&
                  gdt_laz_intdec_new(&m.rgb, 8, 6, 8, 0, NULL) == GDT_OK &&
                  gdt_laz_intdec_new(&m.bytes, 8, NEXTRA, 8, 0, NULL) == GDT_OK &&
                  gdt_laz_symmodel_alloc(&m.changed, 64, NULL) == GDT_OK &&
                  gdt_laz_symmodel_alloc(&m.used, 64, NULL) == GDT_OK,
              "%s", "encoder models");

    /* The VLR of point format 2 with 3 extra bytes, items version 1. */
    {
        unsigned char p[34 + 3 * 6] = {0};
        static const uint16_t items[3][3] = {
            {GDT_LAZ_POINT10, 20, 1}, {GDT_LAZ_RGB12, 6, 1}, {GDT_LAZ_BYTE, NEXTRA, 1}};
        p[0] = GDT_LAZ_COMPRESSOR_POINTWISE_CHUNKED;
        p[4] = 1;
        p[5] = 3;
        p[12] = 0xF4;
        p[13] = 0x01; /* chunk size 500 */
        memset(p + 16, 0xFF, 16);
        p[32] = 3;
        for (int i = 0; i < 3; i++)
            for (int f = 0; f < 3; f++) {
                p[34 + 6 * i + 2 * f] = (unsigned char)items[i][f];
                p[34 + 6 * i + 2 * f + 1] = (unsigned char)(items[i][f] >> 8);
            }
        GDT_CHECK(&c, gdt_laz_vlr_parse("v1.laz", p, sizeof p, 2, RL, &vlr, &err) == GDT_OK,
                  "%s", err.msg);
        GDT_CHECK(&c, gdt_laz_chunk_new(&dec, &vlr, RL, GDT_LAZ_NEED_ALL, &err) == GDT_OK, "%s",
                  err.msg);
    }
    for (size_t t = 0; dec && t < sizeof sizes / sizeof sizes[0]; t++) {
        size_t n = sizes[t], len;
        unsigned char *rec = malloc(n * RL), *got = malloc(n * RL), *chunk;
        make_records(rec, n, 40 + t);
        len = encode_chunk(rec, n, &m, &chunk);
        GDT_CHECK(&c, gdt_laz_chunk_start(dec, chunk, len, n, "v1.laz", t, &err) == GDT_OK, "%s",
                  err.msg);
        GDT_CHECK(&c, gdt_laz_chunk_read(dec, got, n, &err) == GDT_OK, "%s", err.msg);
        GDT_CHECK(&c, memcmp(rec, got, n * RL) == 0, "%zu records differ", n);
        GDT_CHECK(&c, gdt_laz_chunk_used(dec) == len, "used %zu of %zu",
                  gdt_laz_chunk_used(dec), len);
        /* Cut by one byte: the last point must fail as truncated. */
        if (n > 1) {
            gdt_error_clear(&err);
            gdt_laz_chunk_start(dec, chunk, len - 1, n, "v1.laz", t, &err);
            GDT_CHECK(&c, gdt_laz_chunk_read(dec, got, n, &err) == GDT_EINPUT && err.code == 3920,
                      "code %d", err.code);
        }
        free(chunk);
        free(rec);
        free(got);
    }
    gdt_laz_chunk_free(dec);
    gdt_laz_intdec_free(&m.dx);
    gdt_laz_intdec_free(&m.dy);
    gdt_laz_intdec_free(&m.z);
    gdt_laz_intdec_free(&m.rgb);
    gdt_laz_intdec_free(&m.bytes);
    gdt_laz_symmodel_free(&m.changed);
    gdt_laz_symmodel_free(&m.used);
    return gdt_check_finish(&c, "test_laz_v1");
}
