/* CRS of a LAS file from GeoTIFF keys and OGC WKT.  See las_crs.h.
 *
 * design: the WKT is never turned into a tree.  A node is a keyword plus the
 * text between its matching brackets; its items are split at the commas of
 * bracket depth 0.  Bracket matching is an iterative scan, and the only
 * recursion (into compound and bound CRSs) is limited to WKT_MAX_NESTING,
 * so hostile input can neither overflow the stack nor make us allocate.
 */
#include "las_crs.h"

#include "bytes.h"

#include <stdint.h>
#include <stdio.h>
#include <string.h>

#define WKT_MAX_NESTING 8

typedef struct wkt_span {
    const char *s;
    size_t n;
} wkt_span;

typedef enum wkt_item_type { WKT_ITEM_NODE, WKT_ITEM_STRING, WKT_ITEM_TOKEN } wkt_item_type;

/* One item of a node body.  For WKT_ITEM_NODE, kw is the keyword and body the
 * text inside the brackets; for strings, body is the text inside the quotes
 * (doubled quotes are left as they are); for tokens, body is the bare token. */
typedef struct wkt_item {
    wkt_item_type type;
    wkt_span kw;
    wkt_span body;
} wkt_item;

static int wkt_is_space(char c)
{
    return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\f' || c == '\v';
}

static int wkt_is_ident(char c)
{
    return (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_';
}

static size_t wkt_skip_space(const char *s, size_t end, size_t i)
{
    while (i < end && wkt_is_space(s[i]))
        i++;
    return i;
}

/* Case-insensitive comparison of a span with a NUL-terminated ASCII word. */
static int wkt_span_is(wkt_span sp, const char *word)
{
    size_t len = strlen(word);
    if (sp.n != len)
        return 0;
    for (size_t k = 0; k < len; k++) {
        char a = sp.s[k], b = word[k];
        if (a >= 'a' && a <= 'z')
            a = (char)(a - 'a' + 'A');
        if (b >= 'a' && b <= 'z')
            b = (char)(b - 'a' + 'A');
        if (a != b)
            return 0;
    }
    return 1;
}

/* Position just past the closing quote of the string whose opening quote is
 * at s[i]; a doubled quote inside is an escaped quote.  Returns 0 when the
 * string is not closed before end. */
static size_t wkt_skip_string(const char *s, size_t end, size_t i)
{
    i++;
    while (i < end) {
        if (s[i] == '"') {
            if (i + 1 < end && s[i + 1] == '"') {
                i += 2;
                continue;
            }
            return i + 1;
        }
        i++;
    }
    return 0;
}

/* s[open] is '[' or '('.  Sets *close to the index of the matching bracket;
 * returns -1 when the brackets are unbalanced before end. */
static int wkt_match(const char *s, size_t end, size_t open, size_t *close)
{
    size_t depth = 0;
    size_t i = open;
    while (i < end) {
        char c = s[i];
        if (c == '"') {
            size_t next = wkt_skip_string(s, end, i);
            if (next == 0)
                return -1;
            i = next;
            continue;
        }
        if (c == '[' || c == '(') {
            depth++;
        } else if (c == ']' || c == ')') {
            if (depth == 0)
                return -1;
            depth--;
            if (depth == 0) {
                *close = i;
                return 0;
            }
        }
        i++;
    }
    return -1;
}

/* Reads the item starting at or after s[*i] (before end) and advances *i past
 * it and past the following comma.  Returns 1 for an item, 0 at the end of
 * the body, -1 on malformed text. */
static int wkt_next_item(const char *s, size_t end, size_t *i, wkt_item *it)
{
    size_t p = wkt_skip_space(s, end, *i);
    if (p >= end)
        return 0;
    memset(it, 0, sizeof *it);
    if (s[p] == '"') {
        size_t next = wkt_skip_string(s, end, p);
        if (next == 0)
            return -1;
        it->type = WKT_ITEM_STRING;
        it->body.s = s + p + 1;
        it->body.n = next - p - 2;
        p = next;
    } else {
        size_t start = p;
        while (p < end && wkt_is_ident(s[p]))
            p++;
        size_t q = wkt_skip_space(s, end, p);
        if (p > start && q < end && (s[q] == '[' || s[q] == '(')) {
            size_t close;
            if (wkt_match(s, end, q, &close) != 0)
                return -1;
            it->type = WKT_ITEM_NODE;
            it->kw.s = s + start;
            it->kw.n = p - start;
            it->body.s = s + q + 1;
            it->body.n = close - q - 1;
            p = close + 1;
        } else {
            /* A number or an enumeration value: runs to the next comma. */
            while (p < end && s[p] != ',' && s[p] != '[' && s[p] != '(' && s[p] != ']' &&
                   s[p] != ')' && s[p] != '"')
                p++;
            it->type = WKT_ITEM_TOKEN;
            it->body.s = s + start;
            it->body.n = p - start;
            while (it->body.n > 0 && wkt_is_space(it->body.s[it->body.n - 1]))
                it->body.n--;
        }
    }
    p = wkt_skip_space(s, end, p);
    if (p < end) {
        if (s[p] != ',')
            return -1;
        p++;
    }
    *i = p;
    return 1;
}

/* Parses a positive decimal code from a string or token item; 0 if it is
 * not one or does not fit an int. */
static int wkt_code(wkt_span sp)
{
    long v = 0;
    size_t k = 0;
    while (k < sp.n && wkt_is_space(sp.s[k]))
        k++;
    if (k == sp.n)
        return 0;
    for (; k < sp.n; k++) {
        char c = sp.s[k];
        if (c < '0' || c > '9')
            return wkt_is_space(c) ? (int)v : 0;
        v = v * 10 + (c - '0');
        if (v > INT32_MAX)
            return 0;
    }
    return (int)v;
}

/* EPSG code given by an AUTHORITY["EPSG","n"] or ID["EPSG",n] item directly
 * inside body; 0 if none. */
static int wkt_node_epsg(wkt_span body)
{
    size_t i = 0;
    wkt_item it;
    int code = 0;
    while (wkt_next_item(body.s, body.n, &i, &it) == 1) {
        if (it.type != WKT_ITEM_NODE ||
            !(wkt_span_is(it.kw, "AUTHORITY") || wkt_span_is(it.kw, "ID")))
            continue;
        size_t j = 0;
        wkt_item auth, val;
        if (wkt_next_item(it.body.s, it.body.n, &j, &auth) != 1 || auth.type != WKT_ITEM_STRING ||
            !wkt_span_is(auth.body, "EPSG"))
            continue;
        if (wkt_next_item(it.body.s, it.body.n, &j, &val) != 1 || val.type == WKT_ITEM_NODE)
            continue;
        code = wkt_code(val.body);
    }
    return code;
}

/* First direct child node of body with keyword kw; returns 0 if found. */
static int wkt_find_child(wkt_span body, const char *kw, wkt_item *out)
{
    size_t i = 0;
    while (wkt_next_item(body.s, body.n, &i, out) == 1) {
        if (out->type == WKT_ITEM_NODE && wkt_span_is(out->kw, kw))
            return 0;
    }
    return -1;
}

/* Kind and EPSG code of the horizontal CRS described by node it. */
static void wkt_describe(const wkt_item *it, int nesting, gdt_las_wkt_kind *kind, int *epsg)
{
    static const char *const geographic[] = {"GEOGCS", "GEOGCRS", "GEOGRAPHICCRS"};
    static const char *const projected[] = {"PROJCS", "PROJCRS", "PROJECTEDCRS"};
    wkt_item child;

    *kind = GDT_LAS_WKT_UNKNOWN;
    *epsg = 0;
    if (nesting > WKT_MAX_NESTING)
        return;
    for (size_t k = 0; k < sizeof geographic / sizeof geographic[0]; k++) {
        if (wkt_span_is(it->kw, geographic[k])) {
            *kind = GDT_LAS_WKT_GEOGRAPHIC;
            *epsg = wkt_node_epsg(it->body);
            return;
        }
    }
    for (size_t k = 0; k < sizeof projected / sizeof projected[0]; k++) {
        if (wkt_span_is(it->kw, projected[k])) {
            *kind = GDT_LAS_WKT_PROJECTED;
            *epsg = wkt_node_epsg(it->body);
            return;
        }
    }
    if (wkt_span_is(it->kw, "GEOCCS")) {
        *kind = GDT_LAS_WKT_GEOCENTRIC;
        *epsg = wkt_node_epsg(it->body);
        return;
    }
    if (wkt_span_is(it->kw, "GEODCRS") || wkt_span_is(it->kw, "GEODETICCRS")) {
        /* WKT2: geographic or geocentric depending on the coordinate system. */
        if (wkt_find_child(it->body, "CS", &child) == 0) {
            size_t j = 0;
            wkt_item cs_type;
            if (wkt_next_item(child.body.s, child.body.n, &j, &cs_type) == 1 &&
                cs_type.type == WKT_ITEM_TOKEN) {
                if (wkt_span_is(cs_type.body, "ellipsoidal"))
                    *kind = GDT_LAS_WKT_GEOGRAPHIC;
                else if (wkt_span_is(cs_type.body, "Cartesian"))
                    *kind = GDT_LAS_WKT_GEOCENTRIC;
            }
        }
        *epsg = *kind == GDT_LAS_WKT_UNKNOWN ? 0 : wkt_node_epsg(it->body);
        return;
    }
    if (wkt_span_is(it->kw, "COMPD_CS") || wkt_span_is(it->kw, "COMPOUNDCRS")) {
        /* The horizontal component is the first child CRS we recognise. */
        size_t i = 0;
        while (wkt_next_item(it->body.s, it->body.n, &i, &child) == 1) {
            if (child.type != WKT_ITEM_NODE)
                continue;
            wkt_describe(&child, nesting + 1, kind, epsg);
            if (*kind != GDT_LAS_WKT_UNKNOWN)
                return;
        }
        return;
    }
    if (wkt_span_is(it->kw, "BOUNDCRS")) {
        wkt_item inner;
        size_t j = 0;
        if (wkt_find_child(it->body, "SOURCECRS", &child) == 0 &&
            wkt_next_item(child.body.s, child.body.n, &j, &inner) == 1 &&
            inner.type == WKT_ITEM_NODE)
            wkt_describe(&inner, nesting + 1, kind, epsg);
        return;
    }
}

/* Copies a name from the file into dst, replacing control bytes, truncating. */
static void copy_name(char *dst, size_t cap, const char *src, size_t n)
{
    size_t k = 0;
    for (; k < n && k + 1 < cap; k++) {
        unsigned char c = (unsigned char)src[k];
        dst[k] = (c < 0x20 || c == 0x7f) ? '?' : (char)c;
    }
    dst[k] = '\0';
}

int gdt_las_wkt_inspect(const char *wkt, size_t len, gdt_las_wkt_facts *out)
{
    wkt_item top, first;
    size_t i = 0;

    memset(out, 0, sizeof *out);
    /* The payload is often NUL-padded: the text ends at the first NUL. */
    const char *nul = memchr(wkt, '\0', len);
    if (nul != NULL)
        len = (size_t)(nul - wkt);
    if (wkt_next_item(wkt, len, &i, &top) != 1 || top.type != WKT_ITEM_NODE)
        return -1;
    wkt_describe(&top, 0, &out->kind, &out->epsg);
    i = 0;
    if (wkt_next_item(top.body.s, top.body.n, &i, &first) == 1 && first.type == WKT_ITEM_STRING)
        copy_name(out->name, sizeof out->name, first.body.s, first.body.n);
    return 0;
}

static unsigned geokey_word(const unsigned char *p, size_t k)
{
    return gdt_le_get_u16(p + 2 * k);
}

void gdt_las_geokeys_parse(const unsigned char *dir, size_t dir_len, const char *ascii,
                           size_t ascii_len, gdt_las_geokeys *out)
{
    /* Citations in order of preference: PCSCitation, GTCitation, GeogCitation. */
    static const unsigned citation_keys[3] = {3073, 1026, 2049};
    int citation_rank = 3;
    size_t words = dir_len / 2;

    memset(out, 0, sizeof *out);
    if (words < 4)
        return;
    out->present = 1;
    size_t nkeys = geokey_word(dir, 3);
    if (nkeys > (words - 4) / 4) {
        out->malformed = 1;
        nkeys = (words - 4) / 4;
    }
    for (size_t k = 0; k < nkeys; k++) {
        size_t w = 4 + 4 * k;
        unsigned id = geokey_word(dir, w), loc = geokey_word(dir, w + 1);
        unsigned count = geokey_word(dir, w + 2), value = geokey_word(dir, w + 3);
        if (loc == 0) {
            if (id == 1024)
                out->model = (int)value;
            else if (id == 2048)
                out->geographic_code = (int)value;
            else if (id == 3072)
                out->projected_code = (int)value;
            continue;
        }
        if (loc != 34737)
            continue;
        for (int r = 0; r < citation_rank; r++) {
            if (id != citation_keys[r])
                continue;
            if (ascii == NULL || (size_t)value > ascii_len ||
                (size_t)count > ascii_len - (size_t)value) {
                out->malformed = 1;
                break;
            }
            /* GeoTIFF ASCII values end with '|' (and may be NUL-padded). */
            size_t n = count;
            const char *s = ascii + value;
            while (n > 0 && (s[n - 1] == '|' || s[n - 1] == '\0'))
                n--;
            const char *nul = memchr(s, '\0', n);
            if (nul != NULL)
                n = (size_t)(nul - s);
            if (n > 0) {
                copy_name(out->citation, sizeof out->citation, s, n);
                citation_rank = r;
            }
            break;
        }
    }
}

static int valid_code(int code)
{
    return code > 0 && code < GDT_LAS_GEOKEY_USER_DEFINED;
}

void gdt_las_crs_resolve(const gdt_las_geokeys *keys, const char *wkt, size_t wkt_len,
                         int wkt_authoritative, gdt_las_crs *out)
{
    gdt_las_wkt_facts facts;
    int have_wkt = wkt != NULL && gdt_las_wkt_inspect(wkt, wkt_len, &facts) == 0;
    int have_keys = keys != NULL && keys->present;
    int key_code = 0, key_geographic = 0;

    memset(out, 0, sizeof *out);
    if (have_keys) {
        if (keys->model == 2) {
            key_geographic = 1;
            key_code = valid_code(keys->geographic_code) ? keys->geographic_code : 0;
        } else if (valid_code(keys->projected_code)) {
            key_code = keys->projected_code;
        } else if (keys->model == 0 && keys->projected_code == 0 &&
                   valid_code(keys->geographic_code)) {
            /* No model type, only a geographic CRS: lon/lat. */
            key_geographic = 1;
            key_code = keys->geographic_code;
        }
    }
    if (have_wkt && (wkt_authoritative || !have_keys || key_code == 0)) {
        out->epsg = facts.epsg;
        out->geographic = facts.kind == GDT_LAS_WKT_GEOGRAPHIC;
        if (facts.epsg != 0)
            snprintf(out->desc, sizeof out->desc, "EPSG:%d", facts.epsg);
        else if (facts.name[0] != '\0')
            snprintf(out->desc, sizeof out->desc, "WKT: %s", facts.name);
        else
            snprintf(out->desc, sizeof out->desc, "WKT (unnamed)");
        return;
    }
    if (have_keys) {
        out->epsg = key_code;
        out->geographic = key_geographic;
        if (key_code != 0)
            snprintf(out->desc, sizeof out->desc, "EPSG:%d", key_code);
        else if (keys->citation[0] != '\0')
            snprintf(out->desc, sizeof out->desc, "GeoTIFF: %s", keys->citation);
        else
            snprintf(out->desc, sizeof out->desc, "GeoTIFF keys (user-defined)");
        return;
    }
    snprintf(out->desc, sizeof out->desc,
             wkt != NULL && wkt_len > 0 ? "WKT (unrecognised)" : "unknown");
}
