/* The input files of the fuzz targets (see fuzz_input.h). */
#define _GNU_SOURCE /* memfd_create */
#include "fuzz_input.h"

#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

/* One memory file per process, reused: inputs run one at a time. */
static int mem_fd = -1;
static char mem_path[64];

static char work_dir[4096];
static int work_made;

void gdt_fuzz_die(const char *what)
{
    fprintf(stderr, "fuzz harness: %s: %s\n", what, strerror(errno));
    abort();
}

void gdt_fuzz_check_error(gdt_status st, const gdt_error *err)
{
    if (st == GDT_OK || err->status != st || err->msg[0] == '\0' ||
        (st != GDT_EINTERRUPTED && err->code / 1000 != (int)st)) {
        fprintf(stderr, "fuzz harness: status %d reported as status %d, message %d: '%s'\n",
                (int)st, (int)err->status, err->code, err->msg);
        abort();
    }
}

static int write_all(int fd, const uint8_t *data, size_t size)
{
    size_t done = 0;
    while (done < size) {
        ssize_t w = write(fd, data + done, size - done);
        if (w < 0 && errno == EINTR)
            continue;
        if (w <= 0)
            return -1;
        done += (size_t)w;
    }
    return 0;
}

int gdt_fuzz_memfile(const uint8_t *data, size_t size, const char **path)
{
    if (mem_fd < 0) {
        mem_fd = memfd_create("gdt-fuzz-input", MFD_CLOEXEC);
        if (mem_fd < 0)
            return -1;
        snprintf(mem_path, sizeof mem_path, "/proc/self/fd/%d", mem_fd);
    }
    if (ftruncate(mem_fd, 0) != 0 || lseek(mem_fd, 0, SEEK_SET) != 0 ||
        write_all(mem_fd, data, size) != 0)
        return -1;
    *path = mem_path;
    return 0;
}

/* The directory holds only the files the targets name; they remove them
 * before each input, so at exit it is empty but for the last input's. */
static const char *const work_files[] = {"job.db", "job.db-wal", "job.db-shm",
                                         "job.db-journal", "input.ply"};

static void remove_work_dir(void)
{
    for (size_t i = 0; i < sizeof work_files / sizeof work_files[0]; i++)
        gdt_fuzz_remove(work_dir, work_files[i]);
    rmdir(work_dir);
}

int gdt_fuzz_workdir(const char **dir)
{
    if (!work_made) {
        const char *tmp = getenv("TMPDIR");
        int n = snprintf(work_dir, sizeof work_dir, "%s/gdt-fuzz-XXXXXX",
                         tmp != NULL && tmp[0] != '\0' ? tmp : "/tmp");
        if (n < 0 || (size_t)n >= sizeof work_dir) {
            errno = ENAMETOOLONG;
            return -1;
        }
        if (mkdtemp(work_dir) == NULL)
            return -1;
        work_made = 1;
        atexit(remove_work_dir);
    }
    *dir = work_dir;
    return 0;
}

int gdt_fuzz_write_file(const char *dir, const char *name, const uint8_t *data, size_t size)
{
    char path[4200];
    int fd, r;
    snprintf(path, sizeof path, "%s/%s", dir, name);
    fd = open(path, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
    if (fd < 0)
        return -1;
    r = write_all(fd, data, size);
    if (close(fd) != 0)
        r = -1;
    return r;
}

void gdt_fuzz_remove(const char *dir, const char *name)
{
    char path[4200];
    snprintf(path, sizeof path, "%s/%s", dir, name);
    unlink(path);
}
