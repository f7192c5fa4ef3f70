/* ground_pcl.h — the boundary between the ground filter (ground_pmf.cpp)
 * and PCL's approximate progressive morphological filter, which lives in a
 * module of its own (libgdt-tile-pcl.so, ground_pcl.cpp) loaded only by
 * runs with --ground pmf (see private/plugin.h).
 *
 * The interface is plain C and carries no C++ exception: the module fills
 * nothing but PCL's cloud (through the caller's fill function, so the
 * points are not copied twice) and the caller's ground flags. */
#ifndef GDT_GROUND_PCL_H
#define GDT_GROUND_PCL_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define GDT_GROUND_PCL_MODULE "libgdt-tile-pcl.so"
#define GDT_GROUND_PCL_SYMBOL "gdt_ground_pcl_run"

typedef struct gdt_ground_pcl_job {
    size_t n; /* points of PCL's cloud */
    /* writes x, y, z of point i to xyz + i stride, for i in [0, n) */
    void (*fill)(void *ctx, float *xyz, size_t stride);
    void *fill_ctx;
    uint8_t *ground; /* ground[i] = 1 for each i < nflag that PCL keeps */
    size_t nflag;
    int max_window_cells, exponential;
    float slope, initial_distance, max_distance; /* in PCL's units: cells */
} gdt_ground_pcl_job;

enum {
    GDT_GROUND_PCL_OK = 0,
    GDT_GROUND_PCL_NOMEM = 1, /* out of memory */
    GDT_GROUND_PCL_FAILED = 2 /* PCL threw or returned an index out of range: msg says */
};

/* Runs PCL's filter (one thread, cell size 1, base 2) on job's cloud.
 * returns one of the codes above; msg (cap bytes) holds the reason of a
 * failure. */
typedef int (*gdt_ground_pcl_fn)(const gdt_ground_pcl_job *job, char *msg, size_t cap);

#ifdef __cplusplus
}
#endif
#endif
