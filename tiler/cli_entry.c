/* The entry point of the program's module (private/cli_entry.h): the only
 * symbol the module exports. */
#include "gdt_cli.h"
#include "private/cli_entry.h"
#include "private/plugin.h"

__attribute__((visibility("default"))) int gdt_tile_entry(int argc, char **argv,
                                                          volatile sig_atomic_t *stop);

int gdt_tile_entry(int argc, char **argv, volatile sig_atomic_t *stop)
{
    gdt_cli_entry_fn check = gdt_tile_entry; /* the launcher's type, checked here */
    (void)check;
    gdt_plugin_beside_only(); /* the program's plug-ins are beside it, never elsewhere */
    return gdt_cli_main_stop(argc, argv, stop);
}
