/* The start-up check of the inputs and outputs of a command (outpaths.h). */
#define _DEFAULT_SOURCE 1 /* realpath */
#include "private/outpaths.h"

#include <errno.h>
#include <limits.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "gdt_mesh_out.h"
#include "gdt_source.h"

/* What a path is, for comparing paths: the same file when both exist with
 * the same (st_dev, st_ino), or when neither exists and both name the same
 * entry of the same directory (canon: the resolved directory, "/", the last
 * component). */
typedef struct path_id {
    int exists;
    dev_t dev;
    ino_t ino;
    char *canon; /* owned; NULL when it exists, or its directory cannot be resolved */
} path_id;

/* The directory that holds the entry path names ("." for a bare name);
 * trailing slashes are ignored.  Owned by the caller; NULL: out of memory. */
static char *parent_of(const char *path)
{
    size_t len = strlen(path);
    char *p;
    while (len > 1 && path[len - 1] == '/')
        len--;
    while (len > 0 && path[len - 1] != '/')
        len--;
    while (len > 1 && path[len - 1] == '/')
        len--;
    if (len == 0)
        return strdup(".");
    p = malloc(len + 1);
    if (p != NULL) {
        memcpy(p, path, len);
        p[len] = '\0';
    }
    return p;
}

static void id_of(const char *path, path_id *id)
{
    struct stat sb;
    memset(id, 0, sizeof *id);
    if (stat(path, &sb) == 0) {
        id->exists = 1;
        id->dev = sb.st_dev;
        id->ino = sb.st_ino;
        return;
    }
    {
        char *dir = parent_of(path);
        char *rdir = dir != NULL ? realpath(dir, NULL) : NULL;
        const char *base = strrchr(path, '/');
        base = base != NULL ? base + 1 : path;
        if (rdir != NULL) {
            size_t l = strlen(rdir) + strlen(base) + 2;
            id->canon = malloc(l);
            if (id->canon != NULL)
                snprintf(id->canon, l, "%s/%s", rdir, base);
        }
        free(rdir);
        free(dir);
    }
}

static int same_id(const path_id *a, const path_id *b)
{
    if (a->exists && b->exists)
        return a->dev == b->dev && a->ino == b->ino;
    return !a->exists && !b->exists && a->canon != NULL && b->canon != NULL &&
           strcmp(a->canon, b->canon) == 0;
}

/* The directory dir must exist, be a directory and let us create files. */
static gdt_status check_dir_writable(const gdt_outpath *o, const char *dir, gdt_error *err)
{
    struct stat sb;
    if (stat(dir, &sb) != 0) {
        if (errno == ENOENT)
            return gdt_error_set(err, GDT_EUSAGE, 2206, "%s %s: directory %s does not exist",
                                 o->opt, o->path, dir);
        return gdt_error_set(err, GDT_EUSAGE, 2207, "%s %s: directory %s: %s", o->opt, o->path,
                             dir, strerror(errno));
    }
    if (!S_ISDIR(sb.st_mode))
        return gdt_error_set(err, GDT_EUSAGE, 2206, "%s %s: %s is not a directory", o->opt,
                             o->path, dir);
    if (access(dir, W_OK | X_OK) != 0)
        return gdt_error_set(err, GDT_EUSAGE, 2207, "%s %s: cannot create files in %s: %s",
                             o->opt, o->path, dir, strerror(errno));
    return GDT_OK;
}

/* One output on its own (and against the inputs' identities). */
static gdt_status check_one(const gdt_outpath *o, const char *const *inputs,
                            const path_id *in_ids, size_t ninputs, gdt_error *err)
{
    struct stat lsb, sb;
    size_t len = strlen(o->path);
    int have;

    if (len == 0)
        return gdt_error_set(err, GDT_EUSAGE, 2201, "%s: empty path", o->opt);
    if (lstat(o->path, &lsb) != 0) {
        gdt_status st;
        char *dir;
        if (errno != ENOENT)
            return gdt_error_set(err, GDT_EUSAGE, 2207, "%s %s: %s", o->opt, o->path,
                                 strerror(errno));
        if (!o->is_dir && o->path[len - 1] == '/')
            return gdt_error_set(err, GDT_EUSAGE, 2204,
                                 "%s %s: names a directory; the output is a file", o->opt,
                                 o->path);
        dir = parent_of(o->path);
        if (dir == NULL)
            return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        st = check_dir_writable(o, dir, err);
        free(dir);
        return st;
    }
    have = stat(o->path, &sb) == 0;
    for (size_t i = 0; have && i < ninputs; i++)
        if (in_ids[i].exists && in_ids[i].dev == sb.st_dev && in_ids[i].ino == sb.st_ino)
            return gdt_error_set(err, GDT_EUSAGE, 2202,
                                 "%s %s: is the input %s (the same file); gdt-tile never "
                                 "writes over an input",
                                 o->opt, o->path, inputs[i]);
    if (o->is_dir) {
        if (!have)
            return gdt_error_set(err, GDT_EUSAGE, 2205,
                                 "%s %s: is a symbolic link to nothing, not a directory",
                                 o->opt, o->path);
        if (!S_ISDIR(sb.st_mode))
            return gdt_error_set(err, GDT_EUSAGE, 2205,
                                 "%s %s: exists and is %s, not a directory", o->opt, o->path,
                                 gdt_file_kind(sb.st_mode));
        if (access(o->path, W_OK | X_OK) != 0)
            return gdt_error_set(err, GDT_EUSAGE, 2207, "%s %s: cannot create files in it: %s",
                                 o->opt, o->path, strerror(errno));
        return GDT_OK;
    }
    if (S_ISLNK(lsb.st_mode))
        return gdt_error_set(err, GDT_EUSAGE, 2203,
                             "%s %s: is a symbolic link; the output is written under a "
                             "temporary name and renamed over the path, which would replace "
                             "the link, not the file it names: give that file's own path",
                             o->opt, o->path);
    if (!S_ISREG(lsb.st_mode))
        return gdt_error_set(err, GDT_EUSAGE, 2204,
                             "%s %s: exists and is %s; the output is written under a "
                             "temporary name and renamed over the path, so the path must be "
                             "a regular file or a new name",
                             o->opt, o->path, gdt_file_kind(lsb.st_mode));
    {
        char *dir = parent_of(o->path);
        gdt_status st = dir == NULL ? gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory")
                                    : check_dir_writable(o, dir, err);
        free(dir);
        return st;
    }
}

/* An input inside the job directory (resolved paths): the job's files are
 * written and removed there. */
static gdt_status check_inside_job(const gdt_outpath *job, const char *const *inputs,
                                   size_t ninputs, gdt_error *err)
{
    gdt_status st = GDT_OK;
    char *rjob = realpath(job->path, NULL);
    size_t l;
    if (rjob == NULL)
        return GDT_OK; /* not there yet: nothing can be inside it */
    l = strlen(rjob);
    for (size_t i = 0; i < ninputs && st == GDT_OK; i++) {
        char *rin = realpath(inputs[i], NULL);
        if (rin != NULL && strncmp(rin, rjob, l) == 0 &&
            (rin[l] == '/' || (l == 1 && rjob[0] == '/')))
            st = gdt_error_set(err, GDT_EUSAGE, 2209,
                               "%s %s: holds the input %s; the job writes and removes its "
                               "files there, so give it a directory of its own",
                               job->opt, job->path, inputs[i]);
        free(rin);
    }
    free(rjob);
    return st;
}

gdt_status gdt_outpaths_check(const char *const *inputs, size_t ninputs,
                              const gdt_outpath *outs, size_t nouts, gdt_error *err)
{
    path_id *in_ids = calloc(ninputs + 1, sizeof *in_ids);
    path_id *out_ids = calloc(nouts + 1, sizeof *out_ids);
    gdt_status st = GDT_OK;

    if (in_ids == NULL || out_ids == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto done;
    }
    for (size_t i = 0; i < ninputs; i++)
        id_of(inputs[i], &in_ids[i]);
    for (size_t k = 0; k < nouts && st == GDT_OK; k++) {
        if (outs[k].path == NULL)
            continue;
        st = check_one(&outs[k], inputs, in_ids, ninputs, err);
        if (st == GDT_OK && outs[k].is_dir)
            st = check_inside_job(&outs[k], inputs, ninputs, err);
        if (st != GDT_OK)
            break;
        id_of(outs[k].path, &out_ids[k]);
        for (size_t m = 0; m < k && st == GDT_OK; m++)
            if (outs[m].path != NULL && same_id(&out_ids[m], &out_ids[k]))
                st = gdt_error_set(err, GDT_EUSAGE, 2208, "%s %s and %s %s: the same file",
                                   outs[m].opt, outs[m].path, outs[k].opt, outs[k].path);
    }
done:
    for (size_t i = 0; in_ids != NULL && i < ninputs; i++)
        free(in_ids[i].canon);
    for (size_t k = 0; out_ids != NULL && k < nouts; k++)
        free(out_ids[k].canon);
    free(in_ids);
    free(out_ids);
    return st;
}

gdt_status gdt_cli_check_paths(const gdt_options *opts, const char *job, gdt_error *err)
{
    gdt_outpath outs[8];
    size_t n = 0;
    char *prj = NULL;
    gdt_status st;

    for (size_t i = 0; i < opts->ninputs; i++) {
        st = gdt_source_check_path(opts->inputs[i], err);
        if (st != GDT_OK)
            return st;
    }
    if (opts->mode != GDT_MODE_INFO) {
        gdt_mesh_format f = gdt_mesh_format_of(opts->output);
        outs[n++] = (gdt_outpath){"-o", opts->output, 0};
        /* an OBJ's CRS file is written and renamed like the mesh itself */
        if (f == GDT_MESH_OBJ) {
            prj = gdt_mesh_prj_path(opts->output, f);
            if (prj == NULL)
                return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
            outs[n++] = (gdt_outpath){"-o (its .prj)", prj, 0};
        }
    }
    outs[n++] = (gdt_outpath){"--json", opts->json, 0};
    outs[n++] = (gdt_outpath){"--dem", opts->dem, 0};
    outs[n++] = (gdt_outpath){"--preview", opts->preview, 0};
    outs[n++] = (gdt_outpath){"--ground-out", opts->ground_out, 0};
    outs[n++] = (gdt_outpath){"--job", job, 1};
    st = gdt_outpaths_check(opts->inputs, opts->ninputs, outs, n, err);
    free(prj);
    return st;
}
