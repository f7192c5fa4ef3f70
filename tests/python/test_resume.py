"""Crash safety and resumption of tiled runs (gdt-tile INPUT --tile N -o OUT).

Whatever interrupts a run (SIGKILL at any instant, SIGINT/SIGTERM, a full
disk, a write error), rerunning the same command, or gdt-tile --resume DIR,
must finish the job and write a PLY byte-identical to an uninterrupted run;
no file may appear at the output path before a run completes.  A job
directory that does not match the command (changed input bytes, changed
options, other inputs) is refused with exit 6 and a message that
suggests --restart, and the output path is left alone.  --json reports what
a run took from the job directory ("reused") and what it computed
("redone"); damaged tile files are recomputed, never trusted.

Clouds are generated (seeded) and forced into many small tiles with --cell.
Where a test aims at a stage it follows the plain progress lines of stderr
("gdt-tile: <stage>: started|done ...").
"""
import os
import pathlib
import random
import resource
import shutil
import signal
import subprocess

import pytest

import resume_util as ru

# A cloud of many small tiles that runs in about a second (most tests).
SMALL_POINTS, SMALL_SEED = 40_000, 5
SMALL_ARGS = ["--tile", "64", "--cell", "0.25"]
# The smallest cloud of many tiles (tests also run on the sanitizer build).
TINY_POINTS, TINY_SEED = 10_000, 3
TINY_ARGS = ["--tile", "64", "--cell", "0.125"]
# A longer run (2-5 s, ~170 tiles) for kills spread over time.
BIG_POINTS, BIG_SEED = 300_000, 7
BIG_ARGS = ["--tile", "64", "--cell", "0.25"]
# the same cloud in about four times the tiles: a tile stage of a few
# seconds, long enough to see tiles outlive the recording window
MANY_ARGS = ["--tile", "64", "--cell", "0.125"]

KILL_SEED = 20240611
UNIFORM_KILLS = 10          # instants drawn uniformly over an uninterrupted run
MIN_KILLS = 14              # SIGKILLs that must actually hit a running process
CHAIN_LENGTHS = (1, 3, 1, 4, 2, 1, 3, 2)
KILL_AFTER = 2.0    # s into the tile stage (test_json_after_sigkill_in_tile_stage)
LOSS_WINDOW = 1.5   # s of finished tile work a kill may cost


def command(gdt_bin, inputs, out, args, *extra):
    if isinstance(inputs, (str, pathlib.Path)):
        inputs = [inputs]
    return [str(gdt_bin), *map(str, inputs), *args, "-o", str(out), *map(str, extra)]


def run(cmd, cwd=None, **kw):
    return subprocess.run([str(c) for c in cmd], capture_output=True, text=True, timeout=600,
                          cwd=cwd, **kw)


def default_job(out):
    return pathlib.Path(str(out) + ".gdt-job")


class Case:
    """A cloud, its options, and the PLY and summary of an uninterrupted run."""

    def __init__(self, gdt_bin, folder, points, seed, args):
        folder.mkdir(parents=True, exist_ok=True)
        self.gdt = gdt_bin
        self.args = list(args)
        self.las = ru.gen_cloud(folder / "cloud.las", points, seed)
        self.ref = folder / "ref.ply"
        js = folder / "ref.json"
        r = ru.Run(command(gdt_bin, self.las, self.ref, self.args, "--json", js))
        rc = r.finish()
        self.time = r.elapsed()
        assert rc == 0, f"exit {rc}: {ru.shell(r.cmd)}\n{r.stderr}"
        self.timeline = r.timeline()
        self.summary = ru.read_json(js)
        self.ntiles = int(self.summary["tiles"]) if not isinstance(self.summary["tiles"], list) \
            else len(self.summary["tiles"])
        assert self.ntiles >= 16, f"{ru.shell(r.cmd)}: {self.ntiles} tiles, the tests need many"
        assert not default_job(self.ref).exists(), "job directory left after a successful run"
        self.bytes = self.ref.read_bytes()
        self.usage = None

    def copy_input(self, folder, name="in.las"):
        folder.mkdir(parents=True, exist_ok=True)
        dst = folder / name
        shutil.copyfile(self.las, dst)
        return dst

    def cmd(self, inputs, out, *extra):
        return command(self.gdt, inputs, out, self.args, *extra)

    def assert_same(self, path, what):
        path = pathlib.Path(path)
        assert path.exists(), f"{what}: no output at {path}"
        assert path.read_bytes() == self.bytes, \
            f"{what}: output differs from the uninterrupted run: " \
            f"{ru.describe_difference(self.ref, path)}"


@pytest.fixture(scope="module")
def small(gdt_bin, tmp_path_factory):
    return Case(gdt_bin, tmp_path_factory.mktemp("small"), SMALL_POINTS, SMALL_SEED, SMALL_ARGS)


@pytest.fixture(scope="module")
def tiny(gdt_bin, tmp_path_factory):
    return Case(gdt_bin, tmp_path_factory.mktemp("tiny"), TINY_POINTS, TINY_SEED, TINY_ARGS)


@pytest.fixture(scope="module")
def big(gdt_bin, tmp_path_factory):
    return Case(gdt_bin, tmp_path_factory.mktemp("big"), BIG_POINTS, BIG_SEED, BIG_ARGS)


@pytest.fixture(scope="module")
def many(gdt_bin, tmp_path_factory):
    return Case(gdt_bin, tmp_path_factory.mktemp("many"), BIG_POINTS, BIG_SEED, MANY_ARGS)


def kill_in_tile_stage(cmd, job, min_tri=1, sig=signal.SIGKILL):
    """Starts cmd and sends sig once the tile stage runs and at least
    min_tri .tri files exist; returns the finished Run."""
    r = ru.Run(cmd)
    r.wait_for(lambda x: x.started("tiles"))
    ok = r.wait_for(lambda x: len(ru.tri_files(job)) >= min_tri or
                    any(k in ("merge", "write") for _, _, k in x.timeline()), poll=0.001)
    assert ok, f"{ru.shell(cmd)} ended early (exit {r.proc.poll()})\n{r.stderr}"
    r.send(sig)
    r.finish(timeout=60)
    where = r.died_in if sig == signal.SIGKILL else r.last_started
    assert where == "tiles", \
        f"{ru.shell(cmd)}: the signal did not land in the tile stage ({where})\n{r.stderr}"
    return r


def assert_job_error(r, cmd, *names):
    """Exit 6 with a GDT-6xxx message naming each of names and suggesting --restart."""
    assert r.returncode == 6, f"exit {r.returncode}, expected 6: {ru.shell(cmd)}\n{r.stderr}"
    assert "GDT-6" in r.stderr, f"{ru.shell(cmd)}: no GDT-6xxx code\n{r.stderr}"
    assert "--restart" in r.stderr, f"{ru.shell(cmd)}: message does not suggest --restart\n" \
                                     f"{r.stderr}"
    for n in names:
        assert n.lower() in r.stderr.lower(), f"{ru.shell(cmd)}: message does not name {n!r}\n" \
                                              f"{r.stderr}"


def stat_of(path):
    st = os.stat(path)
    return st.st_ino, st.st_size, st.st_mtime_ns


# ------------------------------------------------------------ 1. SIGKILL

def plan_kills(case, rng):
    """Kill specs: ("at", instant) uniform over the uninterrupted run, and
    ("in", stage, offset) for every stage of the run, offset uniform over
    the stage's duration; stages before the tile stage go first in a chain
    (a resumed run does not redo pass 2)."""
    spans = ru.durations(case.timeline, case.time)
    missing = [s for s in ru.REQUIRED_STAGES if s not in spans]
    assert not missing, f"the progress lines of {case.ref} lack the stages {missing}:\n" \
                        f"{case.timeline}"
    uniform = [("at", rng.uniform(0.0, case.time)) for _ in range(UNIFORM_KILLS)]
    targeted = [("in", s, rng.uniform(0.0, spans[s][1])) for s in
                ("pass1", "pass2", "dup", "tiles", "merge", "write") if s in spans]
    targeted.append(("after", "write", rng.uniform(0.0, tail_of(case))))
    return uniform, targeted


def tail_of(case):
    """Seconds from the write stage's done line to the end of the run."""
    spans = ru.durations(case.timeline, case.time)
    return max(0.0, case.time - sum(spans["write"]))


def chains_of(uniform, targeted, rng):
    heads = [t for t in targeted if t[1] in ("pass1", "pass2", "dup")]
    rest = [t for t in targeted if t not in heads] + uniform
    rng.shuffle(rest)
    chains, n = [], 0
    while heads or rest:
        length = CHAIN_LENGTHS[n % len(CHAIN_LENGTHS)]
        n += 1
        chain = [heads.pop(0)] if heads else []
        while len(chain) < length and rest:
            chain.append(rest.pop(0))
        chains.append(chain)
    return chains


def run_chain(case, folder, chain, log):
    """Runs the kill specs of chain one after another on the same command,
    then the command to completion; returns the stages in which SIGKILLs
    hit a running process (one entry per hit)."""
    folder.mkdir(parents=True)
    out = folder / "out.ply"
    cmd = case.cmd(case.las, out)
    hits = []
    first = len(log)
    for spec in chain:
        r = ru.Run(cmd)
        if spec[0] == "at":
            r.stop_at(spec[1])
        elif spec[0] == "in":
            r.stop_in(spec[1], spec[2])
        else:
            r.stop_after(spec[1], spec[2])
        rc = r.finish()
        entry = f"{folder.name}: {spec} -> exit {rc}, {r.died_in}" + \
            (f" (signal at {r.sent_at:.3f} s)" if r.sent_at is not None else "")
        log.append(entry)
        history = "\n".join(log[first:])
        assert rc in (0, -signal.SIGKILL), \
            f"{ru.shell(cmd)}: exit {rc} after earlier kills\n{history}\n{r.stderr}"
        if rc == -signal.SIGKILL:
            hits.append(r.died_in)
        # Nothing at the output path until a run has completed it.
        if out.exists():
            case.assert_same(out, f"file at the output path after: {history}")
    r = run(cmd)
    log.append(f"{folder.name}: final run -> exit {r.returncode}")
    history = "\n".join(log[first:])
    assert r.returncode == 0, f"{ru.shell(cmd)}: exit {r.returncode}\n{history}\n{r.stderr}"
    case.assert_same(out, f"after the kills\n{history}")
    assert not default_job(out).exists(), f"job directory left after completion\n{history}"
    return hits


MUST_HIT = ru.REQUIRED_STAGES + ("after write",)


@pytest.mark.slow
def test_sigkill_at_random_instants_then_rerun(big, tmp_path):
    """SIGKILL at instants drawn uniformly over an uninterrupted run, and
    in every stage (pass 1, pass 2, the duplicate merge, the tile stage, the
    merge, the PLY writing, and after it while the job is removed), chained
    (several kills before a complete run) or followed by a complete run:
    each complete run writes the identical PLY, no file is at the output
    path before a run completes, no job directory is left after it."""
    rng = random.Random(KILL_SEED)
    uniform, targeted = plan_kills(big, rng)
    chains = chains_of(uniform, targeted, rng)
    assert any(len(c) == 1 for c in chains) and any(len(c) >= 3 for c in chains)
    log = [f"uninterrupted: {big.time:.2f} s, {big.ntiles} tiles, stages "
           f"{[(round(t, 3), k, s) for t, k, s in big.timeline]}"]
    hits, failures = [], []

    def attempt(name, chain):
        try:
            hits.extend(run_chain(big, tmp_path / name, chain, log))
        except AssertionError as e:
            failures.append(f"{name} {chain}: {e}")

    for n, chain in enumerate(chains):
        attempt(f"chain{n}", chain)
    # Every stage must have been hit; retry a missed one on a fresh job.  A
    # stage with (nearly) no time of its own in the uninterrupted run cannot
    # be aimed at: the seam merge, for one, finishes beside the tile stage
    # (each row as soon as its tiles are written), leaving 0-15 ms after it,
    # so the kills in the tile stage are the ones that stop it.  A kill aimed
    # by the uninterrupted run's clock lands tens of ms off in a rerun (its
    # start-up and stages vary by that much), so only stages of 50 ms and
    # more are required.
    spans = ru.durations(big.timeline, big.time)
    must_hit = [s for s in MUST_HIT if s == "after write" or s not in spans or
                spans[s][1] >= 0.050]
    log.append(f"stages without time of their own (not required): "
               f"{[s for s in MUST_HIT if s not in must_hit]}")
    for stage in must_hit:
        for k in range(4):
            if stage in hits:
                break
            if stage == "after write":
                spec = ("after", "write", rng.uniform(0.0, tail_of(big)) / (k + 1))
            else:
                spec = ("in", stage, rng.uniform(0.0, spans[stage][1]) / (k + 1))
            attempt(f"retry-{stage.replace(' ', '-')}-{k}", [spec])
    # Reruns reuse work and may finish before their kill instant: top up
    # with kills of fresh runs until enough SIGKILLs hit a running process.
    extra = 0
    while len(hits) < MIN_KILLS and extra < 2 * MIN_KILLS:
        attempt(f"extra{extra}", [("at", rng.uniform(0.0, big.time))])
        extra += 1
    history = "\n".join(log)
    print(history)
    assert not failures, f"{len(failures)} failing scenarios:\n\n" + "\n\n".join(failures) + \
        f"\n\nall runs:\n{history}"
    missed = [s for s in must_hit if s not in hits]
    assert not missed, f"no SIGKILL landed in {missed}\n{history}"
    assert len(hits) >= MIN_KILLS, f"only {len(hits)} SIGKILLs hit a running process\n{history}"


# ------------------------------------------------------------ 2. disk full

NS_SCRIPT = r'''
set -u
mount -t tmpfs -o size="$JOBSZ" tmpfs "$JOBMNT" || exit 99
mount -t tmpfs -o size="$OUTSZ" tmpfs "$OUTMNT" || exit 99
echo MOUNTED
"$@" --json "$T/run1.json" 2>"$T/err1"; echo $? >"$T/rc1"
ls -A "$OUTMNT" >"$T/ls1"
mount -o remount,size="$BIGSZ" "$JOBMNT" || exit 98
mount -o remount,size="$BIGSZ" "$OUTMNT" || exit 98
"$@" --json "$T/run2.json" 2>"$T/err2"; echo $? >"$T/rc2"
ls -A "$OUTMNT" >"$T/ls2"
ls -A "$JOBMNT" >"$T/lsjob2"
cp "$OUTMNT/out.ply" "$T/final.ply" 2>/dev/null
exit 0
'''


def kept_job_usage(case):
    """Page-rounded sizes of the files of a kept job of case by kind, its
    largest file and the PLY's size (measured once per case)."""
    if case.usage is None:
        folder = case.ref.parent / "kept"
        folder.mkdir(exist_ok=True)
        out, job = folder / "base.ply", folder / "base.job"
        cmd = case.cmd(case.las, out, "--keep-job", "--job", job)
        r = run(cmd)
        assert r.returncode == 0, f"{ru.shell(cmd)}\n{r.stderr}"
        case.assert_same(out, ru.shell(cmd))
        use, largest = ru.job_usage(job)
        case.usage = (use, largest, out.stat().st_size)
    return case.usage


@pytest.mark.parametrize("where", ["tiler", "tiles", "output"])
def test_disk_full_then_rerun_with_space(small, tmp_path, where):
    """The job directory (during the tiler's pass 2 or during the tile
    stage) or the output file system fills up: exit 4 naming the file and
    the reason, nothing at the output path; with space again, the same
    command resumes and writes the identical PLY."""
    use, _, ply = kept_job_usage(small)
    mib = 1 << 20
    big_sz = 64 * mib + 4 * (sum(use.values()) + ply)
    slack = 256 * 1024  # the job database's write-ahead log
    before_tiler = slack + use["db"] + use["other"] + use["index"]
    if where == "tiler":
        jobsz, outsz, stages = before_tiler + use["tiler"] // 2, big_sz, ("pass2", "dup")
    elif where == "tiles":
        jobsz, outsz, stages = before_tiler + use["tiler"] + use["tri"] // 2, big_sz, ("tiles",)
    else:
        jobsz, outsz, stages = big_sz, ply // 2, ("write",)
    jobmnt, outmnt, t = tmp_path / "jobfs", tmp_path / "outfs", tmp_path / "res"
    for d in (jobmnt, outmnt, t):
        d.mkdir()
    out, job = outmnt / "out.ply", jobmnt / "job"
    cmd = small.cmd(small.las, out, "--job", job)
    env = {"JOBMNT": str(jobmnt), "OUTMNT": str(outmnt), "T": str(t), "JOBSZ": str(jobsz),
           "OUTSZ": str(outsz), "BIGSZ": str(big_sz)}
    r = ru.run_in_namespace(NS_SCRIPT, cmd, env)
    if r is None or "MOUNTED" not in r.stdout:
        pytest.skip("cannot mount tmpfs in a private mount namespace: "
                    f"{r.stderr.strip() if r else 'no unshare'}")
    assert r.returncode == 0, f"namespace script failed ({r.returncode}): {r.stderr}"
    rc1, err1 = int((t / "rc1").read_text()), (t / "err1").read_text()
    what = f"{where}: {ru.shell(cmd)} with the job on {jobsz} bytes, the output on {outsz}"
    assert rc1 == 4, f"{what}: exit {rc1}, expected 4\n{err1}"
    failed_in = ru.last_started(err1)
    assert failed_in in stages, f"{what}: failed in {failed_in}, expected {stages}\n{err1}"
    assert "No space left on device" in err1, f"{what}: reason not given\n{err1}"
    mnt = outmnt if where == "output" else jobmnt
    assert str(mnt) in err1, f"{what}: the message names no file under {mnt}\n{err1}"
    assert "GDT-4" in err1, f"{what}: no GDT-4xxx code\n{err1}"
    left = (t / "ls1").read_text().split()
    assert "out.ply" not in left, f"{what}: a file at the output path after the failure"
    assert not left, f"{what}: files left on the output file system after the failure: {left}"

    rc2, err2 = int((t / "rc2").read_text()), (t / "err2").read_text()
    assert rc2 == 0, f"{what}: rerun with space: exit {rc2}\n{err2}"
    small.assert_same(t / "final.ply", f"{what}: rerun with space")
    assert (t / "ls2").read_text().split() == ["out.ply"]
    assert (t / "lsjob2").read_text().split() == [], "job directory left after success"
    s2 = ru.read_json(t / "run2.json")
    assert s2["resumed"] is True, f"{what}: the rerun did not resume: {s2}"
    if where != "tiler":
        assert s2["reused"]["pass2"] is True, f"{what}: pass 2 not reused: {s2['reused']}"
    if where == "output":
        assert s2["reused"]["tiles"] == small.ntiles and s2["redone"]["tiles"] == 0, \
            f"{what}: every tile was finished, yet reused {s2['reused']}, redone {s2['redone']}"


def limited(limit):
    def setup():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return setup


@pytest.mark.parametrize("where", ["job", "output"])
def test_write_error_file_size_limit_then_rerun(request, tmp_path, where):
    """A write error (EFBIG under RLIMIT_FSIZE, SIGXFSZ ignored) on a job
    file or on the output: exit 4 naming the file and the reason; without
    the limit the same command resumes and writes the identical PLY.  The
    limit is half the largest job file, or (on the larger cloud, whose job
    files are all much smaller than its PLY) between the largest job file
    and the PLY's size."""
    small = request.getfixturevalue("small" if where == "job" else "big")
    use, largest, ply = kept_job_usage(small)
    if where == "job":
        limit = largest // 2
    else:
        assert 2 * largest < ply, f"a job file ({largest} bytes) is not much smaller than " \
                                  f"the PLY ({ply} bytes)"
        limit = (largest + ply) // 2
    out = tmp_path / "out" / "out.ply"
    out.parent.mkdir()
    job = tmp_path / "job"
    cmd = small.cmd(small.las, out, "--job", job)
    what = f"{ru.shell(cmd)} with RLIMIT_FSIZE {limit}"
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=600,
                       preexec_fn=limited(limit))
    assert r.returncode == 4, f"{what}: exit {r.returncode}, expected 4\n{r.stderr}"
    assert "File too large" in r.stderr, f"{what}: reason not given\n{r.stderr}"
    named = job if where == "job" else out
    assert str(named) in r.stderr, f"{what}: the message names no file under {named}\n{r.stderr}"
    assert not out.exists(), f"{what}: a file at the output path after the failure"
    js = tmp_path / "rerun.json"
    r2 = run(cmd + ["--json", js])
    assert r2.returncode == 0, f"{ru.shell(cmd)} (rerun): exit {r2.returncode}\n{r2.stderr}"
    small.assert_same(out, f"{what}, then without the limit")
    s2 = ru.read_json(js)
    assert s2["resumed"] is True, f"{what}: the rerun did not resume: {s2}"
    if where == "output":
        assert s2["reused"] == {"pass2": True, "tiles": small.ntiles}, s2["reused"]
    assert not job.exists()


# ------------------------------------------------------------ 3. changed job

@pytest.mark.parametrize("how", ["kept", "killed"])
def test_changed_input_refused_then_restart(small, tmp_path, how):
    las = small.copy_input(tmp_path / "in")
    out = tmp_path / "out.ply"
    job = default_job(out)
    cmd = small.cmd(las, out, *(["--keep-job"] if how == "kept" else []))
    if how == "kept":
        r = run(cmd)
        assert r.returncode == 0, r.stderr
        small.assert_same(out, ru.shell(cmd))
        before = stat_of(out)
    else:
        kill_in_tile_stage(cmd, job)
        assert not out.exists()
    assert job.is_dir()
    ru.las_bump_z(las, 0)
    r = run(cmd)
    assert_job_error(r, cmd, las.name)
    if how == "kept":
        assert stat_of(out) == before, "the output was touched by a refused run"
        small.assert_same(out, "after a refused run")
    else:
        assert not out.exists(), "a refused run wrote the output"
    assert job.is_dir(), "a refused run removed the job directory"

    js = tmp_path / "restart.json"
    r = run(cmd + ["--restart", "--json", js])
    assert r.returncode == 0, f"--restart: exit {r.returncode}\n{r.stderr}"
    s = ru.read_json(js)
    assert s["resumed"] is False and s["reused"]["tiles"] == 0 and \
        s["reused"]["pass2"] is False, f"--restart reused old work: {s}"
    restarted = out.read_bytes()
    fresh_dir = tmp_path / "fresh"
    fresh_in = fresh_dir / "in.las"
    fresh_dir.mkdir()
    shutil.copyfile(las, fresh_in)
    fresh_out = fresh_dir / "out.ply"
    r = run(small.cmd(fresh_in, fresh_out))
    assert r.returncode == 0, r.stderr
    assert restarted == fresh_out.read_bytes(), \
        f"--restart differs from a fresh run on the changed input: " \
        f"{ru.describe_difference(fresh_out, out)}"
    assert restarted != small.bytes, "the changed z does not show in the output"


@pytest.mark.sanitize
def test_changed_options_or_inputs_refused(tiny, tmp_path):
    """Each change of --halo, --tile, --cell, --dup or the inputs with an
    existing job: exit 6 naming what differs; output and job kept.  (Another
    output path alone is not a change: test_job_integrity.py.)"""
    las = tiny.copy_input(tmp_path / "in")
    other = tiny.copy_input(tmp_path / "in2", "other.las")
    out = tmp_path / "out.ply"
    job = tmp_path / "job"
    r = run(tiny.cmd(las, out, "--keep-job", "--job", job))
    assert r.returncode == 0, r.stderr
    before = stat_of(out)
    halo = int(tiny.summary["halo"])
    tile = int(tiny.args[tiny.args.index("--tile") + 1])
    cell = float(tiny.args[tiny.args.index("--cell") + 1])
    changes = {
        "halo": command(tiny.gdt, las, out, tiny.args, "--halo", halo + 1, "--job", job),
        "tile": command(tiny.gdt, las, out, ["--tile", tile * 2, "--cell", cell],
                        "--job", job),
        "cell": command(tiny.gdt, las, out, ["--tile", tile, "--cell", cell * 1.5],
                        "--job", job),
        "dup": command(tiny.gdt, las, out, tiny.args, "--dup", "max-z", "--job", job),
        "input": command(tiny.gdt, [las, other], out, tiny.args, "--job", job),
    }
    problems = []
    for name, cmd in changes.items():
        cmd = [str(c) for c in cmd]
        r = run(cmd)
        try:
            assert_job_error(r, cmd, name)
            assert stat_of(out) == before, "the output was touched"
            assert not (tmp_path / "other.ply").exists(), "the other output was written"
        except AssertionError as e:
            problems.append(f"{name}: {e}")
    assert not problems, "\n\n".join(problems)
    js = tmp_path / "rerun.json"
    r = run(tiny.cmd(las, out, "--keep-job", "--job", job, "--json", js))
    assert r.returncode == 0, r.stderr
    s = ru.read_json(js)
    assert s["reused"] == {"pass2": True, "tiles": tiny.ntiles}, \
        f"the refused runs damaged the job: reused {s['reused']}"
    tiny.assert_same(out, "rerun after the refused runs")


# ------------------------------------------------------------ 4. --resume DIR

@pytest.mark.parametrize("paths", ["absolute", "relative"])
def test_resume_dir_finishes_a_killed_job(small, tmp_path, paths):
    """--resume DIR alone, from another working directory, finishes a job
    killed in the tile stage (the command used absolute or relative paths)."""
    work = tmp_path / "work"
    las = small.copy_input(work)
    out, job = work / "out.ply", work / "job"
    if paths == "absolute":
        cmd = small.cmd(las, out, "--job", job)
    else:
        cmd = small.cmd(las.name, out.name, "--job", job.name)
    r = ru.Run(cmd, cwd=work)
    r.wait_for(lambda x: x.started("tiles"))
    r.wait_for(lambda x: len(ru.tri_files(job)) >= 1 or x.proc.poll() is not None, poll=0.001)
    r.send(signal.SIGKILL)
    r.finish()
    assert r.killed and r.died_in == "tiles", f"{r.died_in}: {r.stderr}"
    assert not out.exists()
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    js = tmp_path / "resume.json"
    rcmd = [small.gdt, "--resume", job, "--json", js]
    r = run(rcmd, cwd=elsewhere)
    assert r.returncode == 0, f"{ru.shell(rcmd)} (cwd {elsewhere}) after {ru.shell(cmd)} " \
                              f"(cwd {work}): exit {r.returncode}\n{r.stderr}"
    small.assert_same(out, f"--resume {job}")
    assert ru.read_json(js)["resumed"] is True
    assert not job.exists(), "job directory left after a successful --resume"
    assert ru.listing(elsewhere) == [], "--resume wrote into the working directory"


@pytest.mark.sanitize
@pytest.mark.parametrize("state", ["empty", "missing", "not-a-job"])
def test_resume_dir_without_job(gdt_bin, tmp_path, state):
    d = tmp_path / "nojob"
    if state != "missing":
        d.mkdir()
    if state == "not-a-job":
        (d / "job.db").write_bytes(b"this is not a database" * 100)
    cmd = [gdt_bin, "--resume", d]
    r = run(cmd)
    allowed = (2, 6) if state == "missing" else (6,)
    assert r.returncode in allowed, f"{ru.shell(cmd)}: exit {r.returncode}\n{r.stderr}"
    assert f"GDT-{r.returncode}" in r.stderr, f"no GDT-{r.returncode}xxx code: {r.stderr}"
    assert str(d) in r.stderr, f"the message does not name {d}: {r.stderr}"
    if state == "missing":
        assert not d.exists(), "--resume created the directory"
    else:
        assert ru.listing(d) == ([] if state == "empty" else ["job.db"]), ru.listing(d)
    assert ru.listing(tmp_path) == ([] if state == "missing" else ["nojob"])


def test_resume_dir_refuses_a_changed_input(small, tmp_path):
    las = small.copy_input(tmp_path / "in")
    out, job = tmp_path / "out.ply", tmp_path / "job"
    cmd = small.cmd(las, out, "--job", job)
    kill_in_tile_stage(cmd, job)
    ru.las_bump_z(las, 0)
    rcmd = [small.gdt, "--resume", job]
    r = run(rcmd)
    assert_job_error(r, rcmd, las.name)
    assert not out.exists()
    assert job.is_dir()


# ------------------------------------------------------------ 5. SIGINT, SIGTERM

@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_signal_in_tile_stage_stops_cleanly(small, tmp_path, sig):
    out = tmp_path / "out.ply"
    job = default_job(out)
    cmd = small.cmd(small.las, out)
    r = ru.Run(cmd)
    r.wait_for(lambda x: x.started("tiles"))
    assert r.wait_for(lambda x: len(ru.tri_files(job)) >= 1, poll=0.001), r.stderr
    r.send(sig)
    rc = r.finish(timeout=30)
    assert rc == 130, f"{ru.shell(cmd)} + {sig.name}: exit {rc}, expected 130\n{r.stderr}"
    assert r.last_started == "tiles", r.last_started
    text = r.stderr
    assert "--resume" in text or "same command" in text, \
        f"the message does not say how to continue:\n{text}"
    assert not out.exists(), f"a file at the output path after {sig.name}"
    assert job.is_dir(), f"the job directory is gone after {sig.name}"
    done = len(ru.tri_files(job))
    js = tmp_path / "rerun.json"
    r2 = run(cmd + ["--json", js])
    assert r2.returncode == 0, f"rerun after {sig.name}: exit {r2.returncode}\n{r2.stderr}"
    small.assert_same(out, f"rerun after {sig.name}")
    s = ru.read_json(js)
    assert s["resumed"] is True
    assert s["reused"] == {"pass2": True, "tiles": done}, \
        f"{done} tiles were finished when {sig.name} stopped the run; reused {s['reused']}"
    assert s["redone"] == {"pass2": False, "tiles": small.ntiles - done}, s["redone"]
    assert not job.exists()


# ------------------------------------------------------------ 6. --json, damaged tiles

@pytest.mark.sanitize
def test_json_fresh_run_and_rerun_of_a_finished_job(tiny, tmp_path):
    out = tmp_path / "out.ply"
    j1, j2 = tmp_path / "1.json", tmp_path / "2.json"
    cmd = tiny.cmd(tiny.las, out, "--keep-job")
    r = run(cmd + ["--json", j1])
    assert r.returncode == 0, r.stderr
    s = ru.read_json(j1)
    assert s["resumed"] is False
    assert s["reused"] == {"pass2": False, "tiles": 0}, s["reused"]
    assert s["redone"] == {"pass2": True, "tiles": tiny.ntiles}, s["redone"]
    assert len(ru.tri_files(default_job(out))) == tiny.ntiles
    r = run(cmd + ["--json", j2])
    assert r.returncode == 0, r.stderr
    s = ru.read_json(j2)
    assert s["resumed"] is True
    assert s["reused"] == {"pass2": True, "tiles": tiny.ntiles}, s["reused"]
    assert s["redone"] == {"pass2": False, "tiles": 0}, s["redone"]
    tiny.assert_same(out, "rerun of a finished job")


def test_json_after_sigkill_in_tile_stage(many, tmp_path):
    """SIGKILL late in the tile stage (at least half of the .tri files
    present, or the stage has run KILL_AFTER s): the rerun reports resumed,
    pass 2 reused, and reuses every tile whose .tri file had been present
    for LOSS_WINDOW s before the kill (finished tiles may be recorded in
    batches, so the last moments of work may be redone), at most the tiles
    present; reused + redone = all tiles."""
    out = tmp_path / "out.ply"
    job = default_job(out)
    cmd = many.cmd(many.las, out)
    r = ru.Run(cmd)
    r.wait_for(lambda x: x.started("tiles"))
    t_tiles = r.stage_start("tiles")
    seen = []  # (time, .tri files present)

    def late(x):
        seen.append((x.elapsed(), len(ru.tri_files(job))))
        return seen[-1][1] >= many.ntiles // 2 and seen[-1][0] - t_tiles >= KILL_AFTER or \
            seen[-1][1] >= many.ntiles - 2
    assert r.wait_for(late, poll=0.005), r.stderr
    r.send(signal.SIGKILL)
    t_kill = r.sent_at
    r.finish()
    assert r.died_in == "tiles", f"{r.died_in}\n{r.stderr}"
    present = len(ru.tri_files(job))
    old = max([k for t, k in seen if t <= t_kill - LOSS_WINDOW], default=0)
    assert old > 0, f"the tile stage ran only {t_kill - t_tiles:.2f} s before the kill: " \
                    "too short for this test (use a larger cloud)"
    js = tmp_path / "rerun.json"
    r2 = run(cmd + ["--json", js])
    assert r2.returncode == 0, r2.stderr
    many.assert_same(out, "rerun after a kill in the tile stage")
    s = ru.read_json(js)
    assert s["resumed"] is True and s["reused"]["pass2"] is True, s
    reused, redone = s["reused"]["tiles"], s["redone"]["tiles"]
    assert old <= reused <= present, \
        f"killed {t_kill - t_tiles:.2f} s into the tile stage with {present} of {many.ntiles} " \
        f".tri files present ({old} of them for {LOSS_WINDOW} s or more): reused {reused}"
    assert reused + redone == many.ntiles, s


@pytest.mark.sanitize
def test_damaged_tile_files_are_redone(tiny, tmp_path):
    """A .tri file with a flipped header byte, one with a flipped body
    byte, a truncated one and a deleted one: exactly these four tiles are
    recomputed, each file comes back as it was, the output is identical."""
    out = tmp_path / "out.ply"
    job = default_job(out)
    cmd = tiny.cmd(tiny.las, out, "--keep-job")
    r = run(cmd)
    assert r.returncode == 0, r.stderr
    tris = ru.tri_files(job)
    assert len(tris) == tiny.ntiles
    by_size = sorted(tris, key=lambda p: (-p.stat().st_size, p.name))
    victims = by_size[:4]
    original = {p: p.read_bytes() for p in victims}
    rng = random.Random(7)
    for kind, p in zip(("flip-header", "flip-body", "truncate", "delete"), victims):
        data = bytearray(original[p])
        assert len(data) > 64, f"{p}: no body to damage"
        if kind == "flip-header":
            data[rng.randrange(0, 64)] ^= 1 << rng.randrange(8)
        elif kind == "flip-body":
            data[rng.randrange(64, len(data))] ^= 1 << rng.randrange(8)
        elif kind == "truncate":
            data = data[:len(data) // 2]
        if kind == "delete":
            p.unlink()
        else:
            p.write_bytes(bytes(data))
    js = tmp_path / "rerun.json"
    r = run(cmd + ["--json", js])
    assert r.returncode == 0, r.stderr
    tiny.assert_same(out, "rerun with damaged .tri files")
    s = ru.read_json(js)
    assert s["redone"]["tiles"] == 4 and s["reused"]["tiles"] == tiny.ntiles - 4, \
        f"4 damaged .tri files: reused {s['reused']}, redone {s['redone']}"
    for p in victims:
        assert p.exists() and p.read_bytes() == original[p], f"{p} not restored"


@pytest.mark.sanitize
@pytest.mark.parametrize("damage", ["truncate", "delete"])
def test_damaged_tiler_file_redoes_pass2(tiny, tmp_path, damage):
    """The .pts file of the last tile (in tile order, so every other tile
    is looked at first) loses half its bytes, or is gone (as after a kill
    while a finished job directory is removed): pass 2 is redone and the
    output is identical."""
    out = tmp_path / "out.ply"
    job = default_job(out)
    cmd = tiny.cmd(tiny.las, out, "--keep-job")
    r = run(cmd)
    assert r.returncode == 0, r.stderr
    pts = sorted((job / "tiles").glob("tile_*.pts"),
                 key=lambda p: tuple(int(v) for v in p.stem.split("_")[1:3])[::-1])
    assert len(pts) == tiny.ntiles, "not one .pts file per tile in the kept job"
    victim = pts[-1]
    if damage == "delete":
        victim.unlink()
    else:
        data = victim.read_bytes()
        victim.write_bytes(data[:len(data) // 2])
    js = tmp_path / "rerun.json"
    r = run(cmd + ["--json", js])
    assert r.returncode == 0, f"{ru.shell(cmd)} with {victim.name} {damage}d: exit " \
                              f"{r.returncode}\n{r.stderr}"
    tiny.assert_same(out, f"rerun with {victim.name} {damage}d")
    s = ru.read_json(js)
    assert s["reused"]["pass2"] is False and s["redone"]["pass2"] is True, s
    assert s["reused"]["tiles"] + s["redone"]["tiles"] == tiny.ntiles, s


@pytest.mark.sanitize
def test_pass2_is_recorded_only_once_its_files_are_durable(tiny, tools_dir, tmp_path):
    """Pass 2 renames each tile's .pts and .edge files without a sync of
    their own and makes them all durable at once before the journal records
    pass 2: when that sync fails (an LD_PRELOAD shim fails syncfs through
    the tile directory, as a disk reporting a lost write), the run exits 4
    naming the directory, writes no output, and the rerun redoes pass 2 (the
    journal never recorded it) to the uninterrupted run's bytes."""
    shim = tools_dir / "libgdt_fail_write.so"
    if not shim.exists():
        pytest.fail(f"libgdt_fail_write.so not built at {shim}")
    out, job, log = tmp_path / "o.ply", tmp_path / "job", tmp_path / "refused.log"
    cmd = tiny.cmd(tiny.las, out, "--job", job)
    env = {**os.environ, "LD_PRELOAD": str(shim), "GDT_TEST_FAIL_SYNCFS_MATCH": str(job / "tiles"),
           "GDT_TEST_FAIL_WRITE_LOG": str(log)}
    if "ASAN_OPTIONS" in env:  # the sanitized build: the shim comes before its runtime
        env["ASAN_OPTIONS"] += ":verify_asan_link_order=0"
    r = run(cmd, env=env)
    assert log.exists(), r.stderr  # the shim refused the sync
    assert r.returncode == 4, r.stderr
    assert "cannot sync the files of" in r.stderr and "Input/output error" in r.stderr, r.stderr
    assert str(job / "tiles") in r.stderr, r.stderr
    assert not out.exists() and job.is_dir()
    js = tmp_path / "rerun.json"
    r = run(cmd + ["--json", js])
    assert r.returncode == 0, r.stderr
    tiny.assert_same(out, "rerun after pass 2's sync failed")
    s = ru.read_json(js)
    assert s["reused"]["pass2"] is False and s["redone"]["pass2"] is True, s


# ------------------------------------------------------------ several devices

def test_a_lane_failing_fails_the_run_then_it_resumes(small, tools_dir, tmp_path):
    """With two devices, the further device's lane cannot read its tiles
    (an LD_PRELOAD shim fails every open of a .pts file on the threads named
    gdt-lane): the stage reports the lane's failure at that tile, the run
    exits 4 naming the file, with no output or temporary left and the job
    kept; a rerun on one device, and one on two devices without the fault,
    give the uninterrupted run's bytes."""
    shim = tools_dir / "libgdt_fail_open.so"
    if not shim.exists():
        pytest.fail(f"libgdt_fail_open.so not built at {shim}")
    out, job, log = tmp_path / "o.ply", tmp_path / "job", tmp_path / "refused.log"
    cmd = small.cmd(small.las, out, "--device", "0,0", "--job", job)
    r = run(cmd, env={**os.environ, "LD_PRELOAD": str(shim), "GDT_TEST_FAIL_OPEN_MATCH": ".pts",
                      "GDT_TEST_FAIL_OPEN_THREAD": "gdt-lane",
                      "GDT_TEST_FAIL_OPEN_LOG": str(log)})
    assert log.exists(), r.stderr  # a lane tried to read a tile
    assert r.returncode == 4, r.stderr
    assert r.stderr.count("error GDT-4504") == 1 and ".pts" in r.stderr, r.stderr
    assert not out.exists() and job.is_dir()
    assert [p.name for p in tmp_path.iterdir() if ".tmp-" in p.name] == []
    r = run(small.cmd(small.las, out, "--job", job, "--keep-job"))
    assert r.returncode == 0, r.stderr
    small.assert_same(out, "resumed on one device after a lane failed")
    out.unlink()
    r = run(small.cmd(small.las, out, "--job", job, "--device", "0,0"))
    assert r.returncode == 0, r.stderr
    small.assert_same(out, "rerun on two devices")


def test_two_devices_resume_one_device_and_back(small, tmp_path):
    """The tile stage on two cores (the one PoCL device opened twice, --device
    0,0) gives the bytes of one; killed in its tile stage, the job is finished
    by a run on one device, and a run on two devices reuses every tile of a
    finished job."""
    two = tmp_path / "two.ply"
    r = ru.Run(small.cmd(small.las, two, "--device", "0,0"))
    assert r.finish() == 0, r.stderr
    small.assert_same(two, "--device 0,0")

    out, job = tmp_path / "k.ply", tmp_path / "k.job"
    cmd = small.cmd(small.las, out, "--device", "0,0", "--job", job)
    kill_in_tile_stage(cmd, job, min_tri=2)
    js = tmp_path / "k1.json"
    r = ru.Run(small.cmd(small.las, out, "--job", job, "--keep-job", "--json", js))
    assert r.finish() == 0, r.stderr
    small.assert_same(out, "resumed on one device")
    s = ru.read_json(js)
    # the killed run's tiles count only once their batch was synced and recorded
    assert s["reused"]["tiles"] < small.ntiles, s["reused"]

    out.unlink()
    js = tmp_path / "k2.json"
    r = ru.Run(small.cmd(small.las, out, "--job", job, "--device", "0,0", "--json", js))
    assert r.finish() == 0, r.stderr
    small.assert_same(out, "rerun on two devices")
    assert ru.read_json(js)["reused"]["tiles"] == small.ntiles
