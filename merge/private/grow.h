/* grow.h — growable arrays of the merge module. */
#ifndef GDT_MERGE_GROW_H
#define GDT_MERGE_GROW_H

#include <stddef.h>

/* Grows the array *p of *cap elements of elem bytes to hold at least need
 * (capacity doubling from first when empty); never shrinks.  On failure *p
 * and *cap are unchanged.  returns 0, or -1 when out of memory. */
int gdt_merge_grow(void **p, size_t *cap, size_t need, size_t elem, size_t first);

#endif
