/* gdt-tile — command-line entry point.  Maps status classes to exit codes. */
#include "gdt_cli.h"

int main(int argc, char **argv)
{
    return gdt_cli_main(argc, argv);
}
