/* crs.h — projection of longitude/latitude to UTM/UPS (GeographicLib shim).
 *
 * The implementation is C++ (io/crs.cpp); this header is plain C.  Every
 * exception thrown by GeographicLib or the C++ runtime is caught inside the
 * shim and turned into a gdt_status with a message: nothing propagates
 * through these functions.  Coordinates are on the WGS 84 ellipsoid.
 * Reentrant: no state outside the caller's structs.
 */
#ifndef GDT_CRS_H
#define GDT_CRS_H

#include <stddef.h>

#include "gdt_error.h"

#ifdef __cplusplus
extern "C" {
#endif

/* A fixed UTM zone or polar UPS projection. */
typedef struct gdt_crs_utm {
    int zone;   /* 1..60 for UTM, 0 for UPS */
    int north;  /* 1 northern hemisphere / north pole, 0 southern / south pole */
    int epsg;   /* 326zz / 327zz for UTM, 32661 / 32761 for UPS */
    char name[64]; /* "WGS 84 / UTM zone 10N", "WGS 84 / UPS North (N,E)" */
} gdt_crs_utm;

/* Picks the standard UTM zone of (lon, lat) (UPS north of 84 N and south of
 * 80 S), hemisphere from the sign of lat.
 * returns: GDT_EINPUT 3460 when lon/lat are not finite, lat is outside
 *   [-90, 90] or lon outside [-540, 540); the message has no file name (the
 *   caller prefixes it). */
gdt_status gdt_crs_utm_pick(double lon, double lat, gdt_crs_utm *out, gdt_error *err);

/* Projects n points into the fixed zone z: x[i], y[i] receive easting and
 * northing in metres of (lon[i], lat[i]).  A point south of the equator in a
 * northern zone (or the reverse) is expressed in the zone's hemisphere
 * (northings continue across the equator).  lon/lat and x/y may alias.
 * returns: GDT_EINPUT 3461 when a point is not finite or outside the range
 *   GeographicLib accepts for that zone; *bad is then its index and points
 *   before it are projected.  GDT_EINTERNAL 7461 for an unexpected C++
 *   exception. */
gdt_status gdt_crs_utm_forward(const gdt_crs_utm *z, const double *lon, const double *lat,
                               size_t n, double *x, double *y, size_t *bad, gdt_error *err);

#ifdef __cplusplus
}
#endif
#endif
