#!/usr/bin/env python3
"""bench_mpi.py — strong scaling of one gdt-tile job over K MPI ranks.

  bench_mpi.py [--build-dir DIR] [--points 10M] [--ranks 1,2] [--tile N]
               [--repeat K] [--kind lidar] [--seed S] [--format las|laz]
               [--pml NAME] [--workdir DIR] [--keep] [--target 1.8] [--no-ceiling]
               [--json FILE]

One LiDAR-like LAS cloud of --points records (scripts/gen_cloud.py; not timed,
reused from --workdir) is triangulated by
    mpirun -np K --bind-to core --mca pml ob1 gdt-tile CLOUD.las --tile T --threads 1 -o OUT.ply
for every K of --ranks (--format laz: the same cloud compressed by laspy's
lazrs writer, chunks of 50000 points, written once beside it), one core per rank: --threads 1 and the OpenCL runtime
(PoCL) held to one thread (POCL_MAX_PTHREAD_COUNT=1), each rank bound to a
core of its own (K = 1 too, so that it runs on one core as the others do;
under one rank gdt-tile runs as a plain process).  Each K runs --repeat
rounds, the configurations in turn; the best wall time (of mpirun, the whole
job) counts.  Printed per K: wall time, the speed-up over the first K, the
stage times of rank 0's --json (pass 1, pass 2, tiles, merge; parts, the
PLY's tiles written by their owners beside the merge, K > 1 only;
write, the rest of the output after the merge), the time outside the
run's own clock (mpirun, the processes' and MPI's start, the job's removal
and the exit: the wall time less --json's total), the
load balance of the tile stage (slowest rank over the mean), the CPU
seconds of the whole job (mpirun and every rank, user + system), and whether
the PLY is byte for byte the first K's.  The target is the speed-up of the
largest K over the first, at least --target (1.8 for K = 2), PASS or MISS.

Beside it, what the machine itself allows: in each round the largest K's
number of plain single-core runs of the same job side by side, each pinned
to a core of its own (taskset), no MPI between them, and one such run
alone.  Perfect scaling would run one job in 1/K of their time, so
K x (alone) / (side by side) is the speed-up no K-rank run can pass here:
cores that share caches, memory bandwidth or a host with other machines are
each slower when all are busy.
Printed as the ceiling, with the speed-up's share of it (--no-ceiling: not
measured).

--pml chooses Open MPI's point-to-point layer (default ob1, its own shared
memory and TCP transports; '' leaves Open MPI's choice): on a machine without
an HPC interconnect Debian's Open MPI first tries UCX, which made MPI_Init
take 0.23 s instead of 0.03 s here, paid by every K > 1 and not by K = 1
(one rank runs as a plain process).

Needs Open MPI's mpirun and a gdt-tile built with MPI.  Run as root, Open
MPI is told that is allowed.  On a machine with fewer cores than the largest
K the ranks share cores (--oversubscribe) and the speed-up means little.

Exit status: 0 the target met; 1 missed; 2 usage or a missing program; 3 a
run failed or wrote different bytes.
"""
import argparse
import json
import os
import pathlib
import shutil
import subprocess
import sys
import tempfile
import concurrent.futures

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import bench_e2e as be  # noqa: E402  (cloud generation, process measuring, size parsing)

ROOT = pathlib.Path(__file__).resolve().parents[1]
STAGES = ("pass1", "pass2", "tiles", "merge", "parts", "write")


def rank_list(s):
    try:
        v = [int(x) for x in s.split(",") if x]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{s!r}: a comma-separated list of rank counts")
    if not v or any(k < 1 for k in v):
        raise argparse.ArgumentTypeError(f"{s!r}: rank counts are positive")
    return v


def side_by_side(gdt, las, a, tmp, k, taskset, r):
    """k plain single-core runs of the job at once, run i pinned to core i:
    the wall time until the last one ended."""
    def one(i):
        d = tmp / f"side{i}"
        shutil.rmtree(d, ignore_errors=True)
        d.mkdir()
        cmd = [taskset, "-c", str(i), gdt, las, "--tile", a.tile, "--threads", "1", "-q",
               "-o", d / "o.ply", "--job", d / "job"]
        log = str(tmp / f"side{i}-{r}")
        rc, wall, _, _ = be.run_measured(cmd, log)
        be.check_run(rc, cmd, log, "gdt-tile")
        if not a.keep:
            shutil.rmtree(d, ignore_errors=True)
        return wall

    with concurrent.futures.ThreadPoolExecutor(max_workers=k) as ex:
        return max(ex.map(one, range(k)))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--build-dir", default=os.environ.get("GDT_BUILD_DIR", str(ROOT / "build")))
    ap.add_argument("--points", type=be.parse_size, default=10_000_000)
    ap.add_argument("--ranks", type=rank_list, default=[1, 2], help="rank counts (1,2)")
    ap.add_argument("--tile", type=be.positive_int, default=1024, help="gdt-tile --tile (1024)")
    ap.add_argument("--repeat", type=be.positive_int, default=2, help="rounds, best counts (2)")
    ap.add_argument("--kind", default="lidar", help="gen_cloud.py --kind (lidar)")
    ap.add_argument("--seed", type=int, default=1, help="gen_cloud.py --seed (1)")
    ap.add_argument("--format", choices=("las", "laz"), default="las",
                    help="the cloud as LAS or LAZ (las)")
    ap.add_argument("--pml", default="ob1",
                    help="Open MPI's point-to-point layer, --mca pml NAME (ob1; '' = Open MPI's "
                         "choice)")
    ap.add_argument("--workdir", default=None, help="keep and reuse the generated cloud here")
    ap.add_argument("--tmpdir", default=None, help="parent of the temporary folder")
    ap.add_argument("--keep", action="store_true", help="keep outputs and temporary files")
    ap.add_argument("--target", type=float, default=1.8,
                    help="speed-up of the largest K over the first (1.8)")
    ap.add_argument("--no-ceiling", action="store_true",
                    help="do not measure the machine's ceiling (plain runs side by side)")
    ap.add_argument("--json", default=None, help="write every figure to this JSON file")
    a = ap.parse_args(argv)

    tmp = None
    try:
        gdt = be.need_exe(pathlib.Path(a.build_dir) / "tiler" / "gdt-tile", "gdt-tile")
        mpirun = shutil.which("mpirun")
        if mpirun is None:
            raise be.BenchError(2, "mpirun not found (Open MPI, Debian openmpi-bin)")
        v = subprocess.run([str(gdt), "--version"], capture_output=True, text=True)
        if "mpi: yes" not in v.stdout:
            raise be.BenchError(2, f"{gdt} was built without MPI (libopenmpi-dev)")
        cores = os.cpu_count() or 1
        tmp = pathlib.Path(tempfile.mkdtemp(prefix="gdt-mpi-", dir=a.tmpdir))
        work = pathlib.Path(a.workdir) if a.workdir else tmp
        work.mkdir(parents=True, exist_ok=True)
        las = be.ensure_cloud(work, a.points, a)
        if a.format == "laz":
            laz = las.with_suffix(".laz")
            if not laz.exists():
                import laspy  # noqa: E402  (only for --format laz)
                print(f"bench_mpi: compressing {las.name} to {laz.name} ...", file=sys.stderr,
                      flush=True)
                part = laz.with_suffix(".laz.part")
                with open(part, "wb") as f:  # a path would choose by its suffix
                    laspy.read(str(las)).write(f, do_compress=True,
                                               laz_backend=laspy.LazBackend.Lazrs)
                part.rename(laz)
            las = laz
        with open(las, "rb") as f:  # the input in the page cache
            while f.read(1 << 24):
                pass
        env_keep = {k: v for k, v in os.environ.items()
                    if not k.startswith(("OMPI_COMM_WORLD", "PMI_", "PMIX_"))}
        env_keep.update({"OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
                         "POCL_MAX_PTHREAD_COUNT": "1"})
        os.environ.clear()
        os.environ.update(env_keep)  # run_measured's children inherit it

        res = {k: {"walls": [], "json": [], "cpus": []} for k in a.ranks}
        kmax = max(a.ranks)
        taskset = shutil.which("taskset")
        side, solo = [], []
        measure_side = not a.no_ceiling and 2 <= kmax <= cores and taskset is not None
        if not a.no_ceiling and kmax >= 2 and not measure_side:
            why = "taskset is missing" if taskset is None else f"only {cores} cores"
            print(f"bench_mpi: no ceiling measured ({why})", file=sys.stderr, flush=True)
        first_ply = None
        print(f"bench_mpi: {be.size_label(a.points)} points, --tile {a.tile}, ranks {a.ranks}, "
              f"{cores} cores, best of {a.repeat}", file=sys.stderr, flush=True)
        for r in range(a.repeat):
            for k in a.ranks:
                d = tmp / f"k{k}"
                shutil.rmtree(d, ignore_errors=True)
                d.mkdir()
                cmd = [mpirun, "-np", k, "--bind-to", "core", "--map-by", "core"]
                if a.pml:
                    cmd += ["--mca", "pml", a.pml]
                if k > cores:
                    cmd += ["--oversubscribe"]
                cmd += [gdt, las, "--tile", a.tile, "--threads", "1", "-q", "-o", d / "o.ply",
                        "--job", d / "job", "--json", d / "run.json"]
                log = str(tmp / f"k{k}-{r}")
                rc, wall, _, cpu = be.run_measured(cmd, log)
                be.check_run(rc, cmd, log, "mpirun gdt-tile")
                res[k]["cpus"].append(cpu)
                ply = (d / "o.ply").read_bytes()
                if first_ply is None:
                    first_ply = ply
                elif ply != first_ply:
                    raise be.BenchError(3, f"K = {k} wrote other bytes than K = {a.ranks[0]}")
                del ply
                res[k]["walls"].append(wall)
                res[k]["json"].append(json.loads((d / "run.json").read_text()))
                print(f"  K = {k} run {r + 1}/{a.repeat}: {wall:8.2f} s", file=sys.stderr,
                      flush=True)
                if not a.keep:
                    shutil.rmtree(d, ignore_errors=True)
            if measure_side:
                solo.append(side_by_side(gdt, las, a, tmp, 1, taskset, r))
                side.append(side_by_side(gdt, las, a, tmp, kmax, taskset, r))
                print(f"  a plain run alone {r + 1}/{a.repeat}: {solo[-1]:8.2f} s; {kmax} side by "
                      f"side: {side[-1]:8.2f} s", file=sys.stderr, flush=True)

        rows = []
        base = None
        for k in a.ranks:
            best = min(range(len(res[k]["walls"])), key=lambda i: res[k]["walls"][i])
            j = res[k]["json"][best]
            wall = res[k]["walls"][best]
            base = wall if base is None else base
            rows.append({"ranks": k, "wall_s": wall, "speedup": base / wall,
                         "times": {s: j["times"].get(s, 0.0) for s in STAGES},
                         # mpirun, the processes' start and MPI's, and what
                         # follows the run's own clock (job removal, exit)
                         "outside_s": wall - j["times"].get("total", 0.0),
                         "load_balance": j.get("mpi", {}).get("load_balance", 1.0),
                         # each rank's own parts of the passes and its tile stage
                         "per_rank": [{key: q.get(key, 0.0)
                                       for key in ("pass1_s", "pass2_s", "tiles_s")}
                                      for q in j.get("mpi", {}).get("per_rank", [])],
                         "cpu_s": res[k]["cpus"][best],
                         "walls_s": res[k]["walls"]})
        print()
        print(f"gdt-tile under mpirun: {be.size_label(a.points)} points ({a.kind}, seed "
              f"{a.seed}, {a.format.upper()}), --tile {a.tile}, --threads 1, PoCL 1 thread, one core per rank, "
              f"{'pml ' + a.pml if a.pml else 'Open MPI' + chr(39) + 's own pml'}, "
              f"best of {a.repeat}; the PLY is the same bytes for every K")
        head = f"{'K':>3} {'wall s':>8} {'speed-up':>9} " + " ".join(
            f"{s + ' s':>9}" for s in STAGES) + f" {'outside s':>10} {'balance':>8} {'CPU s':>7}"
        print(head)
        print("-" * len(head))
        for row in rows:
            print(f"{row['ranks']:>3} {row['wall_s']:8.2f} {row['speedup']:9.3f} " +
                  " ".join(f"{row['times'][s]:9.2f}" for s in STAGES) +
                  f" {row['outside_s']:10.2f} {row['load_balance']:8.3f} {row['cpu_s']:7.2f}")
        for row in rows:
            if len(row["per_rank"]) > 1:
                print(f"  K = {row['ranks']}, each rank's own part (rank 0 first): " + "; ".join(
                    f"{label} " + " / ".join(f"{q[key]:.2f}" for q in row["per_rank"]) + " s"
                    for label, key in (("pass 1", "pass1_s"), ("pass 2", "pass2_s"),
                                       ("tiles", "tiles_s"))))
        last = rows[-1]
        ceiling = None
        if side:
            ceiling = kmax * min(solo) / min(side)
            print(f"ceiling: a plain run took {min(solo):.2f} s alone, {kmax} side by side (one core "
                  f"each) {min(side):.2f} s (best of {len(side)}), so no {kmax}-rank run beats "
                  f"{ceiling:.3f} x here; K = {last['ranks']} reached "
                  f"{last['speedup'] / ceiling:.1%} of it")
        ok = last["speedup"] >= a.target
        print(f"target: K = {last['ranks']} at least {a.target:g} x K = {rows[0]['ranks']}: "
              f"{last['speedup']:.3f} {'PASS' if ok else 'MISS'}")
        if a.json:
            pathlib.Path(a.json).write_text(json.dumps(
                {"points": a.points, "tile": a.tile, "cores": cores, "rows": rows,
                 "alone_s": solo, "side_by_side_s": side, "ceiling": ceiling,
                 "target": a.target, "met": ok}, indent=2) + "\n")
        return 0 if ok else 1
    except be.BenchError as e:
        print(f"bench_mpi: {e}", file=sys.stderr)
        return e.status
    finally:
        if tmp is not None and not a.keep:
            shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
