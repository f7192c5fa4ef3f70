/* test_kernel_text.c — a kernel file with its headers written in place
 * (core/private/kernel_text.h): the exact text for nested headers, lines
 * that only look like directives (in block comments, after a string that
 * holds a comment opener), system headers left alone, and the errors: a
 * missing header or kernel file named, a header that includes itself. */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "gdt_check.h"
#include "private/kernel_text.h"

static gdt_checks C;
static char g_dir[256];

static void put(const char *name, const char *text)
{
    char path[512];
    FILE *f;
    snprintf(path, sizeof path, "%s/%s", g_dir, name);
    f = fopen(path, "wb");
    if (f == NULL || fputs(text, f) < 0 || fclose(f) != 0) {
        perror(path);
        exit(2);
    }
}

static void expect_text(const char *file, const char *want)
{
    char failed[512], *out = NULL;
    size_t len = 0;
    int e = gdt_kernel_text(g_dir, file, &out, &len, failed, sizeof failed);
    GDT_CHECK(&C, e == 0, "%s: error %d (%s) at %s", file, e, strerror(e), failed);
    if (e != 0)
        return;
    GDT_CHECK(&C, len == strlen(out), "%s: length %zu, text %zu", file, len, strlen(out));
    GDT_CHECK(&C, strcmp(out, want) == 0, "%s:\n--- got\n%s--- want\n%s---", file, out, want);
    free(out);
}

static void expect_error(const char *file, int want_e, const char *want_failed)
{
    char failed[512], path[512], *out = (char *)1;
    int e = gdt_kernel_text(g_dir, file, &out, NULL, failed, sizeof failed);
    snprintf(path, sizeof path, "%s/%s", g_dir, want_failed);
    GDT_CHECK(&C, e == want_e, "%s: error %d, want %d", file, e, want_e);
    GDT_CHECK(&C, out == NULL, "%s: text returned with an error", file);
    GDT_CHECK(&C, strcmp(failed, path) == 0, "%s: failed at %s, want %s", file, failed, path);
}

int main(void)
{
    const char *tmp = getenv("TMPDIR");
    snprintf(g_dir, sizeof g_dir, "%s/gdt-kernel-text-XXXXXX", tmp && *tmp ? tmp : "/tmp");
    if (mkdtemp(g_dir) == NULL) {
        perror("mkdtemp");
        return 2;
    }

    /* nested headers, each framed by #line; spaces inside the directive; a
     * header without a final newline; a system header kept as it is */
    put("b.clh", "#ifndef B\n#define B\nint b;\n#endif");
    put("a.clh", "#ifndef A\n#define A\n  #  include \"b.clh\"\nint a;\n#endif\n");
    put("k.cl", "#include <stdint.h>\n#include \"a.clh\"\n#include\t\"b.clh\"\nkernel void k(void) {}\n");
    expect_text("k.cl", "#line 1 \"k.cl\"\n"
                        "#include <stdint.h>\n"
                        "#line 1 \"a.clh\"\n"
                        "#ifndef A\n#define A\n"
                        "#line 1 \"b.clh\"\n"
                        "#ifndef B\n#define B\nint b;\n#endif\n"
                        "#line 4 \"a.clh\"\n"
                        "int a;\n#endif\n"
                        "#line 3 \"k.cl\"\n"
                        "#line 1 \"b.clh\"\n"
                        "#ifndef B\n#define B\nint b;\n#endif\n"
                        "#line 4 \"k.cl\"\n"
                        "kernel void k(void) {}\n");

    /* a directive inside a block comment stays text (expanding it would
     * fail: the header does not exist); a string holding a comment opener
     * and a line comment opening none do not hide the next directive */
    put("c.cl", "/* notes:\n#include \"missing.clh\"\n*/\n"
                "const char *s = \"/*\"; char c = '\\''; // /* not a comment\n"
                "#include \"b.clh\"\n"
                "int x; /* one */ /* two\n#include \"missing.clh\"\n */ int y;\n");
    expect_text("c.cl", "#line 1 \"c.cl\"\n"
                        "/* notes:\n#include \"missing.clh\"\n*/\n"
                        "const char *s = \"/*\"; char c = '\\''; // /* not a comment\n"
                        "#line 1 \"b.clh\"\n"
                        "#ifndef B\n#define B\nint b;\n#endif\n"
                        "#line 6 \"c.cl\"\n"
                        "int x; /* one */ /* two\n#include \"missing.clh\"\n */ int y;\n");

    /* an empty kernel file and one without a newline */
    put("e.cl", "");
    expect_text("e.cl", "#line 1 \"e.cl\"\n");
    put("n.cl", "kernel void n(void) {}");
    expect_text("n.cl", "#line 1 \"n.cl\"\nkernel void n(void) {}");

    /* errors name the file that failed */
    put("m.cl", "int m;\n#include \"a.clh\"\n#include \"gone.clh\"\n");
    expect_error("m.cl", ENOENT, "gone.clh");
    expect_error("absent.cl", ENOENT, "absent.cl");
    put("self.clh", "#include \"self.clh\"\n");
    put("s.cl", "#include \"self.clh\"\n");
    expect_error("s.cl", ELOOP, "self.clh");

    {
        const char *names[] = {"a.clh", "b.clh", "k.cl", "c.cl", "e.cl", "n.cl", "m.cl",
                               "self.clh", "s.cl"};
        char path[512];
        for (size_t i = 0; i < sizeof names / sizeof names[0]; i++) {
            snprintf(path, sizeof path, "%s/%s", g_dir, names[i]);
            unlink(path);
        }
        rmdir(g_dir);
    }
    return gdt_check_finish(&C, "test_kernel_text");
}
