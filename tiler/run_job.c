/* run_job.c — the job directory of a tiled run: its paths, lock and
 * journal, the params and fingerprint that tie a job to its command, the
 * clean-up, and --resume (private/stages.h, private/job.h). */
#define _GNU_SOURCE /* st_mtim */
#include "private/ground_out.h"
#include "private/stages.h"

#include <dirent.h>
#include <errno.h>
#include <pthread.h>
#include <inttypes.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "gdt_grow.h"
#include "private/outpaths.h"
#include "private/tiled_files.h"
#include "private/tiled_run.h"

/* *created = 1 when this call made the directory. */
static gdt_status make_dir(const char *path, int *created, gdt_error *err)
{
    struct stat sb;
    *created = mkdir(path, 0777) == 0;
    if (*created)
        return GDT_OK;
    if (errno == EEXIST && stat(path, &sb) == 0 && S_ISDIR(sb.st_mode))
        return GDT_OK;
    return gdt_error_set(err, GDT_EIO, 4801, "%s: cannot create the job directory: %s", path,
                         strerror(errno));
}

static char *default_job(const char *output)
{
    size_t l = strlen(output);
    char *p = malloc(l + 9);
    if (p != NULL) {
        memcpy(p, output, l);
        memcpy(p + l, ".gdt-job", 9);
    }
    return p;
}

gdt_status tr_run_init(tr_run *c, const gdt_options *opts, gdt_error *err)
{
    memset(c, 0, sizeof *c);
    c->t_start = gdt_now();
    c->opts = opts;
    c->tile = opts->tile;
    c->lock_fd = -1;
    c->t_flushed = gdt_now();
    c->filter_comments[0] = c->filter_comment;
    c->filter_comments[1] = c->trim_comment;
    gdt_mesh_init(&c->slot[0].mesh);
    gdt_mesh_init(&c->slot[1].mesh);
    gdt_log_init(&c->log, opts->verbosity);
    gdt_progress_init(&c->prog, opts->verbosity);
    c->job = opts->job != NULL ? strdup(opts->job) : default_job(opts->output);
    c->tiles_dir = c->job != NULL ? tr_path_join(c->job, "tiles") : NULL;
    c->ground_bits = c->job != NULL ? tr_path_join(c->job, "ground.bits") : NULL;
    if (c->job == NULL || c->tiles_dir == NULL || c->ground_bits == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    /* every path (those the job recorded, for --resume) before any work */
    gdt_status st = gdt_cli_check_paths(opts, c->job, err);
    if (st == GDT_OK)
        st = tr_ground_out_check(opts, err);
    return st;
}

/* A growing text buffer. */
typedef struct tr_text {
    char *s;
    size_t len, cap;
    int failed;
} tr_text;

static void text_add(tr_text *t, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void text_add(tr_text *t, const char *fmt, ...)
{
    va_list ap;
    int n;
    if (t->failed)
        return;
    va_start(ap, fmt);
    n = vsnprintf(NULL, 0, fmt, ap);
    va_end(ap);
    if (n < 0 || tr_reserve(&t->s, &t->cap, t->len + (size_t)n + 1 + 256, 1) != 0) {
        t->failed = 1;
        return;
    }
    va_start(ap, fmt);
    vsnprintf(t->s + t->len, t->cap - t->len, fmt, ap);
    va_end(ap);
    t->len += (size_t)n;
}

/* Absolute form of a path (the current directory prefixed to a relative
 * one), so that a job keeps meaning the same files from any directory. */
static void text_abs(tr_text *t, const char *key, const char *path)
{
    char cwd[4096];
    if (path[0] == '/' || getcwd(cwd, sizeof cwd) == NULL)
        text_add(t, "%s=%s\n", key, path);
    else
        text_add(t, "%s=%s/%s\n", key, cwd, path);
}

/* The options and inputs that fix the output, one "key=value" per line
 * (not the output path: finished work serves any -o). */
static gdt_status build_params(const gdt_options *o, int tile, char **out, gdt_error *err)
{
    tr_text t = {NULL, 0, 0, 0};
    char filter[GDT_FILTER_COMMENT_MAX];
    text_add(&t, "tile=%d\ncell=%.17g\nhalo=%ld\ndup=%d\nquantum=%.17g\n", tile, o->cell,
             o->halo, (int)o->dup, o->quantum);
    gdt_filter_describe(&o->filter, filter, sizeof filter);
    text_add(&t, "filter=%s\n", filter);
    if (gdt_trim_on(&o->trim))
        text_add(&t, "trim=%.17g %.17g\n", o->trim.max_edge, o->trim.concavity);
    if (o->ground)
        text_add(&t, "ground=pmf %.17g %.17g %.17g %.17g %.17g %d\n", o->pmf.max_window,
                 o->pmf.slope, o->pmf.initial_distance, o->pmf.max_distance, o->pmf.cell,
                 o->pmf.exponential);
    text_add(&t, "inputs=%zu\n", o->ninputs);
    for (size_t i = 0; i < o->ninputs; i++) {
        if (strchr(o->inputs[i], '\n') != NULL) {
            free(t.s);
            return gdt_error_set(err, GDT_EUSAGE, 2106, "input path with a line break: %s",
                                 o->inputs[i]);
        }
        text_abs(&t, "input", o->inputs[i]);
    }
    if (t.failed) {
        free(t.s);
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    }
    *out = t.s;
    return GDT_OK;
}

/* Per input: size, modification time and a hash of its first and last
 * 64 KiB (the header and the tail of the records). */
static gdt_status build_fingerprint(const gdt_options *o, char **out, gdt_error *err)
{
    enum { PART = 65536 };
    tr_text t = {NULL, 0, 0, 0};
    unsigned char *buf = malloc(PART);
    gdt_status st = GDT_OK;

    if (buf == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    for (size_t i = 0; i < o->ninputs && st == GDT_OK; i++) {
        struct stat sb;
        uint64_t h1 = 0, h2 = 0;
        FILE *f = fopen(o->inputs[i], "rb");
        if (f == NULL || fstat(fileno(f), &sb) != 0) {
            st = gdt_error_set(err, GDT_EINPUT, 3802, "%s: cannot read: %s", o->inputs[i],
                               strerror(errno));
        } else {
            size_t n = fread(buf, 1, PART, f);
            h1 = gdt_hash64(buf, n, 1);
            if (sb.st_size > PART && fseeko(f, sb.st_size - PART, SEEK_SET) == 0) {
                n = fread(buf, 1, PART, f);
                h2 = gdt_hash64(buf, n, 2);
            }
            text_add(&t, "input %zu: size %lld, mtime %lld.%09ld, hash %016llx %016llx\n", i,
                     (long long)sb.st_size, (long long)sb.st_mtim.tv_sec,
                     (long)sb.st_mtim.tv_nsec, (unsigned long long)h1,
                     (unsigned long long)h2);
        }
        if (f != NULL)
            fclose(f);
    }
    free(buf);
    if (st == GDT_OK && t.failed)
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    if (st != GDT_OK) {
        free(t.s);
        return st;
    }
    *out = t.s != NULL ? t.s : strdup("");
    return *out != NULL ? GDT_OK : gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
}

/* The first line where a and b differ, as "was X, now Y". */
static void first_difference(const char *a, const char *b, char *msg, size_t len)
{
    while (*a != '\0' || *b != '\0') {
        size_t la = strcspn(a, "\n"), lb = strcspn(b, "\n");
        if (la != lb || memcmp(a, b, la) != 0) {
            snprintf(msg, len, "was '%.*s', now '%.*s'", (int)(la < 200 ? la : 200), a,
                     (int)(lb < 200 ? lb : 200), b);
            return;
        }
        a += la + (a[la] == '\n');
        b += lb + (b[lb] == '\n');
    }
    snprintf(msg, len, "no difference");
}

/* See stages.h. */
void tr_remove_job_journal(const char *job)
{
    static const char *const names[] = {"job.db", "job.db-wal", "job.db-shm", "job.db-journal",
                                        "index.vdb", "index.vdb.tmp", MF_NAME,
                                        MF_NAME ".tmp", MD_NAME, MD_NAME ".tmp",
                                        CHECK_PLY_NAME, "ground.bits"};
    for (size_t i = 0; i < sizeof names / sizeof names[0]; i++) {
        char *p = tr_path_join(job, names[i]);
        if (p != NULL)
            unlink(p);
        free(p);
    }
}

/* FNV-1a of a name: which share of a removal it falls in. */
static uint32_t name_hash(const char *s)
{
    uint32_t h = 2166136261u;
    for (; *s != '\0'; s++)
        h = (h ^ (unsigned char)*s) * 16777619u;
    return h;
}

/* Unlinkers of one removal: names[i] for i = first, first + step, ...
 * relative to the directory dirfd. */
#define UNLINK_THREADS 4
#define UNLINK_PER_THREAD 32 /* names a further thread must have to be worth starting */

typedef struct unlinker {
    int dirfd;
    char **names;
    size_t n, first, step;
} unlinker;

static void *unlink_main(void *arg)
{
    const unlinker *u = arg;
    for (size_t i = u->first; i < u->n; i += u->step)
        unlinkat(u->dirfd, u->names[i], 0);
    return NULL;
}

/* See stages.h.  An unlink waits for the file system's metadata (and, on
 * a file system mounted with discard, for the device) far longer than it
 * works, so the names are unlinked by up to UNLINK_THREADS threads at once;
 * without memory or threads, one by one here. */
void tr_remove_tile_share(const char *tiles_dir, int part, int parts)
{
    DIR *d = opendir(tiles_dir);
    struct dirent *e;
    char **names = NULL;
    size_t n = 0, cap = 0;
    unlinker u[UNLINK_THREADS];
    pthread_t tid[UNLINK_THREADS];
    int started[UNLINK_THREADS] = {0};
    size_t nt;
    if (d == NULL)
        return;
    while ((e = readdir(d)) != NULL) {
        char *nm;
        if (!((strncmp(e->d_name, "tile_", 5) == 0 || strncmp(e->d_name, "bucket_", 7) == 0 ||
               strncmp(e->d_name, "merge_", 6) == 0) &&
              (parts <= 1 || name_hash(e->d_name) % (uint32_t)parts == (uint32_t)part)))
            continue;
        nm = gdt_grow(&names, &cap, n + 1, sizeof *names, 256) == 0 ? strdup(e->d_name) : NULL;
        if (nm == NULL)
            unlinkat(dirfd(d), e->d_name, 0); /* out of memory: at once */
        else
            names[n++] = nm;
    }
    nt = n / UNLINK_PER_THREAD;
    nt = nt < 1 ? 1 : nt > UNLINK_THREADS ? UNLINK_THREADS : nt;
    for (size_t i = 0; i < nt; i++) {
        u[i].dirfd = dirfd(d);
        u[i].names = names;
        u[i].n = n;
        u[i].first = i;
        u[i].step = nt;
        started[i] = i > 0 && pthread_create(&tid[i], NULL, unlink_main, &u[i]) == 0;
    }
    for (size_t i = 0; i < nt; i++)
        if (!started[i])
            unlink_main(&u[i]); /* the first share, and any whose thread did not start */
    for (size_t i = 0; i < nt; i++)
        if (started[i])
            pthread_join(tid[i], NULL);
    for (size_t i = 0; i < n; i++)
        free(names[i]);
    free(names);
    closedir(d);
}

/* See stages.h. */
void tr_remove_job_files(const char *job, int final, int own_dir)
{
    char *tiles = tr_path_join(job, "tiles");
    /* the journal first: a removal cut short by a crash must not leave a
     * journal that vouches for files already gone */
    tr_remove_job_journal(job);
    if (tiles != NULL) {
        tr_remove_tile_share(tiles, 0, 1);
        rmdir(tiles);
        free(tiles);
    }
    {
        /* the ranks' --ground-out bits of an MPI job (ground.bits.R) */
        DIR *d = opendir(job);
        struct dirent *e;
        if (d != NULL) {
            while ((e = readdir(d)) != NULL)
                if (strncmp(e->d_name, "ground.bits.", 12) == 0)
                    unlinkat(dirfd(d), e->d_name, 0);
            closedir(d);
        }
    }
    if (!final)
        return;
    {
        char *lock = tr_path_join(job, "lock");
        if (lock != NULL)
            unlink(lock);
        free(lock);
    }
    if (own_dir)
        rmdir(job);
}

/* Opens or creates the journal and checks that it belongs to this command.
 * A journal without finished work (gdt_job_has_work) is taken over: its
 * params and fingerprint are rewritten.  The output path is recorded for
 * --resume but not compared.
 * returns GDT_EJOB 6903 (options differ), 6904 (an input changed). */
static gdt_status open_journal(tr_run *c, gdt_error *err)
{
    char *params = NULL, *fp = NULL, *old_params = NULL, *old_fp = NULL;
    char diff[512];
    int is_new = 0, has_work = 0;
    tr_text out = {NULL, 0, 0, 0}, products = {NULL, 0, 0, 0};
    gdt_status st = build_params(c->opts, c->tile, &params, err);

    if (st == GDT_OK)
        st = build_fingerprint(c->opts, &fp, err);
    if (st == GDT_OK) {
        text_abs(&out, "output", c->opts->output);
        if (!out.failed)
            out.s[--out.len] = '\0'; /* the line break */
        /* the products beside the mesh, for --resume (not in params: they
         * do not change the job's files) */
        if (c->opts->dem != NULL) {
            text_abs(&products, "dem", c->opts->dem);
            text_add(&products, "dem_res=%.17g\ndem_nodata=%.17g\n", c->opts->dem_res,
                     c->opts->dem_nodata);
            if (c->opts->preview != NULL)
                text_abs(&products, "preview", c->opts->preview);
        }
        if (c->opts->ground_out != NULL)
            text_abs(&products, "ground_out", c->opts->ground_out);
        if (out.failed || products.failed)
            st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    }
    if (st == GDT_OK)
        st = gdt_job_open(&c->jobdb, c->job, 1, &is_new, err);
    if (st == GDT_OK) {
        gdt_job_id(c->jobdb, c->job_id);
        if (!is_new)
            st = gdt_job_has_work(c->jobdb, &has_work, err);
    }
    if (st == GDT_OK && !is_new)
        st = gdt_job_get_meta(c->jobdb, "params", &old_params, err);
    if (st == GDT_OK && !is_new)
        st = gdt_job_get_meta(c->jobdb, "fingerprint", &old_fp, err);
    if (st != GDT_OK)
        goto done;
    if (!has_work && old_params != NULL && old_fp != NULL &&
        (strcmp(old_params, params) != 0 || strcmp(old_fp, fp) != 0)) {
        /* nothing finished there: the job becomes this command's */
        gdt_log_note(&c->log, "%s: taking over a job without finished work", c->job);
        free(old_params);
        free(old_fp);
        old_params = old_fp = NULL;
    }
    if (old_params != NULL && strcmp(old_params, params) != 0) {
        first_difference(old_params, params, diff, sizeof diff);
        st = gdt_error_set(err, GDT_EJOB, 6903,
                           "%s: the job there was started with other options or paths (%s); "
                           "rerun with --restart to discard it, or use another --job",
                           c->job, diff);
        goto done;
    }
    if (old_params != NULL && old_fp != NULL && strcmp(old_fp, fp) != 0) {
        size_t i = 0;
        const char *a = old_fp, *b = fp;
        while (*a != '\0' && *a == *b) {
            if (*a == '\n')
                i++;
            a++;
            b++;
        }
        first_difference(old_fp, fp, diff, sizeof diff);
        st = gdt_error_set(err, GDT_EJOB, 6904,
                           "%s: input changed since the job in %s started (%s); rerun with "
                           "--restart to start again",
                           i < c->opts->ninputs ? c->opts->inputs[i] : c->opts->inputs[0],
                           c->job, diff);
        goto done;
    }
    st = gdt_job_begin(c->jobdb, err);
    if (st == GDT_OK && (old_params == NULL || old_fp == NULL)) {
        st = gdt_job_set_meta(c->jobdb, "fingerprint", fp, err);
        if (st == GDT_OK)
            st = gdt_job_set_meta(c->jobdb, "params", params, err);
    } else if (st == GDT_OK) {
        c->s.resumed = 1;
    }
    if (st == GDT_OK)
        st = gdt_job_set_meta(c->jobdb, "output", out.s + strlen("output="), err);
    if (st == GDT_OK)
        st = gdt_job_set_meta(c->jobdb, "products", products.s != NULL ? products.s : "", err);
    if (st == GDT_OK)
        st = gdt_job_commit(c->jobdb, err);
done:
    free(out.s);
    free(products.s);
    free(params);
    free(fp);
    free(old_params);
    free(old_fp);
    return st;
}

gdt_status tr_run_prepare_job(tr_run *c, gdt_error *err)
{
    /* one run per job: the lock comes before anything in the directory is
     * read or removed (--restart must not remove a running job's files) */
    gdt_status st = make_dir(c->job, &c->created, err);
    if (st == GDT_OK)
        st = gdt_job_lock(c->job, c->created, &c->lock_fd, &c->own_dir, err);
    if (st == GDT_OK && c->opts->restart)
        tr_remove_job_files(c->job, 0, 0);
    if (st == GDT_OK)
        st = open_journal(c, err);
    return st;
}

/* Reads one "key=value" line of params (the first match); NULL if absent. */
static char *param_get(const char *params, const char *key, const char **next)
{
    size_t kl = strlen(key);
    const char *p = next != NULL && *next != NULL ? *next : params;
    while (*p != '\0') {
        size_t l = strcspn(p, "\n");
        if (l > kl && memcmp(p, key, kl) == 0 && p[kl] == '=') {
            char *v = malloc(l - kl);
            if (v != NULL) {
                memcpy(v, p + kl + 1, l - kl - 1);
                v[l - kl - 1] = '\0';
            }
            if (next != NULL)
                *next = p + l + (p[l] == '\n');
            return v;
        }
        p += l + (p[l] == '\n');
    }
    return NULL;
}

gdt_status gdt_cli_resume(const gdt_options *opts, gdt_error *err)
{
    gdt_options o = *opts;
    gdt_job *j = NULL;
    char *params = NULL, *v = NULL, *output = NULL, *products = NULL, *dem = NULL;
    char *preview = NULL, *ground_out = NULL;
    char **inputs = NULL;
    size_t n = 0;
    gdt_status st = gdt_job_open(&j, opts->resume, 0, NULL, err);

    if (st == GDT_OK)
        st = gdt_job_get_meta(j, "params", &params, err);
    if (st == GDT_OK)
        st = gdt_job_get_meta(j, "output", &output, err);
    if (st == GDT_OK)
        st = gdt_job_get_meta(j, "products", &products, err);
    gdt_job_close(j);
    /* the DEM the job's command asked for (jobs of earlier versions: none) */
    if (st == GDT_OK && products != NULL && (dem = param_get(products, "dem", NULL)) != NULL) {
        char *r = param_get(products, "dem_res", NULL), *nd = param_get(products, "dem_nodata", NULL);
        char *e1 = NULL, *e2 = NULL;
        o.dem = dem;
        o.preview = preview = param_get(products, "preview", NULL);
        if (r != NULL)
            o.dem_res = strtod(r, &e1);
        if (nd != NULL)
            o.dem_nodata = strtod(nd, &e2);
        o.dem_res_set = o.dem_res > 0;
        o.dem_nodata_set = 1;
        if (r == NULL || nd == NULL || *e1 != '\0' || *e2 != '\0' || !(o.dem_res >= 0) ||
            !isfinite(o.dem_res) || !isfinite(o.dem_nodata))
            st = gdt_error_set(err, GDT_EJOB, 6905, "%s: job record has a bad DEM entry",
                               opts->resume);
        free(r);
        free(nd);
    }
    if (st == GDT_OK && products != NULL)
        o.ground_out = ground_out = param_get(products, "ground_out", NULL);
    free(products);
    if (st == GDT_OK && params == NULL)
        st = gdt_error_set(err, GDT_EJOB, 6905,
                           "%s: the job there never recorded its options; start it again "
                           "with the original command",
                           opts->resume);
    if (st != GDT_OK) {
        free(output);
        free(params);
        free(dem);
        free(preview);
        free(ground_out);
        return st;
    }
#define NEED(key)                                                                            \
    do {                                                                                     \
        free(v);                                                                             \
        v = param_get(params, key, NULL);                                                    \
        if (v == NULL) {                                                                     \
            st = gdt_error_set(err, GDT_EJOB, 6905, "%s: job record lacks '%s'",             \
                               opts->resume, key);                                           \
            goto done;                                                                       \
        }                                                                                    \
    } while (0)
    NEED("tile");
    o.tile = atoi(v);
    o.tile_set = 1; /* the job's, whatever the device */
    NEED("cell");
    o.cell = strtod(v, NULL);
    NEED("halo");
    o.halo = strtol(v, NULL, 10);
    NEED("dup");
    o.dup = (gdt_dup_policy)atoi(v);
    NEED("quantum");
    o.quantum = strtod(v, NULL);
    NEED("filter");
    if (gdt_filter_from_description(&o.filter, v) != 0) {
        st = gdt_error_set(err, GDT_EJOB, 6905, "%s: job record has a bad filter '%s'",
                           opts->resume, v);
        goto done;
    }
    free(v);
    v = param_get(params, "trim", NULL);
    if (v != NULL) {
        char *end = NULL;
        o.trim.max_edge = strtod(v, &end);
        o.trim.concavity = strtod(end, &end);
        if (*end != '\0' || !(o.trim.max_edge >= 0) || !(o.trim.concavity >= 0) ||
            !isfinite(o.trim.max_edge) || !isfinite(o.trim.concavity)) {
            st = gdt_error_set(err, GDT_EJOB, 6905, "%s: job record has a bad trim '%s'",
                               opts->resume, v);
            goto done;
        }
    }
    free(v);
    v = param_get(params, "ground", NULL);
    if (v != NULL) {
        gdt_error e2;
        int used = 0;
        gdt_error_clear(&e2);
        o.ground = 1;
        if (sscanf(v, "pmf %lf %lf %lf %lf %lf %d%n", &o.pmf.max_window, &o.pmf.slope,
                   &o.pmf.initial_distance, &o.pmf.max_distance, &o.pmf.cell,
                   &o.pmf.exponential, &used) != 6 ||
            v[used] != '\0' || gdt_pmf_check(&o.pmf, &e2) != GDT_OK) {
            st = gdt_error_set(err, GDT_EJOB, 6905, "%s: job record has a bad ground filter "
                               "'%s'", opts->resume, v);
            goto done;
        }
    }
    NEED("inputs");
    n = (size_t)strtoull(v, NULL, 10);
#undef NEED
    /* Each input is a line of params, so a count beyond its length is a
     * damaged record (and would overflow n + 1 below). */
    if (n > strlen(params)) {
        st = gdt_error_set(err, GDT_EJOB, 6905, "%s: job record counts %s inputs",
                           opts->resume, v);
        goto done;
    }
    inputs = calloc(n + 1, sizeof *inputs);
    if (inputs == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto done;
    }
    {
        const char *next = NULL;
        for (size_t i = 0; i < n; i++) {
            inputs[i] = param_get(params, "input", &next);
            if (inputs[i] == NULL) {
                st = gdt_error_set(err, GDT_EJOB, 6905, "%s: job record lacks input %zu",
                                   opts->resume, i + 1);
                goto done;
            }
        }
    }
    free(v);
    v = output;
    output = NULL;
    if (v == NULL || n == 0) {
        st = gdt_error_set(err, GDT_EJOB, 6905, "%s: job record lacks the output or inputs",
                           opts->resume);
        goto done;
    }
    o.output = v;
    o.inputs = (const char **)inputs;
    o.ninputs = n;
    o.job = opts->resume;
    o.mode = GDT_MODE_RUN;
    st = gdt_cli_tiled(&o, err);
done:
    for (size_t i = 0; inputs != NULL && i < n; i++)
        free(inputs[i]);
    free(inputs);
    free(v);
    free(output);
    free(params);
    free(dem);
    free(preview);
    free(ground_out);
    return st;
}
