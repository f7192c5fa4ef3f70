/* ply_write — test tool: streams a seeded pseudo-random mesh through the PLY
 * writer and prints the values it wrote, for comparison with a reader.
 *
 *   ply_write [options] OUT.ply
 *     --vertices V        number of vertices (default 0)
 *     --faces F           number of faces (default 0; needs V >= 3 when F > 0)
 *     --seed S            generator seed (default 1)
 *     --chunk N           records per write call (default 4096)
 *     --epsg N | --wkt TEXT          CRS (default unknown)
 *     --lattice SX SY OX OY          (default 0.001 0.001 0 0)
 *     --comment TEXT      extra header comment (repeatable)
 *     --quiet             do not print the values
 *     --rss               print "maxrss_kib N" on stderr at the end
 *   Failure simulations (the writer must leave nothing at OUT.ply):
 *     --fsize-limit B     RLIMIT_FSIZE = B bytes, SIGXFSZ ignored: writes
 *                         beyond B fail with EFBIG
 *     --block-final       after the vertices, create a directory at OUT.ply so
 *                         that the final rename fails
 *     --abort-after-vertices   call gdt_ply_abort after the vertices
 *     --kill-after-vertices    raise SIGKILL after the vertices (a crash)
 *     --vertex-after-face      write one more vertex after the first faces
 *     --bad-index              the last face gets index V (out of range)
 *
 * Output on success: "V F", then V lines "x y z" (%.17g), then F lines
 * "a b c".  The vertex set mixes realistic CRS coordinates with extreme
 * doubles (+-DBL_MAX, subnormals, -0.0, random bit patterns).  Values are
 * generated chunk by chunk: the tool holds one chunk, never the mesh.
 * Exit status: 0, or the gdt_status of the first failure (2 on bad usage).
 */
#include <float.h>
#include <inttypes.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>

#include "gdt_check.h"
#include "gdt_ply.h"

#define MAX_COMMENTS 64

typedef struct opts {
    const char *out;
    uint64_t nvert, nface, seed;
    size_t chunk;
    gdt_ply_meta meta;
    const char *comments[MAX_COMMENTS];
    int quiet, rss, block_final, abort_after_v, kill_after_v, vertex_after_face, bad_index;
    unsigned long long fsize_limit;
} opts;

static double unit(uint64_t *s)
{
    return (double)(gdt_splitmix64(s) >> 11) * 0x1p-53;
}

static double gen_double(uint64_t *s)
{
    static const double special[] = {
        DBL_MAX,      -DBL_MAX,      DBL_MIN, -DBL_MIN,  0x1p-1074,
        -0x1p-1074,   -0.0,          0.0,     1.0 / 3.0, -9007199254740993.0,
        2147483647.0, -2147483648.5, 1e300,   -1e-300,
    };
    uint64_t kind = gdt_splitmix64(s) % 8;
    if (kind == 0) {
        for (;;) {
            uint64_t bits = gdt_splitmix64(s);
            double d;
            memcpy(&d, &bits, sizeof d);
            if (isfinite(d))
                return d;
        }
    }
    if (kind == 1)
        return special[gdt_splitmix64(s) % (sizeof special / sizeof special[0])];
    if (kind == 2)
        return (unit(s) - 0.5) * 4e7; /* signed, far from the origin */
    /* Projected CRS coordinates with millimetre steps. */
    return 300000.0 + (double)(gdt_splitmix64(s) % 400000000ull) * 0.001;
}

static int parse_u64(const char *s, uint64_t *out)
{
    char *end = NULL;
    if (s == NULL || *s == '\0' || *s == '-')
        return -1;
    *out = strtoull(s, &end, 10);
    return *end == '\0' ? 0 : -1;
}

static int parse_double(const char *s, double *out)
{
    char *end = NULL;
    if (s == NULL)
        return -1;
    *out = strtod(s, &end);
    return end != s && *end == '\0' ? 0 : -1;
}

static int usage(const char *msg)
{
    fprintf(stderr, "ply_write: %s (see the comment at the top of ply_write.c)\n", msg);
    return 2;
}

static int parse_args(int argc, char **argv, opts *o)
{
    uint64_t v;
    memset(o, 0, sizeof *o);
    o->seed = 1;
    o->chunk = 4096;
    o->meta.lattice.sx = o->meta.lattice.sy = 0.001;
    o->meta.comments = o->comments;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        const char *next = i + 1 < argc ? argv[i + 1] : NULL;
        if (strcmp(a, "--vertices") == 0 && parse_u64(next, &o->nvert) == 0) {
            i++;
        } else if (strcmp(a, "--faces") == 0 && parse_u64(next, &o->nface) == 0) {
            i++;
        } else if (strcmp(a, "--seed") == 0 && parse_u64(next, &o->seed) == 0) {
            i++;
        } else if (strcmp(a, "--chunk") == 0 && parse_u64(next, &v) == 0 && v > 0 &&
                   v <= ((uint64_t)1 << 20)) {
            o->chunk = (size_t)v;
            i++;
        } else if (strcmp(a, "--epsg") == 0 && parse_u64(next, &v) == 0 && v <= INT32_MAX) {
            o->meta.epsg = (int)v;
            i++;
        } else if (strcmp(a, "--wkt") == 0 && next != NULL) {
            o->meta.crs_wkt = next;
            i++;
        } else if (strcmp(a, "--lattice") == 0 && i + 4 < argc &&
                   parse_double(argv[i + 1], &o->meta.lattice.sx) == 0 &&
                   parse_double(argv[i + 2], &o->meta.lattice.sy) == 0 &&
                   parse_double(argv[i + 3], &o->meta.lattice.ox) == 0 &&
                   parse_double(argv[i + 4], &o->meta.lattice.oy) == 0) {
            i += 4;
        } else if (strcmp(a, "--comment") == 0 && next != NULL &&
                   o->meta.ncomments < MAX_COMMENTS) {
            o->comments[o->meta.ncomments++] = next;
            i++;
        } else if (strcmp(a, "--fsize-limit") == 0 && parse_u64(next, &v) == 0) {
            o->fsize_limit = v;
            i++;
        } else if (strcmp(a, "--quiet") == 0) {
            o->quiet = 1;
        } else if (strcmp(a, "--rss") == 0) {
            o->rss = 1;
        } else if (strcmp(a, "--block-final") == 0) {
            o->block_final = 1;
        } else if (strcmp(a, "--abort-after-vertices") == 0) {
            o->abort_after_v = 1;
        } else if (strcmp(a, "--kill-after-vertices") == 0) {
            o->kill_after_v = 1;
        } else if (strcmp(a, "--vertex-after-face") == 0) {
            o->vertex_after_face = 1;
        } else if (strcmp(a, "--bad-index") == 0) {
            o->bad_index = 1;
        } else if (a[0] != '-' && o->out == NULL) {
            o->out = a;
        } else {
            return usage(a);
        }
    }
    if (o->out == NULL)
        return usage("no output path");
    if (o->nface > 0 && o->nvert < 3)
        return usage("faces need at least 3 vertices");
    if (o->nvert > GDT_PLY_MAX_VERTICES)
        return usage("too many vertices");
    return 0;
}

static gdt_status write_vertices(gdt_ply_writer *w, const opts *o, double *buf, gdt_error *err)
{
    uint64_t s = o->seed;
    for (uint64_t done = 0; done < o->nvert;) {
        size_t k = o->nvert - done < o->chunk ? (size_t)(o->nvert - done) : o->chunk;
        gdt_status st;
        for (size_t i = 0; i < 3 * k; i++)
            buf[i] = gen_double(&s);
        st = gdt_ply_write_vertices(w, buf, k, err);
        if (st != GDT_OK)
            return st;
        for (size_t i = 0; i < k && !o->quiet; i++)
            printf("%.17g %.17g %.17g\n", buf[3 * i], buf[3 * i + 1], buf[3 * i + 2]);
        done += k;
    }
    return GDT_OK;
}

static gdt_status write_faces(gdt_ply_writer *w, const opts *o, int32_t *buf, gdt_error *err)
{
    uint64_t s = o->seed ^ 0x5bd1e995ull;
    for (uint64_t done = 0; done < o->nface;) {
        size_t k = o->nface - done < o->chunk ? (size_t)(o->nface - done) : o->chunk;
        gdt_status st;
        for (size_t i = 0; i < k; i++) {
            int32_t *t = buf + 3 * i;
            t[0] = (int32_t)(gdt_splitmix64(&s) % o->nvert);
            do
                t[1] = (int32_t)(gdt_splitmix64(&s) % o->nvert);
            while (t[1] == t[0]);
            do
                t[2] = (int32_t)(gdt_splitmix64(&s) % o->nvert);
            while (t[2] == t[0] || t[2] == t[1]);
        }
        if (o->bad_index && done + k == o->nface)
            buf[3 * k - 1] = (int32_t)o->nvert;
        st = gdt_ply_write_faces(w, buf, k, err);
        if (st != GDT_OK)
            return st;
        for (size_t i = 0; i < k && !o->quiet; i++)
            printf("%" PRId32 " %" PRId32 " %" PRId32 "\n", buf[3 * i], buf[3 * i + 1],
                   buf[3 * i + 2]);
        done += k;
        if (o->vertex_after_face) {
            static const double extra[3] = {1.0, 2.0, 3.0};
            st = gdt_ply_write_vertices(w, extra, 1, err);
            if (st != GDT_OK)
                return st;
        }
    }
    return GDT_OK;
}

int main(int argc, char **argv)
{
    opts o;
    gdt_error err;
    gdt_ply_writer *w = NULL;
    double *vbuf = NULL;
    int32_t *fbuf = NULL;
    gdt_status st = GDT_OK;
    int rc = parse_args(argc, argv, &o);

    if (rc != 0)
        return rc;
    gdt_error_clear(&err);
    if (o.fsize_limit > 0) {
        struct rlimit rl;
        rl.rlim_cur = rl.rlim_max = (rlim_t)o.fsize_limit;
        signal(SIGXFSZ, SIG_IGN);
        if (setrlimit(RLIMIT_FSIZE, &rl) != 0) {
            perror("ply_write: setrlimit");
            return 2;
        }
    }
    vbuf = malloc(3 * o.chunk * sizeof *vbuf);
    fbuf = malloc(3 * o.chunk * sizeof *fbuf);
    if (vbuf == NULL || fbuf == NULL) {
        st = gdt_error_set(&err, GDT_EINTERNAL, 7001, "out of memory");
        goto done;
    }
    st = gdt_ply_create(&w, o.out, &o.meta, &err);
    if (st != GDT_OK)
        goto done;
    if (!o.quiet)
        printf("%" PRIu64 " %" PRIu64 "\n", o.nvert, o.nface);
    st = write_vertices(w, &o, vbuf, &err);
    if (st != GDT_OK)
        goto done;
    if (o.kill_after_v) {
        fflush(stdout);
        raise(SIGKILL);
    }
    if (o.abort_after_v) {
        gdt_ply_abort(w);
        w = NULL;
        goto done;
    }
    if (o.block_final && mkdir(o.out, 0777) != 0) {
        perror("ply_write: mkdir");
        gdt_ply_abort(w);
        w = NULL;
        st = GDT_EUSAGE;
        goto done;
    }
    st = write_faces(w, &o, fbuf, &err);
    if (st != GDT_OK)
        goto done;
    st = gdt_ply_finish(w, &err);
    w = NULL;

done:
    if (w != NULL) {
        /* After a failure the temporary is already gone; finishing must
         * report the same error again and leave nothing. */
        gdt_error again;
        gdt_error_clear(&again);
        if (gdt_ply_finish(w, &again) == GDT_OK) {
            fprintf(stderr, "ply_write: finish succeeded after a failure\n");
            st = GDT_EINTERNAL;
        }
    }
    fflush(stdout);
    gdt_error_print(&err, stderr);
    if (o.rss) {
        struct rusage ru;
        getrusage(RUSAGE_SELF, &ru);
        fprintf(stderr, "maxrss_kib %ld\n", ru.ru_maxrss);
    }
    free(vbuf);
    free(fbuf);
    return (int)st;
}
