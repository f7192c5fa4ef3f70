/* Direct I/O with a fallback (see gdt_direct_io.h). */
#define _GNU_SOURCE 1 /* O_DIRECT */
#include "gdt_direct_io.h"

#include <errno.h>
#include <fcntl.h>
#include <unistd.h>

int gdt_dio_create(const char *path, int mode, int *direct)
{
    int fd = open(path, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC | O_DIRECT, mode);
    *direct = fd >= 0;
    if (fd < 0 && errno == EINVAL) /* no direct I/O on this file system */
        fd = open(path, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, mode);
    return fd;
}

int gdt_dio_open_read(const char *path, int *direct)
{
    int fd = open(path, O_RDONLY | O_CLOEXEC | O_DIRECT);
    *direct = fd >= 0;
    if (fd < 0 && errno == EINVAL)
        fd = open(path, O_RDONLY | O_CLOEXEC);
    return fd;
}

int gdt_dio_end(int fd, int *direct)
{
    int fl = fcntl(fd, F_GETFL);
    *direct = 0;
    if (fl < 0 || fcntl(fd, F_SETFL, fl & ~O_DIRECT) != 0)
        return errno;
    return 0;
}

int gdt_dio_write_blocks(int fd, int *direct, const void *buf, size_t len, size_t *done)
{
    const unsigned char *p = buf;
    size_t whole = len / GDT_DIO_BLOCK * GDT_DIO_BLOCK;

    *done = 0;
    while (*direct && *done < whole) {
        ssize_t k = write(fd, p + *done, whole - *done);
        if (k < 0 && errno == EINTR)
            continue;
        if (k < 0 && errno == EINVAL)
            return gdt_dio_end(fd, direct); /* refused: the page cache from here */
        if (k <= 0)
            return k < 0 ? errno : EIO;
        *done += (size_t)k;
        if ((size_t)k % GDT_DIO_BLOCK != 0)
            return gdt_dio_end(fd, direct); /* short: the offset lost its alignment */
    }
    return 0;
}
