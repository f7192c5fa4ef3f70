/* cli_entry.h — the one symbol the gdt-tile launcher (main.c) looks up
 * in the program's module (cli_entry.c): the whole program, given the
 * stop flag of the launcher's SIGINT/SIGTERM handlers (gdt_cli_main_stop).
 * Shared by both sides so that name and type cannot drift apart. */
#ifndef GDT_PRIVATE_CLI_ENTRY_H
#define GDT_PRIVATE_CLI_ENTRY_H

#include <signal.h>

#define GDT_CLI_ENTRY_SYMBOL "gdt_tile_entry"

typedef int (*gdt_cli_entry_fn)(int argc, char **argv, volatile sig_atomic_t *stop);

#endif
