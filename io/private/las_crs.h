/* las_crs.h — coordinate reference system of a LAS file, from its GeoTIFF
 * key VLRs (records 34735/34736/34737) and its OGC WKT (V)LR (record 2112).
 *
 * Everything here works on bytes already read into memory and never reads
 * outside the (pointer, length) it is given: the inputs come straight from
 * the file and may be malformed in any way.  Nothing here allocates, and
 * every result is returned in caller-owned structs.
 */
#ifndef GDT_LAS_CRS_H
#define GDT_LAS_CRS_H

#include <stddef.h>

/* EPSG code reserved by GeoTIFF for "user-defined". */
#define GDT_LAS_GEOKEY_USER_DEFINED 32767

/* What the GeoKeyDirectoryTag says.  Codes are 0 when the key is absent. */
typedef struct gdt_las_geokeys {
    int present;         /* a directory with a valid header was found */
    int malformed;       /* the directory claims more keys than it holds, or
                            a citation points outside the ASCII params */
    int model;           /* GTModelTypeGeoKey (1024): 1 projected, 2 geographic, 3 geocentric */
    int geographic_code; /* GeographicTypeGeoKey (2048) */
    int projected_code;  /* ProjectedCSTypeGeoKey (3072) */
    char citation[128];  /* PCSCitation, else GTCitation, else GeogCitation; "" if none */
} gdt_las_geokeys;

/* Decodes a GeoKeyDirectoryTag payload (dir, dir_len bytes, little-endian
 * uint16 words).  ascii/ascii_len is the GeoAsciiParamsTag payload or NULL/0.
 * Never fails: a directory too short for its 4-word header leaves
 * out->present == 0; keys beyond the payload are ignored and flagged in
 * out->malformed. */
void gdt_las_geokeys_parse(const unsigned char *dir, size_t dir_len, const char *ascii,
                           size_t ascii_len, gdt_las_geokeys *out);

/* What a WKT string (WKT1 or WKT2) says about its horizontal CRS. */
typedef enum gdt_las_wkt_kind {
    GDT_LAS_WKT_UNKNOWN = 0, /* not parsable, or a kind we do not recognise */
    GDT_LAS_WKT_GEOGRAPHIC,  /* GEOGCS / GEOGCRS / GEODCRS with an ellipsoidal CS */
    GDT_LAS_WKT_PROJECTED,   /* PROJCS / PROJCRS */
    GDT_LAS_WKT_GEOCENTRIC   /* GEOCCS / GEODCRS with a Cartesian CS */
} gdt_las_wkt_kind;

typedef struct gdt_las_wkt_facts {
    gdt_las_wkt_kind kind; /* of the horizontal part (compound and bound CRS are opened) */
    int epsg;              /* EPSG code of the horizontal CRS, 0 if none is given */
    char name[128];        /* name of the top-level CRS, "" if none */
} gdt_las_wkt_facts;

/* Inspects the top-level object of a WKT string of len bytes (it need not
 * be NUL-terminated).  Returns 0 when a top-level keyword with balanced
 * brackets was found, -1 otherwise (out is then all zero). */
int gdt_las_wkt_inspect(const char *wkt, size_t len, gdt_las_wkt_facts *out);

/* The resolved CRS of one file. */
typedef struct gdt_las_crs {
    int epsg;       /* 0 when unknown */
    int geographic; /* 1 when x/y are longitude/latitude degrees */
    char desc[192]; /* "EPSG:26910", "WKT: <name>", "GeoTIFF: <citation>", "unknown" */
} gdt_las_crs;

/* Combines the two sources.  The WKT wins when wkt_authoritative (the LAS 1.4
 * global-encoding WKT bit) or when the GeoTIFF keys give no EPSG code;
 * otherwise the GeoTIFF keys win.  keys or wkt may be NULL (absent). */
void gdt_las_crs_resolve(const gdt_las_geokeys *keys, const char *wkt, size_t wkt_len,
                         int wkt_authoritative, gdt_las_crs *out);

#endif
