/* The single-process tiled run (see private/tiled_run.h): every stage of
 * private/stages.h once, in order, over every tile.  Under mpirun with
 * more than one rank, the MPI scheduler (private/mpi_run.h) runs them. */
#include "private/tiled_run.h"

#include "private/mpi_run.h"
#include "private/stages.h"

gdt_status gdt_cli_tiled(const gdt_options *opts, gdt_error *err)
{
    tr_run c;
    gdt_status st;

    if (opts->comm != NULL && gdt_comm_size(opts->comm) > 1)
        return gdt_cli_tiled_mpi(opts, opts->comm, err);
    st = tr_run_init(&c, opts, err);
    c.cstart.preload_dem = opts->dem != NULL; /* this process writes the DEM */
    if (st == GDT_OK)
        st = tr_run_start_core(&c, err);
    if (st == GDT_OK)
        st = tr_run_prepare_job(&c, err);
    if (st == GDT_OK)
        st = tr_run_pass1(&c, err);
    if (st == GDT_OK)
        st = tr_run_pass2(&c, err);
    if (st == GDT_OK)
        st = tr_run_output_start(&c, err);
    if (st == GDT_OK)
        st = tr_run_merge_start(&c, err);
    if (st == GDT_OK)
        st = tr_run_tiles(&c, NULL, err); /* NULL: every tile */
    if (st == GDT_OK)
        st = tr_run_merge(&c, err);
    if (st == GDT_OK)
        st = tr_run_finish(&c, err);
    return tr_run_close(&c, st);
}
