/* launch.h — how this process was started: alone, or as one rank of a
 * parallel launcher (mpirun, mpiexec, srun with PMI).
 *
 * Decided from the launcher's environment alone, before any MPI library is
 * touched, so a plain run never initialises MPI.  Recognised:
 *   - Open MPI: OMPI_COMM_WORLD_SIZE, OMPI_COMM_WORLD_RANK,
 *     OMPI_COMM_WORLD_LOCAL_RANK;
 *   - the PMI of MPICH, Intel MPI and Slurm's srun --mpi=pmi2: PMI_SIZE,
 *     PMI_RANK (MPI_LOCALRANKID for the local rank);
 *   - PMIx (srun --mpi=pmix, prterun): PMIX_RANK, the size then unknown
 *     unless one of the above gives it.
 * A variable that is not a plain decimal number is ignored. */
#ifndef GDT_LAUNCH_H
#define GDT_LAUNCH_H

typedef struct gdt_launch {
    const char *launcher; /* "Open MPI", "PMI", "PMIx", or NULL: started alone */
    long size;            /* ranks of the job; 0 when the launcher does not say */
    long rank;            /* this process's rank, 0 when alone */
    long local_rank;      /* rank on this node, -1 when unknown */
} gdt_launch;

/* Fills l from the environment. */
void gdt_launch_detect(gdt_launch *l);

/* Whether l describes more than one process (a size above 1, or a rank
 * above 0 when the size is unknown). */
int gdt_launch_is_parallel(const gdt_launch *l);

#endif
