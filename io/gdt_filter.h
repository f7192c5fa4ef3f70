/* gdt_filter.h — which input points a run keeps, and what was dropped.
 *
 * A point filter tests the LAS attributes of each source record
 * (gdt_src_point: class, return numbers, flags) before the record reaches
 * the lattice; a dropped record gets no ordinal.  The tests, in this order
 * (a dropped point is counted once, under the first test it fails):
 *   1. withheld: a point with GDT_PT_WITHHELD is dropped unless
 *      keep_withheld (the LAS specification says to treat it as deleted);
 *   2. class: with a class set, a point whose class is not in it is dropped;
 *   3. returns: first keeps return number 1, last keeps return number ==
 *      number of returns, single keeps number of returns == 1.
 * Formats without attributes (PCD) have all of them zero: only the default
 * withheld test applies to them, and it keeps every point.
 *
 * Message numbers: 2301 (malformed class list), 2302 (class out of
 * 0..255), 2303 (--keep-class with --drop-class), 2304 (unknown --returns
 * value); the command line adds 2306 (filter options with --resume).
 */
#ifndef GDT_FILTER_H
#define GDT_FILTER_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_error.h"
#include "gdt_source.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef enum gdt_returns {
    GDT_RETURNS_ALL = 0,
    GDT_RETURNS_FIRST,  /* return number 1 */
    GDT_RETURNS_LAST,   /* return number == number of returns */
    GDT_RETURNS_SINGLE  /* number of returns 1 */
} gdt_returns;

/* A zeroed filter is the default: every class, all returns, withheld
 * points dropped. */
typedef struct gdt_point_filter {
    int class_mode;           /* 0: every class; 1: keep the set; -1: drop the set */
    uint8_t classes[256];     /* classes[c] != 0: c is in the set */
    gdt_returns returns;
    int keep_withheld;        /* 1: withheld points are kept */
} gdt_point_filter;

/* Why a point was dropped (gdt_filter_test); GDT_KEEP when it is kept. */
typedef enum gdt_drop_reason {
    GDT_KEEP = 0,
    GDT_DROP_WITHHELD,
    GDT_DROP_CLASS,
    GDT_DROP_RETURN
} gdt_drop_reason;

/* Records read and what happened to them. read = kept + the drops. */
typedef struct gdt_filter_counts {
    uint64_t read, kept;
    uint64_t drop_withheld, drop_class, drop_return;
} gdt_filter_counts;

/* What the attributes of the records read look like (--info), before any
 * filtering.  ret and nret are indexed by the field's value (0..15). */
typedef struct gdt_las_census {
    uint64_t records;
    uint64_t cls[256];
    uint64_t ret[16], nret[16];
    uint64_t synthetic, keypoint, withheld, overlap;
} gdt_las_census;

/* Adds the classes of s to f's set and sets f->class_mode to mode (1 keep,
 * -1 drop).  s is a comma list of codes 0..255 and ranges A-B (A <= B),
 * e.g. "2", "2,9", "3-5,17".  opt names the option in messages.
 * returns: GDT_EUSAGE 2301 (malformed), 2302 (out of range), 2303 (the
 *   other mode is already set). */
gdt_status gdt_filter_parse_classes(gdt_point_filter *f, int mode, const char *opt,
                                    const char *s, gdt_error *err);
/* "all", "first", "last", "single".  returns: GDT_EUSAGE 2304. */
gdt_status gdt_filter_parse_returns(gdt_point_filter *f, const char *s, gdt_error *err);
/* "all", "first", "last", "single". */
const char *gdt_returns_name(gdt_returns r);

/* 1 when f tests class or returns (inputs without attributes cannot be
 * filtered so). */
int gdt_filter_uses_attributes(const gdt_point_filter *f);
/* 1 when f's class set holds a class above 31 (formats 0-5 store 0..31). */
int gdt_filter_names_high_class(const gdt_point_filter *f);
/* The GDT_SRC_NEED_* fields f looks at, GDT_SRC_NEED_XYZ included. */
unsigned gdt_filter_need(const gdt_point_filter *f);

static inline gdt_drop_reason gdt_filter_test(const gdt_point_filter *f,
                                              const gdt_src_point *p)
{
    if (!f->keep_withheld && (p->flags & GDT_PT_WITHHELD) != 0)
        return GDT_DROP_WITHHELD;
    if (f->class_mode != 0 && (f->classes[p->cls] != 0) != (f->class_mode > 0))
        return GDT_DROP_CLASS;
    switch (f->returns) {
    case GDT_RETURNS_ALL: break;
    case GDT_RETURNS_FIRST: if (p->ret != 1) return GDT_DROP_RETURN; break;
    case GDT_RETURNS_LAST: if (p->ret != p->nret) return GDT_DROP_RETURN; break;
    case GDT_RETURNS_SINGLE: if (p->nret != 1) return GDT_DROP_RETURN; break;
    }
    return GDT_KEEP;
}

/* The class set as a canonical list ("2,3-5,17": ascending, runs of three
 * or more as ranges, runs of two as two codes) into buf; "" for an empty
 * set.  Truncated to cap - 1 bytes (1024 always suffice). */
void gdt_filter_class_list(const gdt_point_filter *f, char *buf, size_t cap);

/* One-line canonical description, the same for every spelling of the same
 * filter: "keep-class 2 returns all withheld drop" (class part "all
 * classes" or "drop-class L").  Used in job params and PLY comments. */
void gdt_filter_describe(const gdt_point_filter *f, char *buf, size_t cap);

/* Parses what gdt_filter_describe wrote.  returns: 0, or -1 when s is not
 * such a description. */
int gdt_filter_from_description(gdt_point_filter *f, const char *s);

/* 1 when f is the default filter (a zeroed one). */
int gdt_filter_is_default(const gdt_point_filter *f);

/* For run summaries: "" when nothing was dropped and f tests neither class
 * nor returns, else " (R read; dropped: C by class, T by return, W
 * withheld)" (with the leading space). */
void gdt_filter_counts_text(const gdt_point_filter *f, const gdt_filter_counts *c, char *buf,
                            size_t cap);

/* Adds b to a. */
void gdt_filter_counts_add(gdt_filter_counts *a, const gdt_filter_counts *b);
/* Adds the record p to c. */
void gdt_las_census_add(gdt_las_census *c, const gdt_src_point *p);

/* ASPRS name of class code c: "ground", "user definable", ... (static). */
const char *gdt_asprs_class_name(unsigned c);

#ifdef __cplusplus
}
#endif
#endif
