/* plycheck.c — streaming exact checker of an output PLY (see gdt_plycheck.h).
 *
 * Passes over the file:
 *   1. header (streamed line by line, nothing of it is kept but the counts
 *      and the lattice);
 *   2. vertices: lattice integers, bounds;
 *   3. vertices again: one point record per vertex (key: a bijective mix of
 *      the tile-local point, so buckets are balanced) -> duplicates;
 *   4. faces: per-face checks, vertex-use bitmap (window 0), three half-edge
 *      records per face, key (lo << 32 | hi), payload (opposite vertex |
 *      direction bit, face); further windows of the bitmap re-read the faces;
 *   5. half-edges grouped by edge, in key order (so the lower endpoint runs
 *      through the vertices in order and vertex reads stay local):
 *      multiplicity, direction, Lawson test; boundary half-edges become two
 *      boundary records (at the start vertex: "out", at the end: "in");
 *   6. boundary records grouped by vertex: one in, one out, the turn, the
 *      winding count;
 *   7. winding total and Euler's relation.
 */
#include "gdt_plycheck.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include "private/plycheck_spill.h"

#define PC_VERTEX_BYTES 24u
#define PC_FACE_BYTES 13u
/* Largest header read before giving up on finding end_header. */
#define PC_MAX_HEADER ((uint64_t)16 << 20)
/* Longest header line kept (longer comment lines are skipped over). */
#define PC_LINE_MAX 512
/* Lattice recovery: tolerance in lattice units, and the integer limit. */
#define PC_LATTICE_TOL 1e-6
#define PC_INT_LIMIT 9007199254740992.0 /* 2^53 */
/* Largest budget honoured (keeps a sorted bucket below 2^32 records). */
#define PC_MAX_BUDGET ((size_t)1 << 36)
/* Half-edge payload: opposite vertex | PC_DIR when the edge runs hi -> lo. */
#define PC_DIR UINT32_C(0x80000000)
/* Boundary payload: other vertex | PC_OUT when the edge leaves the key vertex. */
#define PC_OUT UINT32_C(0x80000000)

typedef struct pc_ctx {
    const char *path;
    pcs_env env;
    gdt_plycheck_result *res;
    int fd;
    uint64_t hlen; /* header bytes */
    uint64_t V, F;
    gdt_lattice lat;
    int have_lattice;
    unsigned char *map; /* header + vertex section, mapped read-only */
    size_t map_len;
    const unsigned char *vbase; /* first vertex record */
    int64_t ox, oy;             /* tile-local origin (lattice integers) */
    pcs_spill bnd;              /* boundary records (during pass 5) */
    uint64_t wraps, h;          /* pass 6 */
} pc_ctx;

/* ---- little-endian loads ---- */

static inline uint32_t ld32(const unsigned char *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static inline double ldd(const unsigned char *p)
{
    uint64_t u = (uint64_t)ld32(p) | (uint64_t)ld32(p + 4) << 32;
    double d;
    memcpy(&d, &u, sizeof d);
    return d;
}

/* ---- lattice ---- */

/* Lattice integer of coordinate v (x = o + s * i); 0 when v is off the
 * lattice, not finite, or |i| >= 2^53. */
static int lat_int(double v, double s, double o, int64_t *out)
{
    double q = (v - o) / s;
    double r = nearbyint(q);
    if (!isfinite(q) || !(fabs(r) < PC_INT_LIMIT))
        return 0;
    if (!(fabs(q - r) <= PC_LATTICE_TOL || v == o + s * r))
        return 0;
    *out = (int64_t)r;
    return 1;
}

/* Tile-local point of vertex i.  Precondition: pass 2 accepted every
 * vertex, so the lattice integer exists and lies in the extent. */
static inline gdt_ipt pc_pt(const pc_ctx *c, uint32_t i)
{
    const unsigned char *p = c->vbase + (size_t)i * PC_VERTEX_BYTES;
    gdt_ipt q;
    q.x = (int64_t)nearbyint((ldd(p) - c->lat.ox) / c->lat.sx) - c->ox;
    q.y = (int64_t)nearbyint((ldd(p + 8) - c->lat.oy) / c->lat.sy) - c->oy;
    return q;
}

/* Global lattice coordinates of a tile-local point, for messages. */
#define PC_GLOBAL(c, p) (long long)((p).x + (c)->ox), (long long)((p).y + (c)->oy)

/* ---- header ---- */

static int tokenize(char *line, char **tok, int max)
{
    int n = 0;
    char *s = line;
    while (*s != '\0') {
        while (*s == ' ' || *s == '\t')
            s++;
        if (*s == '\0')
            break;
        if (n == max)
            return max + 1;
        tok[n++] = s;
        while (*s != '\0' && *s != ' ' && *s != '\t')
            s++;
        if (*s != '\0')
            *s++ = '\0';
    }
    return n;
}

/* Decimal count, digits only, at most 2^63 - 1. */
static int parse_count(const char *s, uint64_t *out)
{
    uint64_t v = 0;
    if (*s == '\0')
        return 0;
    for (; *s != '\0'; s++) {
        if (*s < '0' || *s > '9')
            return 0;
        if (v > (UINT64_C(0x7FFFFFFFFFFFFFFF) - (uint64_t)(*s - '0')) / 10)
            return 0;
        v = v * 10 + (uint64_t)(*s - '0');
    }
    *out = v;
    return 1;
}

static int parse_double(const char *s, double *out)
{
    char *end;
    errno = 0;
    *out = strtod(s, &end);
    return end != s && *end == '\0' && isfinite(*out);
}

typedef struct hdr_state {
    int lineno;
    int have_format;
    int nelem;  /* 0, 1 (vertex), 2 (face) */
    int vprops; /* vertex properties seen */
    int fprops; /* face properties seen */
    int done;
} hdr_state;

static gdt_status header_line(pc_ctx *c, hdr_state *h, char *line, gdt_error *err)
{
    static const char *const xyz[3] = {"x", "y", "z"};
    char *tok[8];
    int n = tokenize(line, tok, 7);

    if (h->lineno == 1) {
        if (n != 1 || strcmp(tok[0], "ply") != 0)
            return gdt_error_set(err, GDT_EINPUT, 3360, "%s: not a PLY file (no 'ply' magic)",
                                 c->path);
        return GDT_OK;
    }
    if (n == 0)
        return GDT_OK;
    if (strcmp(tok[0], "comment") == 0) {
        if (n >= 2 && strcmp(tok[1], "lattice") == 0) {
            double v[4];
            if (c->have_lattice)
                return gdt_error_set(err, GDT_EINPUT, 3363,
                                     "%s: header line %d: second 'comment lattice' line", c->path,
                                     h->lineno);
            if (n != 6 || !parse_double(tok[2], &v[0]) || !parse_double(tok[3], &v[1]) ||
                !parse_double(tok[4], &v[2]) || !parse_double(tok[5], &v[3]) || !(v[0] > 0) ||
                !(v[1] > 0))
                return gdt_error_set(err, GDT_EINPUT, 3363,
                                     "%s: header line %d: malformed lattice comment (expected "
                                     "'comment lattice sx sy ox oy', finite, sx, sy > 0)",
                                     c->path, h->lineno);
            c->lat.sx = v[0];
            c->lat.sy = v[1];
            c->lat.ox = v[2];
            c->lat.oy = v[3];
            c->have_lattice = 1;
        }
        return GDT_OK;
    }
    if (strcmp(tok[0], "obj_info") == 0)
        return GDT_OK;
    if (strcmp(tok[0], "format") == 0) {
        if (n != 3 || strcmp(tok[1], "binary_little_endian") != 0 || strcmp(tok[2], "1.0") != 0)
            return gdt_error_set(err, GDT_EINPUT, 3362,
                                 "%s: header line %d: unsupported format (binary_little_endian "
                                 "1.0 only)",
                                 c->path, h->lineno);
        h->have_format = 1;
        return GDT_OK;
    }
    if (strcmp(tok[0], "element") == 0) {
        uint64_t cnt;
        const char *want = h->nelem == 0 ? "vertex" : "face";
        if (n != 3 || h->nelem >= 2 || strcmp(tok[1], want) != 0)
            return gdt_error_set(err, GDT_EINPUT, 3362,
                                 "%s: header line %d: expected 'element %s <count>'%s", c->path,
                                 h->lineno, want, h->nelem >= 2 ? " (no third element)" : "");
        if (!parse_count(tok[2], &cnt))
            return gdt_error_set(err, GDT_EINPUT, 3361,
                                 "%s: header line %d: element count '%s' is not a count", c->path,
                                 h->lineno, tok[2]);
        if (h->nelem == 1 && h->vprops != 3)
            return gdt_error_set(err, GDT_EINPUT, 3362,
                                 "%s: vertex element must have the properties double x, y, z",
                                 c->path);
        if (h->nelem == 0) {
            if (cnt > INT32_MAX)
                return gdt_error_set(err, GDT_EINPUT, 3365,
                                     "%s: %llu vertices cannot be addressed by int indices",
                                     c->path, (unsigned long long)cnt);
            c->V = cnt;
        } else {
            if (cnt > UINT32_MAX)
                return gdt_error_set(err, GDT_EINPUT, 3365,
                                     "%s: %llu faces: more than 2^32 - 1 is not supported", c->path,
                                     (unsigned long long)cnt);
            c->F = cnt;
        }
        h->nelem++;
        return GDT_OK;
    }
    if (strcmp(tok[0], "property") == 0) {
        if (h->nelem == 1) {
            int ok = n == 3 && h->vprops < 3 &&
                     (strcmp(tok[1], "double") == 0 || strcmp(tok[1], "float64") == 0) &&
                     strcmp(tok[2], xyz[h->vprops]) == 0;
            if (!ok)
                return gdt_error_set(err, GDT_EINPUT, 3362,
                                     "%s: header line %d: vertex properties must be exactly "
                                     "double x, double y, double z",
                                     c->path, h->lineno);
            h->vprops++;
            return GDT_OK;
        }
        if (h->nelem == 2) {
            int ok = n == 5 && h->fprops == 0 && strcmp(tok[1], "list") == 0 &&
                     (strcmp(tok[2], "uchar") == 0 || strcmp(tok[2], "uint8") == 0) &&
                     (strcmp(tok[3], "int") == 0 || strcmp(tok[3], "int32") == 0) &&
                     (strcmp(tok[4], "vertex_indices") == 0 || strcmp(tok[4], "vertex_index") == 0);
            if (!ok)
                return gdt_error_set(err, GDT_EINPUT, 3362,
                                     "%s: header line %d: the face element must have exactly "
                                     "one property 'list uchar int vertex_indices'",
                                     c->path, h->lineno);
            h->fprops++;
            return GDT_OK;
        }
        return gdt_error_set(err, GDT_EINPUT, 3361,
                             "%s: header line %d: property before any element", c->path, h->lineno);
    }
    if (strcmp(tok[0], "end_header") == 0 && n == 1) {
        if (!h->have_format)
            return gdt_error_set(err, GDT_EINPUT, 3362, "%s: header has no format line", c->path);
        if (h->nelem == 0)
            return gdt_error_set(err, GDT_EINPUT, 3362, "%s: header has no vertex element",
                                 c->path);
        if (h->vprops != 3)
            return gdt_error_set(err, GDT_EINPUT, 3362,
                                 "%s: vertex element must have the properties double x, y, z",
                                 c->path);
        if (h->nelem == 2 && h->fprops != 1)
            return gdt_error_set(err, GDT_EINPUT, 3362,
                                 "%s: the face element must have the property 'list uchar int "
                                 "vertex_indices'",
                                 c->path);
        if (!c->have_lattice)
            return gdt_error_set(err, GDT_EINPUT, 3363,
                                 "%s: no 'comment lattice sx sy ox oy' line: the lattice "
                                 "integers cannot be recovered",
                                 c->path);
        h->done = 1;
        return GDT_OK;
    }
    return gdt_error_set(err, GDT_EINPUT, 3361, "%s: header line %d: unknown keyword '%s'", c->path,
                         h->lineno, tok[0]);
}

/* Streams the header; sets hlen, V, F, lat. */
static gdt_status read_header(pc_ctx *c, gdt_error *err)
{
    unsigned char chunk[4096];
    char line[PC_LINE_MAX + 1];
    size_t len = 0;
    int overlong = 0;
    uint64_t off = 0;
    hdr_state h;
    gdt_status s;

    memset(&h, 0, sizeof h);
    h.lineno = 1;
    while (!h.done) {
        ssize_t r = pread(c->fd, chunk, sizeof chunk, (off_t)off);
        if (r < 0 && errno == EINTR)
            continue;
        if (r < 0)
            return gdt_error_set(err, GDT_EIO, 4361, "%s: cannot read: %s", c->path,
                                 strerror(errno));
        if (r == 0) {
            if (h.lineno == 1 && !(len >= 3 && memcmp(line, "ply", 3) == 0))
                return gdt_error_set(err, GDT_EINPUT, 3360, "%s: not a PLY file (no 'ply' magic)",
                                     c->path);
            return gdt_error_set(err, GDT_EINPUT, 3361,
                                 "%s: PLY header has no end_header line (file ends after %llu "
                                 "bytes)",
                                 c->path, (unsigned long long)off);
        }
        for (ssize_t i = 0; i < r && !h.done; i++) {
            unsigned char ch = chunk[i];
            if (ch != '\n') {
                if (len < PC_LINE_MAX)
                    line[len++] = (char)ch;
                else
                    overlong = 1;
                if (h.lineno == 1 && len <= 3 && ch != "ply"[len - 1])
                    return gdt_error_set(err, GDT_EINPUT, 3360,
                                         "%s: not a PLY file (no 'ply' magic)", c->path);
                continue;
            }
            if (len > 0 && line[len - 1] == '\r')
                len--;
            line[len] = '\0';
            if (overlong) {
                /* Only comment lines may be long; a lattice line never is. */
                if (strncmp(line, "comment", 7) != 0 || strncmp(line, "comment lattice", 15) == 0)
                    return gdt_error_set(err, GDT_EINPUT, 3361,
                                         "%s: header line %d is longer than %d bytes", c->path,
                                         h.lineno, PC_LINE_MAX);
            } else if ((s = header_line(c, &h, line, err)) != GDT_OK) {
                return s;
            }
            if (h.done)
                c->hlen = off + (uint64_t)i + 1;
            h.lineno++;
            len = 0;
            overlong = 0;
        }
        off += (uint64_t)r;
        if (!h.done && off > PC_MAX_HEADER)
            return gdt_error_set(err, GDT_EINPUT, 3361,
                                 "%s: no end_header within the first %llu bytes", c->path,
                                 (unsigned long long)PC_MAX_HEADER);
    }
    return GDT_OK;
}

/* ---- pass 2: lattice, bounds ---- */

static gdt_status vertex_pass(pc_ctx *c, gdt_error *err)
{
    int64_t x0 = 0, x1 = 0, y0 = 0, y1 = 0;
    gdt_plycheck_result *res = c->res;

    for (uint64_t i = 0; i < c->V; i++) {
        const unsigned char *p = c->vbase + i * PC_VERTEX_BYTES;
        double x = ldd(p), y = ldd(p + 8);
        int64_t ix, iy;
        if (!lat_int(x, c->lat.sx, c->lat.ox, &ix) || !lat_int(y, c->lat.sy, c->lat.oy, &iy))
            return gdt_error_set(err, GDT_EINTERNAL, 7360,
                                 "%s: vertex %llu at (%.17g, %.17g) is not on the lattice "
                                 "(%.17g %.17g %.17g %.17g)",
                                 c->path, (unsigned long long)i, x, y, c->lat.sx, c->lat.sy,
                                 c->lat.ox, c->lat.oy);
        if (i == 0 || ix < x0)
            x0 = ix;
        if (i == 0 || ix > x1)
            x1 = ix;
        if (i == 0 || iy < y0)
            y0 = iy;
        if (i == 0 || iy > y1)
            y1 = iy;
    }
    /* |lattice integers| < 2^53: the differences fit int64. */
    c->ox = res->origin_x = x0;
    c->oy = res->origin_y = y0;
    res->extent_x = x1 - x0;
    res->extent_y = y1 - y0;
    if (res->extent_x > GDT_COORD_MAX || res->extent_y > GDT_COORD_MAX)
        return gdt_error_set(err, GDT_EINPUT, 3366,
                             "%s: the vertices span %lld x %lld lattice units; the exact check "
                             "needs both at most 2^31 - 1",
                             c->path, (long long)res->extent_x, (long long)res->extent_y);
    return GDT_OK;
}

/* ---- pass 3: duplicate points ---- */

/* Bijective 64-bit mix (splitmix64 finaliser): equal keys iff equal points. */
static inline uint64_t mix64(uint64_t z)
{
    z = (z ^ (z >> 30)) * UINT64_C(0xbf58476d1ce4e5b9);
    z = (z ^ (z >> 27)) * UINT64_C(0x94d049bb133111eb);
    return z ^ (z >> 31);
}

static gdt_status dup_group(void *vc, const pcs_rec *g, size_t loaded, uint64_t count,
                            gdt_error *err)
{
    pc_ctx *c = vc;
    uint32_t a = UINT32_MAX, b = UINT32_MAX;

    if (count < 2)
        return GDT_OK;
    for (size_t k = 0; k < loaded; k++) {
        if (g[k].a < a)
            b = a, a = g[k].a;
        else if (g[k].a < b)
            b = g[k].a;
    }
    gdt_ipt p = pc_pt(c, a);
    return gdt_error_set(err, GDT_EINTERNAL, 7361,
                         "%s: vertices %u and %u are both at lattice point (%lld, %lld)%s", c->path,
                         a, b, PC_GLOBAL(c, p), count > 2 ? " (and more vertices with it)" : "");
}

static gdt_status dup_pass(pc_ctx *c, gdt_error *err)
{
    pcs_spill sp;
    gdt_status s;

    memset(&sp, 0, sizeof sp);
    if (c->V < 2)
        return GDT_OK;
    if ((s = pcs_spill_init(&sp, &c->env, 0, UINT64_MAX, c->V, 0, err)) != GDT_OK)
        goto fail;
    for (uint64_t i = 0; i < c->V; i++) {
        gdt_ipt p = pc_pt(c, (uint32_t)i);
        uint64_t key = mix64((uint64_t)p.x << 32 | (uint64_t)p.y);
        if ((s = pcs_spill_add(&sp, key, (uint32_t)i, 0, err)) != GDT_OK)
            goto fail;
    }
    s = pcs_spill_walk(&sp, dup_group, c, err);

fail:
    pcs_spill_free(&sp);
    return s;
}

/* No faces: legal for V < 3 or collinear vertices (distinct by pass 3). */
static gdt_status no_faces(pc_ctx *c, gdt_error *err)
{
    if (c->V < 3)
        return GDT_OK;
    gdt_ipt a = pc_pt(c, 0), b = pc_pt(c, 1);
    for (uint64_t k = 2; k < c->V; k++) {
        gdt_ipt p = pc_pt(c, (uint32_t)k);
        if (gdt_orient2d(&c->res->pred, a, b, p) != 0)
            return gdt_error_set(err, GDT_EINTERNAL, 7362,
                                 "%s: the mesh has no faces, but its %llu vertices are not "
                                 "collinear (vertices 0, 1 and %llu at (%lld, %lld), (%lld, "
                                 "%lld), (%lld, %lld))",
                                 c->path, (unsigned long long)c->V, (unsigned long long)k,
                                 PC_GLOBAL(c, a), PC_GLOBAL(c, b), PC_GLOBAL(c, p));
    }
    c->res->collinear = 1;
    return GDT_OK;
}

/* ---- pass 4: faces ---- */

typedef struct face_reader {
    unsigned char *buf;
    size_t bytes; /* allocated */
    size_t per;   /* faces per read */
} face_reader;

/* Reads faces [f, f + k) into fr->buf. */
static gdt_status read_faces(pc_ctx *c, face_reader *fr, uint64_t f, size_t k, gdt_error *err)
{
    uint64_t off = c->hlen + c->V * PC_VERTEX_BYTES + f * PC_FACE_BYTES;
    size_t want = k * PC_FACE_BYTES, got = 0;
    while (got < want) {
        ssize_t r = pread(c->fd, fr->buf + got, want - got, (off_t)(off + got));
        if (r < 0 && errno == EINTR)
            continue;
        if (r <= 0)
            return gdt_error_set(err, GDT_EIO, 4361, "%s: cannot read faces at byte %llu: %s",
                                 c->path, (unsigned long long)(off + got),
                                 r < 0 ? strerror(errno) : "unexpected end of file");
        got += (size_t)r;
    }
    return GDT_OK;
}

static gdt_status face_fault(pc_ctx *c, uint64_t f, const int32_t *t, gdt_error *err)
{
    for (int i = 0; i < 3; i++)
        if (t[i] < 0 || (uint64_t)t[i] >= c->V)
            return gdt_error_set(err, GDT_EINTERNAL, 7364,
                                 "%s: face %llu = (%d, %d, %d): vertex index %d is outside [0, "
                                 "%llu)",
                                 c->path, (unsigned long long)f, (int)t[0], (int)t[1], (int)t[2],
                                 (int)t[i], (unsigned long long)c->V);
    return gdt_error_set(err, GDT_EINTERNAL, 7365, "%s: face %llu = (%d, %d, %d) repeats a vertex",
                         c->path, (unsigned long long)f, (int)t[0], (int)t[1], (int)t[2]);
}

/* Marks the vertices of faces in [w0, w0 + wbits) and reports the first
 * vertex of that window in no face.  scan: read the faces (windows > 0;
 * window 0 is marked by face_pass). */
static gdt_status check_window(pc_ctx *c, face_reader *fr, unsigned char *bits, uint64_t w0,
                               uint64_t wbits, int scan, gdt_error *err)
{
    gdt_status s;
    if (scan) {
        memset(bits, 0, (size_t)((wbits + 7) / 8));
        for (uint64_t f = 0; f < c->F; f += fr->per) {
            size_t k = c->F - f < fr->per ? (size_t)(c->F - f) : fr->per;
            if ((s = read_faces(c, fr, f, k, err)) != GDT_OK)
                return s;
            for (size_t j = 0; j < k; j++)
                for (int i = 0; i < 3; i++) {
                    uint64_t v = ld32(fr->buf + j * PC_FACE_BYTES + 1 + 4 * (size_t)i);
                    if (v - w0 < wbits)
                        bits[(v - w0) >> 3] |= (unsigned char)(1u << ((v - w0) & 7));
                }
        }
    }
    for (uint64_t k = 0; k < wbits; k++)
        if (!(bits[k >> 3] & (1u << (k & 7)))) {
            gdt_ipt p = pc_pt(c, (uint32_t)(w0 + k));
            return gdt_error_set(err, GDT_EINTERNAL, 7367,
                                 "%s: vertex %llu at lattice point (%lld, %lld) is in no face",
                                 c->path, (unsigned long long)(w0 + k), PC_GLOBAL(c, p));
        }
    return GDT_OK;
}

static gdt_status face_pass(pc_ctx *c, pcs_spill *edges, gdt_error *err)
{
    gdt_status s = GDT_OK;
    face_reader fr;
    unsigned char *bits = NULL;
    size_t bits_bytes = 0;
    uint64_t wbits = 0;
    gdt_pred_stats *st = &c->res->pred;

    memset(&fr, 0, sizeof fr);
    fr.per = c->env.budget / 16 / PC_FACE_BYTES;
    if (fr.per > ((size_t)1 << 20) / PC_FACE_BYTES)
        fr.per = ((size_t)1 << 20) / PC_FACE_BYTES;
    fr.bytes = fr.per * PC_FACE_BYTES;
    if ((fr.buf = pcs_alloc(&c->env, fr.bytes, err)) == NULL)
        return GDT_EINTERNAL;
    /* The vertex-use bitmap is checked in windows of B/8 bytes. */
    wbits = (uint64_t)(c->env.budget / 8) * 8;
    if (wbits > c->V)
        wbits = c->V;
    bits_bytes = (size_t)((wbits + 7) / 8);
    if ((bits = pcs_alloc(&c->env, bits_bytes, err)) == NULL) {
        s = GDT_EINTERNAL;
        goto fail;
    }
    memset(bits, 0, bits_bytes);

    for (uint64_t f0 = 0; f0 < c->F; f0 += fr.per) {
        size_t k = c->F - f0 < fr.per ? (size_t)(c->F - f0) : fr.per;
        if ((s = read_faces(c, &fr, f0, k, err)) != GDT_OK)
            goto fail;
        for (size_t j = 0; j < k; j++) {
            const unsigned char *p = fr.buf + j * PC_FACE_BYTES;
            uint64_t f = f0 + j;
            int32_t t[3];
            if (p[0] != 3) {
                s = gdt_error_set(err, GDT_EINTERNAL, 7363,
                                  "%s: face %llu has %u vertex indices, not 3", c->path,
                                  (unsigned long long)f, (unsigned)p[0]);
                goto fail;
            }
            for (int i = 0; i < 3; i++)
                t[i] = (int32_t)ld32(p + 1 + 4 * (size_t)i);
            if (t[0] < 0 || t[1] < 0 || t[2] < 0 || (uint64_t)t[0] >= c->V ||
                (uint64_t)t[1] >= c->V || (uint64_t)t[2] >= c->V || t[0] == t[1] || t[1] == t[2] ||
                t[2] == t[0]) {
                s = face_fault(c, f, t, err);
                goto fail;
            }
            uint32_t u[3] = {(uint32_t)t[0], (uint32_t)t[1], (uint32_t)t[2]};
            gdt_ipt a = pc_pt(c, u[0]), b = pc_pt(c, u[1]), q = pc_pt(c, u[2]);
            int o = gdt_orient2d(st, a, b, q);
            if (o <= 0) {
                s = gdt_error_set(err, GDT_EINTERNAL, 7366,
                                  "%s: face %llu = (%u, %u, %u) at lattice points (%lld, %lld), "
                                  "(%lld, %lld), (%lld, %lld) is %s",
                                  c->path, (unsigned long long)f, u[0], u[1], u[2], PC_GLOBAL(c, a),
                                  PC_GLOBAL(c, b), PC_GLOBAL(c, q),
                                  o < 0 ? "clockwise" : "degenerate (collinear)");
                goto fail;
            }
            for (int i = 0; i < 3; i++) {
                uint32_t v = u[i], w = u[(i + 1) % 3], x = u[(i + 2) % 3];
                uint64_t key = v < w ? (uint64_t)v << 32 | w : (uint64_t)w << 32 | v;
                if (v < wbits)
                    bits[v >> 3] |= (unsigned char)(1u << (v & 7));
                if ((s = pcs_spill_add(edges, key, v < w ? x : x | PC_DIR, (uint32_t)f, err)) !=
                    GDT_OK)
                    goto fail;
            }
        }
    }
    if ((s = check_window(c, &fr, bits, 0, wbits, 0, err)) != GDT_OK)
        goto fail;
    for (uint64_t w0 = wbits; w0 < c->V; w0 += wbits) {
        uint64_t n = c->V - w0 < wbits ? c->V - w0 : wbits;
        if ((s = check_window(c, &fr, bits, w0, n, 1, err)) != GDT_OK)
            goto fail;
    }

fail:
    pcs_free(&c->env, bits, bits_bytes);
    pcs_free(&c->env, fr.buf, fr.bytes);
    return s;
}

/* ---- pass 5: edges ---- */

static gdt_status edge_group(void *vc, const pcs_rec *g, size_t loaded, uint64_t count,
                             gdt_error *err)
{
    pc_ctx *c = vc;
    gdt_plycheck_result *res = c->res;
    uint32_t lo = (uint32_t)(g[0].key >> 32), hi = (uint32_t)g[0].key;
    gdt_status s;

    if (count == 1) {
        uint32_t u = lo, v = hi;
        if (g[0].a & PC_DIR)
            u = hi, v = lo;
        res->boundary_edges++;
        if ((s = pcs_spill_add(&c->bnd, u, v | PC_OUT, g[0].b, err)) != GDT_OK)
            return s;
        return pcs_spill_add(&c->bnd, v, u, g[0].b, err);
    }
    if (count > 2)
        return gdt_error_set(err, GDT_EINTERNAL, 7368,
                             "%s: edge %u-%u is in %llu faces (faces %u, %u, %u%s)", c->path, lo,
                             hi, (unsigned long long)count, g[0].b, g[1].b, g[2].b,
                             count > 3 || loaded < count ? ", ..." : "");
    if (((g[0].a ^ g[1].a) & PC_DIR) == 0) {
        uint32_t u = (g[0].a & PC_DIR) ? hi : lo;
        return gdt_error_set(err, GDT_EINTERNAL, 7369,
                             "%s: edge %u->%u is traversed in the same direction by faces %u "
                             "and %u",
                             c->path, u, u == lo ? hi : lo, g[0].b, g[1].b);
    }
    const pcs_rec *fw = (g[0].a & PC_DIR) ? g + 1 : g;
    const pcs_rec *bw = (g[0].a & PC_DIR) ? g : g + 1;
    uint32_t ci = fw->a, di = bw->a & ~PC_DIR;
    /* Faces (lo, hi, ci) and (hi, lo, di) are counter-clockwise (pass 4). */
    gdt_ipt a = pc_pt(c, lo), b = pc_pt(c, hi), p = pc_pt(c, ci), q = pc_pt(c, di);
    res->interior_edges++;
    if (!gdt_edge_needs_flip(&res->pred, a, b, p, q) &&
        !gdt_edge_needs_flip(&res->pred, b, a, q, p))
        return GDT_OK;
    if (gdt_incircle(&res->pred, a, b, p, q) > 0)
        return gdt_error_set(err, GDT_EINTERNAL, 7370,
                             "%s: edge %u-%u (faces %u and %u) is not locally Delaunay: vertex "
                             "%u at (%lld, %lld) lies strictly inside the circumcircle of "
                             "vertices %u, %u, %u at (%lld, %lld), (%lld, %lld), (%lld, %lld)",
                             c->path, lo, hi, fw->b, bw->b, di, PC_GLOBAL(c, q), lo, hi, ci,
                             PC_GLOBAL(c, a), PC_GLOBAL(c, b), PC_GLOBAL(c, p));
    return gdt_error_set(err, GDT_EINTERNAL, 7371,
                         "%s: edge %u-%u (faces %u and %u) loses the tie-break: the quad %u, %u, "
                         "%u, %u at (%lld, %lld), (%lld, %lld), (%lld, %lld), (%lld, %lld) is "
                         "co-circular and its diagonal %u-%u is preferred",
                         c->path, lo, hi, fw->b, bw->b, lo, di, hi, ci, PC_GLOBAL(c, a),
                         PC_GLOBAL(c, q), PC_GLOBAL(c, b), PC_GLOBAL(c, p), ci, di);
}

/* ---- pass 6: boundary ---- */

static int pt_less(gdt_ipt a, gdt_ipt b)
{
    return a.x < b.x || (a.x == b.x && a.y < b.y);
}

/* For p on the line through a and b: p lies in the closed segment [a, b]. */
static int on_segment(gdt_ipt a, gdt_ipt b, gdt_ipt p)
{
    gdt_ipt lo = pt_less(a, b) ? a : b, hi = pt_less(a, b) ? b : a;
    return !pt_less(p, lo) && !pt_less(hi, p);
}

/* Direction a -> b has its angle in [0, pi). */
static int dir_upper(gdt_ipt a, gdt_ipt b)
{
    return b.y > a.y || (b.y == a.y && b.x > a.x);
}

static gdt_status bnd_group(void *vc, const pcs_rec *g, size_t loaded, uint64_t count,
                            gdt_error *err)
{
    pc_ctx *c = vc;
    uint32_t v = (uint32_t)g[0].key;

    if (count > 2)
        return gdt_error_set(err, GDT_EINTERNAL, 7372,
                             "%s: the boundary is not one simple chain: vertex %u is on %llu "
                             "boundary edges",
                             c->path, v, (unsigned long long)count);
    if (count == 1) {
        uint32_t w = g[0].a & ~PC_OUT;
        if (g[0].a & PC_OUT)
            return gdt_error_set(err, GDT_EINTERNAL, 7372,
                                 "%s: the boundary is open at vertex %u: the boundary edge "
                                 "%u->%u (face %u) leaves it, none enters it",
                                 c->path, v, v, w, g[0].b);
        return gdt_error_set(err, GDT_EINTERNAL, 7372,
                             "%s: the boundary is open at vertex %u: the boundary edge %u->%u "
                             "(face %u) enters it, none leaves it",
                             c->path, v, w, v, g[0].b);
    }
    (void)loaded;
    if (((g[0].a ^ g[1].a) & PC_OUT) == 0) {
        uint32_t w0 = g[0].a & ~PC_OUT, w1 = g[1].a & ~PC_OUT;
        if (g[0].a & PC_OUT)
            return gdt_error_set(err, GDT_EINTERNAL, 7372,
                                 "%s: the boundary is not one simple chain: vertex %u starts "
                                 "two boundary edges (%u->%u and %u->%u)",
                                 c->path, v, v, w0, v, w1);
        return gdt_error_set(err, GDT_EINTERNAL, 7372,
                             "%s: the boundary is not one simple chain: vertex %u ends two "
                             "boundary edges (%u->%u and %u->%u)",
                             c->path, v, w0, v, w1, v);
    }
    const pcs_rec *out = (g[0].a & PC_OUT) ? g : g + 1, *in = (g[0].a & PC_OUT) ? g + 1 : g;
    uint32_t ui = in->a, wi = out->a & ~PC_OUT;
    gdt_ipt pu = pc_pt(c, ui), pv = pc_pt(c, v), pw = pc_pt(c, wi);
    int o = gdt_orient2d(&c->res->pred, pu, pv, pw);
    if (o < 0 || (o == 0 && !on_segment(pu, pw, pv)))
        return gdt_error_set(err, GDT_EINTERNAL, 7373,
                             "%s: the boundary is not convex at vertex %u (%lld, %lld): %s turn "
                             "%u -> %u -> %u (%s)",
                             c->path, v, PC_GLOBAL(c, pv), o < 0 ? "reflex" : "backward", ui, v, wi,
                             o < 0 ? "a notch in the hull or a hole in the mesh"
                                   : "the boundary doubles back");
    if (!dir_upper(pu, pv) && dir_upper(pv, pw))
        c->wraps++;
    c->h++;
    return GDT_OK;
}

static gdt_status edges_and_boundary(pc_ctx *c, pcs_spill *edges, gdt_error *err)
{
    gdt_plycheck_result *res = c->res;
    gdt_status s;

    /* Boundary records stay in memory up to B/8 bytes. */
    s = pcs_spill_init(&c->bnd, &c->env, 0, c->V - 1, 0, c->env.budget / 8 / sizeof(pcs_rec), err);
    if (s != GDT_OK)
        return s;
    if ((s = pcs_spill_walk(edges, edge_group, c, err)) != GDT_OK)
        return s;
    pcs_spill_free(edges);
    if ((s = pcs_spill_walk(&c->bnd, bnd_group, c, err)) != GDT_OK)
        return s;
    res->hull_vertices = c->h;
    if (c->wraps != 1)
        return gdt_error_set(err, GDT_EINTERNAL, 7374,
                             "%s: the %llu boundary edges turn %llu times around in total, not "
                             "once: they form several loops (a hole or separate pieces)",
                             c->path, (unsigned long long)res->boundary_edges,
                             (unsigned long long)c->wraps);
    int64_t euler = 2 * (int64_t)c->V - (int64_t)c->h - 2;
    if ((int64_t)c->F != euler)
        return gdt_error_set(err, GDT_EINTERNAL, 7375,
                             "%s: Euler's relation fails: %llu faces, but 2V - h - 2 = %lld for "
                             "V = %llu vertices and h = %llu hull vertices",
                             c->path, (unsigned long long)c->F, (long long)euler,
                             (unsigned long long)c->V, (unsigned long long)c->h);
    return GDT_OK;
}

/* ---- driver ---- */

void gdt_plycheck_opts_init(gdt_plycheck_opts *opts)
{
    opts->mem_budget = GDT_PLYCHECK_DEFAULT_BUDGET;
    opts->temp_dir = NULL;
}

gdt_status gdt_ply_check(const gdt_plycheck_opts *opts, const char *path, gdt_plycheck_result *res,
                         gdt_error *err)
{
    gdt_status s = GDT_OK;
    pc_ctx c;
    pcs_spill edges;
    char *dir = NULL;
    size_t dir_bytes = 0;
    struct stat sb;

    memset(&edges, 0, sizeof edges);
    memset(&c, 0, sizeof c);
    c.fd = -1;
    if (path == NULL || res == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7376, "gdt_ply_check: NULL %s",
                             path == NULL ? "path" : "result");
    memset(res, 0, sizeof *res);
    c.path = path;
    c.res = res;
    c.env.what = path;
    c.env.budget =
        opts != NULL && opts->mem_budget > 0 ? opts->mem_budget : GDT_PLYCHECK_DEFAULT_BUDGET;
    if (c.env.budget < GDT_PLYCHECK_MIN_BUDGET)
        c.env.budget = GDT_PLYCHECK_MIN_BUDGET;
    if (c.env.budget > PC_MAX_BUDGET)
        c.env.budget = PC_MAX_BUDGET;
    res->mem_budget = c.env.budget;
    if (opts != NULL && opts->temp_dir != NULL && opts->temp_dir[0] != '\0') {
        c.env.temp_dir = opts->temp_dir;
    } else {
        const char *slash = strrchr(path, '/');
        dir_bytes = slash == NULL ? 2 : (size_t)(slash - path) + 2;
        if ((dir = pcs_alloc(&c.env, dir_bytes, err)) == NULL) {
            s = GDT_EINTERNAL;
            goto fail;
        }
        if (slash == NULL)
            memcpy(dir, ".", 2);
        else if (slash == path)
            memcpy(dir, "/", 2);
        else {
            memcpy(dir, path, (size_t)(slash - path));
            dir[slash - path] = '\0';
        }
        c.env.temp_dir = dir;
    }

    c.fd = open(path, O_RDONLY);
    if (c.fd < 0) {
        s = gdt_error_set(err, GDT_EIO, 4360, "%s: cannot open: %s", path, strerror(errno));
        goto fail;
    }
    if (fstat(c.fd, &sb) != 0) {
        s = gdt_error_set(err, GDT_EIO, 4360, "%s: cannot stat: %s", path, strerror(errno));
        goto fail;
    }
    if (!S_ISREG(sb.st_mode)) {
        s = gdt_error_set(err, GDT_EIO, 4360, "%s: not a regular file", path);
        goto fail;
    }
    if ((s = read_header(&c, err)) != GDT_OK)
        goto fail;
    res->vertices = c.V;
    res->faces = c.F;
    res->lattice = c.lat;
    {
        uint64_t need = c.hlen + c.V * PC_VERTEX_BYTES + c.F * PC_FACE_BYTES;
        uint64_t size = (uint64_t)sb.st_size;
        if (size != need) {
            s = gdt_error_set(err, GDT_EINPUT, 3364,
                              "%s: file has %llu bytes, the header (%llu vertices, %llu faces) "
                              "implies %llu (%s)",
                              path, (unsigned long long)size, (unsigned long long)c.V,
                              (unsigned long long)c.F, (unsigned long long)need,
                              size < need ? "truncated" : "trailing bytes");
            goto fail;
        }
    }
    if (c.V > 0) {
        c.map_len = (size_t)(c.hlen + c.V * PC_VERTEX_BYTES);
        void *m = mmap(NULL, c.map_len, PROT_READ, MAP_SHARED, c.fd, 0);
        if (m == MAP_FAILED) {
            s = gdt_error_set(err, GDT_EIO, 4361, "%s: cannot map the vertex section: %s", path,
                              strerror(errno));
            goto fail;
        }
        c.map = m;
        c.vbase = c.map + c.hlen;
    }

    if ((s = vertex_pass(&c, err)) != GDT_OK)
        goto fail;
    if ((s = dup_pass(&c, err)) != GDT_OK)
        goto fail;
    if (c.F == 0) {
        s = no_faces(&c, err);
        goto fail;
    }
    {
        uint64_t vmax = c.V > 0 ? c.V - 1 : 0;
        s = pcs_spill_init(&edges, &c.env, 0, vmax << 32 | vmax, 3 * c.F, 0, err);
        if (s != GDT_OK)
            goto fail;
    }
    if ((s = face_pass(&c, &edges, err)) != GDT_OK)
        goto fail;
    s = edges_and_boundary(&c, &edges, err);

fail:
    pcs_spill_free(&edges);
    pcs_spill_free(&c.bnd);
    if (c.map != NULL)
        munmap(c.map, c.map_len);
    if (c.fd >= 0)
        close(c.fd);
    pcs_free(&c.env, dir, dir_bytes);
    res->spill_bytes = c.env.spill_bytes;
    res->spill_files = c.env.spill_files;
    res->spill_splits = c.env.splits;
    res->peak_heap = c.env.peak;
    return s;
}
