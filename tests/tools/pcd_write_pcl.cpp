// pcd_write_pcl — test tool: writes a seeded pseudo-terrain cloud as PCD through PCL.
//
//   pcd_write_pcl --out FILE [--encoding ascii|binary|binary_compressed]
//                 [--type F4|F8|I1|I2|I4|I8|U1|U2|U4|U8] [--case lower|upper]
//                 [--extra LIST] [--xyz-last] [--width W] [--height H] [--seed S]
//                 [--origin X0,Y0] [--span S] [--nan-frac P] [--nan-z-only]
//                 [--precision D] [--typed xyz|xyzi|xyzrgb] [--via-cloud2]
//
// Without --typed the cloud is built field by field as a pcl::PCLPointCloud2
// (any type and name case, extra fields from LIST: intensity, rgb, normal
// (COUNT 3), label (U2), gps (F8)) and written with pcl::PCDWriter's
// PCLPointCloud2 writers.  With --typed it is a pcl::PointCloud<PointXYZ...>
// written with the templated writers, or converted to PCLPointCloud2 first
// (--via-cloud2: keeps PCL's alignment padding as '_' fields in binary).
// A fraction P of the points is made invalid (x, y, z NaN, or only z with
// --nan-z-only), as PCL does for organized clouds.
// Prints the number of valid points written on stdout.  Exit 0, or 2 on a
// usage error, or 4 when PCL cannot write.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <pcl/PCLPointCloud2.h>
#include <pcl/conversions.h>
#include <pcl/io/pcd_io.h>
#include <pcl/point_types.h>

namespace
{

struct Options {
    std::string out, encoding = "binary", type = "F8", name_case = "lower", extra, typed;
    bool xyz_last = false, nan_z_only = false, via_cloud2 = false;
    std::uint32_t width = 1000, height = 1;
    std::uint64_t seed = 1;
    double x0 = 0.0, y0 = 0.0, span = 1000.0, nan_frac = 0.0;
    int precision = 8;
};

struct Point {
    double x, y, z;
};

int usage()
{
    std::fprintf(stderr, "usage: pcd_write_pcl --out FILE [options] (see the source)\n");
    return 2;
}

// Pseudo terrain: gentle hills, uniform x/y in [origin, origin + span).
std::vector<Point> generate(const Options &o, std::mt19937_64 &rng)
{
    std::uniform_real_distribution<double> u(0.0, 1.0);
    const std::size_t n = static_cast<std::size_t>(o.width) * o.height;
    std::vector<Point> pts(n);
    const double nan = std::numeric_limits<double>::quiet_NaN();
    for (auto &p : pts) {
        const double a = u(rng), b = u(rng);
        p.x = o.x0 + a * o.span;
        p.y = o.y0 + b * o.span;
        p.z = 100.0 + 20.0 * std::sin(6.0 * a) * std::cos(5.0 * b) + u(rng);
        if (o.type[0] != 'F') { // integer coordinates: whole units
            p.x = std::floor(p.x);
            p.y = std::floor(p.y);
            p.z = std::floor(p.z);
        }
        if (o.nan_frac > 0.0 && u(rng) < o.nan_frac) {
            p.z = nan;
            if (!o.nan_z_only)
                p.x = p.y = nan;
        }
    }
    return pts;
}

struct FieldSpec {
    std::string name;
    std::uint8_t datatype;
    std::uint32_t count;
    unsigned size;
};

bool type_of(const std::string &t, std::uint8_t *dt, unsigned *size)
{
    using F = pcl::PCLPointField;
    static const struct {
        const char *n;
        std::uint8_t dt;
        unsigned size;
    } table[] = {{"F4", F::FLOAT32, 4}, {"F8", F::FLOAT64, 8}, {"I1", F::INT8, 1},
                 {"I2", F::INT16, 2},   {"I4", F::INT32, 4},   {"I8", F::INT64, 8},
                 {"U1", F::UINT8, 1},   {"U2", F::UINT16, 2},  {"U4", F::UINT32, 4},
                 {"U8", F::UINT64, 8}};
    for (const auto &e : table)
        if (t == e.n) {
            *dt = e.dt;
            *size = e.size;
            return true;
        }
    return false;
}

template <typename T> void put(std::uint8_t *p, double v)
{
    T t = static_cast<T>(v);
    std::memcpy(p, &t, sizeof t);
}

void store(std::uint8_t *p, std::uint8_t dt, double v)
{
    using F = pcl::PCLPointField;
    switch (dt) {
    case F::FLOAT32: put<float>(p, v); break;
    case F::FLOAT64: put<double>(p, v); break;
    case F::INT8: put<std::int8_t>(p, std::isnan(v) ? 0 : v); break;
    case F::INT16: put<std::int16_t>(p, std::isnan(v) ? 0 : v); break;
    case F::INT32: put<std::int32_t>(p, std::isnan(v) ? 0 : v); break;
    case F::INT64: put<std::int64_t>(p, std::isnan(v) ? 0 : v); break;
    case F::UINT8: put<std::uint8_t>(p, std::isnan(v) ? 0 : v); break;
    case F::UINT16: put<std::uint16_t>(p, std::isnan(v) ? 0 : v); break;
    case F::UINT32: put<std::uint32_t>(p, std::isnan(v) ? 0 : v); break;
    case F::UINT64: put<std::uint64_t>(p, std::isnan(v) ? 0 : v); break;
    default: break;
    }
}

int write_cloud2(const Options &o, const pcl::PCLPointCloud2 &cloud)
{
    pcl::PCDWriter w;
    int rc;
    if (o.encoding == "ascii")
        rc = w.writeASCII(o.out, cloud, Eigen::Vector4f::Zero(), Eigen::Quaternionf::Identity(),
                          o.precision);
    else if (o.encoding == "binary")
        rc = w.writeBinary(o.out, cloud);
    else
        rc = w.writeBinaryCompressed(o.out, cloud);
    return rc == 0 ? 0 : 4;
}

int write_manual(const Options &o, const std::vector<Point> &pts, std::mt19937_64 &rng)
{
    std::uint8_t xyz_dt;
    unsigned xyz_size;
    if (!type_of(o.type, &xyz_dt, &xyz_size))
        return usage();
    const bool upper = o.name_case == "upper";
    std::vector<FieldSpec> xyz = {{upper ? "X" : "x", xyz_dt, 1, xyz_size},
                                  {upper ? "Y" : "y", xyz_dt, 1, xyz_size},
                                  {upper ? "Z" : "z", xyz_dt, 1, xyz_size}};
    std::vector<FieldSpec> extra;
    std::stringstream ss(o.extra);
    std::string item;
    using F = pcl::PCLPointField;
    while (std::getline(ss, item, ',')) {
        if (item == "intensity")
            extra.push_back({upper ? "Intensity" : "intensity", F::FLOAT32, 1, 4});
        else if (item == "rgb")
            extra.push_back({"rgb", F::FLOAT32, 1, 4});
        else if (item == "normal")
            extra.push_back({"normal", F::FLOAT32, 3, 4});
        else if (item == "label")
            extra.push_back({"label", F::UINT16, 1, 2});
        else if (item == "gps")
            extra.push_back({"gps_time", F::FLOAT64, 1, 8});
        else if (!item.empty())
            return usage();
    }
    // Field order: x y z then extras, or the extras interleaved before each
    // coordinate (--xyz-last puts every extra field first).
    std::vector<FieldSpec> order;
    if (o.xyz_last) {
        order = extra;
        order.insert(order.end(), xyz.begin(), xyz.end());
    } else {
        order = xyz;
        order.insert(order.end(), extra.begin(), extra.end());
    }
    pcl::PCLPointCloud2 cloud;
    cloud.width = o.width;
    cloud.height = o.height;
    cloud.is_dense = o.nan_frac == 0.0;
    std::uint32_t off = 0;
    for (const auto &f : order) {
        pcl::PCLPointField pf;
        pf.name = f.name;
        pf.offset = off;
        pf.datatype = f.datatype;
        pf.count = f.count;
        cloud.fields.push_back(pf);
        off += f.size * f.count;
    }
    cloud.point_step = off;
    cloud.row_step = off * o.width;
    cloud.data.assign(static_cast<std::size_t>(off) * pts.size(), 0);
    std::uniform_int_distribution<std::uint32_t> colour(0, 0xffffffu);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    for (std::size_t i = 0; i < pts.size(); i++) {
        std::uint8_t *rec = cloud.data.data() + i * off;
        for (std::size_t k = 0; k < order.size(); k++) {
            const auto &f = order[k];
            std::uint8_t *p = rec + cloud.fields[k].offset;
            if (f.name.size() == 1) {
                const int a = (f.name[0] | 0x20) - 'x';
                store(p, f.datatype, a == 0 ? pts[i].x : a == 1 ? pts[i].y : pts[i].z);
            } else if (f.name == "rgb") {
                const std::uint32_t c = colour(rng) | 0xff000000u; // opaque, packed as PCL does
                std::memcpy(p, &c, 4);
            } else {
                for (std::uint32_t c = 0; c < f.count; c++)
                    store(p + c * f.size, f.datatype,
                          f.name == "label" ? 1000.0 * u(rng) : 1e6 * u(rng));
            }
        }
    }
    return write_cloud2(o, cloud);
}

template <typename PointT>
int write_typed(const Options &o, const std::vector<Point> &pts, std::mt19937_64 &rng)
{
    pcl::PointCloud<PointT> cloud;
    cloud.width = o.width;
    cloud.height = o.height;
    cloud.is_dense = o.nan_frac == 0.0;
    cloud.resize(pts.size());
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    for (std::size_t i = 0; i < pts.size(); i++) {
        auto &q = cloud[i];
        q.x = static_cast<float>(pts[i].x);
        q.y = static_cast<float>(pts[i].y);
        q.z = static_cast<float>(pts[i].z);
        if constexpr (std::is_same_v<PointT, pcl::PointXYZI>)
            q.intensity = 255.0f * u(rng);
        if constexpr (std::is_same_v<PointT, pcl::PointXYZRGB>) {
            q.r = static_cast<std::uint8_t>(255.0f * u(rng));
            q.g = static_cast<std::uint8_t>(255.0f * u(rng));
            q.b = static_cast<std::uint8_t>(255.0f * u(rng));
        }
    }
    cloud.width = o.width;
    cloud.height = o.height;
    if (o.via_cloud2) {
        pcl::PCLPointCloud2 c2;
        pcl::toPCLPointCloud2(cloud, c2);
        return write_cloud2(o, c2);
    }
    pcl::PCDWriter w;
    int rc;
    if (o.encoding == "ascii")
        rc = w.writeASCII(o.out, cloud, o.precision);
    else if (o.encoding == "binary")
        rc = w.writeBinary(o.out, cloud);
    else
        rc = w.writeBinaryCompressed(o.out, cloud);
    return rc == 0 ? 0 : 4;
}

} // namespace

int main(int argc, char **argv)
{
    Options o;
    for (int i = 1; i < argc; i++) {
        const std::string a = argv[i];
        const bool has = i + 1 < argc;
        if (a == "--out" && has)
            o.out = argv[++i];
        else if (a == "--encoding" && has)
            o.encoding = argv[++i];
        else if (a == "--type" && has)
            o.type = argv[++i];
        else if (a == "--case" && has)
            o.name_case = argv[++i];
        else if (a == "--extra" && has)
            o.extra = argv[++i];
        else if (a == "--typed" && has)
            o.typed = argv[++i];
        else if (a == "--width" && has)
            o.width = static_cast<std::uint32_t>(std::strtoul(argv[++i], nullptr, 10));
        else if (a == "--height" && has)
            o.height = static_cast<std::uint32_t>(std::strtoul(argv[++i], nullptr, 10));
        else if (a == "--seed" && has)
            o.seed = std::strtoull(argv[++i], nullptr, 10);
        else if (a == "--span" && has)
            o.span = std::strtod(argv[++i], nullptr);
        else if (a == "--nan-frac" && has)
            o.nan_frac = std::strtod(argv[++i], nullptr);
        else if (a == "--precision" && has)
            o.precision = std::atoi(argv[++i]);
        else if (a == "--origin" && has) {
            if (std::sscanf(argv[++i], "%lf,%lf", &o.x0, &o.y0) != 2)
                return usage();
        } else if (a == "--xyz-last")
            o.xyz_last = true;
        else if (a == "--nan-z-only")
            o.nan_z_only = true;
        else if (a == "--via-cloud2")
            o.via_cloud2 = true;
        else
            return usage();
    }
    if (o.out.empty() || o.width == 0 || o.height == 0 ||
        (o.encoding != "ascii" && o.encoding != "binary" && o.encoding != "binary_compressed") ||
        (o.name_case != "lower" && o.name_case != "upper"))
        return usage();
    std::mt19937_64 rng(o.seed);
    const std::vector<Point> pts = generate(o, rng);
    int rc;
    if (o.typed.empty())
        rc = write_manual(o, pts, rng);
    else if (o.typed == "xyz")
        rc = write_typed<pcl::PointXYZ>(o, pts, rng);
    else if (o.typed == "xyzi")
        rc = write_typed<pcl::PointXYZI>(o, pts, rng);
    else if (o.typed == "xyzrgb")
        rc = write_typed<pcl::PointXYZRGB>(o, pts, rng);
    else
        return usage();
    if (rc != 0)
        return rc;
    // Integer coordinates cannot hold NaN: the writer stored 0 for them.
    const bool int_xyz = o.typed.empty() && o.type[0] != 'F';
    std::size_t valid = 0;
    for (const auto &p : pts)
        valid += int_xyz || (std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z));
    std::printf("%zu\n", valid);
    return 0;
}
