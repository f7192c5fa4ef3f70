/* laz_arith.c — model updates and set-up of the LASzip arithmetic decoder
 * (the per-symbol paths are inline in laz_arith.h). */
#include "laz_arith.h"

#include <stdlib.h>
#include <string.h>

void gdt_laz_dec_init(gdt_laz_dec *d, const unsigned char *data, size_t n)
{
    d->start = d->p = data;
    d->end = data ? data + n : data;
    d->bad = 0;
    d->length = 0xFFFFFFFFu;
    d->value = gdt_laz_dec_byte(d) << 24;
    d->value |= gdt_laz_dec_byte(d) << 16;
    d->value |= gdt_laz_dec_byte(d) << 8;
    d->value |= gdt_laz_dec_byte(d);
    if (d->value >= d->length) {
        /* The encoder's code point lies inside [0, 2^32 - 1): all ones is
         * no stream, and it would break value < length. */
        d->bad |= GDT_LAZ_DEC_CORRUPT;
        d->value = 0;
    }
}

void gdt_laz_bitmodel_init(gdt_laz_bitmodel *m)
{
    m->bit_0_count = 1;
    m->bit_count = 2;
    m->bit_0_prob = 1u << (GDT_LAZ_BM_LENGTH_SHIFT - 1);
    m->update_cycle = m->bits_until_update = 4;
}

void gdt_laz_bitmodel_update(gdt_laz_bitmodel *m)
{
    /* Halve the counts past the limit; bit_count stays > bit_0_count so
     * the probability of 1 never reaches zero. */
    if ((m->bit_count += m->update_cycle) > GDT_LAZ_BM_MAX_COUNT) {
        m->bit_count = (m->bit_count + 1) >> 1;
        m->bit_0_count = (m->bit_0_count + 1) >> 1;
        if (m->bit_0_count == m->bit_count)
            m->bit_count++;
    }
    m->bit_0_prob = (m->bit_0_count * (0x80000000u / m->bit_count)) >>
                    (31 - GDT_LAZ_BM_LENGTH_SHIFT);
    /* Updates become rarer, up to every 64 bits. */
    m->update_cycle = (5 * m->update_cycle) >> 2;
    if (m->update_cycle > 64)
        m->update_cycle = 64;
    m->bits_until_update = m->update_cycle;
}

gdt_status gdt_laz_symmodel_alloc(gdt_laz_symmodel *m, uint32_t symbols, gdt_error *err)
{
    size_t words;

    memset(m, 0, sizeof *m);
    if (symbols < 2 || symbols > GDT_LAZ_MAX_SYMBOLS)
        return gdt_error_set(err, GDT_EINTERNAL, 7390,
                             "LAZ symbol model of %u symbols (2 .. %u allowed)",
                             (unsigned)symbols, GDT_LAZ_MAX_SYMBOLS);
    m->symbols = symbols;
    m->last_symbol = symbols - 1;
    words = 2 * (size_t)symbols;
    if (symbols > 16) {
        /* The table maps the top table_bits bits of a 15-bit position to
         * the first symbol whose interval may hold it; four entries per
         * symbol on average (up to the largest table the look-up bound
         * allows), so the search after the look-up mostly has nothing left
         * to do.  (The table is the decoder's own index: any
         * size finds the same symbols.) */
        uint32_t table_bits = 3;
        while (symbols > (1u << (table_bits - 2)) && table_bits < GDT_LAZ_DM_TABLE_BITS_MAX)
            table_bits++;
        m->table_size = 1u << table_bits;
        m->table_shift = GDT_LAZ_DM_LENGTH_SHIFT - table_bits;
        words += m->table_size + 2;
    }
    m->distribution = malloc(words * sizeof *m->distribution);
    if (!m->distribution)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    m->symbol_count = m->distribution + symbols;
    m->decoder_table = m->table_size ? m->symbol_count + symbols : NULL;
    gdt_laz_symmodel_init(m);
    return GDT_OK;
}

void gdt_laz_symmodel_init(gdt_laz_symmodel *m)
{
    for (uint32_t k = 0; k < m->symbols; k++)
        m->symbol_count[k] = 1;
    m->total_count = 0;
    m->update_cycle = m->symbols;
    gdt_laz_symmodel_update(m);
    m->symbols_until_update = m->update_cycle = (m->symbols + 6) >> 1;
}

void gdt_laz_symmodel_free(gdt_laz_symmodel *m)
{
    free(m->distribution);
    memset(m, 0, sizeof *m);
}

void gdt_laz_symmodel_update(gdt_laz_symmodel *m)
{
    uint32_t sum = 0, scale, s = 0;

    if ((m->total_count += m->update_cycle) > GDT_LAZ_DM_MAX_COUNT) {
        m->total_count = 0;
        for (uint32_t n = 0; n < m->symbols; n++)
            m->total_count += (m->symbol_count[n] = (m->symbol_count[n] + 1) >> 1);
    }
    scale = 0x80000000u / m->total_count;
    if (!m->decoder_table) {
        for (uint32_t k = 0; k < m->symbols; k++) {
            m->distribution[k] = (scale * sum) >> (31 - GDT_LAZ_DM_LENGTH_SHIFT);
            sum += m->symbol_count[k];
        }
    } else {
        /* decoder_table[t] = the last symbol whose distribution starts
         * below t << table_shift (entries 0 .. table_size + 1). */
        for (uint32_t k = 0; k < m->symbols; k++) {
            uint32_t w;
            m->distribution[k] = (scale * sum) >> (31 - GDT_LAZ_DM_LENGTH_SHIFT);
            sum += m->symbol_count[k];
            w = m->distribution[k] >> m->table_shift;
            while (s < w)
                m->decoder_table[++s] = k - 1;
        }
        m->decoder_table[0] = 0;
        while (s <= m->table_size)
            m->decoder_table[++s] = m->symbols - 1;
    }
    m->update_cycle = (5 * m->update_cycle) >> 2;
    if (m->update_cycle > (m->symbols + 6) << 3)
        m->update_cycle = (m->symbols + 6) << 3;
    m->symbols_until_update = m->update_cycle;
}

gdt_status gdt_laz_intdec_new(gdt_laz_intdec *ic, uint32_t bits, uint32_t contexts,
                              uint32_t bits_high, uint32_t range, gdt_error *err)
{
    gdt_status st;

    memset(ic, 0, sizeof *ic);
    if (bits > 32 || contexts == 0 || bits_high == 0 || bits_high > 11)
        return gdt_error_set(err, GDT_EINTERNAL, 7390,
                             "LAZ integer decompressor of %u bits, %u contexts, %u high bits",
                             (unsigned)bits, (unsigned)contexts, (unsigned)bits_high);
    ic->bits = bits;
    ic->contexts = contexts;
    ic->bits_high = bits_high;
    ic->range = range;
    if (range) {
        /* corr_bits: bits of range - 1 (a power of two needs one fewer). */
        ic->corr_bits = 0;
        for (uint32_t r = range; r; r >>= 1)
            ic->corr_bits++;
        if (range == 1u << (ic->corr_bits - 1))
            ic->corr_bits--;
        ic->corr_range = range;
    } else if (bits && bits < 32) {
        ic->corr_bits = bits;
        ic->corr_range = 1u << bits;
    } else {
        ic->corr_bits = 32;
        ic->corr_range = 0;
    }
    if (ic->corr_range) {
        ic->corr_min = -gdt_laz_i32(ic->corr_range / 2);
        ic->corr_max = gdt_laz_i32((uint32_t)ic->corr_min + ic->corr_range - 1);
    } else {
        ic->corr_min = INT32_MIN;
        ic->corr_max = INT32_MAX;
    }
    ic->mbits = calloc(contexts, sizeof *ic->mbits);
    ic->mcorr = calloc(ic->corr_bits + 1, sizeof *ic->mcorr);
    ic->stamp_bits = calloc(contexts, sizeof *ic->stamp_bits);
    ic->stamp_corr = calloc(ic->corr_bits + 1, sizeof *ic->stamp_corr);
    if (!ic->mbits || !ic->mcorr || !ic->stamp_bits || !ic->stamp_corr) {
        gdt_laz_intdec_free(ic);
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    }
    for (uint32_t i = 0; i < contexts; i++)
        if ((st = gdt_laz_symmodel_alloc(&ic->mbits[i], ic->corr_bits + 1, err)) != GDT_OK)
            goto fail;
    for (uint32_t i = 1; i <= ic->corr_bits; i++) {
        uint32_t b = i <= bits_high ? i : bits_high;
        if ((st = gdt_laz_symmodel_alloc(&ic->mcorr[i], 1u << b, err)) != GDT_OK)
            goto fail;
    }
    gdt_laz_bitmodel_init(&ic->mcorr0);
    return GDT_OK;
fail:
    gdt_laz_intdec_free(ic);
    return st;
}

void gdt_laz_intdec_init(gdt_laz_intdec *ic)
{
    /* Every stamp now differs from epoch (the models are fresh for epoch
     * 0 after gdt_laz_intdec_new; on wrap-around the stamps restart). */
    if (++ic->epoch == 0) {
        memset(ic->stamp_bits, 0, ic->contexts * sizeof *ic->stamp_bits);
        memset(ic->stamp_corr, 0, (ic->corr_bits + 1) * sizeof *ic->stamp_corr);
        ic->epoch = 1;
    }
    gdt_laz_bitmodel_init(&ic->mcorr0);
    ic->k = 0;
}

void gdt_laz_intdec_free(gdt_laz_intdec *ic)
{
    if (ic->mbits)
        for (uint32_t i = 0; i < ic->contexts; i++)
            gdt_laz_symmodel_free(&ic->mbits[i]);
    if (ic->mcorr)
        for (uint32_t i = 0; i <= ic->corr_bits; i++)
            gdt_laz_symmodel_free(&ic->mcorr[i]);
    free(ic->mbits);
    free(ic->mcorr);
    free(ic->stamp_bits);
    free(ic->stamp_corr);
    memset(ic, 0, sizeof *ic);
}
