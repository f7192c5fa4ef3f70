/* pred_eval — evaluates predicate cases read from stdin, for the tests that
 * compare gdt-tile's predicates with big-integer arithmetic.
 *
 * usage: pred_eval [-t]
 *
 * Input, one case per record: op v0 v1 v2 v3 v4 v5 v6 v7 (signed integers).
 *   op 0: orient2d(a, b, c)          a = (v0, v1), b = (v2, v3), c = (v4, v5)
 *   op 1: incircle(a, b, c, d)       d = (v6, v7)
 *   op 2: prefer_diagonal(e, f)      e = (v0, v1), f = (v2, v3)
 *   op 3: edge_needs_flip(a, b, c, d)
 * Unused values must be present (any value in range, e.g. 0).
 * Default: binary records of 9 native-endian int64; output 2 bytes per case:
 * the result as int8, then the path bits (1: the in-circle filter escalated
 * to the integer path, 2: the tie-break decided; from the counters).
 * -t: text records, one per line, and text output "result path" per line.
 * The counters go to stderr as one line.  Exit 0, or 3 with a message on
 * malformed or out-of-range input, or 7 if the predicate self-test fails.
 */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_predicates.h"

#define REC_VALUES 9
#define CHUNK 4096

static int in_point_range(int64_t v)
{
    return v >= 0 && v <= GDT_COORD_MAX;
}

static int in_vec_range(int64_t v)
{
    return v >= -GDT_COORD_MAX && v <= GDT_COORD_MAX;
}

/* Evaluates one record; returns 0, or -1 when it is out of range. */
static int eval_record(gdt_pred_stats *st, const int64_t *r, signed char *res, unsigned char *path)
{
    gdt_pred_stats before = *st;
    gdt_ipt a = {r[1], r[2]}, b = {r[3], r[4]}, c = {r[5], r[6]}, d = {r[7], r[8]};
    int npts = r[0] == 0 ? 3 : 4;
    if (r[0] == 2) {
        for (int i = 1; i <= 4; i++)
            if (!in_vec_range(r[i]))
                return -1;
    } else if (r[0] >= 0 && r[0] <= 3) {
        for (int i = 1; i <= 2 * npts; i++)
            if (!in_point_range(r[i]))
                return -1;
    } else {
        return -1;
    }
    switch (r[0]) {
    case 0: *res = (signed char)gdt_orient2d(st, a, b, c); break;
    case 1: *res = (signed char)gdt_incircle(st, a, b, c, d); break;
    case 2: *res = (signed char)gdt_prefer_diagonal(st, a, b); break;
    default: *res = (signed char)gdt_edge_needs_flip(st, a, b, c, d); break;
    }
    *path = 0;
    if (st->incircle_exact != before.incircle_exact)
        *path |= 1;
    if (r[0] == 3 && st->tiebreak_calls != before.tiebreak_calls)
        *path |= 2;
    return 0;
}

static int run_binary(gdt_pred_stats *st, uint64_t *count)
{
    static int64_t rec[CHUNK * REC_VALUES];
    static unsigned char out[CHUNK * 2];
    const size_t rec_bytes = sizeof(int64_t) * REC_VALUES;
    for (;;) {
        size_t got = fread(rec, 1, rec_bytes * CHUNK, stdin);
        size_t n = got / rec_bytes;
        for (size_t i = 0; i < n; i++) {
            signed char res;
            unsigned char path;
            if (eval_record(st, rec + i * REC_VALUES, &res, &path) != 0) {
                fprintf(stderr, "pred_eval: case %llu: bad op or coordinate out of range\n",
                        (unsigned long long)(*count + i));
                return 3;
            }
            out[2 * i] = (unsigned char)res;
            out[2 * i + 1] = path;
        }
        if (n > 0 && fwrite(out, 2, n, stdout) != n) {
            fprintf(stderr, "pred_eval: write error\n");
            return 4;
        }
        *count += n;
        if (got % rec_bytes != 0) {
            fprintf(stderr, "pred_eval: truncated record after case %llu\n",
                    (unsigned long long)*count);
            return 3;
        }
        if (got < rec_bytes * CHUNK)
            return ferror(stdin) ? 4 : 0;
    }
}

static int run_text(gdt_pred_stats *st, uint64_t *count)
{
    char line[1024];
    while (fgets(line, sizeof line, stdin) != NULL) {
        int64_t r[REC_VALUES];
        char *p = line, *end;
        int k = 0;
        while (k < REC_VALUES) {
            long long v = strtoll(p, &end, 10);
            if (end == p)
                break;
            r[k++] = (int64_t)v;
            p = end;
        }
        while (*p == ' ' || *p == '\t' || *p == '\r' || *p == '\n')
            p++;
        if (k == 0 && *p == '\0')
            continue;
        if (k != REC_VALUES || *p != '\0') {
            fprintf(stderr, "pred_eval: line %llu: expected %d integers\n",
                    (unsigned long long)(*count + 1), REC_VALUES);
            return 3;
        }
        signed char res;
        unsigned char path;
        if (eval_record(st, r, &res, &path) != 0) {
            fprintf(stderr, "pred_eval: line %llu: bad op or coordinate out of range\n",
                    (unsigned long long)(*count + 1));
            return 3;
        }
        printf("%d %u\n", res, path);
        (*count)++;
    }
    return ferror(stdin) ? 4 : 0;
}

int main(int argc, char **argv)
{
    int text = argc > 1 && strcmp(argv[1], "-t") == 0;
    gdt_error err;
    gdt_error_clear(&err);
    if (gdt_predicates_selftest(NULL, &err) != GDT_OK) {
        gdt_error_print(&err, stderr);
        return 7;
    }
    gdt_pred_stats st;
    memset(&st, 0, sizeof st);
    uint64_t count = 0;
    int rc = text ? run_text(&st, &count) : run_binary(&st, &count);
    fprintf(stderr,
            "pred_eval: cases %llu orient %llu incircle %llu incircle_exact %llu tiebreak %llu\n",
            (unsigned long long)count, (unsigned long long)st.orient_calls,
            (unsigned long long)st.incircle_calls, (unsigned long long)st.incircle_exact,
            (unsigned long long)st.tiebreak_calls);
    return rc;
}
