/* The modes of the gdt-tile command, one file each. */
#ifndef GDT_CLI_MODES_H
#define GDT_CLI_MODES_H

#include "gdt_cli.h"

/* --info: describe the inputs and the cloud they form; streams every point
 * once (bounded memory) to count what the headers cannot tell. */
gdt_status gdt_cli_info(const gdt_options *opts, gdt_error *err);

/* --reference: in-memory single-tile triangulation with the CPU reference,
 * written as the output PLY. */
gdt_status gdt_cli_reference(const gdt_options *opts, gdt_error *err);

/* GDT_EINTERRUPTED 1303 ("stopped by a signal during <where>") when
 * opts->stop is set, else GDT_OK: the check between the steps of the modes
 * that write nothing until their end. */
gdt_status gdt_cli_check_stop(const gdt_options *opts, const char *where, gdt_error *err);

/* The host threads of --threads K: K, or for 0 the online cores (1..1024). */
int gdt_cli_threads(int k);

#endif
