/* laz_arith.h — the arithmetic decoder of LASzip streams, its adaptive
 * models and the integer decompressor built on them.
 *
 * The coder is a 32-bit range coder: the decoder keeps an interval length
 * and the offset (value) of the code point inside it, and after every
 * decision shifts in bytes while the length is below 2^24.  Bits are coded
 * with adaptive two-symbol models (probabilities in 13 bits), symbols with
 * adaptive multi-symbol models (cumulative distributions in 15 bits, a
 * look-up table for alphabets over 16 symbols); both re-estimate their
 * statistics on a growing period, exactly as the encoder does, so the
 * update schedule below is part of the format.
 *
 * Bounds.  The decoder reads only data[0 .. n): a byte needed beyond the end
 * reads as zero and sets GDT_LAZ_DEC_OVERRUN in bad.  A code word no encoder
 * produces sets GDT_LAZ_DEC_CORRUPT.  Both are sticky; the hot functions
 * return values and never fail, so a caller checks bad once per point (or
 * per batch) and turns it into GDT_EINPUT.  The decoder keeps the invariant
 * value < length, under which every table look-up stays inside its model,
 * whatever the bytes; results of raw reads are masked to their width.
 *
 * Ownership.  Models own their arrays (allocated once by *_alloc / *_new,
 * freed by *_free); *_init only resets statistics, once per chunk.  Nothing
 * here allocates per symbol.  A decoder does not own the bytes it reads.
 */
#ifndef GDT_LAZ_ARITH_H
#define GDT_LAZ_ARITH_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_error.h"

#define GDT_LAZ_AC_MIN_LENGTH 0x01000000u /* renormalise below this length */
#define GDT_LAZ_BM_LENGTH_SHIFT 13        /* bit models: probability bits */
#define GDT_LAZ_BM_MAX_COUNT (1u << GDT_LAZ_BM_LENGTH_SHIFT)
#define GDT_LAZ_DM_LENGTH_SHIFT 15        /* symbol models: distribution bits */
#define GDT_LAZ_DM_MAX_COUNT (1u << GDT_LAZ_DM_LENGTH_SHIFT)
#define GDT_LAZ_MAX_SYMBOLS 2048u         /* largest alphabet of a symbol model */
/* Largest decoder table: 2^9 entries, so the look-up index dv >> (15 - 9)
 * of a position dv <= 2^15 + 63 is at most the table size. */
#define GDT_LAZ_DM_TABLE_BITS_MAX 9u

/* Flags of gdt_laz_dec.bad. */
#define GDT_LAZ_DEC_OVERRUN 1u /* the stream needed bytes past its end */
#define GDT_LAZ_DEC_CORRUPT 2u /* a code word no encoder writes */

typedef struct gdt_laz_dec {
    const unsigned char *start, *p, *end; /* the bytes; p is the next one */
    uint32_t value;                       /* code point - interval base, < length */
    uint32_t length;                      /* interval length, >= 2^24 between calls */
    unsigned bad;                         /* GDT_LAZ_DEC_* flags, sticky */
} gdt_laz_dec;

/* Adaptive model of one bit. */
typedef struct gdt_laz_bitmodel {
    uint32_t bit_0_prob;  /* P(0) scaled to 2^13 */
    uint32_t bit_0_count, bit_count;
    uint32_t update_cycle, bits_until_update;
} gdt_laz_bitmodel;

/* Adaptive model of an alphabet of 2 .. 2048 symbols. */
typedef struct gdt_laz_symmodel {
    uint32_t *distribution;  /* symbols cumulative frequencies, scaled to 2^15 */
    uint32_t *symbol_count;  /* symbols counts */
    uint32_t *decoder_table; /* table_size + 2 entries, or NULL (<= 16 symbols) */
    uint32_t symbols, last_symbol;
    uint32_t table_size, table_shift;
    uint32_t total_count, update_cycle, symbols_until_update;
} gdt_laz_symmodel;

/* Starts decoding the n bytes at data: reads the 4-byte code word.
 * data may be NULL when n is 0 (every read then overruns). */
void gdt_laz_dec_init(gdt_laz_dec *d, const unsigned char *data, size_t n);

/* Bytes the decoder has taken from data so far (at most n).  After the last
 * symbol of a stream this is the size the encoder wrote. */
static inline size_t gdt_laz_dec_used(const gdt_laz_dec *d)
{
    return (size_t)(d->p - d->start);
}

/* Resets m to equal probabilities. */
void gdt_laz_bitmodel_init(gdt_laz_bitmodel *m);
/* The periodic re-estimation (called by gdt_laz_decode_bit). */
void gdt_laz_bitmodel_update(gdt_laz_bitmodel *m);

/* Allocates the arrays of a model of symbols symbols (2 .. 2048) and
 * initialises it.  returns: GDT_EINTERNAL 7001 (out of memory) or 7390 (bad
 * alphabet size: a caller bug), or GDT_OK.  Free with gdt_laz_symmodel_free
 * (also after a failure; a zeroed model may be freed). */
gdt_status gdt_laz_symmodel_alloc(gdt_laz_symmodel *m, uint32_t symbols, gdt_error *err);
/* Resets the statistics: all counts 1. */
void gdt_laz_symmodel_init(gdt_laz_symmodel *m);
void gdt_laz_symmodel_free(gdt_laz_symmodel *m);
/* The periodic re-estimation (called by gdt_laz_decode_symbol). */
void gdt_laz_symmodel_update(gdt_laz_symmodel *m);

static inline uint32_t gdt_laz_dec_byte(gdt_laz_dec *d)
{
    if (d->p < d->end)
        return *d->p++;
    d->bad |= GDT_LAZ_DEC_OVERRUN;
    return 0;
}

static inline void gdt_laz_dec_renorm(gdt_laz_dec *d)
{
    do {
        d->value = (d->value << 8) | gdt_laz_dec_byte(d);
    } while ((d->length <<= 8) < GDT_LAZ_AC_MIN_LENGTH);
}

/* Decodes one bit with model m. */
static inline uint32_t gdt_laz_decode_bit(gdt_laz_dec *d, gdt_laz_bitmodel *m)
{
    uint32_t x = m->bit_0_prob * (d->length >> GDT_LAZ_BM_LENGTH_SHIFT);
    uint32_t sym = d->value >= x;

    if (sym == 0) {
        d->length = x;
        m->bit_0_count++;
    } else {
        d->value -= x;
        d->length -= x;
    }
    if (d->length < GDT_LAZ_AC_MIN_LENGTH)
        gdt_laz_dec_renorm(d);
    if (--m->bits_until_update == 0)
        gdt_laz_bitmodel_update(m);
    return sym;
}

/* Decodes one symbol (0 .. m->symbols - 1) with model m. */
static inline uint32_t gdt_laz_decode_symbol(gdt_laz_dec *d, gdt_laz_symmodel *m)
{
    uint32_t sym, x, y = d->length;

    if (m->decoder_table) {
        /* value < length bounds dv by 2^15 + 63, so t <= table_size
         * (GDT_LAZ_DM_TABLE_BITS_MAX). */
        uint32_t dv = d->value / (d->length >>= GDT_LAZ_DM_LENGTH_SHIFT);
        uint32_t t = dv >> m->table_shift;
        uint32_t n;

        sym = m->decoder_table[t];
        n = m->decoder_table[t + 1] + 1;
        while (n > sym + 1) {
            uint32_t k = (sym + n) >> 1;
            if (m->distribution[k] > dv)
                n = k;
            else
                sym = k;
        }
        x = m->distribution[sym] * d->length;
        if (sym != m->last_symbol)
            y = m->distribution[sym + 1] * d->length;
    } else {
        uint32_t n = m->symbols, k = n >> 1;

        x = sym = 0;
        d->length >>= GDT_LAZ_DM_LENGTH_SHIFT;
        do {
            uint32_t z = d->length * m->distribution[k];
            if (z > d->value) {
                n = k;
                y = z;
            } else {
                sym = k;
                x = z;
            }
        } while ((k = (sym + n) >> 1) != sym);
    }
    d->value -= x;
    d->length = y - x;
    if (d->length < GDT_LAZ_AC_MIN_LENGTH)
        gdt_laz_dec_renorm(d);
    m->symbol_count[sym]++;
    if (--m->symbols_until_update == 0)
        gdt_laz_symmodel_update(m);
    return sym;
}

/* Two's complement int32_t of u without implementation-defined conversions. */
static inline int32_t gdt_laz_i32(uint32_t u)
{
    return u <= (uint32_t)INT32_MAX ? (int32_t)u
                                    : (int32_t)(u - 2147483648u) - INT32_MAX - 1;
}

/* Reads bits (1 .. 19) raw bits: one uniform symbol of 2^bits values
 * (length >= 2^24 keeps length >> bits >= 32). */
static inline uint32_t gdt_laz_read_raw(gdt_laz_dec *d, unsigned bits)
{
    uint32_t sym = d->value / (d->length >>= bits);

    d->value -= d->length * sym;
    if (d->length < GDT_LAZ_AC_MIN_LENGTH)
        gdt_laz_dec_renorm(d);
    if (sym >> bits) {
        /* The code point lies in the rounding remainder of the interval. */
        d->bad |= GDT_LAZ_DEC_CORRUPT;
        sym &= (1u << bits) - 1;
    }
    return sym;
}

/* Reads bits (1 .. 32) raw bits; above 19 bits the low 16 come first. */
static inline uint32_t gdt_laz_read_bits(gdt_laz_dec *d, unsigned bits)
{
    if (bits > 19) {
        uint32_t lo = gdt_laz_read_raw(d, 16);
        return (gdt_laz_read_bits(d, bits - 16) << 16) | lo;
    }
    return gdt_laz_read_raw(d, bits);
}

static inline uint32_t gdt_laz_read_byte(gdt_laz_dec *d)
{
    return gdt_laz_read_raw(d, 8);
}

static inline uint32_t gdt_laz_read_short(gdt_laz_dec *d)
{
    return gdt_laz_read_raw(d, 16);
}

/* 32 raw bits, low half first. */
static inline uint32_t gdt_laz_read_int(gdt_laz_dec *d)
{
    uint32_t lo = gdt_laz_read_short(d);
    return (gdt_laz_read_short(d) << 16) | lo;
}

/* 64 raw bits, low word first. */
static inline uint64_t gdt_laz_read_int64(gdt_laz_dec *d)
{
    uint64_t lo = gdt_laz_read_int(d);
    return ((uint64_t)gdt_laz_read_int(d) << 32) | lo;
}

/* The integer decompressor: a value is coded as the corrector c = real -
 * pred, folded into the range of the integers of bits bits (or of range
 * values).  A symbol model per context gives k, the bit length of |c| (0 ..
 * corr_bits); then a symbol of k bits (the top bits_high bits modelled, the
 * rest raw) places c in [-(2^k - 1), -2^(k-1)] u [2^(k-1) + 1, 2^k]; k = 0
 * codes c in {0, 1} with a bit model. */
typedef struct gdt_laz_intdec {
    uint32_t bits, contexts, bits_high, range;
    uint32_t corr_bits, corr_range; /* corr_range 0: the full 32-bit range */
    int32_t corr_min, corr_max;
    uint32_t k;                     /* k of the last decoded value */
    gdt_laz_symmodel *mbits;        /* contexts models of corr_bits + 1 symbols */
    gdt_laz_symmodel *mcorr;        /* [1 .. corr_bits]: models of the low bits */
    gdt_laz_bitmodel mcorr0;        /* k = 0 */
    /* A model is reset on its first use after gdt_laz_intdec_init (when
     * its stamp differs from epoch), so a chunk pays only for the models
     * it uses: a 32-bit decompressor has thousands of symbols. */
    uint32_t epoch;
    uint32_t *stamp_bits;           /* of mbits */
    uint32_t *stamp_corr;           /* of mcorr */
} gdt_laz_intdec;

/* Creates the models of an integer decompressor (bits 1 .. 32, 0 meaning 32;
 * contexts >= 1; bits_high 1 .. 11; range 0 or the number of values) and
 * initialises them.  returns: GDT_EINTERNAL 7001 / 7390, or GDT_OK.  Free
 * with gdt_laz_intdec_free (also after a failure; a zeroed one may be
 * freed). */
gdt_status gdt_laz_intdec_new(gdt_laz_intdec *ic, uint32_t bits, uint32_t contexts,
                              uint32_t bits_high, uint32_t range, gdt_error *err);
/* Resets every model (once per chunk; the symbol models lazily, see
 * epoch).  An encoder sharing these models must reach them through
 * gdt_laz_intdec_kmodel and gdt_laz_intdec_cmodel too. */
void gdt_laz_intdec_init(gdt_laz_intdec *ic);
void gdt_laz_intdec_free(gdt_laz_intdec *ic);

/* The model of k in context (< contexts), reset if it is stale. */
static inline gdt_laz_symmodel *gdt_laz_intdec_kmodel(gdt_laz_intdec *ic, uint32_t context)
{
    if (ic->stamp_bits[context] != ic->epoch) {
        gdt_laz_symmodel_init(&ic->mbits[context]);
        ic->stamp_bits[context] = ic->epoch;
    }
    return &ic->mbits[context];
}

/* The model of the corrector's (top) bits for k (1 .. corr_bits). */
static inline gdt_laz_symmodel *gdt_laz_intdec_cmodel(gdt_laz_intdec *ic, uint32_t k)
{
    if (ic->stamp_corr[k] != ic->epoch) {
        gdt_laz_symmodel_init(&ic->mcorr[k]);
        ic->stamp_corr[k] = ic->epoch;
    }
    return &ic->mcorr[k];
}

/* The corrector of the next value in context (< contexts). */
static inline int32_t gdt_laz_intdec_corrector(gdt_laz_intdec *ic, gdt_laz_dec *d,
                                               uint32_t context)
{
    uint32_t k, c;

    if (context >= ic->contexts) {
        d->bad |= GDT_LAZ_DEC_CORRUPT;
        context = 0;
    }
    k = ic->k = gdt_laz_decode_symbol(d, gdt_laz_intdec_kmodel(ic, context));
    if (k == 0)
        return (int32_t)gdt_laz_decode_bit(d, &ic->mcorr0);
    if (k >= 32)
        return ic->corr_min;
    c = gdt_laz_decode_symbol(d, gdt_laz_intdec_cmodel(ic, k));
    if (k > ic->bits_high) {
        unsigned k1 = k - ic->bits_high;
        c = (c << k1) | gdt_laz_read_bits(d, k1);
    }
    /* c in [0, 2^(k-1)) are the negatives, [2^(k-1), 2^k) the positives
     * above 1; computed in uint32_t, the result fits int32_t. */
    if (c >= (1u << (k - 1)))
        return gdt_laz_i32(c + 1);
    return -gdt_laz_i32(((1u << k) - 1) - c);
}

/* Decodes the next value predicted by pred in context. */
static inline int32_t gdt_laz_intdec_decode(gdt_laz_intdec *ic, gdt_laz_dec *d, int32_t pred,
                                            uint32_t context)
{
    uint32_t real = (uint32_t)pred + (uint32_t)gdt_laz_intdec_corrector(ic, d, context);

    if (ic->corr_range) {
        if (real & 0x80000000u)
            real += ic->corr_range;
        else if (real >= ic->corr_range)
            real -= ic->corr_range;
    }
    return gdt_laz_i32(real);
}

/* The k (bit length class of the corrector) of the last decoded value. */
static inline uint32_t gdt_laz_intdec_k(const gdt_laz_intdec *ic)
{
    return ic->k;
}

#endif
