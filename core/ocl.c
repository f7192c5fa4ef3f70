/* ocl.c — the OpenCL host driver (see gdt_ocl.h).  The only file of
 * gdt-tile that includes the OpenCL headers. */
/* madvise(MADV_HUGEPAGE) is a Linux extension */
#define _DEFAULT_SOURCE 1
#define _XOPEN_SOURCE 700 /* nftw */
#define CL_TARGET_OPENCL_VERSION 120
#define CL_USE_DEPRECATED_OPENCL_1_2_APIS
#include <CL/cl.h>

#include "gdt_ocl.h"
#include "private/busy_union.h"
#include "private/kernel_text.h"

#include <ctype.h>
#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <ftw.h>
#include <inttypes.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#ifndef GDT_KERNEL_DIR
#define GDT_KERNEL_DIR "kernels"
#endif

#define OCL_HUGE_MIN ((size_t)4 << 20)
#define OCL_HUGE_ALIGN ((size_t)2 << 20)
#define OCL_NAME_MAX 640

struct gdt_ocl_kernel {
    cl_kernel k;
    char *name;
    size_t max_wg;
    uint64_t launches;
    double seconds; /* profiled device time */
};

struct gdt_ocl_program {
    cl_program prog;
    char *file;
    char *opts; /* the build options (a further queue reuses a program built with the same) */
    size_t nkernels;
    gdt_ocl_kernel *kernels;
    gdt_ocl_program *next;
};

struct gdt_ocl_buf {
    cl_mem mem;
    void *host; /* CPU devices: our own allocation behind the buffer */
    int borrowed; /* host is the caller's (gdt_ocl_buf_wrap): not freed */
    size_t bytes;
    const char *what;
    gdt_ocl_buf *prev, *next;
};

/* What the queues of one device share once it has more than one: the
 * built programs, and the device-busy union of their commands' intervals
 * (private/busy_union.h).  Under mu: q[0..nq) are the device's live
 * contexts, busy and every context's bq. */
typedef struct ocl_shared_prog {
    char *file, *opts;
    cl_program prog; /* retained */
} ocl_shared_prog;

static char *dup_str(const char *s);

/* The program-binary cache (see gdt_ocl.h): "programs" in the kernel cache
 * directory; empty: none.  Set once, by gdt_ocl_prepare_env. */
static char g_prog_dir[4096 + 16];

#define OCL_QUEUES_MAX 64
#define OCL_FOLD_AT 8192 /* stored intervals before a fold is tried */

typedef struct ocl_shared {
    pthread_mutex_t mu;
    gdt_ocl *q[OCL_QUEUES_MAX];
    size_t nq;
    ocl_shared_prog *progs;
    size_t nprogs;
    unsigned tags; /* program tags given to further queues so far */
    gdt_busy_union busy;
} ocl_shared;

struct gdt_ocl {
    cl_platform_id platform;
    cl_device_id device;
    cl_context ctx;
    cl_command_queue queue;
    int fp64;
    int is_cpu;
    int huge_pages; /* $GDT_THP is "1": big CPU buffers on transparent huge pages */
    unsigned compute_units;
    size_t device_max_wg; /* CL_DEVICE_MAX_WORK_GROUP_SIZE, at least 1 */
    uint64_t max_alloc;
    uint64_t global_mem;  /* CL_DEVICE_GLOBAL_MEM_SIZE */
    uint64_t live_bytes;  /* bytes of the buffers in bufs */
    uint64_t peak_bytes;  /* the most live_bytes has been */
    char name[OCL_NAME_MAX];
    char *kernel_dir;
    gdt_log *log;
    gdt_ocl_program *programs;
    gdt_ocl_buf *bufs;
    int profile;
    /* Device-busy accounting: every command carries an event (the queue
     * profiles); the events of commands not yet known complete wait in
     * pend; busy_collect adds their execution times to busy_s once a
     * blocking call or a finish has completed them (the queue is in
     * order, so every earlier command is then complete too). */
    cl_event *pend;
    size_t npend, cappend;
    double busy_s;
    /* A device with several queues (gdt_ocl_create with opts->share). */
    ocl_shared *sh;    /* NULL while the device has this queue alone */
    int further;       /* a further queue: the context is another's */
    gdt_busy_queue bq; /* under sh->mu: this queue in the device's busy union */
    unsigned progs_cached, progs_built; /* programs from the binary cache, from source */
    /* 0, or (a further queue whose device cannot share programs between
     * queues, gdt_ocl_queues_need_own_programs) a number no other queue of
     * the device had (1, 2, ... in the order they were made):
     * gdt_ocl_build then adds -DGDT_QUEUE_PROGRAMS=<tag>, so the runtime
     * sees programs of their own, never the shared ones. */
    unsigned program_tag;
};

#define OCL_PEND_MAX 65536 /* pending events before a finish collects them */

/* Where the next command's event goes: a new slot of pend, or NULL when
 * none can be had (the command then runs without one and its time is not
 * counted). */
static cl_event *ev_slot(gdt_ocl *ocl)
{
    if (ocl->npend == ocl->cappend) {
        size_t cap = ocl->cappend ? 2 * ocl->cappend : 256;
        cl_event *p;
        if (cap > OCL_PEND_MAX)
            return NULL;
        p = realloc(ocl->pend, cap * sizeof *p);
        if (p == NULL)
            return NULL;
        ocl->pend = p;
        ocl->cappend = cap;
    }
    return &ocl->pend[ocl->npend];
}

/* Counts the event just written to ev_begin's slot as pending. */
static void ev_keep(gdt_ocl *ocl, cl_event *slot)
{
    if (slot != NULL && *slot != NULL) {
        ocl->npend++;
        if (ocl->sh != NULL && !ocl->bq.pending) {
            pthread_mutex_lock(&ocl->sh->mu);
            ocl->bq.pending = 1;
            pthread_mutex_unlock(&ocl->sh->mu);
        }
    }
}

/* Folds the device's stored intervals that can no longer overlap one
 * still to come (busy_union.h).  sh->mu held. */
static void shared_fold(ocl_shared *sh, int all)
{
    const gdt_busy_queue *qs[OCL_QUEUES_MAX];
    for (size_t i = 0; i < sh->nq; i++)
        qs[i] = &sh->q[i]->bq;
    gdt_busy_fold(&sh->busy, qs, sh->nq, all);
}

/* The execution interval of a complete command's event, device clock;
 * 0 when the device does not report one. */
static int ev_interval(cl_event ev, cl_ulong *t0, cl_ulong *t1)
{
    *t0 = *t1 = 0;
    return clGetEventProfilingInfo(ev, CL_PROFILING_COMMAND_START, sizeof *t0, t0, NULL) ==
               CL_SUCCESS &&
           clGetEventProfilingInfo(ev, CL_PROFILING_COMMAND_END, sizeof *t1, t1, NULL) ==
               CL_SUCCESS &&
           *t1 > *t0;
}

/* busy_collect on a shared device: the intervals go to the union. */
static void shared_collect(gdt_ocl *ocl)
{
    ocl_shared *sh = ocl->sh;
    pthread_mutex_lock(&sh->mu);
    for (size_t i = 0; i < ocl->npend; i++) {
        cl_ulong t0, t1;
        if (ev_interval(ocl->pend[i], &t0, &t1))
            gdt_busy_add(&sh->busy, &ocl->bq, t0, t1);
        clReleaseEvent(ocl->pend[i]);
    }
    ocl->npend = 0;
    ocl->bq.pending = 0;
    if (sh->busy.n >= OCL_FOLD_AT)
        shared_fold(sh, 0);
    pthread_mutex_unlock(&sh->mu);
}

/* Adds the execution time of every pending event (all complete: called
 * after a blocking call or a finish) to busy_s and releases them. */
static void busy_collect(gdt_ocl *ocl)
{
    if (ocl->sh != NULL) {
        shared_collect(ocl);
        return;
    }
    for (size_t i = 0; i < ocl->npend; i++) {
        cl_ulong t0, t1;
        if (ev_interval(ocl->pend[i], &t0, &t1))
            ocl->busy_s += 1e-9 * (double)(t1 - t0);
        clReleaseEvent(ocl->pend[i]);
    }
    ocl->npend = 0;
}

/* Before a command: when the pending list is full, wait for the queue
 * and collect it, so that the list stays bounded. */
static void busy_make_room(gdt_ocl *ocl)
{
    if (ocl->npend == OCL_PEND_MAX && clFinish(ocl->queue) == CL_SUCCESS)
        busy_collect(ocl);
}

/* The slot for the next command's event, after making room; NULL: the
 * command goes without one. */
static cl_event *ev_begin(gdt_ocl *ocl)
{
    cl_event *ev;
    busy_make_room(ocl);
    ev = ev_slot(ocl);
    if (ev != NULL)
        *ev = NULL;
    return ev;
}

double gdt_ocl_busy_seconds(gdt_ocl *ocl)
{
    ocl_shared *sh = ocl->sh;
    double v;
    if (sh == NULL) {
        if (ocl->npend > 0 && clFinish(ocl->queue) == CL_SUCCESS)
            busy_collect(ocl);
        return ocl->busy_s;
    }
    if (ocl->further)
        return 0.0;
    /* no thread drives the device's other queues now (the contract) */
    for (size_t i = 0;; i++) {
        gdt_ocl *q;
        pthread_mutex_lock(&sh->mu);
        q = i < sh->nq ? sh->q[i] : NULL;
        pthread_mutex_unlock(&sh->mu);
        if (q == NULL)
            break;
        if (q->npend > 0 && clFinish(q->queue) == CL_SUCCESS)
            busy_collect(q);
    }
    pthread_mutex_lock(&sh->mu);
    v = gdt_busy_seconds(&sh->busy);
    pthread_mutex_unlock(&sh->mu);
    return v;
}

void gdt_ocl_program_counts(const gdt_ocl *ocl, unsigned *cached, unsigned *built,
                            const char **dir)
{
    *cached = ocl->progs_cached;
    *built = ocl->progs_built;
    *dir = g_prog_dir[0] != '\0' ? g_prog_dir : NULL;
}

int gdt_ocl_same_device(const gdt_ocl *a, const gdt_ocl *b)
{
    return a->device == b->device;
}

int gdt_ocl_is_shared_queue(const gdt_ocl *ocl)
{
    return ocl->further;
}

static void shared_free(ocl_shared *sh)
{
    for (size_t i = 0; i < sh->nprogs; i++) {
        free(sh->progs[i].file);
        free(sh->progs[i].opts);
        if (sh->progs[i].prog)
            clReleaseProgram(sh->progs[i].prog);
    }
    free(sh->progs);
    gdt_busy_free(&sh->busy);
    pthread_mutex_destroy(&sh->mu);
    free(sh);
}

/* Makes ocl a further queue of base's device: base's shared state, made
 * on the first such call from base's programs and its busy time so far
 * (base is idle: the contract of gdt_ocl_create).  own_programs: ocl gets
 * a program tag no other queue of the device has (tags are never reused,
 * so a queue made after another was destroyed still differs from all). */
static gdt_status shared_attach(gdt_ocl *ocl, gdt_ocl *base, int own_programs, gdt_error *err)
{
    ocl_shared *sh = base->sh;
    if (sh == NULL) {
        size_t np = 0;
        sh = calloc(1, sizeof *sh);
        if (sh == NULL)
            return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        for (gdt_ocl_program *p = base->programs; p != NULL; p = p->next)
            np++;
        sh->progs = calloc(np ? np : 1, sizeof *sh->progs);
        if (sh->progs == NULL || pthread_mutex_init(&sh->mu, NULL) != 0) {
            free(sh->progs);
            free(sh);
            return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        }
        for (gdt_ocl_program *p = base->programs; p != NULL; p = p->next) {
            ocl_shared_prog *sp = &sh->progs[sh->nprogs];
            sp->file = dup_str(p->file);
            sp->opts = dup_str(p->opts);
            if (sp->file == NULL || sp->opts == NULL) {
                free(sp->file);
                free(sp->opts);
                shared_free(sh);
                return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
            }
            sp->prog = p->prog;
            clRetainProgram(sp->prog);
            sh->nprogs++;
        }
        if (base->npend > 0 && clFinish(base->queue) == CL_SUCCESS)
            busy_collect(base);
        gdt_busy_init(&sh->busy);
        sh->busy.folded_s = base->busy_s;
        sh->q[sh->nq++] = base;
        base->sh = sh;
    }
    pthread_mutex_lock(&sh->mu);
    if (sh->nq == OCL_QUEUES_MAX) {
        pthread_mutex_unlock(&sh->mu);
        return gdt_error_set(err, GDT_EDEVICE, 5101,
                             "OpenCL device %s: more than %d command queues asked for", base->name,
                             OCL_QUEUES_MAX);
    }
    sh->q[sh->nq++] = ocl;
    ocl->sh = sh;
    ocl->further = 1;
    if (own_programs)
        ocl->program_tag = ++sh->tags;
    pthread_mutex_unlock(&sh->mu);
    return GDT_OK;
}

/* Takes ocl out of its device's shared state; the last one frees it. */
static void shared_detach(gdt_ocl *ocl)
{
    ocl_shared *sh = ocl->sh;
    int last;
    if (sh == NULL)
        return;
    pthread_mutex_lock(&sh->mu);
    for (size_t i = 0; i < sh->nq; i++)
        if (sh->q[i] == ocl) {
            sh->q[i] = sh->q[--sh->nq];
            break;
        }
    last = sh->nq == 0;
    pthread_mutex_unlock(&sh->mu);
    ocl->sh = NULL;
    if (last)
        shared_free(sh);
}

const char *gdt_ocl_error_name(int code)
{
    switch (code) {
#define E(x)                                                                                   \
    case x:                                                                                    \
        return #x
        E(CL_SUCCESS);
        E(CL_DEVICE_NOT_FOUND);
        E(CL_DEVICE_NOT_AVAILABLE);
        E(CL_COMPILER_NOT_AVAILABLE);
        E(CL_MEM_OBJECT_ALLOCATION_FAILURE);
        E(CL_OUT_OF_RESOURCES);
        E(CL_OUT_OF_HOST_MEMORY);
        E(CL_PROFILING_INFO_NOT_AVAILABLE);
        E(CL_MEM_COPY_OVERLAP);
        E(CL_IMAGE_FORMAT_MISMATCH);
        E(CL_IMAGE_FORMAT_NOT_SUPPORTED);
        E(CL_BUILD_PROGRAM_FAILURE);
        E(CL_MAP_FAILURE);
        E(CL_MISALIGNED_SUB_BUFFER_OFFSET);
        E(CL_EXEC_STATUS_ERROR_FOR_EVENTS_IN_WAIT_LIST);
        E(CL_COMPILE_PROGRAM_FAILURE);
        E(CL_LINKER_NOT_AVAILABLE);
        E(CL_LINK_PROGRAM_FAILURE);
        E(CL_DEVICE_PARTITION_FAILED);
        E(CL_KERNEL_ARG_INFO_NOT_AVAILABLE);
        E(CL_INVALID_VALUE);
        E(CL_INVALID_DEVICE_TYPE);
        E(CL_INVALID_PLATFORM);
        E(CL_INVALID_DEVICE);
        E(CL_INVALID_CONTEXT);
        E(CL_INVALID_QUEUE_PROPERTIES);
        E(CL_INVALID_COMMAND_QUEUE);
        E(CL_INVALID_HOST_PTR);
        E(CL_INVALID_MEM_OBJECT);
        E(CL_INVALID_IMAGE_FORMAT_DESCRIPTOR);
        E(CL_INVALID_IMAGE_SIZE);
        E(CL_INVALID_SAMPLER);
        E(CL_INVALID_BINARY);
        E(CL_INVALID_BUILD_OPTIONS);
        E(CL_INVALID_PROGRAM);
        E(CL_INVALID_PROGRAM_EXECUTABLE);
        E(CL_INVALID_KERNEL_NAME);
        E(CL_INVALID_KERNEL_DEFINITION);
        E(CL_INVALID_KERNEL);
        E(CL_INVALID_ARG_INDEX);
        E(CL_INVALID_ARG_VALUE);
        E(CL_INVALID_ARG_SIZE);
        E(CL_INVALID_KERNEL_ARGS);
        E(CL_INVALID_WORK_DIMENSION);
        E(CL_INVALID_WORK_GROUP_SIZE);
        E(CL_INVALID_WORK_ITEM_SIZE);
        E(CL_INVALID_GLOBAL_OFFSET);
        E(CL_INVALID_EVENT_WAIT_LIST);
        E(CL_INVALID_EVENT);
        E(CL_INVALID_OPERATION);
        E(CL_INVALID_GL_OBJECT);
        E(CL_INVALID_BUFFER_SIZE);
        E(CL_INVALID_MIP_LEVEL);
        E(CL_INVALID_GLOBAL_WORK_SIZE);
        E(CL_INVALID_PROPERTY);
        E(CL_INVALID_IMAGE_DESCRIPTOR);
        E(CL_INVALID_COMPILER_OPTIONS);
        E(CL_INVALID_LINKER_OPTIONS);
        E(CL_INVALID_DEVICE_PARTITION_COUNT);
#undef E
    case -1001:
        return "CL_PLATFORM_NOT_FOUND_KHR";
    default:
        return "unknown OpenCL error";
    }
}

static gdt_status cl_fail(gdt_error *err, const char *call, const char *what, cl_int rc)
{
    return gdt_error_set(err, GDT_EDEVICE, 5102, "OpenCL %s%s%s%s failed: %s (%d)", call,
                         what ? "(" : "", what ? what : "", what ? ")" : "",
                         gdt_ocl_error_name(rc), (int)rc);
}

static char *dup_str(const char *s)
{
    size_t n = strlen(s) + 1;
    char *d = malloc(n);
    if (d != NULL)
        memcpy(d, s, n);
    return d;
}

/* mkdir -p; returns 0 or an errno value. */
static int make_dirs(const char *path)
{
    char buf[4096];
    size_t n = strlen(path);
    if (n == 0 || n >= sizeof buf)
        return ENAMETOOLONG;
    memcpy(buf, path, n + 1);
    for (size_t i = 1; i <= n; i++) {
        if (buf[i] == '/' || buf[i] == '\0') {
            char c = buf[i];
            buf[i] = '\0';
            if (mkdir(buf, 0777) != 0 && errno != EEXIST)
                return errno;
            buf[i] = c;
        }
    }
    return 0;
}

static void dev_string(cl_device_id d, cl_device_info what, char *buf, size_t len);

/* 0 when dir is (now) a directory this process may write, else an errno
 * value; private: also owned by this user and closed to everyone else
 * (a directory in a shared temporary directory that another user could
 * have made, or could write kernel binaries into, is refused). */
static int usable_dir(const char *dir, int private)
{
    struct stat st;
    if (private) { /* made closed (its parent, the temporary directory, exists) */
        if (mkdir(dir, 0700) != 0 && errno != EEXIST)
            return errno;
    } else {
        int rc = make_dirs(dir);
        if (rc != 0)
            return rc;
    }
    if (lstat(dir, &st) != 0)
        return errno;
    if (!S_ISDIR(st.st_mode))
        return ENOTDIR;
    if (private && (st.st_uid != getuid() || (st.st_mode & 077) != 0))
        return EPERM;
    return access(dir, W_OK | X_OK) == 0 ? 0 : errno;
}

/* What name is among PoCL's temporary files: 1 "tempfile_" and the six
 * characters mkstemp chose (PoCL 3.1 leaves one, empty, at every start),
 * 2 that with the suffix of a file PoCL's build writes and then renames
 * into place (left behind, filled or not, by a build that was
 * interrupted), 0 anything else. */
static int pocl_tempfile_kind(const char *name)
{
    static const char *const suffixes[] = {".so",  ".so.o",   ".bc",     ".cl",  ".preproc.cl",
                                           ".spirv", ".binary", ".temp"};
    if (strncmp(name, "tempfile_", 9) != 0 || strlen(name) < 15)
        return 0;
    for (int i = 9; i < 15; i++)
        if (!isalnum((unsigned char)name[i]))
            return 0;
    if (name[15] == '\0')
        return 1;
    for (size_t i = 0; i < sizeof suffixes / sizeof suffixes[0]; i++)
        if (strcmp(name + 15, suffixes[i]) == 0)
            return 2;
    return 0;
}

/* Removes from PoCL's cache directory dir the temporary files PoCL leaves
 * behind (see gdt_ocl.h): this user's regular files named as
 * pocl_tempfile_kind says and older than OCL_TEMPFILE_AGE seconds (no
 * build takes that long, and none another process has just created, and
 * may be about to fill, is touched): the empty ones of every start, and in
 * a directory of gdt-tile's own (own) those of interrupted builds too.
 * Best effort: what cannot be read or removed is left. */
#define OCL_TEMPFILE_AGE 3600
static void sweep_pocl_tempfiles(const char *dir, int own)
{
    DIR *d = opendir(dir);
    struct dirent *e;
    time_t now = time(NULL);
    int fd;

    if (d == NULL)
        return;
    fd = dirfd(d);
    while ((e = readdir(d)) != NULL) {
        struct stat st;
        int kind = pocl_tempfile_kind(e->d_name);
        if (kind == 0 || fstatat(fd, e->d_name, &st, AT_SYMLINK_NOFOLLOW) != 0)
            continue;
        if (S_ISREG(st.st_mode) && st.st_uid == getuid() && st.st_mtime < now - OCL_TEMPFILE_AGE &&
            (own || (kind == 1 && st.st_size == 0)))
            (void)unlinkat(fd, e->d_name, 0);
    }
    closedir(d);
}

/* Whether name is made of n or more of the letters A..P, the alphabet of
 * PoCL's cache names (a hash, four bits a letter). */
static int pocl_letters(const char *name, size_t n)
{
    size_t k = 0;
    for (; name[k] != '\0'; k++)
        if (name[k] < 'A' || name[k] > 'P')
            return 0;
    return k >= n;
}

/* Whether name is a program binary's: 16 lowercase hex digits, ".bin". */
static int prog_entry_name(const char *name)
{
    if (strlen(name) != 20 || strcmp(name + 16, ".bin") != 0)
        return 0;
    for (int i = 0; i < 16; i++)
        if (!isdigit((unsigned char)name[i]) && (name[i] < 'a' || name[i] > 'f'))
            return 0;
    return 1;
}

static int remove_entry(const char *path, const struct stat *sb, int type, struct FTW *ftw)
{
    (void)sb;
    (void)ftw;
    if (type == FTW_DP)
        (void)rmdir(path);
    else
        (void)unlink(path);
    return 0; /* best effort: go on */
}

/* Removes from the kernel cache dir what no run has used for
 * OCL_CACHE_AGE seconds: program binaries (programs/<16 hex>.bin, whose
 * time a run that loads one renews) and, when pocl is set (a directory of
 * gdt-tile's own, not one the user shares through POCL_CACHE_DIR), PoCL's
 * program directories (<two letters>/<letters>, whose last_accessed file
 * PoCL 3.1 touches at every build; the directory's own time where there is
 * none).  Only this user's, never through a symbolic link.  A kernel text
 * that changes with an upgrade leaves its old entries behind: without this
 * the directory grows by every version's kernels.
 *
 * Every process that uses the directory holds a shared lock on its
 * ".in-use" file for its whole life; only a process that gets the lock
 * alone prunes (then keeps it shared), so no entry goes while another run
 * (an MPI rank started beside this one, say) may be loading it.  The
 * two-letter directories stay, empty or not: PoCL may be about to create
 * an entry in one.  Best effort, like the sweep above. */
#define OCL_CACHE_AGE (30L * 86400L)
static void prune_cache(const char *dir, int pocl)
{
    char path[4096 + 64];
    const time_t old = time(NULL) - OCL_CACHE_AGE;
    DIR *d;
    struct dirent *e;
    struct stat st;
    int lock;

    snprintf(path, sizeof path, "%s/.in-use", dir);
    lock = open(path, O_RDWR | O_CREAT | O_CLOEXEC, 0600);
    if (lock < 0)
        return;
    if (flock(lock, LOCK_EX | LOCK_NB) != 0) {
        (void)flock(lock, LOCK_SH); /* another run uses the cache: no pruning */
        return;                     /* the descriptor stays open, the lock held */
    }
    snprintf(path, sizeof path, "%s/programs", dir);
    if ((d = opendir(path)) != NULL) {
        int fd = dirfd(d);
        while ((e = readdir(d)) != NULL)
            if (prog_entry_name(e->d_name) &&
                fstatat(fd, e->d_name, &st, AT_SYMLINK_NOFOLLOW) == 0 && S_ISREG(st.st_mode) &&
                st.st_uid == getuid() && st.st_mtime < old)
                (void)unlinkat(fd, e->d_name, 0);
        closedir(d);
    }
    if (!pocl || (d = opendir(dir)) == NULL) {
        (void)flock(lock, LOCK_SH);
        return;
    }
    while ((e = readdir(d)) != NULL) {
        DIR *sub;
        struct dirent *f;
        if (strlen(e->d_name) != 2 || !pocl_letters(e->d_name, 2))
            continue;
        snprintf(path, sizeof path, "%s/%s", dir, e->d_name);
        if (lstat(path, &st) != 0 || !S_ISDIR(st.st_mode) || st.st_uid != getuid() ||
            (sub = opendir(path)) == NULL)
            continue;
        while ((f = readdir(sub)) != NULL) {
            char prog[sizeof path + 300];
            struct stat ps, la;
            if (!pocl_letters(f->d_name, 8) ||
                (size_t)snprintf(prog, sizeof prog, "%s/%s", path, f->d_name) >= sizeof prog ||
                lstat(prog, &ps) != 0 || !S_ISDIR(ps.st_mode) || ps.st_uid != getuid())
                continue;
            {
                char last[sizeof prog + 16];
                snprintf(last, sizeof last, "%s/last_accessed", prog);
                if (lstat(last, &la) == 0 && S_ISREG(la.st_mode))
                    ps.st_mtime = la.st_mtime;
            }
            if (ps.st_mtime < old)
                (void)nftw(prog, remove_entry, 16, FTW_DEPTH | FTW_PHYS);
        }
        closedir(sub);
    }
    closedir(d);
    (void)flock(lock, LOCK_SH);
}

/* Points POCL_CACHE_DIR at a usable directory (see gdt_ocl.h): the one
 * asked for, else the user's own POCL_CACHE_DIR, else
 * $XDG_CACHE_HOME/gdt-tile/pocl, else ~/.cache/gdt-tile/pocl, else
 * gdt-tile-pocl-<uid> in $TMPDIR or /tmp (read-only or missing homes: batch
 * jobs, containers).  Each one that cannot be used is a warning naming it.
 * None usable: the variable is removed (PoCL never sees an empty or
 * unusable one; it then chooses its own) and programs are not cached. */
static void set_pocl_cache(const char *cache_dir, gdt_log *log)
{
    char dir[4096];
    const char *env = getenv("POCL_CACHE_DIR");
    const char *xdg = getenv("XDG_CACHE_HOME"), *home = getenv("HOME");
    const char *tmp = getenv("TMPDIR");
    int rc;

    for (int step = 0; step < 5; step++) {
        int private = 0;
        dir[0] = '\0';
        if (step == 0 && cache_dir != NULL && cache_dir[0] != '\0')
            snprintf(dir, sizeof dir, "%s", cache_dir);
        else if (step == 1 && env != NULL && env[0] != '\0')
            snprintf(dir, sizeof dir, "%s", env);
        else if (step == 2 && xdg != NULL && xdg[0] == '/')
            snprintf(dir, sizeof dir, "%s/gdt-tile/pocl", xdg);
        else if (step == 3 && home != NULL && home[0] == '/')
            snprintf(dir, sizeof dir, "%s/.cache/gdt-tile/pocl", home);
        else if (step == 4) {
            snprintf(dir, sizeof dir, "%s/gdt-tile-pocl-%lu",
                     tmp != NULL && tmp[0] == '/' ? tmp : "/tmp", (unsigned long)getuid());
            private = 1;
        }
        if (dir[0] == '\0' || strlen(dir) + 16 >= sizeof dir)
            continue;
        rc = usable_dir(dir, private);
        if (rc != 0) {
            gdt_log_warn(log, 5150, "cannot use %s as the OpenCL kernel cache directory: %s",
                         dir, strerror(rc));
            continue;
        }
        if (env == NULL || strcmp(env, dir) != 0)
            setenv("POCL_CACHE_DIR", dir, 1);
        snprintf(g_prog_dir, sizeof g_prog_dir, "%s/programs", dir);
        sweep_pocl_tempfiles(dir, step != 1);
        prune_cache(dir, step != 1);
        return;
    }
    if (env != NULL)
        unsetenv("POCL_CACHE_DIR");
}

/* FNV-1a of n bytes, continued from h. */
static uint64_t fnv(uint64_t h, const void *data, size_t n)
{
    const unsigned char *b = data;
    for (size_t i = 0; i < n; i++) {
        h ^= b[i];
        h *= UINT64_C(1099511628211);
    }
    return h;
}

/* The key of a program binary: two independent 64-bit hashes of everything
 * the binary depends on (the platform, device and driver and their
 * versions, the build options, the whole source text with its headers
 * in place), each string with its terminating NUL. */
static void prog_key(const gdt_ocl *ocl, const char *opts, const char *src, uint64_t key[2])
{
    static const cl_platform_info pinfo[] = {CL_PLATFORM_NAME, CL_PLATFORM_VERSION};
    static const cl_device_info dinfo[] = {CL_DEVICE_NAME, CL_DEVICE_VERSION, CL_DRIVER_VERSION,
                                           CL_DEVICE_VENDOR};
    char buf[1024];
    key[0] = UINT64_C(14695981039346656037);
    key[1] = UINT64_C(0x6a09e667f3bcc909);
    for (size_t i = 0; i < sizeof pinfo / sizeof pinfo[0]; i++) {
        buf[0] = '\0';
        clGetPlatformInfo(ocl->platform, pinfo[i], sizeof buf - 1, buf, NULL);
        buf[sizeof buf - 1] = '\0';
        for (int k = 0; k < 2; k++)
            key[k] = fnv(key[k], buf, strlen(buf) + 1);
    }
    for (size_t i = 0; i < sizeof dinfo / sizeof dinfo[0]; i++) {
        dev_string(ocl->device, dinfo[i], buf, sizeof buf);
        for (int k = 0; k < 2; k++)
            key[k] = fnv(key[k], buf, strlen(buf) + 1);
    }
    for (int k = 0; k < 2; k++) {
        key[k] = fnv(key[k], opts, strlen(opts) + 1);
        key[k] = fnv(key[k], src, strlen(src) + 1);
    }
}

#define PROG_MAGIC "GDTPROG2"
#define PROG_HEADER 40 /* magic, key[0], key[1], binary size, FNV-1a of the binary */
#define PROG_MAX ((uint64_t)1 << 30)

/* The cached binary of key (malloc'ed, *n bytes), or NULL: none, or a
 * file that is not one prog_save wrote for key, whole (its header, length
 * and the hash of its body all agree: a damaged binary that the runtime
 * might still accept is never handed to it). */
static unsigned char *prog_load(const uint64_t key[2], size_t *n)
{
    char path[sizeof g_prog_dir + 32];
    unsigned char hdr[PROG_HEADER], *bin = NULL;
    uint64_t k0, k1, size, sum;
    FILE *f;

    if (g_prog_dir[0] == '\0')
        return NULL;
    snprintf(path, sizeof path, "%s/%016" PRIx64 ".bin", g_prog_dir, key[0]);
    f = fopen(path, "rb");
    if (f == NULL)
        return NULL;
    if (fread(hdr, 1, sizeof hdr, f) == sizeof hdr && memcmp(hdr, PROG_MAGIC, 8) == 0) {
        memcpy(&k0, hdr + 8, 8);
        memcpy(&k1, hdr + 16, 8);
        memcpy(&size, hdr + 24, 8);
        memcpy(&sum, hdr + 32, 8);
        if (k0 == key[0] && k1 == key[1] && size > 0 && size <= PROG_MAX &&
            (bin = malloc((size_t)size)) != NULL) {
            int extra = 0;
            if (fread(bin, 1, (size_t)size, f) != (size_t)size || fread(&extra, 1, 1, f) != 0 ||
                fnv(UINT64_C(14695981039346656037), bin, (size_t)size) != sum) {
                free(bin); /* cut short, longer than it says, or damaged */
                bin = NULL;
            } else {
                *n = (size_t)size;
                (void)futimens(fileno(f), NULL); /* in use: prune_cache keeps it */
            }
        }
    }
    fclose(f);
    return bin;
}

/* Saves p's binary under key, whole or not at all (a temporary renamed
 * over the name); any failure leaves the cache as it was. */
static void prog_save(const gdt_ocl *ocl, cl_program p, const uint64_t key[2])
{
    char path[sizeof g_prog_dir + 32], tmp[sizeof g_prog_dir + 64];
    unsigned char hdr[PROG_HEADER], *bin;
    size_t size = 0;
    uint64_t size64, sum;
    FILE *f;
    int ok;

    if (g_prog_dir[0] == '\0' ||
        clGetProgramInfo(p, CL_PROGRAM_BINARY_SIZES, sizeof size, &size, NULL) != CL_SUCCESS ||
        size == 0 || size > PROG_MAX || make_dirs(g_prog_dir) != 0)
        return;
    bin = malloc(size);
    if (bin == NULL)
        return;
    if (clGetProgramInfo(p, CL_PROGRAM_BINARIES, sizeof bin, &bin, NULL) != CL_SUCCESS) {
        free(bin);
        return;
    }
    snprintf(path, sizeof path, "%s/%016" PRIx64 ".bin", g_prog_dir, key[0]);
    snprintf(tmp, sizeof tmp, "%s.tmp-%ld-%p", path, (long)getpid(), (const void *)ocl);
    size64 = size;
    memcpy(hdr, PROG_MAGIC, 8);
    memcpy(hdr + 8, &key[0], 8);
    memcpy(hdr + 16, &key[1], 8);
    memcpy(hdr + 24, &size64, 8);
    sum = fnv(UINT64_C(14695981039346656037), bin, size);
    memcpy(hdr + 32, &sum, 8);
    f = fopen(tmp, "wb");
    ok = f != NULL && fwrite(hdr, 1, sizeof hdr, f) == sizeof hdr &&
         fwrite(bin, 1, size, f) == size;
    if (f != NULL && fclose(f) != 0)
        ok = 0;
    if (!ok || rename(tmp, path) != 0)
        unlink(tmp);
    free(bin);
}

/* PoCL's CPU device sets HWLOC_PLUGINS_PATH=/dev/null (overwriting) when
 * it first looks at the machine's topology, that is on whichever thread
 * first lists the devices: the core's start-up thread, beside pass 1.
 * Adding a variable reallocates the environment array and frees the old
 * one under any getenv running meanwhile (blosc's, inside the tile index's
 * write, crashed that way); set here, before that thread exists, PoCL's
 * later setenv only replaces this entry's value, which leaves the array in
 * place.  The value is PoCL's own.  It also applies to hwloc users that
 * start later in the process (under mpirun, MPI_Init's): they see the
 * machine's cores and memory as before, without the I/O devices hwloc's
 * plug-ins would add, which nothing here uses. */
static void set_hwloc_plugins(void)
{
    if (getenv("HWLOC_PLUGINS_PATH") == NULL)
        setenv("HWLOC_PLUGINS_PATH", "/dev/null", 0);
}

void gdt_ocl_prepare_env(const char *cache_dir, gdt_log *log)
{
    static pthread_mutex_t lock = PTHREAD_MUTEX_INITIALIZER;
    static int done;

    pthread_mutex_lock(&lock);
    if (!done) {
        set_pocl_cache(cache_dir, log);
        set_hwloc_plugins();
        done = 1;
    }
    pthread_mutex_unlock(&lock);
}

typedef struct dev_entry {
    cl_platform_id platform;
    cl_device_id device;
    unsigned pi, di;
    cl_device_type type;
} dev_entry;

/* Every device of every platform.  *out is malloc'ed (caller frees). */
static gdt_status enumerate(dev_entry **out, size_t *n_out, gdt_error *err)
{
    cl_uint np = 0;
    cl_platform_id *plats = NULL;
    dev_entry *devs = NULL;
    size_t n = 0, cap = 0;
    gdt_status st = GDT_OK;
    cl_int rc;

    *out = NULL;
    *n_out = 0;
    rc = clGetPlatformIDs(0, NULL, &np);
    if (rc == -1001 || np == 0)
        return gdt_error_set(err, GDT_EDEVICE, 5101,
                             "no OpenCL platform found (%s): install an OpenCL driver, e.g. "
                             "the Debian package pocl-opencl-icd",
                             gdt_ocl_error_name(rc == CL_SUCCESS ? -1001 : rc));
    if (rc != CL_SUCCESS)
        return cl_fail(err, "clGetPlatformIDs", NULL, rc);
    plats = malloc(np * sizeof *plats);
    if (plats == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    rc = clGetPlatformIDs(np, plats, NULL);
    if (rc != CL_SUCCESS) {
        st = cl_fail(err, "clGetPlatformIDs", NULL, rc);
        goto fail;
    }
    for (cl_uint p = 0; p < np; p++) {
        cl_uint nd = 0;
        cl_device_id *ids;
        rc = clGetDeviceIDs(plats[p], CL_DEVICE_TYPE_ALL, 0, NULL, &nd);
        if (rc == CL_DEVICE_NOT_FOUND || nd == 0)
            continue;
        if (rc != CL_SUCCESS) {
            st = cl_fail(err, "clGetDeviceIDs", NULL, rc);
            goto fail;
        }
        ids = malloc(nd * sizeof *ids);
        if (ids == NULL) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
            goto fail;
        }
        rc = clGetDeviceIDs(plats[p], CL_DEVICE_TYPE_ALL, nd, ids, NULL);
        if (rc != CL_SUCCESS) {
            free(ids);
            st = cl_fail(err, "clGetDeviceIDs", NULL, rc);
            goto fail;
        }
        for (cl_uint d = 0; d < nd; d++) {
            if (n == cap) {
                size_t nc = cap ? 2 * cap : 8;
                dev_entry *g = realloc(devs, nc * sizeof *g);
                if (g == NULL) {
                    free(ids);
                    st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
                    goto fail;
                }
                devs = g;
                cap = nc;
            }
            devs[n].platform = plats[p];
            devs[n].device = ids[d];
            devs[n].pi = p;
            devs[n].di = d;
            devs[n].type = 0;
            clGetDeviceInfo(ids[d], CL_DEVICE_TYPE, sizeof devs[n].type, &devs[n].type, NULL);
            n++;
        }
        free(ids);
    }
    if (n == 0) {
        st = gdt_error_set(err, GDT_EDEVICE, 5101,
                           "no OpenCL device found on %u platform(s) (%s)", (unsigned)np,
                           gdt_ocl_error_name(CL_DEVICE_NOT_FOUND));
        goto fail;
    }
    free(plats);
    *out = devs;
    *n_out = n;
    return GDT_OK;
fail:
    free(plats);
    free(devs);
    return st;
}

static int parse_uint(const char *s, const char *end, unsigned *v)
{
    unsigned long x = 0;
    if (s == end)
        return -1;
    for (; s < end; s++) {
        if (!isdigit((unsigned char)*s))
            return -1;
        x = x * 10 + (unsigned long)(*s - '0');
        if (x > 100000)
            return -1;
    }
    *v = (unsigned)x;
    return 0;
}

/* The device SPEC grammar (gdt_ocl.h), in one place: the syntax check of
 * the command line and the selection both use it. */
typedef enum spec_kind { SPEC_FIRST, SPEC_TYPE, SPEC_PAIR, SPEC_INDEX, SPEC_LOCAL } spec_kind;

typedef struct dev_spec {
    spec_kind kind;
    cl_device_type type; /* SPEC_TYPE, SPEC_LOCAL (0: any type) */
    unsigned a, b;       /* SPEC_INDEX: a; SPEC_PAIR: platform a, device b */
} dev_spec;

static gdt_status parse_spec(const char *spec, dev_spec *out, gdt_error *err)
{
    const char *colon;

    memset(out, 0, sizeof *out);
    if (spec == NULL || spec[0] == '\0')
        return GDT_OK;
    if (strcmp(spec, "cpu") == 0 || strcmp(spec, "gpu") == 0) {
        out->kind = SPEC_TYPE;
        out->type = spec[0] == 'c' ? CL_DEVICE_TYPE_CPU : CL_DEVICE_TYPE_GPU;
        return GDT_OK;
    }
    if (strcmp(spec, "local") == 0 || strcmp(spec, "cpu/local") == 0 ||
        strcmp(spec, "gpu/local") == 0) {
        out->kind = SPEC_LOCAL;
        out->type = spec[0] == 'c'   ? CL_DEVICE_TYPE_CPU
                    : spec[0] == 'g' ? CL_DEVICE_TYPE_GPU
                                     : 0;
        return GDT_OK;
    }
    colon = strchr(spec, ':');
    out->kind = colon != NULL ? SPEC_PAIR : SPEC_INDEX;
    if (colon != NULL ? parse_uint(spec, colon, &out->a) == 0 &&
                            parse_uint(colon + 1, spec + strlen(spec), &out->b) == 0
                      : parse_uint(spec, spec + strlen(spec), &out->a) == 0)
        return GDT_OK;
    return gdt_error_set(err, GDT_EUSAGE, 2110,
                         "--device %s: expected an index N, PLATFORM:DEVICE, 'cpu', 'gpu', "
                         "'local', 'cpu/local' or 'gpu/local' (numbers up to 100000); the "
                         "tiled run also takes a comma-separated list of them, 'all', "
                         "'cpu:all' and 'gpu:all'",
                         spec);
}

/* The device type of an "every device" element ("all", "cpu:all",
 * "gpu:all", lengths len) in *type (0: any); 0 when it is not one. */
static int all_spec(const char *s, size_t len, cl_device_type *type)
{
    if (len == 3 && strncmp(s, "all", 3) == 0) {
        *type = 0;
        return 1;
    }
    if (len == 7 && (strncmp(s, "cpu:all", 7) == 0 || strncmp(s, "gpu:all", 7) == 0)) {
        *type = s[0] == 'c' ? CL_DEVICE_TYPE_CPU : CL_DEVICE_TYPE_GPU;
        return 1;
    }
    return 0;
}

int gdt_ocl_spec_is_list(const char *value)
{
    cl_device_type t;
    return value != NULL &&
           (strchr(value, ',') != NULL || all_spec(value, strlen(value), &t));
}

gdt_status gdt_ocl_check_device_spec(const char *value, gdt_error *err)
{
    dev_spec ds;
    const char *p = value;
    char one[64];

    if (value == NULL || strchr(value, ',') == NULL) {
        cl_device_type t;
        if (value != NULL && all_spec(value, strlen(value), &t))
            return GDT_OK;
        return parse_spec(value, &ds, err);
    }
    for (;;) {
        const char *e = strchr(p, ',');
        size_t len = e != NULL ? (size_t)(e - p) : strlen(p);
        cl_device_type t;
        gdt_status st;
        if (len == 0 || len >= sizeof one)
            return gdt_error_set(err, GDT_EUSAGE, 2110,
                                 "--device %s: an empty or overlong element in the list", value);
        memcpy(one, p, len);
        one[len] = '\0';
        if (!all_spec(one, len, &t)) {
            gdt_error e1;
            gdt_error_clear(&e1);
            st = parse_spec(one, &ds, &e1);
            if (st != GDT_OK)
                return gdt_error_set(err, GDT_EUSAGE, 2110,
                                     "--device %s: the element '%s' is not a device: expected "
                                     "an index N, PLATFORM:DEVICE, 'cpu', 'gpu', 'local', "
                                     "'cpu/local', 'gpu/local', 'all', 'cpu:all' or 'gpu:all'",
                                     value, one);
        }
        if (e == NULL)
            return GDT_OK;
        p = e + 1;
    }
}

/* Appends the first len bytes of s to specs[0..*n) (capacity *cap).
 * returns: 0, or -1 out of memory. */
static int push_spec(char ***specs, size_t *n, size_t *cap, const char *s, size_t len)
{
    char *copy;
    if (*n == *cap) {
        size_t want = *cap ? 2 * *cap : 8;
        char **g = realloc(*specs, want * sizeof *g);
        if (g == NULL)
            return -1;
        *specs = g;
        *cap = want;
    }
    copy = malloc(len + 1);
    if (copy == NULL)
        return -1;
    memcpy(copy, s, len);
    copy[len] = '\0';
    (*specs)[(*n)++] = copy;
    return 0;
}

gdt_status gdt_ocl_device_list(const char *value, char ***out, size_t *n_out, gdt_error *err)
{
    char **specs = NULL;
    size_t n = 0, cap = 0;
    dev_entry *devs = NULL;
    size_t ndev = 0;
    const char *p = value != NULL ? value : "";
    gdt_status st = gdt_ocl_check_device_spec(value, err);

    *out = NULL;
    *n_out = 0;
    while (st == GDT_OK) {
        const char *e = strchr(p, ',');
        size_t len = e != NULL ? (size_t)(e - p) : strlen(p);
        cl_device_type t = 0;
        if (all_spec(p, len, &t)) {
            size_t before = n;
            if (devs == NULL)
                st = enumerate(&devs, &ndev, err);
            for (size_t i = 0; st == GDT_OK && i < ndev; i++) {
                char buf[32];
                if (t != 0 && (devs[i].type & t) == 0)
                    continue;
                snprintf(buf, sizeof buf, "%u:%u", devs[i].pi, devs[i].di);
                if (push_spec(&specs, &n, &cap, buf, strlen(buf)) != 0)
                    st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
            }
            if (st == GDT_OK && n == before)
                st = gdt_error_set(err, GDT_EDEVICE, 5101,
                                   "--device %.*s: no OpenCL device of that type among the "
                                   "%zu found (%s)",
                                   (int)len, p, ndev, gdt_ocl_error_name(CL_DEVICE_NOT_FOUND));
        } else if (push_spec(&specs, &n, &cap, p, len) != 0) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        }
        if (e == NULL)
            break;
        p = e + 1;
    }
    free(devs);
    if (st == GDT_OK && n > GDT_OCL_MAX_DEVICES)
        st = gdt_error_set(err, GDT_EUSAGE, 2110, "--device %s: %zu devices, at most %d",
                           value, n, GDT_OCL_MAX_DEVICES);
    if (st != GDT_OK) {
        gdt_ocl_device_list_free(specs, n);
        return st;
    }
    *out = specs;
    *n_out = n;
    return GDT_OK;
}

void gdt_ocl_device_list_free(char **specs, size_t n)
{
    for (size_t i = 0; specs != NULL && i < n; i++)
        free(specs[i]);
    free(specs);
}

/* Picks the device SPEC designates among devs[0..n). */
static gdt_status select_device(const dev_entry *devs, size_t n, const char *spec,
                                int local_rank, size_t *pick, gdt_error *err)
{
    dev_spec ds;
    gdt_status st = parse_spec(spec, &ds, err);

    if (st != GDT_OK)
        return st;
    if (ds.kind == SPEC_LOCAL) {
        size_t m = 0, want, seen = 0;
        for (size_t i = 0; i < n; i++)
            m += ds.type == 0 || (devs[i].type & ds.type) != 0;
        if (m == 0)
            return gdt_error_set(err, GDT_EDEVICE, 5101,
                                 "--device %s: no OpenCL device of that type among the %zu "
                                 "found (%s)",
                                 spec, n, gdt_ocl_error_name(CL_DEVICE_NOT_FOUND));
        want = (size_t)(local_rank > 0 ? local_rank : 0) % m;
        for (size_t i = 0; i < n; i++) {
            if (!(ds.type == 0 || (devs[i].type & ds.type) != 0))
                continue;
            if (seen++ == want) {
                *pick = i;
                return GDT_OK;
            }
        }
    }
    if (ds.kind == SPEC_FIRST) {
        *pick = 0;
        return GDT_OK;
    }
    if (ds.kind == SPEC_TYPE) {
        cl_device_type want = ds.type;
        for (size_t i = 0; i < n; i++) {
            if (devs[i].type & want) {
                *pick = i;
                return GDT_OK;
            }
        }
        return gdt_error_set(err, GDT_EDEVICE, 5101,
                             "--device %s: no OpenCL %s device among the %zu device(s) found "
                             "(%s)",
                             spec, spec, n, gdt_ocl_error_name(CL_DEVICE_NOT_FOUND));
    }
    if (ds.kind == SPEC_PAIR) {
        for (size_t i = 0; i < n; i++) {
            if (devs[i].pi == ds.a && devs[i].di == ds.b) {
                *pick = i;
                return GDT_OK;
            }
        }
        return gdt_error_set(err, GDT_EDEVICE, 5101,
                             "--device %s: no device %u on platform %u (%s)", spec, ds.b,
                             ds.a, gdt_ocl_error_name(CL_DEVICE_NOT_FOUND));
    }
    if (ds.a >= n)
        return gdt_error_set(err, GDT_EDEVICE, 5101,
                             "--device %s: only %zu OpenCL device(s) found (%s)", spec, n,
                             gdt_ocl_error_name(CL_DEVICE_NOT_FOUND));
    *pick = ds.a;
    return GDT_OK;
}

/* Appends what to the list out (cap bytes, "; " between items). */
static void caps_add(char *out, size_t cap, const char *what)
{
    size_t len = strlen(out);
    if (len + 1 < cap)
        snprintf(out + len, cap - len, "%s%s", len > 0 ? "; " : "", what);
}

int gdt_ocl_caps_missing(const char *profile, const char *c_version, const char *extensions,
                         char *out, size_t cap)
{
    int major = 0, minor = 0, missing = 0;
    char what[160];

    if (cap > 0)
        out[0] = '\0';
    /* "OpenCL C <major>.<minor> <vendor-specific information>" */
    if (c_version == NULL || sscanf(c_version, "OpenCL C %d.%d", &major, &minor) != 2 ||
        major < 1 || (major == 1 && minor < 2)) {
        snprintf(what, sizeof what, "OpenCL C 1.2 (the device offers \"%.100s\")",
                 c_version != NULL ? c_version : "");
        caps_add(out, cap, what);
        missing++;
    }
    if (profile == NULL || strcmp(profile, "FULL_PROFILE") != 0) {
        if (extensions == NULL || strstr(extensions, "cles_khr_int64") == NULL) {
            caps_add(out, cap, "64-bit integers (an embedded profile without cles_khr_int64)");
            missing++;
        }
    }
    return missing;
}

int gdt_ocl_queues_need_own_programs(const char *platform_version, int is_cpu)
{
    const char *v;
    int major = 0;
    if (!is_cpu || platform_version == NULL)
        return 0;
    /* "OpenCL 3.0 PoCL 3.1+debian  Linux, ..." */
    v = strstr(platform_version, "PoCL ");
    if (v == NULL || sscanf(v + 5, "%d", &major) != 1)
        return 0;
    return major < 7;
}

static void dev_string(cl_device_id d, cl_device_info what, char *buf, size_t len)
{
    size_t got = 0;
    buf[0] = '\0';
    if (clGetDeviceInfo(d, what, len - 1, buf, &got) != CL_SUCCESS)
        buf[0] = '\0';
    buf[len - 1] = '\0';
}

gdt_status gdt_ocl_list_devices(char *buf, size_t len, gdt_error *err)
{
    dev_entry *devs = NULL;
    size_t n = 0, used = 0;
    gdt_status st;

    if (len == 0)
        return GDT_OK;
    buf[0] = '\0';
    st = enumerate(&devs, &n, err);
    if (st != GDT_OK)
        return st;
    for (size_t i = 0; i < n; i++) {
        char name[256], pname[256];
        int w;
        dev_string(devs[i].device, CL_DEVICE_NAME, name, sizeof name);
        pname[0] = '\0';
        clGetPlatformInfo(devs[i].platform, CL_PLATFORM_NAME, sizeof pname - 1, pname, NULL);
        pname[sizeof pname - 1] = '\0';
        w = snprintf(buf + used, len - used, "%u:%u  %zu  %s  %s / %s\n", devs[i].pi,
                     devs[i].di, i,
                     (devs[i].type & CL_DEVICE_TYPE_GPU)   ? "gpu"
                     : (devs[i].type & CL_DEVICE_TYPE_CPU) ? "cpu"
                                                           : "other",
                     pname, name);
        if (w < 0 || (size_t)w >= len - used)
            break;
        used += (size_t)w;
    }
    free(devs);
    return GDT_OK;
}

gdt_status gdt_ocl_probe(const gdt_ocl_opts *opts, gdt_ocl_device_info *info, gdt_error *err)
{
    dev_entry *devs = NULL;
    size_t n = 0, pick = 0;
    cl_ulong v = 0;
    gdt_status st;

    memset(info, 0, sizeof *info);
    gdt_ocl_prepare_env(opts->cache_dir, opts->log);
    st = enumerate(&devs, &n, err);
    if (st == GDT_OK)
        st = select_device(devs, n, opts->device, opts->local_rank, &pick, err);
    if (st == GDT_OK) {
        info->is_cpu = (devs[pick].type & CL_DEVICE_TYPE_CPU) != 0;
        if (clGetDeviceInfo(devs[pick].device, CL_DEVICE_GLOBAL_MEM_SIZE, sizeof v, &v, NULL) ==
            CL_SUCCESS)
            info->global_mem = v;
        v = 0;
        if (clGetDeviceInfo(devs[pick].device, CL_DEVICE_MAX_MEM_ALLOC_SIZE, sizeof v, &v,
                            NULL) == CL_SUCCESS)
            info->max_alloc = v;
        dev_string(devs[pick].device, CL_DEVICE_NAME, info->name, sizeof info->name);
    }
    free(devs);
    return st;
}

gdt_status gdt_ocl_create(gdt_ocl **out, const gdt_ocl_opts *opts, gdt_error *err)
{
    gdt_ocl_opts defaults;
    gdt_ocl *ocl = NULL, *base = NULL;
    dev_entry *devs = NULL;
    size_t n = 0, pick = 0;
    char ext[8192], pname[256], dname[256];
    const char *kdir;
    cl_int rc;
    cl_uint cu = 0;
    cl_ulong maxalloc = 0;
    gdt_status st;

    *out = NULL;
    if (opts == NULL) {
        memset(&defaults, 0, sizeof defaults);
        opts = &defaults;
    }
    gdt_ocl_prepare_env(opts->cache_dir, opts->log);
    st = enumerate(&devs, &n, err);
    if (st != GDT_OK)
        return st;
    st = select_device(devs, n, opts->device, opts->local_rank, &pick, err);
    if (st != GDT_OK)
        goto fail;
    for (size_t i = 0; i < opts->nshare && base == NULL; i++)
        if (opts->share[i] != NULL && opts->share[i]->device == devs[pick].device)
            base = opts->share[i];
    ocl = calloc(1, sizeof *ocl);
    if (ocl == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    ocl->log = opts->log;
    ocl->platform = devs[pick].platform;
    ocl->device = devs[pick].device;
    ocl->is_cpu = (devs[pick].type & CL_DEVICE_TYPE_CPU) != 0;
    {
        const char *thp = getenv("GDT_THP");
        ocl->huge_pages = thp != NULL && strcmp(thp, "1") == 0;
    }

    kdir = opts->kernel_dir;
    if (kdir == NULL || kdir[0] == '\0')
        kdir = getenv("GDT_KERNEL_DIR");
    if (kdir == NULL || kdir[0] == '\0')
        kdir = GDT_KERNEL_DIR;
    ocl->kernel_dir = dup_str(kdir);
    if (ocl->kernel_dir == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }

    dev_string(ocl->device, CL_DEVICE_NAME, dname, sizeof dname);
    pname[0] = '\0';
    clGetPlatformInfo(ocl->platform, CL_PLATFORM_NAME, sizeof pname - 1, pname, NULL);
    pname[sizeof pname - 1] = '\0';
    /* Both names are cut so the pair always fits OCL_NAME_MAX. */
    snprintf(ocl->name, sizeof ocl->name, "%.*s / %.*s", (int)(OCL_NAME_MAX / 2 - 2), pname,
             (int)(OCL_NAME_MAX / 2 - 2), dname);
    dev_string(ocl->device, CL_DEVICE_EXTENSIONS, ext, sizeof ext);
    {
        char prof[64], cver[128], missing[512];
        dev_string(ocl->device, CL_DEVICE_PROFILE, prof, sizeof prof);
        dev_string(ocl->device, CL_DEVICE_OPENCL_C_VERSION, cver, sizeof cver);
        if (gdt_ocl_caps_missing(prof, cver, ext, missing, sizeof missing) > 0) {
            st = gdt_error_set(err, GDT_EDEVICE, 5107,
                               "OpenCL device %s cannot run the core: it lacks %s", ocl->name,
                               missing);
            goto fail;
        }
    }
    ocl->fp64 = strstr(ext, "cl_khr_fp64") != NULL && !opts->force_no_fp64;
    clGetDeviceInfo(ocl->device, CL_DEVICE_MAX_COMPUTE_UNITS, sizeof cu, &cu, NULL);
    clGetDeviceInfo(ocl->device, CL_DEVICE_MAX_MEM_ALLOC_SIZE, sizeof maxalloc, &maxalloc, NULL);
    ocl->compute_units = cu ? cu : 1;
    ocl->max_alloc = maxalloc;
    ocl->global_mem = 0;
    clGetDeviceInfo(ocl->device, CL_DEVICE_GLOBAL_MEM_SIZE, sizeof ocl->global_mem,
                    &ocl->global_mem, NULL);
    ocl->device_max_wg = 1;
    clGetDeviceInfo(ocl->device, CL_DEVICE_MAX_WORK_GROUP_SIZE, sizeof ocl->device_max_wg,
                    &ocl->device_max_wg, NULL);
    if (ocl->device_max_wg < 1)
        ocl->device_max_wg = 1;

    if (base != NULL) {
        /* a further queue of a device this process has a context on */
        ocl->ctx = base->ctx;
        clRetainContext(ocl->ctx);
    } else {
        ocl->ctx = clCreateContext(NULL, 1, &ocl->device, NULL, NULL, &rc);
        if (rc != CL_SUCCESS) {
            st = cl_fail(err, "clCreateContext", ocl->name, rc);
            goto fail;
        }
    }
    ocl->profile = opts->profile;
    /* always profiling: the device-busy time (gdt_ocl_busy_seconds) */
    ocl->queue = clCreateCommandQueue(ocl->ctx, ocl->device, CL_QUEUE_PROFILING_ENABLE, &rc);
    if (rc != CL_SUCCESS) {
        st = cl_fail(err, "clCreateCommandQueue", ocl->name, rc);
        goto fail;
    }
    if (base != NULL) {
        char pver[256];
        int own;
        pver[0] = '\0';
        clGetPlatformInfo(ocl->platform, CL_PLATFORM_VERSION, sizeof pver - 1, pver, NULL);
        pver[sizeof pver - 1] = '\0';
        own = gdt_ocl_queues_need_own_programs(pver, ocl->is_cpu);
        st = shared_attach(ocl, base, own, err);
        if (st != GDT_OK)
            goto fail;
        if (own) {
            const char *v = strstr(pver, "PoCL ");
            int vlen = v != NULL ? (int)strcspn(v + 5, " ") + 5 : 0;
            gdt_log_note(opts->log,
                         "OpenCL device %s: a further command queue, with programs of its own "
                         "(%.*s's CPU driver cannot run one program's kernels from two queues "
                         "at once)",
                         ocl->name, vlen, v != NULL ? v : "");
        }
        else
            gdt_log_note(opts->log, "OpenCL device %s: a further command queue", ocl->name);
    } else
        gdt_log_note(opts->log, "OpenCL device %s (%u compute units, %s, kernels from %s)",
                     ocl->name, ocl->compute_units,
                     ocl->fp64 ? "double-precision filter" : "integer predicates only",
                     ocl->kernel_dir);
    free(devs);
    *out = ocl;
    return GDT_OK;
fail:
    free(devs);
    gdt_ocl_destroy(ocl);
    return st;
}

void gdt_ocl_destroy(gdt_ocl *ocl)
{
    if (ocl == NULL)
        return;
    while (ocl->bufs != NULL)
        gdt_ocl_buf_release(ocl, ocl->bufs);
    while (ocl->programs != NULL) {
        gdt_ocl_program *p = ocl->programs;
        ocl->programs = p->next;
        for (size_t i = 0; i < p->nkernels; i++) {
            if (p->kernels[i].k)
                clReleaseKernel(p->kernels[i].k);
            free(p->kernels[i].name);
        }
        free(p->kernels);
        if (p->prog)
            clReleaseProgram(p->prog);
        free(p->file);
        free(p->opts);
        free(p);
    }
    if (ocl->queue) {
        if (clFinish(ocl->queue) == CL_SUCCESS)
            busy_collect(ocl);
        for (size_t i = 0; i < ocl->npend; i++) /* a failed finish: released uncounted */
            clReleaseEvent(ocl->pend[i]);
        ocl->npend = 0;
        clReleaseCommandQueue(ocl->queue);
    }
    shared_detach(ocl);
    free(ocl->pend);
    if (ocl->ctx)
        clReleaseContext(ocl->ctx);
    free(ocl->kernel_dir);
    free(ocl);
}

const char *gdt_ocl_device_name(const gdt_ocl *ocl) { return ocl->name; }
int gdt_ocl_has_fp64(const gdt_ocl *ocl) { return ocl->fp64; }
int gdt_ocl_is_cpu(const gdt_ocl *ocl) { return ocl->is_cpu; }
unsigned gdt_ocl_compute_units(const gdt_ocl *ocl) { return ocl->compute_units; }
size_t gdt_ocl_device_max_wg(const gdt_ocl *ocl) { return ocl->device_max_wg; }
uint64_t gdt_ocl_max_alloc(const gdt_ocl *ocl) { return ocl->max_alloc; }
uint64_t gdt_ocl_global_mem(const gdt_ocl *ocl) { return ocl->global_mem; }
uint64_t gdt_ocl_peak_bytes(const gdt_ocl *ocl) { return ocl->peak_bytes; }
const char *gdt_ocl_kernel_dir(const gdt_ocl *ocl) { return ocl->kernel_dir; }

gdt_status gdt_ocl_build(gdt_ocl *ocl, const char *file, const char *extra,
                         gdt_ocl_program **out, gdt_error *err)
{
    gdt_ocl_program *p = NULL;
    char path[4096], opts[4096 + 512];
    char *src = NULL, *log = NULL;
    cl_kernel *ks = NULL;
    cl_uint nk = 0;
    cl_int rc;
    int e;
    gdt_status st = GDT_OK;

    *out = NULL;
    snprintf(path, sizeof path, "%s/%s", ocl->kernel_dir, file);
    snprintf(opts, sizeof opts, "-cl-std=CL1.2%s%s%s", ocl->fp64 ? "" : " -DGDT_X_NO_F64",
             extra ? " " : "", extra ? extra : "");
    if (ocl->program_tag > 0) {
        size_t used = strlen(opts);
        snprintf(opts + used, sizeof opts - used, " -DGDT_QUEUE_PROGRAMS=%u", ocl->program_tag);
    }

    p = calloc(1, sizeof *p);
    if (p == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    p->file = dup_str(file);
    p->opts = dup_str(opts);
    if (p->file == NULL || p->opts == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    /* a further queue: the program the device's first context built from
     * the same file and options (the source text, headers included, is
     * part of neither, but both were read from the same directory at the
     * start of the same run, so it is not read again) */
    if (ocl->sh != NULL)
        for (size_t i = 0; i < ocl->sh->nprogs && p->prog == NULL; i++)
            if (strcmp(ocl->sh->progs[i].file, file) == 0 &&
                strcmp(ocl->sh->progs[i].opts, opts) == 0) {
                p->prog = ocl->sh->progs[i].prog;
                clRetainProgram(p->prog);
            }
    if (p->prog != NULL) {
        rc = CL_SUCCESS;
    } else {
        uint64_t key[2];
        size_t nbin = 0;
        unsigned char *bin;
        char failed[4096];
        /* the text with its headers in place: the options never name the
         * kernel directory, so a moved one keeps its cached binaries */
        e = gdt_kernel_text(ocl->kernel_dir, file, &src, NULL, failed, sizeof failed);
        if (e != 0) {
            st = gdt_error_set(err, GDT_EDEVICE, 5103, "cannot read the OpenCL kernel source %s: %s",
                               failed, e == ELOOP ? "headers nested too deep" : strerror(e));
            goto fail;
        }
        prog_key(ocl, opts, src, key);
        /* a binary this process or an earlier one built from the same source
         * for the same device and driver: no compiler front end (PoCL
         * preprocesses every source to find its own cache entry) */
        bin = prog_load(key, &nbin);
        if (bin != NULL) {
            const unsigned char *bins[1] = {bin};
            cl_int bst = CL_SUCCESS;
            p->prog = clCreateProgramWithBinary(ocl->ctx, 1, &ocl->device, &nbin, bins, &bst, &rc);
            if (rc == CL_SUCCESS && bst == CL_SUCCESS)
                rc = clBuildProgram(p->prog, 1, &ocl->device, opts, NULL, NULL);
            else
                rc = CL_INVALID_BINARY;
            if (rc != CL_SUCCESS && p->prog != NULL) {
                clReleaseProgram(p->prog); /* not usable: built from the source */
                p->prog = NULL;
            }
            ocl->progs_cached += p->prog != NULL;
            free(bin);
        }
        if (p->prog == NULL) {
            const char *srcs[1] = {src};
            p->prog = clCreateProgramWithSource(ocl->ctx, 1, srcs, NULL, &rc);
            if (rc != CL_SUCCESS) {
                st = cl_fail(err, "clCreateProgramWithSource", file, rc);
                goto fail;
            }
            rc = clBuildProgram(p->prog, 1, &ocl->device, opts, NULL, NULL);
            if (rc == CL_SUCCESS) {
                prog_save(ocl, p->prog, key);
                ocl->progs_built++;
            }
        }
    }
    if (rc != CL_SUCCESS) {
        size_t loglen = 0;
        clGetProgramBuildInfo(p->prog, ocl->device, CL_PROGRAM_BUILD_LOG, 0, NULL, &loglen);
        log = malloc(loglen + 1);
        if (log != NULL) {
            log[0] = '\0';
            clGetProgramBuildInfo(p->prog, ocl->device, CL_PROGRAM_BUILD_LOG, loglen, log, NULL);
            log[loglen] = '\0';
            gdt_log_note(ocl->log, "build log of %s:\n%s", path, log);
        }
        st = gdt_error_set(err, GDT_EDEVICE, 5104, "OpenCL clBuildProgram(%s) failed: %s (%d): %.600s",
                           path, gdt_ocl_error_name(rc), (int)rc, log ? log : "(no build log)");
        goto fail;
    }
    rc = clCreateKernelsInProgram(p->prog, 0, NULL, &nk);
    if (rc != CL_SUCCESS) {
        st = cl_fail(err, "clCreateKernelsInProgram", file, rc);
        goto fail;
    }
    ks = calloc(nk ? nk : 1, sizeof *ks);
    p->kernels = calloc(nk ? nk : 1, sizeof *p->kernels);
    if (ks == NULL || p->kernels == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    if (nk > 0) {
        rc = clCreateKernelsInProgram(p->prog, nk, ks, NULL);
        if (rc != CL_SUCCESS) {
            st = cl_fail(err, "clCreateKernelsInProgram", file, rc);
            goto fail;
        }
    }
    for (cl_uint i = 0; i < nk; i++) {
        char kname[256];
        kname[0] = '\0';
        clGetKernelInfo(ks[i], CL_KERNEL_FUNCTION_NAME, sizeof kname - 1, kname, NULL);
        kname[sizeof kname - 1] = '\0';
        p->kernels[i].k = ks[i];
        ks[i] = NULL;
        p->kernels[i].max_wg = 1;
        clGetKernelWorkGroupInfo(p->kernels[i].k, ocl->device, CL_KERNEL_WORK_GROUP_SIZE,
                                 sizeof p->kernels[i].max_wg, &p->kernels[i].max_wg, NULL);
        if (p->kernels[i].max_wg < 1)
            p->kernels[i].max_wg = 1;
        p->kernels[i].name = dup_str(kname);
        p->nkernels = i + 1;
        if (p->kernels[i].name == NULL) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
            goto fail;
        }
    }
    p->next = ocl->programs;
    ocl->programs = p;
    *out = p;
    p = NULL;
fail:
    if (ks != NULL) {
        for (cl_uint i = 0; i < nk; i++)
            if (ks[i])
                clReleaseKernel(ks[i]);
        free(ks);
    }
    if (p != NULL) {
        for (size_t i = 0; i < p->nkernels; i++) {
            clReleaseKernel(p->kernels[i].k);
            free(p->kernels[i].name);
        }
        free(p->kernels);
        if (p->prog)
            clReleaseProgram(p->prog);
        free(p->file);
        free(p->opts);
        free(p);
    }
    free(log);
    free(src);
    return st;
}

size_t gdt_ocl_program_kernel_count(const gdt_ocl_program *p) { return p->nkernels; }

size_t gdt_ocl_kernel_max_wg(const gdt_ocl_kernel *k) { return k->max_wg; }

const char *gdt_ocl_program_kernel_name(const gdt_ocl_program *p, size_t i)
{
    return i < p->nkernels ? p->kernels[i].name : NULL;
}

gdt_status gdt_ocl_kernel_get(gdt_ocl_program *p, const char *name, gdt_ocl_kernel **out,
                              gdt_error *err)
{
    for (size_t i = 0; i < p->nkernels; i++) {
        if (strcmp(p->kernels[i].name, name) == 0) {
            *out = &p->kernels[i];
            return GDT_OK;
        }
    }
    *out = NULL;
    return gdt_error_set(err, GDT_EDEVICE, 5105, "OpenCL program %s has no kernel %s (%s)",
                         p->file, name, gdt_ocl_error_name(CL_INVALID_KERNEL_NAME));
}

/* Records a new buffer in the context's list (released with it). */
static void buf_link(gdt_ocl *ocl, gdt_ocl_buf *b, size_t bytes, const char *what)
{
    b->bytes = bytes;
    b->what = what;
    ocl->live_bytes += bytes;
    if (ocl->live_bytes > ocl->peak_bytes)
        ocl->peak_bytes = ocl->live_bytes;
    b->next = ocl->bufs;
    if (ocl->bufs)
        ocl->bufs->prev = b;
    ocl->bufs = b;
}

gdt_status gdt_ocl_buf_create(gdt_ocl *ocl, size_t bytes, const char *what, gdt_ocl_buf **out,
                              gdt_error *err)
{
    gdt_ocl_buf *b;
    cl_int rc;
    size_t alloc = bytes < 16 ? 16 : bytes;

    *out = NULL;
    if (ocl->max_alloc != 0 && alloc > ocl->max_alloc)
        return gdt_error_set(err, GDT_EDEVICE, 5106,
                             "OpenCL buffer %s of %zu bytes exceeds the device limit of %" PRIu64
                             " bytes (%s)",
                             what, alloc, ocl->max_alloc, gdt_ocl_error_name(CL_INVALID_BUFFER_SIZE));
    b = calloc(1, sizeof *b);
    if (b == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    if (ocl->is_cpu && alloc >= OCL_HUGE_MIN) {
        /* On a CPU device the kernels use this memory directly.  It stays
         * on 4 KiB pages unless GDT_THP=1: huge pages save TLB misses
         * (about 0.3 s of user time in a 10M-point run), but faulting them
         * in may compact memory on the spot (Debian's default
         * defrag=madvise), and on virtual machines that hand free memory
         * back to the host it cost far more: touching 1 GiB took 0.55-2.3 s
         * on huge pages against 0.41-0.72 s on 4 KiB pages, and the
         * 10M-point run spent 1.3-1.9 s more system time. */
        size_t rounded = (alloc + OCL_HUGE_ALIGN - 1) / OCL_HUGE_ALIGN * OCL_HUGE_ALIGN;
        b->host = aligned_alloc(OCL_HUGE_ALIGN, rounded);
        if (b->host != NULL) {
#if defined(MADV_HUGEPAGE)
            if (ocl->huge_pages)
                madvise(b->host, rounded, MADV_HUGEPAGE);
#endif
            b->mem = clCreateBuffer(ocl->ctx, CL_MEM_READ_WRITE | CL_MEM_USE_HOST_PTR, alloc,
                                    b->host, &rc);
            if (rc != CL_SUCCESS) {
                free(b->host);
                b->host = NULL;
            }
        }
    }
    if (b->host == NULL)
        b->mem = clCreateBuffer(ocl->ctx, CL_MEM_READ_WRITE, alloc, NULL, &rc);
    if (rc != CL_SUCCESS) {
        free(b);
        return gdt_error_set(err, GDT_EDEVICE, 5106,
                             "OpenCL clCreateBuffer(%s, %zu bytes) failed: %s (%d)", what, alloc,
                             gdt_ocl_error_name(rc), (int)rc);
    }
    buf_link(ocl, b, bytes, what);
    *out = b;
    return GDT_OK;
}

void gdt_ocl_buf_release(gdt_ocl *ocl, gdt_ocl_buf *b)
{
    if (b == NULL)
        return;
    if (b->prev)
        b->prev->next = b->next;
    else
        ocl->bufs = b->next;
    if (b->next)
        b->next->prev = b->prev;
    ocl->live_bytes -= b->bytes;
    clReleaseMemObject(b->mem);
    if (!b->borrowed)
        free(b->host);
    free(b);
}

gdt_status gdt_ocl_buf_wrap(gdt_ocl *ocl, void *host, size_t bytes, const char *what,
                            gdt_ocl_buf **out, gdt_error *err)
{
    gdt_ocl_buf *b;
    cl_int rc;

    *out = NULL;
    if (!ocl->is_cpu || host == NULL || bytes == 0)
        return GDT_OK;
    b = calloc(1, sizeof *b);
    if (b == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    b->mem = clCreateBuffer(ocl->ctx, CL_MEM_READ_WRITE | CL_MEM_USE_HOST_PTR, bytes, host, &rc);
    if (rc != CL_SUCCESS) {
        free(b);
        return GDT_OK; /* the caller copies instead */
    }
    b->host = host;
    b->borrowed = 1;
    buf_link(ocl, b, bytes, what);
    *out = b;
    return GDT_OK;
}

gdt_status gdt_ocl_buf_sync_host(gdt_ocl *ocl, gdt_ocl_buf *b, gdt_error *err)
{
    cl_int rc;
    void *p = clEnqueueMapBuffer(ocl->queue, b->mem, CL_TRUE, CL_MAP_READ, 0, b->bytes, 0, NULL,
                                 NULL, &rc);
    if (rc != CL_SUCCESS)
        return cl_fail(err, "clEnqueueMapBuffer", b->what, rc);
    rc = clEnqueueUnmapMemObject(ocl->queue, b->mem, p, 0, NULL, NULL);
    if (rc == CL_SUCCESS)
        rc = clFinish(ocl->queue);
    if (rc == CL_SUCCESS)
        busy_collect(ocl);
    return rc == CL_SUCCESS ? GDT_OK : cl_fail(err, "clEnqueueUnmapMemObject", b->what, rc);
}

size_t gdt_ocl_buf_size(const gdt_ocl_buf *b) { return b->bytes; }

static gdt_status check_range(const gdt_ocl_buf *b, size_t off, size_t bytes, const char *op,
                              gdt_error *err)
{
    if (off > b->bytes || bytes > b->bytes - off)
        return gdt_error_set(err, GDT_EINTERNAL, 7501,
                             "%s of %zu bytes at offset %zu outside the %zu-byte buffer %s", op,
                             bytes, off, b->bytes, b->what);
    return GDT_OK;
}

gdt_status gdt_ocl_map_write(gdt_ocl *ocl, gdt_ocl_buf *b, size_t bytes, void **host,
                             gdt_error *err)
{
    cl_int rc;
    *host = NULL;
    if (check_range(b, 0, bytes, "map", err) != GDT_OK)
        return err->status;
    *host = clEnqueueMapBuffer(ocl->queue, b->mem, CL_TRUE, CL_MAP_WRITE_INVALIDATE_REGION, 0,
                               bytes, 0, NULL, NULL, &rc);
    if (rc != CL_SUCCESS) {
        *host = NULL;
        return cl_fail(err, "clEnqueueMapBuffer", b->what, rc);
    }
    return GDT_OK;
}

gdt_status gdt_ocl_unmap(gdt_ocl *ocl, gdt_ocl_buf *b, void *host, gdt_error *err)
{
    cl_int rc = clEnqueueUnmapMemObject(ocl->queue, b->mem, host, 0, NULL, NULL);
    if (rc == CL_SUCCESS)
        rc = clFinish(ocl->queue);
    if (rc == CL_SUCCESS)
        busy_collect(ocl);
    return rc == CL_SUCCESS ? GDT_OK : cl_fail(err, "clEnqueueUnmapMemObject", b->what, rc);
}

gdt_status gdt_ocl_write(gdt_ocl *ocl, gdt_ocl_buf *b, size_t offset, const void *src,
                         size_t bytes, gdt_error *err)
{
    cl_int rc;
    if (bytes == 0)
        return GDT_OK;
    if (check_range(b, offset, bytes, "write", err) != GDT_OK)
        return err->status;
    {
        cl_event *ev = ev_begin(ocl);
        rc = clEnqueueWriteBuffer(ocl->queue, b->mem, CL_TRUE, offset, bytes, src, 0, NULL, ev);
        if (rc == CL_SUCCESS) {
            ev_keep(ocl, ev);
            busy_collect(ocl);
        }
    }
    return rc == CL_SUCCESS ? GDT_OK : cl_fail(err, "clEnqueueWriteBuffer", b->what, rc);
}

gdt_status gdt_ocl_read(gdt_ocl *ocl, gdt_ocl_buf *b, size_t offset, void *dst, size_t bytes,
                        gdt_error *err)
{
    cl_int rc;
    if (bytes == 0)
        return GDT_OK;
    if (check_range(b, offset, bytes, "read", err) != GDT_OK)
        return err->status;
    {
        cl_event *ev = ev_begin(ocl);
        rc = clEnqueueReadBuffer(ocl->queue, b->mem, CL_TRUE, offset, bytes, dst, 0, NULL, ev);
        if (rc == CL_SUCCESS) {
            ev_keep(ocl, ev);
            busy_collect(ocl);
        }
    }
    return rc == CL_SUCCESS ? GDT_OK : cl_fail(err, "clEnqueueReadBuffer", b->what, rc);
}

gdt_status gdt_ocl_fill_u32(gdt_ocl *ocl, gdt_ocl_buf *b, size_t offset, uint32_t value,
                            size_t bytes, gdt_error *err)
{
    cl_int rc;
    if (bytes == 0)
        return GDT_OK;
    if (check_range(b, offset, bytes, "fill", err) != GDT_OK)
        return err->status;
    if (offset % 4 != 0 || bytes % 4 != 0)
        return gdt_error_set(err, GDT_EINTERNAL, 7501, "unaligned fill of buffer %s", b->what);
    {
        cl_event *ev = ev_begin(ocl);
        rc = clEnqueueFillBuffer(ocl->queue, b->mem, &value, sizeof value, offset, bytes, 0, NULL,
                                 ev);
        if (rc == CL_SUCCESS)
            ev_keep(ocl, ev);
    }
    return rc == CL_SUCCESS ? GDT_OK : cl_fail(err, "clEnqueueFillBuffer", b->what, rc);
}

gdt_status gdt_ocl_copy(gdt_ocl *ocl, gdt_ocl_buf *src, size_t src_off, gdt_ocl_buf *dst,
                        size_t dst_off, size_t bytes, gdt_error *err)
{
    cl_int rc;
    if (bytes == 0)
        return GDT_OK;
    if (check_range(src, src_off, bytes, "copy", err) != GDT_OK ||
        check_range(dst, dst_off, bytes, "copy", err) != GDT_OK)
        return err->status;
    {
        cl_event *ev = ev_begin(ocl);
        rc = clEnqueueCopyBuffer(ocl->queue, src->mem, dst->mem, src_off, dst_off, bytes, 0, NULL,
                                 ev);
        if (rc == CL_SUCCESS)
            ev_keep(ocl, ev);
    }
    return rc == CL_SUCCESS ? GDT_OK : cl_fail(err, "clEnqueueCopyBuffer", dst->what, rc);
}

static gdt_status set_arg(gdt_ocl_kernel *k, unsigned i, size_t size, const void *v,
                          gdt_error *err)
{
    cl_int rc = clSetKernelArg(k->k, i, size, v);
    if (rc != CL_SUCCESS) {
        char what[300];
        snprintf(what, sizeof what, "%s, argument %u", k->name, i);
        return cl_fail(err, "clSetKernelArg", what, rc);
    }
    return GDT_OK;
}

gdt_status gdt_ocl_arg_buf(gdt_ocl_kernel *k, unsigned i, gdt_ocl_buf *b, gdt_error *err)
{
    return set_arg(k, i, sizeof(cl_mem), &b->mem, err);
}

gdt_status gdt_ocl_arg_u32(gdt_ocl_kernel *k, unsigned i, uint32_t v, gdt_error *err)
{
    cl_uint x = v;
    return set_arg(k, i, sizeof x, &x, err);
}

gdt_status gdt_ocl_arg_i32(gdt_ocl_kernel *k, unsigned i, int32_t v, gdt_error *err)
{
    cl_int x = v;
    return set_arg(k, i, sizeof x, &x, err);
}

gdt_status gdt_ocl_arg_i64(gdt_ocl_kernel *k, unsigned i, int64_t v, gdt_error *err)
{
    cl_long x = v;
    return set_arg(k, i, sizeof x, &x, err);
}

gdt_status gdt_ocl_arg_local(gdt_ocl_kernel *k, unsigned i, size_t bytes, gdt_error *err)
{
    return set_arg(k, i, bytes, NULL, err);
}

gdt_status gdt_ocl_run(gdt_ocl *ocl, gdt_ocl_kernel *k, size_t global, size_t local,
                       gdt_error *err)
{
    size_t g = global, l = local;
    cl_int rc;
    if (global == 0)
        return GDT_OK;
    if (local != 0)
        g = (global + local - 1) / local * local;
    if (ocl->profile) {
        cl_event ev;
        cl_ulong t0 = 0, t1 = 0;
        rc = clEnqueueNDRangeKernel(ocl->queue, k->k, 1, NULL, &g, local ? &l : NULL, 0, NULL, &ev);
        if (rc != CL_SUCCESS)
            return cl_fail(err, "clEnqueueNDRangeKernel", k->name, rc);
        clWaitForEvents(1, &ev);
        clGetEventProfilingInfo(ev, CL_PROFILING_COMMAND_START, sizeof t0, &t0, NULL);
        clGetEventProfilingInfo(ev, CL_PROFILING_COMMAND_END, sizeof t1, &t1, NULL);
        clReleaseEvent(ev);
        k->launches++;
        k->seconds += 1e-9 * (double)(t1 - t0);
        ocl->busy_s += 1e-9 * (double)(t1 - t0);
        return GDT_OK;
    }
    {
        cl_event *ev = ev_begin(ocl);
        rc = clEnqueueNDRangeKernel(ocl->queue, k->k, 1, NULL, &g, local ? &l : NULL, 0, NULL,
                                    ev);
        if (rc == CL_SUCCESS)
            ev_keep(ocl, ev);
    }
    return rc == CL_SUCCESS ? GDT_OK : cl_fail(err, "clEnqueueNDRangeKernel", k->name, rc);
}

gdt_status gdt_ocl_finish(gdt_ocl *ocl, gdt_error *err)
{
    cl_int rc = clFinish(ocl->queue);
    if (rc == CL_SUCCESS)
        busy_collect(ocl);
    return rc == CL_SUCCESS ? GDT_OK : cl_fail(err, "clFinish", NULL, rc);
}

void gdt_ocl_profile_dump(gdt_ocl *ocl, FILE *f)
{
    double total = 0;
    size_t nk = 0, at = 0;
    gdt_ocl_kernel **all;
    clFinish(ocl->queue);
    for (gdt_ocl_program *p = ocl->programs; p != NULL; p = p->next)
        nk += p->nkernels;
    all = malloc((nk ? nk : 1) * sizeof *all);
    if (all == NULL)
        return;
    for (gdt_ocl_program *p = ocl->programs; p != NULL; p = p->next)
        for (size_t i = 0; i < p->nkernels; i++) {
            all[at++] = &p->kernels[i];
            total += p->kernels[i].seconds;
        }
    for (size_t i = 1; i < nk; i++)
        for (size_t j = i; j > 0 && all[j]->seconds > all[j - 1]->seconds; j--) {
            gdt_ocl_kernel *t = all[j];
            all[j] = all[j - 1];
            all[j - 1] = t;
        }
    for (size_t i = 0; i < nk && all[i]->launches > 0; i++)
        fprintf(f, "%-22s %8" PRIu64 " launches %9.4f s %5.1f%%\n", all[i]->name,
                all[i]->launches, all[i]->seconds, total > 0 ? 100 * all[i]->seconds / total : 0);
    fprintf(f, "%-22s %8s          %9.4f s\n", "(all kernels)", "", total);
    free(all);
}
