/* gdt-tile INPUT... --info: what a surveyor wants to know about the inputs
 * before a run — format, version, point counts, bounds, CRS, the exact
 * lattice and how many points share an (x, y) lattice position.
 *
 * Headers are printed as read; then one streaming pass over all points
 * (bounded buffers; duplicates counted out of core within the memory budget)
 * gives the true counts and the lattice bounds.  The same pass gives each LAS
 * input's attribute census (classes, returns, flags of every record) and the
 * filter's counts; the cloud's counts, bounds and duplicates are those of the
 * points the filter keeps. */
#include "private/cli_modes.h"
#include "private/filter_report.h"
#include "private/json_out.h"

#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_cloud.h"
#include "gdt_dupcount.h"
#include "gdt_filter.h"
#include "gdt_tiler.h"

#define INFO_CHUNK 65536

typedef struct info_stats {
    uint64_t points;
    int64_t min_x, max_x, min_y, max_y;
    double min_z, max_z;
    gdt_dupcount_result dups;
} info_stats;

static void print_source(FILE *out, size_t i, const char *path, const gdt_source_info *s)
{
    fprintf(out, "input %zu: %s\n", i + 1, path);
    fprintf(out, "  format       : %s %s, %s", s->format_name, s->version, s->encoding);
    if (s->format == GDT_FORMAT_LAS)
        fprintf(out, " (%u bytes/record, %u extra bytes)", s->record_length, s->extra_bytes);
    fputc('\n', out);
    if (s->compressed) {
        fprintf(out, "  compression  : LASzip %s: %s\n", s->compressor, s->laz_items);
        if (s->laz_chunks == 0)
            fprintf(out, "  chunks       : no chunk table (read in order)");
        else
            fprintf(out, "  chunks       : %" PRIu64, s->laz_chunks);
        if (s->laz_chunk_size != 0)
            fprintf(out, ", %" PRIu32 " points each\n", s->laz_chunk_size);
        else
            fprintf(out, ", of variable size\n");
    }
    fprintf(out, "  points       : %" PRIu64 "\n", s->point_count);
    if (s->has_bounds)
        fprintf(out, "  bounds       : x [%.17g, %.17g]  y [%.17g, %.17g]  z [%.17g, %.17g]\n",
                s->min[0], s->max[0], s->min[1], s->max[1], s->min[2], s->max[2]);
    if (s->has_lattice)
        fprintf(out, "  scale        : %.17g %.17g %.17g\n  offset       : %.17g %.17g %.17g\n",
                s->scale[0], s->scale[1], s->scale[2], s->offset[0], s->offset[1], s->offset[2]);
    if (s->format == GDT_FORMAT_LAS)
        fprintf(out, "  VLRs / EVLRs : %u / %u\n", s->vlr_count, s->evlr_count);
    if (s->format == GDT_FORMAT_PCD && s->xy_is_float32)
        fprintf(out, "  precision    : x/y stored as 32-bit floats\n");
    fprintf(out, "  CRS          : %s\n", s->crs_desc != NULL && s->crs_desc[0] ? s->crs_desc
                                                                                : "unknown");
}

static gdt_status scan_points(gdt_cloud *cloud, const gdt_options *opts, info_stats *st_out,
                              gdt_log *log, gdt_error *err)
{
    gdt_point *buf = NULL;
    gdt_dupcount *dc = NULL;
    gdt_dupcount_opts dco;
    gdt_status st;
    info_stats s = {0};

    memset(&s, 0, sizeof s);
    s.min_x = s.min_y = INT64_MAX;
    s.max_x = s.max_y = INT64_MIN;
    memset(&dco, 0, sizeof dco);
    dco.log = log;
    /* --info keeps below ~100 MB whatever the input size: a 64 MiB budget
     * for the duplicate counter unless the user asks for another. */
    dco.mem_budget = opts->mem_budget != 0 ? (size_t)opts->mem_budget : GDT_DUPCOUNT_DEFAULT_BUDGET;
    dco.temp_dir = NULL;
    st = gdt_dupcount_create(&dc, &dco, err);
    if (st != GDT_OK)
        goto fail;
    buf = malloc(INFO_CHUNK * sizeof *buf);
    if (buf == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    for (;;) {
        size_t n = 0;
        st = gdt_cloud_read(cloud, buf, INFO_CHUNK, &n, err);
        if (st != GDT_OK)
            goto fail;
        if (n == 0)
            break;
        for (size_t k = 0; k < n; k++) {
            const gdt_point *p = &buf[k];
            if (s.points == 0 && k == 0)
                s.min_z = s.max_z = p->z;
            if (p->x < s.min_x) s.min_x = p->x;
            if (p->x > s.max_x) s.max_x = p->x;
            if (p->y < s.min_y) s.min_y = p->y;
            if (p->y > s.max_y) s.max_y = p->y;
            if (p->z < s.min_z) s.min_z = p->z;
            if (p->z > s.max_z) s.max_z = p->z;
        }
        s.points += n;
        st = gdt_dupcount_add(dc, buf, n, err);
        if (st != GDT_OK)
            goto fail;
    }
    st = gdt_dupcount_finish(dc, &s.dups, err);
    if (st != GDT_OK)
        goto fail;
    *st_out = s;
fail:
    free(buf);
    gdt_dupcount_destroy(dc);
    return st;
}

/* "label v: n, v: n" for the nonzero n of h[0..16). */
static void print_hist(FILE *out, const char *label, const uint64_t h[16])
{
    const char *sep = " ";
    fputs(label, out);
    for (unsigned v = 0; v < 16; v++)
        if (h[v] != 0) {
            fprintf(out, "%s%u: %" PRIu64, sep, v, h[v]);
            sep = ", ";
        }
    fputc('\n', out);
}

/* The attributes of input i's records (LAS only) and what the filter kept. */
static void print_census(FILE *out, const gdt_cloud *cloud, size_t i)
{
    const gdt_las_census *c = gdt_cloud_input_census(cloud, i);
    const gdt_filter_counts *k = gdt_cloud_input_counts(cloud, i);
    const gdt_point_filter *f = gdt_cloud_filter(cloud);
    char ftext[160];

    fprintf(out, "attributes of input %zu: %s\n", i + 1, gdt_cloud_input_path(cloud, i));
    if (c != NULL && gdt_cloud_input_info(cloud, i)->format == GDT_FORMAT_LAS) {
        fprintf(out, "  records      : %" PRIu64 "\n", c->records);
        for (unsigned k2 = 0; k2 < 256; k2++)
            if (c->cls[k2] != 0)
                fprintf(out, "  class %-3u    : %" PRIu64 " (%s)\n", k2, c->cls[k2],
                        gdt_asprs_class_name(k2));
        print_hist(out, "  return no.   :", c->ret);
        print_hist(out, "  returns/pulse:", c->nret);
        fprintf(out, "  flags        : withheld %" PRIu64 ", synthetic %" PRIu64
                     ", key point %" PRIu64 ", overlap %" PRIu64 "\n",
                c->withheld, c->synthetic, c->keypoint, c->overlap);
    } else {
        fprintf(out, "  records      : %" PRIu64 " (no LAS attributes)\n", k->read);
    }
    gdt_filter_counts_text(f, k, ftext, sizeof ftext);
    fprintf(out, "  kept         : %" PRIu64 "%s\n", k->kept, ftext);
}

static void print_cloud(FILE *out, const gdt_cloud_info *ci, const info_stats *s)
{
    const gdt_lattice *L = &ci->lattice;
    fprintf(out, "cloud:\n");
    fprintf(out, "  inputs       : %zu\n", ci->ninputs);
    fprintf(out, "  points       : %" PRIu64 "\n", s->points);
    fprintf(out, "  CRS          : %s\n", ci->crs_desc[0] ? ci->crs_desc : "unknown");
    fprintf(out, "  lattice      : %.17g %.17g %.17g %.17g (sx sy ox oy; %s)\n", L->sx, L->sy,
            L->ox, L->oy, ci->lattice_native ? "the LAS integer lattice" : "snapped");
    if (s->points > 0) {
        fprintf(out, "  lattice box  : x [%" PRId64 ", %" PRId64 "]  y [%" PRId64 ", %" PRId64
                     "]  (%" PRId64 " x %" PRId64 " steps)\n",
                s->min_x, s->max_x, s->min_y, s->max_y, s->max_x - s->min_x,
                s->max_y - s->min_y);
        fprintf(out, "  bounds       : x [%.17g, %.17g]  y [%.17g, %.17g]  z [%.17g, %.17g]\n",
                L->ox + L->sx * (double)s->min_x, L->ox + L->sx * (double)s->max_x,
                L->oy + L->sy * (double)s->min_y, L->oy + L->sy * (double)s->max_y, s->min_z,
                s->max_z);
    }
    fprintf(out, "  distinct xy  : %" PRIu64 "\n", s->dups.distinct);
    fprintf(out, "  duplicates   : %" PRIu64 " (points sharing an (x, y) with an earlier one; "
                 "largest group %" PRIu64 ")\n",
            s->dups.duplicates, s->dups.max_multiplicity);
}

/* "name": [{"<what>": v, "points": n}, ...] for the nonzero n of h[0..16). */
static void hist_json(gdt_json *j, const char *name, const char *what, const uint64_t h[16])
{
    gdt_json_begin_array(j, name);
    for (unsigned v = 0; v < 16; v++)
        if (h[v] != 0) {
            gdt_json_begin_object(j, NULL);
            gdt_json_uint(j, what, v);
            gdt_json_uint(j, "points", h[v]);
            gdt_json_end_object(j);
        }
    gdt_json_end_array(j);
}

/* The members "records", "classes", "return_numbers", "numbers_of_returns"
 * and "flags" of a LAS input's object. */
static void census_json(gdt_json *j, const gdt_las_census *c, const gdt_source_info *si)
{
    if (c == NULL || si->format != GDT_FORMAT_LAS)
        return;
    gdt_json_uint(j, "records", c->records);
    gdt_json_begin_array(j, "classes");
    for (unsigned k = 0; k < 256; k++)
        if (c->cls[k] != 0) {
            gdt_json_begin_object(j, NULL);
            gdt_json_uint(j, "class", k);
            gdt_json_string(j, "name", gdt_asprs_class_name(k));
            gdt_json_uint(j, "points", c->cls[k]);
            gdt_json_end_object(j);
        }
    gdt_json_end_array(j);
    hist_json(j, "return_numbers", "return", c->ret);
    hist_json(j, "numbers_of_returns", "returns", c->nret);
    gdt_json_begin_object(j, "flags");
    gdt_json_uint(j, "withheld", c->withheld);
    gdt_json_uint(j, "synthetic", c->synthetic);
    gdt_json_uint(j, "key_point", c->keypoint);
    gdt_json_uint(j, "overlap", c->overlap);
    gdt_json_end_object(j);
}

static gdt_status write_json(const char *path, gdt_cloud *cloud, const info_stats *s,
                             const gdt_tile_plan *plan, gdt_error *err)
{
    const gdt_cloud_info *ci = gdt_cloud_get_info(cloud);
    gdt_json j;
    gdt_status st = gdt_json_open(&j, path, err);
    if (st != GDT_OK)
        return st;
    gdt_json_begin_object(&j, NULL);
    gdt_json_begin_array(&j, "inputs");
    for (size_t i = 0; i < ci->ninputs; i++) {
        const gdt_source_info *si = gdt_cloud_input_info(cloud, i);
        gdt_json_begin_object(&j, NULL);
        gdt_json_string(&j, "path", gdt_cloud_input_path(cloud, i));
        gdt_json_string(&j, "format", si->format_name);
        gdt_json_string(&j, "version", si->version);
        gdt_json_string(&j, "encoding", si->encoding);
        if (si->compressed) {
            gdt_json_begin_object(&j, "compression");
            gdt_json_string(&j, "compressor", si->compressor);
            gdt_json_string(&j, "items", si->laz_items);
            gdt_json_uint(&j, "chunk_size", si->laz_chunk_size);
            gdt_json_uint(&j, "chunks", si->laz_chunks);
            gdt_json_end_object(&j);
        }
        gdt_json_uint(&j, "points", si->point_count);
        gdt_json_string(&j, "crs", si->crs_desc != NULL ? si->crs_desc : "");
        gdt_json_int(&j, "epsg", si->epsg);
        census_json(&j, gdt_cloud_input_census(cloud, i), si);
        gdt_json_end_object(&j);
    }
    gdt_json_end_array(&j);
    gdt_filter_report_json(&j, cloud);
    gdt_json_uint(&j, "points", s->points);
    gdt_json_uint(&j, "distinct_xy", s->dups.distinct);
    gdt_json_uint(&j, "duplicates", s->dups.duplicates);
    gdt_json_uint(&j, "largest_duplicate_group", s->dups.max_multiplicity);
    gdt_json_string(&j, "crs", ci->crs_desc);
    gdt_json_int(&j, "epsg", ci->epsg);
    gdt_json_begin_array(&j, "lattice");
    gdt_json_double(&j, NULL, ci->lattice.sx);
    gdt_json_double(&j, NULL, ci->lattice.sy);
    gdt_json_double(&j, NULL, ci->lattice.ox);
    gdt_json_double(&j, NULL, ci->lattice.oy);
    gdt_json_end_array(&j);
    if (s->points > 0) {
        gdt_json_begin_array(&j, "lattice_box");
        gdt_json_int(&j, NULL, s->min_x);
        gdt_json_int(&j, NULL, s->min_y);
        gdt_json_int(&j, NULL, s->max_x);
        gdt_json_int(&j, NULL, s->max_y);
        gdt_json_end_array(&j);
        gdt_json_begin_array(&j, "z_range");
        gdt_json_double(&j, NULL, s->min_z);
        gdt_json_double(&j, NULL, s->max_z);
        gdt_json_end_array(&j);
    }
    if (plan != NULL) {
        gdt_json_begin_object(&j, "tile_plan");
        gdt_json_int(&j, "tile", plan->tile);
        gdt_json_int(&j, "cell_steps", plan->cell);
        gdt_json_bool(&j, "cell_auto", plan->cell_auto);
        gdt_json_int(&j, "halo_texels", plan->halo);
        gdt_json_bool(&j, "halo_auto", plan->halo_auto);
        gdt_json_int(&j, "tiles_x", plan->nx);
        gdt_json_int(&j, "tiles_y", plan->ny);
        gdt_json_uint(&j, "tiles", plan->tiles);
        gdt_json_uint(&j, "empty_tiles", plan->empty_tiles);
        gdt_json_uint(&j, "min_points", plan->min_points);
        gdt_json_uint(&j, "median_points", plan->median_points);
        gdt_json_uint(&j, "max_points", plan->max_points);
        gdt_json_uint(&j, "mem_budget", plan->mem_budget);
        gdt_json_end_object(&j);
    }
    gdt_json_end_object(&j);
    return gdt_json_close(&j, err);
}

gdt_status gdt_cli_info(const gdt_options *opts, gdt_error *err)
{
    gdt_cloud *cloud = NULL;
    gdt_cloud_opts co;
    gdt_log log;
    info_stats s = {0};
    gdt_tile_plan plan;
    int have_plan = 0;
    gdt_status st;

    memset(&plan, 0, sizeof plan);
    gdt_log_init(&log, opts->verbosity);
    memset(&co, 0, sizeof co);
    co.log = &log;
    co.quantum = opts->quantum;
    co.filter = &opts->filter;
    co.census = 1;
    co.threads = gdt_cli_threads(opts->threads);
    st = gdt_cloud_open(&cloud, opts->inputs, opts->ninputs, &co, err);
    if (st != GDT_OK)
        goto fail;
    {
        const gdt_cloud_info *ci = gdt_cloud_get_info(cloud);
        for (size_t i = 0; i < ci->ninputs; i++)
            print_source(stdout, i, gdt_cloud_input_path(cloud, i),
                         gdt_cloud_input_info(cloud, i));
    }
    fflush(stdout);
    st = gdt_cli_check_stop(opts, "the reading", err);
    if (st == GDT_OK)
        st = scan_points(cloud, opts, &s, &log, err);
    if (st == GDT_OK)
        st = gdt_cli_check_stop(opts, "the reading", err);
    if (st != GDT_OK)
        goto fail;
    for (size_t i = 0; i < gdt_cloud_get_info(cloud)->ninputs; i++)
        print_census(stdout, cloud, i);
    print_cloud(stdout, gdt_cloud_get_info(cloud), &s);
    /* The tile plan (pass 1 of the tiler) when a tiling option is given. */
    if (opts->tile_set || opts->cell > 0 || opts->halo >= 0) {
        gdt_tiler_opts to;
        memset(&to, 0, sizeof to);
        to.tile = opts->tile;
        to.cell = opts->cell;
        to.halo = opts->halo;
        to.mem_budget = opts->mem_budget;
        to.dup = opts->dup;
        to.log = &log;
        fflush(stdout);
        st = gdt_cloud_rewind(cloud, err);
        if (st == GDT_OK)
            st = gdt_tiler_plan(&to, cloud, &plan, err);
        if (st != GDT_OK)
            goto fail;
        gdt_tile_plan_print(stdout, &plan);
        have_plan = 1;
    }
    if (opts->json != NULL) {
        st = write_json(opts->json, cloud, &s, have_plan ? &plan : NULL, err);
        if (st != GDT_OK)
            goto fail;
    }
    if (fflush(stdout) != 0)
        st = gdt_error_set(err, GDT_EIO, 4001, "cannot write to standard output");
fail:
    gdt_cloud_close(cloud);
    return st;
}
