/* memcloud.h — the whole cloud in memory, for the in-memory modes
 * (--reference and --single-tile).  Memory grows with the input (about 40
 * bytes per point here, plus the triangulator's), which is why the tiled
 * pipeline exists; these modes are the oracles it is compared with.
 *
 * Both modes share this file so that their outputs are directly comparable:
 * vertices by the lowest input ordinal of their (x, y), faces in canonical
 * order (each rotated to start at its smallest vertex index, then sorted),
 * so the bytes depend only on the point set and the input order. */
#ifndef GDT_MEMCLOUD_H
#define GDT_MEMCLOUD_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_cli.h"
#include "gdt_cloud.h"
#include "gdt_error.h"
#include "gdt_mesh.h"
#include "gdt_dem.h"
#include "gdt_predicates.h"
#include "gdt_raster.h"
#include "private/json_out.h"

typedef struct gdt_memcloud {
    gdt_cloud *cloud;   /* open; owned */
    gdt_point *pts;     /* the kept points, sorted by ordinal; owned */
    gdt_ipt *local;     /* pts minus (min_x, min_y): predicate coordinates; owned */
    size_t read;        /* points read */
    size_t kept;        /* after the --dup merge */
    int64_t min_x, min_y;
    double t_read;      /* seconds: open, read, merge, sort (and --ground) */
    uint64_t ground, nonground; /* --ground: the classes of the distinct points; pts
                                   then holds the ground points only */
    double t_ground;    /* seconds of the ground filter */
    gdt_log *log;       /* the caller's (warnings of the writer); not owned */
    /* --dem: the grid (gdt_memcloud_load), what was written (gdt_memcloud_finish) */
    gdt_raster_grid dem_grid;
    int dem_done;
    gdt_dem_geo dem_geo;
    gdt_dem_stats dem_stats;
    double t_dem;       /* seconds: rasterise and write the DEM (and preview) */
} gdt_memcloud;

/* Opens the inputs of opts, reads every point, merges duplicates (--dup),
 * sorts by ordinal and computes the local coordinates; with opts->dem it
 * defines the DEM grid (so that a --dem-res the lattice refuses stops the
 * run before any triangulation).  mode names the mode in messages
 * ("--reference").
 * returns: the readers' errors; GDT_EINPUT 3401 (the cloud spans more than
 *   2^31 - 1 lattice steps on an axis); gdt_raster_grid_define's; GDT_EINTERNAL
 *   7001.
 * Ownership: mc is filled (zeroed first); release with gdt_memcloud_free,
 * also after a failure. */
gdt_status gdt_memcloud_load(gdt_memcloud *mc, const gdt_options *opts, gdt_log *log,
                             const char *mode, gdt_error *err);
void gdt_memcloud_free(gdt_memcloud *mc);

/* Writes opts->output in the format of its extension (gdt_mesh_out.h):
 * vertex i = mc->pts[i] (mesh vertex i), faces in canonical order, less
 * those opts->trim drops (gdt_trim_mesh); *tc gets the faces before
 * trimming and the drops.  With kept != NULL, *kept (malloc'd; the caller
 * frees it) and *nkept receive the faces written, 3 vertex indices each.
 * returns: the mesh writer's errors, gdt_trim_mesh's. */
gdt_status gdt_memcloud_write(const gdt_memcloud *mc, const gdt_options *opts,
                              const gdt_mesh *mesh, gdt_trim_counts *tc, int32_t **kept,
                              size_t *nkept, gdt_error *err);

/* With opts->dem: the DEM of the nf faces tri[3 nf] (vertex i = mc->pts[i];
 * the faces the mesh kept) on mc->dem_grid (opts->dem_res over the cloud's
 * bounding box), every face rasterised into the streaming writer (budget
 * opts->mem_budget, scratch files beside the DEM), and the preview;
 * mc->dem_* filled.  returns: the rasteriser's and the writer's errors. */
gdt_status gdt_memcloud_dem(gdt_memcloud *mc, const gdt_options *opts, const int32_t *tri,
                            size_t nf, gdt_pred_stats *pred, gdt_error *err);

/* The summary line of the DEM on stderr (unless -q), when one was written. */
void gdt_memcloud_print_dem(const gdt_memcloud *mc, const gdt_options *opts);

/* With opts->check, verifies mesh exactly (gdt_check_mesh, then
 * gdt_check_delaunay; *t_check, *checked set), then writes it
 * (gdt_memcloud_write; *t_write), then the DEM with opts->dem
 * (gdt_memcloud_dem).  pred accumulates the counters. */
gdt_status gdt_memcloud_finish(gdt_memcloud *mc, const gdt_options *opts,
                               const gdt_mesh *mesh, gdt_pred_stats *pred, double *t_check,
                               double *t_write, int *checked, gdt_trim_counts *tc,
                               gdt_error *err);

/* Opens the --json summary of an in-memory mode and writes its head: mode,
 * output, inputs, points read, vertices, duplicates merged, faces, crs and
 * with --dem a "dem" object (path, res, cols, rows, cells, blocks, spills,
 * seconds),
 * inside the top-level object the caller goes on filling and closes with
 * gdt_json_end_object and gdt_json_close.  returns: gdt_json_open's
 * errors. */
gdt_status gdt_memcloud_json_head(gdt_json *j, const gdt_memcloud *mc, const gdt_options *opts,
                                  const char *mode, uint64_t faces, const gdt_trim_counts *tc,
                                  gdt_error *err);

#endif
