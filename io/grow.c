/* grow.c — see gdt_grow.h. */
#include "gdt_grow.h"

#include <stdlib.h>
#include <string.h>

int gdt_grow(void *pp, size_t *cap, size_t need, size_t elem, size_t first)
{
    size_t c = *cap > 0 ? *cap : (first > 0 ? first : 1);
    void *p, *q;
    if (need <= *cap)
        return 0;
    while (c < need) {
        if (c > ((size_t)-1) / 2 / (elem > 0 ? elem : 1))
            return -1;
        c *= 2;
    }
    memcpy(&p, pp, sizeof p);
    q = realloc(p, c * elem);
    if (q == NULL)
        return -1;
    memcpy(pp, &q, sizeof q);
    *cap = c;
    return 0;
}
