#!/usr/bin/env bash
# The one command for a GPU machine: the gCD core on the machine's OpenCL
# GPU, checked exactly against the CPU reference and timed phase by phase,
# printed as one table.
#
#   scripts/gpu_check.sh --make-bundle DIR [--build-dir B]   (here, with the build)
#   DIR/gpu_check.sh [--cpu] [--sizes LIST] [--perf-sizes LIST] [--e2e-sizes LIST]
#                    [--timeout S] [--own-libc]
#
# --make-bundle copies into DIR what a bare machine lacks: the core driver
# gcd_run (tests/tools/gcd_run.c) with every shared library it loads (the
# OpenCL ICD loader, GeographicLib, libstdc++ ... and the C library and its
# dynamic loader, used when the machine's glibc is older than this one's, or
# with --own-libc), CGAL's triangulation as a static program
# (tests/tools/cgal_bench.cpp, target cgal_bench_static, built when CGAL and
# the static GMP and MPFR are installed), the program gdt-tile itself (its
# launcher and module with their libraries; not the PCL and GDAL plug-ins,
# which a plain run does not load), the kernel sources and this script.
# Nothing is installed anywhere.
#
# Run from a bundle, on a machine with an NVIDIA driver: it finds the
# driver's OpenCL library (libnvidia-opencl.so.1) and writes an ICD file
# for it in a temporary directory (OCL_ICD_VENDORS), or says in one line
# that there is none and stops (exit 3).  Then, on the GPU:
#   - gcd_run --check --reference for the uniform, lidar and grid kinds at
#     each of --sizes (default 1M 4M): the core's triangles checked exactly
#     (Delaunay, every point a vertex) and equal to the CPU reference's;
#   - per-phase times (best of 2) of lidar points at --perf-sizes (default
#     1M 4M 16M 64M), and CGAL's time (Delaunay_triangulation_2, Epick, one
#     thread, best of 1) on the same points on this machine's CPU, with the
#     ratio CGAL / core (above 1: the core is faster);
#   - end to end, gdt-tile on a generated LiDAR-like cloud (binary PCD) at
#     each of --e2e-sizes (default 16M), the tile side its own choice for
#     the device, with one and with two command queues (--queues): wall
#     time, the tile stage, the core's time in it and the share of the tile
#     stage the device was busy;
#   - the device's name and memory;
# as one table.  The sizes are meant to finish within 8 minutes on an
# H100/H200-class machine; each gcd_run is cut at --timeout (420 s).
# --cpu runs the same on this machine's OpenCL CPU device (PoCL), sizes
# scaled down unless given (default 20K 50K, perf 50K 200K, e2e 100K), which is how
# the script itself is tested.  Exit: 0 every check passed; 1 a check
# failed; 2 usage; 3 no OpenCL GPU driver.
set -euo pipefail

HERE=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)

usage() {
  echo "usage: gpu_check.sh --make-bundle DIR [--build-dir B] | [--cpu] [--sizes LIST]" \
       "[--perf-sizes LIST] [--e2e-sizes LIST] [--timeout S] [--own-libc]" >&2
  exit 2
}

# ---- building the bundle (on the build machine) ----------------------------
# every library exe loads: the C library's own (and its loader) in DIR/libc/,
# the others in DIR/lib/
copy_libs() {
  local exe=$1 dir=$2 lib
  ldd "$exe" | awk '/=> \// {print $3} /^\t\/.*ld-linux/ {print $1}' | while read -r lib; do
    case "$(basename "$lib")" in
      ld-linux*|libc.so*|libm.so*) cp -L "$lib" "$dir/libc/" ;;
      *) cp -L "$lib" "$dir/lib/" ;;
    esac
  done
}

make_bundle() {
  local dir=$1 build=$2 exe lib
  exe=$build/tests/gcd_run
  [ -x "$exe" ] || { echo "gpu_check: $exe not built" >&2; exit 2; }
  mkdir -p "$dir/lib" "$dir/libc" "$dir/kernels"
  cp "$exe" "$dir/gcd_run"
  copy_libs "$exe" "$dir"
  # and the parts of the C library a vendor driver may load: libpthread,
  # libdl, librt
  for lib in libpthread.so.0 libdl.so.2 librt.so.1; do
    for d in /lib/x86_64-linux-gnu /usr/lib/x86_64-linux-gnu /lib64; do
      if [ -e "$d/$lib" ]; then cp -L "$d/$lib" "$dir/libc/"; break; fi
    done
  done
  getconf GNU_LIBC_VERSION | awk '{print $2}' > "$dir/libc/VERSION"
  if [ -x "$build/tests/cgal_bench_static" ]; then
    cp "$build/tests/cgal_bench_static" "$dir/cgal_bench"
  else
    echo "gpu_check: no static CGAL harness in $build (needs libcgal-dev and the static" \
         "GMP and MPFR): the table will have no CGAL times" >&2
  fi
  if [ -x "$build/tiler/gdt-tile" ] && [ -f "$build/tiler/libgdt-tile.so" ]; then
    # the launcher loads its module from the directory of the running
    # program: beside it, and beside the bundle's loader (libc/), which is
    # the running program when the bundle's C library runs it
    cp "$build/tiler/gdt-tile" "$build/tiler/libgdt-tile.so" "$dir/"
    ln -sf ../libgdt-tile.so "$dir/libc/libgdt-tile.so"
    copy_libs "$build/tiler/libgdt-tile.so" "$dir"
  else
    echo "gpu_check: no gdt-tile in $build/tiler: the table will have no end-to-end rows" >&2
  fi
  cp "$HERE/../kernels/"*.cl "$HERE/../kernels/"*.clh "$dir/kernels/"
  cp "${BASH_SOURCE[0]}" "$dir/gpu_check.sh"
  chmod +x "$dir/gpu_check.sh"
  echo "gpu_check: bundle in $dir ($(du -sh "$dir" | cut -f1)); run $dir/gpu_check.sh there"
}

# n with K/M suffixes -> an integer
count_of() {
  case "$1" in
    *M) echo $(( ${1%M} * 1000000 )) ;;
    *K) echo $(( ${1%K} * 1000 )) ;;
    *) echo "$1" ;;
  esac
}

# a tile side (power of two) of about 4 texels a point, as the tiler plans
grid_of() {
  local n=$1 g=256
  while [ $(( g * g )) -lt $(( 4 * n )) ]; do g=$(( g * 2 )); done
  echo "$g"
}

CPU=0
OWN_LIBC=0
SIZES=""
PERF=""
E2E=""
TIMEOUT=420
BUNDLE_OUT=""
BUILD_DIR="$HERE/../build"
while [ $# -gt 0 ]; do
  case "$1" in
    --make-bundle) BUNDLE_OUT=$2; shift 2 ;;
    --build-dir) BUILD_DIR=$2; shift 2 ;;
    --cpu) CPU=1; shift ;;
    --sizes) SIZES=$2; shift 2 ;;
    --perf-sizes) PERF=$2; shift 2 ;;
    --e2e-sizes) E2E=$2; shift 2 ;;
    --timeout) TIMEOUT=$2; shift 2 ;;
    --own-libc) OWN_LIBC=1; shift ;;
    *) usage ;;
  esac
done
if [ -n "$BUNDLE_OUT" ]; then
  make_bundle "$BUNDLE_OUT" "$BUILD_DIR"
  exit 0
fi
[ -x "$HERE/gcd_run" ] && [ -d "$HERE/lib" ] && [ -f "$HERE/libc/VERSION" ] ||
  { echo "gpu_check: run from a bundle (scripts/gpu_check.sh --make-bundle DIR)" >&2; exit 2; }

if [ "$CPU" -eq 1 ]; then
  DEVICE=cpu
  SIZES=${SIZES:-"20K 50K"}
  PERF=${PERF:-"50K 200K"}
  E2E=${E2E:-"100K"}
else
  DEVICE=gpu
  SIZES=${SIZES:-"1M 4M"}
  PERF=${PERF:-"1M 4M 16M 64M"}
  E2E=${E2E:-"16M"}
  NV=""
  for d in $(ldconfig -p 2>/dev/null | awk '/libnvidia-opencl\.so\.1/ {print $NF}') \
           /usr/lib/x86_64-linux-gnu/libnvidia-opencl.so.1 /usr/lib64/libnvidia-opencl.so.1 \
           /usr/local/nvidia/lib64/libnvidia-opencl.so.1 /usr/lib/libnvidia-opencl.so.1; do
    if [ -e "$d" ]; then NV=$d; break; fi
  done
  if [ -z "$NV" ]; then
    echo "gpu_check: no NVIDIA OpenCL driver (libnvidia-opencl.so.1) on this machine; nothing run"
    exit 3
  fi
  ICD=$(mktemp -d)
  echo "$NV" > "$ICD/nvidia.icd"
  export OCL_ICD_VENDORS=$ICD
fi
export GDT_KERNEL_DIR=$HERE/kernels
# the perf sizes' points, for CGAL (16 bytes a point)
PTS=$(mktemp -d)
trap 'rm -rf "$PTS" ${ICD:+"$ICD"}' EXIT
CGAL=0
[ -x "$HERE/cgal_bench" ] && CGAL=1
T_START=$(date +%s)
# The machine's C library when it is at least the bundle's (a vendor driver
# is built for the machine's), else the bundle's own with its loader.
ver_ge() { [ "$(printf '%s\n%s\n' "$1" "$2" | sort -V | head -1)" = "$2" ]; }
SYSLIBC=$(getconf GNU_LIBC_VERSION 2>/dev/null | awk '{print $2}')
if [ "$OWN_LIBC" -eq 0 ] && [ -n "$SYSLIBC" ] && ver_ge "$SYSLIBC" "$(cat "$HERE/libc/VERSION")"; then
  LIBC_NOTE="this machine's glibc $SYSLIBC"
  run_core() {
    LD_LIBRARY_PATH="$HERE/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}" timeout "$TIMEOUT" \
      "$HERE/gcd_run" --device "$DEVICE" "$@"
  }
  run_tile() {
    LD_LIBRARY_PATH="$HERE/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}" timeout "$TIMEOUT" \
      "$HERE/gdt-tile" --device "$DEVICE" "$@"
  }
else
  LIBC_NOTE="the bundle's glibc $(cat "$HERE/libc/VERSION")"
  LOADER=$(ls "$HERE"/libc/ld-linux* | head -1)
  run_core() {
    timeout "$TIMEOUT" "$LOADER" --library-path "$HERE/lib:$HERE/libc" "$HERE/gcd_run" \
      --device "$DEVICE" "$@"
  }
  run_tile() {
    timeout "$TIMEOUT" "$LOADER" --library-path "$HERE/lib:$HERE/libc" "$HERE/gdt-tile" \
      --device "$DEVICE" "$@"
  }
fi


fail=0
rows=()
devname=""
for kind in uniform lidar grid; do
  for s in $SIZES; do
    n=$(count_of "$s")
    if out=$(run_core --grid "$(grid_of "$n")" --gen "$kind" "$n" 7 --check --reference --json 2>&1); then
      j=$(grep '^{' <<< "$out" | tail -1)
      devname=$(sed -n 's/.*"device": "\([^"]*\)".*/\1/p' <<< "$j")
      total=$(sed -n 's/.*"total": \([0-9.]*\).*/\1/p' <<< "$j")
      ref=$(sed -n 's/.*"reference": \([0-9.]*\).*/\1/p' <<< "$j")
      rows+=("$(printf '%-8s %10s  %-9s %9.3f %9.3f' "$kind" "$n" "equal" "$total" "$ref")")
    else
      rows+=("$(printf '%-8s %10s  %-9s %s' "$kind" "$n" "FAILED" "$(tail -1 <<< "$out")")")
      fail=1
    fi
  done
done
prow=()
for s in $PERF; do
  n=$(count_of "$s")
  dump=()
  [ "$CGAL" -eq 1 ] && dump=(--dump-points "$PTS/lidar-$n.pts")
  if out=$(run_core --grid "$(grid_of "$n")" --gen lidar "$n" 7 --repeat 2 "${dump[@]}" \
             --json 2>&1); then
    j=$(grep '^{' <<< "$out" | tail -1)
    devname=$(sed -n 's/.*"device": "\([^"]*\)".*/\1/p' <<< "$j")
    t() { sed -n "s/.*\"$1\": \\([0-9.]*\\).*/\\1/p" <<< "$j"; }
    row="$(printf '%10s %6s %8.3f %8.3f %8.3f %8.3f %8.3f %8.3f %8.3f %8.3f %6.1f' "$n" \
      "$(grid_of "$n")" "$(t upload)" "$(t phase1)" "$(t phase2)" "$(t phase3)" "$(t phase4)" \
      "$(t phase5)" "$(t download)" "$(t total)" \
      "$(awk -v n="$n" -v s="$(t total)" 'BEGIN { print (s > 0 ? n / s / 1e6 : 0) }')")"
    if [ "$CGAL" -eq 1 ]; then
      # CGAL on the same points, the statically linked harness (no libraries)
      if cg=$(timeout "$TIMEOUT" "$HERE/cgal_bench" "$PTS/lidar-$n.pts" 2>&1); then
        cs=$(sed -n 's/.*"seconds": \([0-9.e-]*\).*/\1/p' <<< "$cg")
        row+="$(awk -v c="$cs" -v s="$(t total)" \
          'BEGIN { printf " %8.3f %7.1f", c, (s > 0 ? c / s : 0) }')"
      else
        row+=" CGAL FAILED $(tail -1 <<< "$cg")"
        fail=1
      fi
      rm -f "$PTS/lidar-$n.pts"
    fi
    prow+=("$row")
  else
    prow+=("$(printf '%10s FAILED %s' "$n" "$(tail -1 <<< "$out")")")
    fail=1
  fi
done

# end to end: gdt-tile on a generated cloud, one and two queues
erow=()
E2E_ON=0
[ -x "$HERE/gdt-tile" ] && E2E_ON=1
# a member of the "times" object of a --json file (one member a line)
jtime() { awk -v k="\"$1\":" '/"times": \{/ {t = 1; next} t && /}/ {t = 0}
  t && $1 == k {gsub(",", "", $2); print $2}' "$2"; }
for s in $([ "$E2E_ON" -eq 1 ] && echo "$E2E"); do
  n=$(count_of "$s")
  if ! out=$(run_core --gen lidar "$n" 7 --grid "$(grid_of "$n")" --dump-pcd "$PTS/e2e.pcd" \
               --dump-only 2>&1); then
    erow+=("$(printf '%10s FAILED %s' "$n" "$(tail -1 <<< "$out")")")
    fail=1
    continue
  fi
  for q in 1 2; do
    t0=$(date +%s.%N)
    if out=$(run_tile "$PTS/e2e.pcd" -o "$PTS/e2e.ply" --queues "$q" --json "$PTS/e2e.json" \
               -q 2>&1); then
      t1=$(date +%s.%N)
      tile=$(awk '$1 == "\"tile\":" {gsub(",", "", $2); print $2}' "$PTS/e2e.json")
      erow+=("$(printf '%10s %6s %6s %8.3f %8.3f %8.3f %6.1f' "$n" "$tile" "$q" \
        "$(awk -v a="$t0" -v b="$t1" 'BEGIN { print b - a }')" "$(jtime tiles "$PTS/e2e.json")" \
        "$(jtime core "$PTS/e2e.json")" \
        "$(awk -v s="$(jtime device_busy_share "$PTS/e2e.json")" 'BEGIN { print 100 * s }')")")
    else
      erow+=("$(printf '%10s %6s %6s FAILED %s' "$n" "-" "$q" "$(tail -1 <<< "$out")")")
      fail=1
    fi
    rm -rf "$PTS/e2e.ply" "$PTS/e2e.json" "$PTS/e2e.ply.gdt-job"
  done
  rm -f "$PTS/e2e.pcd"
done

if [ "$CPU" -eq 1 ]; then
  mem="$(awk '/MemTotal/ {printf "%.1f GiB host memory", $2 / 1048576}' /proc/meminfo)"
elif command -v nvidia-smi >/dev/null 2>&1; then
  mem="$(nvidia-smi --query-gpu=memory.total --format=csv,noheader | head -1)"
else
  mem="memory unknown (no nvidia-smi)"
fi
echo "gpu_check: ${devname:-unknown device}, $mem; $LIBC_NOTE"
echo "exactness (gcd_run --check --reference), seconds (one run each: the first may include compiling kernel variants)"
printf '%-8s %10s  %-9s %9s %9s\n' kind points result core reference
printf '%s\n' "${rows[@]}"
if [ "$CGAL" -eq 1 ]; then
  echo "phases, lidar points, best of 2, seconds; CGAL on the same points (one CPU thread)," \
    "x = CGAL / core total"
  printf '%10s %6s %8s %8s %8s %8s %8s %8s %8s %8s %6s %8s %7s\n' points grid upload p1 p2 p3 \
    p4 p5 download total Mpt/s cgal x
else
  echo "phases, lidar points, best of 2, seconds (no CGAL harness in the bundle)"
  printf '%10s %6s %8s %8s %8s %8s %8s %8s %8s %8s %6s\n' points grid upload p1 p2 p3 p4 p5 \
    download total Mpt/s
fi
printf '%s\n' "${prow[@]}"
if [ "$E2E_ON" -eq 1 ]; then
  echo "end to end, gdt-tile on lidar points (binary PCD), tile side its own choice," \
    "seconds; busy = % of the tile stage the device worked"
  printf '%10s %6s %6s %8s %8s %8s %6s\n' points tile queues wall tiles core busy%
  printf '%s\n' "${erow[@]}"
else
  echo "end to end: no gdt-tile in the bundle"
fi
echo "gpu_check: $(( $(date +%s) - T_START )) s"
exit "$fail"
