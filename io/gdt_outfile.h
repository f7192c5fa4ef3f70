/* gdt_outfile.h — the rule for the files gdt-tile writes under a temporary
 * name and renames over their path (the PLY, the JSON summary).
 *
 * A rename replaces the directory entry, whatever it is: it would put a
 * regular file in place of a FIFO or a device node (`-o /dev/null` as root
 * would replace the real one), and replace a symbolic link rather than
 * write to the file it names.  So an output path must be absent or a
 * regular file.  Writers check it when they start and again right before
 * the rename, since the path may change during a long run.
 */
#ifndef GDT_OUTFILE_H
#define GDT_OUTFILE_H

#include "gdt_error.h"

#ifdef __cplusplus
extern "C" {
#endif

/* returns GDT_OK when path does not exist or is a regular file (not a
 * symbolic link); GDT_EIO 4010 naming what it is otherwise, 4011 when lstat
 * fails for another reason than its absence. */
gdt_status gdt_outfile_check(const char *path, gdt_error *err);

/* The directory part of path: "." when it has no slash, "/" for "/name".
 * malloc'd (the caller frees it); NULL when out of memory. */
char *gdt_outfile_dir(const char *path);

/* "<path>.tmp-<pid>", the temporary name a writer uses beside path.
 * malloc'd; NULL when out of memory. */
char *gdt_outfile_temp(const char *path);

/* fsync of the directory dir, so that a rename in it survives a power
 * loss; a file system that cannot sync a directory (EINVAL) is accepted.
 * returns 0 or the errno. */
int gdt_outfile_sync_dir(const char *dir);

#ifdef __cplusplus
}
#endif
#endif
