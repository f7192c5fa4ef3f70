/* The mesh writer's metadata of a run (private/mesh_meta.h). */
#include "private/mesh_meta.h"
#include "private/filter_report.h"
#include "private/trim_report.h"

#include <string.h>
#include <sys/stat.h>

void gdt_run_mesh_meta(const gdt_cloud *cloud, gdt_log *log, const gdt_trim_rule *trim,
                       char *filter_buf, size_t cap, char *trim_buf, size_t trim_cap,
                       const char **slot, gdt_mesh_meta *out)
{
    const gdt_cloud_info *ci = gdt_cloud_get_info(cloud);
    memset(out, 0, sizeof *out);
    out->lattice = ci->lattice;
    out->epsg = ci->epsg;
    out->crs_wkt = ci->crs_wkt;
    gdt_filter_report_comment(cloud, filter_buf, cap);
    slot[0] = filter_buf;
    out->comments = slot;
    out->ncomments = 1;
    gdt_trim_report_comment(trim, trim_buf, trim_cap);
    if (trim_buf[0] != '\0')
        slot[out->ncomments++] = trim_buf;
    out->log = log;
    for (size_t i = 0; i < ci->ninputs; i++) {
        struct stat sb;
        if (stat(gdt_cloud_input_path(cloud, i), &sb) == 0 && (int64_t)sb.st_mtime > out->stamp)
            out->stamp = (int64_t)sb.st_mtime;
    }
}
