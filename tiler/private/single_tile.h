/* single_tile.h — gdt-tile INPUT... --tile N -o OUT.ply when the whole cloud
 * fits one tile: the OpenCL core (gdt_core.h) triangulates it in memory. */
#ifndef GDT_SINGLE_TILE_H
#define GDT_SINGLE_TILE_H

#include "gdt_cli.h"
#include "gdt_error.h"

/* Reads every input (duplicates merged by --dup), triangulates the cloud as
 * one tile of opts->tile x opts->tile texels on the device opts->device,
 * optionally verifies the result exactly (--check), writes the PLY
 * (vertices by the lowest input ordinal of their (x, y), faces in canonical
 * order, so the bytes depend only on the point set and the input order) and
 * the --json summary (device, path taken and why, per-phase times and
 * counts).
 * returns: GDT_OK; GDT_EUSAGE 2109 (the points the filter kept are more
 *   than half the tile's texels); GDT_EINPUT (the readers' errors, 3401 when the cloud
 *   spans more than 2^31-1 lattice steps on an axis, 3602 duplicate points
 *   cannot happen after the merge); GDT_EDEVICE 51xx (OpenCL, with the
 *   error name: exit 5); GDT_EIO; GDT_EINTERNAL (7601 floating-point
 *   self-test, 73xx failed --check, 76xx core consistency, 7001 memory). */
gdt_status gdt_cli_single_tile(const gdt_options *opts, gdt_error *err);

#endif
