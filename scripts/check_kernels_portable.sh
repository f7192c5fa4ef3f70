#!/usr/bin/env bash
# Compiles every OpenCL kernel (*.cl) of a directory with clang for GPU
# targets other than the PoCL CPU device the tests run on, as OpenCL C 1.2
# with the build options the core's host driver uses (-cl-std=CL1.2, the
# kernel directory on the include path, with and without -DGDT_X_NO_F64,
# -DSTRIP=N where a kernel needs it), and fails on any error or warning
# (-Wall -Werror).  Nothing runs: clang's front end checks the language and
# the builtins a target offers, its back ends (PTX, AMDGPU) what the
# hardware can do, so kernels that only PoCL accepts (a PoCL-only builtin,
# __int128, an extension a GPU lacks) fail here, without a GPU.
#
#   scripts/check_kernels_portable.sh [--clang PATH] [-q] KERNEL_DIR
#
# Targets: NVIDIA (nvptx64-nvidia-nvcl, PTX), AMD (amdgcn-amd-amdhsa,
# -nogpulib, gfx90a and gfx1030, and gfx1100 where this clang knows it:
# Debian 12's clang 14 does not), SPIR (spir64, LLVM IR: the portable
# intermediate form).  Exit status 0: every kernel compiled for every
# target; 1: some did not (each failure printed with clang's messages);
# 2: usage, or no clang.
set -euo pipefail

CLANG=clang
QUIET=0
DIR=""
while [ $# -gt 0 ]; do
  case "$1" in
    --clang) CLANG="$2"; shift 2 ;;
    -q) QUIET=1; shift ;;
    -*) echo "usage: check_kernels_portable.sh [--clang PATH] [-q] KERNEL_DIR" >&2; exit 2 ;;
    *) DIR="$1"; shift ;;
  esac
done
if [ -z "$DIR" ] || [ ! -d "$DIR" ]; then
  echo "usage: check_kernels_portable.sh [--clang PATH] [-q] KERNEL_DIR" >&2
  exit 2
fi
if ! command -v "$CLANG" >/dev/null 2>&1; then
  echo "check_kernels_portable: $CLANG not found (Debian: apt-get install clang)" >&2
  exit 2
fi

# "name|target and code generation options"
TARGETS=(
  "nvidia-ptx|-target nvptx64-nvidia-nvcl -S"
  "amd-gfx90a|-target amdgcn-amd-amdhsa -mcpu=gfx90a -nogpulib -S"
  "amd-gfx1030|-target amdgcn-amd-amdhsa -mcpu=gfx1030 -nogpulib -S"
  "spir64|-target spir64 -emit-llvm -c"
)
# gfx1100 (RDNA 3) needs clang 15 or later
if echo 'kernel void k(void) {}' |
    "$CLANG" -x cl -cl-std=CL1.2 -target amdgcn-amd-amdhsa -mcpu=gfx1100 -nogpulib -S \
      -o /dev/null - >/dev/null 2>&1; then
  TARGETS+=("amd-gfx1100|-target amdgcn-amd-amdhsa -mcpu=gfx1100 -nogpulib -S")
elif [ "$QUIET" -eq 0 ]; then
  echo "check_kernels_portable: this clang does not know gfx1100; checking gfx1030 for RDNA"
fi

shopt -s nullglob
KERNELS=("$DIR"/*.cl)
if [ ${#KERNELS[@]} -eq 0 ]; then
  echo "check_kernels_portable: no *.cl in $DIR" >&2
  exit 2
fi

fail=0
count=0
for k in "${KERNELS[@]}"; do
  for t in "${TARGETS[@]}"; do
    name=${t%%|*}
    read -r -a topts <<< "${t#*|}"
    for variant in fp64 no-fp64; do
      vopts=()
      [ "$variant" = no-fp64 ] && vopts=(-DGDT_X_NO_F64)
      count=$((count + 1))
      if ! msg=$("$CLANG" -x cl -cl-std=CL1.2 -Xclang -finclude-default-header \
            "${topts[@]}" "${vopts[@]}" -DSTRIP=64 -I "$DIR" -Wall -Werror \
            -o /dev/null "$k" 2>&1) || [ -n "$msg" ]; then
        echo "FAIL $(basename "$k") [$name, $variant]:"
        printf '%s\n' "$msg" | head -20
        fail=1
      fi
    done
  done
done
if [ "$fail" -ne 0 ]; then
  echo "check_kernels_portable: some kernels do not compile for every target" >&2
  exit 1
fi
[ "$QUIET" -eq 1 ] || echo "check_kernels_portable: ${#KERNELS[@]} kernels, $count compilations, all clean"
exit 0
