/* gdt_dem.h — the streaming DEM (GeoTIFF) writer.
 *
 * A writer receives the values of the cells of a north-up float32 raster in
 * any order, each cell at most once (runs of cells along a row, as the TIN
 * rasteriser of core/gdt_raster.h produces them), and writes one Cloud
 * Optimized GeoTIFF: tiled 512 x 512, DEFLATE with the floating-point
 * predictor, overviews (the mean of the valid cells of each 2^k x 2^k
 * footprint, ceil(n / 2^k) cells a side), BIGTIFF when it could
 * exceed 4 GiB, the CRS and the nodata value; cells never written are
 * nodata.  The raster may be far larger than memory:
 *
 *   - cells are kept in blocks of GDT_DEM_BLOCK x GDT_DEM_BLOCK (1 MiB),
 *     the tiles of the output; a write-back cache of blocks holds at most
 *     mem_budget bytes of them (at least two blocks).  A block evicted
 *     from the cache goes, whole, to a scratch file in scratch_dir at the
 *     offset of its block index (a sparse file, created and unlinked at
 *     once); a block touched again is read back first.  In memory and in
 *     the scratch file a cell is the bits of its float32 value plus one, so
 *     all-zero bytes (a hole of the sparse file) decode as "not written";
 *   - gdt_dem_finish writes every block exactly once, in row-major block
 *     order, to an intermediate raster with its overview levels, each
 *     block's part of every level computed from the block as it is written
 *     (dem_gdal.c): when the cache holds every block, an in-memory raster
 *     of GDAL's MEM driver that grows as the cache gives each block back;
 *     else a tiled GeoTIFF in scratch_dir (blocks that are all nodata are
 *     left out: sparse).  It frees the cache, and lets GDAL's COG driver
 *     (at most mem_budget / 2 of GDAL block cache) copy the intermediate,
 *     overviews included, to PATH.tmp-PID beside PATH (the same bytes from
 *     either intermediate); that file is fsync'd and
 *     renamed over PATH, so a file at PATH is complete; the scratch files
 *     are removed whatever happens;
 *   - with a preview path, a shaded-relief PNG of the DEM (GDAL's
 *     hillshade, GDALDEMProcessing, of a copy averaged down to at most
 *     GDT_DEM_PREVIEW_MAX pixels on its long side) is written the same way.
 *
 * Same calls -> same bytes: nothing time-dependent is written (no TIFF
 * date tag, no GDAL statistics), compressed blocks are written in block
 * order whatever the threads compressing them, and the
 * output does not depend on the order of the writes or on mem_budget.
 * GDAL's messages never reach stderr: a GDAL failure is an error here,
 * with GDAL's last message in it.  Not thread-safe per writer (one thread
 * feeds it); writers are independent, but GDAL's block cache size is
 * process-wide and is set during gdt_dem_finish (gdt_dem_build).
 */
#ifndef GDT_DEM_H
#define GDT_DEM_H

#include <stdint.h>

#include "gdt_error.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Cells per block side (the tiles of the GeoTIFF). */
#define GDT_DEM_BLOCK 512
/* Longest side of the preview PNG, pixels. */
#define GDT_DEM_PREVIEW_MAX 2048
/* Largest raster: 2^31 - 1 cells per side and 2^40 cells in all. */
#define GDT_DEM_MAX_SIDE INT64_C(2147483647)
#define GDT_DEM_MAX_CELLS (INT64_C(1) << 40)

/* The raster's georeferencing: row 0 is the north row, column 0 the west
 * one; cell (row, col) covers [west + col res_x, west + (col+1) res_x] x
 * [north - (row+1) res_y, north - row res_y] in CRS units. */
typedef struct gdt_dem_geo {
    int64_t ncols, nrows; /* 1..GDT_DEM_MAX_SIDE, ncols * nrows <= GDT_DEM_MAX_CELLS */
    double west, north;   /* CRS coordinates of the north-west corner */
    double res_x, res_y;  /* cell size, CRS units, > 0 */
} gdt_dem_geo;

typedef struct gdt_dem_opts {
    double nodata;           /* value of the cells never written (finite, a float32) */
    const char *scratch_dir; /* NULL: the directory of the output path */
    uint64_t mem_budget;     /* bytes for the block cache; 0: 256 MiB; at least 2 blocks */
    int epsg;                /* CRS as an EPSG code, 0: none (then crs_wkt) */
    const char *crs_wkt;     /* CRS as WKT, NULL: none; neither: no CRS is written */
    const char *preview;     /* PNG path for the shaded relief, NULL: none */
} gdt_dem_opts;

/* What a writer did (for --json and the tests). */
typedef struct gdt_dem_stats {
    uint64_t cells_written;  /* cells given a value */
    uint64_t blocks;         /* blocks of the raster */
    uint64_t cache_blocks;   /* blocks the cache may hold */
    uint64_t spills;         /* block evictions to the scratch file */
    uint64_t reloads;        /* blocks read back from the scratch file */
    uint64_t blocks_written; /* blocks written to the intermediate file (the rest: nodata) */
} gdt_dem_stats;

typedef struct gdt_dem gdt_dem;

/* Loads the GDAL plug-in (private/dem_gdal.h) ahead of gdt_dem_create, so
 * that a run can overlap its loading with other work; failures are left
 * for gdt_dem_create to report.  Thread-safe. */
void gdt_dem_preload(void);

/* Starts a DEM at path.  Strings are copied.
 * returns: GDT_OK; GDT_EUSAGE 2611 (a geo or option out of range);
 *   GDT_EINTERNAL 7004 (the GDAL plug-in cannot be loaded);
 *   GDT_EIO 4650 (scratch file); GDT_EINTERNAL 7001.
 * Ownership: *out is owned by the caller, released by gdt_dem_finish,
 * gdt_dem_commit or gdt_dem_abort (exactly one of them). */
gdt_status gdt_dem_create(gdt_dem **out, const gdt_dem_geo *geo, const char *path,
                          const gdt_dem_opts *opts, gdt_error *err);

/* Sets cells (row, col .. col + n - 1) to z[0 .. n).  Any order of calls;
 * each cell at most once.
 * returns: GDT_OK; GDT_EINTERNAL 7661 (cells outside the raster), 7662 (a
 *   cell given a value twice); GDT_EIO 4651 (scratch file I/O). */
gdt_status gdt_dem_put(gdt_dem *w, int64_t row, int64_t col, int64_t n, const float *z,
                       gdt_error *err);

/* gdt_dem_put with the signature of gdt_raster_sink (core/gdt_raster.h):
 * ctx is the gdt_dem. */
gdt_status gdt_dem_sink(void *ctx, int64_t row, int64_t col, int64_t n, const float *z,
                        gdt_error *err);

/* The counters so far. */
gdt_dem_stats gdt_dem_get_stats(const gdt_dem *w);

/* Writes the GeoTIFF (and the preview) as described above and releases w
 * (also on failure: then no scratch or temporary file is left and nothing
 * new at path, except that a failure of the preview alone leaves the
 * complete DEM at path and nothing at the preview path).  stats, when not NULL, receives the final counters.
 * returns: GDT_OK; GDT_EINPUT 3650 (the CRS is unknown to GDAL); GDT_EIO
 *   4651 (scratch file), 4652 (GDAL could not write a file: its message),
 *   4653 (fsync or rename); GDT_EINTERNAL 7001. */
gdt_status gdt_dem_finish(gdt_dem *w, gdt_dem_stats *stats, gdt_error *err);

/* gdt_dem_finish in two steps, so that the work of the first can run
 * beside something the second must wait for (the mesh's own sync):
 * gdt_dem_build writes the GeoTIFF (and the preview) as above to their
 * temporaries, synced, frees the cache and keeps w; no gdt_dem_put after
 * it.  Then gdt_dem_commit (after a successful build) renames them into
 * place and releases w, or gdt_dem_abort removes them.  A failure of the
 * preview alone is returned by the commit, after the DEM is in place.
 * returns: as gdt_dem_finish; GDT_EINTERNAL 7664 (built twice, or
 *   committed unbuilt). */
gdt_status gdt_dem_build(gdt_dem *w, gdt_dem_stats *stats, gdt_error *err);
gdt_status gdt_dem_commit(gdt_dem *w, gdt_error *err);

/* Releases w without writing anything; removes its scratch file.  NULL is
 * accepted. */
void gdt_dem_abort(gdt_dem *w);

#ifdef __cplusplus
}
#endif
#endif
