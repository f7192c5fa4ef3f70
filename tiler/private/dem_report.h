/* dem_report.h — the DEM (--dem) in the outputs of a run: the --json member
 * and the summary line.  Every mode reports the same way. */
#ifndef GDT_DEM_REPORT_H
#define GDT_DEM_REPORT_H

#include "gdt_cli.h"
#include "gdt_dem.h"
#include "private/json_out.h"

/* The member "dem" of the current JSON object: path, preview, res, cols,
 * rows, west, north, cells_with_value, blocks, cache_blocks, spills and
 * seconds (the rasterising and writing). */
void gdt_dem_report_json(gdt_json *j, const gdt_options *opts, const gdt_dem_geo *geo,
                         const gdt_dem_stats *st, double seconds);

/* "gdt-tile: OUT.tif: DEM of C x R cells of RES, N with a value[; preview P]"
 * on stderr, unless -q. */
void gdt_dem_report_line(const gdt_options *opts, const gdt_dem_geo *geo,
                         const gdt_dem_stats *st);

#endif
