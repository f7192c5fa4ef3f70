/* The replaceable-output rule and the temporary names, directories and
 * directory syncs of the writers that follow it (gdt_outfile.h). */
#include "gdt_outfile.h"

#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

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

char *gdt_outfile_dir(const char *path)
{
    const char *slash = strrchr(path, '/');
    char *d;
    size_t n;

    if (slash == NULL)
        return strdup(".");
    n = slash == path ? 1 : (size_t)(slash - path);
    d = malloc(n + 1);
    if (d == NULL)
        return NULL;
    memcpy(d, path, n);
    d[n] = '\0';
    return d;
}

char *gdt_outfile_temp(const char *path)
{
    size_t l = strlen(path) + 32;
    char *t = malloc(l);
    if (t != NULL)
        snprintf(t, l, "%s.tmp-%ld", path, (long)getpid());
    return t;
}

int gdt_outfile_sync_dir(const char *dir)
{
    int e = 0;
    int fd = open(dir, O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (fd < 0)
        return errno;
    if (fsync(fd) != 0 && errno != EINVAL)
        e = errno;
    close(fd);
    return e;
}
