/* pcd_lzf.h — incremental LZF decoder (the compression of PCD binary_compressed).
 *
 * LZF stream format (as produced by liblzf and PCL's lzfCompress):
 * a sequence of items, each starting with a control byte c.
 *   c < 32        literal run: the next c + 1 input bytes are copied to the output.
 *   c >= 32       back-reference: len = c >> 5 (1..7); when len == 7 one more
 *                 byte is added to it; then one byte b; the reference copies
 *                 len + 2 bytes starting at distance ((c & 31) << 8) + b + 1
 *                 before the current output position (source and destination
 *                 may overlap: the copy runs byte by byte).
 * Hence a back-reference reaches at most 8192 bytes back and copies at most
 * 264 bytes; a literal item expands by at most 1 byte per 32 output bytes.
 *
 * The decoder is a byte-wise state machine: input may be fed in pieces of
 * any size (items may straddle pieces) and output may be taken in pieces of
 * any size, or discarded.  It keeps only the last 8192 output bytes, so its
 * memory is constant (sizeof(gdt_lzf_dec)), whatever the stream length.
 * It never reads or writes outside the buffers it is given, whatever the
 * input bytes: a reference reaching before the start of the output is
 * reported as corruption.
 */
#ifndef GDT_PCD_LZF_H
#define GDT_PCD_LZF_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define GDT_LZF_WINDOW 8192u /* power of two, >= the largest reference distance */

typedef enum gdt_lzf_result {
    GDT_LZF_OK = 0,     /* progress made or nothing to do; see the counts */
    GDT_LZF_BAD_REF = 1 /* reference distance beyond the bytes produced so far */
} gdt_lzf_result;

typedef struct gdt_lzf_dec {
    uint8_t window[GDT_LZF_WINDOW]; /* output byte k lives at window[k % GDT_LZF_WINDOW] */
    uint64_t produced;              /* output bytes produced (taken or discarded) so far */
    unsigned state;                 /* where the decoder is inside the current item */
    unsigned ctrl;                  /* control byte of the current back-reference */
    unsigned left;                  /* bytes still to copy in the current item */
    unsigned dist;                  /* distance of the current back-reference */
} gdt_lzf_dec;

/* Starts a new stream. */
void gdt_lzf_init(gdt_lzf_dec *d);

/* Decodes from in[0 .. in_len) into out[0 .. out_cap) (out == NULL discards
 * the bytes but still counts them and keeps them in the window).  Stops when
 * the input is used up or out_cap bytes were produced, whichever comes first.
 * *in_used and *out_made tell how far it went; they are set on error too.
 * returns: GDT_LZF_OK, or GDT_LZF_BAD_REF on a corrupt stream (the decoder
 * must then not be used any more). */
gdt_lzf_result gdt_lzf_decode(gdt_lzf_dec *d, const uint8_t *in, size_t in_len, size_t *in_used,
                              uint8_t *out, size_t out_cap, size_t *out_made);

/* 1 when the decoder stands between two items (a stream may end only there). */
int gdt_lzf_at_item_boundary(const gdt_lzf_dec *d);

#ifdef __cplusplus
}
#endif

#endif
