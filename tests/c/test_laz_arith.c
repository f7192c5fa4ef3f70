/* test_laz_arith.c — the LASzip arithmetic decoder against an encoder
 * written here from the format's definition (range coder with carry
 * propagation, the same adaptive models), on seeded random streams of
 * bits, symbols, raw values and integer-compressed values; then its bounds:
 * truncated, empty and random streams must set the sticky flags and never
 * yield a symbol outside its model. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_check.h"
#include "laz_test_enc.h"
#include "private/laz_arith.h"

/* ---- the script of one stream ---- */

enum { NBIT = 3, NSYM = 6, NINT = 4 };
static const uint32_t SYMS[NSYM] = {2, 5, 16, 17, 300, 2048};
static const uint32_t INTCFG[NINT][4] = {
    {16, 1, 8, 0}, {32, 4, 8, 0}, {8, 2, 8, 0}, {0, 1, 8, 1000}};

typedef struct models {
    gdt_laz_bitmodel bit[NBIT];
    gdt_laz_symmodel sym[NSYM];
    gdt_laz_intdec ic[NINT];
} models;

static int models_new(models *m)
{
    memset(m, 0, sizeof *m);
    for (int i = 0; i < NBIT; i++)
        gdt_laz_bitmodel_init(&m->bit[i]);
    for (int i = 0; i < NSYM; i++)
        if (gdt_laz_symmodel_alloc(&m->sym[i], SYMS[i], NULL) != GDT_OK)
            return -1;
    for (int i = 0; i < NINT; i++)
        if (gdt_laz_intdec_new(&m->ic[i], INTCFG[i][0], INTCFG[i][1], INTCFG[i][2],
                               INTCFG[i][3], NULL) != GDT_OK)
            return -1;
    return 0;
}

static void models_reset(models *m)
{
    for (int i = 0; i < NBIT; i++)
        gdt_laz_bitmodel_init(&m->bit[i]);
    for (int i = 0; i < NSYM; i++)
        gdt_laz_symmodel_init(&m->sym[i]);
    for (int i = 0; i < NINT; i++)
        gdt_laz_intdec_init(&m->ic[i]);
}

static void models_free(models *m)
{
    for (int i = 0; i < NSYM; i++)
        gdt_laz_symmodel_free(&m->sym[i]);
    for (int i = 0; i < NINT; i++)
        gdt_laz_intdec_free(&m->ic[i]);
}

typedef struct op {
    int kind, which;
    uint64_t v;
    int32_t pred;
    uint32_t ctx;
} op;

/* A skewed value of the script (small values frequent, as in LiDAR). */
static uint64_t skewed(uint64_t *rng, uint64_t range)
{
    uint64_t r = gdt_splitmix64(rng);
    if ((r & 3) != 0)
        return (r >> 8) % (range < 8 ? range : 8);
    return (r >> 8) % range;
}

static void make_script(op *ops, size_t n, uint64_t seed)
{
    uint64_t rng = seed;
    for (size_t i = 0; i < n; i++) {
        op *o = &ops[i];
        uint64_t r = gdt_splitmix64(&rng);
        o->kind = (int)(r % 4);
        switch (o->kind) {
        case 0:
            o->which = (int)((r >> 8) % NBIT);
            o->v = skewed(&rng, 2);
            break;
        case 1:
            o->which = (int)((r >> 8) % NSYM);
            o->v = skewed(&rng, SYMS[o->which]);
            break;
        case 2:
            o->which = 1 + (int)((r >> 8) % 33); /* 1 .. 32 bits, 33: int64 */
            o->v = gdt_splitmix64(&rng);
            if (o->which <= 32)
                o->v &= o->which == 32 ? 0xFFFFFFFFu : (UINT64_C(1) << o->which) - 1;
            break;
        default: {
            const uint32_t *cfg;
            o->which = (int)((r >> 8) % NINT);
            cfg = INTCFG[o->which];
            o->ctx = (uint32_t)((r >> 16) % cfg[1]);
            uint64_t u = gdt_splitmix64(&rng);
            if (cfg[3]) {
                o->pred = (int32_t)(u % cfg[3]);
                o->v = (uint64_t)(int64_t)((o->pred + (int32_t)skewed(&rng, 40) - 20 + 1000) %
                                           1000);
            } else {
                uint32_t bits = cfg[0] ? cfg[0] : 32;
                uint32_t mask = bits == 32 ? 0xFFFFFFFFu : (1u << bits) - 1;
                o->pred = (int32_t)(uint32_t)(u & mask);
                uint32_t delta = (u >> 40) & 1 ? (uint32_t)skewed(&rng, 1u << 20)
                                               : (uint32_t)(u >> 32);
                uint32_t real = ((uint32_t)o->pred + delta) & mask;
                o->v = real;
            }
        } break;
        }
    }
}

static size_t encode_script(const op *ops, size_t n, models *m, unsigned char **out)
{
    enc e = {NULL, 0, 0, 0, 0xFFFFFFFFu};
    models_reset(m);
    for (size_t i = 0; i < n; i++) {
        const op *o = &ops[i];
        switch (o->kind) {
        case 0:
            enc_bit(&e, &m->bit[o->which], (uint32_t)o->v);
            break;
        case 1:
            enc_symbol(&e, &m->sym[o->which], (uint32_t)o->v);
            break;
        case 2:
            if (o->which == 33) {
                enc_bits(&e, 16, (uint32_t)o->v & 0xFFFF);
                enc_bits(&e, 16, (uint32_t)(o->v >> 16) & 0xFFFF);
                enc_bits(&e, 16, (uint32_t)(o->v >> 32) & 0xFFFF);
                enc_bits(&e, 16, (uint32_t)(o->v >> 48));
            } else {
                enc_bits(&e, (unsigned)o->which, (uint32_t)o->v);
            }
            break;
        default:
            enc_int(&e, &m->ic[o->which], o->pred, (int32_t)(uint32_t)o->v, o->ctx);
            break;
        }
    }
    enc_done(&e);
    *out = e.buf;
    return e.n;
}

/* Decodes the script from buf[0 .. n) and counts mismatches. */
static size_t decode_script(const op *ops, size_t nops, models *m, const unsigned char *buf,
                            size_t n, gdt_laz_dec *d)
{
    size_t wrong = 0;
    models_reset(m);
    gdt_laz_dec_init(d, buf, n);
    for (size_t i = 0; i < nops; i++) {
        const op *o = &ops[i];
        uint64_t v;
        switch (o->kind) {
        case 0:
            v = gdt_laz_decode_bit(d, &m->bit[o->which]);
            break;
        case 1:
            v = gdt_laz_decode_symbol(d, &m->sym[o->which]);
            break;
        case 2:
            v = o->which == 33 ? gdt_laz_read_int64(d)
                               : gdt_laz_read_bits(d, (unsigned)o->which);
            break;
        default:
            v = (uint32_t)gdt_laz_intdec_decode(&m->ic[o->which], d, o->pred, o->ctx);
            break;
        }
        wrong += v != o->v;
    }
    return wrong;
}

int main(void)
{
    gdt_checks c = {0, 0};
    models m;
    const size_t nops = 20000;
    op *ops = malloc(nops * sizeof *ops);

    GDT_CHECK(&c, ops && models_new(&m) == 0, "%s", "set-up");
    if (!ops)
        return 1;
    for (uint64_t seed = 1; seed <= 12; seed++) {
        size_t len = seed <= 4 ? (size_t)seed : nops; /* tiny streams too */
        unsigned char *buf;
        gdt_laz_dec d;
        make_script(ops, len, seed);
        size_t n = encode_script(ops, len, &m, &buf);
        size_t wrong = decode_script(ops, len, &m, buf, n, &d);
        GDT_CHECK(&c, wrong == 0, "seed %llu: %zu of %zu values differ",
                  (unsigned long long)seed, wrong, len);
        GDT_CHECK(&c, d.bad == 0, "seed %llu: flags %u", (unsigned long long)seed, d.bad);
        GDT_CHECK(&c, gdt_laz_dec_used(&d) == n, "seed %llu: used %zu of %zu",
                  (unsigned long long)seed, gdt_laz_dec_used(&d), n);
        /* Truncated by one byte: the decoder must report it, and still
         * read nothing past the copy's end (ASan builds check this). */
        unsigned char *cut = malloc(n - 1);
        memcpy(cut, buf, n - 1);
        decode_script(ops, len, &m, cut, n - 1, &d);
        GDT_CHECK(&c, (d.bad & GDT_LAZ_DEC_OVERRUN) != 0, "seed %llu: truncation not seen",
                  (unsigned long long)seed);
        GDT_CHECK(&c, gdt_laz_dec_used(&d) == n - 1, "%s", "used past the end");
        free(cut);
        free(buf);
    }

    /* Random bytes: every symbol must be inside its model. */
    {
        uint64_t rng = 99;
        size_t n = 4096, outside = 0;
        unsigned char *junk = malloc(n);
        for (size_t i = 0; i < n; i++)
            junk[i] = (unsigned char)gdt_splitmix64(&rng);
        for (int round = 0; round < 3; round++) {
            gdt_laz_dec d;
            models_reset(&m);
            gdt_laz_dec_init(&d, junk + round * 7, n - (size_t)round * 7);
            for (int i = 0; i < 200000; i++) {
                int w = i % NSYM;
                uint32_t s = gdt_laz_decode_symbol(&d, &m.sym[w]);
                outside += s >= SYMS[w];
                (void)gdt_laz_intdec_decode(&m.ic[i % NINT], &d, 0, 0);
                outside += gdt_laz_read_bits(&d, 1 + (unsigned)(i % 32)) >
                           (i % 32 == 31 ? 0xFFFFFFFFu : (1u << (1 + i % 32)) - 1);
            }
            GDT_CHECK(&c, outside == 0, "%zu symbols outside their model", outside);
            GDT_CHECK(&c, (d.bad & GDT_LAZ_DEC_OVERRUN) != 0, "%s", "random stream: no overrun");
            GDT_CHECK(&c, gdt_laz_dec_used(&d) == n - (size_t)round * 7, "%s", "used");
        }
        free(junk);
    }

    /* No bytes at all, and the impossible all-ones code word. */
    {
        gdt_laz_dec d;
        static const unsigned char ones[8] = {0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF};
        gdt_laz_dec_init(&d, NULL, 0);
        GDT_CHECK(&c, d.bad == GDT_LAZ_DEC_OVERRUN && gdt_laz_dec_used(&d) == 0, "flags %u",
                  d.bad);
        GDT_CHECK(&c, gdt_laz_read_int(&d) == 0, "%s", "overrun reads zeros");
        gdt_laz_dec_init(&d, ones, sizeof ones);
        GDT_CHECK(&c, (d.bad & GDT_LAZ_DEC_CORRUPT) != 0 && d.value < d.length, "flags %u",
                  d.bad);
        gdt_laz_dec_init(&d, ones, 3);
        GDT_CHECK(&c, d.bad == GDT_LAZ_DEC_OVERRUN, "flags %u", d.bad);
    }

    /* Bad alphabet sizes are refused, not allocated. */
    {
        gdt_laz_symmodel sm;
        gdt_error err;
        gdt_error_clear(&err);
        GDT_CHECK(&c, gdt_laz_symmodel_alloc(&sm, 1, &err) == GDT_EINTERNAL, "%s", "1 symbol");
        gdt_laz_symmodel_free(&sm);
        GDT_CHECK(&c, gdt_laz_symmodel_alloc(&sm, 4097, NULL) == GDT_EINTERNAL, "%s", "4097");
        gdt_laz_symmodel_free(&sm);
    }

    models_free(&m);
    free(ops);
    return gdt_check_finish(&c, "test_laz_arith");
}
