/* The TIN writer over PLY, OBJ and LandXML (see gdt_mesh_out.h). */
#define _GNU_SOURCE 1 /* copy_file_range */
#include "gdt_mesh_out.h"
#include "gdt_outfile.h"
#include "gdt_ply.h"
#include "private/fd_io.h"
#include "private/mesh_crs.h"
#include "private/num_text.h"

#include <errno.h>
#include <fcntl.h>
#include <inttypes.h>
#include <locale.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#ifndef GDT_VERSION
#error "GDT_VERSION must be defined by the build"
#endif

/* Longest text of one record: "<P id=\"2147483647\">" + 3 numbers of at
 * most 24 characters + "</P>\n"; a flush leaves at least this much room. */
#define MESH_RECORD_MAX 160

/* Invariants (text formats; a PLY writer only uses ply):
 *  - the temporary holds the bytes before buf[0..fill);
 *  - fd >= 0 and tmp_exists while usable; fail.status != GDT_OK once
 *    anything failed, and then every temporary is already removed;
 *  - prj_wkt != NULL iff a .prj is to be written (OBJ with a WKT);
 *  - cloc is the C locale, made current (uselocale) only inside a batch. */
struct gdt_mesh_writer {
    gdt_mesh_format fmt;
    gdt_ply_writer *ply;
    char *path;
    char *tmp_path;
    char *dir_path;
    char *prj_path; /* OBJ only */
    char *prj_tmp;
    char *prj_wkt;
    int fd;
    int tmp_exists;
    int prj_tmp_exists;
    char *buf;
    size_t fill;
    uint64_t nvert;
    uint64_t nface;
    int in_faces;
    int fragment; /* gdt_mesh_fragment_create: records only, no header, footer or rename */
    locale_t cloc;
    gdt_error fail;
};

/* ---- format and paths --------------------------------------------------- */

/* The extension of the last path component, without its dot; "" if none. */
static const char *extension(const char *path)
{
    const char *slash = strrchr(path, '/');
    const char *base = slash != NULL ? slash + 1 : path;
    const char *dot = strrchr(base, '.');
    return dot != NULL && dot != base ? dot + 1 : "";
}

gdt_mesh_format gdt_mesh_format_of(const char *path)
{
    const char *ext;
    if (path == NULL)
        return GDT_MESH_PLY;
    ext = extension(path);
    if (strcasecmp(ext, "obj") == 0)
        return GDT_MESH_OBJ;
    if (strcasecmp(ext, "xml") == 0)
        return GDT_MESH_LANDXML;
    return GDT_MESH_PLY;
}

const char *gdt_mesh_format_name(gdt_mesh_format f)
{
    switch (f) {
    case GDT_MESH_OBJ: return "OBJ";
    case GDT_MESH_LANDXML: return "LandXML";
    default: return "PLY";
    }
}

char *gdt_mesh_prj_path(const char *path, gdt_mesh_format f)
{
    const char *ext;
    size_t stem;
    char *p;
    if (path == NULL || f != GDT_MESH_OBJ)
        return NULL;
    ext = extension(path);
    stem = ext[0] != '\0' ? (size_t)(ext - path) - 1 : strlen(path);
    p = malloc(stem + 5);
    if (p == NULL)
        return NULL;
    memcpy(p, path, stem);
    memcpy(p + stem, ".prj", 5);
    return p;
}

/* ---- numbers ------------------------------------------------------------ */

/* Shortest round-trip text of the finite d; the C numeric locale must be
 * current.  returns the length, 0 when none of the precisions round-trips. */
static size_t fmt_double_c(char *out, size_t cap, double d)
{
    /* the same text without the C library for the usual magnitudes */
    if (cap >= GDT_NUM_TEXT_MAX) {
        size_t n = gdt_num_text(out, d);
        if (n > 0)
            return n;
    }
    for (int prec = 15; prec <= 17; prec++) {
        int n = snprintf(out, cap, "%.*g", prec, d);
        if (n <= 0 || (size_t)n >= cap)
            return 0;
        /* 17 significant digits always read back as the same double
         * (IEEE 754 binary64); the check there guards the C library only */
        if (strtod(out, NULL) == d)
            return (size_t)n;
    }
    return 0;
}

size_t gdt_mesh_format_double(char *out, size_t cap, double d)
{
    locale_t c, prev;
    size_t n;
    if (out == NULL || cap < 32 || !isfinite(d))
        return 0;
    c = newlocale(LC_NUMERIC_MASK, "C", (locale_t)0);
    if (c == (locale_t)0)
        return 0;
    prev = uselocale(c);
    n = fmt_double_c(out, cap, d);
    uselocale(prev);
    freelocale(c);
    return n;
}

/* Decimal text of v (< 2^63) at out; returns its length. */
static size_t put_u64(char *out, uint64_t v)
{
    char tmp[24];
    size_t n = 0, k;
    do {
        tmp[n++] = (char)('0' + v % 10);
        v /= 10;
    } while (v != 0);
    for (k = 0; k < n; k++)
        out[k] = tmp[n - 1 - k];
    return n;
}

/* ---- failures and the buffer -------------------------------------------- */

static void discard(gdt_mesh_writer *w)
{
    if (w->fd >= 0) {
        close(w->fd);
        w->fd = -1;
    }
    if (w->tmp_exists) {
        unlink(w->tmp_path);
        w->tmp_exists = 0;
    }
    if (w->prj_tmp_exists) {
        unlink(w->prj_tmp);
        w->prj_tmp_exists = 0;
    }
}

static void writer_free(gdt_mesh_writer *w)
{
    if (w->cloc != (locale_t)0)
        freelocale(w->cloc);
    free(w->buf);
    free(w->path);
    free(w->tmp_path);
    free(w->dir_path);
    free(w->prj_path);
    free(w->prj_tmp);
    free(w->prj_wkt);
    free(w);
}

static gdt_status wfail(gdt_mesh_writer *w, gdt_error *err, gdt_status st, int code,
                        const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 5, 6)))
#endif
    ;

/* Records the first failure, removes the temporaries, reports it. */
static gdt_status wfail(gdt_mesh_writer *w, gdt_error *err, gdt_status st, int code,
                        const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    gdt_error_vset(&w->fail, st, code, fmt, ap);
    va_end(ap);
    discard(w);
    return gdt_error_set(err, w->fail.status, w->fail.code, "%s", w->fail.msg);
}

static gdt_status refail(const gdt_mesh_writer *w, gdt_error *err)
{
    return gdt_error_set(err, w->fail.status, w->fail.code, "%s", w->fail.msg);
}

static gdt_status flush_buf(gdt_mesh_writer *w, gdt_error *err)
{
    int e = w->fill > 0 ? gdt_fd_write_all(w->fd, w->buf, w->fill, -1) : 0;
    if (e != 0)
        return wfail(w, err, GDT_EIO, 4712, "%s: write failed (temporary %s removed): %s", w->path,
                     w->tmp_path, strerror(e));
    w->fill = 0;
    return GDT_OK;
}

/* Appends n bytes through the buffer. */
static gdt_status put(gdt_mesh_writer *w, const char *s, size_t n, gdt_error *err)
{
    while (n > 0) {
        size_t room = GDT_MESH_BUFFER_BYTES - w->fill;
        size_t k = n < room ? n : room;
        memcpy(w->buf + w->fill, s, k);
        w->fill += k;
        s += k;
        n -= k;
        if (w->fill == GDT_MESH_BUFFER_BYTES && flush_buf(w, err) != GDT_OK)
            return w->fail.status;
    }
    return GDT_OK;
}

static gdt_status puts_(gdt_mesh_writer *w, const char *s, gdt_error *err)
{
    return put(w, s, strlen(s), err);
}

/* Appends s as XML text: markup characters escaped, control characters
 * (line breaks included) as spaces and bytes >= 0x80 as '?' (the document
 * is ASCII, valid UTF-8 whatever the input's encoding). */
static gdt_status put_xml_text(gdt_mesh_writer *w, const char *s, gdt_error *err)
{
    for (const unsigned char *p = (const unsigned char *)s; *p != '\0'; p++) {
        const char *e = NULL;
        char c = (char)*p;
        switch (*p) {
        case '&': e = "&amp;"; break;
        case '<': e = "&lt;"; break;
        case '>': e = "&gt;"; break;
        case '"': e = "&quot;"; break;
        default:
            if (*p >= 0x80)
                c = '?';
            else if (*p < 0x20 || *p == 0x7f)
                c = ' ';
        }
        if ((e != NULL ? puts_(w, e, err) : put(w, &c, 1, err)) != GDT_OK)
            return w->fail.status;
    }
    return GDT_OK;
}

/* Appends s on one line: control characters as spaces, bytes >= 0x80 as
 * '?'; in an XML comment (xml_comment) "--" is broken up as well. */
static gdt_status put_line_text(gdt_mesh_writer *w, const char *s, int xml_comment, gdt_error *err)
{
    char prev = '\0';
    for (const unsigned char *p = (const unsigned char *)s; *p != '\0'; p++) {
        char c = (char)*p;
        if (*p >= 0x80)
            c = '?';
        else if (*p < 0x20 || *p == 0x7f)
            c = ' ';
        if (xml_comment && c == '-' && prev == '-' && put(w, " ", 1, err) != GDT_OK)
            return w->fail.status;
        if (put(w, &c, 1, err) != GDT_OK)
            return w->fail.status;
        prev = c;
    }
    if (xml_comment && prev == '-' && put(w, " ", 1, err) != GDT_OK)
        return w->fail.status;
    return GDT_OK;
}

/* ---- meta and header ---------------------------------------------------- */

static int comment_byte_ok(unsigned char c)
{
    return c == '\t' || (c >= 0x20 && c < 0x7f);
}

static gdt_status check_meta(const char *path, const gdt_mesh_meta *meta, gdt_error *err)
{
    const gdt_lattice *l = &meta->lattice;
    if (meta->epsg < 0)
        return gdt_error_set(err, GDT_EINTERNAL, 7710, "%s: negative EPSG code %d", path,
                             meta->epsg);
    if (!isfinite(l->sx) || !isfinite(l->sy) || !isfinite(l->ox) || !isfinite(l->oy) ||
        !(l->sx > 0.0) || !(l->sy > 0.0))
        return gdt_error_set(err, GDT_EINTERNAL, 7712,
                             "%s: lattice (%g %g %g %g) must be finite with positive spacing", path,
                             l->sx, l->sy, l->ox, l->oy);
    if (meta->ncomments > 0 && meta->comments == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7710, "%s: %zu comments but no array", path,
                             meta->ncomments);
    for (size_t i = 0; i < meta->ncomments; i++) {
        const unsigned char *c = (const unsigned char *)meta->comments[i];
        if (c == NULL)
            return gdt_error_set(err, GDT_EINTERNAL, 7710, "%s: comment %zu is NULL", path, i);
        for (size_t k = 0; c[k] != '\0'; k++)
            if (!comment_byte_ok(c[k]))
                return gdt_error_set(err, GDT_EINTERNAL, 7711,
                                     "%s: comment %zu has byte 0x%02x at offset %zu; header "
                                     "comments must be one line of printable ASCII",
                                     path, i, c[k], k);
    }
    return GDT_OK;
}

/* "sx sy ox oy" of the lattice, each exact. */
static gdt_status lattice_text(gdt_mesh_writer *w, const gdt_lattice *L, char *out, size_t cap,
                               gdt_error *err)
{
    char num[4][40];
    const double v[4] = {L->sx, L->sy, L->ox, L->oy};
    for (int i = 0; i < 4; i++)
        if (fmt_double_c(num[i], sizeof num[i], v[i]) == 0)
            return wfail(w, err, GDT_EINTERNAL, 7717,
                         "%s: the lattice value %.17g has no round-trip text", w->path, v[i]);
    snprintf(out, cap, "%s %s %s %s", num[0], num[1], num[2], num[3]);
    return GDT_OK;
}

static gdt_status obj_header(gdt_mesh_writer *w, const gdt_mesh_meta *meta, gdt_error *err)
{
    char line[256], lat[192];
    if (puts_(w, "# gdt-tile " GDT_VERSION " TIN (Wavefront OBJ)\n# crs ", err) != GDT_OK)
        return w->fail.status;
    if (meta->epsg > 0) {
        snprintf(line, sizeof line, "EPSG:%d", meta->epsg);
        if (puts_(w, line, err) != GDT_OK)
            return w->fail.status;
    } else if (meta->crs_wkt != NULL && meta->crs_wkt[0] != '\0') {
        if (put_line_text(w, meta->crs_wkt, 0, err) != GDT_OK)
            return w->fail.status;
    } else if (puts_(w, "unknown", err) != GDT_OK) {
        return w->fail.status;
    }
    if (lattice_text(w, &meta->lattice, lat, sizeof lat, err) != GDT_OK)
        return w->fail.status;
    snprintf(line, sizeof line, "\n# lattice %s\n", lat);
    if (puts_(w, line, err) != GDT_OK)
        return w->fail.status;
    for (size_t i = 0; i < meta->ncomments; i++)
        if (puts_(w, "# ", err) != GDT_OK || puts_(w, meta->comments[i], err) != GDT_OK ||
            puts_(w, "\n", err) != GDT_OK)
            return w->fail.status;
    return puts_(w, "# vertices (v x y z), then faces (f a b c: 1-based, counter-clockwise)\n",
                 err);
}

/* The surface name: the file's stem. */
static gdt_status put_stem_xml(gdt_mesh_writer *w, gdt_error *err)
{
    const char *slash = strrchr(w->path, '/');
    const char *base = slash != NULL ? slash + 1 : w->path;
    const char *ext = extension(w->path);
    size_t n = ext[0] != '\0' ? (size_t)(ext - base) - 1 : strlen(base);
    char *stem = strndup(base, n);
    gdt_status st;
    if (stem == NULL)
        return wfail(w, err, GDT_EINTERNAL, 7001, "out of memory");
    st = put_xml_text(w, stem, err);
    free(stem);
    return st;
}

static gdt_status xml_header(gdt_mesh_writer *w, const gdt_mesh_meta *meta, const char *wkt,
                             gdt_error *err)
{
    char line[512], lat[192];
    struct tm tm;
    time_t t = (time_t)meta->stamp;
    int foot = gdt_mesh_crs_wkt_foot(wkt);

    if (gmtime_r(&t, &tm) == NULL)
        memset(&tm, 0, sizeof tm), tm.tm_year = 70, tm.tm_mday = 1;
    if (lattice_text(w, &meta->lattice, lat, sizeof lat, err) != GDT_OK)
        return w->fail.status;
    snprintf(line, sizeof line,
             "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
             "<!-- gdt-tile " GDT_VERSION " TIN; lattice %s -->\n",
             lat);
    if (puts_(w, line, err) != GDT_OK)
        return w->fail.status;
    for (size_t i = 0; i < meta->ncomments; i++)
        if (puts_(w, "<!-- ", err) != GDT_OK ||
            put_line_text(w, meta->comments[i], 1, err) != GDT_OK ||
            puts_(w, " -->\n", err) != GDT_OK)
            return w->fail.status;
    snprintf(line, sizeof line,
             "<LandXML xmlns=\"" GDT_LANDXML_NS "\" "
             "xmlns:xsi=\"http://www.w3.org/2001/XMLSchema-instance\" "
             "xsi:schemaLocation=\"" GDT_LANDXML_NS " " GDT_LANDXML_NS "/LandXML-1.2.xsd\" "
             "version=\"1.2\" date=\"%04d-%02d-%02d\" time=\"%02d:%02d:%02d\">\n",
             tm.tm_year + 1900, tm.tm_mon + 1, tm.tm_mday, tm.tm_hour, tm.tm_min, tm.tm_sec);
    if (puts_(w, line, err) != GDT_OK)
        return w->fail.status;
    if (puts_(w,
              foot ? "<Units><Imperial areaUnit=\"squareFoot\" linearUnit=\""
                   : "<Units><Metric areaUnit=\"squareMeter\" linearUnit=\"meter\" "
                     "volumeUnit=\"cubicMeter\" temperatureUnit=\"celsius\" "
                     "pressureUnit=\"milliBars\"/></Units>\n",
              err) != GDT_OK)
        return w->fail.status;
    if (foot && puts_(w,
                      foot == 2 ? "USSurveyFoot\" volumeUnit=\"cubicFeet\" temperatureUnit=\""
                                  "fahrenheit\" pressureUnit=\"inchHG\"/></Units>\n"
                                : "foot\" volumeUnit=\"cubicFeet\" temperatureUnit=\""
                                  "fahrenheit\" pressureUnit=\"inchHG\"/></Units>\n",
                      err) != GDT_OK)
        return w->fail.status;
    if (meta->epsg > 0 || wkt != NULL) {
        if (puts_(w, "<CoordinateSystem", err) != GDT_OK)
            return w->fail.status;
        if (meta->epsg > 0) {
            snprintf(line, sizeof line, " name=\"EPSG:%d\" epsgCode=\"%d\"", meta->epsg,
                     meta->epsg);
            if (puts_(w, line, err) != GDT_OK)
                return w->fail.status;
        }
        if (wkt != NULL && (puts_(w, " ogcWktCode=\"", err) != GDT_OK ||
                            put_xml_text(w, wkt, err) != GDT_OK || puts_(w, "\"", err) != GDT_OK))
            return w->fail.status;
        if (puts_(w, "/>\n", err) != GDT_OK)
            return w->fail.status;
    }
    if (puts_(w,
              "<Application name=\"gdt-tile\" version=\"" GDT_VERSION "\" "
              "desc=\"exact Delaunay TIN of a point cloud\"/>\n"
              "<Surfaces>\n<Surface name=\"",
              err) != GDT_OK ||
        put_stem_xml(w, err) != GDT_OK ||
        puts_(w, "\">\n<Definition surfType=\"TIN\">\n<Pnts>\n", err) != GDT_OK)
        return w->fail.status;
    return GDT_OK;
}

/* The WKT of the CRS: the input's, else one made for its EPSG code; NULL
 * (and *oom) when none. */
static char *crs_wkt_of(const gdt_mesh_meta *meta, int *oom)
{
    if (meta->crs_wkt != NULL && meta->crs_wkt[0] != '\0') {
        char *s = strdup(meta->crs_wkt);
        if (s == NULL)
            *oom = 1;
        return s;
    }
    return meta->epsg > 0 ? gdt_mesh_crs_wkt_of_epsg(meta->epsg, oom) : NULL;
}

/* ---- create ------------------------------------------------------------- */

static gdt_status create_ply(gdt_mesh_writer *w, const char *path, const gdt_mesh_meta *meta,
                             gdt_error *err)
{
    gdt_ply_meta pm;
    memset(&pm, 0, sizeof pm);
    pm.lattice = meta->lattice;
    pm.epsg = meta->epsg;
    pm.crs_wkt = meta->crs_wkt;
    pm.comments = meta->comments;
    pm.ncomments = meta->ncomments;
    return gdt_ply_create(&w->ply, path, &pm, err);
}

/* The .prj of an OBJ: its path checked, and either a WKT to write at
 * finish or a warning that there is none. */
static gdt_status plan_prj(gdt_mesh_writer *w, const gdt_mesh_meta *meta, char *wkt, gdt_error *err)
{
    struct stat sb;
    gdt_status st;
    w->prj_path = gdt_mesh_prj_path(w->path, GDT_MESH_OBJ);
    if (w->prj_path == NULL) {
        free(wkt);
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    }
    if (stat(w->prj_path, &sb) == 0 && S_ISDIR(sb.st_mode)) {
        free(wkt);
        return gdt_error_set(err, GDT_EIO, 4010,
                             "%s: is a directory; the CRS file of %s is renamed over its path, "
                             "so it is not replaced",
                             w->prj_path, w->path);
    }
    st = gdt_outfile_check(w->prj_path, err);
    if (st != GDT_OK) {
        free(wkt);
        return st;
    }
    w->prj_wkt = wkt;
    if (wkt == NULL) {
        if (meta->epsg > 0)
            gdt_log_warn(meta->log, 3720,
                         "%s: no %s written: the CRS is EPSG:%d, known only by its code, and "
                         "gdt-tile makes WKT only for WGS 84 UTM/UPS and NAD83 UTM (the code "
                         "is in the OBJ header)",
                         w->path, w->prj_path, meta->epsg);
        else
            gdt_log_note(meta->log, "%s: no %s written: the input's CRS is unknown", w->path,
                         w->prj_path);
        return GDT_OK;
    }
    w->prj_tmp = gdt_outfile_temp(w->prj_path);
    if (w->prj_tmp == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    return GDT_OK;
}

gdt_status gdt_mesh_create(gdt_mesh_writer **out, const char *path, gdt_mesh_format fmt,
                           const gdt_mesh_meta *meta, gdt_error *err)
{
    gdt_mesh_writer *w = NULL;
    gdt_status st;
    struct stat sb;
    size_t len;
    char *wkt = NULL;
    int oom = 0;

    if (out == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7710, "mesh writer: NULL output argument");
    *out = NULL;
    if (path == NULL || path[0] == '\0' || meta == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7710, "mesh writer: %s",
                             meta == NULL ? "NULL metadata" : "empty output path");
    if (fmt != GDT_MESH_PLY && fmt != GDT_MESH_OBJ && fmt != GDT_MESH_LANDXML)
        return gdt_error_set(err, GDT_EINTERNAL, 7710, "%s: unknown mesh format %d", path,
                             (int)fmt);
    w = calloc(1, sizeof *w);
    if (w == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    w->fd = -1;
    w->fmt = fmt;
    gdt_error_clear(&w->fail);
    if (fmt == GDT_MESH_PLY) {
        st = create_ply(w, path, meta, err);
        if (st != GDT_OK)
            goto fail;
        *out = w;
        return GDT_OK;
    }
    st = check_meta(path, meta, err);
    if (st != GDT_OK)
        goto fail;
    len = strlen(path);
    if (path[len - 1] == '/' || (stat(path, &sb) == 0 && S_ISDIR(sb.st_mode))) {
        st = gdt_error_set(err, GDT_EIO, 4710, "%s: is a directory, not a file name", path);
        goto fail;
    }
    st = gdt_outfile_check(path, err);
    if (st != GDT_OK)
        goto fail;
    w->path = strdup(path);
    w->dir_path = gdt_outfile_dir(path);
    w->tmp_path = gdt_outfile_temp(path);
    w->buf = malloc(GDT_MESH_BUFFER_BYTES);
    w->cloc = newlocale(LC_NUMERIC_MASK, "C", (locale_t)0);
    wkt = crs_wkt_of(meta, &oom);
    if (w->path == NULL || w->dir_path == NULL || w->tmp_path == NULL || w->buf == NULL || oom) {
        free(wkt);
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    if (w->cloc == (locale_t)0) {
        free(wkt);
        st = gdt_error_set(err, GDT_EINTERNAL, 7718, "%s: cannot make the C numeric locale: %s",
                           path, strerror(errno));
        goto fail;
    }
    if (fmt == GDT_MESH_OBJ) {
        st = plan_prj(w, meta, wkt, err); /* takes wkt */
        wkt = NULL;
        if (st != GDT_OK)
            goto fail;
    }
    w->fd = open(w->tmp_path, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666);
    if (w->fd < 0) {
        free(wkt);
        st = gdt_error_set(err, GDT_EIO, 4711, "%s: cannot create temporary file %s: %s", path,
                           w->tmp_path, strerror(errno));
        goto fail;
    }
    w->tmp_exists = 1;
    {
        locale_t prev = uselocale(w->cloc);
        st = fmt == GDT_MESH_OBJ ? obj_header(w, meta, err) : xml_header(w, meta, wkt, err);
        uselocale(prev);
    }
    free(wkt);
    if (st != GDT_OK)
        goto fail;
    *out = w;
    return GDT_OK;

fail:
    if (w->ply != NULL)
        gdt_ply_abort(w->ply);
    discard(w);
    writer_free(w);
    return st;
}

/* ---- records ------------------------------------------------------------ */

/* Makes room for one record of at most MESH_RECORD_MAX bytes. */
static gdt_status room(gdt_mesh_writer *w, gdt_error *err)
{
    if (GDT_MESH_BUFFER_BYTES - w->fill < MESH_RECORD_MAX)
        return flush_buf(w, err);
    return GDT_OK;
}

static gdt_status text_vertices(gdt_mesh_writer *w, const double *xyz, size_t n, gdt_error *err)
{
    int xml = w->fmt == GDT_MESH_LANDXML;
    for (size_t i = 0; i < n; i++) {
        const double *v = xyz + 3 * i;
        /* LandXML points are northing, easting, elevation */
        const double c[3] = {xml ? v[1] : v[0], xml ? v[0] : v[1], v[2]};
        char *p;
        if (!isfinite(v[0]) || !isfinite(v[1]) || !isfinite(v[2]))
            return wfail(w, err, GDT_EINTERNAL, 7716,
                         "%s: vertex %" PRIu64 " is not finite (%g %g %g)", w->path, w->nvert + i,
                         v[0], v[1], v[2]);
        if (room(w, err) != GDT_OK)
            return w->fail.status;
        p = w->buf + w->fill;
        if (xml) {
            memcpy(p, "<P id=\"", 7);
            p += 7;
            p += put_u64(p, w->nvert + i + 1);
            memcpy(p, "\">", 2);
            p += 2;
        } else {
            memcpy(p, "v ", 2);
            p += 2;
        }
        for (int k = 0; k < 3; k++) {
            size_t m = fmt_double_c(p, 40, c[k]);
            if (m == 0)
                return wfail(w, err, GDT_EINTERNAL, 7717,
                             "%s: vertex %" PRIu64 ": %.17g has no round-trip text", w->path,
                             w->nvert + i, c[k]);
            p += m;
            *p++ = k < 2 ? ' ' : (xml ? '<' : '\n');
        }
        if (xml) {
            memcpy(p, "/P>\n", 4);
            p += 4;
        }
        w->fill = (size_t)(p - w->buf);
    }
    return GDT_OK;
}

gdt_status gdt_mesh_write_vertices(gdt_mesh_writer *w, const double *xyz, size_t n, gdt_error *err)
{
    gdt_status st;
    locale_t prev;

    if (w == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7710, "mesh writer: NULL writer");
    if (w->ply != NULL)
        return gdt_ply_write_vertices(w->ply, xyz, n, err);
    if (w->fail.status != GDT_OK)
        return refail(w, err);
    if (w->in_faces)
        return wfail(w, err, GDT_EINTERNAL, 7713,
                     "%s: vertices written after the first face (%" PRIu64 " faces so far)",
                     w->path, w->nface);
    if ((uint64_t)n > GDT_PLY_MAX_VERTICES - w->nvert)
        return wfail(w, err, GDT_EINPUT, 3710,
                     "%s: %" PRIu64 " + %zu vertices exceed the limit of %" PRIu64
                     " (face indices are 32-bit signed integers)",
                     w->path, w->nvert, n, GDT_PLY_MAX_VERTICES);
    if (n > 0 && xyz == NULL)
        return wfail(w, err, GDT_EINTERNAL, 7710, "%s: NULL vertex array", w->path);
    prev = uselocale(w->cloc);
    st = text_vertices(w, xyz, n, err);
    uselocale(prev);
    if (st == GDT_OK)
        w->nvert += n;
    return st;
}

gdt_status gdt_mesh_write_faces(gdt_mesh_writer *w, const int32_t *tri, size_t n, gdt_error *err)
{
    int xml;

    if (w == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7710, "mesh writer: NULL writer");
    if (w->ply != NULL)
        return gdt_ply_write_faces(w->ply, tri, n, err);
    if (w->fail.status != GDT_OK)
        return refail(w, err);
    if (n > 0 && tri == NULL)
        return wfail(w, err, GDT_EINTERNAL, 7710, "%s: NULL face array", w->path);
    xml = w->fmt == GDT_MESH_LANDXML;
    if (!w->in_faces) {
        w->in_faces = 1;
        if (xml && puts_(w, "</Pnts>\n<Faces>\n", err) != GDT_OK)
            return w->fail.status;
    }
    for (size_t i = 0; i < n; i++) {
        const int32_t *t = tri + 3 * i;
        char *p;
        for (int k = 0; k < 3; k++)
            if (t[k] < 0 || (uint64_t)t[k] >= w->nvert)
                return wfail(w, err, GDT_EINTERNAL, 7714,
                             "%s: face %" PRIu64 " (%" PRId32 " %" PRId32 " %" PRId32
                             ") has an index outside [0, %" PRIu64 ")",
                             w->path, w->nface + i, t[0], t[1], t[2], w->nvert);
        if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2])
            return wfail(w, err, GDT_EINTERNAL, 7715,
                         "%s: face %" PRIu64 " (%" PRId32 " %" PRId32 " %" PRId32
                         ") repeats a vertex",
                         w->path, w->nface + i, t[0], t[1], t[2]);
        if (room(w, err) != GDT_OK)
            return w->fail.status;
        p = w->buf + w->fill;
        memcpy(p, xml ? "<F>" : "f ", xml ? 3 : 2);
        p += xml ? 3 : 2;
        for (int k = 0; k < 3; k++) {
            p += put_u64(p, (uint64_t)t[k] + 1);
            *p++ = k < 2 ? ' ' : '\n';
        }
        if (xml) {
            memcpy(p - 1, "</F>\n", 5);
            p += 4;
        }
        w->fill = (size_t)(p - w->buf);
    }
    w->nface += n;
    return GDT_OK;
}

uint64_t gdt_mesh_vertex_count(const gdt_mesh_writer *w)
{
    if (w == NULL)
        return 0;
    return w->ply != NULL ? gdt_ply_vertex_count(w->ply) : w->nvert;
}

uint64_t gdt_mesh_face_count(const gdt_mesh_writer *w)
{
    if (w == NULL)
        return 0;
    return w->ply != NULL ? gdt_ply_face_count(w->ply) : w->nface;
}

gdt_mesh_format gdt_mesh_writer_format(const gdt_mesh_writer *w)
{
    return w != NULL ? w->fmt : GDT_MESH_PLY;
}

/* ---- finish ------------------------------------------------------------- */

/* Writes and fsyncs the .prj temporary (the WKT and a line break). */
static gdt_status write_prj_tmp(gdt_mesh_writer *w, gdt_error *err)
{
    int fd = open(w->prj_tmp, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666);
    int e;
    if (fd < 0)
        return wfail(w, err, GDT_EIO, 4717, "%s: cannot create temporary file %s: %s", w->prj_path,
                     w->prj_tmp, strerror(errno));
    w->prj_tmp_exists = 1;
    e = gdt_fd_write_all(fd, w->prj_wkt, strlen(w->prj_wkt), -1);
    if (e == 0)
        e = gdt_fd_write_all(fd, "\n", 1, -1);
    if (e == 0 && fsync(fd) != 0)
        e = errno;
    if (close(fd) != 0 && e == 0)
        e = errno;
    if (e != 0)
        return wfail(w, err, GDT_EIO, 4717, "%s: writing %s failed (temporaries removed): %s",
                     w->prj_path, w->prj_tmp, strerror(e));
    return GDT_OK;
}

/* The outfile rule for path, again right before its rename. */
static gdt_status recheck(gdt_mesh_writer *w, const char *path, gdt_error *err)
{
    gdt_error e2;
    gdt_error_clear(&e2);
    if (gdt_outfile_check(path, &e2) != GDT_OK)
        return wfail(w, err, e2.status, e2.code, "%s (temporaries removed)", e2.msg);
    return GDT_OK;
}

static gdt_status finish_text(gdt_mesh_writer *w, gdt_error *err)
{
    int e;
    char line[96];
    int prj_placed = 0;

    if (w->fmt == GDT_MESH_LANDXML) {
        if (!w->in_faces && puts_(w, "</Pnts>\n<Faces>\n", err) != GDT_OK)
            return w->fail.status;
        if (puts_(w, "</Faces>\n</Definition>\n</Surface>\n</Surfaces>\n</LandXML>\n", err) !=
            GDT_OK)
            return w->fail.status;
    } else {
        snprintf(line, sizeof line, "# %" PRIu64 " vertices, %" PRIu64 " faces\n", w->nvert,
                 w->nface);
        if (puts_(w, line, err) != GDT_OK)
            return w->fail.status;
    }
    if (flush_buf(w, err) != GDT_OK)
        return w->fail.status;
    if (fsync(w->fd) != 0)
        return wfail(w, err, GDT_EIO, 4713, "%s: fsync failed (temporary %s removed): %s", w->path,
                     w->tmp_path, strerror(errno));
    e = close(w->fd);
    w->fd = -1;
    if (e != 0)
        return wfail(w, err, GDT_EIO, 4714, "%s: close failed (temporary %s removed): %s", w->path,
                     w->tmp_path, strerror(errno));
    if (w->prj_wkt != NULL && write_prj_tmp(w, err) != GDT_OK)
        return w->fail.status;
    if (recheck(w, w->path, err) != GDT_OK)
        return w->fail.status;
    if (w->prj_path != NULL) {
        if (recheck(w, w->prj_path, err) != GDT_OK)
            return w->fail.status;
        if (w->prj_wkt != NULL) {
            if (rename(w->prj_tmp, w->prj_path) != 0)
                return wfail(w, err, GDT_EIO, 4715,
                             "%s: cannot rename %s to it (temporaries removed): %s", w->prj_path,
                             w->prj_tmp, strerror(errno));
            w->prj_tmp_exists = 0;
            prj_placed = 1;
        } else if (unlink(w->prj_path) != 0 && errno != ENOENT) {
            return wfail(w, err, GDT_EIO, 4718,
                         "%s: cannot remove this CRS file of an earlier output (the new mesh "
                         "has no .prj; temporary removed): %s",
                         w->prj_path, strerror(errno));
        }
    }
    if (rename(w->tmp_path, w->path) != 0) {
        int re = errno;
        if (prj_placed)
            unlink(w->prj_path);
        return wfail(w, err, GDT_EIO, 4715, "%s: cannot rename %s to it (temporary removed%s): %s",
                     w->path, w->tmp_path, prj_placed ? ", and the new .prj with it" : "",
                     strerror(re));
    }
    w->tmp_exists = 0;
    e = gdt_outfile_sync_dir(w->dir_path);
    if (e != 0)
        return gdt_error_set(err, GDT_EIO, 4716,
                             "%s: written, but syncing its directory %s failed: %s", w->path,
                             w->dir_path, strerror(e));
    return GDT_OK;
}

gdt_ply_writer *gdt_mesh_ply_writer(gdt_mesh_writer *w)
{
    return w != NULL ? w->ply : NULL;
}

gdt_status gdt_mesh_finish_parts(gdt_mesh_writer *w, uint64_t nface, gdt_error *err)
{
    gdt_status st;
    if (w == NULL || w->ply == NULL)
        st = gdt_error_set(err, GDT_EINTERNAL, 7710, "mesh writer: %s",
                           w == NULL ? "NULL writer" : "parts of a text mesh");
    else
        st = gdt_ply_finish_parts(w->ply, nface, err);
    if (w != NULL) {
        w->ply = NULL;
        discard(w);
        writer_free(w);
    }
    return st;
}

gdt_status gdt_mesh_finish(gdt_mesh_writer *w, gdt_error *err)
{
    gdt_status st;
    if (w == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7710, "mesh writer: NULL writer");
    if (w->fragment) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7710, "%s: a fragment is not a mesh", w->path);
    } else if (w->ply != NULL) {
        st = gdt_ply_finish(w->ply, err);
        w->ply = NULL;
    } else if (w->fail.status != GDT_OK) {
        st = refail(w, err);
    } else {
        st = finish_text(w, err);
    }
    discard(w);
    writer_free(w);
    return st;
}

void gdt_mesh_abort(gdt_mesh_writer *w)
{
    if (w == NULL)
        return;
    if (w->ply != NULL)
        gdt_ply_abort(w->ply);
    discard(w);
    writer_free(w);
}

/* ---- text meshes in parts ----------------------------------------------- */

const char *gdt_mesh_text_separator(gdt_mesh_format f)
{
    return f == GDT_MESH_LANDXML ? "</Pnts>\n<Faces>\n" : "";
}

gdt_status gdt_mesh_fragment_create(gdt_mesh_writer **out, const char *path, gdt_mesh_format fmt,
                                    uint64_t first, int faces, gdt_error *err)
{
    gdt_mesh_writer *w;

    if (out == NULL || path == NULL || path[0] == '\0' ||
        (fmt != GDT_MESH_OBJ && fmt != GDT_MESH_LANDXML))
        return gdt_error_set(err, GDT_EINTERNAL, 7710, "mesh fragment: %s",
                             out == NULL || path == NULL || path[0] == '\0'
                                 ? "NULL or empty argument"
                                 : "not a text format");
    *out = NULL;
    if (first > GDT_PLY_MAX_VERTICES)
        return gdt_error_set(err, GDT_EINPUT, 3710,
                             "%s: vertex %" PRIu64 " beyond the limit of %" PRIu64, path, first,
                             GDT_PLY_MAX_VERTICES);
    w = calloc(1, sizeof *w);
    if (w == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    w->fd = -1;
    w->fmt = fmt;
    w->fragment = 1;
    gdt_error_clear(&w->fail);
    w->path = strdup(path);
    w->tmp_path = strdup(path);
    w->buf = malloc(GDT_MESH_BUFFER_BYTES);
    w->cloc = newlocale(LC_NUMERIC_MASK, "C", (locale_t)0);
    if (w->path == NULL || w->tmp_path == NULL || w->buf == NULL || w->cloc == (locale_t)0) {
        writer_free(w);
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    }
    w->fd = open(path, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666);
    if (w->fd < 0) {
        int e = errno;
        writer_free(w);
        return gdt_error_set(err, GDT_EIO, 4711, "%s: cannot create this part of the mesh: %s",
                             path, strerror(e));
    }
    w->tmp_exists = 1;
    /* vertices: numbered from first; faces: over first vertices, no
     * separator before them */
    w->nvert = first;
    w->in_faces = faces != 0;
    *out = w;
    return GDT_OK;
}

gdt_status gdt_mesh_fragment_close(gdt_mesh_writer *w, uint64_t *bytes, gdt_error *err)
{
    gdt_status st = GDT_OK;
    off_t end;

    if (w == NULL || !w->fragment) {
        gdt_mesh_abort(w);
        return gdt_error_set(err, GDT_EINTERNAL, 7710, "mesh fragment: not a fragment");
    }
    if (w->fail.status != GDT_OK)
        st = refail(w, err);
    if (st == GDT_OK)
        st = flush_buf(w, err);
    if (st == GDT_OK) {
        end = lseek(w->fd, 0, SEEK_CUR);
        if (end < 0)
            st = wfail(w, err, GDT_EIO, 4712, "%s: cannot tell its length: %s", w->path,
                       strerror(errno));
        else if (bytes != NULL)
            *bytes = (uint64_t)end;
    }
    if (st == GDT_OK) {
        int e = close(w->fd);
        w->fd = -1;
        if (e != 0)
            st = wfail(w, err, GDT_EIO, 4714, "%s: close failed (removed): %s", w->path,
                       strerror(errno));
        else
            w->tmp_exists = 0; /* kept: it is the caller's now */
    }
    discard(w);
    writer_free(w);
    return st;
}

const char *gdt_mesh_temp_path(const gdt_mesh_writer *w)
{
    if (w == NULL)
        return NULL;
    return w->ply != NULL ? gdt_ply_temp_path(w->ply) : w->tmp_path;
}

gdt_status gdt_mesh_begin_text_parts(gdt_mesh_writer *w, uint64_t *header, gdt_error *err)
{
    off_t end;
    if (w == NULL || w->ply != NULL || w->fragment || w->nvert != 0 || w->in_faces)
        return gdt_error_set(err, GDT_EINTERNAL, 7710,
                             "mesh writer: parts begin on a fresh text mesh only");
    if (w->fail.status != GDT_OK)
        return refail(w, err);
    if (flush_buf(w, err) != GDT_OK)
        return w->fail.status;
    end = lseek(w->fd, 0, SEEK_CUR);
    if (end < 0)
        return wfail(w, err, GDT_EIO, 4712,
                     "%s: cannot tell its header's length (temporary %s "
                     "removed): %s",
                     w->path, w->tmp_path, strerror(errno));
    *header = (uint64_t)end;
    return GDT_OK;
}

gdt_status gdt_mesh_resume_text(gdt_mesh_writer *w, uint64_t offset, uint64_t nvert, uint64_t nface,
                                gdt_error *err)
{
    if (w == NULL || w->ply != NULL || w->fragment || nvert > GDT_PLY_MAX_VERTICES)
        return gdt_error_set(err, GDT_EINTERNAL, 7710,
                             "mesh writer: resuming what is not a text mesh in parts");
    if (w->fail.status != GDT_OK)
        return refail(w, err);
    if (flush_buf(w, err) != GDT_OK)
        return w->fail.status;
    if (offset > (uint64_t)INT64_MAX || lseek(w->fd, (off_t)offset, SEEK_SET) < 0)
        return wfail(w, err, GDT_EIO, 4712,
                     "%s: cannot go to byte %" PRIu64 " (temporary %s removed): %s", w->path,
                     offset, w->tmp_path, strerror(errno));
    w->nvert = nvert;
    w->nface = nface;
    w->in_faces = 1;
    return GDT_OK;
}

/* Another process's handle on the temporary of a text mesh in parts. */
struct gdt_mesh_part {
    int fd;
    char *path;
    char *buf; /* GDT_MESH_BUFFER_BYTES: copies that copy_file_range cannot make */
};

gdt_status gdt_mesh_part_open(gdt_mesh_part **out, const char *tmp_path, gdt_error *err)
{
    gdt_mesh_part *p = calloc(1, sizeof *p);
    *out = NULL;
    if (p == NULL || (p->path = strdup(tmp_path)) == NULL) {
        free(p);
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    }
    /* never created here: rank 0 made it, and a part must not bring back a
     * temporary that was removed after a failure */
    p->fd = open(tmp_path, O_WRONLY | O_CLOEXEC);
    if (p->fd < 0) {
        int e = errno;
        free(p->path);
        free(p);
        return gdt_error_set(err, GDT_EIO, 4720,
                             "%s: cannot open the mesh's temporary to "
                             "write a part: %s",
                             tmp_path, strerror(e));
    }
    *out = p;
    return GDT_OK;
}

gdt_status gdt_mesh_part_write(gdt_mesh_part *p, const void *bytes, size_t n, uint64_t offset,
                               gdt_error *err)
{
    int e =
        offset <= (uint64_t)INT64_MAX ? gdt_fd_write_all(p->fd, bytes, n, (int64_t)offset) : EFBIG;
    if (e != 0)
        return gdt_error_set(err, GDT_EIO, 4721,
                             "%s: writing a part at byte %" PRIu64 " failed: %s", p->path, offset,
                             strerror(e));
    return GDT_OK;
}

gdt_status gdt_mesh_part_copy(gdt_mesh_part *p, const char *fragment, uint64_t bytes,
                              uint64_t offset, gdt_error *err)
{
    int in = open(fragment, O_RDONLY | O_CLOEXEC);
    struct stat sb;
    uint64_t done = 0;
    int use_range = 1;
    gdt_status st = GDT_OK;

    if (in < 0 || fstat(in, &sb) != 0) {
        int e = errno;
        if (in >= 0)
            close(in);
        return gdt_error_set(err, GDT_EIO, 4805, "%s: cannot open: %s", fragment, strerror(e));
    }
    if ((uint64_t)sb.st_size != bytes) {
        close(in);
        return gdt_error_set(err, GDT_EJOB, 6802,
                             "%s: %" PRIu64 " bytes where %" PRIu64 " were written", fragment,
                             (uint64_t)sb.st_size, bytes);
    }
    while (st == GDT_OK && done < bytes) {
        size_t want = bytes - done < ((uint64_t)1 << 30) ? (size_t)(bytes - done) : (size_t)1 << 30;
        ssize_t k = -1;
        if (use_range) {
            off_t ioff = (off_t)done, ooff = (off_t)(offset + done);
            k = copy_file_range(in, &ioff, p->fd, &ooff, want, 0);
            if (k < 0 && (errno == EXDEV || errno == EINVAL || errno == ENOSYS ||
                          errno == EOPNOTSUPP || errno == EBADF)) {
                use_range = 0; /* this file system cannot: copy through memory */
                continue;
            }
            if (k < 0 && errno == EINTR)
                continue;
        } else {
            size_t got = 0;
            int e;
            if (p->buf == NULL && (p->buf = malloc(GDT_MESH_BUFFER_BYTES)) == NULL)
                st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
            if (st != GDT_OK)
                break;
            if (want > GDT_MESH_BUFFER_BYTES)
                want = GDT_MESH_BUFFER_BYTES;
            e = gdt_fd_pread_all(in, p->buf, want, done, &got);
            if (e != 0 || got == 0) {
                st = e != 0 ? gdt_error_set(err, GDT_EIO, 4805, "%s: cannot read: %s", fragment,
                                            strerror(e))
                            : gdt_error_set(err, GDT_EJOB, 6802, "%s: truncated", fragment);
                break;
            }
            st = gdt_mesh_part_write(p, p->buf, got, offset + done, err);
            k = (ssize_t)got;
        }
        if (st == GDT_OK && k < 0)
            st = gdt_error_set(err, GDT_EIO, 4721, "%s: copying %s into it failed: %s", p->path,
                               fragment, strerror(errno));
        else if (st == GDT_OK && k == 0)
            st = gdt_error_set(err, GDT_EJOB, 6802, "%s: truncated", fragment);
        else if (st == GDT_OK)
            done += (uint64_t)k;
    }
    close(in);
    return st;
}

gdt_status gdt_mesh_part_close(gdt_mesh_part *p, gdt_error *err)
{
    gdt_status st;
    if (p == NULL)
        return GDT_OK;
    st = gdt_fd_sync_close_part(p->fd, p->path, err);
    p->fd = -1;
    gdt_mesh_part_abort(p);
    return st;
}

void gdt_mesh_part_abort(gdt_mesh_part *p)
{
    if (p == NULL)
        return;
    if (p->fd >= 0)
        close(p->fd);
    free(p->path);
    free(p->buf);
    free(p);
}
