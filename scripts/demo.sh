#!/usr/bin/env bash
# The main job on a point cloud the project generates itself:
# sets up and builds (scripts/setup.sh), generates a LiDAR-like LAS cloud,
# describes it with --info, triangulates it with the tiled pipeline (OpenCL
# core per tile, certification, seam merge) at --tile 1024, i.e. several tiles,
# validates the mesh exactly and compares it with the CPU reference.
#
#   scripts/demo.sh [POINTS]        (default 1000000)
#
# Outputs go to out/demo/.
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$ROOT"
POINTS=${1:-1000000}

scripts/setup.sh
mkdir -p out/demo
CLOUD=out/demo/cloud.las
MESH=out/demo/cloud.ply

echo "== generating a LiDAR-like cloud of $POINTS points: $CLOUD"
.venv/bin/python scripts/gen_cloud.py "$CLOUD" --points "$POINTS" --seed 1 --kind lidar

echo "== gdt-tile $CLOUD --info"
build/tiler/gdt-tile "$CLOUD" --info

echo "== gdt-tile $CLOUD --tile 1024 -o $MESH"
build/tiler/gdt-tile "$CLOUD" --tile 1024 -o "$MESH" --json out/demo/run.json

echo "== validate_mesh.py $MESH --input $CLOUD"
.venv/bin/python scripts/validate_mesh.py "$MESH" --input "$CLOUD"

echo "== the same cloud with the CPU reference, compared"
build/tiler/gdt-tile "$CLOUD" --reference -o out/demo/reference.ply -q
.venv/bin/python scripts/compare_meshes.py "$MESH" out/demo/reference.ply
