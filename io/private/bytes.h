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

static inline uint32_t gdt_le_get_u32(const unsigned char *p)
{
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}

static inline uint64_t gdt_le_get_u64(const unsigned char *p)
{
    return (uint64_t)gdt_le_get_u32(p) | ((uint64_t)gdt_le_get_u32(p + 4) << 32);
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
    for (int i = 0; i < 4; i++)
        p[i] = (unsigned char)((v >> (8 * i)) & 0xffu);
}

static inline void gdt_le_put_u64(unsigned char *p, uint64_t v)
{
    for (int i = 0; i < 8; i++)
        p[i] = (unsigned char)((v >> (8 * i)) & 0xffu);
}

/* Stores d as IEEE 754 binary64. */
static inline void gdt_le_put_f64(unsigned char *p, double d)
{
    uint64_t bits;
    memcpy(&bits, &d, sizeof bits);
    gdt_le_put_u64(p, bits);
}

#endif
