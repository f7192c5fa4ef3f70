#!/usr/bin/env bash
# The whole test suite: set-up (packages, .venv, the three builds), then
# CTest and pytest on the release build, the sanitizer-marked tests again on
# the ASan+UBSan build (with MPI), and on the clang fuzz build (ASan+UBSan,
# without MPI) the launch tests of a build without MPI, the saved fuzz
# inputs and a smoke run of every fuzz target (10 s each).  pytest runs its tests on one
# worker process per CPU (pytest-xdist): every test has its own temporary
# directory, and the few that time a run compare CPU seconds of their own
# children, so they do not depend on what runs beside them.
#
#   scripts/test.sh
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$ROOT"

scripts/setup.sh --asan --fuzz

JOBS=$(nproc 2>/dev/null || echo 2)
export ASAN_OPTIONS=${ASAN_OPTIONS:-abort_on_error=0:detect_leaks=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}

echo "== ctest (release build)"
ctest --test-dir build --output-on-failure -j"$JOBS"
echo "== ctest (ASan+UBSan build)"
ctest --test-dir build-asan --output-on-failure -j"$JOBS" -LE 'nosanitize|unsafe_fp'
echo "== pytest (release build)"
GDT_BUILD_DIR="$ROOT/build" .venv/bin/python -m pytest -q -n "$JOBS" tests/python
echo "== pytest, sanitize-marked tests (ASan+UBSan build)"
GDT_BUILD_DIR="$ROOT/build-asan" .venv/bin/python -m pytest -q -n "$JOBS" -m sanitize tests/python
echo "== pytest, launch tests of a build without MPI (clang ASan+UBSan fuzz build)"
GDT_BUILD_DIR="$ROOT/build-fuzz" .venv/bin/python -m pytest -q -n "$JOBS" tests/python/test_launch.py
echo "== ctest, saved fuzz inputs (clang fuzz build)"
ctest --test-dir build-fuzz --output-on-failure -L fuzz
echo "== fuzz smoke run (clang fuzz build)"
scripts/fuzz.sh smoke build-fuzz 10
echo "== all tests passed"
