/* num_text.h — the shortest round-trip text of a double, made with integer
 * arithmetic for the values a terrain mesh holds.
 *
 * The text formats write each number as the first of printf's "%.15g",
 * "%.16g", "%.17g" (C locale) that strtod reads back as the same double.
 * Those conversions cost about a microsecond each in the C library, three
 * of them and three strtod calls for most coordinates of a LAS file (whose
 * x = offset + scale * X is rarely the double nearest its short decimal),
 * which made a text mesh several times slower to write than the PLY.
 *
 * gdt_num_text makes the same bytes without the C library when
 * 1e-4 <= |d| < 1e14, where every one of those conversions is in fixed
 * notation ("%g" picks fixed when the decimal exponent X of the rounded
 * value has -4 <= X < precision):
 *   - for P = 15, 16, 17 in turn, the P-digit decimal N * 10^-s nearest to
 *     d (ties to even, as glibc's printf rounds in the default mode) is
 *     computed exactly: d = m 2^-k with m < 2^53 and k <= 66, s = P-1-X <=
 *     20, so m 10^s < 2^120 and N = round(m 10^s / 2^k) fits 128 bits;
 *   - N reads back as d exactly when it lies within half an ulp of d, the
 *     bounds included when m is even (strtod rounds to nearest, ties to
 *     even; below a power of two the gap is half as wide): compared as the
 *     integers N 2^(k+2) and (4m +- 2) 10^s (or 4m - 1), all below 2^126;
 *   - the text is N with a point s digits from the right, trailing zeros
 *     and a bare point removed, a '-' for a negative d.
 * It is tested against the C library's text for every class of value the
 * range holds (random bits, lattice values, powers and their neighbours).
 */
#ifndef GDT_NUM_TEXT_H
#define GDT_NUM_TEXT_H

#include <stddef.h>

/* Longest text gdt_num_text makes: '-', 17 digits, '.', 3 zeros after the
 * point ("0.000" of a value below 1e-3), and the terminating NUL. */
#define GDT_NUM_TEXT_MAX 24

/* Writes the text described above into out (at least GDT_NUM_TEXT_MAX
 * bytes, NUL-terminated).  returns its length, or 0 when d is outside
 * 1e-4 <= |d| < 1e14 (zero, tiny, huge, not finite): the caller then uses
 * the C library. */
size_t gdt_num_text(char *out, double d);

#endif
