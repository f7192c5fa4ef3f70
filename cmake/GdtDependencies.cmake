# Every third-party dependency comes from Debian 12 packages; see
# scripts/setup.sh for the package list.  Each is required: a missing one is a
# configure error naming the Debian package to install.

find_package(PkgConfig REQUIRED)

macro(gdt_require found pkg what)
  if(NOT ${found})
    message(FATAL_ERROR "gdt-tile needs ${what}: install the Debian package '${pkg}' "
                        "(or run scripts/setup.sh)")
  endif()
endmacro()

# OpenCL (ICD loader; PoCL provides the CPU device at run time).
find_package(OpenCL QUIET)
gdt_require(OpenCL_FOUND "ocl-icd-opencl-dev opencl-headers" "OpenCL")

# SQLite (job state).
pkg_check_modules(SQLITE3 QUIET IMPORTED_TARGET sqlite3)
gdt_require(SQLITE3_FOUND libsqlite3-dev "SQLite 3")

# GeographicLib (CRS projection).
pkg_check_modules(GEOGRAPHICLIB QUIET IMPORTED_TARGET geographiclib)
gdt_require(GEOGRAPHICLIB_FOUND libgeographiclib-dev "GeographicLib")

# GDAL (the DEM GeoTIFF and its preview).
pkg_check_modules(GDAL QUIET IMPORTED_TARGET gdal)
gdt_require(GDAL_FOUND libgdal-dev "GDAL")

# PCL: PCD input (io) and the ground filter (segmentation).
find_package(PCL QUIET COMPONENTS common io segmentation)
gdt_require(PCL_FOUND libpcl-dev "PCL (Point Cloud Library)")

# OpenVDB (tile index); Debian ships its Find module in a versioned folder.
list(APPEND CMAKE_MODULE_PATH /usr/lib/x86_64-linux-gnu/cmake/OpenVDB
                              /usr/lib/${CMAKE_LIBRARY_ARCHITECTURE}/cmake/OpenVDB)
find_package(OpenVDB QUIET)
gdt_require(OpenVDB_FOUND libopenvdb-dev "OpenVDB")

find_package(Threads REQUIRED)
find_library(GDT_LIBM m)

# MPI (mpirun: one job over many ranks) is optional: a build without it
# runs one process and refuses a parallel launch with a message.
option(GDT_MPI "Build the MPI scheduler when an MPI library is found" ON)
set(GDT_HAVE_MPI OFF)
if(GDT_MPI)
  find_package(MPI QUIET COMPONENTS C)
  if(MPI_C_FOUND)
    set(GDT_HAVE_MPI ON)
  endif()
endif()
