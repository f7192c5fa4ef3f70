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

#endif
