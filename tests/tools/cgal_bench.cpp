// cgal_bench — CGAL's single-threaded 2D Delaunay triangulation on a points
// file, timed, for scripts/bench_core.py.
//
//   cgal_bench FILE [--repeat K]
//
// FILE is a points file of tests/tools/gcd_run.c ("GDTPTS1\n", uint64 count,
// int64 x, y pairs).  CGAL::Delaunay_triangulation_2 with the exact-predicates
// kernel (Epick); the points are inserted as one range, which CGAL sorts
// along a Hilbert curve first.  The time covers the construction only (not
// reading the file).  Output, one JSON object on stdout:
//   {"points": N, "vertices": V, "faces": F, "seconds": best of K}
// CGAL breaks co-circular ties its own way, so only the counts are
// comparable with gdt-tile's output, not the triangles.
// Exit status: 0, 1 unreadable file or exception, 2 usage.
#include <CGAL/Delaunay_triangulation_2.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <exception>
#include <fstream>
#include <string>
#include <vector>

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Delaunay = CGAL::Delaunay_triangulation_2<Kernel>;

static bool read_points(const char *path, std::vector<Kernel::Point_2> &pts)
{
    std::ifstream in(path, std::ios::binary);
    char magic[8];
    std::uint64_t n = 0;
    if (!in.read(magic, 8) || std::memcmp(magic, "GDTPTS1\n", 8) != 0 ||
        !in.read(reinterpret_cast<char *>(&n), 8) || n > (std::uint64_t(1) << 28))
        return false;
    std::vector<std::int64_t> xy(2 * n);
    if (n > 0 && !in.read(reinterpret_cast<char *>(xy.data()),
                          static_cast<std::streamsize>(16 * n)))
        return false;
    pts.reserve(n);
    for (std::uint64_t i = 0; i < n; i++)
        pts.emplace_back(static_cast<double>(xy[2 * i]), static_cast<double>(xy[2 * i + 1]));
    return true;
}

int main(int argc, char **argv)
{
    if (argc != 2 && !(argc == 4 && std::string(argv[2]) == "--repeat")) {
        std::fprintf(stderr, "usage: cgal_bench FILE [--repeat K]\n");
        return 2;
    }
    int repeat = argc == 4 ? std::atoi(argv[3]) : 1;
    if (repeat < 1)
        repeat = 1;
    try {
        std::vector<Kernel::Point_2> pts;
        if (!read_points(argv[1], pts)) {
            std::fprintf(stderr, "cgal_bench: cannot read points file %s\n", argv[1]);
            return 1;
        }
        double best = 0;
        std::size_t nv = 0, nf = 0;
        for (int k = 0; k < repeat; k++) {
            auto t0 = std::chrono::steady_clock::now();
            Delaunay dt;
            dt.insert(pts.begin(), pts.end());
            auto t1 = std::chrono::steady_clock::now();
            double s = std::chrono::duration<double>(t1 - t0).count();
            if (k == 0 || s < best)
                best = s;
            nv = dt.number_of_vertices();
            nf = dt.number_of_faces();
        }
        std::printf("{\"points\": %zu, \"vertices\": %zu, \"faces\": %zu, \"seconds\": %.6f}\n",
                    pts.size(), nv, nf, best);
    } catch (const std::exception &e) {
        std::fprintf(stderr, "cgal_bench: %s\n", e.what());
        return 1;
    } catch (...) {
        std::fprintf(stderr, "cgal_bench: unknown exception\n");
        return 1;
    }
    return 0;
}
