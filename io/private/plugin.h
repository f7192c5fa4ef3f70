/* plugin.h — modules loaded only by the runs that need them.
 *
 * Some libraries cost a run more to load than many runs take to compute:
 * PCL's segmentation and its dependencies add about 0.15 s of symbol
 * binding to every start.  Code that needs such a library lives in a module
 * of its own (libgdt-tile-NAME.so) with a C entry point, loaded on first
 * use by the run that needs it and never unloaded.
 *
 * A module is looked for in the directory of the object that holds this
 * code (the program's module, beside which the build puts every plug-in),
 * then, unless gdt_plugin_beside_only was called (the program does), in
 * GDT_PLUGIN_DIR, the build's plug-in directory, for the test programs
 * that link the libraries statically.  Thread-safe: concurrent first uses
 * load the module once. */
#ifndef GDT_PLUGIN_H
#define GDT_PLUGIN_H

#include "gdt_error.h"

#ifdef __cplusplus
extern "C" {
#endif

/* From now on modules are looked for beside this code only. */
void gdt_plugin_beside_only(void);

/* *out = the address of symbol sym of module file (a file name such as
 * "libgdt-tile-pcl.so"); what names what the module is for in the message.
 * returns: GDT_OK; GDT_EINTERNAL 7004 (the module cannot be loaded, or has
 *   no such symbol: the message names the paths tried and the loader's
 *   reason). */
gdt_status gdt_plugin_symbol(const char *file, const char *sym, const char *what, void **out,
                             gdt_error *err);

#ifdef __cplusplus
}
#endif
#endif
