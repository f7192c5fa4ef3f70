/* gdt_ocl.h — the OpenCL host driver: the only code of gdt-tile that talks
 * to OpenCL.
 *
 * A gdt_ocl context holds one platform, one device, one OpenCL context and
 * one in-order command queue, the programs built from kernels/<name>.cl, and
 * every device buffer the caller creates through it.  Callers (the gCD core)
 * see opaque handles only; no OpenCL type or header leaks out of core/ocl.c.
 *
 * Device selection (gdt_ocl_opts.device, the --device SPEC of the command
 * line):
 *   NULL or ""   the first device of the first platform that has one;
 *   "N"          the N-th device (from 0) counting every device of every
 *                platform in enumeration order;
 *   "P:D"        device D of platform P;
 *   "cpu", "gpu" the first device of that type;
 *   "local", "cpu/local", "gpu/local"
 *                for one rank of an MPI job: device (local rank mod m) of
 *                the m devices (of every type, or of that type), so that
 *                the ranks on one node take its devices in turn (with 4
 *                GPUs, local ranks 0..7 use GPUs 0, 1, 2, 3, 0, 1, 2, 3);
 *                the local rank is gdt_ocl_opts.local_rank (0 alone).
 *
 * Programs: kernels/<file> is read with every #include "x.clh" line of it
 * and of its headers replaced by that header of the kernel directory
 * (framed by #line directives; core/private/kernel_text.h), so the program
 * depends on its text and options only: a kernel binary cache keyed on
 * them never serves a stale build after a header changed, and still serves
 * a kernel directory that was moved or copied.  It is built with
 *   -cl-std=CL1.2 [-DGDT_X_NO_F64] [extra options]
 * and never with any of OpenCL's relaxed or unsafe math build options (the
 * exact predicates rely on IEEE double rounding).  -DGDT_X_NO_F64 is passed
 * when the device lacks cl_khr_fp64, or when the caller forces the integer
 * path; kernels then never use double.
 *
 * Program binaries: a program built from its source is saved as the
 * device's binary (clGetProgramInfo) in "programs" of the kernel cache
 * directory below, named by a hash of everything it depends on (platform,
 * device, driver and their versions, the build options, the source text
 * with its headers in place), checked against a second hash and, for its
 * body, a hash of the binary itself; later builds
 * of the same take it from there (clCreateProgramWithBinary), without the
 * compiler front end.  An entry that does not load or build is ignored: the
 * program is built from the source and the entry written again (whole,
 * through a temporary renamed over it).
 *
 * PoCL kernel cache: before the first OpenCL call of the process, the
 * environment variable POCL_CACHE_DIR is pointed at the first usable one
 * (created if needed, writable) of: opts.cache_dir when given; a non-empty
 * POCL_CACHE_DIR already set; $XDG_CACHE_HOME/gdt-tile/pocl;
 * ~/.cache/gdt-tile/pocl; gdt-tile-pocl-<uid> in $TMPDIR or /tmp, which
 * must also be this user's and closed to others (a read-only or missing
 * home).  Each one passed over is a warning (5150) naming it; with none
 * usable the variable is removed, so PoCL never sees an empty or unusable
 * one (it aborts on an empty one).  PoCL reads the variable once per
 * process, so the first context created decides.  PoCL (3.1) leaves one
 * empty file, "tempfile_" and six characters, in that directory at every
 * start, and a build that is interrupted leaves its temporaries (the same
 * name with a suffix such as ".so"): those of this user older than an hour
 * are removed then (of the second kind, only in a directory of gdt-tile's
 * own), so the directory holds no more of them than an hour's runs left.
 * Entries no run used for 30 days are removed then too: program binaries
 * (a run that loads one renews its time) and, in a directory of gdt-tile's own (not a
 * POCL_CACHE_DIR the user set), PoCL's program directories (by the
 * last_accessed file PoCL touches at every build): the directory does not
 * grow by the kernels of every version that changed them.  Each process
 * holds a shared lock on the directory's ".in-use" file, and one prunes
 * only when no other holds it (no entry goes while another run may load
 * it).
 *
 * Errors: every OpenCL failure is GDT_EDEVICE (exit 5) with a message
 * naming the call and the OpenCL error (e.g. "clBuildProgram(gcd_pba.cl):
 * CL_BUILD_PROGRAM_FAILURE ..."); message numbers 5101-5199.
 *
 * Threading: a context is not thread-safe; distinct contexts are independent
 * (apart from the process-wide POCL_CACHE_DIR noted above).
 */
#ifndef GDT_OCL_H
#define GDT_OCL_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include "gdt_error.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct gdt_ocl gdt_ocl;
typedef struct gdt_ocl_program gdt_ocl_program;
typedef struct gdt_ocl_kernel gdt_ocl_kernel;
typedef struct gdt_ocl_buf gdt_ocl_buf;

typedef struct gdt_ocl_opts {
    const char *device;     /* device SPEC (see above); NULL = first device */
    const char *cache_dir;  /* PoCL kernel cache directory; NULL = default */
    const char *kernel_dir; /* NULL: $GDT_KERNEL_DIR, else the source tree's kernels/ */
    int force_no_fp64;      /* nonzero: build every program with -DGDT_X_NO_F64 */
    int profile;            /* nonzero: time every launch (gdt_ocl_profile_dump) */
    gdt_log *log;           /* notes (-v) and warnings; may be NULL */
    int local_rank;         /* this process's rank on its node (the "local" SPECs) */
    /* Contexts already made (nshare of them, may be NULL): when the selected
     * device is one of theirs, the new one is a further queue on it (below). */
    gdt_ocl *const *share;
    size_t nshare;
} gdt_ocl_opts;

/* Points POCL_CACHE_DIR at the kernel cache (above) and sets what the
 * OpenCL runtime would otherwise add to the environment itself when it
 * starts (PoCL: HWLOC_PLUGINS_PATH), once per process; later calls do
 * nothing.  gdt_ocl_create calls it; adding a variable must not happen
 * while another thread may call getenv (libraries do, e.g. compressors
 * writing the tile index), so a program that creates contexts on a thread
 * of its own calls this first, before it starts that thread or any other.
 * Thread-safe. */
void gdt_ocl_prepare_env(const char *cache_dir, gdt_log *log);

/* Several devices (the tiled run's --device): a comma-separated list of
 * SPECs ("0,1"; the same device may be named twice, each name is one
 * command queue), or an element "all", "cpu:all" or "gpu:all" (every device, or
 * every one of that type, in enumeration order).  At most
 * GDT_OCL_MAX_DEVICES. */
#define GDT_OCL_MAX_DEVICES 64

/* Checks the syntax of a device SPEC (above), or of a list of them,
 * without touching OpenCL, so a malformed one is a usage error before any
 * work.  NULL and "" are valid.
 * returns: GDT_OK; GDT_EUSAGE 2110 (malformed). */
gdt_status gdt_ocl_check_device_spec(const char *spec, gdt_error *err);

/* 1 when value names more than one SPEC: a list, or an "all" element. */
int gdt_ocl_spec_is_list(const char *value);

/* The single SPECs of value (a SPEC or a list, above), "all" elements
 * expanded to "P:D" by enumerating the devices.  *specs (n of them) is
 * allocated here: release with gdt_ocl_device_list_free.
 * Errors: GDT_EUSAGE 2110; GDT_EDEVICE 5101 (an "all" element finds no
 * device), 5102; GDT_EINTERNAL 7001. */
gdt_status gdt_ocl_device_list(const char *value, char ***specs, size_t *n, gdt_error *err);
void gdt_ocl_device_list_free(char **specs, size_t n);

/* Creates a context on the selected device, or, when opts->share holds one
 * on the same device, a further command queue in that context ("a queue of
 * a shared device"): it uses the context's built programs (gdt_ocl_build
 * compiles nothing when the first one built the same file with the same
 * options; kernels and buffers are its own, so each queue is driven by its
 * own thread), and the device's busy time is counted once for all its
 * queues (gdt_ocl_busy_seconds).  The first context may be destroyed before
 * the others.  On a device where gdt_ocl_queues_need_own_programs holds, a
 * further queue builds programs of its own instead (its build options gain
 * -DGDT_QUEUE_PROGRAMS=<n>, n distinct per queue of the device; kernels
 * ignore it), so that no two queues ever launch one program's kernels.
 * Ownership: *out is allocated here; release with gdt_ocl_destroy.
 * Errors: GDT_EUSAGE 2110 (malformed SPEC), GDT_EDEVICE 5101 (no
 * platform/device, or none the SPEC names), 5102 (OpenCL call failed),
 * GDT_EINTERNAL 7001 (out of memory). */
gdt_status gdt_ocl_create(gdt_ocl **out, const gdt_ocl_opts *opts, gdt_error *err);

/* What gdt_ocl_probe reports of a device. */
typedef struct gdt_ocl_device_info {
    int is_cpu;          /* CL_DEVICE_TYPE_CPU */
    uint64_t global_mem; /* CL_DEVICE_GLOBAL_MEM_SIZE (0: not reported) */
    uint64_t max_alloc;  /* CL_DEVICE_MAX_MEM_ALLOC_SIZE (0: not reported) */
    char name[128];      /* CL_DEVICE_NAME */
} gdt_ocl_device_info;

/* The device gdt_ocl_create would select for opts, described without
 * creating a context or building anything (opts->kernel_dir, force_no_fp64
 * and profile are not used).  Errors as gdt_ocl_create's selection:
 * GDT_EUSAGE 2110, GDT_EDEVICE 5101, 5102, GDT_EINTERNAL 7001. */
gdt_status gdt_ocl_probe(const gdt_ocl_opts *opts, gdt_ocl_device_info *info, gdt_error *err);

/* Releases every kernel, program and buffer of the context, then the
 * context itself.  ocl may be NULL. */
void gdt_ocl_destroy(gdt_ocl *ocl);

/* "platform name / device name" of the selected device (owned by ocl). */
const char *gdt_ocl_device_name(const gdt_ocl *ocl);
/* 1 when programs are built with double precision (cl_khr_fp64 present and
 * not forced off), else 0. */
int gdt_ocl_has_fp64(const gdt_ocl *ocl);
/* 1 for a CPU device, 0 otherwise. */
int gdt_ocl_is_cpu(const gdt_ocl *ocl);
/* Number of compute units of the device. */
unsigned gdt_ocl_compute_units(const gdt_ocl *ocl);
/* The device's largest work-group (CL_DEVICE_MAX_WORK_GROUP_SIZE), >= 1. */
size_t gdt_ocl_device_max_wg(const gdt_ocl *ocl);
/* Largest single buffer the device accepts, in bytes. */
uint64_t gdt_ocl_max_alloc(const gdt_ocl *ocl);
/* The device's memory (CL_DEVICE_GLOBAL_MEM_SIZE), in bytes (0: unknown). */
uint64_t gdt_ocl_global_mem(const gdt_ocl *ocl);
/* The most bytes the context's buffers have held at once, those wrapping
 * host memory included (on a device with memory of its own they would be
 * device buffers). */
uint64_t gdt_ocl_peak_bytes(const gdt_ocl *ocl);
/* The kernel directory programs are read from (owned by ocl). */
const char *gdt_ocl_kernel_dir(const gdt_ocl *ocl);

/* What the kernels need of a device, checked at gdt_ocl_create from its
 * CL_DEVICE_PROFILE, CL_DEVICE_OPENCL_C_VERSION and CL_DEVICE_EXTENSIONS
 * strings: OpenCL C 1.2 or later, and 64-bit integers (the full profile, or
 * cles_khr_int64 in the embedded one).  Double precision is not needed
 * (without cl_khr_fp64 the kernels take their integer path), nor are 64-bit
 * atomics (the kernels use none).  Writes the missing ones, separated by
 * "; ", to out (NUL-terminated, truncated to cap; "" when none) and
 * returns their number. */
int gdt_ocl_caps_missing(const char *profile, const char *c_version, const char *extensions,
                         char *out, size_t cap);

/* 1 when several command queues of one device must not launch kernels of
 * one program, from the device's CL_PLATFORM_VERSION and whether it is a
 * CPU device: PoCL's CPU drivers before PoCL 7 keep one process-wide cache
 * of compiled work-group functions and match a finished launch to its
 * entry by kernel and local size only, so two queues running one kernel
 * with different ranges can release each other's entries, and the runtime
 * aborts (an assertion in pocl_release_dlhandle_cache).  Kernels of
 * distinct programs never share an entry. */
int gdt_ocl_queues_need_own_programs(const char *platform_version, int is_cpu);

/* Lists every platform and device, one line each ("P:D  N  type  name"),
 * into buf (NUL-terminated, truncated to len).  Needs no context. */
gdt_status gdt_ocl_list_devices(char *buf, size_t len, gdt_error *err);

/* Builds kernels/<file> with the options above plus extra (may be NULL).
 * Ownership: the program belongs to ocl (released by gdt_ocl_destroy).
 * Errors: 5103 (source unreadable: GDT_EDEVICE, naming the path), 5104
 * (build failed: the message carries the head of the build log, the full
 * log goes to the log as a note). */
gdt_status gdt_ocl_build(gdt_ocl *ocl, const char *file, const char *extra,
                         gdt_ocl_program **out, gdt_error *err);

/* Number of kernels in a built program and the name of kernel i (for the
 * compile test); names are owned by the program. */
size_t gdt_ocl_program_kernel_count(const gdt_ocl_program *p);
const char *gdt_ocl_program_kernel_name(const gdt_ocl_program *p, size_t i);

/* Largest work-group size the device runs kernel k with
 * (CL_KERNEL_WORK_GROUP_SIZE), at least 1. */
size_t gdt_ocl_kernel_max_wg(const gdt_ocl_kernel *k);

/* Looks up a kernel of a built program.  Owned by ocl. */
gdt_status gdt_ocl_kernel_get(gdt_ocl_program *p, const char *name, gdt_ocl_kernel **out,
                              gdt_error *err);

/* ---- buffers ----
 * Device buffers owned by the context: released by gdt_ocl_buf_release or
 * gdt_ocl_destroy.  Sizes are in bytes; a zero size is rounded up to a
 * small allocation so kernels can always be given a valid buffer. */
gdt_status gdt_ocl_buf_create(gdt_ocl *ocl, size_t bytes, const char *what, gdt_ocl_buf **out,
                              gdt_error *err);
void gdt_ocl_buf_release(gdt_ocl *ocl, gdt_ocl_buf *b);
size_t gdt_ocl_buf_size(const gdt_ocl_buf *b);
/* On a CPU device: a buffer over the caller's memory host[0..bytes)
 * (CL_MEM_USE_HOST_PTR), so that kernels write where the caller reads
 * without a copy; host stays the caller's (gdt_ocl_buf_release leaves it).
 * *out = NULL (and GDT_OK) on other devices or when the runtime refuses:
 * the caller then copies.  After kernels wrote it, gdt_ocl_buf_sync_host
 * (a blocking map and unmap) makes host hold the contents, also on a
 * runtime that keeps a copy of its own behind such a buffer. */
gdt_status gdt_ocl_buf_wrap(gdt_ocl *ocl, void *host, size_t bytes, const char *what,
                            gdt_ocl_buf **out, gdt_error *err);
gdt_status gdt_ocl_buf_sync_host(gdt_ocl *ocl, gdt_ocl_buf *b, gdt_error *err);
/* Maps the first bytes of b for writing (their old contents are lost);
 * the caller fills *host, then gdt_ocl_unmap hands them to the device.  On
 * a CPU device the runtime normally hands out the buffer's own memory (no
 * copy; PoCL does); elsewhere it stages and copies at the unmap. */
gdt_status gdt_ocl_map_write(gdt_ocl *ocl, gdt_ocl_buf *b, size_t bytes, void **host,
                             gdt_error *err);
gdt_status gdt_ocl_unmap(gdt_ocl *ocl, gdt_ocl_buf *b, void *host, gdt_error *err);
/* Blocking transfers of bytes at offset. */
gdt_status gdt_ocl_write(gdt_ocl *ocl, gdt_ocl_buf *b, size_t offset, const void *src,
                         size_t bytes, gdt_error *err);
gdt_status gdt_ocl_read(gdt_ocl *ocl, gdt_ocl_buf *b, size_t offset, void *dst, size_t bytes,
                        gdt_error *err);
/* Fills bytes at offset with a 4-byte pattern (offset, bytes multiples of 4). */
gdt_status gdt_ocl_fill_u32(gdt_ocl *ocl, gdt_ocl_buf *b, size_t offset, uint32_t value,
                            size_t bytes, gdt_error *err);
/* Device-side copy. */
gdt_status gdt_ocl_copy(gdt_ocl *ocl, gdt_ocl_buf *src, size_t src_off, gdt_ocl_buf *dst,
                        size_t dst_off, size_t bytes, gdt_error *err);

/* ---- kernel arguments and launches ---- */
gdt_status gdt_ocl_arg_buf(gdt_ocl_kernel *k, unsigned i, gdt_ocl_buf *b, gdt_error *err);
gdt_status gdt_ocl_arg_u32(gdt_ocl_kernel *k, unsigned i, uint32_t v, gdt_error *err);
gdt_status gdt_ocl_arg_i32(gdt_ocl_kernel *k, unsigned i, int32_t v, gdt_error *err);
gdt_status gdt_ocl_arg_i64(gdt_ocl_kernel *k, unsigned i, int64_t v, gdt_error *err);
/* Local memory of bytes for argument i. */
gdt_status gdt_ocl_arg_local(gdt_ocl_kernel *k, unsigned i, size_t bytes, gdt_error *err);

/* Enqueues k over a 1-D range of global work-items, rounded up to a
 * multiple of local (local = 0: the implementation chooses, no rounding).
 * Kernels must ignore work-items at or beyond their own count.  global = 0
 * is a no-op.  The queue is in order; gdt_ocl_finish waits. */
gdt_status gdt_ocl_run(gdt_ocl *ocl, gdt_ocl_kernel *k, size_t global, size_t local,
                       gdt_error *err);
gdt_status gdt_ocl_finish(gdt_ocl *ocl, gdt_error *err);

/* The device-busy time so far: the time (the device's own profiling
 * clock) during which at least one command of the device's queues, kernels
 * and transfers, was executing; waits for the queues first.  With one
 * queue it is the sum of the commands' execution times (the queue is in
 * order: its commands never overlap).  Several queues on a shared device:
 * the first context made on it returns the union of all their commands'
 * intervals and every further queue returns 0, so summing over contexts
 * counts each device once; call it on the first while no thread drives
 * another of the device's queues. */
double gdt_ocl_busy_seconds(gdt_ocl *ocl);

/* How many of ocl's programs came from the program-binary cache and how
 * many were built from source; *dir: the cache's directory (NULL: none). */
void gdt_ocl_program_counts(const gdt_ocl *ocl, unsigned *cached, unsigned *built,
                            const char **dir);

/* 1 when a and b drive the same device, else 0. */
int gdt_ocl_same_device(const gdt_ocl *a, const gdt_ocl *b);

/* 1 when ocl is a further queue of a device another context was made on
 * (gdt_ocl_create with opts->share), else 0. */
int gdt_ocl_is_shared_queue(const gdt_ocl *ocl);

/* With opts.profile: per kernel, the number of launches and the device time
 * they took, one line each, slowest first, to f (waits for the queue). */
void gdt_ocl_profile_dump(gdt_ocl *ocl, FILE *f);

/* Name of an OpenCL status code ("CL_OUT_OF_RESOURCES"); a constant
 * string, "unknown OpenCL error" for codes the table does not know. */
const char *gdt_ocl_error_name(int code);

#ifdef __cplusplus
}
#endif
#endif
