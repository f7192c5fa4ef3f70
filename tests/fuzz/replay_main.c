/* Replays inputs through a fuzz target without libFuzzer, so that the
 * saved crash inputs run as a test in every build (the ASan build
 * included).
 *
 *   fuzz_<target>_replay PATH...
 *
 * Each PATH is a file or a folder whose regular files (in name order) are
 * inputs.  Exit status 0 when every input ran (a crash aborts the process),
 * 2 when a path cannot be read or no input was found: a replay of nothing
 * must not pass as a replay.
 */
#include <dirent.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static int run_file(const char *path)
{
    FILE *f = fopen(path, "rb");
    uint8_t *buf = NULL;
    size_t len = 0, cap = 0;
    int ok = f != NULL;

    while (ok) {
        size_t n;
        if (len == cap) {
            uint8_t *nb = realloc(buf, cap = cap ? 2 * cap : 65536);
            if (nb == NULL) {
                ok = 0;
                break;
            }
            buf = nb;
        }
        n = fread(buf + len, 1, cap - len, f);
        len += n;
        if (n == 0) {
            ok = !ferror(f);
            break;
        }
    }
    if (f != NULL)
        fclose(f);
    if (!ok) {
        fprintf(stderr, "replay: cannot read %s\n", path);
        free(buf);
        return -1;
    }
    /* an exact-size copy, so that ASan sees reads past the input's end */
    {
        uint8_t *in = malloc(len ? len : 1);
        if (in == NULL) {
            free(buf);
            return -1;
        }
        if (len)
            memcpy(in, buf, len);
        free(buf);
        fprintf(stderr, "replay: %s (%zu bytes)\n", path, len);
        LLVMFuzzerTestOneInput(in, len);
        free(in);
    }
    return 0;
}

static int by_name(const void *a, const void *b)
{
    return strcmp(*(char *const *)a, *(char *const *)b);
}

/* Runs every regular file of dir; *count += inputs run. */
static int run_dir(const char *dir, unsigned long *count)
{
    DIR *d = opendir(dir);
    char **names = NULL;
    size_t n = 0, cap = 0;
    int r = 0;
    struct dirent *e;

    if (d == NULL) {
        fprintf(stderr, "replay: cannot open folder %s\n", dir);
        return -1;
    }
    while ((e = readdir(d)) != NULL) {
        char *p;
        struct stat sb;
        size_t l = strlen(dir) + strlen(e->d_name) + 2;
        if (e->d_name[0] == '.')
            continue;
        p = malloc(l);
        if (p == NULL) {
            r = -1;
            break;
        }
        snprintf(p, l, "%s/%s", dir, e->d_name);
        if (stat(p, &sb) != 0 || !S_ISREG(sb.st_mode)) {
            free(p);
            continue;
        }
        if (n == cap) {
            char **nn = realloc(names, (cap = cap ? 2 * cap : 16) * sizeof *names);
            if (nn == NULL) {
                free(p);
                r = -1;
                break;
            }
            names = nn;
        }
        names[n++] = p;
    }
    closedir(d);
    if (n > 1)
        qsort(names, n, sizeof *names, by_name);
    for (size_t i = 0; i < n; i++) {
        if (r == 0 && run_file(names[i]) != 0)
            r = -1;
        else if (r == 0)
            (*count)++;
        free(names[i]);
    }
    free(names);
    return r;
}

int main(int argc, char **argv)
{
    unsigned long count = 0;
    for (int i = 1; i < argc; i++) {
        struct stat sb;
        if (stat(argv[i], &sb) != 0) {
            fprintf(stderr, "replay: no such file or folder: %s\n", argv[i]);
            return 2;
        }
        if (S_ISDIR(sb.st_mode) ? run_dir(argv[i], &count) != 0 : run_file(argv[i]) != 0)
            return 2;
        if (!S_ISDIR(sb.st_mode))
            count++;
    }
    if (count == 0) {
        fprintf(stderr, "replay: no inputs (usage: replay PATH...)\n");
        return 2;
    }
    fprintf(stderr, "replay: %lu inputs, no crash\n", count);
    return 0;
}
