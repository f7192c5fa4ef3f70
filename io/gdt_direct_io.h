/* gdt_direct_io.h — direct I/O (O_DIRECT) with a fallback, for large files
 * written once and read at most once (the PLY, the tile files): whole
 * GDT_DIO_BLOCK blocks from buffers aligned to it bypass the page cache,
 * where the file system allows it; everything else goes through the page
 * cache as usual.  Filling the page cache with fresh pages costs more system
 * time than the transfer.
 *
 * A descriptor is "direct" while O_DIRECT is set on it; *direct mirrors
 * that.  While direct, the file offset is a multiple of GDT_DIO_BLOCK.
 * Errors are errno values (0 = success).
 */
#ifndef GDT_DIRECT_IO_H
#define GDT_DIRECT_IO_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Block size and buffer alignment of direct transfers (a multiple of every
 * logical block size in use). */
#define GDT_DIO_BLOCK 4096u

/* Creates (truncates) path for writing, O_CLOEXEC, with O_DIRECT when the
 * file system accepts it (*direct = 1).  Returns the descriptor, or -1 with
 * errno set. */
int gdt_dio_create(const char *path, int mode, int *direct);

/* Opens path for reading, with O_DIRECT when accepted.  As gdt_dio_create. */
int gdt_dio_open_read(const char *path, int *direct);

/* Clears O_DIRECT on fd (*direct = 0).  Returns 0 or errno. */
int gdt_dio_end(int fd, int *direct);

/* While *direct: writes the whole blocks of buf[0..len) (buf aligned to
 * GDT_DIO_BLOCK) at the file position, *done = the bytes written.  A write
 * the file system refuses (EINVAL) or a short one takes fd out of direct
 * mode (*direct = 0) and stops; the caller writes the rest the usual way.
 * When !*direct, nothing is written.  Returns 0 or errno. */
int gdt_dio_write_blocks(int fd, int *direct, const void *buf, size_t len, size_t *done);

#ifdef __cplusplus
}
#endif

#endif
