/* cloud.c — several inputs as one cloud on one exact integer lattice.
 *
 * Invariants of an open cloud:
 *  - in[i].info is a deep copy of input i's header (strings owned here), and
 *    in[i].map says how its points reach the lattice.
 *  - at most one source is open (src, for input cur); cur_read points of it
 *    have been returned, next_ord points in all since the last rewind.
 *  - pass is the number of rewinds; only pass 0 lets readers' warnings
 *    through to opts.log (quiet is used otherwise).
 *  - sbuf holds scap source records; px/py (projected clouds only) hold scap
 *    doubles each.
 *  - replay (opts.replay_dir set) holds the records of the compressed inputs
 *    pass 0 read to their end (a share: to the end of its part of the
 *    input); while input cur streams from it, replaying is 1 and src is
 *    NULL.  Pass 0 writes input cur to it while recording is 1; a later
 *    pass replays an input when it reads the same records of it.
 *  - cur_read counts the records of input cur (what its header counts);
 *    next_ord counts the points kept by the filter, so ordinals have no gaps.
 *    in[i].counts (and census) describe the records of input i read in this
 *    pass: after a whole pass they are the same in every pass.
 *  - ranged (gdt_cloud_set_range): only the records [r_first, r_end) of the
 *    record sequence are read, ordinals from r_ord; input cur is read from
 *    its record cur_read to cur_end (its point count when the share ends
 *    at or after its end).
 */
#include "gdt_cloud.h"
#include "gdt_filter.h"
#include "private/cloud_lattice.h"
#include "private/crs.h"
#include "private/replay.h"

#include <ctype.h>
#include <stdarg.h>
#include <float.h>
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>

/* Source records converted per read call. */
#define CLOUD_CHUNK 4096

typedef struct cloud_input {
    char *path;
    gdt_source_info info; /* crs_wkt / crs_desc point at wkt / desc below */
    char *wkt;
    char *desc;
    gdt_cloud_input_map map;
    gdt_filter_counts counts; /* this pass so far */
    gdt_las_census *census;   /* this pass so far; opts.census only */
    uint64_t *starts;         /* a chunked (LAZ) input: the records it can start at */
    uint64_t nstarts;         /* (gdt_source_starts); 0 for other inputs */
} cloud_input;

struct gdt_cloud {
    gdt_cloud_opts opts;
    gdt_cloud_info info;
    cloud_input *in;
    size_t nin;
    char *crs_desc; /* info.crs_desc */
    gdt_crs_utm utm;
    size_t cur;
    gdt_source *src;
    uint64_t cur_read;
    uint64_t next_ord;
    unsigned long pass;
    gdt_log quiet;
    gdt_src_point *sbuf;
    uint32_t *sidx;   /* after filtering: sbuf[k] was record cur_read + sidx[k] of the chunk */
    double *px, *py;
    size_t scap;
    gdt_point_filter filter;
    gdt_error failed; /* sticky read error; status GDT_OK when none */
    gdt_replay *replay;
    struct timespec *mtime; /* per input: modification time when pass 0 read it */
    int replaying, recording;
    int replay_noted;
    uint64_t replayed_inputs; /* inputs (or their shares) read from the replay */
    /* gdt_cloud_set_range: the share [r_first, r_end) of the record
     * sequence, ordinals from r_ord; cur_end: input cur is read up to its
     * record cur_end (its point count outside a share) */
    int ranged;
    uint64_t r_first, r_end, r_ord;
    uint64_t cur_end;
};

/* ---- pure lattice and CRS decisions ---------------------------------- */

gdt_snap_result gdt_cloud_snap(double v, double origin, double step, int64_t *out)
{
    double t;
    if (!isfinite(v))
        return GDT_SNAP_NONFINITE;
    t = nearbyint((v - origin) / step);
    if (!(fabs(t) < GDT_LATTICE_LIMIT))
        return GDT_SNAP_RANGE;
    *out = (int64_t)t;
    return GDT_SNAP_OK;
}

int gdt_cloud_lattice_relation(double s_from, double o_from, double s_to, double o_to,
                               int64_t *m, int64_t *k)
{
    double rm, rk, d, noise;

    if (!isfinite(s_from) || !isfinite(o_from) || !isfinite(s_to) || !isfinite(o_to) ||
        !(s_from > 0.0) || !(s_to > 0.0))
        return 0;
    rm = nearbyint(s_from / s_to);
    if (!(rm >= 1.0 && rm <= 2097152.0))
        return 0;
    if (fabs(fma(-rm, s_to, s_from)) > 4.0 * DBL_EPSILON * s_from)
        return 0;
    noise = 4.0 * DBL_EPSILON * (fabs(o_from) + fabs(o_to));
    if (noise > 1e-4 * s_to)
        return 0;
    d = o_from - o_to;
    rk = nearbyint(d / s_to);
    if (!(fabs(rk) < 4503599627370496.0)) /* 2^52 */
        return 0;
    if (fabs(fma(-rk, s_to, d)) > fmax(1e-9 * s_to, noise))
        return 0;
    *m = (int64_t)rm;
    *k = (int64_t)rk;
    return 1;
}

int gdt_cloud_crs_known(const gdt_source_info *in)
{
    return in->format != GDT_FORMAT_PCD &&
           (in->epsg != 0 || in->crs_wkt != NULL || in->crs_geographic);
}

/* Equal up to white space outside quoted strings, keywords compared without
 * case. */
static int wkt_equal(const char *a, const char *b)
{
    int qa = 0, qb = 0;
    for (;;) {
        while (!qa && *a != '\0' && isspace((unsigned char)*a))
            a++;
        while (!qb && *b != '\0' && isspace((unsigned char)*b))
            b++;
        if (*a == '\0' || *b == '\0')
            return *a == *b;
        if (qa != qb)
            return 0;
        if (qa ? *a != *b : tolower((unsigned char)*a) != tolower((unsigned char)*b))
            return 0;
        if (*a == '"')
            qa = qb = !qa;
        a++;
        b++;
    }
}

gdt_crs_relation gdt_cloud_crs_compare(const gdt_source_info *a, const gdt_source_info *b)
{
    if (!gdt_cloud_crs_known(a) || !gdt_cloud_crs_known(b))
        return GDT_CRS_UNKNOWN;
    if ((a->crs_geographic != 0) != (b->crs_geographic != 0))
        return GDT_CRS_KIND;
    if (a->epsg != 0 && b->epsg != 0)
        return a->epsg == b->epsg ? GDT_CRS_SAME : GDT_CRS_DIFFERENT;
    if (a->crs_wkt != NULL && b->crs_wkt != NULL)
        return wkt_equal(a->crs_wkt, b->crs_wkt) ? GDT_CRS_SAME : GDT_CRS_DIFFERENT;
    return GDT_CRS_UNDECIDABLE;
}

/* Lower-cased alphanumerics of s[0..len) into out (NUL-terminated). */
static void squeeze_name(const char *s, size_t len, char *out, size_t cap)
{
    size_t j = 0;
    for (size_t i = 0; i < len && j + 1 < cap; i++) {
        if (isalnum((unsigned char)s[i]))
            out[j++] = (char)tolower((unsigned char)s[i]);
    }
    out[j] = '\0';
}

int gdt_cloud_crs_is_wgs84(const gdt_source_info *in)
{
    const char *p;

    if (in->epsg == 4326 || in->epsg == 4979)
        return 1;
    if (in->epsg != 0 || in->crs_wkt == NULL)
        return 0;
    /* The name of every DATUM (WKT1) or ENSEMBLE/DATUM (WKT2) node must be a
     * WGS 84 name; at least one must exist. */
    p = in->crs_wkt;
    int found = 0;
    for (;;) {
        const char *d1 = strstr(p, "DATUM[");
        const char *d2 = strstr(p, "ENSEMBLE[");
        const char *d = d1 == NULL ? d2 : (d2 == NULL || d1 < d2 ? d1 : d2);
        const char *q, *e;
        char name[128];
        if (d == NULL)
            break;
        q = strchr(d, '[') + 1;
        while (*q == ' ' || *q == '\t' || *q == '\n' || *q == '\r')
            q++;
        if (*q != '"') {
            p = q;
            continue;
        }
        e = strchr(q + 1, '"');
        if (e == NULL)
            return 0;
        squeeze_name(q + 1, (size_t)(e - q - 1), name, sizeof name);
        if (strstr(name, "wgs84") == NULL && strstr(name, "wgs1984") == NULL &&
            strstr(name, "worldgeodeticsystem1984") == NULL)
            return 0;
        found = 1;
        p = e + 1;
    }
    return found;
}

/* ---- opening ----------------------------------------------------------- */

static char *dup_or_null(const char *s, int *oom)
{
    char *c;
    if (s == NULL)
        return NULL;
    c = strdup(s);
    if (c == NULL)
        *oom = 1;
    return c;
}

/* Deep copy of a header; the copy's strings point into dst. */
static gdt_status copy_info(cloud_input *dst, const gdt_source_info *src, gdt_error *err)
{
    int oom = 0;
    dst->info = *src;
    dst->wkt = dup_or_null(src->crs_wkt, &oom);
    dst->desc = dup_or_null(src->crs_desc != NULL ? src->crs_desc : "", &oom);
    if (oom)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    dst->info.crs_wkt = dst->wkt;
    dst->info.crs_desc = dst->desc;
    return GDT_OK;
}

static const char *crs_label(const cloud_input *ci, char *buf, size_t cap)
{
    if (ci->info.crs_desc != NULL && ci->info.crs_desc[0] != '\0')
        return ci->info.crs_desc;
    if (ci->info.epsg != 0) {
        snprintf(buf, cap, "EPSG:%d", ci->info.epsg);
        return buf;
    }
    return ci->info.crs_wkt != NULL ? "a WKT CRS" : "unknown CRS";
}

/* Every input with a known CRS agrees with the first such input, *ref
 * (SIZE_MAX when no input has a CRS). */
static gdt_status check_crs(gdt_cloud *c, size_t *ref, gdt_error *err)
{
    char b1[32], b2[32];
    *ref = SIZE_MAX;
    for (size_t i = 0; i < c->nin; i++) {
        const cloud_input *a, *b;
        gdt_crs_relation rel;
        if (!gdt_cloud_crs_known(&c->in[i].info))
            continue;
        if (*ref == SIZE_MAX) {
            *ref = i;
            continue;
        }
        a = &c->in[*ref];
        b = &c->in[i];
        rel = gdt_cloud_crs_compare(&a->info, &b->info);
        if (rel == GDT_CRS_KIND)
            return gdt_error_set(err, GDT_EINPUT, 3411,
                                 "%s is in %s (%s) but %s is in %s (%s): inputs in different "
                                 "CRSs cannot form one cloud",
                                 b->path, crs_label(b, b2, sizeof b2),
                                 b->info.crs_geographic ? "geographic" : "projected", a->path,
                                 crs_label(a, b1, sizeof b1),
                                 a->info.crs_geographic ? "geographic" : "projected");
        if (rel == GDT_CRS_DIFFERENT)
            return gdt_error_set(err, GDT_EINPUT, 3410,
                                 "%s is in %s but %s is in %s: inputs in different CRSs "
                                 "cannot form one cloud",
                                 b->path, crs_label(b, b2, sizeof b2), a->path,
                                 crs_label(a, b1, sizeof b1));
        if (rel == GDT_CRS_UNDECIDABLE)
            return gdt_error_set(err, GDT_EINPUT, 3412,
                                 "%s is in %s but %s is in %s, and these cannot be shown to be "
                                 "one CRS (one gives only an EPSG code, the other a WKT without "
                                 "one): inputs in different CRSs cannot form one cloud",
                                 b->path, crs_label(b, b2, sizeof b2), a->path,
                                 crs_label(a, b1, sizeof b1));
    }
    return GDT_OK;
}

static gdt_status set_desc(gdt_cloud *c, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

static gdt_status set_desc(gdt_cloud *c, const char *fmt, ...)
{
    va_list ap;
    char tmp[512];
    va_start(ap, fmt);
    vsnprintf(tmp, sizeof tmp, fmt, ap);
    va_end(ap);
    free(c->crs_desc);
    c->crs_desc = strdup(tmp);
    if (c->crs_desc == NULL)
        return GDT_EINTERNAL;
    c->info.crs_desc = c->crs_desc;
    return GDT_OK;
}

/* Projected cloud: zone from the centre of the union of header bounds. */
static gdt_status plan_projected(gdt_cloud *c, const cloud_input *ref, gdt_error *err)
{
    double lo[2] = {INFINITY, INFINITY}, hi[2] = {-INFINITY, -INFINITY};
    char src_label[256];
    gdt_error local;
    size_t nb = 0;

    for (size_t i = 0; i < c->nin; i++) {
        const gdt_source_info *in = &c->in[i].info;
        if (!in->has_bounds)
            continue;
        for (int a = 0; a < 2; a++) {
            if (!isfinite(in->min[a]) || !isfinite(in->max[a]) || in->min[a] > in->max[a] ||
                (a == 1 && (in->min[a] < -90.0 || in->max[a] > 90.0)) ||
                (a == 0 && (in->min[a] < -540.0 || in->max[a] >= 540.0)))
                return gdt_error_set(err, GDT_EINPUT, 3460,
                                     "%s: header bounds (%.9g..%.9g, %.9g..%.9g) are not "
                                     "longitude/latitude degrees",
                                     c->in[i].path, in->min[0], in->max[0], in->min[1],
                                     in->max[1]);
            lo[a] = fmin(lo[a], in->min[a]);
            hi[a] = fmax(hi[a], in->max[a]);
        }
        nb++;
    }
    if (nb == 0)
        return gdt_error_set(err, GDT_EINPUT, 3460,
                             "%s: geographic input without header bounds: cannot choose the "
                             "UTM/UPS zone",
                             ref->path);
    gdt_error_clear(&local);
    if (gdt_crs_utm_pick(0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), &c->utm, &local) !=
        GDT_OK)
        return gdt_error_set(err, local.status, local.code, "%s: %s", ref->path, local.msg);
    if (ref->info.epsg != 0)
        snprintf(src_label, sizeof src_label, "EPSG:%d", ref->info.epsg);
    else
        snprintf(src_label, sizeof src_label, "%s",
                 ref->info.crs_desc[0] != '\0' ? ref->info.crs_desc : "geographic lon/lat");
    if (!gdt_cloud_crs_is_wgs84(&ref->info))
        gdt_log_warn(c->opts.log, 3421,
                     "%s: geographic CRS %s is not WGS 84; it is projected as if it were "
                     "WGS 84 (positions may be off by up to a few metres)",
                     ref->path, src_label);
    c->info.lattice.sx = c->info.lattice.sy = c->opts.quantum;
    c->info.lattice.ox = c->info.lattice.oy = 0.0;
    c->info.projected = 1;
    c->info.utm_zone = c->utm.zone;
    c->info.utm_north = c->utm.north;
    c->info.epsg = c->utm.epsg;
    c->info.crs_wkt = NULL;
    for (size_t i = 0; i < c->nin; i++)
        c->in[i].map.kind = GDT_CLOUD_MAP_PROJECT;
    if (set_desc(c, "EPSG:%d (%s, projected from %s)", c->utm.epsg, c->utm.name,
                 src_label) != GDT_OK)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    gdt_log_note(c->opts.log, "lon/lat input projected to %s", c->info.crs_desc);
    return GDT_OK;
}

static int las_lattice_usable(const gdt_source_info *in)
{
    return in->format == GDT_FORMAT_LAS && in->has_lattice && isfinite(in->scale[0]) &&
           isfinite(in->scale[1]) && in->scale[0] > 0.0 && in->scale[1] > 0.0 &&
           isfinite(in->offset[0]) && isfinite(in->offset[1]) &&
           /* every int32 record maps to a finite CRS coordinate (the PLY's) */
           isfinite(fabs(in->offset[0]) + in->scale[0] * 2147483648.0) &&
           isfinite(fabs(in->offset[1]) + in->scale[1] * 2147483648.0);
}

/* Planar cloud: lattice of the first LAS input, else the quantum lattice. */
static gdt_status plan_planar(gdt_cloud *c, size_t ref, gdt_error *err)
{
    size_t first = SIZE_MAX;
    gdt_lattice *L = &c->info.lattice;
    gdt_status st;

    for (size_t i = 0; i < c->nin && first == SIZE_MAX; i++)
        if (las_lattice_usable(&c->in[i].info))
            first = i;
    if (first != SIZE_MAX) {
        const gdt_source_info *f = &c->in[first].info;
        L->sx = f->scale[0];
        L->sy = f->scale[1];
        L->ox = f->offset[0];
        L->oy = f->offset[1];
        c->info.lattice_native = 1;
        c->info.lattice_input = first;
        gdt_log_note(c->opts.log, "lattice of %s (scale %.17g %.17g, offset %.17g %.17g); "
                     "the quantum is not used", c->in[first].path, L->sx, L->sy, L->ox, L->oy);
    } else {
        L->sx = L->sy = c->opts.quantum;
        L->ox = L->oy = 0.0;
    }
    for (size_t i = 0; i < c->nin; i++) {
        cloud_input *ci = &c->in[i];
        gdt_cloud_input_map *m = &ci->map;
        if (i == first) {
            m->kind = GDT_CLOUD_MAP_NATIVE;
            m->mx = m->my = 1;
            m->kx = m->ky = 0;
        } else if (las_lattice_usable(&ci->info) &&
                   gdt_cloud_lattice_relation(ci->info.scale[0], ci->info.offset[0], L->sx,
                                              L->ox, &m->mx, &m->kx) &&
                   gdt_cloud_lattice_relation(ci->info.scale[1], ci->info.offset[1], L->sy,
                                              L->oy, &m->my, &m->ky)) {
            m->kind = GDT_CLOUD_MAP_SHIFT;
            gdt_log_note(c->opts.log,
                         "%s: lattice maps exactly onto that of %s (x: %" PRId64 " X + %" PRId64
                         ", y: %" PRId64 " Y + %" PRId64 ")",
                         ci->path, c->in[first].path, m->mx, m->kx, m->my, m->ky);
        } else {
            m->kind = GDT_CLOUD_MAP_SNAP;
            m->mx = m->my = m->kx = m->ky = 0;
            if (ci->info.format == GDT_FORMAT_LAS && first != SIZE_MAX)
                gdt_log_warn(c->opts.log, 3420,
                             "%s: its lattice (scale %.17g %.17g, offset %.17g %.17g) is not an "
                             "integer shift of the lattice of %s (scale %.17g %.17g, offset "
                             "%.17g %.17g); its points are snapped to that lattice",
                             ci->path, ci->info.scale[0], ci->info.scale[1], ci->info.offset[0],
                             ci->info.offset[1], c->in[first].path, L->sx, L->sy, L->ox, L->oy);
            else if (first != SIZE_MAX)
                gdt_log_note(c->opts.log, "%s: float coordinates snapped to the lattice of %s",
                             ci->path, c->in[first].path);
        }
    }
    if (ref != SIZE_MAX) {
        char b[32];
        c->info.epsg = c->in[ref].info.epsg;
        c->info.crs_wkt = c->in[ref].info.crs_wkt;
        st = set_desc(c, "%s", crs_label(&c->in[ref], b, sizeof b));
    } else {
        st = set_desc(c, "unknown");
    }
    if (st != GDT_OK)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    return GDT_OK;
}

/* The filter against input ci: class and return tests need LAS
 * attributes; a class list naming codes above 31 is worth a warning for a
 * legacy format, which cannot hold them. */
static gdt_status check_filter(gdt_cloud *c, cloud_input *ci, gdt_error *err)
{
    const gdt_point_filter *f = &c->filter;
    if (ci->info.format != GDT_FORMAT_LAS && gdt_filter_uses_attributes(f))
        return gdt_error_set(err, GDT_EUSAGE, 2305,
                             "%s: a %s file has no point classes or return numbers; "
                             "--keep-class, --drop-class and --returns apply to LAS input only",
                             ci->path, ci->info.format_name);
    if (ci->info.format == GDT_FORMAT_LAS && ci->info.point_format <= 5 &&
        gdt_filter_names_high_class(f))
        gdt_log_warn(c->opts.log, 3430,
                     "%s: point format %u stores classes 0-31 only; the classes above 31 "
                     "named by %s match none of its points",
                     ci->path, ci->info.point_format,
                     f->class_mode > 0 ? "--keep-class" : "--drop-class");
    if (c->opts.census) {
        ci->census = calloc(1, sizeof *ci->census);
        if (ci->census == NULL)
            return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    }
    return GDT_OK;
}

gdt_status gdt_cloud_open(gdt_cloud **out, const char *const *paths, size_t npaths,
                          const gdt_cloud_opts *opts, gdt_error *err)
{
    gdt_cloud *c = NULL;
    gdt_source *src = NULL;
    gdt_source_opts so;
    gdt_status st;
    size_t ref;

    *out = NULL;
    if (paths == NULL || npaths == 0)
        return gdt_error_set(err, GDT_EUSAGE, 2401, "no input file given");
    if (opts != NULL && (!isfinite(opts->quantum) || opts->quantum < 0.0))
        return gdt_error_set(err, GDT_EUSAGE, 2401, "quantum %g is not a positive number",
                             opts->quantum);
    c = calloc(1, sizeof *c);
    if (c == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    if (opts != NULL)
        c->opts = *opts;
    if (c->opts.filter != NULL)
        c->filter = *c->opts.filter;
    c->opts.filter = NULL; /* the copy above is the cloud's */
    if (c->opts.quantum == 0.0)
        c->opts.quantum = GDT_CLOUD_DEFAULT_QUANTUM;
    gdt_error_clear(&c->failed);
    c->in = calloc(npaths, sizeof *c->in);
    if (c->in == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    c->nin = npaths;
    c->info.ninputs = npaths;
    gdt_log_init(&c->quiet, -1);
    memset(&so, 0, sizeof so);
    so.log = &c->quiet;
    so.buffer_bytes = c->opts.buffer_bytes;
    for (size_t i = 0; i < npaths; i++) {
        cloud_input *ci = &c->in[i];
        ci->path = strdup(paths[i] != NULL ? paths[i] : "");
        if (ci->path == NULL) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
            goto fail;
        }
        st = gdt_source_open(&src, ci->path, &so, err);
        if (st != GDT_OK)
            goto fail;
        st = copy_info(ci, gdt_source_get_info(src), err);
        if (st == GDT_OK && (ci->nstarts = gdt_source_starts(src, NULL, 0)) > 0) {
            ci->starts = malloc(ci->nstarts * sizeof *ci->starts);
            if (ci->starts == NULL)
                st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
            else
                gdt_source_starts(src, ci->starts, ci->nstarts);
        }
        gdt_source_close(src);
        src = NULL;
        if (st != GDT_OK)
            goto fail;
        if (ci->info.point_count > UINT64_MAX - c->info.point_count) {
            st = gdt_error_set(err, GDT_EINPUT, 3404, "%s: total point count overflows",
                               ci->path);
            goto fail;
        }
        c->info.point_count += ci->info.point_count;
        st = check_filter(c, ci, err);
        if (st != GDT_OK)
            goto fail;
    }
    st = check_crs(c, &ref, err);
    if (st != GDT_OK)
        goto fail;
    if (ref != SIZE_MAX && c->in[ref].info.crs_geographic)
        st = plan_projected(c, &c->in[ref], err);
    else
        st = plan_planar(c, ref, err);
    if (st != GDT_OK)
        goto fail;
    c->scap = CLOUD_CHUNK;
    c->sbuf = malloc(c->scap * sizeof *c->sbuf);
    c->sidx = malloc(c->scap * sizeof *c->sidx);
    if (c->sidx == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    if (c->info.projected) {
        c->px = malloc(c->scap * sizeof *c->px);
        c->py = malloc(c->scap * sizeof *c->py);
    }
    if (c->sbuf == NULL || (c->info.projected && (c->px == NULL || c->py == NULL))) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    if (c->opts.replay_dir != NULL) {
        int any = 0;
        for (size_t i = 0; i < npaths; i++)
            any |= c->in[i].info.compressed;
        if (any) {
            gdt_error local;
            gdt_error_clear(&local);
            c->mtime = calloc(npaths, sizeof *c->mtime);
            if (c->mtime == NULL)
                gdt_error_set(&local, GDT_EINTERNAL, 7001, "out of memory");
            else
                gdt_replay_open(&c->replay, c->opts.replay_dir, &local);
            if (c->replay == NULL)
                gdt_log_note(c->opts.log, "%s; compressed inputs are decoded in every pass",
                             local.msg);
        }
    }
    *out = c;
    return GDT_OK;
fail:
    gdt_source_close(src);
    gdt_cloud_close(c);
    return st;
}

const gdt_cloud_info *gdt_cloud_get_info(const gdt_cloud *cloud) { return &cloud->info; }

uint64_t gdt_cloud_replayed(const gdt_cloud *cloud)
{
    return cloud != NULL ? cloud->replayed_inputs : 0;
}

const gdt_source_info *gdt_cloud_input_info(const gdt_cloud *cloud, size_t i)
{
    return i < cloud->nin ? &cloud->in[i].info : NULL;
}

const char *gdt_cloud_input_path(const gdt_cloud *cloud, size_t i)
{
    return i < cloud->nin ? cloud->in[i].path : NULL;
}

const gdt_cloud_input_map *gdt_cloud_input_map_of(const gdt_cloud *cloud, size_t i)
{
    return i < cloud->nin ? &cloud->in[i].map : NULL;
}

/* ---- streaming ----------------------------------------------------------- */

/* Starts input c->cur from the replay file, after checking by its size and
 * modification time that the file is still the one pass 0 decoded. */
static gdt_status replay_current(gdt_cloud *c, uint64_t lo, gdt_error *err)
{
    const cloud_input *ci = &c->in[c->cur];
    struct stat sb;

    if (stat(ci->path, &sb) != 0 || (uint64_t)sb.st_size != ci->info.file_size ||
        sb.st_mtim.tv_sec != c->mtime[c->cur].tv_sec ||
        sb.st_mtim.tv_nsec != c->mtime[c->cur].tv_nsec)
        return gdt_error_set(err, GDT_EINPUT, 3405,
                             "%s: the file changed since it was opened (size or modification "
                             "time differ)",
                             ci->path);
    c->cur_read = lo;
    c->replaying = 1;
    c->replayed_inputs++;
    gdt_log_note(c->opts.log, "%s: reading the points decoded by the first pass", ci->path);
    return gdt_replay_start(c->replay, c->cur, ci->info.scale, ci->info.offset, err);
}

/* Opens input c->cur for its records [lo, hi) (seeking is the caller's)
 * and checks it is still the file seen at open, or replays them. */
static gdt_status open_current(gdt_cloud *c, uint64_t lo, uint64_t hi, gdt_error *err)
{
    const cloud_input *ci = &c->in[c->cur];
    const gdt_source_info *now;
    gdt_source_opts so;
    gdt_status st;

    if (c->pass > 0 && gdt_replay_has(c->replay, c->cur, lo, hi))
        return replay_current(c, lo, err);

    memset(&so, 0, sizeof so);
    so.log = c->pass == 0 ? c->opts.log : &c->quiet;
    so.buffer_bytes = c->opts.buffer_bytes;
    so.need = c->opts.census ? GDT_SRC_NEED_XYZ | GDT_SRC_NEED_ATTRS
                             : gdt_filter_need(&c->filter);
    so.threads = c->opts.threads;
    st = gdt_source_open(&c->src, ci->path, &so, err);
    if (st != GDT_OK)
        return st;
    now = gdt_source_get_info(c->src);
    if (now->format != ci->info.format || now->point_count != ci->info.point_count ||
        now->file_size != ci->info.file_size || now->has_lattice != ci->info.has_lattice ||
        memcmp(now->scale, ci->info.scale, sizeof now->scale) != 0 ||
        memcmp(now->offset, ci->info.offset, sizeof now->offset) != 0 ||
        now->epsg != ci->info.epsg || now->crs_geographic != ci->info.crs_geographic)
        return gdt_error_set(err, GDT_EINPUT, 3405,
                             "%s: the file changed since it was opened (header or size differ)",
                             ci->path);
    c->cur_read = 0;
    if (c->pass == 0 && c->replay != NULL && ci->info.compressed) {
        struct stat sb;
        if (stat(ci->path, &sb) == 0) {
            c->mtime[c->cur] = sb.st_mtim;
            gdt_replay_begin(c->replay, c->cur, lo, hi);
            c->recording = 1;
        }
    }
    return GDT_OK;
}

/* Ends input c->cur's stream (complete: read to its end). */
static void end_current(gdt_cloud *c, int complete)
{
    gdt_source_close(c->src);
    c->src = NULL;
    c->replaying = 0;
    if (c->recording) {
        if (complete)
            gdt_replay_end(c->replay);
        else
            gdt_replay_abandon(c->replay);
        c->recording = 0;
        if (gdt_replay_failed(c->replay) != NULL && !c->replay_noted) {
            gdt_log_note(c->opts.log, "keeping decoded points for the next pass stopped (%s);"
                         " compressed inputs from %s on are decoded again",
                         gdt_replay_failed(c->replay), c->in[c->cur].path);
            c->replay_noted = 1;
        }
    }
}

static gdt_status bad_point(const gdt_cloud *c, uint64_t idx, gdt_snap_result r, char axis,
                            double v, gdt_error *err)
{
    const char *path = c->in[c->cur].path;
    if (r == GDT_SNAP_NONFINITE)
        return gdt_error_set(err, GDT_EINPUT, 3401, "%s: point %" PRIu64 ": %c = %g is not finite",
                             path, idx, axis, v);
    return gdt_error_set(err, GDT_EINPUT, 3402,
                         "%s: point %" PRIu64 ": %c = %.17g is outside the lattice range "
                         "(|%c - origin| / step must stay below 2^53)",
                         path, idx, axis, v, axis);
}

/* Converts the got filtered records of sbuf into out[0..got). */
static gdt_status convert(gdt_cloud *c, size_t got, gdt_point *out, gdt_error *err)
{
    const cloud_input *ci = &c->in[c->cur];
    const gdt_cloud_input_map *m = &ci->map;
    const gdt_lattice *L = &c->info.lattice;
    const uint64_t base = c->next_ord;
    gdt_snap_result r;

    if (m->kind == GDT_CLOUD_MAP_PROJECT) {
        size_t bad = 0;
        gdt_error local;
        for (size_t i = 0; i < got; i++) {
            c->px[i] = c->sbuf[i].x;
            c->py[i] = c->sbuf[i].y;
        }
        gdt_error_clear(&local);
        if (gdt_crs_utm_forward(&c->utm, c->px, c->py, got, c->px, c->py, &bad, &local) !=
            GDT_OK)
            return gdt_error_set(err, local.status, local.code, "%s: point %" PRIu64 ": %s",
                                 ci->path, c->cur_read + c->sidx[bad], local.msg);
    }
    for (size_t i = 0; i < got; i++) {
        const gdt_src_point *s = &c->sbuf[i];
        gdt_point *p = &out[i];
        const uint64_t idx = c->cur_read + c->sidx[i];
        if (!isfinite(s->z))
            return bad_point(c, idx, GDT_SNAP_NONFINITE, 'z', s->z, err);
        switch (m->kind) {
        case GDT_CLOUD_MAP_NATIVE:
        case GDT_CLOUD_MAP_SHIFT:
            /* |m| <= 2^21, |X| < 2^31, |k| < 2^52: no overflow in int64. */
            p->x = m->mx * (int64_t)s->X + m->kx;
            p->y = m->my * (int64_t)s->Y + m->ky;
            if (!(fabs((double)p->x) < GDT_LATTICE_LIMIT))
                return bad_point(c, idx, GDT_SNAP_RANGE, 'x', s->x, err);
            if (!(fabs((double)p->y) < GDT_LATTICE_LIMIT))
                return bad_point(c, idx, GDT_SNAP_RANGE, 'y', s->y, err);
            break;
        case GDT_CLOUD_MAP_SNAP:
            if ((r = gdt_cloud_snap(s->x, L->ox, L->sx, &p->x)) != GDT_SNAP_OK)
                return bad_point(c, idx, r, 'x', s->x, err);
            if ((r = gdt_cloud_snap(s->y, L->oy, L->sy, &p->y)) != GDT_SNAP_OK)
                return bad_point(c, idx, r, 'y', s->y, err);
            break;
        case GDT_CLOUD_MAP_PROJECT:
            if ((r = gdt_cloud_snap(c->px[i], 0.0, L->sx, &p->x)) != GDT_SNAP_OK)
                return bad_point(c, idx, r, 'x', c->px[i], err);
            if ((r = gdt_cloud_snap(c->py[i], 0.0, L->sy, &p->y)) != GDT_SNAP_OK)
                return bad_point(c, idx, r, 'y', c->py[i], err);
            break;
        }
        p->z = s->z;
        p->ord = base + i;
    }
    return GDT_OK;
}

/* Applies the filter to the got records of sbuf: the kept ones move to the
 * front in file order, sidx[k] their place in the chunk; counts (and the
 * census) take every record.  Returns the number kept. */
static size_t filter_chunk(gdt_cloud *c, size_t got)
{
    cloud_input *ci = &c->in[c->cur];
    gdt_filter_counts *k = &ci->counts;
    size_t kept = 0;
    for (size_t i = 0; i < got; i++) {
        const gdt_src_point *p = &c->sbuf[i];
        if (ci->census != NULL)
            gdt_las_census_add(ci->census, p);
        switch (gdt_filter_test(&c->filter, p)) {
        case GDT_KEEP:
            if (kept != i)
                c->sbuf[kept] = *p;
            c->sidx[kept++] = (uint32_t)i;
            break;
        case GDT_DROP_WITHHELD: k->drop_withheld++; break;
        case GDT_DROP_CLASS: k->drop_class++; break;
        case GDT_DROP_RETURN: k->drop_return++; break;
        }
    }
    k->read += got;
    k->kept += kept;
    return kept;
}

/* After the first pass over input i: a note with its counts; after the last
 * input, a warning when the filter kept none of the points read. */
static void report_filter(gdt_cloud *c, size_t i)
{
    const gdt_filter_counts *k = &c->in[i].counts;
    gdt_log_note(c->opts.log,
                 "%s: %" PRIu64 " records, %" PRIu64 " kept (dropped: %" PRIu64
                 " by class, %" PRIu64 " by return, %" PRIu64 " withheld)",
                 c->in[i].path, k->read, k->kept, k->drop_class, k->drop_return,
                 k->drop_withheld);
    if (i + 1 == c->nin) {
        gdt_filter_counts t = gdt_cloud_total_counts(c);
        char d[1200];
        if (t.read > 0 && t.kept == 0) {
            gdt_filter_describe(&c->filter, d, sizeof d);
            gdt_log_warn(c->opts.log, 3431,
                         "the point filter (%s) kept none of the %" PRIu64 " points read", d,
                         t.read);
        }
    }
}

/* The first record of input i in the record sequence. */
static uint64_t input_base(const gdt_cloud *c, size_t i)
{
    uint64_t b = 0;
    for (size_t k = 0; k < i; k++)
        b += c->in[k].info.point_count;
    return b;
}

/* 1 when input i can start at any record (fixed-size records: uncompressed
 * LAS, PCD binary; gdt_source_can_seek). */
static int input_seekable(const cloud_input *ci)
{
    return (ci->info.format == GDT_FORMAT_LAS && !ci->info.compressed) ||
           (ci->info.format == GDT_FORMAT_PCD && strcmp(ci->info.encoding, "binary") == 0);
}

/* 1 when input ci can be read from record r on, and up to it: its ends,
 * any record of uncompressed LAS and PCD binary, the chunk starts of LAZ. */
static int input_cuts_at(const cloud_input *ci, uint64_t r)
{
    uint64_t lo = 0, hi = ci->nstarts;
    if (r == 0 || r >= ci->info.point_count || input_seekable(ci))
        return 1;
    while (lo < hi) { /* the first start >= r */
        uint64_t mid = lo + (hi - lo) / 2;
        if (ci->starts[mid] < r)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo < ci->nstarts && ci->starts[lo] == r;
}

/* The record nearest to r (0 <= r <= its count) where input ci can be
 * cut (the upper one of two as near). */
static uint64_t input_cut_near(const cloud_input *ci, uint64_t r)
{
    uint64_t n = ci->info.point_count, below = 0, above = n, lo = 0, hi = ci->nstarts;
    if (input_seekable(ci))
        return r;
    while (lo < hi) { /* the first start > r */
        uint64_t mid = lo + (hi - lo) / 2;
        if (ci->starts[mid] <= r)
            lo = mid + 1;
        else
            hi = mid;
    }
    if (lo > 0)
        below = ci->starts[lo - 1];
    if (lo < ci->nstarts)
        above = ci->starts[lo];
    return r - below < above - r ? below : above;
}

/* The records [*lo, *hi) of input i in the share; 0 when there are none. */
static int share_of(const gdt_cloud *c, size_t i, uint64_t *lo, uint64_t *hi)
{
    uint64_t b = input_base(c, i), e = b + c->in[i].info.point_count;
    uint64_t a = b > c->r_first ? b : c->r_first, z = e < c->r_end ? e : c->r_end;
    if (a >= z)
        return 0;
    *lo = a - b;
    *hi = z - b;
    return 1;
}

gdt_status gdt_cloud_set_range(gdt_cloud *cloud, uint64_t first, uint64_t end,
                               uint64_t ord_base, gdt_error *err)
{
    if (cloud->src != NULL || cloud->replaying || cloud->cur != 0 || cloud->cur_read != 0 ||
        cloud->next_ord != cloud->r_ord)
        gdt_cloud_rewind(cloud, err);
    if (first > end)
        return gdt_error_set(err, GDT_EINTERNAL, 7403, "share [%" PRIu64 ", %" PRIu64 ") of "
                             "the cloud is empty the wrong way round", first, end);
    for (size_t i = 0; i < cloud->nin; i++) {
        uint64_t b = input_base(cloud, i), e = b + cloud->in[i].info.point_count;
        if ((first > b && first < e && !input_cuts_at(&cloud->in[i], first - b)) ||
            (end > b && end < e && !input_cuts_at(&cloud->in[i], end - b)))
            return gdt_error_set(err, GDT_EINTERNAL, 7403,
                                 "%s: a share of the cloud cannot start or end there "
                                 "(it is read from its first record%s)",
                                 cloud->in[i].path,
                                 cloud->in[i].nstarts > 0 ? " or a chunk's" : "");
    }
    cloud->ranged = !(first == 0 && end == UINT64_MAX);
    cloud->r_first = first;
    cloud->r_end = end;
    cloud->r_ord = ord_base;
    cloud->next_ord = ord_base;
    return GDT_OK;
}

int gdt_cloud_split(const gdt_cloud *cloud, int n, uint64_t *bounds)
{
    uint64_t total = input_base(cloud, cloud->nin);
    int ok = 1;
    for (size_t i = 0; i < cloud->nin; i++)
        ok &= !cloud->in[i].info.compressed || cloud->in[i].nstarts > 1;
    bounds[0] = 0;
    for (int j = 1; j < n; j++) {
        /* floor(total * j / n) without overflow */
        uint64_t t = total / (uint64_t)n * (uint64_t)j +
                     total % (uint64_t)n * (uint64_t)j / (uint64_t)n;
        uint64_t b = 0;
        size_t i = 0;
        while (i < cloud->nin && b + cloud->in[i].info.point_count <= t)
            b += cloud->in[i++].info.point_count;
        if (i < cloud->nin && t > b)
            t = b + input_cut_near(&cloud->in[i], t - b);
        bounds[j] = t > bounds[j - 1] ? t : bounds[j - 1];
    }
    bounds[n] = total;
    return ok;
}

void gdt_cloud_add_counts(gdt_cloud *cloud, size_t i, const gdt_filter_counts *k)
{
    if (i < cloud->nin)
        gdt_filter_counts_add(&cloud->in[i].counts, k);
}

void gdt_cloud_report_counts(gdt_cloud *cloud)
{
    for (size_t i = 0; i < cloud->nin; i++)
        report_filter(cloud, i);
}

gdt_status gdt_cloud_read(gdt_cloud *cloud, gdt_point *buf, size_t cap, size_t *n,
                          gdt_error *err)
{
    gdt_status st;
    size_t got = 0, kept;

    *n = 0;
    if (cloud->failed.status != GDT_OK)
        return gdt_error_set(err, cloud->failed.status, cloud->failed.code, "%s",
                             cloud->failed.msg);
    if (buf == NULL || cap == 0)
        return gdt_error_set(err, GDT_EINTERNAL, 7402, "gdt_cloud_read: empty buffer");
    while (cloud->cur < cloud->nin) {
        const cloud_input *ci = &cloud->in[cloud->cur];
        size_t want = cap < cloud->scap ? cap : cloud->scap;
        if (cloud->src == NULL && !cloud->replaying) {
            uint64_t lo = 0, hi = ci->info.point_count;
            if (cloud->ranged && !share_of(cloud, cloud->cur, &lo, &hi)) {
                cloud->cur++;
                continue;
            }
            st = open_current(cloud, lo, hi, &cloud->failed);
            if (st == GDT_OK && !cloud->replaying) {
                /* a replay holds just these records; a source seeks */
                if (lo > 0 || hi < ci->info.point_count)
                    st = gdt_source_seek(cloud->src, lo, hi, &cloud->failed);
                cloud->cur_read = lo;
            }
            cloud->cur_end = hi;
            if (st != GDT_OK)
                goto fail;
        }
        if (cloud->cur_end < ci->info.point_count) {
            /* a share that ends inside this input: its records are complete */
            if (cloud->cur_read == cloud->cur_end) {
                end_current(cloud, 1);
                cloud->cur++;
                continue;
            }
            if (want > cloud->cur_end - cloud->cur_read)
                want = (size_t)(cloud->cur_end - cloud->cur_read);
        }
        if (cloud->replaying)
            st = gdt_replay_read(cloud->replay, cloud->sbuf, want, &got, &cloud->failed);
        else
            st = gdt_source_read(cloud->src, cloud->sbuf, want, &got, &cloud->failed);
        if (st != GDT_OK)
            goto fail;
        if (cloud->recording)
            gdt_replay_append(cloud->replay, cloud->sbuf, got);
        if (got == 0) {
            if (ci->info.format == GDT_FORMAT_LAS && cloud->cur_read != ci->info.point_count) {
                st = gdt_error_set(&cloud->failed, GDT_EINPUT, 3404,
                                   "%s: holds %" PRIu64 " points but its header says %" PRIu64,
                                   ci->path, cloud->cur_read, ci->info.point_count);
                goto fail;
            }
            end_current(cloud, 1);
            if (cloud->pass == 0 && !cloud->ranged)
                report_filter(cloud, cloud->cur);
            cloud->cur++;
            continue;
        }
        if (got > ci->info.point_count - cloud->cur_read) {
            st = gdt_error_set(&cloud->failed, GDT_EINPUT, 3404,
                               "%s: holds more points than its header says (%" PRIu64 ")",
                               ci->path, ci->info.point_count);
            goto fail;
        }
        kept = filter_chunk(cloud, got);
        st = convert(cloud, kept, buf, &cloud->failed);
        if (st != GDT_OK)
            goto fail;
        cloud->cur_read += got;
        if (kept == 0)
            continue; /* *n == 0 would mean the end */
        cloud->next_ord += kept;
        *n = kept;
        return GDT_OK;
    }
    return GDT_OK;
fail:
    end_current(cloud, 0);
    return gdt_error_set(err, cloud->failed.status, cloud->failed.code, "%s",
                         cloud->failed.msg);
}

gdt_status gdt_cloud_rewind(gdt_cloud *cloud, gdt_error *err)
{
    (void)err;
    end_current(cloud, 0);
    cloud->cur = 0;
    cloud->cur_read = 0;
    cloud->cur_end = 0;
    cloud->next_ord = cloud->r_ord;
    cloud->pass++;
    for (size_t i = 0; i < cloud->nin; i++) {
        memset(&cloud->in[i].counts, 0, sizeof cloud->in[i].counts);
        if (cloud->in[i].census != NULL)
            memset(cloud->in[i].census, 0, sizeof *cloud->in[i].census);
    }
    gdt_error_clear(&cloud->failed);
    return GDT_OK;
}

const gdt_filter_counts *gdt_cloud_input_counts(const gdt_cloud *cloud, size_t i)
{
    return i < cloud->nin ? &cloud->in[i].counts : NULL;
}

gdt_filter_counts gdt_cloud_total_counts(const gdt_cloud *cloud)
{
    gdt_filter_counts t;
    memset(&t, 0, sizeof t);
    for (size_t i = 0; i < cloud->nin; i++)
        gdt_filter_counts_add(&t, &cloud->in[i].counts);
    return t;
}

const gdt_las_census *gdt_cloud_input_census(const gdt_cloud *cloud, size_t i)
{
    return i < cloud->nin ? cloud->in[i].census : NULL;
}

const gdt_point_filter *gdt_cloud_filter(const gdt_cloud *cloud) { return &cloud->filter; }

void gdt_cloud_release_replay(gdt_cloud *cloud)
{
    if (cloud == NULL || cloud->replay == NULL || cloud->replaying || cloud->recording)
        return;
    gdt_replay_close(cloud->replay);
    cloud->replay = NULL;
    gdt_log_note(cloud->opts.log, "the points decoded by the first pass are released (read "
                                  "for the last time)");
}

void gdt_cloud_close(gdt_cloud *cloud)
{
    if (cloud == NULL)
        return;
    gdt_source_close(cloud->src);
    gdt_replay_close(cloud->replay);
    free(cloud->mtime);
    for (size_t i = 0; i < cloud->nin; i++) {
        free(cloud->in[i].path);
        free(cloud->in[i].wkt);
        free(cloud->in[i].desc);
        free(cloud->in[i].census);
        free(cloud->in[i].starts);
    }
    free(cloud->in);
    free(cloud->crs_desc);
    free(cloud->sbuf);
    free(cloud->sidx);
    free(cloud->px);
    free(cloud->py);
    free(cloud);
}

/* v rounded up to two significant digits (v > 0, finite). */
static double round_up_2(double v)
{
    double p = pow(10.0, floor(log10(v)) - 1.0);
    return ceil(v / p * (1.0 - 1e-12)) * p;
}

gdt_status gdt_cloud_check_span(const gdt_cloud *cloud, int64_t wx, int64_t wy,
                                const char *what, gdt_error *err)
{
    const gdt_lattice *L = &cloud->info.lattice;
    const int64_t lim = INT32_MAX;
    double grow, sx, sy;

    if (wx <= lim && wy <= lim)
        return GDT_OK;
    /* the step that brings the wider axis within the limit, on both axes */
    grow = (double)(wx > wy ? wx : wy) / (double)lim;
    sx = round_up_2(L->sx * grow);
    sy = round_up_2(L->sy * grow);
    if (cloud->info.lattice_native)
        return gdt_error_set(
            err, GDT_EINPUT, 3406,
            "%s: the cloud spans %" PRId64 " x %" PRId64 " lattice steps; %s handles at most "
            "2^31 - 1 steps per axis, %.6g x %.6g CRS units on this lattice, whose step is "
            "the scale of the LAS input %s (--quantum does not apply to LAS input): split the "
            "input into areas at most that wide, or rewrite it with a LAS scale of at least "
            "%.2g x %.2g",
            cloud->in[0].path, wx, wy, what, L->sx * (double)lim, L->sy * (double)lim,
            cloud->in[cloud->info.lattice_input].path, sx, sy);
    return gdt_error_set(err, GDT_EINPUT, 3406,
                         "%s: the cloud spans %" PRId64 " x %" PRId64 " lattice steps; %s "
                         "handles at most 2^31 - 1 steps per axis, %.6g CRS units with "
                         "--quantum %.17g: use --quantum %.2g or coarser, or split the input "
                         "into areas at most that wide",
                         cloud->in[0].path, wx, wy, what, L->sx * (double)lim, L->sx, sx);
}
