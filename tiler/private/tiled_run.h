/* tiled_run.h — gdt-tile INPUT... --tile N -o OUT.ply: the tiled pipeline.
 *
 * The stages are functions on one context (private/stages.h: what each
 * reads and writes, in which order); gdt_cli_tiled runs them in order over
 * every tile in this process.
 *
 * Stages, all in the job directory (--job, default OUT.ply.gdt-job):
 *   1. the tiler (gdt_tiler.h): pass 1 (index.vdb), pass 2 (the .pts and
 *      .edge tile files, duplicates merged by --dup);
 *   2. per tile, in tile order: the OpenCL core triangulates the tile's own
 *      points, the halo is loaded beside them, gdt_certify.h marks the final
 *      triangles, and tiles/tile_<i>_<j>.tri receives the certified faces and
 *      the tile's seam (gdt_seam.h);
 *   3. the seam merge by rows of tiles (gdt_merger_round, gdt_seam.h), on a
 *      thread of its own beside stage 2, each row as soon as its tiles have
 *      their files: the seams of one row are read back from its .tri files, and each round's
 *      final faces are appended to merge.faces in the job directory
 *      ("GDTMRG01", u64 face count, then 3 x u32 output indices per face;
 *      written under a temporary name, fsync'd, renamed; a resumed run
 *      redoes the merge).  Memory: one row of seams and the merger's band,
 *      never all seams;
 *   4. the mesh (tiled_out.h, written by a thread from the start of stage 2
 *      on): vertices tile by tile (each tile's points by lowest input
 *      ordinal), then every tile's certified faces, then the merge's faces
 *      round by round (each round's sorted).
 * Output bytes depend only on the inputs and the options --tile, --cell,
 * --halo, --dup and --quantum.  The face count is checked against Euler's
 * relation F = 2V - h - 2 before the PLY is completed.
 *
 * .tri layout (little-endian): 64-byte header = "GDTTRI02", u64 vertex base,
 * u64 vertices, u64 certified faces, u64 seam vertices, u64 barrier edges,
 * the job's 128-bit id as two u64 (so another job's file never passes for
 * this job's, even where its faces are the same); faces as 3 x u32 output indices (counter-clockwise, each
 * rotated to its smallest index, sorted); seam vertices as u64 index,
 * i64 x, i64 y (merge frame), f64 z; barrier edges as u64 a, u64 b; with
 * --max-edge or --concavity the trim section (tiled_files.h) ends it. */
#ifndef GDT_TILED_RUN_H
#define GDT_TILED_RUN_H

#include "gdt_cli.h"
#include "gdt_error.h"

/* returns: GDT_OK; the tiler's, core's and merge's errors; GDT_EIO 48xx
 * (job directory and .tri files); GDT_EINTERNAL 7820 (Euler's relation
 * fails: a bug), 73xx (--check). */
gdt_status gdt_cli_tiled(const gdt_options *opts, gdt_error *err);

/* gdt-tile --resume DIR: the tiled run recorded in DIR/job.db (inputs,
 * output and options from the record; verbosity, --json, --device, --check
 * and --keep-job from this command line).
 * returns: as gdt_cli_tiled; GDT_EJOB 6902 (no job in DIR), 6905 (record
 * incomplete). */
gdt_status gdt_cli_resume(const gdt_options *opts, gdt_error *err);

#endif
