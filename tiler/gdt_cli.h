/* gdt_cli.h — the gdt-tile command line.
 *
 * Every option is declared once, with its help text and default, in the
 * option table of cli.c.  Parsing is strict: malformed numbers, out-of-range
 * values, unknown options and conflicting modes are usage errors (exit 2).
 */
#ifndef GDT_CLI_H
#define GDT_CLI_H

#include <signal.h>
#include <stddef.h>
#include <stdint.h>

#include "gdt_cloud.h"
#include "gdt_ground.h"
#include "gdt_error.h"
#include "gdt_filter.h"
#include "gdt_trim.h"

#ifdef __cplusplus
extern "C" {
#endif

/* The most command queues --queues gives a device. */
#define GDT_CLI_MAX_QUEUES 8

typedef enum gdt_mode {
    GDT_MODE_RUN = 0,   /* the tiled pipeline */
    GDT_MODE_INFO,      /* --info */
    GDT_MODE_REFERENCE, /* --reference: in-memory single-tile oracle */
    GDT_MODE_RESUME,    /* --resume DIR */
    GDT_MODE_HELP,
    GDT_MODE_VERSION
} gdt_mode;

/* Parsed command line.  Strings point into argv (not owned). */
typedef struct gdt_options {
    gdt_mode mode;
    const char **inputs;     /* owned: array of argv pointers */
    size_t ninputs;
    const char *output;      /* -o; NULL = default "out.ply" beside nothing: required for runs */
    int tile;                /* --tile N: texels per tile side (power of two, 64..16384) */
    int tile_set;
    double cell;             /* --cell S; 0 = automatic */
    long halo;               /* --halo H texels; -1 = automatic */
    const char *job;         /* --job DIR; NULL = OUT.ply.gdt-job */
    int restart;             /* --restart */
    int keep_job;            /* --keep-job */
    int single_tile;         /* --single-tile */
    const char *resume;      /* --resume DIR */
    const char *device;      /* --device SPEC; NULL = first device */
    int threads;             /* --threads K; 0 = number of cores */
    int queues;              /* --queues N, command queues per device; 0 = auto */
    uint64_t mem_budget;     /* --mem-budget bytes; 0 = automatic */
    double quantum;          /* --quantum Q (CRS units) */
    gdt_dup_policy dup;      /* --dup */
    gdt_point_filter filter; /* --keep-class, --drop-class, --returns, --keep-withheld */
    gdt_trim_rule trim;      /* --max-edge, --concavity (0 = off); sx, sy unused here */
    int ground;              /* --ground pmf: triangulate the ground points only */
    gdt_pmf_params pmf;      /* --pmf-* (defaults: gdt_pmf_defaults) */
    const char *pmf_set;     /* the first --pmf-* option given, NULL if none */
    const char *ground_out;  /* --ground-out FILE.las: every input record, class 2 or 1 */
    int check;               /* --check */
    const char *json;        /* --json FILE */
    const char *dem;         /* --dem OUT.tif, NULL: no DEM */
    double dem_res;          /* --dem-res R (CRS units); 0 = automatic */
    double dem_nodata;       /* --dem-nodata V (a float32); default -9999 */
    int dem_res_set, dem_nodata_set;
    const char *preview;     /* --preview OUT.png (needs --dem) */
    int verbosity;           /* -q = -1, default 0, -v = 1 (-vv = 2) */
    volatile sig_atomic_t *stop; /* set (nonzero) by a signal handler: stop cleanly;
                                    NULL = never */
    struct gdt_comm *comm;   /* the ranks of an MPI launch (private/comm.h); NULL:
                                this process alone */
} gdt_options;

/* Parses argv into opts.  Ownership: opts->inputs is allocated; release with
 * gdt_options_free.  Returns GDT_EUSAGE with a message in err on any error. */
gdt_status gdt_cli_parse(gdt_options *opts, int argc, char **argv, gdt_error *err);
void gdt_options_free(gdt_options *opts);

/* Prints the full help text (usage, options with defaults, exit codes). */
void gdt_cli_print_help(FILE *stream);

/* The whole program: parse, run the mode, print errors, return the exit
 * code.  stop is the flag of the SIGINT/SIGTERM handlers the caller
 * installed (the gdt-tile launcher, main.c, does so before the libraries
 * are even loaded); a nonzero value stops the run at its next check. */
int gdt_cli_main_stop(int argc, char **argv, volatile sig_atomic_t *stop);

#ifdef __cplusplus
}
#endif
#endif
