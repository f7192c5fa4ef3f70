/* mesh_crs.h — what the TIN writers (gdt_mesh_out.h) need to know of a CRS
 * beyond what the cloud gives: WKT for the EPSG codes gdt-tile itself
 * produces or commonly meets (so a .prj can be written for them), and the
 * linear unit named by a WKT (for the LandXML <Units>).  No allocation
 * except the returned string; no state. */
#ifndef GDT_MESH_CRS_H
#define GDT_MESH_CRS_H

/* OGC WKT 1 of WGS 84 / UTM zone 1..60 N (32601..32660) and S
 * (32701..32760), WGS 84 / UPS North and South (32661, 32761) and NAD83 /
 * UTM zone 1..23 N (26901..26923); NULL for any other code or out of
 * memory (*oom set to 1 then, when oom is not NULL).  Axis order of the
 * UPS entries is easting, northing, as gdt-tile writes them.
 * Ownership: the caller frees the result. */
char *gdt_mesh_crs_wkt_of_epsg(int epsg, int *oom);

/* 1 when the linear unit of the top-level projected CRS of wkt (WKT 1
 * UNIT child of PROJCS, WKT 2 LENGTHUNIT of PROJCRS or its axes; a
 * compound CRS is looked into) is a foot (international or US survey), 2
 * for a US survey foot precisely, 0 otherwise (metre, unknown, NULL). */
int gdt_mesh_crs_wkt_foot(const char *wkt);

#endif
