// cgal_dt — test tool: Delaunay triangulation by CGAL, for comparison with
// the reference triangulator.
//
//   cgal_dt FILE|-
//
// Input and output formats are those of ref_dt: "x y" integer lines in;
// "V F" then the F finite faces as input-order vertex indices, each rotated
// so that its smallest index comes first (counter-clockwise kept), sorted.
// CGAL::Delaunay_triangulation_2 with exact predicates: coordinates below
// 2^31 are exact doubles.  CGAL resolves co-circular points its own way, so
// only sets in general position can be compared.
// Exit status: 0, 2 usage, 3 unreadable input, 7 exception.
#include <CGAL/Delaunay_triangulation_2.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_vertex_base_with_info_2.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <exception>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Vb = CGAL::Triangulation_vertex_base_with_info_2<long, Kernel>;
using Tds = CGAL::Triangulation_data_structure_2<Vb>;
using Delaunay = CGAL::Delaunay_triangulation_2<Kernel, Tds>;

static bool read_points(std::istream &in, std::vector<std::pair<Kernel::Point_2, long>> &pts)
{
    std::string line;
    while (std::getline(in, line)) {
        if (line.find_first_not_of(" \t\r") == std::string::npos)
            continue;
        std::istringstream ls(line);
        long long x, y;
        if (!(ls >> x >> y))
            return false;
        pts.emplace_back(Kernel::Point_2(static_cast<double>(x), static_cast<double>(y)),
                         static_cast<long>(pts.size()));
    }
    return true;
}

int main(int argc, char **argv)
{
    if (argc != 2) {
        std::fprintf(stderr, "usage: cgal_dt FILE|-\n");
        return 2;
    }
    try {
        std::vector<std::pair<Kernel::Point_2, long>> pts;
        bool ok;
        if (std::string(argv[1]) == "-") {
            ok = read_points(std::cin, pts);
        } else {
            std::ifstream f(argv[1]);
            ok = f.good() && read_points(f, pts);
        }
        if (!ok) {
            std::fprintf(stderr, "cgal_dt: cannot read points from %s\n", argv[1]);
            return 3;
        }
        Delaunay dt;
        dt.insert(pts.begin(), pts.end());
        std::vector<std::array<long, 3>> faces;
        if (dt.dimension() == 2) {
            for (auto f = dt.finite_faces_begin(); f != dt.finite_faces_end(); ++f) {
                std::array<long, 3> t = {f->vertex(0)->info(), f->vertex(1)->info(),
                                         f->vertex(2)->info()};
                auto lo = std::min_element(t.begin(), t.end()) - t.begin();
                std::rotate(t.begin(), t.begin() + lo, t.end());
                faces.push_back(t);
            }
        }
        std::sort(faces.begin(), faces.end());
        std::printf("%zu %zu\n", pts.size(), faces.size());
        for (const auto &t : faces)
            std::printf("%ld %ld %ld\n", t[0], t[1], t[2]);
    } catch (const std::exception &e) {
        std::fprintf(stderr, "cgal_dt: %s\n", e.what());
        return 7;
    }
    return 0;
}
