/* gdt_ground.h — ground classification of a cloud by PCL's approximate
 * progressive morphological filter (Zhang et al. 2003;
 * pcl::ApproximateProgressiveMorphologicalFilter), on the lattice, so that
 * a tile with a halo gets exactly the classes a whole-cloud run gives.
 *
 * The filter (as PCL implements it):
 *  - A grid of square cells of side `cell`; A(c) = the lowest z of the
 *    points in cell c (empty cells are undefined and skipped).
 *  - Windows w_i = 2 h_i + 1 cells, h_i = 2^i (exponential) or 2 (i + 1)
 *    (linear), i = 0, 1, ... while the previous window is below the
 *    maximum window (in cells); so the last window may exceed it.
 *  - Round i: Z = the minimum of A over the w_i x w_i window of each cell
 *    (erosion), Zf = the maximum of Z over the same window (dilation); a
 *    point still ground stays ground iff z - Zf(cell) < t_i, where
 *    t_0 = initial_distance, t_i = slope * (w_i - w_{i-1}) * cell +
 *    initial_distance, both capped at max_distance; then A = Zf.
 * So the class of a point depends only on the points in the cells within
 * D = sum of 2 h_i cells of its own (Chebyshev distance on the grid):
 * erosion and dilation each reach h_i cells, and a round reads only the
 * previous round's grid.  A region that holds every point of those cells
 * classifies the point exactly as the whole cloud does.
 *
 * Exactness across tilings.  The grid is one global grid on the lattice:
 * the cell of lattice point (x, y) is (floor(x * sx / cell), floor(y * sy /
 * cell)) evaluated in double, a function of the point alone (and monotone
 * in x and y).  PCL receives each point as the centre of its cell in cell
 * units relative to the smallest cell of the call (integers + 1/2, exact in
 * float), with cell size 1 and the slope scaled by the cell, and z as the
 * float nearest to z - z0 for one z0 of the whole run; PCL's own grid is
 * then the global grid shifted by whole cells, whatever points a call
 * holds.  Every float PCL compares is a function of one point, so a tile's
 * call and a whole-cloud call decide every point the region covers alike.
 *
 * Not thread-safe per call; calls on different data may run concurrently
 * (the filter runs on one thread: PCL's parallel loop that builds A writes
 * cells from several threads at once).
 *
 * Message numbers: 2701 bad parameter (the message names the option),
 * 2702 a region's grid too large (cells or memory), 7001 out of memory,
 * 7701 PCL failure.
 */
#ifndef GDT_GROUND_H
#define GDT_GROUND_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_cloud.h"
#include "gdt_error.h"

#ifdef __cplusplus
extern "C" {
#endif

#define GDT_PMF_MAX_ROUNDS 24

/* The filter's parameters, with PDAL's filters.pmf names and defaults
 * (CRS units). */
typedef struct gdt_pmf_params {
    double max_window;       /* --pmf-max-window 33 */
    double slope;            /* --pmf-slope 1.0 */
    double initial_distance; /* --pmf-initial-distance 0.15 */
    double max_distance;     /* --pmf-max-distance 2.5 */
    double cell;             /* --pmf-cell 1.0 */
    int exponential;         /* --pmf-exponential true */
} gdt_pmf_params;

void gdt_pmf_defaults(gdt_pmf_params *p);

/* "ground pmf max-window 33 slope 1 ..." (the PLY header's comment line),
 * into buf of cap bytes (truncated to fit). */
void gdt_pmf_describe(const gdt_pmf_params *p, char *buf, size_t cap);

/* Refuses a parameter that is not finite, a window or cell that is not
 * positive, a negative slope or distance, a maximum window under one cell.
 * returns: GDT_EUSAGE 2701 naming the option. */
gdt_status gdt_pmf_check(const gdt_pmf_params *p, gdt_error *err);

/* The filter on one lattice: its rounds and its reach. */
typedef struct gdt_pmf {
    gdt_pmf_params p;
    double fx, fy;           /* sx / cell, sy / cell */
    double z0;               /* z is given to PCL as (float)(z - z0) */
    int rounds;
    int half[GDT_PMF_MAX_ROUNDS];  /* h_i, cells */
    int64_t reach_cells;     /* D */
    int64_t reach;           /* lattice steps: every point in a cell within D
                                cells of point p's lies within reach of p
                                (in x and in y) */
    int max_window_cells;    /* what PCL is given */
    float pcl_slope;         /* slope * cell, PCL's slope for cells of size 1 */
} gdt_pmf;

/* Sets the filter up for lattice lat with z origin z0 (one value for the
 * whole run, e.g. pass 1's lowest z).  returns: GDT_EUSAGE 2701 (as
 * gdt_pmf_check; or a reach beyond 2^40 lattice steps). */
gdt_status gdt_pmf_init(gdt_pmf *f, const gdt_pmf_params *p, const gdt_lattice *lat, double z0,
                        gdt_error *err);

/* The cell column and row of lattice point (x, y). */
int64_t gdt_pmf_cell_x(const gdt_pmf *f, int64_t x);
int64_t gdt_pmf_cell_y(const gdt_pmf *f, int64_t y);

/* An inclusive box of lattice points: [x0, x1] x [y0, y1]. */
typedef struct gdt_pmf_box {
    int64_t x0, x1, y0, y1;
} gdt_pmf_box;

/* Classifies pts[0, n) and more[0, nmore) (NULL when nmore is 0) as one
 * set of points, point i of it being pts[i] for i < n, else more[i - n]:
 * ground[i] = 1 (ground) or 0, for i < n + nmore.  cloud is the lattice
 * bounding box of the whole cloud (PCL's grid of a whole-cloud run is the
 * box of its cells: cells inside it exist, and erosion and dilation fill
 * the empty ones, which later rounds read); roi is the region whose classes
 * matter.  The class of point i is that of a whole-cloud call when it lies
 * in roi and the points hold every point of the cloud within f->reach of
 * roi (in x and y).  The call's grid is made to cover every cell of the
 * cloud's box within D cells of roi's cells (points with z NaN at two
 * corners widen PCL's box: such a point never changes a cell's lowest z,
 * and is never ground).  max_bytes bounds the filter's memory (grids and
 * PCL's copies; 0: no bound).
 * returns: GDT_EUSAGE 2702 (the grid spans more than 2^22 cells a side, or
 *   needs more than max_bytes), GDT_EINTERNAL 7001, 7701. */
gdt_status gdt_pmf_classify(const gdt_pmf *f, const gdt_point *pts, size_t n,
                            const gdt_point *more, size_t nmore, const gdt_pmf_box *cloud,
                            const gdt_pmf_box *roi, uint8_t *ground, uint64_t max_bytes,
                            gdt_error *err);

/* Bytes gdt_pmf_classify holds per point (PCL's cloud and its copy per
 * round, the index lists; not the caller's points) and per grid cell. */
#define GDT_PMF_BYTES_PER_POINT 40
#define GDT_PMF_BYTES_PER_CELL 12

#ifdef __cplusplus
}
#endif
#endif
