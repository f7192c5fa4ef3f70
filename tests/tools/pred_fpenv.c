/* pred_fpenv — runs the predicates' floating-point environment self-test and
 * compares the faults it reports with an expectation, so the tests can show
 * that each probe fires in a build (or rounding mode) that breaks the filter.
 *
 * usage: pred_fpenv [--round upward|downward|towardzero]
 *                   (--expect LIST | --includes LIST)
 * LIST: "none" or comma-separated fault names: contraction, reassoc,
 * rounding, filter, int128.  --expect: the reported mask must equal LIST;
 * --includes: it must contain LIST.  Exit 0 when it does, 1 when not, 2 on
 * bad usage.
 */
#include <fenv.h>
#include <stdio.h>
#include <string.h>

#include "gdt_predicates.h"

static const struct {
    const char *name;
    unsigned bit;
} fault_names[] = {{"contraction", GDT_FPENV_CONTRACTION},
                   {"reassoc", GDT_FPENV_REASSOC},
                   {"rounding", GDT_FPENV_ROUNDING},
                   {"filter", GDT_FPENV_FILTER},
                   {"int128", GDT_FPENV_INT128}};

/* Parses LIST into *mask; returns 0, or -1 on an unknown name. */
static int parse_faults(const char *list, unsigned *mask)
{
    *mask = 0;
    if (strcmp(list, "none") == 0)
        return 0;
    char buf[256];
    snprintf(buf, sizeof buf, "%s", list);
    for (char *tok = strtok(buf, ","); tok != NULL; tok = strtok(NULL, ",")) {
        size_t i, n = sizeof fault_names / sizeof fault_names[0];
        for (i = 0; i < n; i++)
            if (strcmp(tok, fault_names[i].name) == 0)
                break;
        if (i == n)
            return -1;
        *mask |= fault_names[i].bit;
    }
    return 0;
}

int main(int argc, char **argv)
{
    int round = FE_TONEAREST, includes = -1;
    unsigned want = 0;
    for (int i = 1; i < argc; i++) {
        if (strcmp(argv[i], "--round") == 0 && i + 1 < argc) {
            const char *m = argv[++i];
            if (strcmp(m, "upward") == 0)
                round = FE_UPWARD;
            else if (strcmp(m, "downward") == 0)
                round = FE_DOWNWARD;
            else if (strcmp(m, "towardzero") == 0)
                round = FE_TOWARDZERO;
            else
                goto usage;
        } else if ((strcmp(argv[i], "--expect") == 0 || strcmp(argv[i], "--includes") == 0)
                   && i + 1 < argc) {
            includes = strcmp(argv[i], "--includes") == 0;
            if (parse_faults(argv[++i], &want) != 0)
                goto usage;
        } else {
            goto usage;
        }
    }
    if (includes < 0)
        goto usage;
    if (fesetround(round) != 0) {
        fprintf(stderr, "pred_fpenv: cannot set the rounding mode\n");
        return 1;
    }
    unsigned faults = 0;
    gdt_error err;
    gdt_error_clear(&err);
    gdt_status st = gdt_predicates_selftest(&faults, &err);
    fesetround(FE_TONEAREST);
    printf("pred_fpenv: status %d faults 0x%x (want %s 0x%x)\n", (int)st, faults,
           includes ? "at least" : "exactly", want);
    if (st != GDT_OK)
        gdt_error_print(&err, stdout);
    if ((st == GDT_OK) != (faults == 0))
        return 1;
    int ok = includes ? (faults & want) == want : faults == want;
    return ok ? 0 : 1;
usage:
    fprintf(stderr, "usage: pred_fpenv [--round upward|downward|towardzero] "
                    "(--expect LIST | --includes LIST)\n");
    return 2;
}
