// pcd_dump_pcl — test tool: prints the points of a PCD file as read by PCL.
//
//   pcd_dump_pcl FILE
//
// Same line format as gdt_dump ("x y z X Y Z", %.17g, the LAS integers 0)
// and the same rule for invalid points: a point whose x, y or z is NaN or
// infinite is not printed.  Exit status: the gdt_status of a failure.
#include <cinttypes>
#include <cmath>
#include <cstdio>

#include <pcl/console/print.h>

#include "pcd_pcl.h"

namespace
{

int print_point(void *, double x, double y, double z)
{
    if (std::isfinite(x) && std::isfinite(y) && std::isfinite(z))
        std::printf("%.17g %.17g %.17g 0 0 0\n", x, y, z);
    return 0;
}

} // namespace

int main(int argc, char **argv)
{
    if (argc != 2) {
        std::fprintf(stderr, "usage: pcd_dump_pcl FILE\n");
        return GDT_EUSAGE;
    }
    pcl::console::setVerbosityLevel(pcl::console::L_ERROR);
    gdt_error err;
    gdt_error_clear(&err);
    std::uint64_t n = 0;
    const gdt_status st = gdt_pcd_pcl_read(argv[1], print_point, nullptr, &n, &err);
    if (st != GDT_OK) {
        gdt_error_print(&err, stderr);
        return static_cast<int>(st);
    }
    return std::fflush(stdout) == 0 ? 0 : GDT_EIO;
}
