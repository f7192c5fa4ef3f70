/* mesh_meta.h — the metadata every mode gives the mesh writer
 * (gdt_mesh_out.h), so that the tiled run, --single-tile and --reference
 * write the same header bytes for the same inputs and options. */
#ifndef GDT_TILER_MESH_META_H
#define GDT_TILER_MESH_META_H

#include <stddef.h>

#include "gdt_cloud.h"
#include "gdt_mesh_out.h"

/* Fills *out: the cloud's lattice and CRS; one comment, the filter line
 * (written into filter_buf, cap >= GDT_FILTER_COMMENT_MAX; *slot is the
 * one-element array out->comments points at); the LandXML stamp, the
 * newest modification time of the inputs (a function of the inputs, not
 * of the time of the run; 0 when none can be read); log for warnings.
 * filter_buf, slot and the cloud must outlive the writer. */
void gdt_run_mesh_meta(const gdt_cloud *cloud, gdt_log *log, char *filter_buf, size_t cap,
                       const char **slot, gdt_mesh_meta *out);

#endif
