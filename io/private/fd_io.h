/* Whole-buffer reads and writes of file descriptors, shared by the readers
 * and writers of io/. */
#ifndef GDT_FD_IO_H
#define GDT_FD_IO_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_error.h"

/* Writes all n bytes of p to fd: at byte offset off when off >= 0 (the file
 * position is left alone), else at the file position.  Partial writes and
 * EINTR are retried.
 * returns: 0, or an errno value (EIO when the system accepts no byte). */
int gdt_fd_write_all(int fd, const void *p, size_t n, int64_t off);

/* Reads n bytes at byte offset off into p (the file position is left
 * alone); EINTR and partial reads are retried.  *got is the number of bytes
 * read: n, or fewer when the file ends first.
 * returns: 0, or an errno value. */
int gdt_fd_pread_all(int fd, void *p, size_t n, uint64_t off, size_t *got);

/* Syncs and closes the part of a file written in parts (fd, named path in
 * messages); fd is closed whatever happens.  returns: GDT_OK; GDT_EIO 4722
 * (fsync or close failed). */
gdt_status gdt_fd_sync_close_part(int fd, const char *path, gdt_error *err);

#endif
