/* Incremental LZF decoder; the format is described in pcd_lzf.h. */
#include "pcd_lzf.h"

#include <string.h>

enum {
    LZF_CTRL = 0,     /* next input byte is a control byte */
    LZF_LITERAL = 1,  /* `left` literal bytes follow in the input */
    LZF_REF_LEN = 2,  /* next input byte extends the reference length */
    LZF_REF_DIST = 3, /* next input byte is the low byte of the distance */
    LZF_REF_COPY = 4  /* `left` bytes to copy from `dist` back */
};

#define LZF_MASK (GDT_LZF_WINDOW - 1u)

void gdt_lzf_init(gdt_lzf_dec *d)
{
    memset(d, 0, sizeof *d);
    d->state = LZF_CTRL;
}

int gdt_lzf_at_item_boundary(const gdt_lzf_dec *d)
{
    return d->state == LZF_CTRL;
}

gdt_lzf_result gdt_lzf_decode(gdt_lzf_dec *d, const uint8_t *in, size_t in_len, size_t *in_used,
                              uint8_t *out, size_t out_cap, size_t *out_made)
{
    size_t used = 0, made = 0;
    gdt_lzf_result rc = GDT_LZF_OK;

    /* Invariant: every byte emitted goes to window[produced % WINDOW], so the
     * window always holds the last min(produced, WINDOW) output bytes. */
    while (made < out_cap) {
        if (d->state == LZF_REF_COPY) {
            size_t n = d->left;
            if (n > out_cap - made)
                n = out_cap - made;
            for (size_t k = 0; k < n; k++) {
                uint8_t b = d->window[(d->produced - d->dist) & LZF_MASK];
                d->window[d->produced & LZF_MASK] = b;
                d->produced++;
                if (out != NULL)
                    out[made + k] = b;
            }
            made += n;
            d->left -= (unsigned)n;
            if (d->left == 0)
                d->state = LZF_CTRL;
            continue;
        }
        if (used == in_len)
            break;
        switch (d->state) {
        case LZF_CTRL: {
            unsigned c = in[used++];
            if (c < 32) {
                d->left = c + 1;
                d->state = LZF_LITERAL;
            } else {
                d->ctrl = c;
                d->left = c >> 5;
                d->state = d->left == 7 ? LZF_REF_LEN : LZF_REF_DIST;
            }
            break;
        }
        case LZF_LITERAL: {
            size_t n = d->left;
            if (n > in_len - used)
                n = in_len - used;
            if (n > out_cap - made)
                n = out_cap - made;
            for (size_t k = 0; k < n; k++) {
                uint8_t b = in[used + k];
                d->window[d->produced & LZF_MASK] = b;
                d->produced++;
                if (out != NULL)
                    out[made + k] = b;
            }
            used += n;
            made += n;
            d->left -= (unsigned)n;
            if (d->left == 0)
                d->state = LZF_CTRL;
            break;
        }
        case LZF_REF_LEN:
            d->left += in[used++];
            d->state = LZF_REF_DIST;
            break;
        case LZF_REF_DIST:
            d->dist = ((d->ctrl & 31u) << 8) + in[used++] + 1u;
            d->left += 2;
            if ((uint64_t)d->dist > d->produced) {
                rc = GDT_LZF_BAD_REF;
                goto done;
            }
            d->state = LZF_REF_COPY;
            break;
        default: rc = GDT_LZF_BAD_REF; goto done;
        }
    }
done:
    *in_used = used;
    *out_made = made;
    return rc;
}
