/* Progress on stderr (see private/progress.h). */
#include "private/progress.h"

#include <stdio.h>
#include <string.h>
#include <unistd.h>

#include "private/run_stats.h"

#define BAR 30

void gdt_progress_init(gdt_progress *p, int verbosity)
{
    memset(p, 0, sizeof *p);
    if (verbosity < 0)
        p->mode = 0;
    else
        p->mode = isatty(STDERR_FILENO) ? 2 : 1;
}

static void human(char *buf, size_t len, double v)
{
    if (v >= 1e9)
        snprintf(buf, len, "%.2fG", v / 1e9);
    else if (v >= 1e6)
        snprintf(buf, len, "%.2fM", v / 1e6);
    else if (v >= 1e3)
        snprintf(buf, len, "%.1fk", v / 1e3);
    else
        snprintf(buf, len, "%.0f", v);
}

static void draw(gdt_progress *p, double now, int final)
{
    double el = now - p->t_stage, rate = el > 0 ? (double)p->done / el : 0;
    double frac = p->total > 0 ? (double)p->done / (double)p->total : 0;
    char d[16], t[16], r[16], eta[32] = "";
    if (frac > 1)
        frac = 1;
    human(d, sizeof d, (double)p->done);
    human(t, sizeof t, (double)p->total);
    human(r, sizeof r, rate);
    if (!final && p->total > 0 && rate > 0 && p->done < p->total)
        snprintf(eta, sizeof eta, ", ETA %.0f s", (double)(p->total - p->done) / rate);
    if (p->mode == 2) {
        char bar[BAR + 1];
        int fill = (int)(frac * BAR);
        for (int i = 0; i < BAR; i++)
            bar[i] = i < fill ? '#' : '.';
        bar[BAR] = '\0';
        fprintf(stderr, "\r%-8s [%s] %3.0f%%  %s/%s %s, %s %s/s%s   ", p->stage, bar,
                100 * frac, d, t, p->unit, r, p->unit, eta);
    } else if (final) {
        fprintf(stderr, "gdt-tile: %s: done, %s %s in %.2f s (%s %s/s)\n", p->stage, d, p->unit,
                el, r, p->unit);
    } else {
        fprintf(stderr, "gdt-tile: %s: %.0f%% (%s of %s %s), %s %s/s%s\n", p->stage,
                100 * frac, d, t, p->unit, r, p->unit, eta);
    }
    fflush(stderr);
}

void gdt_progress_stage(gdt_progress *p, const char *stage, uint64_t total, const char *unit)
{
    gdt_progress_end(p);
    if (p->mode == 0)
        return;
    snprintf(p->stage, sizeof p->stage, "%s", stage);
    p->unit = unit;
    p->total = total;
    p->done = 0;
    p->t_stage = p->t_last = gdt_now();
    p->open = 1;
    if (p->mode == 1)
        fprintf(stderr, "gdt-tile: %s: started (%llu %s)\n", p->stage,
                (unsigned long long)total, unit);
}

void gdt_progress_update(gdt_progress *p, uint64_t done)
{
    double now;
    if (p->mode == 0 || !p->open)
        return;
    p->done = done;
    now = gdt_now();
    if (now - p->t_last < (p->mode == 2 ? 0.1 : 2.0))
        return;
    p->t_last = now;
    draw(p, now, 0);
}

void gdt_progress_end(gdt_progress *p)
{
    if (p->mode == 0 || !p->open)
        return;
    p->open = 0;
    if (p->mode == 2)
        fputc('\r', stderr);
    if (p->mode == 1)
        draw(p, gdt_now(), 1);
    else
        fprintf(stderr, "%-8s done: %llu %s in %.2f s%40s\n", p->stage,
                (unsigned long long)p->done, p->unit, gdt_now() - p->t_stage, "");
    fflush(stderr);
}

void gdt_progress_abort(gdt_progress *p)
{
    if (p->mode == 0 || !p->open)
        return;
    p->open = 0;
    if (p->mode == 2) {
        fputc('\n', stderr);
        fflush(stderr);
    }
}
