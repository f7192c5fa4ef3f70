/* kernel_text.c — a kernel file with its headers written in place (see
 * kernel_text.h for the rule). */
#include "kernel_text.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* A growing NUL-terminated text.  Invariant: s[n] == '\0' when s != NULL,
 * n < cap. */
typedef struct text_buf {
    char *s;
    size_t n, cap;
} text_buf;

static int tb_add(text_buf *b, const char *s, size_t n)
{
    if (b->cap - b->n <= n) {
        size_t nc = b->cap ? b->cap : 16384;
        char *g;
        while (nc - b->n <= n)
            nc *= 2;
        g = realloc(b->s, nc);
        if (g == NULL)
            return ENOMEM;
        b->s = g;
        b->cap = nc;
    }
    memcpy(b->s + b->n, s, n);
    b->n += n;
    b->s[b->n] = '\0';
    return 0;
}

static int tb_printf_line(text_buf *b, unsigned long line, const char *name)
{
    char buf[320];
    int k = snprintf(buf, sizeof buf, "#line %lu \"%s\"\n", line, name);
    if (k < 0 || (size_t)k >= sizeof buf)
        return ENAMETOOLONG;
    return tb_add(b, buf, (size_t)k);
}

/* A whole file, malloc'ed and NUL-terminated. */
static int read_file(const char *path, char **out)
{
    FILE *f = fopen(path, "rb");
    text_buf b = {0};
    char chunk[8192];
    size_t got;
    int e = 0;

    *out = NULL;
    if (f == NULL)
        return errno ? errno : EIO;
    while (e == 0 && (got = fread(chunk, 1, sizeof chunk, f)) > 0)
        e = tb_add(&b, chunk, got);
    if (e == 0 && ferror(f))
        e = EIO;
    fclose(f);
    if (e == 0 && b.s == NULL)
        e = tb_add(&b, "", 0); /* an empty file is an empty text */
    if (e != 0) {
        free(b.s);
        return e;
    }
    *out = b.s;
    return 0;
}

/* The header name of a line that is an #include "name" directive, copied
 * to name (NUL-terminated), or 0 when the line is anything else. */
static int include_name(const char *line, const char *end, char *name, size_t cap)
{
    const char *p = line, *q;
    while (p < end && (*p == ' ' || *p == '\t'))
        p++;
    if (p == end || *p != '#')
        return 0;
    p++;
    while (p < end && (*p == ' ' || *p == '\t'))
        p++;
    if ((size_t)(end - p) < 7 || memcmp(p, "include", 7) != 0)
        return 0;
    p += 7;
    while (p < end && (*p == ' ' || *p == '\t'))
        p++;
    if (p == end || *p != '"')
        return 0;
    q = memchr(p + 1, '"', (size_t)(end - p - 1));
    if (q == NULL || q == p + 1 || (size_t)(q - p - 1) >= cap)
        return 0;
    memcpy(name, p + 1, (size_t)(q - p - 1));
    name[q - p - 1] = '\0';
    return 1;
}

/* Whether a block comment is open after the line [s, end), given whether
 * one was open at its start (string and character literals and line
 * comments are skipped). */
static int comment_after(const char *s, const char *end, int in_block)
{
    while (s < end) {
        if (in_block) {
            if (s + 1 < end && s[0] == '*' && s[1] == '/') {
                in_block = 0;
                s += 2;
            } else
                s++;
        } else if (s + 1 < end && s[0] == '/' && s[1] == '/') {
            break;
        } else if (s + 1 < end && s[0] == '/' && s[1] == '*') {
            in_block = 1;
            s += 2;
        } else if (*s == '"' || *s == '\'') {
            char quote = *s++;
            while (s < end && *s != quote)
                s += (*s == '\\' && s + 1 < end) ? 2 : 1;
            if (s < end)
                s++;
        } else
            s++;
    }
    return in_block;
}

static int expand(const char *dir, const char *file, const char *text, text_buf *out, int depth,
                  char *failed, size_t failed_len)
{
    const char *s = text;
    unsigned long line = 1;
    int in_block = 0, e;

    while (*s != '\0') {
        const char *nl = strchr(s, '\n');
        const char *end = nl ? nl : s + strlen(s);
        char name[256];

        if (!in_block && include_name(s, end, name, sizeof name)) {
            char path[4096], *inc = NULL;
            int k = snprintf(path, sizeof path, "%s/%s", dir, name);
            if (k < 0 || (size_t)k >= sizeof path)
                e = ENAMETOOLONG;
            else if (depth + 1 > GDT_KERNEL_TEXT_MAX_DEPTH)
                e = ELOOP;
            else
                e = read_file(path, &inc);
            if (e != 0) {
                snprintf(failed, failed_len, "%s", path);
                return e;
            }
            e = tb_printf_line(out, 1, name);
            if (e == 0)
                e = expand(dir, name, inc, out, depth + 1, failed, failed_len);
            free(inc);
            if (e == 0 && out->n > 0 && out->s[out->n - 1] != '\n')
                e = tb_add(out, "\n", 1);
            if (e == 0)
                e = tb_printf_line(out, line + 1, file);
        } else {
            in_block = comment_after(s, end, in_block);
            e = tb_add(out, s, (size_t)(end - s) + (nl != NULL));
        }
        if (e != 0) {
            if (failed[0] == '\0')
                snprintf(failed, failed_len, "%s/%s", dir, file);
            return e;
        }
        if (nl == NULL)
            break;
        s = nl + 1;
        line++;
    }
    return 0;
}

int gdt_kernel_text(const char *dir, const char *file, char **out, size_t *len, char *failed,
                    size_t failed_len)
{
    char path[4096], *text = NULL;
    text_buf b = {0};
    int e, k;

    *out = NULL;
    if (failed_len > 0)
        failed[0] = '\0';
    k = snprintf(path, sizeof path, "%s/%s", dir, file);
    if (k < 0 || (size_t)k >= sizeof path)
        e = ENAMETOOLONG;
    else
        e = read_file(path, &text);
    if (e != 0) {
        snprintf(failed, failed_len, "%s/%s", dir, file);
        return e;
    }
    e = tb_printf_line(&b, 1, file);
    if (e == 0)
        e = expand(dir, file, text, &b, 0, failed, failed_len);
    free(text);
    if (e != 0) {
        if (failed_len > 0 && failed[0] == '\0')
            snprintf(failed, failed_len, "%s/%s", dir, file);
        free(b.s);
        return e;
    }
    *out = b.s;
    if (len)
        *len = b.n;
    return 0;
}
