/* gcd_single_tile — the single-tile mode of gdt-tile (tiler/single_tile.c)
 * as a stand-alone command for the tests: same command line as gdt-tile
 * (gdt_cli_parse), same exit codes.
 *
 *   gcd_single_tile INPUT [INPUT ...] -o OUT.ply [--tile N] [--device SPEC]
 *                   [--dup ...] [--quantum Q] [--check] [--json FILE] [-q] [-v] */
#include <stdio.h>

#include "gdt_cli.h"
#include "private/single_tile.h"

int main(int argc, char **argv)
{
    gdt_options opts;
    gdt_error err;
    gdt_status st;

    gdt_error_clear(&err);
    st = gdt_cli_parse(&opts, argc, argv, &err);
    if (st == GDT_OK && opts.mode != GDT_MODE_RUN)
        st = gdt_error_set(&err, GDT_EUSAGE, 2000, "only the plain run mode is supported here");
    if (st == GDT_OK)
        st = gdt_cli_single_tile(&opts, &err);
    if (st != GDT_OK)
        gdt_error_print(&err, stderr);
    gdt_options_free(&opts);
    return (int)st;
}
