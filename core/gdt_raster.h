/* gdt_raster.h — the DEM grid on the lattice and the rasterisation of TIN
 * triangles into it.
 *
 * Grid rule.  A cell is mx lattice steps wide and my tall, with
 * mx sx = my sy = R (square cells in CRS units; R is a common multiple of
 * both steps).  The grid lines are anchored at the lattice lines nearest to
 * the CRS origin: ax = round(-ox / sx), ay = round(-oy / sy), and column
 * lines run at lattice x = ax + K mx, row lines at y = ay + K my for every
 * integer K.  When ox is a multiple of sx (LAS offsets and PCD quanta
 * usually are; checked to 1e-9 of a step) those are exactly the CRS lines
 * x = K R, so cell centres are at (K + 1/2) R; otherwise they are the
 * lattice lines within half a step of them.  The raster holds every cell
 * that meets the cloud's lattice bounding box (at least one): column c
 * spans lattice x [x0 + c mx, x0 + (c+1) mx], row r (from the north) spans
 * y [y0 - (r+1) my, y0 - r my].  Its centre, in doubled lattice
 * coordinates (gdt_hpt), is (2 x0 + mx (2c + 1), 2 y0 - my (2r + 1)).
 *
 * Ownership rule.  A centre belongs to the counter-clockwise triangle
 * (a, b, c) when each of its three directed edges owns it
 * (gdt_edge_owns_half: strictly inside, or on a west or south edge, i.e.
 * the centre moved infinitesimally east, then north, is strictly inside).
 * Every centre inside the triangulated region belongs to exactly one
 * triangle of a triangulation, whatever order or batches its faces come
 * in; a centre on the region's boundary belongs to one or none; a centre
 * outside to none (its cell stays nodata, like the cells of triangles the
 * caller does not pass).
 *
 * Value.  With the vertices rotated so that a is the lexicographically
 * smallest (x, then y) and b, c follow counter-clockwise, A, B, C, P the
 * doubled coordinates of a, b, c and the centre, the exact integers
 *     wa = (C - B) x (P - B),  wb = (A - C) x (P - C),  wc = (B - A) x (P - A),
 *     D = wa + wb + wc = (B - A) x (C - A) > 0
 * are rounded to double (nearest) and
 *     z = ((wa * za + wb * zb) + wc * zc) / D
 * is evaluated in IEEE binary64, each operation rounded to nearest, in
 * that order, no contraction; the cell gets (float) z, rounded to nearest.
 * Since a triangle's rotation is fixed by its vertices, the value of a
 * cell depends only on the triangle that owns it.
 */
#ifndef GDT_RASTER_H
#define GDT_RASTER_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_cloud.h"
#include "gdt_dem.h"
#include "gdt_error.h"
#include "gdt_predicates.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Largest cell side in lattice steps. */
#define GDT_RASTER_MAX_M (INT64_C(1) << 31)

typedef struct gdt_raster_grid {
    gdt_lattice lattice; /* of the cloud */
    int64_t mx, my;      /* cell size in lattice steps, 1..GDT_RASTER_MAX_M */
    int64_t x0;          /* lattice x of the west edge of column 0 */
    int64_t y0;          /* lattice y of the north edge of row 0 */
    gdt_dem_geo geo;     /* ncols, nrows; CRS corner; res_x = res_y = R */
    double inv_dx, inv_dy; /* 1 / (2 mx), 1 / (2 my): estimates for cell indices */
    uint64_t mag_dx, mag_dy; /* floor((2^64 - 1) / d) + 1 for d = 2 mx, 2 my: exact
                              * quotients of 32-bit numerators; 0 = not set */
    int64_t x1;          /* lattice x of the east edge of the last column */
    int64_t y1;          /* lattice y of the south edge of the last row */
    int fast;            /* the grid spans under 2^32 doubled steps each way: with
                          * mag_dx, mag_dy set, faces inside it take exact
                          * multiply-high cell bounds; 0 = the general path
                          * always (the same cells, values and runs) */
} gdt_raster_grid;

/* A TIN vertex: global lattice integers (|x|, |y| < 2^53, as gdt_point)
 * and its z. */
typedef struct gdt_raster_vertex {
    int64_t x, y;
    double z;
} gdt_raster_vertex;

/* Where rasterised cells go: cells (row, col .. col + n - 1) get
 * z[0 .. n).  Returning anything but GDT_OK stops the rasterisation. */
typedef gdt_status (*gdt_raster_sink)(void *ctx, int64_t row, int64_t col, int64_t n,
                                      const float *z, gdt_error *err);

/* The common unit of the two lattice steps: the smallest ux, uy >= 1
 * (ux <= 10^4) with ux sx = uy sy to 1e-12 relative (decimal steps such
 * as 0.01 and 0.001 or 0.025 have one; irrational ratios are refused); ux = uy = 1 when
 * sx == sy.  returns 0 when there is none (then a square grid cannot lie
 * on the lattice), 1 otherwise. */
int gdt_raster_unit(const gdt_lattice *lat, int64_t *ux, int64_t *uy);

/* The default cell size: twice the mean point spacing sqrt(W H / n) of
 * the bounding box W x H (CRS units) of the n points (max(W, H) / (n - 1)
 * when the box is flat), rounded to the nearest multiple (at least one) of
 * the common unit; 0 when there is no common unit. */
double gdt_raster_default_res(const gdt_lattice *lat, int64_t min_x, int64_t min_y,
                              int64_t max_x, int64_t max_y, uint64_t npoints);

/* Defines the grid of cell size res (CRS units; 0: gdt_raster_default_res)
 * over the lattice bounding box [min_x, max_x] x [min_y, max_y] of the
 * cloud.  res must be a multiple of both lattice steps to 1e-9 relative
 * (refused otherwise, not rounded: the message names the nearest multiples).
 * opt names the option in messages ("--dem-res").
 * returns: GDT_OK; GDT_EUSAGE 2601 (res not a lattice multiple), 2602 (no
 *   common multiple of sx and sy), 2603 (the raster would exceed
 *   GDT_DEM_MAX_SIDE or GDT_DEM_MAX_CELLS, or a cell GDT_RASTER_MAX_M). */
gdt_status gdt_raster_grid_define(gdt_raster_grid *g, const gdt_lattice *lat, int64_t min_x,
                                  int64_t min_y, int64_t max_x, int64_t max_y,
                                  uint64_t npoints, double res, const char *opt,
                                  gdt_error *err);

/* The doubled lattice coordinates of the centre of cell (row, col). */
gdt_hpt gdt_raster_centre(const gdt_raster_grid *g, int64_t row, int64_t col);

/* Rasterises one triangle (either orientation; a degenerate one owns no
 * centre): every centre it owns, by the rule above, goes to sink as runs
 * along rows, rows from north to south, columns west to east.  st (may be
 * NULL) counts the predicate calls.
 * returns: GDT_OK; the sink's error; GDT_EINTERNAL 7660 (a vertex outside
 *   |x|, |y| < 2^53). */
gdt_status gdt_raster_triangle(const gdt_raster_grid *g, gdt_pred_stats *st,
                               const gdt_raster_vertex v[3], gdt_raster_sink sink, void *ctx,
                               gdt_error *err);

/* gdt_raster_triangle for the faces tri[3f .. 3f+2] (f < nfaces) indexing
 * pts[0 .. npts) (global lattice integers and z, as the cloud gives them).
 * returns: as gdt_raster_triangle; GDT_EINTERNAL 7663 (an index out of
 *   range). */
gdt_status gdt_raster_faces(const gdt_raster_grid *g, gdt_pred_stats *st, const gdt_point *pts,
                            size_t npts, const int32_t *tri, size_t nfaces, gdt_raster_sink sink,
                            void *ctx, gdt_error *err);

#ifdef __cplusplus
}
#endif
#endif
