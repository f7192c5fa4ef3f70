/* laz10.c — pointwise LASzip chunks: the item decoders of point formats 0-5.
 *
 * Every item keeps the previous record's value of its fields and decodes
 * the next one from it.  Integers wrap as the encoder's 32/64-bit two's
 * complement arithmetic does (computed here in unsigned types).  Model
 * statistics restart with every chunk; the models keyed by a byte value
 * are reset lazily, on their first use in a chunk (an epoch per model), so
 * a short chunk does not pay for 768 models it never touches.
 */
#include "laz10.h"

#include <inttypes.h>
#include <stddef.h>
#include <stdlib.h>
#include <string.h>

#include "bytes.h"
#include "laz_arith.h"
#include "laz_median.h"

/* ---- byte access, wrapping arithmetic, keyed models ---- */

static inline void put_u16(unsigned char *p, uint32_t v)
{
    p[0] = (unsigned char)v;
    p[1] = (unsigned char)(v >> 8);
}

static inline uint32_t get_u16(const unsigned char *p)
{
    return gdt_le_get_u16(p);
}

static inline int32_t get_i32(const unsigned char *p)
{
    return gdt_laz_i32(gdt_le_get_u32(p));
}

static inline void put_i32(unsigned char *p, int32_t v)
{
    gdt_le_put_u32(p, (uint32_t)v);
}

/* a * b and a + b with 32-bit wrap-around. */
static inline int32_t mul32(int32_t a, int32_t b)
{
    return gdt_laz_i32((uint32_t)a * (uint32_t)b);
}

static inline int32_t add32(int32_t a, int32_t b)
{
    return gdt_laz_i32((uint32_t)a + (uint32_t)b);
}

static inline uint8_t clamp_u8(int32_t v)
{
    return v <= 0 ? 0 : v >= 255 ? 255 : (uint8_t)v;
}

/* Models keyed by the previous value of a byte, created on first use. */
typedef struct keyed256 {
    gdt_laz_symmodel m[256];
    uint64_t epoch[256]; /* chunk in which m[i] was last reset */
} keyed256;

static gdt_laz_symmodel *keyed_get(keyed256 *k, unsigned key, uint64_t epoch, int *oom)
{
    gdt_laz_symmodel *m = &k->m[key];
    if (k->epoch[key] != epoch) {
        if (!m->distribution && gdt_laz_symmodel_alloc(m, 256, NULL) != GDT_OK) {
            *oom = 1;
            return NULL;
        }
        gdt_laz_symmodel_init(m);
        k->epoch[key] = epoch;
    }
    return m;
}

/* Replaces the byte *v by the symbol its model decodes; 0, or -1 when the
 * model could not be allocated (*oom set). */
static inline int keyed_decode(keyed256 *k, uint32_t *v, gdt_laz_dec *d, uint64_t epoch, int *oom)
{
    gdt_laz_symmodel *m = keyed_get(k, *v, epoch, oom);
    if (!m)
        return -1;
    *v = gdt_laz_decode_symbol(d, m);
    return 0;
}

static void keyed_free(keyed256 *k)
{
    for (int i = 0; i < 256; i++)
        gdt_laz_symmodel_free(&k->m[i]);
}

/* One context model of an item's state: a symbol model of symbols
 * symbols, or (symbols 0) an integer decompressor of bits bits and contexts
 * contexts.  Each item lists its models once, in a table; they are
 * created, reset per chunk and freed by walking it. */
typedef struct model_spec {
    size_t off; /* of the model in the item's state */
    uint16_t symbols;
    uint8_t bits, contexts;
} model_spec;

#define SYM(type, field, n) {offsetof(type, field), n, 0, 0}
#define INT(type, field, b, c) {offsetof(type, field), 0, b, c}
#define NSPEC(a) ((unsigned)(sizeof(a) / sizeof(a)[0]))

static gdt_status models_new(void *s, const model_spec *spec, unsigned n, gdt_error *err)
{
    gdt_status st = GDT_OK;
    for (unsigned i = 0; i < n && st == GDT_OK; i++) {
        void *m = (unsigned char *)s + spec[i].off;
        st = spec[i].symbols ? gdt_laz_symmodel_alloc(m, spec[i].symbols, err)
                             : gdt_laz_intdec_new(m, spec[i].bits, spec[i].contexts, 8, 0, err);
    }
    return st;
}

/* Resets (release 0) or frees (release 1) the models of a state; freeing
 * also undoes a models_new that failed half-way: the state starts zeroed,
 * and a zeroed model frees as nothing. */
static void models_reset(void *s, const model_spec *spec, unsigned n, int release)
{
    for (unsigned i = 0; i < n; i++) {
        void *m = (unsigned char *)s + spec[i].off;
        if (spec[i].symbols)
            (release ? gdt_laz_symmodel_free : gdt_laz_symmodel_init)(m);
        else
            (release ? gdt_laz_intdec_free : gdt_laz_intdec_init)(m);
    }
}

/* Contexts of the return number r and the number of returns n (both 0-7):
 * the regular pairs 1 <= r <= n <= 5 get contexts 0-14, the others share
 * the rest; and the distance |n - r| as the level of a return. */
static const uint8_t RETURN_MAP[8][8] = {
    {15, 14, 13, 12, 11, 10, 9, 8},   {14, 0, 1, 3, 6, 10, 10, 9},
    {13, 1, 2, 4, 7, 11, 11, 10},     {12, 3, 4, 5, 8, 12, 12, 11},
    {11, 6, 7, 8, 9, 13, 13, 12},     {10, 10, 11, 12, 13, 14, 14, 13},
    {9, 10, 11, 12, 13, 14, 15, 14},  {8, 9, 10, 11, 12, 13, 14, 15}};

static inline unsigned return_level(unsigned n, unsigned r)
{
    return n > r ? n - r : r - n;
}

/* ---- POINT10 (20 bytes: X Y Z intensity flags class angle user psid) ---- */

typedef struct p10 {
    int32_t x, y, z;
    uint32_t intensity, flags, cls, angle, user, psid;
} p10;

static void p10_load(p10 *p, const unsigned char *b)
{
    p->x = get_i32(b);
    p->y = get_i32(b + 4);
    p->z = get_i32(b + 8);
    p->intensity = get_u16(b + 12);
    p->flags = b[14];
    p->cls = b[15];
    p->angle = b[16];
    p->user = b[17];
    p->psid = get_u16(b + 18);
}

static void p10_store(const p10 *p, unsigned char *b)
{
    put_i32(b, p->x);
    put_i32(b + 4, p->y);
    put_i32(b + 8, p->z);
    put_u16(b + 12, p->intensity);
    b[14] = (unsigned char)p->flags;
    b[15] = (unsigned char)p->cls;
    b[16] = (unsigned char)p->angle;
    b[17] = (unsigned char)p->user;
    put_u16(b + 18, p->psid);
}

typedef struct p10v2 {
    gdt_laz_symmodel changed;      /* 64: which fields changed */
    gdt_laz_symmodel angle[2];     /* by scan direction */
    gdt_laz_intdec intensity, psid, dx, dy, z;
    keyed256 flags, cls, user;
    gdt_laz_median5 mx[16], my[16];
    uint32_t last_intensity[16];
    int32_t last_height[8];
    p10 last;
} p10v2;

static const model_spec P10V2_MODELS[] = {
    SYM(p10v2, changed, 64),        SYM(p10v2, angle[0], 256),     SYM(p10v2, angle[1], 256),
    INT(p10v2, intensity, 16, 4),   INT(p10v2, psid, 16, 1),       INT(p10v2, dx, 32, 2),
    INT(p10v2, dy, 32, 22),         INT(p10v2, z, 32, 20)};

static void p10v2_init(p10v2 *s, const unsigned char *raw)
{
    for (int i = 0; i < 16; i++) {
        gdt_laz_median5_init(&s->mx[i]);
        gdt_laz_median5_init(&s->my[i]);
        s->last_intensity[i] = 0;
    }
    memset(s->last_height, 0, sizeof s->last_height);
    p10_load(&s->last, raw);
    s->last.intensity = 0; /* intensity is predicted by last_intensity only */
}

static void p10v2_read(p10v2 *s, gdt_laz_dec *d, unsigned char *out, uint64_t epoch, int *oom)
{
    p10 *p = &s->last;
    uint32_t changed = gdt_laz_decode_symbol(d, &s->changed);
    unsigned r, n, m, l, k;
    int32_t diff;

    if ((changed & 32) && keyed_decode(&s->flags, &p->flags, d, epoch, oom) != 0)
        return;
    r = p->flags & 7;
    n = (p->flags >> 3) & 7;
    m = RETURN_MAP[n][r];
    l = return_level(n, r);
    if (changed & 16) {
        p->intensity = (uint16_t)gdt_laz_intdec_decode(&s->intensity, d,
                                                       (int32_t)s->last_intensity[m],
                                                       m < 3 ? m : 3);
        s->last_intensity[m] = p->intensity;
    } else {
        p->intensity = s->last_intensity[m];
    }
    if ((changed & 8) && keyed_decode(&s->cls, &p->cls, d, epoch, oom) != 0)
        return;
    if (changed & 4)
        p->angle = (gdt_laz_decode_symbol(d, &s->angle[(p->flags >> 6) & 1]) + p->angle) & 0xFF;
    if ((changed & 2) && keyed_decode(&s->user, &p->user, d, epoch, oom) != 0)
        return;
    if (changed & 1)
        p->psid = (uint16_t)gdt_laz_intdec_decode(&s->psid, d, (int32_t)p->psid, 0);

    diff = gdt_laz_intdec_decode(&s->dx, d, s->mx[m].v[2], n == 1);
    p->x = add32(p->x, diff);
    gdt_laz_median5_add(&s->mx[m], diff);
    k = gdt_laz_intdec_k(&s->dx);
    diff = gdt_laz_intdec_decode(&s->dy, d, s->my[m].v[2], (n == 1) + (k < 20 ? k & ~1u : 20));
    p->y = add32(p->y, diff);
    gdt_laz_median5_add(&s->my[m], diff);
    k = (gdt_laz_intdec_k(&s->dx) + gdt_laz_intdec_k(&s->dy)) / 2;
    p->z = gdt_laz_intdec_decode(&s->z, d, s->last_height[l], (n == 1) + (k < 18 ? k & ~1u : 18));
    s->last_height[l] = p->z;
    p10_store(p, out);
}

typedef struct p10v1 {
    gdt_laz_symmodel changed;
    gdt_laz_intdec dx, dy, z, intensity, angle, psid;
    keyed256 flags, cls, user;
    int32_t last_dx[3], last_dy[3];
    unsigned last_incr;
    p10 last;
} p10v1;

static const model_spec P10V1_MODELS[] = {
    SYM(p10v1, changed, 64),      INT(p10v1, dx, 32, 1),     INT(p10v1, dy, 32, 20),
    INT(p10v1, z, 32, 20),        INT(p10v1, intensity, 16, 1), INT(p10v1, angle, 8, 2),
    INT(p10v1, psid, 16, 1)};

static void p10v1_init(p10v1 *s, const unsigned char *raw)
{
    memset(s->last_dx, 0, sizeof s->last_dx);
    memset(s->last_dy, 0, sizeof s->last_dy);
    s->last_incr = 0;
    p10_load(&s->last, raw);
}

/* The median of three. */
static inline int32_t median3(const int32_t *v)
{
    if (v[0] < v[1])
        return v[1] < v[2] ? v[1] : v[0] < v[2] ? v[2] : v[0];
    return v[0] < v[2] ? v[0] : v[1] < v[2] ? v[2] : v[1];
}

static void p10v1_read(p10v1 *s, gdt_laz_dec *d, unsigned char *out, uint64_t epoch, int *oom)
{
    p10 *p = &s->last;
    int32_t dx, dy;
    uint32_t k, changed;

    dx = gdt_laz_intdec_decode(&s->dx, d, median3(s->last_dx), 0);
    p->x = add32(p->x, dx);
    k = gdt_laz_intdec_k(&s->dx);
    dy = gdt_laz_intdec_decode(&s->dy, d, median3(s->last_dy), k < 19 ? k : 19);
    p->y = add32(p->y, dy);
    k = (k + gdt_laz_intdec_k(&s->dy)) / 2;
    p->z = gdt_laz_intdec_decode(&s->z, d, p->z, k < 19 ? k : 19);
    changed = gdt_laz_decode_symbol(d, &s->changed);
    if (changed & 32)
        p->intensity = (uint16_t)gdt_laz_intdec_decode(&s->intensity, d, (int32_t)p->intensity, 0);
    if ((changed & 16) && keyed_decode(&s->flags, &p->flags, d, epoch, oom) != 0)
        return;
    if ((changed & 8) && keyed_decode(&s->cls, &p->cls, d, epoch, oom) != 0)
        return;
    if (changed & 4)
        p->angle = (uint8_t)gdt_laz_intdec_decode(&s->angle, d, (int32_t)p->angle, k < 3);
    if ((changed & 2) && keyed_decode(&s->user, &p->user, d, epoch, oom) != 0)
        return;
    if (changed & 1)
        p->psid = (uint16_t)gdt_laz_intdec_decode(&s->psid, d, (int32_t)p->psid, 0);
    s->last_dx[s->last_incr] = dx;
    s->last_dy[s->last_incr] = dy;
    s->last_incr = s->last_incr == 2 ? 0 : s->last_incr + 1;
    p10_store(p, out);
}

/* ---- GPSTIME11 (8 bytes: the double's bits, coded as an int64) ---- */

enum {
    GPS_MULTI = 500,
    GPS_MULTI_MINUS = -10,
    GPS_UNCHANGED = GPS_MULTI - GPS_MULTI_MINUS + 1, /* 511 */
    GPS_CODE_FULL = GPS_MULTI - GPS_MULTI_MINUS + 2, /* 512 */
    GPS_TOTAL = GPS_MULTI - GPS_MULTI_MINUS + 6      /* 516 */
};

typedef struct gpsv2 {
    gdt_laz_symmodel multi, zero_diff;
    gdt_laz_intdec ic;
    unsigned last, next;      /* of four interleaved sequences */
    uint64_t time[4];
    int32_t diff[4];
    int32_t extreme[4];
} gpsv2;

static const model_spec GPSV2_MODELS[] = {
    SYM(gpsv2, multi, GPS_TOTAL), SYM(gpsv2, zero_diff, 6), INT(gpsv2, ic, 32, 9)};

static void gpsv2_init(gpsv2 *s, const unsigned char *raw)
{
    s->last = s->next = 0;
    memset(s->diff, 0, sizeof s->diff);
    memset(s->extreme, 0, sizeof s->extreme);
    s->time[0] = gdt_le_get_u64(raw);
    s->time[1] = s->time[2] = s->time[3] = 0;
}

/* A new sequence whose high word is predicted by the current one's. */
static void gpsv2_full(gpsv2 *s, gdt_laz_dec *d)
{
    uint32_t hi;
    s->next = (s->next + 1) & 3;
    hi = (uint32_t)gdt_laz_intdec_decode(&s->ic, d, gdt_laz_i32((uint32_t)(s->time[s->last] >> 32)),
                                         8);
    s->time[s->next] = ((uint64_t)hi << 32) | gdt_laz_read_int(d);
    s->last = s->next;
    s->diff[s->last] = 0;
    s->extreme[s->last] = 0;
}

/* A difference of an extreme multiple replaces the prediction after
 * repeating more than three times. */
static inline void gpsv2_extreme(gpsv2 *s, int32_t diff)
{
    if (++s->extreme[s->last] > 3) {
        s->diff[s->last] = diff;
        s->extreme[s->last] = 0;
    }
}

static void gpsv2_read(gpsv2 *s, gdt_laz_dec *d, unsigned char *out)
{
    /* An encoder switches sequence at most once per record; more switches
     * are a corrupt stream. */
    for (int switches = 0;; switches++) {
        uint32_t multi;
        if (switches > 1) {
            d->bad |= GDT_LAZ_DEC_CORRUPT;
            break;
        }
        if (s->diff[s->last] == 0) {
            multi = gdt_laz_decode_symbol(d, &s->zero_diff);
            if (multi == 1) {
                int32_t diff = gdt_laz_intdec_decode(&s->ic, d, 0, 0);
                s->diff[s->last] = diff;
                s->time[s->last] += (uint64_t)(int64_t)diff;
                s->extreme[s->last] = 0;
            } else if (multi == 2) {
                gpsv2_full(s, d);
            } else if (multi > 2) {
                s->last = (s->last + multi - 2) & 3;
                continue;
            }
            break;
        }
        multi = gdt_laz_decode_symbol(d, &s->multi);
        if (multi == 1) {
            s->time[s->last] +=
                (uint64_t)(int64_t)gdt_laz_intdec_decode(&s->ic, d, s->diff[s->last], 1);
            s->extreme[s->last] = 0;
        } else if (multi < GPS_UNCHANGED) {
            int32_t diff, last = s->diff[s->last];
            if (multi == 0) {
                diff = gdt_laz_intdec_decode(&s->ic, d, 0, 7);
                gpsv2_extreme(s, diff);
            } else if (multi < GPS_MULTI) {
                diff = gdt_laz_intdec_decode(&s->ic, d, mul32((int32_t)multi, last),
                                             multi < 10 ? 2 : 3);
            } else if (multi == GPS_MULTI) {
                diff = gdt_laz_intdec_decode(&s->ic, d, mul32(GPS_MULTI, last), 4);
                gpsv2_extreme(s, diff);
            } else {
                int32_t neg = GPS_MULTI - (int32_t)multi; /* -1 .. -10 */
                if (neg > GPS_MULTI_MINUS) {
                    diff = gdt_laz_intdec_decode(&s->ic, d, mul32(neg, last), 5);
                } else {
                    diff = gdt_laz_intdec_decode(&s->ic, d, mul32(GPS_MULTI_MINUS, last), 6);
                    gpsv2_extreme(s, diff);
                }
            }
            s->time[s->last] += (uint64_t)(int64_t)diff;
        } else if (multi == GPS_CODE_FULL) {
            gpsv2_full(s, d);
        } else if (multi > GPS_CODE_FULL) {
            s->last = (s->last + multi - GPS_CODE_FULL) & 3;
            continue;
        }
        break;
    }
    gdt_le_put_u64(out, s->time[s->last]);
}

enum { GPS1_MULTIMAX = 512 };

typedef struct gpsv1 {
    gdt_laz_symmodel multi, zero_diff;
    gdt_laz_intdec ic;
    uint64_t time;
    int32_t diff, extreme;
} gpsv1;

static const model_spec GPSV1_MODELS[] = {
    SYM(gpsv1, multi, GPS1_MULTIMAX), SYM(gpsv1, zero_diff, 3), INT(gpsv1, ic, 32, 6)};

static void gpsv1_init(gpsv1 *s, const unsigned char *raw)
{
    s->diff = s->extreme = 0;
    s->time = gdt_le_get_u64(raw);
}

static void gpsv1_read(gpsv1 *s, gdt_laz_dec *d, unsigned char *out)
{
    uint32_t multi;
    if (s->diff == 0) {
        multi = gdt_laz_decode_symbol(d, &s->zero_diff);
        if (multi == 1) {
            s->diff = gdt_laz_intdec_decode(&s->ic, d, 0, 0);
            s->time += (uint64_t)(int64_t)s->diff;
        } else if (multi == 2) {
            s->time = gdt_laz_read_int64(d);
        }
    } else {
        multi = gdt_laz_decode_symbol(d, &s->multi);
        if (multi < GPS1_MULTIMAX - 2) {
            int32_t diff;
            if (multi == 1) {
                diff = gdt_laz_intdec_decode(&s->ic, d, s->diff, 1);
                s->diff = diff;
                s->extreme = 0;
            } else if (multi == 0) {
                diff = gdt_laz_intdec_decode(&s->ic, d, s->diff / 4, 2);
                if (++s->extreme > 3) {
                    s->diff = diff;
                    s->extreme = 0;
                }
            } else {
                diff = gdt_laz_intdec_decode(&s->ic, d, mul32((int32_t)multi, s->diff),
                                             multi < 10 ? 3 : multi < 50 ? 4 : 5);
                if (multi == GPS1_MULTIMAX - 3 && ++s->extreme > 3) {
                    s->diff = diff;
                    s->extreme = 0;
                }
            }
            s->time += (uint64_t)(int64_t)diff;
        } else if (multi < GPS1_MULTIMAX - 1) {
            s->time = gdt_laz_read_int64(d);
        }
    }
    gdt_le_put_u64(out, s->time);
}

/* ---- RGB12 (6 bytes: R G B as u16) ---- */

typedef struct rgbv2 {
    gdt_laz_symmodel used, diff[6];
    uint32_t last[3];
} rgbv2;

static const model_spec RGBV2_MODELS[] = {
    SYM(rgbv2, used, 128),    SYM(rgbv2, diff[0], 256), SYM(rgbv2, diff[1], 256),
    SYM(rgbv2, diff[2], 256), SYM(rgbv2, diff[3], 256), SYM(rgbv2, diff[4], 256),
    SYM(rgbv2, diff[5], 256)};

static void rgbv2_init(rgbv2 *s, const unsigned char *raw)
{
    for (int i = 0; i < 3; i++)
        s->last[i] = get_u16(raw + 2 * i);
}

static void rgbv2_read(rgbv2 *s, gdt_laz_dec *d, unsigned char *out)
{
    const uint32_t *l = s->last;
    uint32_t sym = gdt_laz_decode_symbol(d, &s->used), c[3];
    int32_t diff;

    c[0] = sym & 1 ? (gdt_laz_decode_symbol(d, &s->diff[0]) + (l[0] & 0xFF)) & 0xFF : l[0] & 0xFF;
    c[0] |= sym & 2 ? ((gdt_laz_decode_symbol(d, &s->diff[1]) + (l[0] >> 8)) & 0xFF) << 8
                    : l[0] & 0xFF00;
    if (sym & 64) {
        /* Green and blue are predicted by red's change. */
        diff = (int32_t)(c[0] & 0xFF) - (int32_t)(l[0] & 0xFF);
        if (sym & 4)
            c[1] = (gdt_laz_decode_symbol(d, &s->diff[2]) +
                    clamp_u8(diff + (int32_t)(l[1] & 0xFF))) & 0xFF;
        else
            c[1] = l[1] & 0xFF;
        if (sym & 16) {
            diff = (diff + ((int32_t)(c[1] & 0xFF) - (int32_t)(l[1] & 0xFF))) / 2;
            c[2] = (gdt_laz_decode_symbol(d, &s->diff[4]) +
                    clamp_u8(diff + (int32_t)(l[2] & 0xFF))) & 0xFF;
        } else {
            c[2] = l[2] & 0xFF;
        }
        diff = (int32_t)(c[0] >> 8) - (int32_t)(l[0] >> 8);
        if (sym & 8)
            c[1] |= ((gdt_laz_decode_symbol(d, &s->diff[3]) +
                      clamp_u8(diff + (int32_t)(l[1] >> 8))) & 0xFF) << 8;
        else
            c[1] |= l[1] & 0xFF00;
        if (sym & 32) {
            diff = (diff + ((int32_t)(c[1] >> 8) - (int32_t)(l[1] >> 8))) / 2;
            c[2] |= ((gdt_laz_decode_symbol(d, &s->diff[5]) +
                      clamp_u8(diff + (int32_t)(l[2] >> 8))) & 0xFF) << 8;
        } else {
            c[2] |= l[2] & 0xFF00;
        }
    } else {
        c[1] = c[2] = c[0];
    }
    for (int i = 0; i < 3; i++) {
        s->last[i] = c[i];
        put_u16(out + 2 * i, c[i]);
    }
}

typedef struct rgbv1 {
    gdt_laz_symmodel used;
    gdt_laz_intdec ic;
    uint32_t last[3];
} rgbv1;

static const model_spec RGBV1_MODELS[] = {SYM(rgbv1, used, 64), INT(rgbv1, ic, 8, 6)};

static void rgbv1_init(rgbv1 *s, const unsigned char *raw)
{
    for (int i = 0; i < 3; i++)
        s->last[i] = get_u16(raw + 2 * i);
}

static void rgbv1_read(rgbv1 *s, gdt_laz_dec *d, unsigned char *out)
{
    uint32_t sym = gdt_laz_decode_symbol(d, &s->used);
    for (unsigned i = 0; i < 3; i++) {
        uint32_t lo = s->last[i] & 0xFF, hi = s->last[i] >> 8;
        if (sym & (1u << (2 * i)))
            lo = (uint32_t)gdt_laz_intdec_decode(&s->ic, d, (int32_t)lo, 2 * i) & 0xFF;
        if (sym & (2u << (2 * i)))
            hi = (uint32_t)gdt_laz_intdec_decode(&s->ic, d, (int32_t)hi, 2 * i + 1) & 0xFF;
        s->last[i] = lo | hi << 8;
        put_u16(out + 2 * i, s->last[i]);
    }
}

/* ---- WAVEPACKET13 (29 bytes: descriptor index, u64 offset, u32 size,
 * f32 return point, f32 dx dy dz; the floats coded as their bits) ---- */

typedef struct wave {
    gdt_laz_symmodel index, offset_diff[4];
    gdt_laz_intdec offset, size, rpoint, xyz;
    int32_t last_diff;
    uint32_t last_sym;
    uint64_t off;
    int32_t psize, rp, x, y, z;
} wave;

static const model_spec WAVE_MODELS[] = {
    SYM(wave, index, 256),          SYM(wave, offset_diff[0], 4), SYM(wave, offset_diff[1], 4),
    SYM(wave, offset_diff[2], 4),   SYM(wave, offset_diff[3], 4), INT(wave, offset, 32, 1),
    INT(wave, size, 32, 1),         INT(wave, rpoint, 32, 1),     INT(wave, xyz, 32, 3)};

static void wave_init(wave *s, const unsigned char *raw)
{
    s->last_diff = 0;
    s->last_sym = 0;
    s->off = gdt_le_get_u64(raw + 1);
    s->psize = get_i32(raw + 9);
    s->rp = get_i32(raw + 13);
    s->x = get_i32(raw + 17);
    s->y = get_i32(raw + 21);
    s->z = get_i32(raw + 25);
}

static void wave_read(wave *s, gdt_laz_dec *d, unsigned char *out)
{
    out[0] = (unsigned char)gdt_laz_decode_symbol(d, &s->index);
    s->last_sym = gdt_laz_decode_symbol(d, &s->offset_diff[s->last_sym]);
    switch (s->last_sym) {
    case 0:
        break;
    case 1:
        s->off += (uint32_t)s->psize;
        break;
    case 2:
        s->last_diff = gdt_laz_intdec_decode(&s->offset, d, s->last_diff, 0);
        s->off += (uint64_t)(int64_t)s->last_diff;
        break;
    default:
        s->off = gdt_laz_read_int64(d);
        break;
    }
    s->psize = gdt_laz_intdec_decode(&s->size, d, s->psize, 0);
    s->rp = gdt_laz_intdec_decode(&s->rpoint, d, s->rp, 0);
    s->x = gdt_laz_intdec_decode(&s->xyz, d, s->x, 0);
    s->y = gdt_laz_intdec_decode(&s->xyz, d, s->y, 1);
    s->z = gdt_laz_intdec_decode(&s->xyz, d, s->z, 2);
    gdt_le_put_u64(out + 1, s->off);
    put_i32(out + 9, s->psize);
    put_i32(out + 13, s->rp);
    put_i32(out + 17, s->x);
    put_i32(out + 21, s->y);
    put_i32(out + 25, s->z);
}

/* ---- BYTE (extra bytes) ---- */

typedef struct bytes_item {
    unsigned n;
    gdt_laz_symmodel *m;   /* v2: n models of 256 symbols */
    gdt_laz_intdec ic;     /* v1: 8 bits, n contexts */
    unsigned char *last;
} bytes_item;

static gdt_status bytes_new(bytes_item *s, unsigned n, unsigned version, gdt_error *err)
{
    gdt_status st;
    s->n = n;
    s->last = malloc(n);
    if (!s->last)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    if (version == 1)
        return gdt_laz_intdec_new(&s->ic, 8, n, 8, 0, err);
    s->m = calloc(n, sizeof *s->m);
    if (!s->m)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    for (unsigned i = 0; i < n; i++)
        if ((st = gdt_laz_symmodel_alloc(&s->m[i], 256, err)) != GDT_OK)
            return st;
    return GDT_OK;
}

static void bytes_free(bytes_item *s)
{
    if (s->m)
        for (unsigned i = 0; i < s->n; i++)
            gdt_laz_symmodel_free(&s->m[i]);
    free(s->m);
    gdt_laz_intdec_free(&s->ic);
    free(s->last);
}

static void bytes_init(bytes_item *s, const unsigned char *raw)
{
    if (s->m)
        for (unsigned i = 0; i < s->n; i++)
            gdt_laz_symmodel_init(&s->m[i]);
    else
        gdt_laz_intdec_init(&s->ic);
    memcpy(s->last, raw, s->n);
}

static void bytesv2_read(bytes_item *s, gdt_laz_dec *d, unsigned char *out)
{
    for (unsigned i = 0; i < s->n; i++)
        out[i] = s->last[i] = (unsigned char)(s->last[i] + gdt_laz_decode_symbol(d, &s->m[i]));
}

static void bytesv1_read(bytes_item *s, gdt_laz_dec *d, unsigned char *out)
{
    for (unsigned i = 0; i < s->n; i++)
        out[i] = s->last[i] =
            (unsigned char)gdt_laz_intdec_decode(&s->ic, d, (int32_t)s->last[i], i);
}

/* ---- the plan ---- */

enum kind { K_P10V1, K_P10V2, K_GPSV1, K_GPSV2, K_RGBV1, K_RGBV2, K_WAVE, K_BYTEV1, K_BYTEV2 };

typedef struct plan_item {
    enum kind kind;
    unsigned off;             /* of the item in the record */
    void *s;                  /* the state, of the kind's type */
    const model_spec *models; /* of the state (bytes: none, their own) */
    unsigned nmodels;
} plan_item;

struct gdt_laz10 {
    unsigned record_length, nitems;
    plan_item items[GDT_LAZ_MAX_ITEMS];
    gdt_laz_dec dec;
    unsigned char *raw;     /* the chunk's first record */
    uint64_t npoints, next; /* of the chunk: points, the next to read */
    uint64_t epoch;         /* chunks started, for the keyed models */
    size_t raw_used;        /* record_length once started */
    const char *path;
    uint64_t chunk_index;
};

static void item_free(plan_item *it)
{
    if (!it->s)
        return;
    models_reset(it->s, it->models, it->nmodels, 1);
    switch (it->kind) {
    case K_P10V1: {
        p10v1 *p = it->s;
        keyed_free(&p->flags);
        keyed_free(&p->cls);
        keyed_free(&p->user);
    } break;
    case K_P10V2: {
        p10v2 *p = it->s;
        keyed_free(&p->flags);
        keyed_free(&p->cls);
        keyed_free(&p->user);
    } break;
    case K_BYTEV1:
    case K_BYTEV2: bytes_free(it->s); break;
    default: break;
    }
    free(it->s);
    it->s = NULL;
}

void gdt_laz10_free(gdt_laz10 *z)
{
    if (!z)
        return;
    for (unsigned i = 0; i < z->nitems; i++)
        item_free(&z->items[i]);
    free(z->raw);
    free(z);
}

/* The kind, state size and models of each pointwise item coding. */
static const struct item_kind {
    uint16_t type, version;
    enum kind kind;
    size_t size;
    const model_spec *models;
    unsigned nmodels;
} KINDS[] = {
    {GDT_LAZ_POINT10, 1, K_P10V1, sizeof(p10v1), P10V1_MODELS, NSPEC(P10V1_MODELS)},
    {GDT_LAZ_POINT10, 2, K_P10V2, sizeof(p10v2), P10V2_MODELS, NSPEC(P10V2_MODELS)},
    {GDT_LAZ_GPSTIME11, 1, K_GPSV1, sizeof(gpsv1), GPSV1_MODELS, NSPEC(GPSV1_MODELS)},
    {GDT_LAZ_GPSTIME11, 2, K_GPSV2, sizeof(gpsv2), GPSV2_MODELS, NSPEC(GPSV2_MODELS)},
    {GDT_LAZ_RGB12, 1, K_RGBV1, sizeof(rgbv1), RGBV1_MODELS, NSPEC(RGBV1_MODELS)},
    {GDT_LAZ_RGB12, 2, K_RGBV2, sizeof(rgbv2), RGBV2_MODELS, NSPEC(RGBV2_MODELS)},
    /* WAVEPACKET13 has one coding under both version numbers. */
    {GDT_LAZ_WAVEPACKET13, 1, K_WAVE, sizeof(wave), WAVE_MODELS, NSPEC(WAVE_MODELS)},
    {GDT_LAZ_WAVEPACKET13, 2, K_WAVE, sizeof(wave), WAVE_MODELS, NSPEC(WAVE_MODELS)},
    /* The extra bytes have as many models as bytes: bytes_new. */
    {GDT_LAZ_BYTE, 1, K_BYTEV1, sizeof(bytes_item), NULL, 0},
    {GDT_LAZ_BYTE, 2, K_BYTEV2, sizeof(bytes_item), NULL, 0},
};

gdt_status gdt_laz10_new(gdt_laz10 **out, const gdt_laz_vlr *vlr, unsigned record_length,
                         gdt_error *err)
{
    gdt_laz10 *z = calloc(1, sizeof *z);
    gdt_status st = GDT_OK;
    unsigned off = 0;

    *out = NULL;
    if (!z || !(z->raw = malloc(record_length ? record_length : 1))) {
        free(z);
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    }
    z->record_length = record_length;
    for (unsigned i = 0; i < vlr->nitems && st == GDT_OK; i++) {
        const gdt_laz_item *vi = &vlr->items[i];
        plan_item *it = &z->items[z->nitems];
        const struct item_kind *k = NULL;

        for (unsigned j = 0; j < sizeof KINDS / sizeof KINDS[0] && !k; j++)
            if (KINDS[j].type == vi->type && KINDS[j].version == vi->version)
                k = &KINDS[j];
        if (!k) {
            st = gdt_error_set(err, GDT_EINPUT, 3923,
                               "LASzip item type %u version %u is not a pointwise item",
                               (unsigned)vi->type, (unsigned)vi->version);
            break;
        }
        it->kind = k->kind;
        it->models = k->models;
        it->nmodels = k->nmodels;
        it->off = off;
        off += vi->size;
        if (!(it->s = calloc(1, k->size))) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
            break;
        }
        z->nitems++;
        if (it->kind == K_BYTEV1 || it->kind == K_BYTEV2)
            st = bytes_new(it->s, vi->size, vi->version, err);
        else
            st = models_new(it->s, it->models, it->nmodels, err);
    }
    if (st == GDT_OK && off != record_length)
        st = gdt_error_set(err, GDT_EINPUT, 3923,
                           "LASzip items cover %u bytes of records of %u", off, record_length);
    if (st != GDT_OK) {
        gdt_laz10_free(z);
        return st;
    }
    *out = z;
    return GDT_OK;
}

gdt_status gdt_laz10_start(gdt_laz10 *z, const unsigned char *data, size_t avail,
                           uint64_t npoints, const char *path, uint64_t chunk_index,
                           gdt_error *err)
{
    z->path = path;
    z->chunk_index = chunk_index;
    z->npoints = 0; /* no point to read until the chunk has started */
    z->next = 0;
    z->epoch++;
    z->raw_used = 0;
    gdt_laz_dec_init(&z->dec, NULL, 0);
    if (avail < z->record_length)
        return gdt_error_set(err, GDT_EINPUT, 3922,
                             "%s: LAZ chunk %" PRIu64 " of %zu bytes is shorter than its first "
                             "record (%u bytes)",
                             path, chunk_index, avail, z->record_length);
    memcpy(z->raw, data, z->record_length);
    z->raw_used = z->record_length;
    z->npoints = npoints;
    for (unsigned i = 0; i < z->nitems; i++) {
        plan_item *it = &z->items[i];
        const unsigned char *r = data + it->off;
        models_reset(it->s, it->models, it->nmodels, 0);
        switch (it->kind) {
        case K_P10V1: p10v1_init(it->s, r); break;
        case K_P10V2: p10v2_init(it->s, r); break;
        case K_GPSV1: gpsv1_init(it->s, r); break;
        case K_GPSV2: gpsv2_init(it->s, r); break;
        case K_RGBV1: rgbv1_init(it->s, r); break;
        case K_RGBV2: rgbv2_init(it->s, r); break;
        case K_WAVE: wave_init(it->s, r); break;
        case K_BYTEV1:
        case K_BYTEV2: bytes_init(it->s, r); break;
        }
    }
    /* The coder starts right after the raw record, even for a chunk of one
     * point (the encoder flushes its 4 bytes there too). */
    gdt_laz_dec_init(&z->dec, data + z->record_length, avail - z->record_length);
    return GDT_OK;
}

static gdt_status stream_error(const gdt_laz10 *z, uint64_t point, gdt_error *err)
{
    if (z->dec.bad & GDT_LAZ_DEC_OVERRUN)
        return gdt_error_set(err, GDT_EINPUT, 3920,
                             "%s: LAZ chunk %" PRIu64 " is truncated: point %" PRIu64 " of %" PRIu64
                             " needs bytes past its %zu bytes",
                             z->path, z->chunk_index, point, z->npoints,
                             z->raw_used + (size_t)(z->dec.end - z->dec.start));
    return gdt_error_set(err, GDT_EINPUT, 3921,
                         "%s: LAZ chunk %" PRIu64 " is corrupt at point %" PRIu64 " of %" PRIu64,
                         z->path, z->chunk_index, point, z->npoints);
}

gdt_status gdt_laz10_read(gdt_laz10 *z, unsigned char *records, size_t n, gdt_error *err)
{
    const unsigned rl = z->record_length;
    int oom = 0;

    if (n > z->npoints - z->next)
        return gdt_error_set(err, GDT_EINTERNAL, 7391,
                             "LAZ chunk %" PRIu64 ": %zu points asked, %" PRIu64 " left",
                             z->chunk_index, n, z->npoints - z->next);
    if (n > 0 && z->next == 0) {
        if (z->dec.bad & GDT_LAZ_DEC_CORRUPT)
            return stream_error(z, 0, err);
        memcpy(records, z->raw, rl);
        records += rl;
        n--;
        z->next = 1;
    }
    for (size_t j = 0; j < n; j++, records += rl) {
        for (unsigned i = 0; i < z->nitems; i++) {
            plan_item *it = &z->items[i];
            unsigned char *out = records + it->off;
            switch (it->kind) {
            case K_P10V1: p10v1_read(it->s, &z->dec, out, z->epoch, &oom); break;
            case K_P10V2: p10v2_read(it->s, &z->dec, out, z->epoch, &oom); break;
            case K_GPSV1: gpsv1_read(it->s, &z->dec, out); break;
            case K_GPSV2: gpsv2_read(it->s, &z->dec, out); break;
            case K_RGBV1: rgbv1_read(it->s, &z->dec, out); break;
            case K_RGBV2: rgbv2_read(it->s, &z->dec, out); break;
            case K_WAVE: wave_read(it->s, &z->dec, out); break;
            case K_BYTEV1: bytesv1_read(it->s, &z->dec, out); break;
            case K_BYTEV2: bytesv2_read(it->s, &z->dec, out); break;
            }
        }
        if (oom)
            return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        if (z->dec.bad)
            return stream_error(z, z->next, err);
        z->next++;
    }
    return GDT_OK;
}

size_t gdt_laz10_used(const gdt_laz10 *z)
{
    return z->raw_used + gdt_laz_dec_used(&z->dec);
}
