/* stages_subset — the stages of a tiled run (tiler/private/stages.h) up to
 * the tile stage, over a subset of the tiles.
 *
 *   stages_subset K1,K2,... GDT-TILE-ARGUMENTS...
 *
 * Runs tr_run_init through tr_run_pass2 for the gdt-tile command line, then
 * tr_run_tiles over the tiles K1 < K2 < ... only (no mesh writer, no
 * merge), and closes the run, which keeps the job.  Prints "done K" for
 * every tile the stage reports finished, in the order it reports them.
 * Exit status: 0, or the gdt_status of the first stage that failed (its
 * message on stderr). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_cli.h"
#include "private/stages.h"

static void on_done(void *ctx, uint64_t k)
{
    (void)ctx;
    printf("done %llu\n", (unsigned long long)k);
}

int main(int argc, char **argv)
{
    gdt_options opts;
    gdt_error err;
    tr_run c;
    tr_tile_set set = {NULL, 0, on_done, NULL, NULL, NULL, NULL, NULL};
    uint64_t *ks = NULL;
    const char *p;
    gdt_status st;

    if (argc < 3) {
        fprintf(stderr, "usage: stages_subset K1,K2,... GDT-TILE-ARGUMENTS...\n");
        return 2;
    }
    ks = calloc(strlen(argv[1]) + 1, sizeof *ks);
    if (ks == NULL)
        return 1;
    for (p = argv[1]; *p != '\0';) {
        char *end;
        ks[set.n++] = strtoull(p, &end, 10);
        if (end == p || (*end != ',' && *end != '\0')) {
            fprintf(stderr, "stages_subset: bad tile list %s\n", argv[1]);
            free(ks);
            return 2;
        }
        p = *end == ',' ? end + 1 : end;
    }
    set.k = ks;
    gdt_error_clear(&err);
    /* the gdt-tile arguments after the program name */
    argv[1] = argv[0];
    st = gdt_cli_parse(&opts, argc - 1, argv + 1, &err);
    if (st != GDT_OK) {
        fprintf(stderr, "stages_subset: %s\n", err.msg);
        free(ks);
        return (int)st;
    }
    st = tr_run_init(&c, &opts, &err);
    if (st == GDT_OK)
        st = tr_run_start_core(&c, &err);
    if (st == GDT_OK)
        st = tr_run_prepare_job(&c, &err);
    if (st == GDT_OK)
        st = tr_run_pass1(&c, &err);
    if (st == GDT_OK)
        st = tr_run_pass2(&c, &err);
    if (st == GDT_OK)
        st = tr_run_tiles(&c, &set, &err);
    st = tr_run_close(&c, st);
    if (st != GDT_OK)
        fprintf(stderr, "stages_subset: %s\n", err.msg);
    fflush(stdout);
    gdt_options_free(&opts);
    free(ks);
    return (int)st;
}
