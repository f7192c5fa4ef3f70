/* laz14.c — layered LASzip chunks: POINT14 and the items that follow it.
 *
 * design: one arithmetic decoder per layer, all reading from the caller's
 * chunk bytes.  Each item keeps four scanner-channel contexts; a context is
 * initialised (models reset, last values copied from the point the stream
 * had reached) the first time a chunk uses its channel.  A context's
 * generation equals the decoder's chunk generation exactly when it is in
 * use in the current chunk, so starting a chunk resets nothing but the
 * first channel's context.  The models a context creates only on demand
 * (per classification, per flags, per user data, per return count) carry
 * their own generation and are reset on their first use in a chunk, which
 * is what the encoder does when it creates them.
 *
 * Selective decoding: a layer is decoded when the need mask asks for its
 * field group (xyz: the changed-values layer, which also carries X, Y and
 * the returns, and Z; class: classification; flags: the returns and the
 * flags layer; any other bit: every other layer and item).  The
 * changed-values layer is always decoded: every other layer's contexts
 * depend on it.  No other layer depends on one another, so skipping one
 * changes nothing in the rest.
 */
#include "laz14.h"

#include <inttypes.h>
#include <stdlib.h>
#include <string.h>

#include "bytes.h"
#include "laz_arith.h"
#include "laz_median.h"

#define NCTX 4 /* scanner channels */

/* Layers of POINT14, in stream order. */
enum {
    L_XY,
    L_Z,
    L_CLASS,
    L_FLAGS,
    L_INTENSITY,
    L_SCAN_ANGLE,
    L_USER_DATA,
    L_POINT_SOURCE,
    L_GPS_TIME,
    L_P14
};

static const char *const p14_layer_name[L_P14] = {
    "changed values", "Z",         "classification", "flags",   "intensity",
    "scan angle",     "user data", "point source",   "GPS time"};

/* The GPS time coding: multipliers of the last difference up to 500, down
 * to -10, a code for a full 64-bit time and codes to switch among the four
 * time sequences. */
#define GPS_MULTI 500
#define GPS_MULTI_MINUS (-10)
#define GPS_CODE_FULL (GPS_MULTI - GPS_MULTI_MINUS + 1)
#define GPS_SYMBOLS (GPS_MULTI - GPS_MULTI_MINUS + 5)

/* Return map of (number of returns, return number) to one of 6 contexts:
 * row n, column r, one digit each. */
static const char return_map6[16][17] = {
    "0123453445555555", "1013333333333333", "2124444444433333", "3345444444444444",
    "4344544444444444", "5344454444444444", "3344445444444444", "4344444544444444",
    "4344444454444444", "5344444445444444", "5344444444544444", "5334444444455444",
    "5334444444455544", "5334444444445554", "5334444444444555", "5334444444444455"};

/* A symbol model created on first use; stamp is the chunk generation of its
 * last reset. */
typedef struct lazy_model {
    gdt_laz_symmodel m; /* distribution NULL until allocated */
    uint64_t stamp;
} lazy_model;

/* POINT14 values as the stream predicts them. */
typedef struct p14_point {
    uint32_t x, y, z;
    uint16_t intensity, scan_angle, point_source;
    uint8_t ret, nret, cflags, channel, scan_dir, edge, cls, user;
    uint64_t gps; /* the bits of the binary64 time */
    int gps_change;
} p14_point;

typedef struct p14_ctx {
    uint64_t gen; /* == decoder gen: in use in this chunk */
    int allocated;
    p14_point last;
    gdt_laz_symmodel changed[8], channel, ret_gps_same;
    lazy_model nret[16], ret[16];
    gdt_laz_intdec dx, dy, z;
    gdt_laz_median5 mx[12], my[12];
    int32_t last_z[8];
    lazy_model cls[64], flags[64], user[64];
    gdt_laz_intdec intensity, scan_angle, point_source, gps;
    uint16_t last_intensity[8];
    gdt_laz_symmodel gps_multi, gps_0diff;
    unsigned gps_last, gps_next;
    uint64_t gps_seq[4];
    int32_t gps_diff[4], gps_extreme[4];
} p14_ctx;

typedef struct rgb_models {
    gdt_laz_symmodel used, diff[6];
} rgb_models;

typedef struct nir_models {
    gdt_laz_symmodel used, diff[2];
} nir_models;

typedef struct wave_models {
    gdt_laz_symmodel index, offset[4];
    gdt_laz_intdec offset_diff, size, ret, xyz;
    int32_t last_diff;
    uint32_t last_sym;
} wave_models;

/* One context of an item after POINT14. */
typedef struct x_ctx {
    uint64_t gen;
    int allocated;
    unsigned char *last;     /* size bytes: the item's last values */
    rgb_models rgb;          /* RGB14, RGBNIR14 */
    nir_models nir;          /* RGBNIR14 */
    wave_models wave;        /* WAVEPACKET14 */
    gdt_laz_symmodel *bytes; /* BYTE14: size models */
} x_ctx;

typedef struct x_item {
    unsigned type, version, size;
    unsigned offset; /* in the record */
    unsigned layer;  /* its first layer */
    unsigned nlayers;
    unsigned cur;         /* its current context */
    unsigned char *store; /* NCTX * size bytes behind the contexts' last */
    x_ctx ctx[NCTX];
} x_item;

struct gdt_laz14 {
    unsigned record_length;
    unsigned version; /* of POINT14 */
    int want_xyz, want_class, want_flags, want_rest, want_all;
    unsigned nitems; /* items after POINT14 */
    x_item items[GDT_LAZ_MAX_ITEMS];
    unsigned nlayers;
    uint32_t *lsize;      /* nlayers */
    size_t *loff;         /* nlayers, from data */
    int *ldecode;         /* nlayers: 1 when the run decodes this layer */
    gdt_laz_dec *dec;     /* nlayers */
    gdt_laz_dec **active; /* the decoders started for this chunk */
    unsigned nactive;
    /* the chunk */
    const unsigned char *data;
    size_t used;
    uint64_t npoints, pos, chunk;
    const char *path;
    uint64_t gen;
    unsigned cur;       /* POINT14 context */
    unsigned char *lon; /* nlayers: decoded in this chunk (needed and not empty) */
    p14_ctx p14[NCTX];
};

static gdt_status oom(gdt_error *err)
{
    return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
}

/* ---- small pieces ---------------------------------------------------- */

static inline uint32_t clamp_u8(int32_t v)
{
    return v <= 0 ? 0u : v >= 255 ? 255u : (uint32_t)v;
}

static inline uint32_t even_below(uint32_t k, uint32_t cap)
{
    return k < cap ? (k & ~1u) : cap;
}

static inline void put16(unsigned char *p, uint32_t v)
{
    p[0] = (unsigned char)v;
    p[1] = (unsigned char)(v >> 8);
}

/* The model m ready for this chunk: allocated once, reset on first use. */
static inline gdt_laz_symmodel *lazy(lazy_model *m, uint32_t symbols, uint64_t gen, gdt_error *err)
{
    if (m->stamp == gen)
        return &m->m;
    if (!m->m.distribution) {
        if (gdt_laz_symmodel_alloc(&m->m, symbols, err) != GDT_OK)
            return NULL;
    } else {
        gdt_laz_symmodel_init(&m->m);
    }
    m->stamp = gen;
    return &m->m;
}

static void lazy_free(lazy_model *m, unsigned n)
{
    for (unsigned i = 0; i < n; i++)
        gdt_laz_symmodel_free(&m[i].m);
}

/* ---- POINT14 ---------------------------------------------------------- */

static void p14_parse(p14_point *p, const unsigned char *r)
{
    p->x = gdt_le_get_u32(r);
    p->y = gdt_le_get_u32(r + 4);
    p->z = gdt_le_get_u32(r + 8);
    p->intensity = gdt_le_get_u16(r + 12);
    p->ret = r[14] & 15;
    p->nret = r[14] >> 4;
    p->cflags = r[15] & 15;
    p->channel = (r[15] >> 4) & 3;
    p->scan_dir = (r[15] >> 6) & 1;
    p->edge = r[15] >> 7;
    p->cls = r[16];
    p->user = r[17];
    p->scan_angle = gdt_le_get_u16(r + 18);
    p->point_source = gdt_le_get_u16(r + 20);
    p->gps = gdt_le_get_u64(r + 22);
    p->gps_change = 0;
}

/* Writes the needed fields of p; the caller zeroed the record unless every
 * field is needed. */
static inline void p14_put(const gdt_laz14 *z, unsigned char *r, const p14_point *p)
{
    if (z->want_xyz) {
        gdt_le_put_u32(r, p->x);
        gdt_le_put_u32(r + 4, p->y);
        gdt_le_put_u32(r + 8, p->z);
    }
    if (z->want_flags) {
        r[14] = (unsigned char)(p->ret | (p->nret << 4));
        r[15] =
            (unsigned char)(p->cflags | (p->channel << 4) | (p->scan_dir << 6) | (p->edge << 7));
    }
    if (z->want_class)
        r[16] = p->cls;
    if (z->want_rest) {
        put16(r + 12, p->intensity);
        r[17] = p->user;
        put16(r + 18, p->scan_angle);
        put16(r + 20, p->point_source);
        gdt_le_put_u64(r + 22, p->gps);
    }
}

static void p14_ctx_free(p14_ctx *c)
{
    for (unsigned i = 0; i < 8; i++)
        gdt_laz_symmodel_free(&c->changed[i]);
    gdt_laz_symmodel_free(&c->channel);
    gdt_laz_symmodel_free(&c->ret_gps_same);
    lazy_free(c->nret, 16);
    lazy_free(c->ret, 16);
    gdt_laz_intdec_free(&c->dx);
    gdt_laz_intdec_free(&c->dy);
    gdt_laz_intdec_free(&c->z);
    lazy_free(c->cls, 64);
    lazy_free(c->flags, 64);
    lazy_free(c->user, 64);
    gdt_laz_intdec_free(&c->intensity);
    gdt_laz_intdec_free(&c->scan_angle);
    gdt_laz_intdec_free(&c->point_source);
    gdt_laz_intdec_free(&c->gps);
    gdt_laz_symmodel_free(&c->gps_multi);
    gdt_laz_symmodel_free(&c->gps_0diff);
}

/* Allocates the models of a context (they start initialised). */
static gdt_status p14_ctx_alloc(gdt_laz14 *z, p14_ctx *c, gdt_error *err)
{
    for (unsigned i = 0; i < 8; i++)
        if (gdt_laz_symmodel_alloc(&c->changed[i], 128, err) != GDT_OK)
            return GDT_EINTERNAL;
    if (gdt_laz_symmodel_alloc(&c->channel, 3, err) != GDT_OK ||
        gdt_laz_symmodel_alloc(&c->ret_gps_same, 13, err) != GDT_OK ||
        gdt_laz_intdec_new(&c->dx, 32, 2, 8, 0, err) != GDT_OK ||
        gdt_laz_intdec_new(&c->dy, 32, 22, 8, 0, err) != GDT_OK)
        return GDT_EINTERNAL;
    if (z->ldecode[L_Z])
        if (gdt_laz_intdec_new(&c->z, 32, 20, 8, 0, err) != GDT_OK)
            return GDT_EINTERNAL;
    if (z->want_rest) {
        if (gdt_laz_intdec_new(&c->intensity, 16, 4, 8, 0, err) != GDT_OK ||
            gdt_laz_intdec_new(&c->scan_angle, 16, 2, 8, 0, err) != GDT_OK ||
            gdt_laz_intdec_new(&c->point_source, 16, 1, 8, 0, err) != GDT_OK ||
            gdt_laz_intdec_new(&c->gps, 32, 9, 8, 0, err) != GDT_OK ||
            gdt_laz_symmodel_alloc(&c->gps_multi, GPS_SYMBOLS, err) != GDT_OK ||
            gdt_laz_symmodel_alloc(&c->gps_0diff, 5, err) != GDT_OK)
            return GDT_EINTERNAL;
    }
    c->allocated = 1;
    return GDT_OK;
}

/* Puts context c in use for this chunk, continuing from the values of from
 * (the point the stream had reached; copied, it may be c's own). */
static gdt_status p14_ctx_start(gdt_laz14 *z, p14_ctx *c, const p14_point *from, gdt_error *err)
{
    p14_point p = *from;

    if (!c->allocated) {
        if (p14_ctx_alloc(z, c, err) != GDT_OK)
            return GDT_EINTERNAL;
    } else {
        for (unsigned i = 0; i < 8; i++)
            gdt_laz_symmodel_init(&c->changed[i]);
        gdt_laz_symmodel_init(&c->channel);
        gdt_laz_symmodel_init(&c->ret_gps_same);
        gdt_laz_intdec_init(&c->dx);
        gdt_laz_intdec_init(&c->dy);
        if (z->ldecode[L_Z])
            gdt_laz_intdec_init(&c->z);
        if (z->want_rest) {
            gdt_laz_intdec_init(&c->intensity);
            gdt_laz_intdec_init(&c->scan_angle);
            gdt_laz_intdec_init(&c->point_source);
            gdt_laz_intdec_init(&c->gps);
            gdt_laz_symmodel_init(&c->gps_multi);
            gdt_laz_symmodel_init(&c->gps_0diff);
        }
    }
    for (unsigned i = 0; i < 12; i++) {
        gdt_laz_median5_init(&c->mx[i]);
        gdt_laz_median5_init(&c->my[i]);
    }
    for (unsigned i = 0; i < 8; i++) {
        c->last_z[i] = gdt_laz_i32(p.z);
        c->last_intensity[i] = p.intensity;
    }
    c->gps_last = c->gps_next = 0;
    memset(c->gps_diff, 0, sizeof c->gps_diff);
    memset(c->gps_extreme, 0, sizeof c->gps_extreme);
    c->gps_seq[0] = p.gps;
    c->gps_seq[1] = c->gps_seq[2] = c->gps_seq[3] = 0;
    p.gps_change = 0;
    c->last = p;
    c->gen = z->gen;
    return GDT_OK;
}

/* The next time of the current sequence (or of a new one); a stream that
 * keeps switching sequences without coding a time is corrupt. */
static void p14_gps(p14_ctx *c, gdt_laz_dec *d)
{
    for (unsigned hops = 0; hops < 8; hops++) {
        unsigned l = c->gps_last, nx;
        uint32_t multi, hi;

        if (c->gps_diff[l] == 0) {
            multi = gdt_laz_decode_symbol(d, &c->gps_0diff);
            if (multi == 0) {
                c->gps_diff[l] = gdt_laz_intdec_decode(&c->gps, d, 0, 0);
                c->gps_seq[l] += (uint64_t)(int64_t)c->gps_diff[l];
                c->gps_extreme[l] = 0;
                return;
            }
            if (multi > 1) {
                c->gps_last = (l + multi - 1) & 3;
                continue;
            }
        } else {
            multi = gdt_laz_decode_symbol(d, &c->gps_multi);
            if (multi == 1) {
                c->gps_seq[l] +=
                    (uint64_t)(int64_t)gdt_laz_intdec_decode(&c->gps, d, c->gps_diff[l], 1);
                c->gps_extreme[l] = 0;
                return;
            }
            if (multi < GPS_CODE_FULL) {
                uint32_t ld = (uint32_t)c->gps_diff[l];
                int32_t diff;
                int extreme = 0;

                /* The products wrap as the encoder's 32-bit ones do. */
                if (multi == 0) {
                    diff = gdt_laz_intdec_decode(&c->gps, d, 0, 7);
                    extreme = 1;
                } else if (multi < GPS_MULTI) {
                    diff = gdt_laz_intdec_decode(&c->gps, d, gdt_laz_i32(multi * ld),
                                                 multi < 10 ? 2 : 3);
                } else if (multi == GPS_MULTI) {
                    diff = gdt_laz_intdec_decode(&c->gps, d, gdt_laz_i32(GPS_MULTI * ld), 4);
                    extreme = 1;
                } else if (multi < GPS_MULTI - GPS_MULTI_MINUS) {
                    /* multipliers -1 .. -9 */
                    uint32_t neg = multi - GPS_MULTI; /* 1 .. 9 */
                    diff = gdt_laz_intdec_decode(&c->gps, d, gdt_laz_i32(0u - neg * ld), 5);
                } else {
                    diff = gdt_laz_intdec_decode(
                        &c->gps, d, gdt_laz_i32(0u - (uint32_t)(-GPS_MULTI_MINUS) * ld), 6);
                    extreme = 1;
                }
                if (extreme && ++c->gps_extreme[l] > 3) {
                    c->gps_diff[l] = diff;
                    c->gps_extreme[l] = 0;
                }
                c->gps_seq[l] += (uint64_t)(int64_t)diff;
                return;
            }
            if (multi > GPS_CODE_FULL) {
                c->gps_last = (l + multi - GPS_CODE_FULL) & 3;
                continue;
            }
        }
        /* A full time in a new sequence: its high word predicted by the
         * current one's, the low word raw. */
        nx = c->gps_next = (c->gps_next + 1) & 3;
        hi = (uint32_t)gdt_laz_intdec_decode(&c->gps, d,
                                             gdt_laz_i32((uint32_t)(c->gps_seq[l] >> 32)), 8);
        c->gps_seq[nx] = ((uint64_t)hi << 32) | gdt_laz_read_int(d);
        c->gps_last = nx;
        c->gps_diff[nx] = 0;
        c->gps_extreme[nx] = 0;
        return;
    }
    d->bad |= GDT_LAZ_DEC_CORRUPT;
}

/* Decodes one POINT14 point into r; *context receives the channel the other
 * items follow. */
static gdt_status p14_read(gdt_laz14 *z, unsigned char *r, unsigned *context, gdt_error *err)
{
    p14_ctx *c = &z->p14[z->cur];
    gdt_laz_dec *d = &z->dec[L_XY];
    p14_point *p = &c->last;
    uint64_t gen = z->gen;
    gdt_laz_symmodel *m;
    uint32_t lpr, cv, n, rn, mctx, lvl, cpr, kb;
    int32_t diff;
    int gps_change, switched = 0;

    lpr = (p->ret == 1) + 2u * (p->ret >= p->nret) + 4u * (p->gps_change != 0);
    cv = gdt_laz_decode_symbol(d, &c->changed[lpr]);
    if (cv & (1u << 6)) {
        unsigned ch = (z->cur + gdt_laz_decode_symbol(d, &c->channel) + 1) & 3;
        p14_ctx *nc = &z->p14[ch];

        if (nc->gen != gen && p14_ctx_start(z, nc, p, err) != GDT_OK)
            return GDT_EINTERNAL;
        z->cur = ch;
        c = nc;
        p = &c->last;
        p->channel = (uint8_t)ch;
        switched = 1;
    }
    /* Version 3 tells the other items the channel only when it changes. */
    *context = (switched || z->version >= 4) ? z->cur : 0;
    gps_change = (cv >> 4) & 1;

    if (cv & (1u << 2)) {
        if (!(m = lazy(&c->nret[p->nret], 16, gen, err)))
            return GDT_EINTERNAL;
        p->nret = (uint8_t)gdt_laz_decode_symbol(d, m);
    }
    n = p->nret;
    switch (cv & 3) {
    case 0: break;
    case 1: p->ret = (p->ret + 1) & 15; break;
    case 2: p->ret = (p->ret + 15) & 15; break;
    default:
        if (gps_change) {
            if (!(m = lazy(&c->ret[p->ret], 16, gen, err)))
                return GDT_EINTERNAL;
            p->ret = (uint8_t)gdt_laz_decode_symbol(d, m);
        } else {
            p->ret = (p->ret + gdt_laz_decode_symbol(d, &c->ret_gps_same) + 2) & 15;
        }
        break;
    }
    rn = p->ret;
    mctx = (uint32_t)(return_map6[n][rn] - '0');
    lvl = n > rn ? n - rn : rn - n;
    if (lvl > 7)
        lvl = 7;
    cpr = (rn == 1 ? 2u : 0u) + (rn >= n ? 1u : 0u);

    {
        unsigned mi = (mctx << 1) | (unsigned)gps_change;
        diff = gdt_laz_intdec_decode(&c->dx, d, c->mx[mi].v[2], n == 1);
        p->x += (uint32_t)diff;
        gdt_laz_median5_add(&c->mx[mi], diff);
        kb = gdt_laz_intdec_k(&c->dx);
        diff = gdt_laz_intdec_decode(&c->dy, d, c->my[mi].v[2], (n == 1) + even_below(kb, 20));
        p->y += (uint32_t)diff;
        gdt_laz_median5_add(&c->my[mi], diff);
    }
    if (z->lon[L_Z]) {
        kb = (gdt_laz_intdec_k(&c->dx) + gdt_laz_intdec_k(&c->dy)) / 2;
        c->last_z[lvl] = gdt_laz_intdec_decode(&c->z, &z->dec[L_Z], c->last_z[lvl],
                                               (n == 1) + even_below(kb, 18));
        p->z = (uint32_t)c->last_z[lvl];
    }
    if (z->lon[L_CLASS]) {
        if (!(m = lazy(&c->cls[((p->cls & 0x1Fu) << 1) + (cpr == 3)], 256, gen, err)))
            return GDT_EINTERNAL;
        p->cls = (uint8_t)gdt_laz_decode_symbol(&z->dec[L_CLASS], m);
    }
    if (z->lon[L_FLAGS]) {
        uint32_t f;
        if (!(m = lazy(&c->flags[(p->edge << 5) | (p->scan_dir << 4) | p->cflags], 64, gen, err)))
            return GDT_EINTERNAL;
        f = gdt_laz_decode_symbol(&z->dec[L_FLAGS], m);
        p->edge = (f >> 5) & 1;
        p->scan_dir = (f >> 4) & 1;
        p->cflags = f & 15;
    }
    if (z->lon[L_INTENSITY]) {
        unsigned ii = (cpr << 1) | (unsigned)gps_change;
        p->intensity = (uint16_t)gdt_laz_intdec_decode(&c->intensity, &z->dec[L_INTENSITY],
                                                       c->last_intensity[ii], cpr);
        c->last_intensity[ii] = p->intensity;
    }
    if (z->lon[L_SCAN_ANGLE] && (cv & (1u << 3)))
        p->scan_angle = (uint16_t)gdt_laz_intdec_decode(&c->scan_angle, &z->dec[L_SCAN_ANGLE],
                                                        p->scan_angle, gps_change);
    if (z->lon[L_USER_DATA]) {
        if (!(m = lazy(&c->user[p->user >> 2], 256, gen, err)))
            return GDT_EINTERNAL;
        p->user = (uint8_t)gdt_laz_decode_symbol(&z->dec[L_USER_DATA], m);
    }
    if (z->lon[L_POINT_SOURCE] && (cv & (1u << 5)))
        p->point_source = (uint16_t)gdt_laz_intdec_decode(&c->point_source, &z->dec[L_POINT_SOURCE],
                                                          p->point_source, 0);
    if (z->lon[L_GPS_TIME] && gps_change) {
        p14_gps(c, &z->dec[L_GPS_TIME]);
        p->gps = c->gps_seq[c->gps_last];
    }
    p14_put(z, r, p);
    p->gps_change = gps_change;
    return GDT_OK;
}

/* ---- the items after POINT14 ------------------------------------------ */

static unsigned item_layers(unsigned type, unsigned size)
{
    switch (type) {
    case GDT_LAZ_RGBNIR14: return 2;
    case GDT_LAZ_BYTE14: return size;
    default: return 1;
    }
}

static gdt_status syms_alloc(gdt_laz_symmodel *m, unsigned n, uint32_t symbols, gdt_error *err)
{
    for (unsigned i = 0; i < n; i++)
        if (gdt_laz_symmodel_alloc(&m[i], symbols, err) != GDT_OK)
            return GDT_EINTERNAL;
    return GDT_OK;
}

static void syms_init(gdt_laz_symmodel *m, unsigned n)
{
    for (unsigned i = 0; i < n; i++)
        gdt_laz_symmodel_init(&m[i]);
}

static void syms_free(gdt_laz_symmodel *m, unsigned n)
{
    for (unsigned i = 0; i < n; i++)
        gdt_laz_symmodel_free(&m[i]);
}

static void x_ctx_free(const x_item *it, x_ctx *c)
{
    syms_free(&c->rgb.used, 1);
    syms_free(c->rgb.diff, 6);
    syms_free(&c->nir.used, 1);
    syms_free(c->nir.diff, 2);
    syms_free(&c->wave.index, 1);
    syms_free(c->wave.offset, 4);
    gdt_laz_intdec_free(&c->wave.offset_diff);
    gdt_laz_intdec_free(&c->wave.size);
    gdt_laz_intdec_free(&c->wave.ret);
    gdt_laz_intdec_free(&c->wave.xyz);
    if (c->bytes)
        syms_free(c->bytes, it->size);
    free(c->bytes);
}

static gdt_status x_ctx_alloc(x_item *it, x_ctx *c, gdt_error *err)
{
    switch (it->type) {
    case GDT_LAZ_RGBNIR14:
        if (syms_alloc(&c->nir.used, 1, 4, err) != GDT_OK ||
            syms_alloc(c->nir.diff, 2, 256, err) != GDT_OK)
            return GDT_EINTERNAL;
        /* fall through */
    case GDT_LAZ_RGB14:
        if (syms_alloc(&c->rgb.used, 1, 128, err) != GDT_OK ||
            syms_alloc(c->rgb.diff, 6, 256, err) != GDT_OK)
            return GDT_EINTERNAL;
        break;
    case GDT_LAZ_WAVEPACKET14:
        if (syms_alloc(&c->wave.index, 1, 256, err) != GDT_OK ||
            syms_alloc(c->wave.offset, 4, 4, err) != GDT_OK ||
            gdt_laz_intdec_new(&c->wave.offset_diff, 32, 1, 8, 0, err) != GDT_OK ||
            gdt_laz_intdec_new(&c->wave.size, 32, 1, 8, 0, err) != GDT_OK ||
            gdt_laz_intdec_new(&c->wave.ret, 32, 1, 8, 0, err) != GDT_OK ||
            gdt_laz_intdec_new(&c->wave.xyz, 32, 3, 8, 0, err) != GDT_OK)
            return GDT_EINTERNAL;
        break;
    default: /* BYTE14 */
        if (!(c->bytes = calloc(it->size, sizeof *c->bytes)))
            return oom(err);
        if (syms_alloc(c->bytes, it->size, 256, err) != GDT_OK)
            return GDT_EINTERNAL;
        break;
    }
    c->allocated = 1;
    return GDT_OK;
}

/* Puts context ci of it in use for this chunk, continuing from the item
 * values at from (size bytes; may be another context's last). */
static gdt_status x_ctx_start(gdt_laz14 *z, x_item *it, unsigned ci, const unsigned char *from,
                              gdt_error *err)
{
    x_ctx *c = &it->ctx[ci];

    if (!c->allocated) {
        if (x_ctx_alloc(it, c, err) != GDT_OK)
            return GDT_EINTERNAL;
    } else {
        switch (it->type) {
        case GDT_LAZ_RGBNIR14:
            syms_init(&c->nir.used, 1);
            syms_init(c->nir.diff, 2);
            /* fall through */
        case GDT_LAZ_RGB14:
            syms_init(&c->rgb.used, 1);
            syms_init(c->rgb.diff, 6);
            break;
        case GDT_LAZ_WAVEPACKET14:
            syms_init(&c->wave.index, 1);
            syms_init(c->wave.offset, 4);
            gdt_laz_intdec_init(&c->wave.offset_diff);
            gdt_laz_intdec_init(&c->wave.size);
            gdt_laz_intdec_init(&c->wave.ret);
            gdt_laz_intdec_init(&c->wave.xyz);
            break;
        default: syms_init(c->bytes, it->size); break;
        }
    }
    c->wave.last_diff = 0;
    c->wave.last_sym = 0;
    if (c->last != from)
        memcpy(c->last, from, it->size);
    c->gen = z->gen;
    return GDT_OK;
}

/* The 16-bit colour channels: the low and high bytes of red, then green and
 * blue predicted from red's change, each byte only where sym says it
 * changed. */
static void rgb_read(gdt_laz_dec *d, rgb_models *m, const unsigned char *last, unsigned char *out)
{
    uint32_t l0 = gdt_le_get_u16(last), l1 = gdt_le_get_u16(last + 2),
             l2 = gdt_le_get_u16(last + 4);
    uint32_t sym = gdt_laz_decode_symbol(d, &m->used);
    uint32_t v0, v1, v2, lo, hi;
    int32_t diff;

    lo = (sym & 1) ? (gdt_laz_decode_symbol(d, &m->diff[0]) + (l0 & 255)) & 255 : l0 & 255;
    hi = (sym & 2) ? (gdt_laz_decode_symbol(d, &m->diff[1]) + (l0 >> 8)) & 255 : l0 >> 8;
    v0 = lo | (hi << 8);
    if (sym & (1u << 6)) {
        uint32_t g_lo, b_lo, g_hi, b_hi;

        diff = (int32_t)(v0 & 255) - (int32_t)(l0 & 255);
        g_lo =
            (sym & 4)
                ? (gdt_laz_decode_symbol(d, &m->diff[2]) + clamp_u8(diff + (int32_t)(l1 & 255))) &
                      255
                : l1 & 255;
        if (sym & 16) {
            diff = (diff + ((int32_t)g_lo - (int32_t)(l1 & 255))) / 2;
            b_lo = (gdt_laz_decode_symbol(d, &m->diff[4]) + clamp_u8(diff + (int32_t)(l2 & 255))) &
                   255;
        } else {
            b_lo = l2 & 255;
        }
        diff = (int32_t)(v0 >> 8) - (int32_t)(l0 >> 8);
        g_hi = (sym & 8)
                   ? (gdt_laz_decode_symbol(d, &m->diff[3]) + clamp_u8(diff + (int32_t)(l1 >> 8))) &
                         255
                   : l1 >> 8;
        if (sym & 32) {
            diff = (diff + ((int32_t)g_hi - (int32_t)(l1 >> 8))) / 2;
            b_hi =
                (gdt_laz_decode_symbol(d, &m->diff[5]) + clamp_u8(diff + (int32_t)(l2 >> 8))) & 255;
        } else {
            b_hi = l2 >> 8;
        }
        v1 = g_lo | (g_hi << 8);
        v2 = b_lo | (b_hi << 8);
    } else {
        v1 = v2 = v0;
    }
    put16(out, v0);
    put16(out + 2, v1);
    put16(out + 4, v2);
}

static uint32_t nir_read(gdt_laz_dec *d, nir_models *m, uint32_t l)
{
    uint32_t sym = gdt_laz_decode_symbol(d, &m->used);
    uint32_t lo = (sym & 1) ? (gdt_laz_decode_symbol(d, &m->diff[0]) + (l & 255)) & 255 : l & 255;
    uint32_t hi = (sym & 2) ? (gdt_laz_decode_symbol(d, &m->diff[1]) + (l >> 8)) & 255 : l >> 8;
    return lo | (hi << 8);
}

/* The wave packet: descriptor index, byte offset (same, after the last
 * packet, a 32-bit difference or raw), size, return point and x, y, z. */
static void wave_read(gdt_laz_dec *d, wave_models *m, const unsigned char *last, unsigned char *out)
{
    uint64_t off = gdt_le_get_u64(last + 1);
    uint32_t size = gdt_le_get_u32(last + 9);

    out[0] = (unsigned char)gdt_laz_decode_symbol(d, &m->index);
    m->last_sym = gdt_laz_decode_symbol(d, &m->offset[m->last_sym]);
    switch (m->last_sym) {
    case 0: break;
    case 1: off += size; break;
    case 2:
        m->last_diff = gdt_laz_intdec_decode(&m->offset_diff, d, m->last_diff, 0);
        off += (uint64_t)(int64_t)m->last_diff;
        break;
    default: off = gdt_laz_read_int64(d); break;
    }
    gdt_le_put_u64(out + 1, off);
    gdt_le_put_u32(out + 9, (uint32_t)gdt_laz_intdec_decode(&m->size, d, gdt_laz_i32(size), 0));
    gdt_le_put_u32(out + 13, (uint32_t)gdt_laz_intdec_decode(
                                 &m->ret, d, gdt_laz_i32(gdt_le_get_u32(last + 13)), 0));
    for (unsigned i = 0; i < 3; i++)
        gdt_le_put_u32(out + 17 + 4 * i,
                       (uint32_t)gdt_laz_intdec_decode(
                           &m->xyz, d, gdt_laz_i32(gdt_le_get_u32(last + 17 + 4 * i)), i));
}

/* Decodes item it of one point into out, following context. */
static gdt_status x_read(gdt_laz14 *z, x_item *it, unsigned context, unsigned char *out,
                         gdt_error *err)
{
    unsigned char *last = it->ctx[it->cur].last;
    gdt_laz_dec *d = &z->dec[it->layer];
    x_ctx *c;

    if (it->cur != context) {
        it->cur = context;
        if (it->ctx[context].gen != z->gen) {
            if (x_ctx_start(z, it, context, last, err) != GDT_OK)
                return GDT_EINTERNAL;
            last = it->ctx[context].last;
        } else if (it->version >= 4) {
            last = it->ctx[context].last;
        }
        /* Version 3, switching to a channel in use: the point is predicted
         * from, and stored as, the previous channel's last values. */
    }
    c = &it->ctx[context];
    switch (it->type) {
    case GDT_LAZ_RGB14:
    case GDT_LAZ_RGBNIR14:
        if (z->lon[it->layer]) {
            rgb_read(d, &c->rgb, last, out);
            memcpy(last, out, 6);
        } else {
            memcpy(out, last, 6);
        }
        if (it->type == GDT_LAZ_RGBNIR14) {
            gdt_laz_dec *dn = &z->dec[it->layer + 1];
            uint32_t v = gdt_le_get_u16(last + 6);
            if (z->lon[it->layer + 1]) {
                v = nir_read(dn, &c->nir, v);
                put16(last + 6, v);
            }
            put16(out + 6, v);
        }
        break;
    case GDT_LAZ_WAVEPACKET14:
        /* An empty layer leaves the packet of the first point. */
        if (z->lon[it->layer]) {
            wave_read(d, &c->wave, last, out);
            memcpy(last, out, 29);
        } else {
            memcpy(out, last, 29);
        }
        break;
    default:
        for (unsigned i = 0; i < it->size; i++, d++) {
            if (z->lon[it->layer + i])
                last[i] = (unsigned char)(last[i] + gdt_laz_decode_symbol(d, &c->bytes[i]));
            out[i] = last[i];
        }
        break;
    }
    return GDT_OK;
}

/* ---- the decoder ------------------------------------------------------ */

void gdt_laz14_free(gdt_laz14 *z)
{
    if (!z)
        return;
    for (unsigned i = 0; i < NCTX; i++)
        p14_ctx_free(&z->p14[i]);
    for (unsigned k = 0; k < z->nitems; k++) {
        x_item *it = &z->items[k];
        for (unsigned i = 0; i < NCTX; i++)
            x_ctx_free(it, &it->ctx[i]);
        free(it->store);
    }
    free(z->lsize);
    free(z->loff);
    free(z->ldecode);
    free(z->dec);
    free(z->active);
    free(z->lon);
    free(z);
}

gdt_status gdt_laz14_new(gdt_laz14 **out, const gdt_laz_vlr *vlr, unsigned record_length,
                         unsigned need, gdt_error *err)
{
    gdt_laz14 *z;
    unsigned offset, nl;

    *out = NULL;
    if (vlr->nitems < 1 || vlr->items[0].type != GDT_LAZ_POINT14 || vlr->items[0].size != 30)
        return gdt_error_set(err, GDT_EINPUT, 3940,
                             "layered LAZ stream does not start with a POINT14 item");
    if (!(z = calloc(1, sizeof *z)))
        return oom(err);
    z->record_length = record_length;
    z->version = vlr->items[0].version;
    z->want_xyz = (need & GDT_LAZ_NEED_XYZ) != 0;
    z->want_class = (need & GDT_LAZ_NEED_CLASS) != 0;
    z->want_flags = (need & GDT_LAZ_NEED_FLAGS) != 0;
    z->want_rest =
        (need & ~(unsigned)(GDT_LAZ_NEED_XYZ | GDT_LAZ_NEED_CLASS | GDT_LAZ_NEED_FLAGS)) != 0;
    z->want_all = z->want_xyz && z->want_class && z->want_flags && z->want_rest;
    offset = 30;
    nl = L_P14;
    for (unsigned k = 1; k < vlr->nitems; k++) {
        const gdt_laz_item *vi = &vlr->items[k];
        x_item *it = &z->items[z->nitems++];
        unsigned want = 0;

        switch (vi->type) {
        case GDT_LAZ_RGB14: want = 6; break;
        case GDT_LAZ_RGBNIR14: want = 8; break;
        case GDT_LAZ_WAVEPACKET14: want = 29; break;
        case GDT_LAZ_BYTE14: want = vi->size; break;
        default: break;
        }
        if (want == 0 || vi->size != want || (vi->version != 3 && vi->version != 4)) {
            gdt_laz14_free(z);
            return gdt_error_set(err, GDT_EINPUT, 3940,
                                 "layered LAZ stream: item %u (type %u, %u bytes, version %u) "
                                 "cannot follow POINT14",
                                 k, (unsigned)vi->type, (unsigned)vi->size, (unsigned)vi->version);
        }
        it->type = vi->type;
        it->size = vi->size;
        it->version = vi->version;
        it->offset = offset;
        it->layer = nl;
        it->nlayers = item_layers(it->type, it->size);
        nl += it->nlayers;
        offset += it->size;
        if (!(it->store = malloc((size_t)NCTX * it->size))) {
            gdt_laz14_free(z);
            return oom(err);
        }
        for (unsigned i = 0; i < NCTX; i++)
            it->ctx[i].last = it->store + (size_t)i * it->size;
    }
    if (offset != record_length || (z->version != 3 && z->version != 4)) {
        gdt_laz14_free(z);
        return gdt_error_set(err, GDT_EINPUT, 3940,
                             "layered LAZ stream: items of %u bytes (POINT14 version %u) for "
                             "records of %u bytes",
                             offset, z->version, record_length);
    }
    z->nlayers = nl;
    z->lsize = calloc(nl, sizeof *z->lsize);
    z->loff = calloc(nl, sizeof *z->loff);
    z->ldecode = calloc(nl, sizeof *z->ldecode);
    z->dec = calloc(nl, sizeof *z->dec);
    z->active = calloc(nl, sizeof *z->active);
    z->lon = calloc(nl, 1);
    if (!z->lon || !z->lsize || !z->loff || !z->ldecode || !z->dec || !z->active) {
        gdt_laz14_free(z);
        return oom(err);
    }
    z->ldecode[L_XY] = 1;
    z->ldecode[L_Z] = z->want_xyz;
    z->ldecode[L_CLASS] = z->want_class;
    z->ldecode[L_FLAGS] = z->want_flags;
    for (unsigned l = L_INTENSITY; l < nl; l++)
        z->ldecode[l] = z->want_rest;
    *out = z;
    return GDT_OK;
}

/* What layer l holds, for messages. */
static const char *layer_name(const gdt_laz14 *z, unsigned l)
{
    if (l < L_P14)
        return p14_layer_name[l];
    for (unsigned k = 0; k < z->nitems; k++) {
        const x_item *it = &z->items[k];
        if (l >= it->layer && l < it->layer + it->nlayers) {
            switch (it->type) {
            case GDT_LAZ_RGB14: return "RGB";
            case GDT_LAZ_RGBNIR14: return l == it->layer ? "RGB" : "NIR";
            case GDT_LAZ_WAVEPACKET14: return "wave packet";
            default: return "extra byte";
            }
        }
    }
    return "unknown";
}

gdt_status gdt_laz14_start(gdt_laz14 *z, const unsigned char *data, size_t avail, uint64_t npoints,
                           const char *path, uint64_t chunk_index, gdt_error *err)
{
    size_t head = (size_t)z->record_length + 4 + 4 * (size_t)z->nlayers;
    uint64_t pos;
    uint32_t count;

    z->data = data;
    z->npoints = 0; /* until the chunk is started: no point to read */
    z->pos = 0;
    z->path = path;
    z->chunk = chunk_index;
    z->used = 0;
    z->nactive = 0;
    if (avail < head)
        return gdt_error_set(err, GDT_EINPUT, 3941,
                             "%s: LAZ chunk %" PRIu64 " has %zu bytes, fewer than the %zu of "
                             "its first point, count and layer sizes",
                             path, chunk_index, avail, head);
    count = gdt_le_get_u32(data + z->record_length);
    if (count < npoints)
        return gdt_error_set(err, GDT_EINPUT, 3942,
                             "%s: LAZ chunk %" PRIu64 " holds %" PRIu32 " points, not the %" PRIu64
                             " the file assigns it",
                             path, chunk_index, count, npoints);
    pos = head;
    for (unsigned l = 0; l < z->nlayers; l++) {
        z->lsize[l] = gdt_le_get_u32(data + z->record_length + 4 + 4 * (size_t)l);
        z->loff[l] = (size_t)pos;
        pos += z->lsize[l];
        if (pos > avail) {
            const char *what = layer_name(z, l);
            return gdt_error_set(err, GDT_EINPUT, 3943,
                                 "%s: LAZ chunk %" PRIu64 ": its %s layer (%u) of %" PRIu32
                                 " bytes ends at byte %" PRIu64 ", past the chunk's %zu",
                                 path, chunk_index, what, l, z->lsize[l], pos, avail);
        }
    }
    z->used = (size_t)pos;

    /* Start the layers the run decodes and that hold something; an empty
     * layer is one whose values stay those of the first point. */
    for (unsigned l = 0; l < z->nlayers; l++) {
        gdt_laz_dec *d = &z->dec[l];
        z->lon[l] = z->ldecode[l] && z->lsize[l] > 0;
        if (z->lon[l]) {
            gdt_laz_dec_init(d, data + z->loff[l], z->lsize[l]);
            z->active[z->nactive++] = d;
        } else {
            memset(d, 0, sizeof *d);
        }
    }
    /* The first point's layer always decodes: a chunk of more than one
     * point must have it, else the points after the first cannot change. */
    if (!z->lon[L_XY] && npoints > 1)
        return gdt_error_set(err, GDT_EINPUT, 3943,
                             "%s: LAZ chunk %" PRIu64 " of %" PRIu64 " points has an empty "
                             "changed-values layer",
                             path, chunk_index, npoints);

    z->gen++;
    z->npoints = npoints;
    return GDT_OK;
}

/* Puts the first point's channel contexts in use: done when the second
 * point is decoded, so one-point chunks never reset a model. */
static gdt_status chunk_contexts(gdt_laz14 *z, gdt_error *err)
{
    p14_point first;

    p14_parse(&first, z->data);
    z->cur = first.channel;
    if (p14_ctx_start(z, &z->p14[z->cur], &first, err) != GDT_OK)
        return GDT_EINTERNAL;
    if (z->want_rest) {
        for (unsigned k = 0; k < z->nitems; k++) {
            x_item *it = &z->items[k];
            it->cur = z->cur;
            if (x_ctx_start(z, it, it->cur, z->data + it->offset, err) != GDT_OK)
                return GDT_EINTERNAL;
        }
    }
    return GDT_OK;
}

/* The error of the first decoder found bad at point k. */
static gdt_status layer_error(const gdt_laz14 *z, gdt_error *err)
{
    for (unsigned l = 0; l < z->nlayers; l++) {
        const gdt_laz_dec *d = &z->dec[l];
        if (z->lon[l] && d->bad) {
            const char *what = layer_name(z, l);
            if (d->bad & GDT_LAZ_DEC_OVERRUN)
                return gdt_error_set(err, GDT_EINPUT, 3944,
                                     "%s: LAZ chunk %" PRIu64 ", point %" PRIu64
                                     ": the %s layer (%u) runs past its %" PRIu32 " bytes",
                                     z->path, z->chunk, z->pos, what, l, z->lsize[l]);
            return gdt_error_set(err, GDT_EINPUT, 3945,
                                 "%s: LAZ chunk %" PRIu64 ", point %" PRIu64
                                 ": the %s layer (%u) holds a code no encoder writes",
                                 z->path, z->chunk, z->pos, what, l);
        }
    }
    return gdt_error_set(err, GDT_EINPUT, 3945,
                         "%s: LAZ chunk %" PRIu64 ", point %" PRIu64 ": corrupt layer", z->path,
                         z->chunk, z->pos);
}

gdt_status gdt_laz14_read(gdt_laz14 *z, unsigned char *records, size_t n, gdt_error *err)
{
    size_t rl = z->record_length;

    if (n > z->npoints - z->pos)
        return gdt_error_set(err, GDT_EINTERNAL, 7395,
                             "LAZ chunk %" PRIu64 ": %zu points asked, %" PRIu64 " left", z->chunk,
                             n, z->npoints - z->pos);
    for (size_t i = 0; i < n; i++) {
        unsigned char *r = records + i * rl;
        unsigned context;

        if (!z->want_all)
            memset(r, 0, rl);
        if (z->pos == 0) {
            p14_point first;
            p14_parse(&first, z->data);
            p14_put(z, r, &first);
            if (z->want_rest)
                memcpy(r + 30, z->data + 30, rl - 30);
            if (z->npoints > 1 && chunk_contexts(z, err) != GDT_OK)
                return GDT_EINTERNAL;
        } else {
            if (p14_read(z, r, &context, err) != GDT_OK)
                return GDT_EINTERNAL;
            if (z->want_rest)
                for (unsigned k = 0; k < z->nitems; k++)
                    if (x_read(z, &z->items[k], context, r + z->items[k].offset, err) != GDT_OK)
                        return GDT_EINTERNAL;
        }
        {
            unsigned bad = 0;
            for (unsigned a = 0; a < z->nactive; a++)
                bad |= z->active[a]->bad;
            if (bad)
                return layer_error(z, err);
        }
        z->pos++;
    }
    return GDT_OK;
}

size_t gdt_laz14_used(const gdt_laz14 *z)
{
    return z->used;
}
