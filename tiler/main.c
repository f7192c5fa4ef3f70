/* gdt-tile — command-line entry point.  Maps status classes to exit codes. */
#include "gdt_cli.h"

#if defined(__ELF__) && defined(__GNUC__)
/* The libraries' initializers (OpenVDB, TBB, the OpenCL loader) run before
 * main and take tens of milliseconds; a SIGINT or SIGTERM in that window
 * would kill by its default action, without a word.  An entry of
 * .preinit_array runs before any of them, just after the dynamic loader has
 * mapped the program, so the handlers are in place from then on. */
static void install_early(int argc, char **argv, char **envp)
{
    (void)argc;
    (void)argv;
    (void)envp;
    gdt_cli_install_signal_handlers();
}

__attribute__((section(".preinit_array"), used)) static void (*const gdt_preinit)(int, char **,
                                                                                   char **) =
    install_early;
#endif

int main(int argc, char **argv)
{
    return gdt_cli_main(argc, argv);
}
