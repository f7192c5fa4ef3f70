// Reference PCD reader through PCL; contract in pcd_pcl.h.
#include "pcd_pcl.h"

#include <cstring>
#include <exception>
#include <string>

#include <pcl/PCLPointCloud2.h>
#include <pcl/io/pcd_io.h>

namespace
{

bool name_is(const std::string &name, char axis)
{
    return name.size() == 1 && (name[0] == axis || name[0] == axis - 'a' + 'A');
}

template <typename T> double load(const std::uint8_t *p)
{
    T v;
    std::memcpy(&v, p, sizeof v);
    return static_cast<double>(v);
}

// Bytes of one value of a PCL datatype; 0 for unknown types.
unsigned field_bytes(std::uint8_t datatype)
{
    using F = pcl::PCLPointField;
    switch (datatype) {
    case F::INT8:
    case F::UINT8: return 1;
    case F::INT16:
    case F::UINT16: return 2;
    case F::INT32:
    case F::UINT32:
    case F::FLOAT32: return 4;
    case F::INT64:
    case F::UINT64:
    case F::FLOAT64: return 8;
    default: return 0;
    }
}

// Value of a PCL field of the given datatype at p; false for unknown types.
bool load_field(std::uint8_t datatype, const std::uint8_t *p, double *out)
{
    using F = pcl::PCLPointField;
    switch (datatype) {
    case F::INT8: *out = load<std::int8_t>(p); return true;
    case F::UINT8: *out = load<std::uint8_t>(p); return true;
    case F::INT16: *out = load<std::int16_t>(p); return true;
    case F::UINT16: *out = load<std::uint16_t>(p); return true;
    case F::INT32: *out = load<std::int32_t>(p); return true;
    case F::UINT32: *out = load<std::uint32_t>(p); return true;
    case F::INT64: *out = load<std::int64_t>(p); return true;
    case F::UINT64: *out = load<std::uint64_t>(p); return true;
    case F::FLOAT32: *out = load<float>(p); return true;
    case F::FLOAT64: *out = load<double>(p); return true;
    default: return false;
    }
}

gdt_status read_cloud(const char *path, gdt_pcd_pcl_point_fn fn, void *ctx, std::uint64_t *count,
                      gdt_error *err)
{
    pcl::PCLPointCloud2 cloud;
    pcl::PCDReader reader;
    if (reader.read(path, cloud) < 0)
        return gdt_error_set(err, GDT_EINPUT, 3290, "%s: PCL cannot read this PCD file", path);
    const pcl::PCLPointField *axis[3] = {nullptr, nullptr, nullptr};
    for (const auto &f : cloud.fields) {
        for (int a = 0; a < 3; a++) {
            if (!name_is(f.name, static_cast<char>('x' + a)))
                continue;
            if (axis[a] != nullptr)
                return gdt_error_set(err, GDT_EINPUT, 3291, "%s: two fields name coordinate %c",
                                     path, 'x' + a);
            axis[a] = &f;
        }
    }
    for (int a = 0; a < 3; a++) {
        if (axis[a] == nullptr)
            return gdt_error_set(err, GDT_EINPUT, 3291, "%s: PCL finds no %c field", path, 'x' + a);
        const unsigned bytes = field_bytes(axis[a]->datatype);
        if (bytes == 0 || std::uint64_t{axis[a]->offset} + bytes > cloud.point_step)
            return gdt_error_set(err, GDT_EINPUT, 3293,
                                 "%s: PCL field %s has an unusable type or offset", path,
                                 axis[a]->name.c_str());
    }
    const std::uint64_t n = static_cast<std::uint64_t>(cloud.width) * cloud.height;
    if (count != nullptr)
        *count = n;
    if (cloud.data.size() / cloud.point_step < n)
        return gdt_error_set(err, GDT_EINPUT, 3292,
                             "%s: PCL returned %zu data bytes for %llu "
                             "points",
                             path, cloud.data.size(), static_cast<unsigned long long>(n));
    for (std::uint64_t i = 0; i < n; i++) {
        const std::uint8_t *rec = cloud.data.data() + i * cloud.point_step;
        double v[3] = {0.0, 0.0, 0.0};
        for (int a = 0; a < 3; a++)
            load_field(axis[a]->datatype, rec + axis[a]->offset, &v[a]);
        if (fn(ctx, v[0], v[1], v[2]) != 0)
            return gdt_error_set(err, GDT_EINTERNAL, 7290, "%s: reading stopped by the caller",
                                 path);
    }
    return GDT_OK;
}

} // namespace

extern "C" gdt_status gdt_pcd_pcl_read(const char *path, gdt_pcd_pcl_point_fn fn, void *ctx,
                                       uint64_t *count, gdt_error *err)
{
    try {
        return read_cloud(path, fn, ctx, count, err);
    } catch (const std::exception &e) {
        return gdt_error_set(err, GDT_EINPUT, 3294, "%s: PCL failed: %s", path, e.what());
    } catch (...) {
        return gdt_error_set(err, GDT_EINPUT, 3294, "%s: PCL failed with an unknown exception",
                             path);
    }
}
