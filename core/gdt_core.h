/* gdt_core.h — the per-tile core: the gCD algorithm on OpenCL.
 *
 * gdt_core_triangulate computes T_{d1,d2}, the unique Delaunay
 * triangulation with the preferred-direction tie-break (gdt_predicates.h),
 * of the distinct tile-local points of one tile: exactly what
 * gdt_reference_triangulate gives, as a canonical triangle set.
 *
 * Paths (stats->path says which one ran and why):
 *   gcd     the digital-Voronoi path of Qi, Cao & Tan (gCD):
 *           1. exact digital Voronoi diagram of the grid (Parallel Banding
 *              Algorithm, integer dominance tests, the fixed tie rule of
 *              kernels/gcd_pba.cl) and debris recolouring (Algorithm A.1),
 *              equal to standard flooding.  Points sharing a texel: the
 *              lowest index stays, the others are missing points.  Every
 *              border texel is the site of a "frame" vertex of its own, so
 *              no region reaches the border and the dual is a triangulation
 *              of the frame rectangle (Cao, Edelsbrunner, Tan); points in
 *              border texels are missing points too;
 *           2. dual triangles of the digital Voronoi vertices, the fake
 *              boundary around them (a polygon at infinity, evaluated
 *              symbolically: kernels/gcd_geom.clh), neighbour links from
 *              vertex arrays;
 *           3. points shifted from their texel corners to their true
 *              positions, all at once where every triangle stays positively
 *              oriented, then Algorithm 1 for the rest; bad cases and the
 *              frame vertices deleted in independent rounds (Algorithm 2);
 *           4. missing points inserted in parallel rounds (atomic-min marks);
 *              Phase 2 reserves two triangle slots per missing point, so
 *              an insertion writes its new triangles without a scan; walks
 *              start at the triangle of the owner of the point's texel;
 *           5. Lawson flipping with the exact in-circle and the tie-break.
 *              On CPU devices each work-item flips sequentially inside its
 *              own block of triangle slots (a flip touching another block
 *              is left for later); parallel rounds with symmetric votes and
 *              two-phase flips finish the leftovers, and do all the work on
 *              GPUs.  Triangles touching a fake vertex are dropped at the
 *              end: what remains is T_{d1,d2} of the points.
 *   insert  phases 1-3 replaced by a fan of the fake boundary and every
 *           point inserted by phase 4, flipping after each round (gDel2D
 *           style); phase 5 follows as usual.  Taken only when asked for
 *           (opts.path, or AUTO with opts.missing_limit below the missing
 *           fraction): with the slots and walk hints above the gcd path is
 *           faster even when nearly all points fall into a few texels.
 * Every phase runs as OpenCL kernels; the host only orchestrates, plus two
 * small sequential steps the paper also does on the CPU: the debris
 * recolouring (a priority queue over the few debris texels) and the ring of
 * triangles between the frame and the fake boundary (O(grid side)).
 * Internally the kept points are renumbered in texel order for locality;
 * the output uses the input indices.
 *
 * Threading: a context is not thread-safe; use one per thread.
 */
#ifndef GDT_CORE_H
#define GDT_CORE_H

#include <signal.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include "gdt_error.h"
#include "gdt_mesh.h"
#include "gdt_predicates.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct gdt_core gdt_core;

typedef enum gdt_core_path_choice {
    GDT_CORE_PATH_AUTO = 0, /* gcd unless more than missing_limit would be missing */
    GDT_CORE_PATH_GCD,      /* always the digital-Voronoi path */
    GDT_CORE_PATH_INSERT    /* always the insertion path */
} gdt_core_path_choice;

typedef struct gdt_core_opts {
    const char *device;      /* OpenCL device SPEC (gdt_ocl.h); NULL = first device */
    int local_rank;          /* rank on the node, for the "local" SPECs (0 alone) */
    const char *cache_dir;   /* PoCL kernel cache; NULL = default (gdt_ocl.h) */
    const char *kernel_dir;  /* NULL = built-in */
    gdt_log *log;            /* may be NULL */
    gdt_core_path_choice path;
    int force_no_fp64;       /* test: integer predicates only */
    double missing_limit;    /* AUTO: insertion path above this missing fraction
                                (0 = default 1: never) */
    int full_grid;           /* use grid_n texels per side whatever the point count
                                (default: at most about 4 texels per point
                                of the points' bounding box) */
    int profile;             /* time every kernel (gdt_core_profile_dump) */
    int check_phases;        /* debug: download and verify the triangulation
                                after phases 2, 3 and 4 (GDT_EINTERNAL 7690) */
    int copy_out;            /* test: the result is compacted in device buffers
                                and read back, as on devices with memory of
                                their own (default on a CPU device: the
                                kernels write the caller's mesh directly) */
    int gpu_layout;          /* test: the launch sizes and the phase-1 column
                                layout chosen for a GPU, on any device (the
                                result is the same bytes whatever the layout) */
    /* Cores already made (nshare of them): when the device is one of
     * theirs, this core is a further command queue of that device's
     * context and uses its built kernels (gdt_ocl_create, opts->share). */
    struct gdt_core *const *share;
    size_t nshare;
    /* A signal handler's flag (may be NULL): once nonzero, gdt_core_create
     * builds no further program and fails with GDT_EINTERRUPTED, so a stop
     * during a cold kernel build waits for one program, not all of them. */
    const volatile sig_atomic_t *stop;
} gdt_core_opts;

/* Per-phase figures of one gdt_core_triangulate call (cf. Fig. 11 of the
 * gCD paper).  Times are wall-clock seconds including the device work. */
typedef struct gdt_core_stats {
    char path[16];             /* "gcd" or "insert" */
    char path_reason[160];     /* why that path was taken */
    uint64_t points;           /* n */
    uint32_t grid_w, grid_h;   /* texels used (<= grid_n each) */
    int64_t cell;              /* lattice units per texel */
    double t_upload, t_phase1, t_phase2, t_phase3, t_phase4, t_phase5, t_download, t_total;
    /* phase 1 */
    uint64_t kept;             /* points owning a texel */
    uint64_t missing_phase1;   /* points sharing a texel with a lower index */
    uint64_t debris_texels;    /* texels recoloured by Algorithm A.1 */
    /* phase 2 */
    uint64_t dual_triangles;   /* from digital Voronoi vertices */
    uint64_t hull_triangles;   /* completing the dual to the convex hull */
    uint64_t fake_triangles;   /* between the hull and the fake boundary */
    /* phase 3 */
    uint64_t shift_iterations; /* rounds of Algorithm 1 */
    uint64_t shifted;          /* good cases (points moved in place) */
    uint64_t bad_cases;        /* deleted and re-inserted */
    uint64_t delete_iterations;
    /* phase 4 */
    uint64_t inserted;         /* missing points inserted */
    uint64_t insert_iterations;
    uint64_t walk_steps;       /* point-location steps */
    uint64_t insert_flips;     /* insertion path: flips between rounds */
    /* phase 5 */
    uint64_t flips;
    uint64_t flip_iterations;
    uint64_t edges_tested;     /* in-circle tests evaluated */
    uint64_t exact_escalations; /* tests the double filter left to the integer path */
    uint64_t tiebreaks;        /* co-circular convex quads decided by the tie-break */
    uint64_t triangles;        /* output triangles */
} gdt_core_stats;

/* Creates a core on the selected OpenCL device and builds its kernels.
 * Ownership: *out is allocated here; free it with gdt_core_destroy.
 * Errors: GDT_EDEVICE (5101-5199, with the OpenCL error name),
 * GDT_EINTERNAL 7001. */
gdt_status gdt_core_create(gdt_core **out, const gdt_core_opts *opts, gdt_error *err);

/* Name of the core's device (owned by the core). */
const char *gdt_core_device_name(const gdt_core *core);

/* Triangulates pts[0..n) (distinct, tile-local coordinates in
 * [0, GDT_COORD_MAX]) on a grid of at most grid_n x grid_n texels
 * (grid_n a power of two, 64..16384; unless opts.full_grid, a tile whose
 * points' bounding box has more than about 4 texels per point gets coarser
 * texels, down to 64 texels per side).  On success out holds vertex i =
 * pts[i] (out->ids, if allocated, 0..n-1) and the triangles of T_{d1,d2}
 * with their opposite pointers; fewer than 3 points or all collinear give
 * no triangle.  out must have been initialised (gdt_mesh_init); its content
 * is replaced.  pts may be out->pts itself when out holds room for n
 * vertices (gdt_mesh_reserve): the points then stay where they are, with no
 * copy.  stats may be NULL.
 * Errors: GDT_EINPUT 3601 (bad grid_n, coordinate out of range, too many
 * points), 3602 (duplicate points, naming two input indices);
 * GDT_EDEVICE 51xx; GDT_EINTERNAL 7601-7699 (an internal consistency check
 * failed: a bug), 7001 out of memory. */
gdt_status gdt_core_triangulate(gdt_core *core, const gdt_ipt *pts, size_t n, int grid_n,
                                gdt_mesh *out, gdt_core_stats *stats, gdt_error *err);

/* The most bytes the core's device buffers have held at once since it was
 * created (on a CPU device those that wrap the caller's memory included:
 * a device with memory of its own holds them too). */
uint64_t gdt_core_device_peak(const gdt_core *core);

/* An upper bound of the device memory a core needs for one tile of
 * grid_n x grid_n texels holding points points, in bytes: what
 * gdt_core_device_peak reports on a device with memory of its own (tested
 * with the GPU layout and the result read back, opts.gpu_layout and
 * opts.copy_out), with a margin. */
uint64_t gdt_core_tile_bytes(int grid_n, uint64_t points);

/* The tile side (texels) for a run that does not choose one.  A CPU device
 * gets GDT_CORE_CPU_TILE (there the core's buffers are host memory, and
 * larger tiles only add memory).  Any other device gets the largest power
 * of two of GDT_CORE_CPU_TILE..16384 whose densest tile, N^2/2 points (the
 * planner keeps tiles to about N^2/4), needs at most three quarters of
 * device_mem (gdt_core_tile_bytes), no buffer beyond max_alloc, and, on
 * the host, at most half of host_mem (GDT_CORE_HOST_BYTES_PER_POINT a
 * point: the tile stage's two slots of points, triangles and faces);
 * device_mem, max_alloc and host_mem 0 mean unknown (not a limit). */
#define GDT_CORE_CPU_TILE 4096
#define GDT_CORE_HOST_BYTES_PER_POINT 200u
int gdt_core_auto_tile(int is_cpu, uint64_t device_mem, uint64_t max_alloc, uint64_t host_mem);

/* With opts.profile: the device time of every kernel so far, to f. */
void gdt_core_profile_dump(gdt_core *core, FILE *f);

/* Seconds the core's device has been busy so far (gdt_ocl_busy_seconds;
 * waits for the queue): with several cores on one device (opts.share), the
 * first returns the device's time, counted once, and the others 0; call it
 * on the first while no thread uses the others. */
double gdt_core_device_busy(gdt_core *core);

/* 1 when the core is a further queue of a device an earlier core was made
 * on (opts.share), else 0. */
int gdt_core_shares_device(const gdt_core *core);

/* 1 when both cores run on the same device, else 0. */
int gdt_core_same_device(const gdt_core *a, const gdt_core *b);

/* 1 when the core's device is a CPU device, else 0. */
int gdt_core_on_cpu(const gdt_core *core);

/* CL_DEVICE_GLOBAL_MEM_SIZE of the core's device (0: not reported). */
uint64_t gdt_core_device_memory(const gdt_core *core);

/* Releases the core and every device resource.  core may be NULL. */
void gdt_core_destroy(gdt_core *core);

#ifdef __cplusplus
}
#endif
#endif
