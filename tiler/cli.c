/* Command-line parsing, help text and the top-level dispatch of gdt-tile. */
#include "gdt_cli.h"
#include "gdt_ocl.h"
#include "gdt_predicates.h"
#include "private/cli_modes.h"
#include "private/comm.h"
#include "private/launch.h"
#include "private/outpaths.h"
#include "private/single_tile.h"
#include "private/tiled_run.h"

#include <errno.h>
#include <float.h>
#include <signal.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <unistd.h>

#ifndef GDT_VERSION
#define GDT_VERSION "0.0.0"
#endif

typedef enum opt_id {
    OPT_OUTPUT, OPT_TILE, OPT_CELL, OPT_HALO, OPT_JOB, OPT_RESTART, OPT_RESUME, OPT_DEVICE,
    OPT_THREADS, OPT_MEM, OPT_QUANTUM, OPT_DUP, OPT_CHECK, OPT_JSON, OPT_QUIET, OPT_VERBOSE,
    OPT_INFO, OPT_REFERENCE, OPT_SINGLE, OPT_KEEP_JOB, OPT_HELP, OPT_VERSION,
    OPT_KEEP_CLASS, OPT_DROP_CLASS, OPT_RETURNS, OPT_KEEP_WITHHELD, OPT_MAX_EDGE,
    OPT_CONCAVITY, OPT_DEM, OPT_DEM_RES, OPT_DEM_NODATA, OPT_PREVIEW, OPT_GROUND,
    OPT_PMF_MAX_WINDOW, OPT_PMF_SLOPE, OPT_PMF_INITIAL, OPT_PMF_MAX_DISTANCE, OPT_PMF_CELL,
    OPT_PMF_EXPONENTIAL, OPT_GROUND_OUT, OPT_QUEUES
} opt_id;

/* The option table: every option once, with its argument, default and help. */
typedef struct opt_spec {
    opt_id id;
    const char *lng;   /* "--tile" */
    const char *shrt;  /* "-o" or NULL */
    const char *arg;   /* argument name, NULL for flags */
    const char *dflt;  /* default as shown in --help, NULL if none */
    const char *help;
} opt_spec;

static const opt_spec OPTIONS[] = {
    {OPT_OUTPUT, "--output", "-o", "OUT.ply", "out.ply",
     "output mesh, by its extension (any case): .obj OBJ (+ .prj), .xml LandXML, else PLY"},
    {OPT_TILE, "--tile", NULL, "N", "auto",
     "tile size in texels per side: a power of two, 64..16384 (auto: 4096 on a CPU "
     "device; on a GPU the largest of 4096..16384 its memory holds; 4096 with "
     "--single-tile and --info)"},
    {OPT_CELL, "--cell", NULL, "S", "auto",
     "texel size in CRS units (auto: about N*N/4 points per tile)"},
    {OPT_HALO, "--halo", NULL, "H", "auto", "halo width in texels around each tile (0 is legal)"},
    {OPT_JOB, "--job", NULL, "DIR", "OUT.ply.gdt-job", "job directory (state for resuming)"},
    {OPT_KEEP_JOB, "--keep-job", NULL, NULL, NULL,
     "keep the job directory after a successful run (tile files, index)"},
    {OPT_RESTART, "--restart", NULL, NULL, NULL,
     "discard an existing job directory that does not match and start again"},
    {OPT_RESUME, "--resume", NULL, "DIR", NULL, "resume the job in DIR (needs nothing else)"},
    {OPT_DEVICE, "--device", NULL, "SPEC", "first device",
     "OpenCL device: index, PLATFORM:DEVICE, 'cpu' or 'gpu'; under mpirun 'gpu/local' "
     "(or 'cpu/local', 'local') gives a node's ranks its devices in turn; the tiled run "
     "takes several: a comma-separated list ('0,1') or 'gpu:all' ('cpu:all', 'all')"},
    {OPT_QUEUES, "--queues", NULL, "N", "auto",
     "command queues per device in the tile stage, 1..8: tiles run on N queues of each device "
     "at once (auto: 2 on a GPU whose memory holds two tiles, else 1)"},
    {OPT_THREADS, "--threads", NULL, "K", "all cores", "host worker threads, 1..1024"},
    {OPT_MEM, "--mem-budget", NULL, "SIZE", "auto",
     "memory budget, at least 16M, e.g. 512M or 4G (binary units)"},
    {OPT_QUANTUM, "--quantum", NULL, "Q", "0.001",
     "lattice step for float and projected input, CRS units"},
    {OPT_DUP, "--dup", NULL, "first|min-z|max-z", "first",
     "which z to keep for points with the same (x, y)"},
    {OPT_KEEP_CLASS, "--keep-class", NULL, "LIST", NULL,
     "keep only LAS points of these classes: ASPRS codes 0..255, e.g. 2 or 2,9 or 3-5"},
    {OPT_DROP_CLASS, "--drop-class", NULL, "LIST", NULL,
     "drop LAS points of these classes (not together with --keep-class)"},
    {OPT_RETURNS, "--returns", NULL, "WHICH", "all",
     "LAS returns to keep: all, first (return 1), last (return = number of returns), "
     "single (one-return pulses)"},
    {OPT_KEEP_WITHHELD, "--keep-withheld", NULL, NULL, NULL,
     "keep LAS points flagged withheld (dropped by default: the LAS spec deletes them)"},
    {OPT_GROUND, "--ground", NULL, "pmf", NULL,
     "classify ground with PCL's progressive morphological filter (approximate, on a global "
     "grid, tile by tile with a halo: the classes of a whole-cloud run) and triangulate the "
     "ground points only; replaces LAS classes (not with --keep-class)"},
    {OPT_PMF_MAX_WINDOW, "--pmf-max-window", NULL, "W", "33",
     "--ground pmf: largest window, CRS units (windows of 3, 5, 9, 17, ... cells up to it)"},
    {OPT_PMF_SLOPE, "--pmf-slope", NULL, "S", "1.0",
     "--ground pmf: terrain slope; the height threshold grows by S times the window's growth"},
    {OPT_PMF_INITIAL, "--pmf-initial-distance", NULL, "D", "0.15",
     "--ground pmf: height threshold of the first window, CRS units"},
    {OPT_PMF_MAX_DISTANCE, "--pmf-max-distance", NULL, "D", "2.5",
     "--ground pmf: largest height threshold, CRS units"},
    {OPT_PMF_CELL, "--pmf-cell", NULL, "C", "1.0",
     "--ground pmf: cell size of the filter's grid, CRS units"},
    {OPT_PMF_EXPONENTIAL, "--pmf-exponential", NULL, "true|false", "true",
     "--ground pmf: windows grow exponentially (3, 5, 9, 17, ...) or linearly (5, 9, 13, ...)"},
    {OPT_GROUND_OUT, "--ground-out", NULL, "FILE.las", NULL,
     "with --ground: also write every input record as LAS, class 2 (ground) or 1 (the "
     "filter's points), other records and fields as they were (LAS/LAZ inputs of one "
     "point layout; PCD inputs: one format-0 record per point); under mpirun each rank "
     "writes its share"},
    {OPT_MAX_EDGE, "--max-edge", NULL, "L", NULL,
     "drop every triangle with an edge longer than L (horizontal, CRS units)"},
    {OPT_CONCAVITY, "--concavity", NULL, "L", NULL,
     "drop triangles from the convex hull inwards across edges longer than L, until no "
     "boundary edge is longer (water, voids and the hull's bridges)"},
    {OPT_DEM, "--dem", NULL, "OUT.tif", NULL,
     "also write the TIN as a DEM: a Cloud Optimized GeoTIFF (float32, the input's CRS), "
     "each cell centre linearly interpolated in its triangle (trimmed triangles: nodata)"},
    {OPT_DEM_RES, "--dem-res", NULL, "R", "auto",
     "DEM cell size in CRS units, a whole number of lattice steps (other values are "
     "refused); grid aligned to multiples of R (auto: twice the mean point spacing, "
     "rounded to a lattice multiple)"},
    {OPT_DEM_NODATA, "--dem-nodata", NULL, "V", "-9999",
     "DEM value of cells outside the TIN (a finite float32)"},
    {OPT_PREVIEW, "--preview", NULL, "OUT.png", NULL,
     "with --dem: a shaded-relief PNG of the DEM, at most 2048 pixels on its long side"},
    {OPT_CHECK, "--check", NULL, NULL, NULL,
     "validate the written mesh exactly (a tiled .obj/.xml output: through a PLY copy of the "
     "same records in the job directory; --reference/--single-tile: the mesh in memory); "
     "not with --max-edge or --concavity"},
    {OPT_JSON, "--json", NULL, "FILE", NULL, "write a machine-readable run summary"},
    {OPT_QUIET, "--quiet", "-q", NULL, NULL, "no progress and no warnings on stderr"},
    {OPT_VERBOSE, "--verbose", "-v", NULL, NULL, "more detail (predicate counters, stages)"},
    {OPT_INFO, "--info", NULL, NULL, NULL,
     "describe the inputs (format, counts, bounds, CRS, lattice, duplicates; LAS classes, "
     "returns and flags) and stop; "
     "with --tile/--cell/--halo also the tile plan"},
    {OPT_REFERENCE, "--reference", NULL, NULL, NULL,
     "triangulate in memory with the CPU reference (one tile; for testing)"},
    {OPT_SINGLE, "--single-tile", NULL, NULL, NULL,
     "triangulate the whole cloud as one tile with the OpenCL core, in memory (at most "
     "N*N/2 points; for testing)"},
    {OPT_HELP, "--help", "-h", NULL, NULL, "show this help"},
    {OPT_VERSION, "--version", NULL, NULL, NULL, "show the version"},
};
#define NOPTIONS (sizeof OPTIONS / sizeof OPTIONS[0])

void gdt_cli_print_help(FILE *out)
{
    fprintf(out,
            "gdt-tile %s — exact, seamless Delaunay triangulation (TIN) of huge point clouds\n\n"
            "usage: gdt-tile INPUT [INPUT ...] [-o OUT.ply] [--tile N] [options]\n"
            "       gdt-tile INPUT [INPUT ...] --info\n"
            "       gdt-tile --resume DIR\n\n"
            "INPUT: LAS 1.0-1.4 (point formats 0-10) or PCD (ascii, binary,\n"
            "binary_compressed); several inputs form one cloud.\n"
            "OUT: .ply (binary PLY), .obj (Wavefront OBJ, 1-based CCW faces, and OUT.prj\n"
            "with the CRS as WKT when known), .xml (LandXML 1.2 TIN surface: points as\n"
            "northing easting elevation); written under a temporary name, then renamed.\n"
            "\noptions:\n",
            GDT_VERSION);
    for (size_t i = 0; i < NOPTIONS; i++) {
        const opt_spec *o = &OPTIONS[i];
        char left[64];
        if (o->shrt != NULL)
            snprintf(left, sizeof left, "%s, %s%s%s", o->shrt, o->lng, o->arg ? " " : "",
                     o->arg ? o->arg : "");
        else
            snprintf(left, sizeof left, "    %s%s%s", o->lng, o->arg ? " " : "",
                     o->arg ? o->arg : "");
        fprintf(out, "  %-32s %s", left, o->help);
        if (o->dflt != NULL)
            fprintf(out, " [default: %s]", o->dflt);
        fputc('\n', out);
    }
    fprintf(out,
            "\nexit codes:\n"
            "  0    success\n"
            "  2    usage error (bad option or value; a stage not available in this build;\n"
            "       an output that is an input, a special file or in no writable directory)\n"
            "  3    bad input (unreadable, corrupt or lying file, unknown format; a FIFO,\n"
            "       device or directory: inputs are read twice)\n"
            "  4    I/O error (read/write failure, disk full)\n"
            "  5    OpenCL device error\n"
            "  6    job directory does not match the command (use --restart)\n"
            "  7    internal error or failed validation\n"
            "  130  interrupted (the job stays resumable)\n");
}

/* ---- strict value parsers ------------------------------------------------ */

static gdt_status parse_long(const char *opt, const char *s, long lo, long hi, long *out,
                             gdt_error *err)
{
    char *end = NULL;
    long v;
    errno = 0;
    if (s[0] == '\0' || s[0] == ' ' || s[0] == '+')
        goto bad;
    v = strtol(s, &end, 10);
    if (errno != 0 || end == s || *end != '\0')
        goto bad;
    if (v < lo || v > hi)
        return gdt_error_set(err, GDT_EUSAGE, 2002, "%s %s: out of range (%ld..%ld)", opt, s,
                             lo, hi);
    *out = v;
    return GDT_OK;
bad:
    return gdt_error_set(err, GDT_EUSAGE, 2001, "%s: '%s' is not an integer", opt, s);
}

static gdt_status parse_finite_double(const char *opt, const char *s, double *out,
                                      gdt_error *err)
{
    char *end = NULL;
    double v;
    errno = 0;
    if (s[0] == '\0' || s[0] == ' ')
        goto bad;
    v = strtod(s, &end);
    if (errno != 0 || end == s || *end != '\0' || !isfinite(v))
        goto bad;
    *out = v;
    return GDT_OK;
bad:
    return gdt_error_set(err, GDT_EUSAGE, 2001, "%s: '%s' is not a finite number", opt, s);
}

static gdt_status parse_positive_double(const char *opt, const char *s, double *out,
                                        gdt_error *err)
{
    double v = 0;
    gdt_status st = parse_finite_double(opt, s, &v, err);
    if (st != GDT_OK)
        return st;
    if (!(v > 0.0))
        return gdt_error_set(err, GDT_EUSAGE, 2002, "%s %s: must be positive", opt, s);
    *out = v;
    return GDT_OK;
}

/* Sizes: a number with an optional binary suffix K, M, G or T (optionally
 * followed by "B" or "iB"); a plain number is bytes. */
static gdt_status parse_size(const char *opt, const char *s, uint64_t *out, gdt_error *err)
{
    char *end = NULL;
    double v, mult = 1.0;
    errno = 0;
    if (s[0] < '0' || s[0] > '9')
        goto bad;
    v = strtod(s, &end);
    if (errno != 0 || end == s || !isfinite(v))
        goto bad;
    switch (*end) {
    case 'k': case 'K': mult = 1024.0; end++; break;
    case 'm': case 'M': mult = 1024.0 * 1024.0; end++; break;
    case 'g': case 'G': mult = 1024.0 * 1024.0 * 1024.0; end++; break;
    case 't': case 'T': mult = 1024.0 * 1024.0 * 1024.0 * 1024.0; end++; break;
    default: break;
    }
    if (mult > 1.0 && (strcmp(end, "B") == 0 || strcmp(end, "iB") == 0))
        end += strlen(end);
    else if (mult == 1.0 && strcmp(end, "B") == 0)
        end++;
    if (*end != '\0')
        goto bad;
    v *= mult;
    if (v < 16.0 * 1024.0 * 1024.0 || v > 1.0e18)
        return gdt_error_set(err, GDT_EUSAGE, 2002, "%s %s: out of range (16M..1e18 bytes)",
                             opt, s);
    *out = (uint64_t)v;
    return GDT_OK;
bad:
    return gdt_error_set(err, GDT_EUSAGE, 2001,
                         "%s: '%s' is not a size (examples: 512M, 4G, 1073741824)", opt, s);
}

static const opt_spec *find_option(const char *name, size_t len)
{
    for (size_t i = 0; i < NOPTIONS; i++) {
        const opt_spec *o = &OPTIONS[i];
        if ((strlen(o->lng) == len && strncmp(o->lng, name, len) == 0) ||
            (o->shrt != NULL && strlen(o->shrt) == len && strncmp(o->shrt, name, len) == 0))
            return o;
    }
    return NULL;
}

static gdt_status set_mode(gdt_options *opts, gdt_mode m, const char *name, gdt_error *err)
{
    if (opts->mode != GDT_MODE_RUN && opts->mode != m)
        return gdt_error_set(err, GDT_EUSAGE, 2004, "%s cannot be combined with the other mode "
                             "options (--info, --reference, --resume)", name);
    opts->mode = m;
    return GDT_OK;
}

static gdt_status apply(gdt_options *opts, const opt_spec *o, const char *val, gdt_error *err)
{
    long l;
    gdt_status st = GDT_OK;

    switch (o->id) {
    case OPT_OUTPUT: opts->output = val; break;
    case OPT_TILE:
        st = parse_long(o->lng, val, 64, 16384, &l, err);
        if (st == GDT_OK && (l & (l - 1)) != 0)
            st = gdt_error_set(err, GDT_EUSAGE, 2003, "--tile %s: must be a power of two", val);
        opts->tile = (int)l;
        opts->tile_set = 1;
        break;
    case OPT_CELL: st = parse_positive_double(o->lng, val, &opts->cell, err); break;
    case OPT_HALO:
        st = parse_long(o->lng, val, 0, 1L << 20, &l, err);
        opts->halo = l;
        break;
    case OPT_JOB: opts->job = val; break;
    case OPT_RESTART: opts->restart = 1; break;
    case OPT_RESUME:
        st = set_mode(opts, GDT_MODE_RESUME, o->lng, err);
        opts->resume = val;
        break;
    case OPT_DEVICE:
        if (val[0] == '\0')
            st = gdt_error_set(err, GDT_EUSAGE, 2001, "--device: empty device specification");
        else
            st = gdt_ocl_check_device_spec(val, err);
        opts->device = val;
        break;
    case OPT_THREADS:
        st = parse_long(o->lng, val, 1, 1024, &l, err);
        opts->threads = (int)l;
        break;
    case OPT_QUEUES:
        st = parse_long(o->lng, val, 1, GDT_CLI_MAX_QUEUES, &l, err);
        opts->queues = (int)l;
        break;
    case OPT_MEM: st = parse_size(o->lng, val, &opts->mem_budget, err); break;
    case OPT_QUANTUM:
        st = parse_positive_double(o->lng, val, &opts->quantum, err);
        if (st == GDT_OK && (opts->quantum < 1e-9 || opts->quantum > 1e6))
            st = gdt_error_set(err, GDT_EUSAGE, 2002, "--quantum %s: out of range (1e-9..1e6)",
                               val);
        break;
    case OPT_DUP:
        if (strcmp(val, "first") == 0)
            opts->dup = GDT_DUP_FIRST;
        else if (strcmp(val, "min-z") == 0)
            opts->dup = GDT_DUP_MIN_Z;
        else if (strcmp(val, "max-z") == 0)
            opts->dup = GDT_DUP_MAX_Z;
        else
            st = gdt_error_set(err, GDT_EUSAGE, 2001,
                               "--dup: '%s' is not one of first, min-z, max-z", val);
        break;
    case OPT_DEM: opts->dem = val; break;
    case OPT_DEM_RES:
        st = parse_positive_double(o->lng, val, &opts->dem_res, err);
        opts->dem_res_set = 1;
        break;
    case OPT_DEM_NODATA:
        st = parse_finite_double(o->lng, val, &opts->dem_nodata, err);
        if (st == GDT_OK && (fabs(opts->dem_nodata) > FLT_MAX ||
                             (double)(float)opts->dem_nodata != opts->dem_nodata))
            st = gdt_error_set(err, GDT_EUSAGE, 2604,
                               "--dem-nodata %s: not exactly a float32 value (the DEM's cells "
                               "are float32); the nearest is %.9g",
                               val, fabs(opts->dem_nodata) > FLT_MAX
                                        ? (opts->dem_nodata > 0 ? FLT_MAX : -FLT_MAX)
                                        : (double)(float)opts->dem_nodata);
        opts->dem_nodata_set = 1;
        break;
    case OPT_PREVIEW: opts->preview = val; break;
    case OPT_CHECK: opts->check = 1; break;
    case OPT_JSON: opts->json = val; break;
    case OPT_QUIET: opts->verbosity = -1; break;
    case OPT_VERBOSE: opts->verbosity = opts->verbosity < 1 ? 1 : opts->verbosity + 1; break;
    case OPT_INFO: st = set_mode(opts, GDT_MODE_INFO, o->lng, err); break;
    case OPT_REFERENCE: st = set_mode(opts, GDT_MODE_REFERENCE, o->lng, err); break;
    case OPT_SINGLE: opts->single_tile = 1; break;
    case OPT_KEEP_JOB: opts->keep_job = 1; break;
    case OPT_HELP: opts->mode = GDT_MODE_HELP; break;
    case OPT_VERSION: if (opts->mode != GDT_MODE_HELP) opts->mode = GDT_MODE_VERSION; break;
    case OPT_KEEP_CLASS:
    case OPT_DROP_CLASS:
        st = gdt_filter_parse_classes(&opts->filter, o->id == OPT_KEEP_CLASS ? 1 : -1, o->lng,
                                      val, err);
        break;
    case OPT_RETURNS: st = gdt_filter_parse_returns(&opts->filter, val, err); break;
    case OPT_KEEP_WITHHELD: opts->filter.keep_withheld = 1; break;
    case OPT_GROUND:
        if (strcmp(val, "pmf") != 0)
            st = gdt_error_set(err, GDT_EUSAGE, 2701, "--ground: '%s' is not a ground filter "
                               "(pmf)", val);
        opts->ground = 1;
        break;
    case OPT_PMF_MAX_WINDOW:
    case OPT_PMF_SLOPE:
    case OPT_PMF_INITIAL:
    case OPT_PMF_MAX_DISTANCE:
    case OPT_PMF_CELL: {
        double *dst = o->id == OPT_PMF_MAX_WINDOW   ? &opts->pmf.max_window
                      : o->id == OPT_PMF_SLOPE      ? &opts->pmf.slope
                      : o->id == OPT_PMF_INITIAL    ? &opts->pmf.initial_distance
                      : o->id == OPT_PMF_MAX_DISTANCE ? &opts->pmf.max_distance
                                                    : &opts->pmf.cell;
        st = parse_finite_double(o->lng, val, dst, err);
        if (opts->pmf_set == NULL)
            opts->pmf_set = o->lng;
        break;
    }
    case OPT_PMF_EXPONENTIAL:
        if (strcmp(val, "true") == 0 || strcmp(val, "on") == 0 || strcmp(val, "1") == 0)
            opts->pmf.exponential = 1;
        else if (strcmp(val, "false") == 0 || strcmp(val, "off") == 0 || strcmp(val, "0") == 0)
            opts->pmf.exponential = 0;
        else
            st = gdt_error_set(err, GDT_EUSAGE, 2701,
                               "--pmf-exponential: '%s' is not true or false", val);
        if (opts->pmf_set == NULL)
            opts->pmf_set = o->lng;
        break;
    case OPT_GROUND_OUT: {
        size_t len = strlen(val);
        opts->ground_out = val;
        if (len < 4 || strcasecmp(val + len - 4, ".las") != 0)
            st = gdt_error_set(err, GDT_EUSAGE, 2704,
                               "--ground-out %s: the classified points are written as LAS "
                               "(uncompressed); name the file .las",
                               val);
        break;
    }
    case OPT_MAX_EDGE: st = parse_positive_double(o->lng, val, &opts->trim.max_edge, err); break;
    case OPT_CONCAVITY:
        st = parse_positive_double(o->lng, val, &opts->trim.concavity, err);
        break;
    }
    return st;
}

gdt_status gdt_cli_parse(gdt_options *opts, int argc, char **argv, gdt_error *err)
{
    int only_inputs = 0;

    memset(opts, 0, sizeof *opts);
    opts->tile = 4096;
    opts->halo = -1;
    opts->quantum = 0.001;
    opts->dup = GDT_DUP_FIRST;
    opts->dem_nodata = -9999.0;
    gdt_pmf_defaults(&opts->pmf);
    opts->inputs = calloc((size_t)(argc > 0 ? argc : 1), sizeof *opts->inputs);
    if (opts->inputs == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");

    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        const char *eq, *val = NULL;
        const opt_spec *o;
        size_t len;
        gdt_status st;

        if (only_inputs || a[0] != '-' || strcmp(a, "-") == 0) {
            opts->inputs[opts->ninputs++] = a;
            continue;
        }
        if (strcmp(a, "--") == 0) {
            only_inputs = 1;
            continue;
        }
        if (strcmp(a, "-vv") == 0) {
            opts->verbosity = 2;
            continue;
        }
        eq = strncmp(a, "--", 2) == 0 ? strchr(a, '=') : NULL;
        len = eq != NULL ? (size_t)(eq - a) : strlen(a);
        o = find_option(a, len);
        if (o == NULL)
            return gdt_error_set(err, GDT_EUSAGE, 2000, "unknown option '%.*s' (see --help)",
                                 (int)len, a);
        if (o->arg != NULL) {
            if (eq != NULL)
                val = eq + 1;
            else if (i + 1 < argc)
                val = argv[++i];
            else
                return gdt_error_set(err, GDT_EUSAGE, 2005, "%s needs a value (%s)", o->lng,
                                     o->arg);
        } else if (eq != NULL) {
            return gdt_error_set(err, GDT_EUSAGE, 2006, "%s takes no value", o->lng);
        }
        st = apply(opts, o, val, err);
        if (st != GDT_OK)
            return st;
    }
    if (opts->mode == GDT_MODE_HELP || opts->mode == GDT_MODE_VERSION)
        return GDT_OK;
    if (opts->mode == GDT_MODE_RESUME) {
        if (opts->ninputs > 0)
            return gdt_error_set(err, GDT_EUSAGE, 2007,
                                 "--resume DIR takes no inputs: the job directory has them");
        return GDT_OK;
    }
    if (opts->ninputs == 0)
        return gdt_error_set(err, GDT_EUSAGE, 2008, "no input given (see --help)");
    if (opts->output == NULL)
        opts->output = "out.ply";
    if (opts->ground || opts->pmf_set != NULL)
        return gdt_pmf_check(&opts->pmf, err);
    return GDT_OK;
}

void gdt_options_free(gdt_options *opts)
{
    free((void *)opts->inputs);
    opts->inputs = NULL;
    opts->ninputs = 0;
}

/* --single-tile: the inputs' header point counts must add up to at most
 * N^2/2 (half the texels of the tile's grid).  With a class or return
 * filter the header counts are only an upper bound: the points kept are
 * checked after the reading instead (gdt_cli_single_tile). */
static gdt_status check_one_tile(const gdt_options *opts, gdt_error *err)
{
    uint64_t total = 0, limit = (uint64_t)opts->tile * (uint64_t)opts->tile / 2;
    for (size_t i = 0; i < opts->ninputs; i++) {
        gdt_source *src = NULL;
        gdt_source_opts so;
        gdt_status st;
        memset(&so, 0, sizeof so);
        st = gdt_source_open(&src, opts->inputs[i], &so, err);
        if (st != GDT_OK)
            return st;
        total += gdt_source_get_info(src)->point_count;
        gdt_source_close(src);
    }
    if (total > limit && !gdt_filter_uses_attributes(&opts->filter))
        return gdt_error_set(err, GDT_EUSAGE, 2102,
                             "--single-tile: the inputs hold %llu points, more than one tile "
                             "of %d x %d texels takes (%llu); use a larger --tile or the "
                             "tiled pipeline (without --single-tile)",
                             (unsigned long long)total, opts->tile, opts->tile,
                             (unsigned long long)limit);
    return GDT_OK;
}

/* Options that belong to stages this build does not have yet are refused
 * rather than silently ignored. */
static gdt_status refuse_unavailable(const gdt_options *opts, gdt_error *err)
{
    if ((opts->job != NULL || opts->keep_job || opts->restart) &&
        (opts->mode != GDT_MODE_RUN || opts->single_tile) && opts->mode != GDT_MODE_RESUME)
        return gdt_error_set(err, GDT_EUSAGE, 2104,
                             "--job, --keep-job and --restart only apply to a tiled run");
    if (opts->mode == GDT_MODE_RESUME && (opts->job != NULL || opts->restart))
        return gdt_error_set(err, GDT_EUSAGE, 2107,
                             "--resume DIR names the job itself (no --job, no --restart)");
    if (opts->mode == GDT_MODE_RESUME && !gdt_filter_is_default(&opts->filter))
        return gdt_error_set(err, GDT_EUSAGE, 2306,
                             "--resume DIR filters the points as its job recorded (no "
                             "--keep-class, --drop-class, --returns or --keep-withheld)");
    if (opts->mode == GDT_MODE_RESUME && opts->output != NULL)
        return gdt_error_set(err, GDT_EUSAGE, 2108,
                             "--resume DIR writes the output its job recorded (no -o)");
    if (opts->device != NULL && opts->mode != GDT_MODE_RUN && opts->mode != GDT_MODE_RESUME)
        return gdt_error_set(err, GDT_EUSAGE, 2103,
                             "--device only applies to a triangulation run (not --info or "
                             "--reference)");
    if (opts->single_tile && opts->mode != GDT_MODE_RUN)
        return gdt_error_set(err, GDT_EUSAGE, 2105,
                             "--single-tile only applies to a triangulation run");
    if (opts->single_tile && gdt_ocl_spec_is_list(opts->device))
        return gdt_error_set(err, GDT_EUSAGE, 2103,
                             "--device %s: several devices share the tiled run's tiles; "
                             "--single-tile runs one tile on one device",
                             opts->device);
    if (opts->queues > 0 &&
        ((opts->mode != GDT_MODE_RUN && opts->mode != GDT_MODE_RESUME) || opts->single_tile))
        return gdt_error_set(err, GDT_EUSAGE, 2103,
                             "--queues %d: several queues share the tiled run's tiles; it does "
                             "not apply to --info, --reference or --single-tile",
                             opts->queues);
    if (gdt_trim_on(&opts->trim) && opts->mode == GDT_MODE_RESUME)
        return gdt_error_set(err, GDT_EUSAGE, 2802,
                             "--resume DIR trims the mesh as its job recorded (no --max-edge "
                             "or --concavity)");
    if (gdt_trim_on(&opts->trim) && opts->mode != GDT_MODE_RUN &&
        opts->mode != GDT_MODE_REFERENCE)
        return gdt_error_set(err, GDT_EUSAGE, 2801,
                             "--max-edge and --concavity only apply to a triangulation run");
    if (gdt_trim_on(&opts->trim) && opts->check)
        return gdt_error_set(err, GDT_EUSAGE, 2803,
                             "--check validates a whole triangulation, not a trimmed one: "
                             "check the untrimmed mesh, and the trimming with "
                             "scripts/validate_mesh.py TRIMMED.ply --trimmed-from FULL.ply");
    if (opts->pmf_set != NULL && !opts->ground)
        return gdt_error_set(err, GDT_EUSAGE, 2703, "%s needs --ground pmf", opts->pmf_set);
    if (opts->ground_out != NULL && !opts->ground)
        return gdt_error_set(err, GDT_EUSAGE, 2703, "--ground-out needs --ground pmf");
    if (opts->ground && opts->filter.class_mode > 0)
        return gdt_error_set(err, GDT_EUSAGE, 2703,
                             "--ground pmf classifies the points itself: not with --keep-class "
                             "(--drop-class, for example of noise, is allowed)");
    if (opts->ground && opts->mode == GDT_MODE_RESUME)
        return gdt_error_set(err, GDT_EUSAGE, 2703,
                             "--resume DIR classifies ground as its job recorded (no --ground)");
    if (opts->ground && opts->mode != GDT_MODE_RUN && opts->mode != GDT_MODE_REFERENCE)
        return gdt_error_set(err, GDT_EUSAGE, 2703,
                             "--ground applies to a triangulation run (not --info)");
    if (opts->ground_out != NULL && (opts->mode != GDT_MODE_RUN || opts->single_tile))
        return gdt_error_set(err, GDT_EUSAGE, 2703,
                             "--ground-out is written by the tiled run (not with --reference "
                             "or --single-tile)");
    if (opts->dem == NULL && (opts->dem_res_set || opts->dem_nodata_set || opts->preview))
        return gdt_error_set(err, GDT_EUSAGE, 2605, "%s needs --dem OUT.tif",
                             opts->preview != NULL ? "--preview"
                             : opts->dem_res_set  ? "--dem-res"
                                                  : "--dem-nodata");
    if (opts->dem != NULL && opts->mode == GDT_MODE_RESUME)
        return gdt_error_set(err, GDT_EUSAGE, 2606,
                             "--resume DIR writes the DEM its job recorded (no --dem)");
    if (opts->dem != NULL && opts->mode != GDT_MODE_RUN && opts->mode != GDT_MODE_REFERENCE)
        return gdt_error_set(err, GDT_EUSAGE, 2606,
                             "--dem only applies to a triangulation run (not --info)");
    return GDT_OK;
}

/* SIGINT / SIGTERM ask the run to stop at its next check (between read
 * batches, tiles and output chunks, and the steps of the start-up); a
 * second signal kills at once (SA_RESETHAND).  The handlers belong to the
 * gdt-tile executable (main.c), which installs them before it loads this
 * library and hands their flag to gdt_cli_main_stop. */
gdt_status gdt_cli_check_stop(const gdt_options *opts, const char *where, gdt_error *err)
{
    if (opts->stop == NULL || *opts->stop == 0)
        return GDT_OK;
    return gdt_error_set(err, GDT_EINTERRUPTED, 1303,
                         "stopped by a signal during %s; nothing was written", where);
}

int gdt_cli_threads(int k)
{
    long n = sysconf(_SC_NPROCESSORS_ONLN);
    if (k > 0)
        return k;
    return n < 1 ? 1 : n > 1024 ? 1024 : (int)n;
}

/* A parallel launch (mpirun -np K, K > 1): the tiled run and --resume are
 * shared between the ranks (private/mpi_run.h); MPI is initialised only
 * then, never in a plain run or under one rank, which runs as a plain
 * process.  Every other mode runs in one process and is refused (2951); a
 * build without MPI refuses any parallel launch (2950).  Refused before
 * anything is opened, so nothing is touched.  *comm: the ranks, or NULL. */
static gdt_status start_parallel(gdt_options *opts, gdt_comm **comm, int *follower,
                                 gdt_error *err)
{
    gdt_launch l;
    gdt_status st;
    *comm = NULL;
    *follower = 0;
    gdt_launch_detect(&l);
    if (!gdt_launch_is_parallel(&l))
        return GDT_OK;
    *follower = l.rank != 0;
    if (!gdt_comm_available())
        return gdt_error_set(err, GDT_EUSAGE, 2950,
                             "started as rank %ld of %ld by %s, but this gdt-tile was built "
                             "without MPI (install libopenmpi-dev and build again); run it "
                             "without the launcher or with one rank (mpirun -np 1)",
                             l.rank, l.size, l.launcher);
    if (!((opts->mode == GDT_MODE_RUN && !opts->single_tile) || opts->mode == GDT_MODE_RESUME))
        return gdt_error_set(err, GDT_EUSAGE, 2951,
                             "started as rank %ld of %ld by %s: only the tiled run and "
                             "--resume are shared between ranks; run --info, --reference and "
                             "--single-tile without the launcher or with one rank",
                             l.rank, l.size, l.launcher);
    st = gdt_comm_init(comm, err);
    if (st != GDT_OK)
        return st;
    *follower = gdt_comm_rank(*comm) != 0;
    opts->comm = *comm;
    return GDT_OK;
}

/* The environment the OpenCL runtime needs (gdt_ocl_prepare_env), set
 * while this is the process's only thread of ours: before MPI_Init, whose
 * library starts threads of its own, and before any stage starts one.
 * Warnings go to rank 0's stderr only, as the run's own do. */
static void prepare_opencl_env(const gdt_options *opts)
{
    gdt_launch l;
    gdt_log log;
    if (!(opts->mode == GDT_MODE_RUN || opts->mode == GDT_MODE_RESUME))
        return;
    gdt_launch_detect(&l);
    gdt_log_init(&log, l.rank != 0 ? -1 : opts->verbosity);
    gdt_ocl_prepare_env(NULL, &log);
}

int gdt_cli_main_stop(int argc, char **argv, volatile sig_atomic_t *stop)
{
    gdt_options opts;
    gdt_error err;
    gdt_status st;
    gdt_comm *comm = NULL;
    int follower = 0;

    gdt_error_clear(&err);
    st = gdt_cli_parse(&opts, argc, argv, &err);
    if (st != GDT_OK)
        goto done;
    opts.stop = stop;
    switch (opts.mode) {
    case GDT_MODE_HELP:
        gdt_cli_print_help(stdout);
        goto done;
    case GDT_MODE_VERSION:
        printf("gdt-tile %s\nmpi: %s\n", GDT_VERSION,
               gdt_comm_available() ? "yes (mpirun -np K shares a tiled run)" : "no");
        goto done;
    default:
        break;
    }
    prepare_opencl_env(&opts);
    st = start_parallel(&opts, &comm, &follower, &err);
    if (st == GDT_EUSAGE && follower) {
        gdt_options_free(&opts);
        return (int)st; /* rank 0 says why, once for the whole job */
    }
    if (st == GDT_OK)
        st = refuse_unavailable(&opts, &err);
    if (st == GDT_OK)
        st = gdt_cli_check_stop(&opts, "start-up", &err);
    /* every path before any work; the tiled run checks its own (its job
     * directory, and for --resume the paths the job recorded) */
    if (st == GDT_OK && (opts.mode != GDT_MODE_RUN || opts.single_tile) &&
        opts.mode != GDT_MODE_RESUME)
        st = gdt_cli_check_paths(&opts, NULL, &err);
    if (st != GDT_OK)
        goto done;
    if (opts.mode == GDT_MODE_INFO) {
        st = gdt_cli_info(&opts, &err);
    } else {
        /* The filters' error analysis assumes IEEE double without contraction
         * or reassociation: refuse to compute anything in a build that breaks it. */
        unsigned faults = 0;
        st = gdt_predicates_selftest(&faults, &err);
        if (st == GDT_OK)
            st = gdt_cli_check_stop(&opts, "start-up", &err);
        if (st == GDT_OK && opts.mode == GDT_MODE_REFERENCE) {
            st = gdt_cli_reference(&opts, &err);
        } else if (st == GDT_OK && opts.mode == GDT_MODE_RESUME) {
            st = gdt_cli_resume(&opts, &err);
        } else if (st == GDT_OK && opts.mode == GDT_MODE_RUN) {
            if (opts.single_tile) {
                st = check_one_tile(&opts, &err);
                if (st == GDT_OK)
                    st = gdt_cli_single_tile(&opts, &err);
            } else {
                st = gdt_cli_tiled(&opts, &err);
            }
        }
    }
done:
    /* another rank of an MPI run has no message of its own: rank 0 prints
     * the job's error (and a rank's that failed before the run, its own) */
    if (st != GDT_OK && (comm == NULL || err.status != GDT_OK)) {
        gdt_error_print(&err, stderr);
        if (st == GDT_EUSAGE)
            fprintf(stderr, "usage: gdt-tile INPUT [INPUT ...] [-o OUT.ply] [options]; "
                            "see gdt-tile --help\n");
    }
    gdt_options_free(&opts);
    gdt_comm_finish(comm);
    return (int)st;
}
