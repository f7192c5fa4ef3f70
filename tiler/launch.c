/* The launcher's environment (see private/launch.h). */
#include "private/launch.h"

#include <errno.h>
#include <stdlib.h>

/* The value of variable name as a decimal number in [0, 2^31), or -1. */
static long env_number(const char *name)
{
    const char *s = getenv(name);
    char *end;
    long v;
    if (s == NULL || *s < '0' || *s > '9')
        return -1;
    errno = 0;
    v = strtol(s, &end, 10);
    if (errno != 0 || *end != '\0' || v > 2147483647L)
        return -1;
    return v;
}

void gdt_launch_detect(gdt_launch *l)
{
    long size, rank;

    l->launcher = NULL;
    l->size = 1;
    l->rank = 0;
    l->local_rank = -1;
    size = env_number("OMPI_COMM_WORLD_SIZE");
    rank = env_number("OMPI_COMM_WORLD_RANK");
    if (size >= 1 && rank >= 0) {
        l->launcher = "Open MPI";
        l->size = size;
        l->rank = rank;
        l->local_rank = env_number("OMPI_COMM_WORLD_LOCAL_RANK");
        return;
    }
    size = env_number("PMI_SIZE");
    rank = env_number("PMI_RANK");
    if (size >= 1 && rank >= 0) {
        l->launcher = "PMI";
        l->size = size;
        l->rank = rank;
        l->local_rank = env_number("MPI_LOCALRANKID");
        return;
    }
    rank = env_number("PMIX_RANK");
    if (rank >= 0) {
        l->launcher = "PMIx";
        l->size = 0;
        l->rank = rank;
    }
}

int gdt_launch_is_parallel(const gdt_launch *l)
{
    return l->size > 1 || l->rank > 0;
}
