/* gdt_check.h — the check macro and the seeded generator shared by the C
 * tests.  Header-only: everything is static inline, so a test includes it
 * without linking anything.
 *
 * A test keeps one gdt_checks (its counts), records every check with
 * GDT_CHECK, and returns gdt_check_finish() from main.  A failed check is
 * reported on stderr as "FILE:LINE: check failed: EXPR: MESSAGE" and does
 * not stop the test.
 */
#ifndef GDT_CHECK_H
#define GDT_CHECK_H

#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>

/* Counts of one test program; {0, 0} is the start. */
typedef struct gdt_checks {
    unsigned long failed;
    unsigned long checks;
} gdt_checks;

#if defined(__GNUC__)
__attribute__((format(printf, 6, 7)))
#endif
/* Counts a failed check in *c and reports it unless quiet_after > 0 failures
 * have been reported already. */
static inline void gdt_check_failed(gdt_checks *c, unsigned long quiet_after, const char *file,
                                    int line, const char *expr, const char *fmt, ...)
{
    char msg[1024];
    va_list ap;

    c->failed++;
    if (quiet_after != 0 && c->failed > quiet_after)
        return;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    if (msg[0] != '\0')
        fprintf(stderr, "%s:%d: check failed: %s: %s\n", file, line, expr, msg);
    else
        fprintf(stderr, "%s:%d: check failed: %s\n", file, line, expr);
}

/* Counts one check in *c; when cond is false, reports it with the printf
 * message that follows (use "%s", "" for none). */
#define GDT_CHECK(c, cond, ...) GDT_CHECK_QUIET_AFTER(c, 0, cond, __VA_ARGS__)

/* GDT_CHECK that reports only the first n failures of *c (n > 0), for
 * tests where one fault fails thousands of cases; all are still counted. */
#define GDT_CHECK_QUIET_AFTER(c, n, cond, ...)                                                     \
    do {                                                                                           \
        (c)->checks++;                                                                             \
        if (!(cond))                                                                               \
            gdt_check_failed((c), (n), __FILE__, __LINE__, #cond, __VA_ARGS__);                    \
    } while (0)

/* Prints the outcome of the test program name and returns its exit status:
 * 0 when no check failed, else 1. */
static inline int gdt_check_finish(const gdt_checks *c, const char *name)
{
    if (c->failed != 0) {
        fprintf(stderr, "%s: %lu of %lu checks FAILED\n", name, c->failed, c->checks);
        return 1;
    }
    printf("%s: all %lu checks passed\n", name, c->checks);
    return 0;
}

/* splitmix64 (Steele, Lea and Flood): advances *state and returns the next
 * value.  Any seed, zero included, gives a full-period sequence. */
static inline uint64_t gdt_splitmix64(uint64_t *state)
{
    uint64_t z = (*state += UINT64_C(0x9e3779b97f4a7c15));
    z = (z ^ (z >> 30)) * UINT64_C(0xbf58476d1ce4e5b9);
    z = (z ^ (z >> 27)) * UINT64_C(0x94d049bb133111eb);
    return z ^ (z >> 31);
}

/* The whole file at path in a malloc'd buffer (free it), its length in *n;
 * NULL (*n = 0) when it cannot be read or is empty. */
static inline unsigned char *gdt_check_slurp(const char *path, size_t *n)
{
    FILE *f = fopen(path, "rb");
    unsigned char *b = NULL;
    long len;
    *n = 0;
    if (f == NULL)
        return NULL;
    if (fseek(f, 0, SEEK_END) == 0 && (len = ftell(f)) > 0 && fseek(f, 0, SEEK_SET) == 0 &&
        (b = malloc((size_t)len)) != NULL && fread(b, 1, (size_t)len, f) == (size_t)len)
        *n = (size_t)len;
    fclose(f);
    if (*n == 0) {
        free(b);
        b = NULL;
    }
    return b;
}

#endif
