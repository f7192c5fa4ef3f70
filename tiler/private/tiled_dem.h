/* tiled_dem.h — --dem in the tiled run.
 *
 * The DEM is the rasterisation (core/gdt_raster.h) of every face the mesh
 * keeps (trimming, gdt_trim.h, drops the same faces from both), fed to one
 * streaming writer (io/gdt_dem.h) by the mesh writer (tiled_out.c):
 *   - each tile's kept certified faces as it copies them from the tile's
 *     .tri file; a certified triangle has its three vertices among the
 *     tile's own points, whose coordinates and z it reads from the tile's
 *     .pts file (tr_dem_tile_faces);
 *   - then the merge's kept faces, as it copies them from merge.faces, with
 *     their vertices from merge.dem, which the merge writes beside it from
 *     the band (the seam vertices carry their z: gdt_seam.h) (tr_dem_faces).
 * Every cell centre is owned by exactly one face and the writer's output
 * does not depend on the order of the writes, so the bytes are those of
 * --reference on the same cloud.
 *
 * Grid: gdt_raster_grid_define over the plan's lattice bounding box with
 * the run's distinct point count (the bounding box and the count of the
 * in-memory modes).  Budget: the DEM's block cache gets an eighth of
 * --mem-budget (at least 16 MiB), 256 MiB without one; its scratch files go
 * to the job directory. */
#ifndef GDT_TILED_DEM_H
#define GDT_TILED_DEM_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_cli.h"
#include "gdt_cloud.h"
#include "gdt_dem.h"
#include "gdt_raster.h"
#include "gdt_error.h"
#include "gdt_seam.h"
#include "gdt_tiler.h"

typedef struct tr_dem tr_dem;

/* Defines the grid and starts the writer at opts->dem (preview: opts->preview).
 * returns: gdt_raster_grid_define's and gdt_dem_create's errors; 7001.
 * Ownership: release with tr_dem_commit or tr_dem_abort. */
gdt_status tr_dem_create(tr_dem **out, const gdt_options *opts, const gdt_cloud_info *ci,
                         const gdt_tile_plan *pl, uint64_t vertices, const char *scratch_dir,
                         gdt_error *err);

/* The points of a tile as tr_dem_tile_faces and tr_dem_window_begin read
 * them: its n records as they lie in its .pts file (TL_REC bytes each, in
 * tl_rec_put's layout: global lattice x and y, then z, little-endian),
 * mapped from that file by the mesh writer, so that a tile's points take
 * no memory of their own.  Every point lies in the tile's local square
 * [x0, x0 + extent) x [y0, y0 + extent) (gdt_tile_desc local_x0, local_y0,
 * local_extent); one that does not fails the faces that name it with
 * GDT_EJOB 6802, naming path. */
typedef struct tr_dem_tile {
    const unsigned char *rec;
    size_t n;
    int64_t x0, y0, extent;
    const char *path;
} tr_dem_tile;

/* Rasterises m faces tri[3m] (output vertex indices) of a tile whose points
 * t (tr_dem_tile) have the output indices base..base+n-1, after finishing
 * the faces given before.  alone: now, on the caller's thread only (the
 * helpers stay idle); else (with helper threads) the faces are copied and
 * handed to the helpers, and the call returns at once: the caller takes
 * the parts still left at its next call or at tr_dem_tile_wait.  tri may be
 * reused when the call returns; t's points must stay as they are until the
 * next call or tr_dem_tile_wait.  The DEM is the same either way.
 * Thread-safe.
 * returns: GDT_OK; GDT_EINTERNAL 7663 (an index outside the tile), 7001;
 * GDT_EJOB 6802 (a point outside the tile);
 * the writer's errors; a failure of the faces given before (the first in
 * face order) is returned by the next call or tr_dem_tile_wait. */
gdt_status tr_dem_tile_faces(tr_dem *d, const tr_dem_tile *t, uint64_t base, const int32_t *tri,
                             size_t m, int alone, gdt_error *err);

/* Finishes the faces handed to the helpers (the caller takes the parts
 * still left) and returns their status.  Thread-safe. */
gdt_status tr_dem_tile_wait(tr_dem *d, gdt_error *err);

/* Rasterises m faces given by their vertices v[3 m] (global lattice, z).
 * Thread-safe.  returns: GDT_OK; the writer's errors. */
gdt_status tr_dem_faces(tr_dem *d, const gdt_raster_vertex *v, size_t m, gdt_error *err);

/* Writes the DEM in two steps (gdt_dem_build, gdt_dem_commit): the build
 * finishes the faces handed to the helpers (tr_dem_tile_wait), stops the
 * helpers and writes the temporaries, once every face is in (geo
 * and stats, may be NULL, receive what was written); it may run on another
 * thread than the rest.  The commit (only after a successful build) puts
 * them in place and releases d; else tr_dem_abort. */
gdt_status tr_dem_build(tr_dem *d, gdt_dem_geo *geo, gdt_dem_stats *stats, gdt_error *err);
gdt_status tr_dem_commit(tr_dem *d, gdt_error *err);

/* ---- Under mpirun: the other ranks rasterise their own tiles ----
 *
 * A rank other than 0 has no writer: it rasterises each of its tiles'
 * kept faces (tr_dem_tile_faces, as the writer of its part copies them)
 * into a window, the cells around the tile's points, saved as the tile's
 * .dwin file; rank 0 puts every window's cells into its writer
 * (tr_dem_window_put) before the merge's faces.  A cell is owned by one
 * face, so the windows, rank 0's own tiles and the merge's faces write
 * each cell once, and the DEM is the plain run's. */

/* A DEM in window mode over rank 0's grid (tr_dem_grid).  returns: 7001. */
gdt_status tr_dem_create_windows(tr_dem **out, const gdt_raster_grid *grid, gdt_error *err);

/* Whether d is in window mode. */
int tr_dem_windowed(const tr_dem *d);

/* The grid of d. */
const gdt_raster_grid *tr_dem_grid(const tr_dem *d);

/* Window mode: starts the window of a tile whose points are t
 * (every cell any of its faces can own), all cells unwritten, to be saved
 * at path.  A window of up to 2^24 cells (or the environment's
 * GDT_DEM_WINDOW_CELLS) is kept in memory; a larger one (a raster much
 * finer than the points) is written to path run by run as the faces are
 * rasterised.  returns: GDT_OK; GDT_EIO 4806; GDT_EJOB 6802 (a point outside
 * the tile); 7001. */
gdt_status tr_dem_window_begin(tr_dem *d, const tr_dem_tile *t, const char *path,
                               gdt_error *err);

/* Window mode: completes the current window's file.  returns: GDT_OK;
 * GDT_EIO 4806 (nothing left at its path). */
gdt_status tr_dem_window_save(tr_dem *d, gdt_error *err);

/* Rank 0: the cells of the window file at path into the writer.  Thread-
 * safe.  returns: GDT_OK; GDT_EIO 4805; GDT_EJOB 6801, 6802 (not a window,
 * or one that does not fit the raster); the writer's errors (a cell
 * written twice among them). */
gdt_status tr_dem_window_put(tr_dem *d, const char *path, gdt_error *err);

/* Releases d without writing; NULL is accepted. */
void tr_dem_abort(tr_dem *d);

#endif
