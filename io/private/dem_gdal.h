/* dem_gdal.h — the GDAL side of the DEM writer (gdt_dem.h): the only code
 * of gdt-tile that calls GDAL.  It is a plug-in (private/plugin.h):
 * dem_gdal.c is built into libgdt-tile-gdal.so, which only runs that write
 * a DEM load (GDAL and its hundred libraries cost every start about
 * 0.1 s); dem.c reaches it through the table gdt_dem_gdal_api, the one
 * symbol the module exports.  Every entry point keeps GDAL's messages
 * off stderr (a quiet error handler for the duration of the call) and
 * turns a GDAL failure into a gdt_error carrying GDAL's last message.
 * Thread-safe across threads as GDAL is; GDAL's block cache size is
 * process-wide. */
#ifndef GDT_DEM_GDAL_H
#define GDT_DEM_GDAL_H

#include <stdint.h>

#include "gdt_dem.h"
#include "gdt_error.h"

/* Fills buf (GDT_DEM_BLOCK x GDT_DEM_BLOCK float32, row-major, stride
 * GDT_DEM_BLOCK) with block (bx, by); *empty = 1 when every cell is
 * nodata (buf is then not used).  Each block is asked for once. */
typedef gdt_status (*gdt_dem_block_fn)(void *ctx, int64_t bx, int64_t by, float *buf, int *empty,
                                       gdt_error *err);

/* The intermediate raster the COG is copied from: the full resolution
 * (512 x 512 blocks) with its own overview levels (see dem_gdal.c),
 * georeferencing, CRS (epsg, else wkt, else none) and nodata, each block
 * asked from fn once, in row-major block order.  Either a tiled GeoTIFF
 * at tiles_path (uncompressed, BIGTIFF, sparse: empty blocks are not
 * written), or, with tiles_path NULL, a dataset of GDAL's MEM driver whose
 * band is raster itself (ncols x nrows float32, row-major, nodata where no
 * value; not copied: it must outlive the dataset) with its overviews in
 * memory, returned in *mem_ds for gdt_dem_gdal_cog (fn is then not
 * called).  Both give the COG the same cells and the same georeferencing.
 * gdal_cache bounds GDAL's block cache (bytes).
 * returns: GDT_OK; fn's errors; GDT_EINPUT 3650 (the CRS is unknown to
 * GDAL); GDT_EIO 4652; GDT_EINTERNAL 7001, 7665 (no raster in memory). */
gdt_status gdt_dem_gdal_tiles(const gdt_dem_geo *geo, double nodata, int epsg, const char *wkt,
                              const char *tiles_path, float *raster, uint64_t gdal_cache,
                              gdt_dem_block_fn fn, void *ctx, void **mem_ds, gdt_error *err);

/* Copies the intermediate (mem_ds when not NULL, which it closes, else the
 * file tiles_path) to the COG tmp_path (DEFLATE level 1, floating-point
 * predictor, BIGTIFF=IF_SAFER, 512 x 512 tiles, the intermediate's
 * overviews, or GDAL's averaged ones when it has none) and fsyncs it; the
 * caller renames it.  path names the output in messages.
 * returns: GDT_OK; GDT_EIO 4652, 4653. */
gdt_status gdt_dem_gdal_cog(const char *tiles_path, void *mem_ds, const char *tmp_path,
                            const char *path, uint64_t gdal_cache, gdt_error *err);

/* Closes an intermediate of gdt_dem_gdal_tiles that was not copied; NULL
 * is accepted. */
void gdt_dem_gdal_discard(void *mem_ds);

/* Writes the hillshade of the GeoTIFF dem_path, averaged down to at most
 * GDT_DEM_PREVIEW_MAX pixels on its long side, as the PNG tmp_path, and
 * fsyncs it; the caller renames it.  path names the preview in messages.
 * returns: GDT_OK; GDT_EIO 4652, 4653. */
gdt_status gdt_dem_gdal_preview(const char *dem_path, const char *tmp_path, const char *path,
                                uint64_t gdal_cache, gdt_error *err);

#define GDT_DEM_GDAL_MODULE "libgdt-tile-gdal.so"
#define GDT_DEM_GDAL_SYMBOL "gdt_dem_gdal_api"

/* The entry points above, as the module exports them. */
typedef struct gdt_dem_gdal_fns {
    gdt_status (*tiles)(const gdt_dem_geo *geo, double nodata, int epsg, const char *wkt,
                        const char *tiles_path, float *raster, uint64_t gdal_cache,
                        gdt_dem_block_fn fn, void *ctx, void **mem_ds, gdt_error *err);
    gdt_status (*cog)(const char *tiles_path, void *mem_ds, const char *tmp_path, const char *path,
                      uint64_t gdal_cache, gdt_error *err);
    void (*discard)(void *mem_ds);
    gdt_status (*preview)(const char *dem_path, const char *tmp_path, const char *path,
                          uint64_t gdal_cache, gdt_error *err);
} gdt_dem_gdal_fns;

#endif
