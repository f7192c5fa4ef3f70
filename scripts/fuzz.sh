#!/usr/bin/env bash
# Seed corpora and runs of the libFuzzer targets (tests/fuzz/), on a build
# configured with -DGDT_FUZZ=ON (clang; scripts/setup.sh --fuzz makes build-fuzz/).
#
#   scripts/fuzz.sh corpus   BUILD                 seeds into BUILD/fuzz-seeds/<target>/
#   scripts/fuzz.sh smoke    BUILD [SECONDS]       each target SECONDS (default 15)
#   scripts/fuzz.sh campaign BUILD OUT [SECONDS]   each target SECONDS (default 1800),
#                                                  two at a time, at nice 19
#
# A run keeps what it finds: new inputs in <dir>/corpus/, crash, leak and
# timeout inputs in <dir>/artifacts/, libFuzzer's output with its final stats
# in <dir>/log (smoke: <dir> = BUILD/fuzz-smoke/<target>; campaign:
# OUT/<target>).  The exit status is 1 when any target crashed: a crash
# input belongs in tests/fuzz/regress/<target>/ with its fix.
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
# FUZZ_TARGETS="las pcd" narrows a run to some targets.
read -r -a TARGETS <<<"${FUZZ_TARGETS:-las pcd plycheck job tri laz lazfile laz14}"

usage() {
  sed -n '5,8p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//' >&2
  exit 2
}

# -max_len of each target: the largest seed it gets (make_corpus.py cuts
# real samples to 16 KiB; a small job.db is a few SQLite pages; the tile
# files of a small job are kept up to 64 KiB).
max_len() {
  case "$1" in
    job|tri) echo 65536 ;;
    *) echo 16384 ;;
  esac
}

# The generators need numpy: $PYTHON, else the project's .venv (scripts/setup.sh).
python_bin() {
  if [ -n "${PYTHON:-}" ]; then echo "$PYTHON"
  elif [ -x "$ROOT/.venv/bin/python" ]; then echo "$ROOT/.venv/bin/python"; else echo python3; fi
}

corpus() {
  local build=$1
  [ -x "$build/tests/fuzz_las" ] || {
    echo "fuzz.sh: $build has no fuzz targets (configure it with -DGDT_FUZZ=ON)" >&2
    exit 2
  }
  "$(python_bin)" "$ROOT/tests/fuzz/make_corpus.py" "$build" "$build/fuzz-seeds"
}

# run_target BUILD TARGET DIR SECONDS [NICE]: one libFuzzer run; status 0
# when it ended without a finding.
run_target() {
  local build=$1 t=$2 dir=$3 secs=$4 nice=${5:-0}
  mkdir -p "$dir/corpus" "$dir/artifacts"
  # The job journal is fsync'd on every commit: a memory file system keeps
  # that from being a disk's pace.
  local tmp=${TMPDIR:-/tmp}
  if [ -z "${TMPDIR:-}" ] && [ -d /dev/shm ] && [ -w /dev/shm ]; then tmp=/dev/shm; fi
  # detect_leaks: a reader that leaks on a bad file leaks on every bad file.
  ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1} \
  UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1} TMPDIR=$tmp \
    nice -n "$nice" "$build/tests/fuzz_$t" -max_total_time="$secs" -max_len="$(max_len "$t")" \
      -timeout=10 -rss_limit_mb=2048 -print_final_stats=1 \
      -artifact_prefix="$dir/artifacts/" "$dir/corpus" "$build/fuzz-seeds/$t" \
      >"$dir/log" 2>&1
}

summary() {
  local t=$1 dir=$2 rc=$3
  local execs time
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$dir/log" | tail -1)
  time=$(sed -n 's/^Done [0-9]* runs in \([0-9]*\) second.*/\1/p' "$dir/log" | tail -1)
  printf '%-9s rc=%-3s %6s s  %10s execs  corpus %5s files  findings %s\n' "$t" "$rc" \
    "${time:-?}" "${execs:-?}" "$(find "$dir/corpus" -type f | wc -l)" \
    "$(find "$dir/artifacts" -type f | wc -l)"
}

smoke() {
  local build=$1 secs=${2:-15} failed=0
  corpus "$build" >/dev/null
  for t in "${TARGETS[@]}"; do
    local dir="$build/fuzz-smoke/$t"
    rm -rf "$dir"
    local rc=0
    run_target "$build" "$t" "$dir" "$secs" || rc=$?
    summary "$t" "$dir" "$rc"
    if [ "$rc" -ne 0 ]; then
      failed=1
      tail -40 "$dir/log" >&2
    fi
  done
  return "$failed"
}

campaign() {
  local build=$1 out=$2 secs=${3:-1800} failed=0
  # seeds made once: a campaign may run on a copy of the targets and seeds
  [ -d "$build/fuzz-seeds" ] || corpus "$build" >/dev/null
  for t in "${TARGETS[@]}"; do
    while [ "$(jobs -rp | wc -l)" -ge 2 ]; do wait -n || true; done
    mkdir -p "$out/$t"
    ( rc=0; run_target "$build" "$t" "$out/$t" "$secs" 19 || rc=$?; echo "$rc" >"$out/$t/rc" ) &
  done
  wait
  for t in "${TARGETS[@]}"; do
    local rc
    rc=$(cat "$out/$t/rc")
    summary "$t" "$out/$t" "$rc"
    [ "$rc" -eq 0 ] || failed=1
  done
  return "$failed"
}

[ $# -ge 2 ] || usage
cmd=$1
build=$(cd "$2" && pwd)
shift 2
case "$cmd" in
  corpus) corpus "$build" ;;
  smoke) smoke "$build" "$@" ;;
  campaign) [ $# -ge 1 ] || usage; campaign "$build" "$@" ;;
  *) usage ;;
esac
