/* gdt_vdb_index.h — the tiler's spatial index in OpenVDB (C interface).
 *
 * Two grids of 64-bit integer counts, 2D data on the z = 0 plane:
 *  - "tile_points": voxel (i - tile_i0, j - tile_j0, 0) holds the number of
 *    points of tile (i, j) (one active voxel per non-empty tile);
 *  - "density": voxel (vx, vy, 0) holds the number of points with
 *    floor(x / V) = vx and floor(y / V) = vy, V = 2^density_shift lattice
 *    steps (absolute voxel indices, |vx|, |vy| < 2^30).
 * The grids' transforms map voxel centres to lattice coordinates (a world
 * unit is one lattice step: CRS x = gdt_lattice_ox + gdt_lattice_sx * world
 * x, y likewise, as the string metadata "gdt_world" says; in lattice units
 * no valid lattice gives a transform OpenVDB refuses), and the metadata (gdt_vdb_meta, as int64, double and string metadata named
 * "gdt_<field>" on both grids) makes the file self-describing.  The tiler
 * accumulates the density in a bounded histogram while it streams
 * (density.c) and fills both grids at the end of pass 1.
 *
 * Every function catches every exception at the boundary and reports it as
 * a gdt_status: GDT_EINTERNAL 7001 (std::bad_alloc), 7511 (OpenVDB or the
 * C++ library failed), GDT_EIO 4511 (the file cannot be written), GDT_EINPUT
 * 3511 (the file cannot be read or is not a gdt-tile index).
 * Not thread-safe per instance.
 */
#ifndef GDT_VDB_INDEX_H
#define GDT_VDB_INDEX_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_cloud.h"
#include "gdt_error.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Metadata written with the grids (names as in the file: "gdt_" + field). */
typedef struct gdt_vdb_meta {
    int64_t tile;          /* N */
    int64_t cell;          /* texel side, lattice steps */
    int64_t halo;          /* texels */
    int64_t span;          /* T = N * cell */
    int64_t tile_i0, tile_j0;
    int64_t density_shift;
    int64_t points;
    gdt_lattice lattice;
    const char *dup;       /* --dup rule name */
} gdt_vdb_meta;

typedef struct gdt_vdb_index gdt_vdb_index;

/* Ownership: *out is new, free with gdt_vdb_index_destroy (NULL allowed). */
gdt_status gdt_vdb_index_create(gdt_vdb_index **out, gdt_error *err);
void gdt_vdb_index_destroy(gdt_vdb_index *ix);

/* Bytes of one leaf, lower internal and upper internal node of the grids'
 * tree (8, 128 and 4096 voxels a side). */
void gdt_vdb_node_bytes(size_t bytes[3]);

/* Sets density voxel (vx, vy) (|vx|, |vy| < 2^30) to count. */
gdt_status gdt_vdb_density_set(gdt_vdb_index *ix, int64_t vx, int64_t vy, uint64_t count,
                               gdt_error *err);

/* Sets tile voxel (ci, cj) (relative indices, each in [0, 2^31 - 1]) to count. */
gdt_status gdt_vdb_tiles_set(gdt_vdb_index *ix, int64_t ci, int64_t cj, uint64_t count,
                             gdt_error *err);

/* Names the grids, sets their transforms and metadata from meta and writes
 * both to path (OpenVDB's own file format).  The caller makes the file
 * durable (fsync, rename). */
gdt_status gdt_vdb_index_write(gdt_vdb_index *ix, const gdt_vdb_meta *meta, const char *path,
                               gdt_error *err);

typedef int (*gdt_vdb_visit_fn)(void *ctx, int64_t ci, int64_t cj, uint64_t count);

/* Reads the "tile_points" grid of an index file: fn(ctx, ci, cj, count) for
 * every active voxel, relative indices; meta receives the metadata (its dup
 * string points to a static "first"/"min-z"/"max-z" or "unknown"). */
gdt_status gdt_vdb_index_read_tiles(const char *path, gdt_vdb_meta *meta, gdt_vdb_visit_fn fn,
                                    void *ctx, gdt_error *err);

#ifdef __cplusplus
}
#endif
#endif
