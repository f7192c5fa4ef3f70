/* mpi_run.h — gdt-tile under mpirun: one tiled job over every rank.
 *
 * Rank 0 runs the job as a single process does (private/stages.h) and is
 * the only rank that touches the job's lock and journal and writes the
 * outputs; every rank, rank 0 included, triangulates its share of the tiles
 * (dealt out in tile order, balanced by point count) into the shared
 * job directory, which must be on a file system every rank sees.  The
 * output is byte for byte that of a single process, and a job interrupted
 * under one number of ranks resumes under any other, or without mpirun.
 * The protocol is described in mpi_run.c. */
#ifndef GDT_MPI_RUN_H
#define GDT_MPI_RUN_H

#include "gdt_cli.h"
#include "gdt_error.h"
#include "private/comm.h"

/* The tiled run of opts over the ranks of comm (more than one).  Every
 * rank returns the job's status; rank 0 has its error in *err (a failure
 * on another rank is named "rank R: ..."), the other ranks report nothing.
 * returns: as gdt_cli_tiled; GDT_EINTERNAL 795x (the ranks' messages). */
gdt_status gdt_cli_tiled_mpi(const gdt_options *opts, gdt_comm *comm, gdt_error *err);

#endif
