"""Integrity of a job directory between runs (gdt-tile ... --job DIR).

Nothing a rerun takes from a job directory may reach the output unless it
is proven intact and this job's: every job file kind (.pts, .edge, .tri,
the journal itself, index.vdb, merge.faces) truncated, with a flipped
coordinate or z bit, swapped with another tile's, or replaced by another
job's (a job of a different cloud with the same tile plan: the same points
with other z values) gives either a PLY byte-identical to an uninterrupted
run (the damaged work redone, with a warning naming the file) or exit 6
naming the file, never a wrong mesh.

One job, one process: a second run on a job directory that a run holds
exits 6 at once naming the holder's pid, also with --restart or --resume,
and the first run finishes correctly; a killed run's lock does not block.

A failure that finished nothing never blocks the fix: an empty input then
the right one, a full disk while the journal is created, a journal left
without its schema row; and a changed output path alone keeps the finished
tiles (after a full output disk, -o elsewhere with the same --job).

The job of an uninterrupted --keep-job run is made once per module and
copied for each test (a job directory is self-contained).
"""
import os
import pathlib
import re
import shutil
import signal
import sqlite3
import subprocess
import time

import pytest

import resume_util as ru
from test_resume import TINY_ARGS, TINY_POINTS, TINY_SEED, Case, kill_in_tile_stage, run

REC = 32  # bytes per .pts / .edge record: x, y (int64), z (double), ord


class Jobs:
    """The tiny case, a kept job of it, and a kept job of another cloud with
    the same tile plan (the same x, y; every z changed)."""

    def __init__(self, gdt_bin, folder):
        self.case = Case(gdt_bin, folder / "case", TINY_POINTS, TINY_SEED, TINY_ARGS)
        self.job = folder / "kept.job"
        r = run(self.case.cmd(self.case.las, folder / "kept.ply", "--keep-job", "--job",
                              self.job))
        assert r.returncode == 0, r.stderr
        other = folder / "other"
        other.mkdir()
        self.other_las = other / "cloud.las"
        shutil.copyfile(self.case.las, self.other_las)
        _, _, count = ru.las_layout(self.other_las)
        for i in range(count):
            ru.las_bump_z(self.other_las, i)
        self.other_job = folder / "other.job"
        r = run(self.case.cmd(self.other_las, other / "out.ply", "--keep-job", "--job",
                              self.other_job))
        assert r.returncode == 0, r.stderr
        self.other_ply = other / "out.ply"
        assert self.other_ply.read_bytes() != self.case.bytes, "the other cloud gives the same PLY"
        assert sorted(p.name for p in (self.job / "tiles").iterdir()) == \
            sorted(p.name for p in (self.other_job / "tiles").iterdir()), \
            "the other cloud's job has another tile plan"

    def copy(self, dst, which="kept"):
        shutil.copytree(self.job if which == "kept" else self.other_job, dst)
        return dst


@pytest.fixture(scope="module")
def jobs(gdt_bin, tmp_path_factory):
    return Jobs(gdt_bin, tmp_path_factory.mktemp("integrity"))


def tile_files(job, ext):
    """The job's tile_<i>_<j>.<ext> files in tile order (rows, then columns)."""
    files = [p for p in (job / "tiles").glob(f"tile_*.{ext}")]
    return sorted(files, key=lambda p: tuple(int(v) for v in p.stem.split("_")[1:3])[::-1])


def victims(job, ext):
    """Two different tiles' files of a kind, near the middle, each with at
    least two records (.pts/.edge) or a body (.tri)."""
    files = [p for p in tile_files(job, ext) if p.stat().st_size >= 2 * REC + 64]
    assert len(files) >= 4, f"too few {ext} files to damage in {job}"
    mid = len(files) // 2
    return files[mid], files[mid + 1]


def flip(path, offset, bit):
    data = bytearray(path.read_bytes())
    data[offset] ^= 1 << bit
    path.write_bytes(bytes(data))


def damage(job, jobs, ext, how):
    """Damages one ext file of job as how says; returns the file's name."""
    a, b = victims(job, ext)
    body = 64 if ext == "tri" else 0
    if how == "truncate":
        # whole records off the end: the size stays plausible
        data = a.read_bytes()
        a.write_bytes(data[:len(data) - REC])
    elif how == "flip-xy":
        flip(a, body + REC + 0, 0)          # x of the second record (a face index in .tri)
    elif how == "flip-z":
        flip(a, body + REC + 22, 0)         # a high mantissa bit of z (.tri: a face index)
    elif how == "swap":
        tmp = a.with_name(a.name + ".swap")
        a.rename(tmp)
        b.rename(a)
        tmp.rename(b)
    elif how == "other-job":
        shutil.copyfile(jobs.other_job / "tiles" / a.name, a)
    else:
        raise AssertionError(how)
    return a.name


def rerun(jobs, job, tmp_path, *extra):
    out = tmp_path / "out.ply"
    js = tmp_path / "rerun.json"
    cmd = jobs.case.cmd(jobs.case.las, out, "--job", job, "--json", js, *extra)
    r = run(cmd)
    return cmd, r, out, js


def assert_identical_or_refused(jobs, cmd, r, out, name):
    """Exit 0 with the uninterrupted run's PLY and a warning naming the file,
    or exit 6 naming it with nothing at the output path."""
    what = ru.shell(cmd)
    if r.returncode == 6:
        assert name in r.stderr and "GDT-6" in r.stderr, f"{what}: exit 6 without naming " \
                                                         f"{name}\n{r.stderr}"
        assert not out.exists(), f"{what}: refused, yet wrote the output"
        return False
    assert r.returncode == 0, f"{what}: exit {r.returncode}\n{r.stderr}"
    jobs.case.assert_same(out, f"{what} with {name} damaged")
    assert name in r.stderr and "GDT-6" in r.stderr, \
        f"{what}: the damaged {name} was redone without a warning naming it\n{r.stderr}"
    return True


# ------------------------------------------------------------ 1. damaged files

DAMAGES = ["truncate", "flip-xy", "flip-z", "swap", "other-job"]


@pytest.mark.parametrize("how", DAMAGES)
@pytest.mark.parametrize("ext", ["pts", "edge"])
def test_damaged_pass2_file_redoes_pass2(jobs, tmp_path, ext, how):
    job = jobs.copy(tmp_path / "job")
    name = damage(job, jobs, ext, how)
    cmd, r, out, js = rerun(jobs, job, tmp_path)
    if assert_identical_or_refused(jobs, cmd, r, out, name):
        s = ru.read_json(js)
        assert s["redone"]["pass2"] is True, f"{ru.shell(cmd)}: pass 2 adopted: {s}"


@pytest.mark.parametrize("how", ["truncate", "flip-xy", "swap", "other-job"])
def test_damaged_tri_file_redoes_the_tile(jobs, tmp_path, how):
    job = jobs.copy(tmp_path / "job")
    name = damage(job, jobs, "tri", how)
    cmd, r, out, js = rerun(jobs, job, tmp_path)
    if assert_identical_or_refused(jobs, cmd, r, out, name):
        s = ru.read_json(js)
        redo = 2 if how == "swap" else 1
        assert s["reused"]["pass2"] is True and s["redone"]["tiles"] == redo, \
            f"{ru.shell(cmd)}: one damaged .tri ({how}): reused {s['reused']}, " \
            f"redone {s['redone']}"


@pytest.mark.sanitize
def test_whole_tiles_dir_of_another_job(jobs, tmp_path):
    """tiles/ replaced by the other cloud's: identical files names, sizes
    and .tri faces, other z values: all of it redone."""
    job = jobs.copy(tmp_path / "job")
    shutil.rmtree(job / "tiles")
    shutil.copytree(jobs.other_job / "tiles", job / "tiles")
    cmd, r, out, js = rerun(jobs, job, tmp_path)
    assert_identical_or_refused(jobs, cmd, r, out, "tile_")
    s = ru.read_json(js)
    assert s["reused"] == {"pass2": False, "tiles": 0}, s


@pytest.mark.parametrize("how", ["checksum", "swap-rows", "id", "flip-header",
                                 "other-job-db"])
def test_tampered_journal(jobs, tmp_path, how):
    """The journal edited (a recorded checksum, two tiles' records swapped,
    the job id), its header damaged, or replaced by the other job's: the
    output is identical (the files no longer verify: redone) or exit 6
    naming job.db or the job."""
    job = jobs.copy(tmp_path / "job")
    db = job / "job.db"
    if how == "flip-header":
        flip(db, 3, 1)
    elif how == "other-job-db":
        shutil.copyfile(jobs.other_job / "job.db", db)
    else:
        con = sqlite3.connect(db)
        with con:
            if how == "checksum":
                con.execute("UPDATE pfile SET checksum = checksum + 1 WHERE k = 3 AND kind = 1")
            elif how == "swap-rows":
                con.execute("UPDATE pfile SET k = -1 WHERE k = 3")
                con.execute("UPDATE pfile SET k = 3 WHERE k = 4")
                con.execute("UPDATE pfile SET k = 4 WHERE k = -1")
            else:
                con.execute("UPDATE meta SET value = '0123456789abcdef0123456789abcdef' "
                            "WHERE key = 'id'")
        con.close()
    cmd, r, out, js = rerun(jobs, job, tmp_path)
    if r.returncode == 6:
        assert str(job) in r.stderr and "GDT-6" in r.stderr, r.stderr
        assert not out.exists()
        assert how in ("flip-header", "other-job-db"), \
            f"{ru.shell(cmd)}: refused a journal whose files can be redone\n{r.stderr}"
        return
    assert r.returncode == 0, f"{ru.shell(cmd)}: exit {r.returncode}\n{r.stderr}"
    jobs.case.assert_same(out, f"{ru.shell(cmd)} with the journal tampered ({how})")
    s = ru.read_json(js)
    assert s["redone"]["pass2"] is True, s


@pytest.mark.sanitize
@pytest.mark.parametrize("name", ["index.vdb", "merge.faces"])
def test_files_rewritten_each_run_are_never_trusted(jobs, tmp_path, name):
    """index.vdb (pass 1) and merge.faces (the merge) are written anew by
    every run: damaged or another job's, the output is identical."""
    job = jobs.copy(tmp_path / "job")
    shutil.copyfile(jobs.other_job / name, job / name)
    data = bytearray((job / name).read_bytes())
    (job / name).write_bytes(bytes(data[:len(data) // 2]))
    cmd, r, out, js = rerun(jobs, job, tmp_path)
    assert r.returncode == 0, f"{ru.shell(cmd)}: exit {r.returncode}\n{r.stderr}"
    jobs.case.assert_same(out, f"{ru.shell(cmd)} with {name} damaged")
    assert ru.read_json(js)["reused"] == {"pass2": True, "tiles": jobs.case.ntiles}


# ------------------------------------------------------------ 2. one job, one process

def test_second_run_on_a_held_job_exits_at_once(jobs, tmp_path):
    """While a run holds the job (stopped with SIGSTOP once pass 1 runs, so
    it cannot finish first), the same command, --restart and --resume each
    exit 6 within seconds naming the holder's pid; continued, the holder
    finishes with the right PLY and removes the job."""
    case = jobs.case
    out = tmp_path / "out.ply"
    job = tmp_path / "job"
    cmd = case.cmd(case.las, out, "--job", job)
    first = ru.Run(cmd)
    problems = []
    try:
        first.wait_for(lambda x: x.started("pass1"))
        first.proc.send_signal(signal.SIGSTOP)
        for extra in ([], ["--restart"], None):
            other = [case.gdt, "--resume", job] if extra is None else cmd + extra
            t0 = time.monotonic()
            r = run(other)
            took = time.monotonic() - t0
            if r.returncode != 6 or f"pid {first.proc.pid}" not in r.stderr or \
                    "GDT-6906" not in r.stderr or took > 10:
                problems.append(f"{ru.shell(other)}: exit {r.returncode} after {took:.1f} s\n"
                                f"{r.stderr}")
            assert not out.exists(), f"{ru.shell(other)} wrote the output"
    finally:
        first.proc.send_signal(signal.SIGCONT)
    rc = first.finish()
    assert rc == 0, f"the holder failed: {first.stderr}"
    assert not problems, "\n".join(problems)
    case.assert_same(out, "the run that held the job")
    assert not job.exists(), "job directory left after a successful run"


def test_lock_of_a_killed_run_does_not_block(jobs, tmp_path):
    case = jobs.case
    out = tmp_path / "out.ply"
    job = tmp_path / "job"
    cmd = case.cmd(case.las, out, "--job", job)
    kill_in_tile_stage(cmd, job)
    assert (job / "lock").exists()
    r = run(cmd)
    assert r.returncode == 0, f"{ru.shell(cmd)} after a SIGKILL: exit {r.returncode}\n{r.stderr}"
    case.assert_same(out, "rerun after a SIGKILL")
    assert not job.exists()


def test_removal_cut_short_leaves_no_directory(jobs, tmp_path):
    """A job directory the run made, killed while a finished job was being
    removed (the journal already gone, the rest not): the rerun computes
    everything and removes the directory (it is still this job's)."""
    case = jobs.case
    out = tmp_path / "out.ply"
    job = pathlib.Path(str(out) + ".gdt-job")
    cmd = case.cmd(case.las, out)
    kill_in_tile_stage(cmd, job)
    for name in ("job.db", "job.db-wal", "job.db-shm", "index.vdb"):
        if (job / name).exists():
            (job / name).unlink()
    r = run(cmd)
    assert r.returncode == 0, f"{ru.shell(cmd)}: exit {r.returncode}\n{r.stderr}"
    case.assert_same(out, "rerun after a removal cut short")
    assert not job.exists(), f"job directory left: {ru.listing(job)}"


@pytest.mark.sanitize
def test_given_job_directory_is_kept(jobs, tmp_path):
    """--job naming a directory that existed before the job: its files go
    at the end, the directory stays (and so does anything else in it)."""
    case = jobs.case
    job = tmp_path / "mine"
    job.mkdir()
    (job / "notes.txt").write_text("mine")
    out = tmp_path / "out.ply"
    r = run(case.cmd(case.las, out, "--job", job))
    assert r.returncode == 0, r.stderr
    case.assert_same(out, "run in a given directory")
    assert ru.listing(job) == ["notes.txt"]
    (job / "notes.txt").unlink()
    r = run(case.cmd(case.las, out, "--job", job, "--restart"))
    assert r.returncode == 0, r.stderr
    assert job.is_dir() and ru.listing(job) == [], ru.listing(job)


# ------------------------------------------------------------ 3. failures that must not block

@pytest.mark.sanitize
@pytest.mark.parametrize("fix", ["same-path", "other-path"])
def test_empty_input_then_the_right_one(jobs, tmp_path, fix):
    case = jobs.case
    las = tmp_path / "in.las"
    las.write_bytes(b"")
    out = tmp_path / "out.ply"
    job = tmp_path / "job"
    r = run(case.cmd(las, out, "--job", job))
    assert r.returncode == 3, f"empty input: exit {r.returncode}\n{r.stderr}"
    # a run that finished nothing leaves nothing behind
    assert not job.exists(), f"the failed run left {ru.listing(job)}"
    if fix == "same-path":
        shutil.copyfile(case.las, las)
    else:
        las = case.las
    cmd = case.cmd(las, out, "--job", job)
    r = run(cmd)
    assert r.returncode == 0, f"{ru.shell(cmd)} after an empty input: exit {r.returncode}\n" \
                              f"{r.stderr}"
    case.assert_same(out, "the corrected rerun")


@pytest.mark.sanitize
def test_refused_option_leaves_no_job_files(jobs, tmp_path):
    """A run refused after it took the job (a --cell below the lattice
    step) removes what it made: the default job directory goes, a given
    one is emptied of the job's files and kept."""
    case = jobs.case
    out = tmp_path / "out.ply"
    r = run(case.cmd(case.las, out, "--cell", "1e-9"))
    assert r.returncode == 2, f"--cell 1e-9: exit {r.returncode}\n{r.stderr}"
    default = tmp_path / "out.ply.gdt-job"
    assert not default.exists(), f"the refused run left {ru.listing(default)}"
    mine = tmp_path / "mine"
    mine.mkdir()
    r = run(case.cmd(case.las, out, "--cell", "1e-9", "--job", mine))
    assert r.returncode == 2, r.stderr
    assert mine.is_dir() and ru.listing(mine) == [], ru.listing(mine)
    assert not out.exists()


# A job directory on a tmpfs of SIZE: the run fails (exit 4); with the
# file system grown, the same command runs.  Prints RC1=, RC2=.
FULL_JOB = '''mount -t tmpfs -o size="$SIZE" tmpfs "$1" || exit 99
echo MOUNTED
shift
"$@"
echo "RC1=$?"
mount -o remount,size=256m "$JOBDIR" || exit 98
"$@"
echo "RC2=$?"
'''


@pytest.mark.parametrize("size", ["4k", "8k", "12k", "16k", "24k", "32k", "64k"])
def test_full_disk_while_creating_the_journal(jobs, tmp_path, size):
    """The job's file system is full while the lock, the journal or its
    first records are written: exit 4; then, with space, the same command
    runs (a journal cut short is never "of another version")."""
    case = jobs.case
    out = tmp_path / "out.ply"
    job = tmp_path / "job"
    job.mkdir()
    cmd = case.cmd(case.las, out, "--job", job)
    r = ru.run_in_namespace(FULL_JOB, [job, *cmd], {"SIZE": size, "JOBDIR": str(job)})
    if r is None or "MOUNTED" not in r.stdout:
        pytest.skip("cannot mount tmpfs in a private mount namespace")
    what = f"{ru.shell(cmd)} with the job on {size}"
    assert "RC1=4" in r.stdout, f"{what}: {r.stdout}\n{r.stderr}"
    assert "RC2=0" in r.stdout, f"{what}, then with space: {r.stdout}\n{r.stderr}"
    case.assert_same(out, f"{what}, then with space")


@pytest.mark.sanitize
@pytest.mark.parametrize("state", ["empty-file", "tables-only", "old-schema", "old-schema-work"])
def test_journal_without_schema_row_is_new(jobs, tmp_path, state):
    """A journal cut short before its schema row (an empty file, tables
    only) or of an older schema that finished nothing is started afresh;
    one of an older schema with finished work is refused (exit 6)."""
    case = jobs.case
    out = tmp_path / "out.ply"
    job = tmp_path / "job"
    job.mkdir()
    if state == "empty-file":
        (job / "job.db").write_bytes(b"")
    else:
        con = sqlite3.connect(job / "job.db")
        con.execute("CREATE TABLE meta(key TEXT PRIMARY KEY, value TEXT NOT NULL)")
        con.execute("CREATE TABLE stage(name TEXT PRIMARY KEY, done INTEGER NOT NULL)")
        if state.startswith("old-schema"):
            con.execute("INSERT INTO meta VALUES ('schema', '1'), ('params', 'tile=1')")
            con.execute("INSERT INTO stage VALUES ('pass2', ?)", (int(state.endswith("work")),))
        con.commit()
        con.close()
    r = run(case.cmd(case.las, out, "--job", job))
    if state == "old-schema-work":
        assert r.returncode == 6 and "GDT-6901" in r.stderr and "job.db" in r.stderr, \
            f"{state}: exit {r.returncode}\n{r.stderr}"
        assert not out.exists()
        return
    assert r.returncode == 0, f"{state}: exit {r.returncode}\n{r.stderr}"
    case.assert_same(out, f"run over a journal ({state})")


def test_full_output_disk_then_output_elsewhere(jobs, tmp_path):
    """The output file system fills up (tmpfs of 64 KiB): exit 4, the tiles
    are kept in the job; the same command with -o elsewhere and the same
    --job reuses every tile and writes the identical PLY; --resume then
    knows the new output."""
    case = jobs.case
    full = tmp_path / "full"
    full.mkdir()
    job = tmp_path / "job"
    cmd = case.cmd(case.las, full / "out.ply", "--job", job)
    script = 'mount -t tmpfs -o size=64k tmpfs "$1" || exit 99\necho MOUNTED\nshift\n"$@"\n' \
             'echo "RC=$?"\n'
    r = ru.run_in_namespace(script, [full, *cmd], {})
    if r is None or "MOUNTED" not in r.stdout:
        pytest.skip("cannot mount tmpfs in a private mount namespace")
    m = re.search(r"RC=(\d+)", r.stdout)
    assert m and m.group(1) == "4", f"{ru.shell(cmd)} on a full output disk: {r.stdout}\n" \
                                    f"{r.stderr}"
    assert "No space left on device" in r.stderr, r.stderr
    out = tmp_path / "elsewhere" / "out.ply"
    out.parent.mkdir()
    js = tmp_path / "rerun.json"
    cmd2 = case.cmd(case.las, out, "--job", job, "--json", js, "--keep-job")
    r2 = run(cmd2)
    assert r2.returncode == 0, f"{ru.shell(cmd2)}: exit {r2.returncode}\n{r2.stderr}"
    case.assert_same(out, "-o elsewhere after a full output disk")
    s = ru.read_json(js)
    assert s["resumed"] is True and s["reused"] == {"pass2": True, "tiles": case.ntiles}, s
    out.unlink()
    r3 = run([case.gdt, "--resume", job])
    assert r3.returncode == 0, r3.stderr
    case.assert_same(out, "--resume after the output moved")
