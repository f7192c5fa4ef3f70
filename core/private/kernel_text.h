/* kernel_text.h — the text of an OpenCL program as it is handed to the
 * runtime: a kernel file with every header it includes from the kernel
 * directory written in place (used by ocl.c; no OpenCL here).
 *
 * Why in place and not through "-I <kernel dir>": the program then depends
 * on nothing but its text and its build options, neither of which names
 * where the kernels are installed, so
 *   - a binary cache keyed on text and options (ours and the runtime's)
 *     serves a kernel directory that was moved or copied (an installed
 *     tree, a bundle carried to another machine) without compiling again;
 *   - a header that changed changes the text, so such a cache can never
 *     serve a build made from the old header.
 *
 * Rule: a line whose first non-blank characters are #include "name" (a
 * preprocessing directive, not inside a block comment) is replaced by
 *   #line 1 "name"
 *   <the contents of dir/name, expanded the same way>
 *   #line <the next line> "<the including file>"
 * so compiler messages still name the file and line they are about.
 * Every other line, #include <...> included, is copied unchanged; the
 * headers' own include guards still decide what is compiled.  The text
 * starts with #line 1 "<file>". */
#ifndef GDT_KERNEL_TEXT_H
#define GDT_KERNEL_TEXT_H

#include <stddef.h>

/* Headers nested deeper than this (a header that includes itself) are an
 * error. */
#define GDT_KERNEL_TEXT_MAX_DEPTH 8

/* The expanded text of dir/file, malloc'ed and NUL-terminated, in *out
 * (its length in *len when len is not NULL).  Returns 0, or an errno
 * value with *out NULL and the file that failed (dir/name, or the kernel
 * file itself) in failed[0..failed_len): ENOENT and the like from reading
 * it, ELOOP for headers nested too deep, ENAMETOOLONG for a name that
 * does not fit a path, ENOMEM. */
int gdt_kernel_text(const char *dir, const char *file, char **out, size_t *len, char *failed,
                    size_t failed_len);

#endif
