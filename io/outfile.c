/* The replaceable-output rule (gdt_outfile.h). */
#include "gdt_outfile.h"

#include <errno.h>
#include <string.h>
#include <sys/stat.h>

#include "gdt_source.h"

gdt_status gdt_outfile_check(const char *path, gdt_error *err)
{
    struct stat sb;
    if (lstat(path, &sb) != 0)
        return errno == ENOENT ? GDT_OK
                               : gdt_error_set(err, GDT_EIO, 4011, "%s: cannot check the path: %s",
                                               path, strerror(errno));
    if (S_ISREG(sb.st_mode))
        return GDT_OK;
    return gdt_error_set(err, GDT_EIO, 4010,
                         "%s: is %s; an output is renamed over its path, so it is not replaced",
                         path, gdt_file_kind(sb.st_mode));
}
