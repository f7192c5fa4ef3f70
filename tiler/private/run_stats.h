/* Small process measurements for run summaries. */
#ifndef GDT_RUN_STATS_H
#define GDT_RUN_STATS_H

#include <stdint.h>

/* Monotonic clock in seconds. */
double gdt_now(void);
/* Peak resident set size of this process so far, in bytes. */
uint64_t gdt_peak_rss(void);

#endif
