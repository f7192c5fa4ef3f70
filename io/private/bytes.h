/* Little-endian byte access for the file formats (LAS, PCD, PLY), independent
 * of the host byte order.  Header-only.  Preconditions: p points to at least
 * as many bytes as the width of the value. */
#ifndef GDT_BYTES_H
#define GDT_BYTES_H

#include <stdint.h>
#include <string.h>

static inline uint16_t gdt_le_get_u16(const unsigned char *p)
{
    return (uint16_t)(p[0] | (p[1] << 8));
}

/* Whole-word loads and stores (memcpy, byte-swapped on big-endian hosts):
 * byte-by-byte loops are not always merged by the compiler, and the PLY
 * and tile writers store hundreds of millions of words. */
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__
#define GDT_LE32(v) __builtin_bswap32(v)
#define GDT_LE64(v) __builtin_bswap64(v)
#else
#define GDT_LE32(v) (v)
#define GDT_LE64(v) (v)
#endif

static inline uint32_t gdt_le_get_u32(const unsigned char *p)
{
    uint32_t v;
    memcpy(&v, p, sizeof v);
    return GDT_LE32(v);
}

static inline uint64_t gdt_le_get_u64(const unsigned char *p)
{
    uint64_t v;
    memcpy(&v, p, sizeof v);
    return GDT_LE64(v);
}

static inline int32_t gdt_le_get_i32(const unsigned char *p)
{
    uint32_t u = gdt_le_get_u32(p);
    /* Two's complement without implementation-defined conversions. */
    return u <= (uint32_t)INT32_MAX ? (int32_t)u
                                    : (int32_t)(u - (uint32_t)2147483648u) - INT32_MAX - 1;
}

/* The IEEE 754 binary64 value stored at p. */
static inline double gdt_le_get_f64(const unsigned char *p)
{
    uint64_t u = gdt_le_get_u64(p);
    double d;
    memcpy(&d, &u, sizeof d);
    return d;
}

static inline void gdt_le_put_u32(unsigned char *p, uint32_t v)
{
    v = GDT_LE32(v);
    memcpy(p, &v, sizeof v);
}

static inline void gdt_le_put_u64(unsigned char *p, uint64_t v)
{
    v = GDT_LE64(v);
    memcpy(p, &v, sizeof v);
}

/* Stores d as IEEE 754 binary64. */
static inline void gdt_le_put_f64(unsigned char *p, double d)
{
    uint64_t bits;
    memcpy(&bits, &d, sizeof bits);
    gdt_le_put_u64(p, bits);
}

#endif
