/* outpaths.h — the start-up check of every path a command reads or writes.
 *
 * Run before any work (before an input is opened, a job directory created
 * or the device started), so that a command that cannot finish safely fails
 * at once, and so that no output can ever replace an input:
 *   - inputs: gdt_source_check_path (existing regular files; a FIFO, device
 *     or directory is refused without being opened, since opening a FIFO
 *     blocks);
 *   - file outputs (the mesh, an OBJ's .prj, --json, --dem, --preview): not empty; not an input, by path or
 *     by identity (same device and inode: covers ./x, symbolic and hard
 *     links); if the path exists, a regular file and not a symbolic link
 *     (outputs are written under a temporary name in the same directory
 *     and renamed over the path: a rename replaces a link, not its target,
 *     and a special file is replaced, not written to); the directory that
 *     receives the file exists and is writable;
 *   - the job directory: not an input; a directory (it is created when
 *     absent, in a directory that must exist and be writable); no input
 *     inside it (the job's files are written and removed there);
 *   - no two outputs name the same file.
 * All refusals are GDT_EUSAGE 22xx naming the option, the path and the
 * reason; input refusals are the GDT_EINPUT/GDT_EIO of gdt_source.h.
 */
#ifndef GDT_OUTPATHS_H
#define GDT_OUTPATHS_H

#include <stddef.h>

#include "gdt_cli.h"
#include "gdt_error.h"

/* One path the command writes.  Strings are borrowed. */
typedef struct gdt_outpath {
    const char *opt;  /* the option that names it, for messages ("-o", "--json") */
    const char *path; /* NULL: not written by this command */
    int is_dir;       /* a directory the command writes in (the job) */
} gdt_outpath;

/* Checks outs[0..nouts) against each other and against inputs[0..ninputs)
 * as described above (the inputs themselves are not checked here).
 * returns: GDT_OK; GDT_EUSAGE 2201 (empty path), 2202 (an output is an
 * input), 2203 (a symbolic link), 2204 (exists and is not a regular file),
 * 2205 (the job exists and is not a directory), 2206 (its directory does not
 * exist), 2207 (not writable), 2208 (two outputs are one file), 2209 (an
 * input inside the job directory); GDT_EINTERNAL 7001. */
gdt_status gdt_outpaths_check(const char *const *inputs, size_t ninputs,
                              const gdt_outpath *outs, size_t nouts, gdt_error *err);

/* The paths of the command opts describes: its inputs (gdt_source_check_path,
 * then) its outputs for its mode: --json, --dem, --preview; the mesh unless
 * --info, and for an OBJ its .prj (gdt_mesh_prj_path); job, when not NULL,
 * as the job directory. */
gdt_status gdt_cli_check_paths(const gdt_options *opts, const char *job, gdt_error *err);

#endif
