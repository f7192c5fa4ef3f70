#!/usr/bin/env bash
# The whole test suite: set-up (packages, .venv, the three builds), then
# CTest and pytest on the release build, the sanitizer-marked tests again on
# the ASan+UBSan build (with MPI), and on the clang fuzz build (ASan+UBSan,
# without MPI) the launch tests of a build without MPI, the saved fuzz
# inputs and a smoke run of every fuzz target (5 s each).  pytest runs its tests on one
# worker process per CPU (pytest-xdist): every test has its own temporary
# directory, and the few that time a run compare CPU seconds of their own
# children, so they do not depend on what runs beside them.
#
#   scripts/test.sh
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$ROOT"

# "== what (at M:SS)": each step with the time since the start, so a log
# shows where the suite's time goes
step() { printf '== %s (at %d:%02d)\n' "$1" $((SECONDS / 60)) $((SECONDS % 60)); }

# The builds' kernel compile check and the C tests compile the OpenCL kernels
# into a kernel cache of the suite's own; each pytest worker's cache starts
# as a copy of it (tests/python/conftest.py), so no worker compiles them again.
SEED="$ROOT/build/test-kernel-cache"
export POCL_CACHE_DIR="$SEED"

scripts/setup.sh --asan --fuzz

JOBS=$(nproc 2>/dev/null || echo 2)
export ASAN_OPTIONS=${ASAN_OPTIONS:-abort_on_error=0:detect_leaks=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}

# PoCL's CPU device builds a set of programs for every further command queue
# (core/gdt_ocl.h): one run with three queues, beside the release C tests,
# puts two such sets into the suite's cache for the pytest workers.  Not a
# test (those that check several queues are in pytest): a failure here only
# leaves the workers to compile the sets themselves.
warm_queue_programs() {
  local d rc=0
  d=$(mktemp -d)
  build/tests/gcd_run --gen lidar 5000 3 --grid 256 --dump-pcd "$d/q.pcd" --dump-only \
      > /dev/null 2>&1 &&
    build/tiler/gdt-tile "$d/q.pcd" -o "$d/q.ply" --queues 3 --tile 128 -q > /dev/null 2>&1 ||
    rc=$?
  rm -rf "$d"
  [ "$rc" -eq 0 ] || echo "note: the kernel cache was not filled for several queues (exit $rc)"
}

step "ctest (release build)"
warm_queue_programs &
WARM=$!
ctest --test-dir build --output-on-failure -j"$JOBS" || { rc=$?; wait "$WARM"; exit "$rc"; }
wait "$WARM"
step "ctest (ASan+UBSan build)"
ctest --test-dir build-asan --output-on-failure -j"$JOBS" -LE 'nosanitize|unsafe_fp'
# pytest: a kernel cache per worker, seeded; worksteal: a worker that runs
# out of tests takes some of the other's
unset POCL_CACHE_DIR
export GDT_TEST_POCL_SEED="$SEED"
PYTEST=(.venv/bin/python -m pytest -q -n "$JOBS" --dist worksteal)
step "pytest (release build)"
# --durations: the slowest tests named in the log, where the suite's time goes
GDT_BUILD_DIR="$ROOT/build" "${PYTEST[@]}" --durations=25 tests/python
step "pytest, sanitize-marked tests (ASan+UBSan build)"
GDT_BUILD_DIR="$ROOT/build-asan" "${PYTEST[@]}" -m sanitize tests/python
step "pytest, launch tests of a build without MPI (clang ASan+UBSan fuzz build)"
GDT_BUILD_DIR="$ROOT/build-fuzz" "${PYTEST[@]}" tests/python/test_launch.py
step "ctest, saved fuzz inputs (clang fuzz build)"
ctest --test-dir build-fuzz --output-on-failure -L fuzz
step "fuzz smoke run (clang fuzz build)"
scripts/fuzz.sh smoke build-fuzz 5
step "all tests passed"
