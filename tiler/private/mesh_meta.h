/* mesh_meta.h — the metadata every mode gives the mesh writer
 * (gdt_mesh_out.h), so that the tiled run, --single-tile and --reference
 * write the same header bytes for the same inputs and options. */
#ifndef GDT_TILER_MESH_META_H
#define GDT_TILER_MESH_META_H

#include <stddef.h>

#include "gdt_cloud.h"
#include "gdt_mesh_out.h"
#include "gdt_trim.h"

/* Fills *out: the cloud's lattice and CRS; the comments: the filter line
 * (written into filter_buf, cap >= GDT_FILTER_COMMENT_MAX), then with a
 * trimming rule on the trim line (into trim_buf, trim_cap >=
 * GDT_TRIM_TEXT_MAX; trim may be NULL); slot is the two-element array
 * out->comments points at; the LandXML stamp, the newest modification
 * time of the inputs (a function of the inputs, not of the time of the
 * run; 0 when none can be read); log for warnings.  The buffers, slot and
 * the cloud must outlive the writer. */
void gdt_run_mesh_meta(const gdt_cloud *cloud, gdt_log *log, const gdt_trim_rule *trim,
                       char *filter_buf, size_t cap, char *trim_buf, size_t trim_cap,
                       const char **slot, gdt_mesh_meta *out);

#endif
