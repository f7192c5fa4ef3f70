/* fuzz_input.h — what the fuzz targets share: the input bytes as a file.
 *
 * The readers under test take a path, not a buffer, so each input is
 * written to a memory file (memfd) that lives for the whole process and is
 * reopened through /proc/self/fd/N: no disk traffic per input, nothing left
 * behind.  Readers that need a real directory (the job journal; the PLY
 * checker's temporary files) get one made once with mkdtemp and removed at
 * exit.
 *
 * Every function returns 0 on success and -1 on failure (errno set); a
 * target that cannot set up its input aborts, since a silently skipped
 * input would hide a crash.
 */
#ifndef GDT_FUZZ_INPUT_H
#define GDT_FUZZ_INPUT_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_error.h"

/* Replaces the memory file's content with data[0..size) and stores its path
 * ("/proc/self/fd/N", valid until the process ends) in *path. */
int gdt_fuzz_memfile(const uint8_t *data, size_t size, const char **path);

/* A private directory, made on the first call and removed (with the files
 * named by gdt_fuzz_workdir_forget) at exit; *dir is valid until then. */
int gdt_fuzz_workdir(const char **dir);

/* Writes data[0..size) to dir/name, replacing it. */
int gdt_fuzz_write_file(const char *dir, const char *name, const uint8_t *data, size_t size);

/* Removes dir/name if it exists. */
void gdt_fuzz_remove(const char *dir, const char *name);

/* Aborts unless err records st with a message number whose first digit is
 * st's class and a non-empty message: a failure is never silent. */
void gdt_fuzz_check_error(gdt_status st, const gdt_error *err);

/* Aborts with a message on stderr (set-up failure of the harness). */
void gdt_fuzz_die(const char *what);

#endif
