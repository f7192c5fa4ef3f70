/* Streaming reader for PCD (Point Cloud Data) files, versions 0.5 to 0.7.
 *
 * design:
 *   open:  parse the text header line by line (one line buffer, capped), check
 *          every key, cross-check FIELDS/SIZE/TYPE/COUNT, WIDTH x HEIGHT ==
 *          POINTS, and the data size against the file size for the binary
 *          encodings; locate the x/y/z fields (names in any case).
 *   read:  ascii              tokens scanned byte by byte from a buffer of
 *                             opts.buffer_bytes; one record per line.
 *          binary             whole records read into a buffer of
 *                             max(opts.buffer_bytes, one record) bytes.
 *          binary_compressed  the LZF block holds the fields one after the
 *                             other (all x, then all y, ...).  Three LZF
 *                             decoders walk the same compressed stream, each
 *                             positioned at the start of one coordinate
 *                             column, so point i is assembled from the i-th
 *                             value of each column without ever holding the
 *                             uncompressed block: memory is three 8 KiB
 *                             decoder windows plus three input buffers of
 *                             opts.buffer_bytes, whatever the point count.
 *                             Cost: up to three decodings of the stream.
 *          After the last point the whole remaining input is checked (ascii:
 *          nothing but white space; compressed: the stream decodes to exactly
 *          the declared size and ends there).  Binary files may carry bytes
 *          after the data (PCL's writers pad them): those are ignored.
 *   Points whose x, y or z is NaN or infinite (PCL marks invalid points of
 *   organized clouds with NaN) are skipped and counted; one warning at the end.
 *
 * notes: the byte order of binary data is little-endian (as written by PCL on
 * every platform it supports); numbers in ascii data are parsed with strtod /
 * strtof in the "C" locale (the library never changes the locale).
 */
#include "private/bytes.h"
#include "private/pcd_lzf.h"
#include "private/source_impl.h"

#include <errno.h>
#include <inttypes.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#define PCD_MAX_FIELDS 4096u               /* fields named in FIELDS */
#define PCD_MAX_LINE ((size_t)256 << 10)   /* bytes in one header line */
#define PCD_MAX_RECORD ((uint64_t)1 << 20) /* bytes (or ascii values) per point */
#define PCD_MAX_TOKEN 128u                 /* characters of one ascii number */
#define PCD_MIN_CBUF 64u                   /* smallest compressed-input buffer */

/* Float32 has a unit round-off of 2^-24: a coordinate v stored as F4 may be
 * off by up to |v| * 2^-24.  Beyond 2^24 * 0.001 (about 16.8 km) that bound
 * exceeds the default 1 mm lattice, so such files get a precision warning. */
#define PCD_F4_PRECISE_LIMIT (16777216.0 * 0.001)

typedef enum pcd_encoding { PCD_ASCII, PCD_BINARY, PCD_COMPRESSED } pcd_encoding;

typedef struct pcd_field {
    char *name;     /* points into pcd_reader.names */
    unsigned size;  /* bytes per value: 1, 2, 4, 8 */
    char type;      /* 'F', 'I', 'U' */
    uint64_t count; /* values per point, >= 1 */
} pcd_field;

/* Where one coordinate lives in each encoding. */
typedef struct pcd_coord {
    unsigned size;
    char type;
    uint64_t rec_off; /* byte offset inside a binary record */
    uint64_t col_off; /* byte offset of its column in the uncompressed block */
    uint64_t token;   /* index of its value in an ascii record */
} pcd_coord;

/* One LZF decoder positioned on one column of the compressed block. */
typedef struct pcd_column {
    gdt_lzf_dec dec;
    uint64_t in_pos; /* file offset of the next compressed byte to fetch */
    uint8_t *in;     /* fetched compressed bytes, in[in_off .. in_len) unused yet */
    size_t in_len, in_off, in_cap;
    int positioned; /* 1 once the decoder has skipped to its column */
} pcd_column;

typedef struct pcd_reader {
    FILE *f;
    const char *path; /* src->path */
    gdt_log *log;
    pcd_encoding enc;
    uint32_t nfields;
    pcd_field *fields;    /* nfields entries */
    char *names;          /* storage of the field names */
    uint64_t record_size; /* bytes per binary record, padding fields '_' included */
    uint64_t packed_size; /* bytes per point in the compressed block ('_' excluded) */
    uint64_t tokens;      /* values per ascii record */
    pcd_coord xyz[3];
    uint64_t npoints;  /* POINTS (== WIDTH * HEIGHT) */
    uint64_t next;     /* index of the next point record to decode */
    uint64_t first, end; /* the records read: [0, npoints), or a binary
                            file's range (pcd_seek) */
    uint64_t data_off; /* file offset of the first data byte */
    uint64_t file_size;
    /* ascii and binary read buffer: buf[pos .. len) not consumed yet */
    uint8_t *buf;
    size_t cap, len, pos;
    int at_eof;    /* the file has no bytes beyond buf[len) */
    uint64_t line; /* ascii: number of the line being read (1-based) */
    /* binary_compressed */
    uint64_t csize, usize; /* declared compressed / uncompressed sizes */
    pcd_column col[3];
    uint64_t skipped; /* points dropped for NaN/inf coordinates */
    int warned_precision;
    int finished;      /* trailing checks done, warnings given */
    gdt_status failed; /* sticky failure of an earlier read */
    char version[8];
} pcd_reader;

static const char pcd_crs_desc[] = "unknown (PCD has no CRS)";

/* ------------------------------------------------------------------------ */
/* small helpers                                                             */

/* Copies at most 40 characters of s into out, non-printable bytes as '?', so
 * garbage never reaches a terminal raw. */
static const char *pcd_printable(const char *s, char out[48])
{
    size_t i = 0;
    for (; s[i] != '\0' && i < 40; i++)
        out[i] = (s[i] >= 0x20 && s[i] < 0x7f) ? s[i] : '?';
    if (s[i] != '\0') {
        memcpy(out + i, "...", 3);
        i += 3;
    }
    out[i] = '\0';
    return out;
}

/* Decimal unsigned integer, digits only; returns 0 on success. */
static int pcd_parse_u64(const char *s, uint64_t *out)
{
    uint64_t v = 0;
    if (*s == '\0')
        return -1;
    for (; *s != '\0'; s++) {
        unsigned d;
        if (*s < '0' || *s > '9')
            return -1;
        d = (unsigned)(*s - '0');
        if (v > (UINT64_MAX - d) / 10)
            return -1;
        v = v * 10 + d;
    }
    *out = v;
    return 0;
}

static int pcd_parse_double(const char *s, double *out)
{
    char *end = NULL;
    if (*s == '\0')
        return -1;
    *out = strtod(s, &end);
    return *end == '\0' ? 0 : -1;
}

static int pcd_iequal(const char *a, const char *b)
{
    for (; *a != '\0' && *b != '\0'; a++, b++) {
        int ca = (*a >= 'A' && *a <= 'Z') ? *a + 32 : *a;
        int cb = (*b >= 'A' && *b <= 'Z') ? *b + 32 : *b;
        if (ca != cb)
            return 0;
    }
    return *a == *b;
}

/* Little-endian value of the given PCD type at p (size bytes). */
static double pcd_decode_value(const uint8_t *p, char type, unsigned size)
{
    uint64_t u = 0;
    for (unsigned i = size; i-- > 0;)
        u = (u << 8) | p[i];
    if (type == 'F') {
        if (size == 4) {
            uint32_t u32 = (uint32_t)u;
            float fv;
            memcpy(&fv, &u32, sizeof fv);
            return (double)fv;
        }
        double dv;
        memcpy(&dv, &u, sizeof dv);
        return dv;
    }
    if (type == 'I' && size < 8 && (u >> (8 * size - 1)) != 0)
        u |= ~(uint64_t)0 << (8 * size); /* sign extension */
    if (type == 'I') {
        /* two's complement without implementation-defined conversions */
        if (u >> 63)
            return -(double)(~u) - 1.0;
        return (double)u;
    }
    return (double)u;
}

/* ------------------------------------------------------------------------ */
/* header                                                                    */

enum {
    KEY_VERSION,
    KEY_FIELDS,
    KEY_SIZE,
    KEY_TYPE,
    KEY_COUNT,
    KEY_WIDTH,
    KEY_HEIGHT,
    KEY_VIEWPOINT,
    KEY_POINTS,
    KEY_DATA,
    KEY_N
};
static const char *const pcd_key_names[KEY_N] = {
    "VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS", "DATA"};

/* Raw header values as read, before the cross-checks. */
typedef struct pcd_header {
    int seen[KEY_N];
    uint64_t line_of[KEY_N];
    int version;     /* 5, 6, 7, or 0 without a VERSION line */
    uint64_t *sizes; /* nfields entries each, when seen */
    char *types;
    uint64_t *counts;
    uint64_t width, height, points;
} pcd_header;

/* Reads one header line into line[0 .. *len) (NUL-terminated, without the
 * newline).  *got is 0 at the end of the file. */
static gdt_status pcd_header_line(pcd_reader *r, char *line, size_t *len, int *got, uint64_t lineno,
                                  gdt_error *err)
{
    size_t n = 0;
    int c;
    *got = 0;
    while ((c = getc(r->f)) != EOF) {
        *got = 1;
        if (c == '\n')
            break;
        if (c == '\0')
            return gdt_error_set(err, GDT_EINPUT, 3202,
                                 "%s: PCD header line %" PRIu64 " contains a NUL byte "
                                 "(not a PCD header)",
                                 r->path, lineno);
        if (n + 1 >= PCD_MAX_LINE)
            return gdt_error_set(err, GDT_EINPUT, 3202,
                                 "%s: PCD header line %" PRIu64 " is longer than %zu bytes",
                                 r->path, lineno, PCD_MAX_LINE);
        line[n++] = (char)c;
    }
    if (ferror(r->f))
        return gdt_error_set(err, GDT_EIO, 4201, "%s: read error in the PCD header: %s", r->path,
                             strerror(errno));
    line[n] = '\0';
    *len = n;
    return GDT_OK;
}

/* Splits line in place at blanks (space, tab, CR, VT, FF); at most max tokens.
 * returns: the token count, or max + 1 when there are more. */
static size_t pcd_split(char *line, char **tok, size_t max)
{
    size_t n = 0;
    char *p = line;
    for (;;) {
        while (*p == ' ' || *p == '\t' || *p == '\r' || *p == '\v' || *p == '\f')
            p++;
        if (*p == '\0')
            return n;
        if (n == max)
            return max + 1;
        tok[n++] = p;
        while (*p != '\0' && *p != ' ' && *p != '\t' && *p != '\r' && *p != '\v' && *p != '\f')
            p++;
        if (*p != '\0')
            *p++ = '\0';
    }
}

/* Handles the values of one header key (tok[0] is the key). */
static gdt_status pcd_header_key(pcd_reader *r, pcd_header *h, int key, char **tok, size_t ntok,
                                 uint64_t lineno, gdt_error *err)
{
    size_t nval = ntok - 1;
    char pr[48], pn[48];

    if (h->seen[key])
        return gdt_error_set(err, GDT_EINPUT, 3205,
                             "%s: PCD header line %" PRIu64 ": duplicate %s (first on line %" PRIu64
                             ")",
                             r->path, lineno, pcd_key_names[key], h->line_of[key]);
    h->seen[key] = 1;
    h->line_of[key] = lineno;
    if ((key == KEY_SIZE || key == KEY_TYPE || key == KEY_COUNT) && !h->seen[KEY_FIELDS])
        return gdt_error_set(err, GDT_EINPUT, 3209,
                             "%s: PCD header line %" PRIu64 ": %s comes before FIELDS", r->path,
                             lineno, pcd_key_names[key]);
    if ((key == KEY_SIZE || key == KEY_TYPE || key == KEY_COUNT) && nval != r->nfields)
        return gdt_error_set(err, GDT_EINPUT, 3209,
                             "%s: PCD header line %" PRIu64 ": %s has %zu values but FIELDS "
                             "names %" PRIu32 " fields",
                             r->path, lineno, pcd_key_names[key], nval, r->nfields);
    switch (key) {
    case KEY_VERSION: {
        static const char *const ok[] = {"0.5", ".5", "0.6", ".6", "0.7", ".7"};
        if (nval == 1)
            for (int i = 0; i < 6; i++)
                if (strcmp(tok[1], ok[i]) == 0)
                    h->version = 5 + i / 2;
        if (h->version == 0)
            return gdt_error_set(err, GDT_EINPUT, 3207,
                                 "%s: PCD header line %" PRIu64 ": unsupported VERSION '%s' "
                                 "(0.5, 0.6 and 0.7 are read)",
                                 r->path, lineno, nval >= 1 ? pcd_printable(tok[1], pr) : "");
        snprintf(r->version, sizeof r->version, "0.%d", h->version);
        return GDT_OK;
    }
    case KEY_FIELDS: {
        size_t bytes = 0;
        char *dst;
        if (nval == 0 || nval > PCD_MAX_FIELDS)
            return gdt_error_set(err, GDT_EINPUT, 3208,
                                 "%s: PCD header line %" PRIu64 ": FIELDS must name 1 to %u "
                                 "fields",
                                 r->path, lineno, PCD_MAX_FIELDS);
        for (size_t i = 1; i < ntok; i++)
            bytes += strlen(tok[i]) + 1;
        r->fields = calloc(nval, sizeof *r->fields);
        r->names = malloc(bytes);
        h->sizes = calloc(nval, sizeof *h->sizes);
        h->types = calloc(nval, 1);
        h->counts = calloc(nval, sizeof *h->counts);
        if (r->fields == NULL || r->names == NULL || h->sizes == NULL || h->types == NULL ||
            h->counts == NULL)
            return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        r->nfields = (uint32_t)nval;
        dst = r->names;
        for (size_t i = 0; i < nval; i++) {
            size_t l = strlen(tok[i + 1]) + 1;
            memcpy(dst, tok[i + 1], l);
            r->fields[i].name = dst;
            dst += l;
        }
        return GDT_OK;
    }
    case KEY_SIZE:
        for (size_t i = 0; i < nval; i++)
            if (pcd_parse_u64(tok[i + 1], &h->sizes[i]) != 0 ||
                (h->sizes[i] != 1 && h->sizes[i] != 2 && h->sizes[i] != 4 && h->sizes[i] != 8))
                return gdt_error_set(err, GDT_EINPUT, 3210,
                                     "%s: PCD header line %" PRIu64 ": SIZE '%s' of field '%s' "
                                     "is not 1, 2, 4 or 8",
                                     r->path, lineno, pcd_printable(tok[i + 1], pr),
                                     pcd_printable(r->fields[i].name, pn));
        return GDT_OK;
    case KEY_TYPE:
        for (size_t i = 0; i < nval; i++) {
            const char *t = tok[i + 1];
            if ((t[0] != 'F' && t[0] != 'I' && t[0] != 'U') || t[1] != '\0')
                return gdt_error_set(err, GDT_EINPUT, 3210,
                                     "%s: PCD header line %" PRIu64 ": TYPE '%s' of field '%s' "
                                     "is not F, I or U",
                                     r->path, lineno, pcd_printable(t, pr),
                                     pcd_printable(r->fields[i].name, pn));
            h->types[i] = t[0];
        }
        return GDT_OK;
    case KEY_COUNT:
        for (size_t i = 0; i < nval; i++)
            if (pcd_parse_u64(tok[i + 1], &h->counts[i]) != 0 || h->counts[i] == 0 ||
                h->counts[i] > PCD_MAX_RECORD)
                return gdt_error_set(err, GDT_EINPUT, 3211,
                                     "%s: PCD header line %" PRIu64 ": COUNT '%s' of field '%s' "
                                     "is not an integer in 1..%" PRIu64,
                                     r->path, lineno, pcd_printable(tok[i + 1], pr),
                                     pcd_printable(r->fields[i].name, pn), PCD_MAX_RECORD);
        return GDT_OK;
    case KEY_WIDTH:
    case KEY_HEIGHT:
    case KEY_POINTS: {
        uint64_t *dst = key == KEY_WIDTH ? &h->width : key == KEY_HEIGHT ? &h->height : &h->points;
        if (nval != 1 || pcd_parse_u64(tok[1], dst) != 0)
            return gdt_error_set(err, GDT_EINPUT, 3212,
                                 "%s: PCD header line %" PRIu64 ": %s needs one non-negative "
                                 "integer",
                                 r->path, lineno, pcd_key_names[key]);
        return GDT_OK;
    }
    case KEY_VIEWPOINT: {
        double v;
        if (nval != 7)
            return gdt_error_set(err, GDT_EINPUT, 3214,
                                 "%s: PCD header line %" PRIu64 ": VIEWPOINT needs 7 numbers "
                                 "(tx ty tz qw qx qy qz), found %zu",
                                 r->path, lineno, nval);
        for (size_t i = 1; i <= 7; i++)
            if (pcd_parse_double(tok[i], &v) != 0)
                return gdt_error_set(err, GDT_EINPUT, 3214,
                                     "%s: PCD header line %" PRIu64 ": VIEWPOINT value '%s' is "
                                     "not a number",
                                     r->path, lineno, pcd_printable(tok[i], pr));
        return GDT_OK;
    }
    case KEY_DATA:
        if (nval == 1 && strcmp(tok[1], "ascii") == 0)
            r->enc = PCD_ASCII;
        else if (nval == 1 && strcmp(tok[1], "binary") == 0)
            r->enc = PCD_BINARY;
        else if (nval == 1 && strcmp(tok[1], "binary_compressed") == 0)
            r->enc = PCD_COMPRESSED;
        else
            return gdt_error_set(err, GDT_EINPUT, 3215,
                                 "%s: PCD header line %" PRIu64 ": DATA must be ascii, binary "
                                 "or binary_compressed, found '%s'",
                                 r->path, lineno, nval >= 1 ? pcd_printable(tok[1], pr) : "");
        return GDT_OK;
    default: break;
    }
    return gdt_error_set(err, GDT_EINTERNAL, 7002, "%s: PCD header key %d unhandled", r->path, key);
}

/* Cross-checks the header once DATA was read and lays out the fields.
 * Version 0.7 requires FIELDS SIZE TYPE WIDTH HEIGHT POINTS DATA; earlier
 * versions (and files without VERSION) default SIZE to 4, TYPE to F,
 * HEIGHT to 1 and POINTS to WIDTH x HEIGHT.  COUNT defaults to 1 and
 * VIEWPOINT is optional everywhere. */
static gdt_status pcd_header_check(pcd_reader *r, pcd_header *h, gdt_error *err)
{
    static const int required7[] = {KEY_FIELDS, KEY_SIZE,   KEY_TYPE, KEY_WIDTH,
                                    KEY_HEIGHT, KEY_POINTS, KEY_DATA};
    static const int required_old[] = {KEY_FIELDS, KEY_WIDTH, KEY_DATA};
    const int *req = h->version == 7 ? required7 : required_old;
    size_t nreq = h->version == 7 ? 7 : 3;
    uint64_t rec = 0, packed = 0, tokens = 0;
    int found[3] = {-1, -1, -1};
    static const char *const axis[3] = {"x", "y", "z"};
    char pr[48], pn[48];

    for (size_t i = 0; i < nreq; i++)
        if (!h->seen[req[i]])
            return gdt_error_set(err, GDT_EINPUT, 3206,
                                 "%s: PCD header has no %s line (required%s)", r->path,
                                 pcd_key_names[req[i]], h->version == 7 ? " in version 0.7" : "");
    if (!h->seen[KEY_HEIGHT])
        h->height = 1;
    if (h->width != 0 && h->height > UINT64_MAX / h->width)
        return gdt_error_set(err, GDT_EINPUT, 3213,
                             "%s: PCD header WIDTH %" PRIu64 " x HEIGHT %" PRIu64 " overflows",
                             r->path, h->width, h->height);
    if (!h->seen[KEY_POINTS])
        h->points = h->width * h->height;
    if (h->width * h->height != h->points)
        return gdt_error_set(err, GDT_EINPUT, 3213,
                             "%s: PCD header says POINTS %" PRIu64 " but WIDTH %" PRIu64
                             " x HEIGHT %" PRIu64 " = %" PRIu64,
                             r->path, h->points, h->width, h->height, h->width * h->height);
    for (uint32_t i = 0; i < r->nfields; i++) {
        pcd_field *fd = &r->fields[i];
        fd->size = h->seen[KEY_SIZE] ? (unsigned)h->sizes[i] : 4;
        fd->type = h->seen[KEY_TYPE] ? h->types[i] : 'F';
        fd->count = h->seen[KEY_COUNT] ? h->counts[i] : 1;
        if (fd->type == 'F' && fd->size != 4 && fd->size != 8)
            return gdt_error_set(err, GDT_EINPUT, 3210,
                                 "%s: PCD field '%s' has TYPE F with SIZE %u (floats are 4 or 8 "
                                 "bytes)",
                                 r->path, pcd_printable(fd->name, pn), fd->size);
        /* count <= PCD_MAX_RECORD and size <= 8, so no product overflows */
        rec += fd->count * fd->size;
        if (strcmp(fd->name, "_") != 0)
            packed += fd->count * fd->size;
        tokens += fd->count;
        if (rec > PCD_MAX_RECORD)
            return gdt_error_set(err, GDT_EINPUT, 3217,
                                 "%s: PCD point records are larger than %" PRIu64 " bytes", r->path,
                                 PCD_MAX_RECORD);
        for (int a = 0; a < 3; a++) {
            if (!pcd_iequal(fd->name, axis[a]))
                continue;
            if (found[a] >= 0)
                return gdt_error_set(err, GDT_EINPUT, 3216,
                                     "%s: PCD fields '%s' and '%s' both name coordinate %s",
                                     r->path, pcd_printable(r->fields[found[a]].name, pr),
                                     pcd_printable(fd->name, pn), axis[a]);
            if (fd->count != 1)
                return gdt_error_set(err, GDT_EINPUT, 3216,
                                     "%s: PCD coordinate field '%s' has COUNT %" PRIu64
                                     " (must be 1)",
                                     r->path, pcd_printable(fd->name, pn), fd->count);
            found[a] = (int)i;
        }
    }
    for (int a = 0; a < 3; a++)
        if (found[a] < 0)
            return gdt_error_set(err, GDT_EINPUT, 3216,
                                 "%s: PCD file has no %s field (FIELDS must name x, y and z, "
                                 "in any case)",
                                 r->path, axis[a]);
    if (rec == 0 || (h->points != 0 && h->points > (UINT64_MAX >> 2) / rec))
        return gdt_error_set(err, GDT_EINPUT, 3212,
                             "%s: PCD header POINTS %" PRIu64 " is impossibly large", r->path,
                             h->points);
    r->record_size = rec;
    r->packed_size = packed;
    r->tokens = tokens;
    r->npoints = h->points;
    {
        uint64_t off = 0, col = 0, tok = 0;
        for (uint32_t i = 0; i < r->nfields; i++) {
            const pcd_field *fd = &r->fields[i];
            for (int a = 0; a < 3; a++)
                if (found[a] == (int)i) {
                    r->xyz[a].size = fd->size;
                    r->xyz[a].type = fd->type;
                    r->xyz[a].rec_off = off;
                    r->xyz[a].col_off = col;
                    r->xyz[a].token = tok;
                }
            off += fd->size * fd->count;
            if (strcmp(fd->name, "_") != 0)
                col += fd->size * fd->count * r->npoints;
            tok += fd->count;
        }
    }
    if (r->version[0] == '\0')
        snprintf(r->version, sizeof r->version, "%s", "none"); /* read with the 0.5 defaults */
    return GDT_OK;
}

static gdt_status pcd_read_header(pcd_reader *r, gdt_error *err)
{
    pcd_header h;
    char *line = NULL;
    char **tok = NULL;
    gdt_status st = GDT_OK;
    uint64_t lineno = 0;
    char pr[48];

    memset(&h, 0, sizeof h);
    line = malloc(PCD_MAX_LINE);
    tok = malloc((PCD_MAX_FIELDS + 2) * sizeof *tok);
    if (line == NULL || tok == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    while (!h.seen[KEY_DATA]) {
        size_t len = 0, ntok;
        int got = 0, key = -1;
        lineno++;
        st = pcd_header_line(r, line, &len, &got, lineno, err);
        if (st != GDT_OK)
            goto fail;
        if (!got) {
            st = gdt_error_set(err, GDT_EINPUT, 3203,
                               "%s: PCD header ends at line %" PRIu64 " before its DATA line "
                               "(truncated file?)",
                               r->path, lineno);
            goto fail;
        }
        ntok = pcd_split(line, tok, PCD_MAX_FIELDS + 1);
        if (ntok == 0 || tok[0][0] == '#')
            continue;
        for (int k = 0; k < KEY_N; k++)
            if (strcmp(tok[0], pcd_key_names[k]) == 0)
                key = k;
        if (strcmp(tok[0], "COLUMNS") == 0) /* the 0.5 name of FIELDS */
            key = KEY_FIELDS;
        if (key < 0) {
            st = gdt_error_set(err, GDT_EINPUT, 3204,
                               "%s: PCD header line %" PRIu64 ": unknown key '%s'", r->path, lineno,
                               pcd_printable(tok[0], pr));
            goto fail;
        }
        if (ntok > PCD_MAX_FIELDS + 1) {
            st = gdt_error_set(err, GDT_EINPUT, key == KEY_FIELDS ? 3208 : 3209,
                               "%s: PCD header line %" PRIu64 ": %s has more than %u values",
                               r->path, lineno, pcd_key_names[key], PCD_MAX_FIELDS);
            goto fail;
        }
        st = pcd_header_key(r, &h, key, tok, ntok, lineno, err);
        if (st != GDT_OK)
            goto fail;
    }
    r->line = lineno + 1;
    st = pcd_header_check(r, &h, err);
fail:
    free(h.sizes);
    free(h.types);
    free(h.counts);
    free(tok);
    free(line);
    return st;
}

/* ------------------------------------------------------------------------ */
/* ascii                                                                     */

/* Next data byte, EOF at the end of the file, or -2 after a read error
 * (already recorded in err). */
static int pcd_getc(pcd_reader *r, gdt_error *err)
{
    if (r->pos == r->len) {
        if (r->at_eof)
            return EOF;
        r->len = fread(r->buf, 1, r->cap, r->f);
        r->pos = 0;
        if (r->len < r->cap) {
            if (ferror(r->f)) {
                gdt_error_set(err, GDT_EIO, 4201, "%s: read error: %s", r->path, strerror(errno));
                return -2;
            }
            r->at_eof = 1;
        }
        if (r->len == 0)
            return EOF;
    }
    return r->buf[r->pos++];
}

static int pcd_blank(int c)
{
    return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f';
}

/* Parses ascii token s as a value of coordinate a. */
static int pcd_parse_coord(const pcd_coord *cd, const char *s, double *out)
{
    char *end = NULL;
    errno = 0;
    if (cd->type == 'F' && cd->size == 4) {
        *out = (double)strtof(s, &end);
    } else if (cd->type == 'F') {
        *out = strtod(s, &end);
    } else if (cd->type == 'I') {
        long long v = strtoll(s, &end, 10);
        long long lim = cd->size == 8 ? LLONG_MAX : (1LL << (8 * cd->size - 1)) - 1;
        if (errno == ERANGE || v > lim || v < -lim - 1)
            return -1;
        *out = (double)v;
    } else {
        unsigned long long v;
        if (*s == '-')
            return -1;
        v = strtoull(s, &end, 10);
        if (errno == ERANGE || (cd->size < 8 && v > (1ULL << (8 * cd->size)) - 1))
            return -1;
        *out = (double)v;
    }
    return (end != s && *end == '\0') ? 0 : -1;
}

/* Reads one ascii record (one line; blank lines before it are skipped). */
static gdt_status pcd_ascii_point(pcd_reader *r, double p[3], gdt_error *err)
{
    char tok[PCD_MAX_TOKEN + 1];
    uint64_t k = 0;
    int c;
    char pr[48];

    for (;;) { /* skip blank lines */
        c = pcd_getc(r, err);
        while (pcd_blank(c))
            c = pcd_getc(r, err);
        if (c == -2)
            return GDT_EIO;
        if (c == EOF)
            return gdt_error_set(err, GDT_EINPUT, 3242,
                                 "%s: PCD data ends at line %" PRIu64 " after %" PRIu64
                                 " of %" PRIu64 " points (truncated file or wrong POINTS)",
                                 r->path, r->line, r->next, r->npoints);
        if (c != '\n')
            break;
        r->line++;
    }
    for (;;) {
        size_t n = 0;
        while (c >= 0 && c != '\n' && !pcd_blank(c)) {
            if (n == PCD_MAX_TOKEN || c == '\0') {
                tok[n] = '\0';
                return gdt_error_set(err, GDT_EINPUT, 3241,
                                     "%s: PCD data line %" PRIu64 ": value %" PRIu64
                                     " ('%s') is not a number",
                                     r->path, r->line, k + 1, pcd_printable(tok, pr));
            }
            tok[n++] = (char)c;
            c = pcd_getc(r, err);
        }
        if (c == -2)
            return GDT_EIO;
        tok[n] = '\0';
        if (k == r->tokens)
            return gdt_error_set(err, GDT_EINPUT, 3240,
                                 "%s: PCD data line %" PRIu64 " has more than the %" PRIu64
                                 " values the header declares",
                                 r->path, r->line, r->tokens);
        {
            int a, bad;
            double v;
            for (a = 0; a < 3; a++)
                if (r->xyz[a].token == k)
                    break;
            bad = a < 3 ? pcd_parse_coord(&r->xyz[a], tok, &p[a]) : pcd_parse_double(tok, &v);
            if (bad)
                return gdt_error_set(
                    err, GDT_EINPUT, 3241,
                    "%s: PCD data line %" PRIu64 ": value %" PRIu64 " ('%s') is not a number%s",
                    r->path, r->line, k + 1, pcd_printable(tok, pr),
                    a < 3 && r->xyz[a].type != 'F' ? " in the range of its integer type" : "");
        }
        k++;
        while (pcd_blank(c))
            c = pcd_getc(r, err);
        if (c == -2)
            return GDT_EIO;
        if (c == '\n' || c == EOF)
            break;
    }
    if (k != r->tokens)
        return gdt_error_set(err, GDT_EINPUT, 3240,
                             "%s: PCD data line %" PRIu64 " has %" PRIu64 " values, the header "
                             "declares %" PRIu64,
                             r->path, r->line, k, r->tokens);
    if (c == '\n')
        r->line++;
    return GDT_OK;
}

/* After the last record only white space may follow. */
static gdt_status pcd_ascii_finish(pcd_reader *r, gdt_error *err)
{
    int c;
    while ((c = pcd_getc(r, err)) != EOF) {
        if (c == -2)
            return GDT_EIO;
        if (c == '\n')
            r->line++;
        else if (!pcd_blank(c))
            return gdt_error_set(err, GDT_EINPUT, 3243,
                                 "%s: PCD data line %" PRIu64 ": more data after the %" PRIu64
                                 " points declared by POINTS",
                                 r->path, r->line, r->npoints);
    }
    return GDT_OK;
}

/* ------------------------------------------------------------------------ */
/* binary                                                                    */

static gdt_status pcd_binary_point(pcd_reader *r, double p[3], gdt_error *err)
{
    const uint8_t *rec;
    if (r->pos == r->len) {
        uint64_t left = (r->end - r->next) * r->record_size;
        size_t want = (r->cap / r->record_size) * r->record_size;
        if ((uint64_t)want > left)
            want = (size_t)left;
        r->len = fread(r->buf, 1, want, r->f);
        r->pos = 0;
        if (r->len < want) {
            if (ferror(r->f))
                return gdt_error_set(err, GDT_EIO, 4201, "%s: read error: %s", r->path,
                                     strerror(errno));
            return gdt_error_set(err, GDT_EINPUT, 3222,
                                 "%s: PCD binary data ends inside point %" PRIu64 " of %" PRIu64
                                 " (file truncated while reading)",
                                 r->path, r->next + r->len / r->record_size, r->npoints);
        }
    }
    rec = r->buf + r->pos;
    for (int a = 0; a < 3; a++)
        p[a] = pcd_decode_value(rec + r->xyz[a].rec_off, r->xyz[a].type, r->xyz[a].size);
    r->pos += (size_t)r->record_size;
    return GDT_OK;
}

/* ------------------------------------------------------------------------ */
/* binary_compressed                                                         */

/* Produces the next n bytes of column cursor c into out (NULL: discard).
 * The compressed stream is file[data_off + 8 .. data_off + 8 + csize). */
static gdt_status pcd_column_take(pcd_reader *r, pcd_column *c, uint8_t *out, uint64_t n,
                                  gdt_error *err)
{
    const uint64_t in_end = r->data_off + 8 + r->csize;
    while (n > 0) {
        size_t used = 0, made = 0;
        size_t want = n > (uint64_t)SIZE_MAX ? SIZE_MAX : (size_t)n;
        size_t get;
        /* A pending back-reference produces output without input, so the
         * decoder runs first and input is fetched only when it is stuck. */
        if (gdt_lzf_decode(&c->dec, c->in + c->in_off, c->in_len - c->in_off, &used, out, want,
                           &made) != GDT_LZF_OK)
            return gdt_error_set(err, GDT_EINPUT, 3234,
                                 "%s: PCD compressed data is corrupt: LZF back-reference "
                                 "before the start of the data (at output byte %" PRIu64 ")",
                                 r->path, c->dec.produced);
        c->in_off += used;
        n -= made;
        if (out != NULL)
            out += made;
        if (made > 0 || used > 0)
            continue;
        /* stuck: every fetched byte is used (in_off == in_len) */
        get = c->in_cap;
        if ((uint64_t)get > in_end - c->in_pos)
            get = (size_t)(in_end - c->in_pos);
        if (get == 0)
            return gdt_error_set(err, GDT_EINPUT, 3235,
                                 "%s: PCD compressed data is corrupt: the LZF stream ends "
                                 "after %" PRIu64 " of %" PRIu64 " bytes",
                                 r->path, c->dec.produced, r->usize);
        if (fseeko(r->f, (off_t)c->in_pos, SEEK_SET) != 0 || fread(c->in, 1, get, r->f) != get) {
            if (ferror(r->f))
                return gdt_error_set(err, GDT_EIO, 4201, "%s: read error: %s", r->path,
                                     strerror(errno));
            return gdt_error_set(err, GDT_EINPUT, 3222,
                                 "%s: PCD compressed data is shorter than declared "
                                 "(file truncated while reading)",
                                 r->path);
        }
        c->in_pos += get;
        c->in_len = get;
        c->in_off = 0;
    }
    return GDT_OK;
}

static gdt_status pcd_compressed_point(pcd_reader *r, double p[3], gdt_error *err)
{
    for (int a = 0; a < 3; a++) {
        pcd_column *c = &r->col[a];
        uint8_t v[8];
        gdt_status st;
        if (!c->positioned) {
            st = pcd_column_take(r, c, NULL, r->xyz[a].col_off, err);
            if (st != GDT_OK)
                return st;
            c->positioned = 1;
        }
        st = pcd_column_take(r, c, v, r->xyz[a].size, err);
        if (st != GDT_OK)
            return st;
        p[a] = pcd_decode_value(v, r->xyz[a].type, r->xyz[a].size);
    }
    return GDT_OK;
}

/* Decodes the rest of the stream with the cursor that is furthest along:
 * it must yield exactly usize bytes and end exactly at the end of the
 * compressed data, on an item boundary. */
static gdt_status pcd_compressed_finish(pcd_reader *r, gdt_error *err)
{
    pcd_column *c = &r->col[0];
    gdt_status st;
    for (int a = 1; a < 3; a++)
        if (r->col[a].dec.produced > c->dec.produced)
            c = &r->col[a];
    st = pcd_column_take(r, c, NULL, r->usize - c->dec.produced, err);
    if (st != GDT_OK)
        return st;
    if (c->in_off != c->in_len || c->in_pos != r->data_off + 8 + r->csize ||
        !gdt_lzf_at_item_boundary(&c->dec))
        return gdt_error_set(err, GDT_EINPUT, 3236,
                             "%s: PCD compressed data is corrupt: the LZF stream does not end "
                             "at the declared uncompressed size %" PRIu64,
                             r->path, r->usize);
    return GDT_OK;
}

/* Checks the 8-byte size prefix of the compressed block against the header
 * and the file, and sets up the column cursors. */
static gdt_status pcd_compressed_open(pcd_reader *r, size_t buffer_bytes, gdt_error *err)
{
    uint8_t pre[8];
    uint64_t expect;
    if (r->file_size < r->data_off + 8)
        return gdt_error_set(err, GDT_EINPUT, 3230,
                             "%s: PCD binary_compressed file ends before its 8-byte size "
                             "prefix (truncated)",
                             r->path);
    if (fread(pre, 1, 8, r->f) != 8)
        return gdt_error_set(err, ferror(r->f) ? GDT_EIO : GDT_EINPUT, ferror(r->f) ? 4201 : 3230,
                             "%s: cannot read the PCD compressed "
                             "size prefix",
                             r->path);
    r->csize = gdt_le_get_u32(pre);
    r->usize = gdt_le_get_u32(pre + 4);
    expect = r->npoints * r->packed_size;
    if (r->usize != expect)
        return gdt_error_set(err, GDT_EINPUT, 3231,
                             "%s: PCD compressed block declares %" PRIu64 " uncompressed bytes "
                             "but POINTS %" PRIu64 " x %" PRIu64 " bytes per point = %" PRIu64,
                             r->path, r->usize, r->npoints, r->packed_size, expect);
    /* Bytes after the block are ignored (PCL pads its files, see gdt_pcd_open). */
    if (r->data_off + 8 + r->csize > r->file_size)
        return gdt_error_set(err, GDT_EINPUT, 3232,
                             "%s: PCD compressed block declares %" PRIu64 " bytes but the file "
                             "holds only %" PRIu64 " after the size prefix (truncated)",
                             r->path, r->csize, r->file_size - r->data_off - 8);
    /* A literal item costs one control byte per <= 32 bytes; a back-reference
     * yields at most 264 bytes from 3 input bytes after a first literal. */
    if (r->csize > r->usize + r->usize / 32 + 1 || r->usize > 88 * r->csize)
        return gdt_error_set(err, GDT_EINPUT, 3233,
                             "%s: PCD compressed sizes %" PRIu64 " -> %" PRIu64 " are "
                             "impossible for LZF",
                             r->path, r->csize, r->usize);
    for (int a = 0; a < 3; a++) {
        pcd_column *c = &r->col[a];
        gdt_lzf_init(&c->dec);
        c->in_cap = buffer_bytes < PCD_MIN_CBUF ? PCD_MIN_CBUF : buffer_bytes;
        c->in = malloc(c->in_cap);
        if (c->in == NULL)
            return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        c->in_pos = r->data_off + 8;
    }
    return GDT_OK;
}

/* ------------------------------------------------------------------------ */
/* source interface                                                          */

static void pcd_free(pcd_reader *r)
{
    if (r == NULL)
        return;
    if (r->f != NULL)
        fclose(r->f);
    for (int a = 0; a < 3; a++)
        free(r->col[a].in);
    free(r->buf);
    free(r->fields);
    free(r->names);
    free(r);
}

static void pcd_close(gdt_source *src)
{
    pcd_free(src->impl);
    src->impl = NULL;
}

/* Trailing checks and the end-of-data warning; run once, after the last point. */
static gdt_status pcd_finish(pcd_reader *r, gdt_error *err)
{
    gdt_status st = GDT_OK;
    if (r->enc == PCD_ASCII)
        st = pcd_ascii_finish(r, err);
    else if (r->enc == PCD_COMPRESSED)
        st = pcd_compressed_finish(r, err);
    /* (binary: its size was checked at open; a range has nothing after it) */
    if (st != GDT_OK)
        return st;
    if (r->skipped > 0 && r->first == 0 && r->end == r->npoints)
        gdt_log_warn(r->log, 3250,
                     "%s: skipped %" PRIu64 " of %" PRIu64 " points whose x, y or z is NaN or "
                     "infinite (invalid points)",
                     r->path, r->skipped, r->npoints);
    else if (r->skipped > 0)
        gdt_log_warn(r->log, 3250,
                     "%s: skipped %" PRIu64 " of the %" PRIu64 " points %" PRIu64 "..%" PRIu64
                     " whose x, y or z is NaN or infinite (invalid points)",
                     r->path, r->skipped, r->end - r->first, r->first, r->end - 1);
    r->finished = 1;
    return GDT_OK;
}

static gdt_status pcd_read(gdt_source *src, gdt_src_point *buf, size_t cap, size_t *n,
                           gdt_error *err)
{
    pcd_reader *r = src->impl;
    gdt_status st = GDT_OK;

    *n = 0;
    if (r->failed != GDT_OK)
        return gdt_error_set(err, r->failed, gdt_error_code_in_class(r->failed, 299),
                             "%s: PCD reading already failed", r->path);
    while (*n < cap && r->next < r->end) {
        double p[3];
        st = r->enc == PCD_ASCII    ? pcd_ascii_point(r, p, err)
             : r->enc == PCD_BINARY ? pcd_binary_point(r, p, err)
                                    : pcd_compressed_point(r, p, err);
        if (st != GDT_OK)
            goto fail;
        r->next++;
        if (!isfinite(p[0]) || !isfinite(p[1]) || !isfinite(p[2])) {
            r->skipped++;
            continue;
        }
        if (!r->warned_precision && src->info.xy_is_float32 &&
            (fabs(p[0]) > PCD_F4_PRECISE_LIMIT || fabs(p[1]) > PCD_F4_PRECISE_LIMIT)) {
            gdt_log_warn(r->log, 3251,
                         "%s: x/y are stored as 32-bit floats and reach %.3f (beyond %.3f "
                         "their rounding error can exceed 1 mm)",
                         r->path, fmax(fabs(p[0]), fabs(p[1])), PCD_F4_PRECISE_LIMIT);
            r->warned_precision = 1;
        }
        buf[*n].x = p[0];
        buf[*n].y = p[1];
        buf[*n].z = p[2];
        buf[*n].X = buf[*n].Y = buf[*n].Z = 0;
        buf[*n].cls = buf[*n].ret = buf[*n].nret = buf[*n].flags = 0;
        (*n)++;
    }
    if (r->next == r->end && !r->finished) {
        st = pcd_finish(r, err);
        if (st != GDT_OK)
            goto fail;
    }
    return GDT_OK;
fail:
    *n = 0;
    r->failed = st;
    return st;
}

/* binary only (gdt_source_can_seek), before the first read: fixed-size
 * records from data_off on, read from rec up to end (the reader stops
 * there, so records with invalid coordinates it skips do not move the
 * range). */
static gdt_status pcd_seek(gdt_source *src, uint64_t rec, uint64_t end, gdt_error *err)
{
    pcd_reader *r = src->impl;
    if (r->enc != PCD_BINARY || r->next != 0 || r->len != 0)
        return gdt_error_set(err, GDT_EINTERNAL, 7102,
                             "%s: PCD data cannot start at point record %" PRIu64 " (%s)",
                             r->path, rec,
                             r->enc != PCD_BINARY ? "only DATA binary can" : "after reading");
    if (end > r->npoints)
        end = r->npoints;
    if (rec > end)
        rec = end;
    if (fseeko(r->f, (off_t)(r->data_off + rec * r->record_size), SEEK_SET) != 0)
        return gdt_error_set(err, GDT_EIO, 4201, "%s: cannot seek: %s", r->path,
                             strerror(errno));
    r->first = r->next = rec;
    r->end = end;
    return GDT_OK;
}

static const gdt_source_vtable pcd_vtable = {pcd_read, pcd_close, pcd_seek, NULL, NULL};

gdt_status gdt_pcd_open(gdt_source *src, gdt_error *err)
{
    pcd_reader *r = NULL;
    gdt_source_info *in = &src->info;
    gdt_status st;
    struct stat sb;
    size_t bufsz = src->opts.buffer_bytes != 0 ? src->opts.buffer_bytes : (size_t)1 << 20;
    off_t here;

    r = calloc(1, sizeof *r);
    if (r == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    r->path = src->path;
    r->log = src->opts.log;
    r->f = fopen(src->path, "rb");
    if (r->f == NULL) {
        st = gdt_error_set(err, errno == ENOENT || errno == EACCES ? GDT_EINPUT : GDT_EIO,
                           errno == ENOENT || errno == EACCES ? 3201 : 4201, "%s: cannot open: %s",
                           src->path, strerror(errno));
        goto fail;
    }
    if (fstat(fileno(r->f), &sb) != 0 || !S_ISREG(sb.st_mode)) {
        st = gdt_error_set(err, GDT_EINPUT, 3201, "%s: not a regular file", src->path);
        goto fail;
    }
    r->file_size = (uint64_t)sb.st_size;
    st = pcd_read_header(r, err);
    if (st != GDT_OK)
        goto fail;
    here = ftello(r->f);
    if (here < 0) {
        st = gdt_error_set(err, GDT_EIO, 4201, "%s: cannot tell the file position: %s", src->path,
                           strerror(errno));
        goto fail;
    }
    r->data_off = (uint64_t)here;
    if (r->enc == PCD_BINARY) {
        uint64_t need = r->npoints * r->record_size;
        uint64_t have = r->file_size - r->data_off;
        if (have < need) {
            st = gdt_error_set(err, GDT_EINPUT, 3220,
                               "%s: PCD binary data holds %" PRIu64 " bytes but POINTS %" PRIu64
                               " x %" PRIu64 " bytes per point = %" PRIu64 " (truncated file or "
                               "POINTS too large)",
                               src->path, have, r->npoints, r->record_size, need);
            goto fail;
        }
        /* PCL's PCLPointCloud2 binary writer pads its files with up to a page
         * of zeros, so bytes beyond the records are legal and ignored. */
        if (have > need)
            gdt_log_note(r->log, "%s: ignoring %" PRIu64 " bytes after the PCD binary data",
                         src->path, have - need);
        /* the buffer holds at least one record */
        if ((uint64_t)bufsz < r->record_size)
            bufsz = (size_t)r->record_size;
    } else if (r->enc == PCD_COMPRESSED) {
        st = pcd_compressed_open(r, bufsz, err);
        if (st != GDT_OK)
            goto fail;
    }
    if (r->enc != PCD_COMPRESSED) {
        r->cap = bufsz;
        r->buf = malloc(r->cap);
        if (r->buf == NULL) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
            goto fail;
        }
    }

    in->format = GDT_FORMAT_PCD;
    snprintf(in->format_name, sizeof in->format_name, "PCD");
    snprintf(in->version, sizeof in->version, "%s", r->version);
    snprintf(in->encoding, sizeof in->encoding, "%s",
             r->enc == PCD_ASCII    ? "ascii"
             : r->enc == PCD_BINARY ? "binary"
                                    : "binary_compressed");
    in->point_count = r->npoints;
    r->end = r->npoints;
    in->has_bounds = 0;
    in->has_lattice = 0;
    in->xy_is_float32 = (r->xyz[0].type == 'F' && r->xyz[0].size == 4) ||
                        (r->xyz[1].type == 'F' && r->xyz[1].size == 4);
    in->z_is_float32 = r->xyz[2].type == 'F' && r->xyz[2].size == 4;
    in->epsg = 0;
    in->crs_wkt = NULL;
    in->crs_geographic = 0;
    in->crs_desc = pcd_crs_desc;
    in->record_length = (unsigned)r->record_size;
    in->file_size = r->file_size;
    src->impl = r;
    src->vt = &pcd_vtable;
    return GDT_OK;
fail:
    pcd_free(r);
    src->impl = NULL;
    src->vt = NULL;
    return st;
}
