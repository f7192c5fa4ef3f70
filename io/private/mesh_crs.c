/* CRS facts for the TIN writers (mesh_crs.h). */
#include "mesh_crs.h"

#include <ctype.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char GEOG_WGS84[] =
    "GEOGCS[\"WGS 84\",DATUM[\"WGS_1984\",SPHEROID[\"WGS 84\",6378137,298.257223563,"
    "AUTHORITY[\"EPSG\",\"7030\"]],AUTHORITY[\"EPSG\",\"6326\"]],"
    "PRIMEM[\"Greenwich\",0,AUTHORITY[\"EPSG\",\"8901\"]],"
    "UNIT[\"degree\",0.0174532925199433,AUTHORITY[\"EPSG\",\"9122\"]],"
    "AUTHORITY[\"EPSG\",\"4326\"]]";
static const char GEOG_NAD83[] =
    "GEOGCS[\"NAD83\",DATUM[\"North_American_Datum_1983\",SPHEROID[\"GRS 1980\",6378137,"
    "298.257222101,AUTHORITY[\"EPSG\",\"7019\"]],AUTHORITY[\"EPSG\",\"6269\"]],"
    "PRIMEM[\"Greenwich\",0,AUTHORITY[\"EPSG\",\"8901\"]],"
    "UNIT[\"degree\",0.0174532925199433,AUTHORITY[\"EPSG\",\"9122\"]],"
    "AUTHORITY[\"EPSG\",\"4269\"]]";
static const char METRE[] = "UNIT[\"metre\",1,AUTHORITY[\"EPSG\",\"9001\"]]";

char *gdt_mesh_crs_wkt_of_epsg(int epsg, int *oom)
{
    const char *geog = NULL, *datum = NULL;
    int zone = 0, south = 0, ups = 0;
    size_t cap;
    char *s;

    if (epsg >= 32601 && epsg <= 32660) {
        geog = GEOG_WGS84, datum = "WGS 84", zone = epsg - 32600;
    } else if (epsg >= 32701 && epsg <= 32760) {
        geog = GEOG_WGS84, datum = "WGS 84", zone = epsg - 32700, south = 1;
    } else if (epsg == 32661 || epsg == 32761) {
        geog = GEOG_WGS84, datum = "WGS 84", ups = 1, south = epsg == 32761;
    } else if (epsg >= 26901 && epsg <= 26923) {
        geog = GEOG_NAD83, datum = "NAD83", zone = epsg - 26900;
    } else {
        return NULL;
    }
    cap = strlen(geog) + 1024;
    s = malloc(cap);
    if (s == NULL) {
        if (oom != NULL)
            *oom = 1;
        return NULL;
    }
    if (ups)
        snprintf(s, cap,
                 "PROJCS[\"%s / UPS %s\",%s,PROJECTION[\"Polar_Stereographic\"],"
                 "PARAMETER[\"latitude_of_origin\",%d],PARAMETER[\"central_meridian\",0],"
                 "PARAMETER[\"scale_factor\",0.994],PARAMETER[\"false_easting\",2000000],"
                 "PARAMETER[\"false_northing\",2000000],%s,AXIS[\"Easting\",EAST],"
                 "AXIS[\"Northing\",NORTH],AUTHORITY[\"EPSG\",\"%d\"]]",
                 datum, south ? "South" : "North", geog, south ? -90 : 90, METRE, epsg);
    else
        snprintf(s, cap,
                 "PROJCS[\"%s / UTM zone %d%c\",%s,PROJECTION[\"Transverse_Mercator\"],"
                 "PARAMETER[\"latitude_of_origin\",0],PARAMETER[\"central_meridian\",%d],"
                 "PARAMETER[\"scale_factor\",0.9996],PARAMETER[\"false_easting\",500000],"
                 "PARAMETER[\"false_northing\",%d],%s,AXIS[\"Easting\",EAST],"
                 "AXIS[\"Northing\",NORTH],AUTHORITY[\"EPSG\",\"%d\"]]",
                 datum, zone, south ? 'S' : 'N', geog, 6 * zone - 183, south ? 10000000 : 0, METRE,
                 epsg);
    return s;
}

/* Case-insensitive: does [p, p+n) start with the keyword kw followed by '['
 * or '(' (WKT allows both)? */
static int keyword_at(const char *p, const char *end, const char *kw)
{
    size_t k = strlen(kw);
    if ((size_t)(end - p) <= k)
        return 0;
    for (size_t i = 0; i < k; i++)
        if (toupper((unsigned char)p[i]) != kw[i])
            return 0;
    return p[k] == '[' || p[k] == '(';
}

/* The quoted name right after "KW[" at p; copies at most cap-1 bytes. */
static void name_after(const char *p, const char *end, char *out, size_t cap)
{
    size_t j = 0;
    while (p < end && *p != '"' && *p != '[' && *p != '(')
        p++;
    if (p < end && (*p == '[' || *p == '('))
        p++;
    while (p < end && isspace((unsigned char)*p))
        p++;
    if (p < end && *p == '"') {
        for (p++; p < end && *p != '"' && j + 1 < cap; p++)
            out[j++] = (char)tolower((unsigned char)*p);
    }
    out[j] = '\0';
}

/* design: walk the WKT once, tracking bracket depth relative to the first
 * PROJCS / PROJCRS / PROJECTEDCRS keyword (compound CRS wrappers come
 * before it).  Inside it, BASEGEOGCRS / BASEGEODCRS / GEOGCS children hold
 * angular units and are skipped; the first UNIT or LENGTHUNIT met
 * elsewhere inside the projected CRS names its linear unit. */
int gdt_mesh_crs_wkt_foot(const char *wkt)
{
    const char *p, *end;
    int depth = 0, proj_depth = -1, skip_depth = -1, in_str = 0;
    char name[96];

    if (wkt == NULL)
        return 0;
    end = wkt + strlen(wkt);
    for (p = wkt; p < end; p++) {
        char c = *p;
        if (in_str) {
            if (c == '"') {
                if (p + 1 < end && p[1] == '"')
                    p++; /* "" inside a quoted string */
                else
                    in_str = 0;
            }
            continue;
        }
        if (c == '"') {
            in_str = 1;
            continue;
        }
        if (c == '[' || c == '(') {
            depth++;
            continue;
        }
        if (c == ']' || c == ')') {
            depth--;
            if (skip_depth >= 0 && depth < skip_depth)
                skip_depth = -1;
            if (proj_depth >= 0 && depth < proj_depth)
                return 0; /* the projected CRS ended without a linear unit */
            continue;
        }
        if (!isalpha((unsigned char)c) || (p > wkt && isalnum((unsigned char)p[-1])))
            continue;
        if (proj_depth < 0) {
            if (keyword_at(p, end, "PROJCS") || keyword_at(p, end, "PROJCRS") ||
                keyword_at(p, end, "PROJECTEDCRS"))
                proj_depth = depth + 1;
            continue;
        }
        if (skip_depth >= 0)
            continue;
        if (keyword_at(p, end, "GEOGCS") || keyword_at(p, end, "BASEGEOGCRS") ||
            keyword_at(p, end, "BASEGEODCRS") || keyword_at(p, end, "CONVERSION") ||
            keyword_at(p, end, "PROJECTION") || keyword_at(p, end, "PARAMETER")) {
            skip_depth = depth + 1;
            continue;
        }
        if (keyword_at(p, end, "UNIT") || keyword_at(p, end, "LENGTHUNIT")) {
            name_after(p, end, name, sizeof name);
            if (strstr(name, "us survey foot") != NULL || strstr(name, "foot_us") != NULL ||
                strstr(name, "us_survey_foot") != NULL)
                return 2;
            if (strstr(name, "foot") != NULL || strstr(name, "feet") != NULL)
                return 1;
            return 0;
        }
    }
    return 0;
}
