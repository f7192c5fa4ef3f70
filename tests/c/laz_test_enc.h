/* laz_test_enc.h — a LASzip arithmetic encoder for the C tests, written
 * from the format's definition: the range coder with carry propagation, the
 * adaptive models of io/private/laz_arith.h (whose update rules encoder and
 * decoder share) and the integer compressor.  Header-only; the output
 * buffer grows with realloc and aborts when memory runs out. */
#ifndef GDT_LAZ_TEST_ENC_H
#define GDT_LAZ_TEST_ENC_H

#include <stdint.h>
#include <stdlib.h>

#include "private/laz_arith.h"


typedef struct enc {
    unsigned char *buf;
    size_t n, cap;
    uint32_t base, length;
} enc;

static inline void enc_put(enc *e, unsigned char b)
{
    if (e->n == e->cap) {
        e->cap = e->cap ? 2 * e->cap : 256;
        e->buf = realloc(e->buf, e->cap);
        if (!e->buf)
            abort();
    }
    e->buf[e->n++] = b;
}

static inline void enc_carry(enc *e)
{
    size_t i = e->n;
    while (i > 0 && e->buf[i - 1] == 0xFF)
        e->buf[--i] = 0;
    if (i > 0)
        e->buf[i - 1]++;
}

static inline void enc_renorm(enc *e)
{
    do {
        enc_put(e, (unsigned char)(e->base >> 24));
        e->base <<= 8;
    } while ((e->length <<= 8) < GDT_LAZ_AC_MIN_LENGTH);
}

static inline void enc_interval(enc *e, uint32_t x, uint32_t newlen)
{
    uint32_t b0 = e->base;
    e->base += x;
    e->length = newlen;
    if (b0 > e->base)
        enc_carry(e);
    if (e->length < GDT_LAZ_AC_MIN_LENGTH)
        enc_renorm(e);
}

static inline void enc_bit(enc *e, gdt_laz_bitmodel *m, uint32_t bit)
{
    uint32_t x = m->bit_0_prob * (e->length >> GDT_LAZ_BM_LENGTH_SHIFT);
    if (bit == 0) {
        m->bit_0_count++;
        enc_interval(e, 0, x);
    } else {
        enc_interval(e, x, e->length - x);
    }
    if (--m->bits_until_update == 0)
        gdt_laz_bitmodel_update(m);
}

static inline void enc_symbol(enc *e, gdt_laz_symmodel *m, uint32_t sym)
{
    uint32_t l = e->length >> GDT_LAZ_DM_LENGTH_SHIFT;
    uint32_t x = m->distribution[sym] * l;
    if (sym == m->last_symbol)
        enc_interval(e, x, e->length - x);
    else
        enc_interval(e, x, m->distribution[sym + 1] * l - x);
    m->symbol_count[sym]++;
    if (--m->symbols_until_update == 0)
        gdt_laz_symmodel_update(m);
}

static inline void enc_bits(enc *e, unsigned bits, uint32_t v)
{
    if (bits > 19) {
        enc_bits(e, 16, v & 0xFFFF);
        enc_bits(e, bits - 16, v >> 16);
        return;
    }
    uint32_t l = e->length >> bits;
    enc_interval(e, v * l, l);
}

static inline void enc_done(enc *e)
{
    int another = 1;
    uint32_t b0 = e->base;
    if (e->length > 2 * GDT_LAZ_AC_MIN_LENGTH) {
        e->base += GDT_LAZ_AC_MIN_LENGTH;
        e->length = GDT_LAZ_AC_MIN_LENGTH >> 1;
    } else {
        e->base += GDT_LAZ_AC_MIN_LENGTH >> 1;
        e->length = GDT_LAZ_AC_MIN_LENGTH >> 9;
        another = 0;
    }
    if (b0 > e->base)
        enc_carry(e);
    enc_renorm(e);
    enc_put(e, 0);
    enc_put(e, 0);
    if (another)
        enc_put(e, 0);
}

/* The integer compressor's encoding of real against pred. */
static inline void enc_int(enc *e, gdt_laz_intdec *ic, int32_t pred, int32_t real, uint32_t ctx)
{
    int64_t corr = (int64_t)real - pred;
    uint32_t k = 0, c1;

    if (ic->corr_range) {
        if (corr < ic->corr_min)
            corr += ic->corr_range;
        else if (corr > ic->corr_max)
            corr -= ic->corr_range;
    } else {
        corr = (int32_t)(uint32_t)(uint64_t)corr;
    }
    int32_t c = (int32_t)corr;
    c1 = c <= 0 ? 0u - (uint32_t)c : (uint32_t)c - 1;
    while (c1) {
        c1 >>= 1;
        k++;
    }
    enc_symbol(e, gdt_laz_intdec_kmodel(ic, ctx), k);
    if (k == 0) {
        enc_bit(e, &ic->mcorr0, (uint32_t)c);
    } else if (k < 32) {
        uint32_t u = c < 0 ? (uint32_t)c + ((1u << k) - 1) : (uint32_t)c - 1;
        if (k <= ic->bits_high) {
            enc_symbol(e, gdt_laz_intdec_cmodel(ic, k), u);
        } else {
            unsigned k1 = k - ic->bits_high;
            enc_symbol(e, gdt_laz_intdec_cmodel(ic, k), u >> k1);
            enc_bits(e, k1, u & ((1u << k1) - 1));
        }
    }
}

#endif
