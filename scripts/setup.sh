#!/usr/bin/env bash
# Installs what is missing on a Debian 12 machine, then configures and builds.
#
#   scripts/setup.sh [--asan] [--fuzz]
#
# System packages come from apt (installed only when missing); the Python
# test tools go into a project-local virtual environment (.venv), because
# Debian 12's system Python refuses pip installs.  The main tree build/ is a
# Release build.  --asan also builds the AddressSanitizer +
# UndefinedBehaviorSanitizer tree in build-asan/ (gcc, with MPI), --fuzz the clang tree
# build-fuzz/ with the libFuzzer targets (ASan + UBSan on every library; without MPI).
# Every tree is built with -Werror (GDT_WERROR=ON): warnings are errors in
# development and CI, not in a user's or packager's plain cmake build.
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$ROOT"

ASAN=0
FUZZ=0
for a in "$@"; do
  case "$a" in
    --asan) ASAN=1 ;;
    --fuzz) FUZZ=1 ;;
    *) echo "usage: scripts/setup.sh [--asan] [--fuzz]" >&2; exit 2 ;;
  esac
done

APT_PACKAGES=(
  build-essential cmake pkg-config python3 python3-venv
  pocl-opencl-icd ocl-icd-opencl-dev opencl-headers clinfo
  libpcl-dev libopenvdb-dev libgeographiclib-dev libsqlite3-dev libcgal-dev
  libgdal-dev gdal-bin
  openmpi-bin libopenmpi-dev
)
# The fuzz tree needs clang, and libFuzzer with clang's sanitizer runtimes
# (libclang-rt-14-dev, which clang only recommends).
if [ "$FUZZ" -eq 1 ]; then
  APT_PACKAGES+=(clang libclang-rt-14-dev)
fi

missing=()
for p in "${APT_PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing Debian packages: ${missing[*]}"
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends \
    "${missing[@]}" >/dev/null
fi

# Python test tools in .venv; reinstalled only when the requirements change.
REQ="$ROOT/scripts/requirements.txt"
if [ ! -x .venv/bin/python ]; then
  python3 -m venv .venv
fi
if ! cmp -s "$REQ" .venv/.requirements.installed 2>/dev/null; then
  echo "setup: installing Python test tools into .venv"
  .venv/bin/python -m pip install -q --upgrade pip >/dev/null
  .venv/bin/python -m pip install -q -r "$REQ"
  cp "$REQ" .venv/.requirements.installed
fi

JOBS=$(nproc 2>/dev/null || echo 2)
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release -DGDT_WERROR=ON >/dev/null
cmake --build build -j"$JOBS"
if [ "$ASAN" -eq 1 ]; then
  # with MPI (when Open MPI is installed), so the MPI stages run sanitized
  # too; the build without MPI is the fuzz tree's
  cmake -S . -B build-asan -DCMAKE_BUILD_TYPE=Debug -DGDT_SANITIZE=ON -DGDT_WERROR=ON >/dev/null
  cmake --build build-asan -j"$JOBS"
fi
if [ "$FUZZ" -eq 1 ]; then
  # without MPI: besides the fuzz targets, its gdt-tile is the sanitized
  # build without MPI that the launch tests need (a build without MPI under
  # mpirun); build-asan has MPI
  cmake -S . -B build-fuzz -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_C_COMPILER=clang \
    -DCMAKE_CXX_COMPILER=clang++ -DGDT_FUZZ=ON -DGDT_WERROR=ON -DGDT_MPI=OFF >/dev/null
  # the fuzz targets and what scripts/fuzz.sh makes their seeds with; the
  # tests and tools are the other trees'
  cmake --build build-fuzz -j"$JOBS" --target gdt_fuzz_all gdt-tile gdt-tile-module \
    pcd_write_pcl
fi
