/* Point filters: parsing, canonical descriptions, counts (gdt_filter.h). */
#include "gdt_filter.h"

#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Parses a decimal code 0..255 at *p (digits only); advances *p.
 * returns 0, -1 (no digits), -2 (above 255). */
static int parse_code(const char **p, unsigned *out)
{
    const char *s = *p;
    unsigned v = 0;
    if (*s < '0' || *s > '9')
        return -1;
    while (*s >= '0' && *s <= '9') {
        if (v <= 255)
            v = v * 10 + (unsigned)(*s - '0');
        s++;
    }
    *p = s;
    if (v > 255)
        return -2;
    *out = v;
    return 0;
}

gdt_status gdt_filter_parse_classes(gdt_point_filter *f, int mode, const char *opt,
                                    const char *s, gdt_error *err)
{
    uint8_t set[256];
    const char *p = s;

    if (f->class_mode != 0 && f->class_mode != mode)
        return gdt_error_set(err, GDT_EUSAGE, 2303,
                             "--keep-class and --drop-class cannot be combined: give the "
                             "classes to keep (--keep-class) or those to drop (--drop-class)");
    memcpy(set, f->classes, sizeof set);
    for (;;) {
        unsigned a, b;
        int r = parse_code(&p, &a);
        if (r == 0) {
            b = a;
            if (*p == '-') {
                p++;
                r = parse_code(&p, &b);
            }
        }
        if (r == -2)
            return gdt_error_set(err, GDT_EUSAGE, 2302,
                                 "%s '%s': class codes are 0..255 (ASPRS classification)", opt,
                                 s);
        if (r != 0 || a > b || (*p != ',' && *p != '\0'))
            return gdt_error_set(err, GDT_EUSAGE, 2301,
                                 "%s '%s': not a list of class codes (examples: 2; 2,9; 3-5,17)",
                                 opt, s);
        for (unsigned c = a; c <= b; c++)
            set[c] = 1;
        if (*p == '\0')
            break;
        p++;
    }
    memcpy(f->classes, set, sizeof set);
    f->class_mode = mode;
    return GDT_OK;
}

static const char *const RETURNS[] = {"all", "first", "last", "single"};

gdt_status gdt_filter_parse_returns(gdt_point_filter *f, const char *s, gdt_error *err)
{
    for (int i = 0; i < 4; i++)
        if (strcmp(s, RETURNS[i]) == 0) {
            f->returns = (gdt_returns)i;
            return GDT_OK;
        }
    return gdt_error_set(err, GDT_EUSAGE, 2304,
                         "--returns: '%s' is not one of all, first, last, single", s);
}

const char *gdt_returns_name(gdt_returns r)
{
    return (unsigned)r < 4 ? RETURNS[r] : "?";
}

int gdt_filter_uses_attributes(const gdt_point_filter *f)
{
    return f->class_mode != 0 || f->returns != GDT_RETURNS_ALL;
}

int gdt_filter_names_high_class(const gdt_point_filter *f)
{
    if (f->class_mode == 0)
        return 0;
    for (unsigned c = 32; c < 256; c++)
        if (f->classes[c])
            return 1;
    return 0;
}

unsigned gdt_filter_need(const gdt_point_filter *f)
{
    unsigned need = GDT_SRC_NEED_XYZ;
    if (f->class_mode != 0)
        need |= GDT_SRC_NEED_CLASS;
    if (!f->keep_withheld || f->returns != GDT_RETURNS_ALL)
        need |= GDT_SRC_NEED_FLAGS;
    return need;
}

void gdt_filter_class_list(const gdt_point_filter *f, char *buf, size_t cap)
{
    size_t len = 0;
    if (cap == 0)
        return;
    buf[0] = '\0';
    for (unsigned c = 0; c < 256; c++) {
        unsigned e = c;
        int n;
        if (!f->classes[c])
            continue;
        while (e + 1 < 256 && f->classes[e + 1])
            e++;
        if (e >= c + 2)
            n = snprintf(buf + len, cap - len, "%s%u-%u", len ? "," : "", c, e);
        else if (e == c + 1)
            n = snprintf(buf + len, cap - len, "%s%u,%u", len ? "," : "", c, e);
        else
            n = snprintf(buf + len, cap - len, "%s%u", len ? "," : "", c);
        if (n < 0 || (size_t)n >= cap - len)
            return;
        len += (size_t)n;
        c = e;
    }
}

void gdt_filter_describe(const gdt_point_filter *f, char *buf, size_t cap)
{
    char list[1024];
    gdt_filter_class_list(f, list, sizeof list);
    if (f->class_mode == 0)
        snprintf(buf, cap, "classes all returns %s withheld %s", gdt_returns_name(f->returns),
                 f->keep_withheld ? "keep" : "drop");
    else
        snprintf(buf, cap, "%s %s returns %s withheld %s",
                 f->class_mode > 0 ? "keep-class" : "drop-class", list[0] ? list : "none",
                 gdt_returns_name(f->returns), f->keep_withheld ? "keep" : "drop");
}

int gdt_filter_from_description(gdt_point_filter *f, const char *s)
{
    char cls[16], list[1024], ret[16], wh[16];
    char again[1200];
    gdt_point_filter g;
    gdt_error e;

    memset(&g, 0, sizeof g);
    gdt_error_clear(&e);
    if (strlen(s) >= sizeof again ||
        sscanf(s, "%15s %1023s returns %15s withheld %15s", cls, list, ret, wh) != 4)
        return -1;
    if (strcmp(cls, "classes") == 0) {
        if (strcmp(list, "all") != 0)
            return -1;
    } else if (strcmp(cls, "keep-class") == 0 || strcmp(cls, "drop-class") == 0) {
        int mode = cls[0] == 'k' ? 1 : -1;
        if (strcmp(list, "none") == 0)
            g.class_mode = mode;
        else if (gdt_filter_parse_classes(&g, mode, cls, list, &e) != GDT_OK)
            return -1;
    } else {
        return -1;
    }
    if (gdt_filter_parse_returns(&g, ret, &e) != GDT_OK)
        return -1;
    if (strcmp(wh, "keep") == 0)
        g.keep_withheld = 1;
    else if (strcmp(wh, "drop") != 0)
        return -1;
    /* only the canonical spelling is a description */
    gdt_filter_describe(&g, again, sizeof again);
    if (strcmp(again, s) != 0)
        return -1;
    *f = g;
    return 0;
}

int gdt_filter_is_default(const gdt_point_filter *f)
{
    static const gdt_point_filter zero;
    return memcmp(f, &zero, sizeof zero) == 0;
}

void gdt_filter_counts_text(const gdt_point_filter *f, const gdt_filter_counts *c, char *buf,
                            size_t cap)
{
    if (c->read == c->kept && !gdt_filter_uses_attributes(f))
        snprintf(buf, cap, "%s", "");
    else
        snprintf(buf, cap,
                 " (%" PRIu64 " read; dropped: %" PRIu64 " by class, %" PRIu64
                 " by return, %" PRIu64 " withheld)",
                 c->read, c->drop_class, c->drop_return, c->drop_withheld);
}

void gdt_filter_counts_add(gdt_filter_counts *a, const gdt_filter_counts *b)
{
    a->read += b->read;
    a->kept += b->kept;
    a->drop_withheld += b->drop_withheld;
    a->drop_class += b->drop_class;
    a->drop_return += b->drop_return;
}

void gdt_las_census_add(gdt_las_census *c, const gdt_src_point *p)
{
    c->records++;
    c->cls[p->cls]++;
    c->ret[p->ret & 15u]++;
    c->nret[p->nret & 15u]++;
    c->synthetic += (p->flags & GDT_PT_SYNTHETIC) != 0;
    c->keypoint += (p->flags & GDT_PT_KEYPOINT) != 0;
    c->withheld += (p->flags & GDT_PT_WITHHELD) != 0;
    c->overlap += (p->flags & GDT_PT_OVERLAP) != 0;
}

const char *gdt_asprs_class_name(unsigned c)
{
    static const char *const names[] = {
        "never classified", "unassigned", "ground", "low vegetation", "medium vegetation",
        "high vegetation", "building", "low point (noise)",
        "reserved / model key point (1.0-1.3)", "water", "rail", "road surface",
        "reserved / overlap (1.0-1.3)", "wire guard", "wire conductor", "transmission tower",
        "wire connector", "bridge deck", "high noise", "overhead structure", "ignored ground",
        "snow", "temporal exclusion"};
    if (c < sizeof names / sizeof names[0])
        return names[c];
    return c >= 64 && c <= 255 ? "user definable" : "reserved";
}
