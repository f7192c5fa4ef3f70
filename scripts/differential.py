#!/usr/bin/env python3
"""Randomised differential runs of the whole program.

  differential.py [--build-dir DIR] [--seeds A:B] [--workdir DIR] [--mpi-every N]
                  [--keep]

For every seed in [A, B) a cloud is generated (scripts/gen_cloud.py: its kind,
2000 to 30000 points, sometimes rewritten as LAZ) and options are drawn: the
DEM cell size (the default or 0.07 to 5), --max-edge, --concavity and
--ground pmf, each or not.  The same job then runs as

  ref    --reference (the in-memory CPU triangulation)
  t64    --tile 64, from the LAZ copy when there is one
  t128   --tile 128 --halo 0 --threads 1
  t256   --tile 256
  mpi2   mpirun -np 2 ... --tile 64 (every --mpi-every-th seed, when this
         gdt-tile has MPI and mpirun exists)

each with --dem.  Every run must exit 0, every DEM must be the same bytes as
the reference's and every mesh the same triangles (scripts/compare_meshes.py;
the tiled PLY lists them in another order).  A seed that breaks this is
printed with its runs' exit codes and the commands to repeat it; its files
stay in WORKDIR/seed-S.  A run killed by a signal is such a failure too: the
script is as much a search for crashes and races as for differences (the
fixed tests run one configuration each; this one mixes them).

Exit status: 0 every seed agreed; 1 at least one did not; 2 usage or a
missing program.
"""
import argparse
import hashlib
import os
import pathlib
import random
import shlex
import shutil
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parents[1]
SCRIPTS = ROOT / "scripts"
MPI_ENV = {"OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
           "POCL_MAX_PTHREAD_COUNT": "1"}


def seeds(text):
    try:
        a, b = (int(x) for x in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError("A:B, two integers") from None
    if not 0 <= a < b:
        raise argparse.ArgumentTypeError("need 0 <= A < B")
    return range(a, b)


def digest(path):
    if not path.exists():
        return None
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def draw(seed):
    """The cloud and the options of one seed (the same on every machine)."""
    rng = random.Random(seed)
    kind = rng.choice(["lidar", "grid", "uniform", "dem", "mixed"])
    points = rng.choice([2000, 5000, 12000, 30000])
    res = rng.choice([None, "0.07", "0.13", "0.5", "1", "2.37", "5"])
    opts = []
    if rng.random() < 0.3:
        opts += ["--max-edge", rng.choice(["0.8", "2", "5"])]
    if rng.random() < 0.3:
        opts += ["--concavity", rng.choice(["0.8", "2", "5"])]
    if rng.random() < 0.2:
        opts += ["--ground", "pmf"]
    if res is not None:
        opts += ["--dem-res", res]
    return kind, points, rng.random() < 0.3, opts


def has_mpi(gdt):
    if shutil.which("mpirun") is None:
        return False
    r = subprocess.run([str(gdt), "--version"], capture_output=True, text=True)
    return "mpi: yes" in r.stdout


def one_seed(seed, gdt, work, mpi):
    kind, points, laz, opts = draw(seed)
    d = work / f"seed-{seed}"
    shutil.rmtree(d, ignore_errors=True)
    d.mkdir(parents=True)
    las = d / "cloud.las"
    r = subprocess.run([sys.executable, str(SCRIPTS / "gen_cloud.py"), str(las), "--points",
                        str(points), "--seed", str(seed), "--kind", kind, "-q"],
                       capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"gen_cloud.py failed for seed {seed}: {r.stderr.strip()}")
    src64 = las
    if laz:
        import laspy  # the project's test environment has it (scripts/requirements.txt)
        src64 = d / "cloud.laz"
        laspy.read(str(las)).write(str(src64))
    runs = [("ref", las, ["--reference"]), ("t64", src64, ["--tile", "64"]),
            ("t128", las, ["--tile", "128", "--halo", "0", "--threads", "1"]),
            ("t256", las, ["--tile", "256"])]
    if mpi:
        runs.append(("mpi2", las, ["--tile", "64"]))
    results, cmds = {}, {}
    for name, src, extra in runs:
        cmd = [str(gdt), str(src), "-q", "-o", str(d / f"{name}.ply"), "--dem",
               str(d / f"{name}.tif"), *opts, *extra]
        env = dict(os.environ)
        if name == "mpi2":
            cmd = ["mpirun", "--oversubscribe", "-np", "2", *cmd]
            env.update(MPI_ENV)
        cmds[name] = cmd
        r = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=900)
        results[name] = (r.returncode, digest(d / f"{name}.tif"), r.stderr.strip()[-400:])
    problems = []
    for name, (rc, dem, err) in results.items():
        if rc != 0:
            problems.append(f"{name}: exit {rc}" + (f": {err}" if err else ""))
        elif dem != results["ref"][1]:
            problems.append(f"{name}: the DEM differs from the reference's")
        elif name != "ref":
            c = subprocess.run([sys.executable, str(SCRIPTS / "compare_meshes.py"),
                                str(d / "ref.ply"), str(d / f"{name}.ply")],
                               capture_output=True, text=True)
            if c.returncode != 0:
                problems.append(f"{name}: the mesh differs from the reference's: "
                                f"{c.stdout.strip()[:300]}")
    label = f"seed {seed}: {kind}, {points} points{' (LAZ for t64)' if laz else ''}, " \
            f"{' '.join(opts) or 'default options'}"
    return label, problems, cmds, d


def main(argv=None):
    ap = argparse.ArgumentParser(
        prog="differential.py",
        description="Randomised differential runs: every mode and tiling gives the same mesh "
                    "and DEM.",
        epilog="exit status: 0 every seed agreed, 1 one did not, 2 usage")
    ap.add_argument("--build-dir", type=pathlib.Path, default=ROOT / "build")
    ap.add_argument("--seeds", type=seeds, default=range(1, 51), metavar="A:B",
                    help="seeds A to B-1 (default 1:51)")
    ap.add_argument("--workdir", type=pathlib.Path, default=pathlib.Path("/tmp/gdt-differential"))
    ap.add_argument("--mpi-every", type=int, default=3, metavar="N",
                    help="a two-rank run for every N-th seed (0: never; default 3)")
    ap.add_argument("--keep", action="store_true", help="keep the files of seeds that agreed")
    a = ap.parse_args(argv)
    gdt = a.build_dir.resolve() / "tiler" / "gdt-tile"
    if not gdt.exists():
        ap.error(f"gdt-tile not built at {gdt}")
    mpi_ok = a.mpi_every > 0 and has_mpi(gdt)
    a.workdir.mkdir(parents=True, exist_ok=True)
    failed = 0
    for seed in a.seeds:
        label, problems, cmds, d = one_seed(seed, gdt, a.workdir,
                                            mpi_ok and seed % a.mpi_every == 0)
        if not problems:
            print(f"{label}: agree ({len(cmds)} runs)", flush=True)
            if not a.keep:
                shutil.rmtree(d, ignore_errors=True)
            continue
        failed += 1
        print(f"{label}: DIFFERENT", flush=True)
        for p in problems:
            print(f"  {p}", flush=True)
        print(f"  files in {d}; the runs:", flush=True)
        for name, cmd in cmds.items():
            print(f"  {name}: {shlex.join(cmd)}", flush=True)
    n = len(a.seeds)
    print(f"differential: {n - failed} of {n} seeds agreed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
