#!/usr/bin/env bash
# slurm_example.sh — one gdt-tile job on a SLURM cluster, shared by every rank.
#
#   sbatch scripts/slurm_example.sh /shared/survey/*.laz
#
# Every rank must see the same file system for the inputs, the job directory
# and the output (here $WORK); gdt-tile must be built with MPI on the nodes
# (gdt-tile --version says "mpi: yes").  Rank 0 reads the input, records the
# job and writes the mesh; every rank triangulates its share of the tiles.
# The output is the same bytes whatever the number of nodes, and a job that
# was killed or ran out of time is resumed by submitting the same command
# again, with any number of nodes.
#
# Resources: one rank per GPU where the nodes have GPUs (--device picks the
# OpenCL device), or one rank per node with --threads set to its cores.
#SBATCH --job-name=gdt-tile
#SBATCH --nodes=4
#SBATCH --ntasks-per-node=1
#SBATCH --cpus-per-task=32
#SBATCH --time=04:00:00
#SBATCH --output=gdt-tile-%j.log
set -euo pipefail

if [ "$#" -lt 1 ]; then
  echo "usage: sbatch $0 INPUT [INPUT ...]" >&2
  exit 2
fi

WORK=${WORK:-$PWD}                 # a shared directory
OUT=${OUT:-$WORK/terrain.ply}
JOB=${JOB:-$OUT.gdt-job}            # the job directory: keep it on the shared file system
THREADS=${SLURM_CPUS_PER_TASK:-1}
GDT=${GDT:-gdt-tile}

# Open MPI started by srun: PMIx (or PMI-2, --mpi=pmi2, on older sites).
# gdt-tile exits with the job's code on every rank: 0 done, 3 bad input,
# 4 I/O, 5 device, 6 job directory, 130 interrupted (resumable).
srun --mpi=pmix "$GDT" "$@" -o "$OUT" --job "$JOB" --tile 4096 --threads "$THREADS" \
  --json "$OUT.json" --dem "${OUT%.ply}.tif"

# Without srun's MPI support, the same with Open MPI's launcher:
#   mpirun -np "$SLURM_NTASKS" --map-by ppr:1:node "$GDT" "$@" -o "$OUT" --job "$JOB" ...
