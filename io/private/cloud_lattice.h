/* cloud_lattice.h — the pure lattice and CRS decisions behind gdt_cloud.
 *
 * No I/O and no allocation here: these take numbers and header records and
 * say how points map onto the cloud lattice, so they can be tested on
 * their own.  Implemented in io/cloud.c.
 */
#ifndef GDT_CLOUD_LATTICE_H
#define GDT_CLOUD_LATTICE_H

#include <stdint.h>

#include "gdt_cloud.h"
#include "gdt_source.h"

typedef enum gdt_snap_result {
    GDT_SNAP_OK = 0,
    GDT_SNAP_NONFINITE,   /* v is NaN or infinite */
    GDT_SNAP_RANGE        /* |round((v - origin) / step)| >= 2^53 (or not finite) */
} gdt_snap_result;

/* *out = round_half_even((v - origin) / step), computed in double under the
 * default rounding mode.  Preconditions: origin finite, step finite and > 0.
 * *out is written only on GDT_SNAP_OK. */
gdt_snap_result gdt_cloud_snap(double v, double origin, double step, int64_t *out);

/* Decides whether the lattice (s_from, o_from) of one axis maps exactly
 * onto (s_to, o_to): returns 1 and sets *m >= 1, *k such that
 * o_from + s_from * X == o_to + s_to * (m * X + k) for every integer X, up
 * to the rounding noise of the decimal values written in the headers:
 *   m = s_from / s_to rounded, with |s_from - m s_to| <= 4 eps s_from;
 *   k = (o_from - o_to) / s_to rounded, with the residual
 *       |o_from - o_to - k s_to| <= max(1e-9 s_to, noise),
 *       noise = 4 eps (|o_from| + |o_to|) required to be <= 1e-4 s_to.
 * Also requires 1 <= m <= 2^21 and |k| < 2^52, so m * X + k never overflows
 * for an int32 X.  Returns 0 (outputs untouched) otherwise, or when any
 * argument is not finite or a step is <= 0. */
int gdt_cloud_lattice_relation(double s_from, double o_from, double s_to, double o_to,
                               int64_t *m, int64_t *k);

/* How the CRSs of two inputs relate. */
typedef enum gdt_crs_relation {
    GDT_CRS_SAME = 0,      /* same EPSG, or same WKT up to white space */
    GDT_CRS_UNKNOWN,       /* at least one input carries no CRS: compatible */
    GDT_CRS_DIFFERENT,     /* different EPSG codes or different WKT */
    GDT_CRS_KIND,          /* one geographic, the other projected */
    GDT_CRS_UNDECIDABLE    /* one gives only an EPSG code, the other only a
                              WKT without one */
} gdt_crs_relation;

/* 1 when the header names a CRS: an EPSG code, a WKT or the geographic
 * flag (a GeoTIFF citation alone is not enough to compare two files).  PCD
 * never carries one. */
int gdt_cloud_crs_known(const gdt_source_info *in);
gdt_crs_relation gdt_cloud_crs_compare(const gdt_source_info *a, const gdt_source_info *b);

/* 1 when a geographic CRS is WGS 84 or a realisation treated as identical
 * (EPSG 4326, 4979, or a WKT whose datum names WGS 84). */
int gdt_cloud_crs_is_wgs84(const gdt_source_info *in);

#endif
