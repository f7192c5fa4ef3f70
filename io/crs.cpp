// crs.cpp — UTM/UPS projection through GeographicLib behind a C interface.
//
// Boundary rule: every function body is wrapped in try/catch; no exception
// leaves this file.  GeographicLib throws GeographicErr for out-of-range
// input, which is the caller's bad data (GDT_EINPUT); anything else is
// unexpected (GDT_EINTERNAL).
#include "private/crs.h"

#include <GeographicLib/Constants.hpp>
#include <GeographicLib/UTMUPS.hpp>

#include <cmath>
#include <cstdio>
#include <exception>

using GeographicLib::GeographicErr;
using GeographicLib::UTMUPS;

extern "C" gdt_status gdt_crs_utm_pick(double lon, double lat, gdt_crs_utm *out,
                                       gdt_error *err)
{
    try {
        if (!std::isfinite(lon) || !std::isfinite(lat) || std::fabs(lat) > 90.0 ||
            lon < -540.0 || lon >= 540.0)
            return gdt_error_set(err, GDT_EINPUT, 3460,
                                 "centre (lon %.9g, lat %.9g) is not a valid longitude/latitude",
                                 lon, lat);
        int zone = UTMUPS::StandardZone(lat, lon);
        bool north = lat >= 0.0;
        out->zone = zone;
        out->north = north ? 1 : 0;
        out->epsg = UTMUPS::EncodeEPSG(zone, north);
        if (zone == UTMUPS::UPS)
            std::snprintf(out->name, sizeof out->name, "WGS 84 / UPS %s (N,E)",
                          north ? "North" : "South");
        else
            std::snprintf(out->name, sizeof out->name, "WGS 84 / UTM zone %d%c", zone,
                          north ? 'N' : 'S');
        return GDT_OK;
    } catch (const GeographicErr &e) {
        return gdt_error_set(err, GDT_EINPUT, 3460, "cannot choose a UTM/UPS zone: %s",
                             e.what());
    } catch (const std::exception &e) {
        return gdt_error_set(err, GDT_EINTERNAL, 7461, "projection failed: %s", e.what());
    } catch (...) {
        return gdt_error_set(err, GDT_EINTERNAL, 7461, "projection failed: unknown exception");
    }
}

extern "C" gdt_status gdt_crs_utm_forward(const gdt_crs_utm *z, const double *lon,
                                          const double *lat, size_t n, double *x, double *y,
                                          size_t *bad, gdt_error *err)
{
    size_t i = 0;
    *bad = 0;
    try {
        const bool want_north = z->north != 0;
        for (i = 0; i < n; i++) {
            const double la = lat[i], lo = lon[i];
            if (!std::isfinite(la) || !std::isfinite(lo) || std::fabs(la) > 90.0 ||
                lo < -540.0 || lo >= 540.0) {
                *bad = i;
                return gdt_error_set(err, GDT_EINPUT, 3461,
                                     "(lon %.9g, lat %.9g) is not a valid longitude/latitude",
                                     lo, la);
            }
            int zone = 0;
            bool north = false;
            double e = 0.0, nn = 0.0;
            UTMUPS::Forward(la, lo, zone, north, e, nn, z->zone);
            if (north != want_north)
                UTMUPS::Transfer(zone, north, e, nn, z->zone, want_north, e, nn, zone);
            x[i] = e;
            y[i] = nn;
        }
        return GDT_OK;
    } catch (const GeographicErr &e) {
        *bad = i;
        return gdt_error_set(err, GDT_EINPUT, 3461,
                             "(lon %.9g, lat %.9g) cannot be projected to EPSG:%d: %s", lon[i],
                             lat[i], z->epsg, e.what());
    } catch (const std::exception &e) {
        *bad = i;
        return gdt_error_set(err, GDT_EINTERNAL, 7461, "projection failed: %s", e.what());
    } catch (...) {
        *bad = i;
        return gdt_error_set(err, GDT_EINTERNAL, 7461, "projection failed: unknown exception");
    }
}
