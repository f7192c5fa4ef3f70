/* See fd_io.h. */
#include "fd_io.h"

#include <errno.h>
#include <string.h>
#include <sys/types.h>
#include <unistd.h>

int gdt_fd_write_all(int fd, const void *p, size_t n, int64_t off)
{
    const unsigned char *b = p;
    while (n > 0) {
        ssize_t k = off < 0 ? write(fd, b, n) : pwrite(fd, b, n, (off_t)off);
        if (k < 0) {
            if (errno == EINTR)
                continue;
            return errno;
        }
        if (k == 0)
            return EIO;
        b += (size_t)k;
        n -= (size_t)k;
        if (off >= 0)
            off += (int64_t)k;
    }
    return 0;
}

int gdt_fd_pread_all(int fd, void *p, size_t n, uint64_t off, size_t *got)
{
    unsigned char *b = p;
    *got = 0;
    while (*got < n) {
        ssize_t k = pread(fd, b + *got, n - *got, (off_t)(off + *got));
        if (k < 0) {
            if (errno == EINTR)
                continue;
            return errno;
        }
        if (k == 0)
            break;
        *got += (size_t)k;
    }
    return 0;
}

gdt_status gdt_fd_sync_close_part(int fd, const char *path, gdt_error *err)
{
    gdt_status st = GDT_OK;
    if (fsync(fd) != 0)
        st = gdt_error_set(err, GDT_EIO, 4722, "%s: fsync of a part failed: %s", path,
                           strerror(errno));
    if (close(fd) != 0 && st == GDT_OK)
        st = gdt_error_set(err, GDT_EIO, 4722, "%s: close of a part failed: %s", path,
                           strerror(errno));
    return st;
}
