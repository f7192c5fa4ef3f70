/* gdt_grow.h — growable arrays: the one helper every module uses. */
#ifndef GDT_GROW_H
#define GDT_GROW_H

#include <stddef.h>

/* Grows the array whose pointer is at pp (the address of a pointer of any
 * object type) from *cap elements of elem bytes to hold at least need
 * (capacity doubling from first when empty); never shrinks.  The pointer is
 * read and written with memcpy, not through a void ** lvalue, which strict
 * aliasing would let the optimiser ignore.  On failure the pointer and
 * *cap are unchanged.  returns 0, or -1 when out of memory. */
int gdt_grow(void *pp, size_t *cap, size_t need, size_t elem, size_t first);

#endif
