"""Never destroy, never silently wrong: the start-up checks of gdt-tile.

- No output (-o, --json, the job directory) may be an input, by any path
  form (the same name, ./name, a symbolic link, a hard link): refused with
  exit 2 before any work, the input left as it was.
- Outputs are written under a temporary name and renamed over the path, so
  an output that exists must be a regular file: FIFOs, devices,
  directories and symbolic links are refused (exit 2) and left alone.
- An empty output path or one in a missing directory is refused at start-up
  (exit 2), not after the run.
- Inputs are read more than once, so a FIFO, /dev/stdin on a pipe, a device
  or a directory is refused at once (exit 3) instead of hanging.
- SIGINT/SIGTERM at any moment after the program's first instruction stop
  every mode with exit 130 and a message saying so; a malformed --device
  is a usage error (exit 2).
No test here ever names /dev/null or another shared special file as an
output: the special files they use are made in the test's own directory.
"""
import os
import shutil
import signal
import stat
import subprocess
import sys
import time

import pytest

import tiled_util as tu

QUICK = 30  # seconds: every refusal here comes before any work


@pytest.fixture(scope="module")
def cloud(tmp_path_factory):
    d = tmp_path_factory.mktemp("safety")
    return tu.gen_cloud(d / "cloud.las", 4000, 5)


@pytest.fixture(scope="module")
def big_cloud(tmp_path_factory):
    """A cloud whose --reference run takes a few tenths of a second."""
    d = tmp_path_factory.mktemp("safety_big")
    return tu.gen_cloud(d / "big.las", 200000, 2)


def copy_input(cloud, dst):
    dst.write_bytes(cloud.read_bytes())
    return dst


def run(cmd, cwd=None, timeout=QUICK, **kw):
    return subprocess.run([str(c) for c in cmd], capture_output=True, text=True, cwd=cwd,
                          timeout=timeout, **kw)


def refused(r, code, *words):
    """r exited with code, and its error line holds every word."""
    assert r.returncode == code, f"exit {r.returncode}, expected {code}\n{r.stderr}"
    errors = [x for x in r.stderr.splitlines() if x.startswith("gdt-tile: error ")]
    assert len(errors) == 1 and errors[0].startswith(f"gdt-tile: error GDT-{code}"), r.stderr
    line = errors[0]
    for w in words:
        assert w in line, f"{w!r} not in {line!r}"


# ------------------------------------------------ outputs that are inputs

def path_forms(tmp_path, las):
    """name -> (the argument naming las another way, the cwd to run in)."""
    (tmp_path / "link.las").symlink_to(las.name)
    os.link(las, tmp_path / "hard.las")
    return {
        "same": las.name,
        "dot-slash": "./" + las.name,
        "absolute": str(las),
        "symlink": "link.las",
        "hardlink": "hard.las",
        "dotdot": f"../{tmp_path.name}/{las.name}",
    }


MODES = {
    "tiled": ["--tile", "128"],
    "reference": ["--reference"],
    "single-tile": ["--single-tile", "--tile", "128"],
}


@pytest.mark.sanitize
@pytest.mark.parametrize("form", ["same", "dot-slash", "absolute", "symlink", "hardlink",
                                  "dotdot"])
@pytest.mark.parametrize("opt", ["-o", "--json", "--job"])
def test_no_output_may_be_an_input(gdt_bin, cloud, tmp_path, form, opt):
    las = copy_input(cloud, tmp_path / "in.las")
    before = las.read_bytes()
    arg = path_forms(tmp_path, las)[form]
    extra = [] if opt == "-o" else ["-o", "out.ply"]
    r = run([gdt_bin, las.name, *MODES["tiled"], opt, arg, *extra], cwd=tmp_path)
    refused(r, 2, "is the input", "never writes over an input")
    assert las.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["hard.las", "in.las", "link.las"]


@pytest.mark.parametrize("mode", ["reference", "single-tile", "info"])
@pytest.mark.parametrize("opt", ["-o", "--json"])
def test_no_output_may_be_an_input_in_any_mode(gdt_bin, cloud, tmp_path, mode, opt):
    if mode == "info" and opt == "-o":
        pytest.skip("--info writes no PLY")
    las = copy_input(cloud, tmp_path / "in.las")
    before = las.read_bytes()
    args = ["--info"] if mode == "info" else MODES[mode]
    r = run([gdt_bin, "in.las", *args, opt, "./in.las"], cwd=tmp_path)
    refused(r, 2, "is the input")
    assert las.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["in.las"]


def test_restart_with_the_job_naming_an_input(gdt_bin, cloud, tmp_path):
    """--restart removes the job's files: it must never get to an input."""
    las = copy_input(cloud, tmp_path / "in.las")
    before = las.read_bytes()
    r = run([gdt_bin, las, "--tile", "128", "--job", las, "--restart", "-o",
             tmp_path / "o.ply"])
    refused(r, 2, "is the input")
    assert las.read_bytes() == before


def test_an_input_inside_the_job_directory(gdt_bin, cloud, tmp_path):
    job = tmp_path / "job"
    job.mkdir()
    las = copy_input(cloud, job / "in.las")
    r = run([gdt_bin, las, "--tile", "128", "--job", job, "-o", tmp_path / "o.ply"])
    refused(r, 2, "holds the input")
    assert sorted(p.name for p in job.iterdir()) == ["in.las"]


# ------------------------------------------------ special files as outputs

def special_outputs(tmp_path):
    """name -> a path in tmp_path that exists and is not a regular file."""
    out = {}
    os.mkfifo(tmp_path / "fifo")
    out["fifo"] = tmp_path / "fifo"
    (tmp_path / "dir").mkdir()
    out["directory"] = tmp_path / "dir"
    (tmp_path / "target.ply").write_bytes(b"keep")
    (tmp_path / "link.ply").symlink_to("target.ply")
    out["symlink"] = tmp_path / "link.ply"
    try:  # a node like /dev/null, but our own: only where we may make one
        os.mknod(tmp_path / "null", stat.S_IFCHR | 0o666, os.makedev(1, 3))
        out["chardev"] = tmp_path / "null"
    except (PermissionError, OSError):
        pass
    return out


def kind(path):
    st = os.lstat(path)
    return stat.S_IFMT(st.st_mode), st.st_ino


@pytest.mark.sanitize
@pytest.mark.parametrize("mode", ["tiled", "reference", "single-tile"])
@pytest.mark.parametrize("opt", ["-o", "--json"])
def test_special_files_are_never_replaced(gdt_bin, cloud, tmp_path, mode, opt):
    outs = special_outputs(tmp_path)
    for name, path in outs.items():
        was = kind(path)
        extra = [] if opt == "-o" else ["-o", tmp_path / "o.ply"]
        r = run([gdt_bin, cloud, *MODES[mode], opt, path, *extra])
        refused(r, 2, str(path))
        assert ("symbolic link" if name == "symlink" else "renamed over") in r.stderr, \
            r.stderr
        assert kind(path) == was, f"{name} was replaced"
    assert (tmp_path / "target.ply").read_bytes() == b"keep"
    assert not (tmp_path / "o.ply").exists()


def test_job_directory_must_be_a_directory(gdt_bin, cloud, tmp_path):
    os.mkfifo(tmp_path / "fifo")
    (tmp_path / "file").write_bytes(b"x")
    for name in ["fifo", "file"]:
        r = run([gdt_bin, cloud, "--tile", "128", "--job", tmp_path / name, "-o",
                 tmp_path / "o.ply"])
        refused(r, 2, "not a directory")
    assert stat.S_ISFIFO(os.lstat(tmp_path / "fifo").st_mode)
    assert (tmp_path / "file").read_bytes() == b"x"


def test_resume_checks_the_recorded_paths(gdt_bin, cloud, tmp_path):
    """--resume takes its output from the job record: it is checked as -o is."""
    out, job = tmp_path / "o.ply", tmp_path / "job"
    r = run([gdt_bin, cloud, "--tile", "128", "-o", out, "--job", job, "--keep-job", "-q"],
            timeout=300)
    assert r.returncode == 0, r.stderr
    out.unlink()
    os.mkfifo(out)
    r = run([gdt_bin, "--resume", job, "-q"])
    refused(r, 2, str(out), "FIFO")
    assert stat.S_ISFIFO(os.lstat(out).st_mode)
    out.unlink()
    r = run([gdt_bin, "--resume", job, "--json", cloud, "-q"])
    refused(r, 2, "is the input")
    # -o would be ignored: the output is the recorded one
    r = run([gdt_bin, "--resume", job, "-o", tmp_path / "other.ply", "-q"])
    refused(r, 2, "no -o")
    assert not (tmp_path / "other.ply").exists()


# ------------------------------------------------ outputs checked at start-up

@pytest.mark.sanitize
@pytest.mark.parametrize("args", [["-o", ""], ["--json", ""], ["--job", ""],
                                  ["--json", "no/such/dir/x.json"],
                                  ["-o", "no/such/dir/x.ply"],
                                  ["--job", "no/such/dir/job"],
                                  ["-o", "x.ply", "--json", "x.ply"],
                                  ["-o", "x.ply", "--job", "x.ply"],
                                  ["-o", "newdir/"]],
                         ids=lambda a: " ".join(repr(x) for x in a))
def test_bad_outputs_are_refused_before_any_work(gdt_bin, cloud, tmp_path, args):
    t0 = time.monotonic()
    r = run([gdt_bin, cloud, "--tile", "128", *args], cwd=tmp_path)
    took = time.monotonic() - t0
    refused(r, 2)
    assert "pass 1" not in r.stderr, r.stderr
    assert list(tmp_path.iterdir()) == [], "the refused run left files behind"
    assert took < 10, f"refusal took {took:.1f} s"


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write anywhere")
def test_unwritable_output_directory(gdt_bin, cloud, tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        r = run([gdt_bin, cloud, "--tile", "128", "-o", ro / "x.ply"])
        refused(r, 2, "cannot create files in")
    finally:
        ro.chmod(0o755)


# ------------------------------------------------ special files as inputs

INPUT_MODES = {
    "tiled": ["--tile", "128"],
    "info": ["--info"],
    "reference": ["--reference"],
    "single-tile": ["--single-tile", "--tile", "128"],
}


@pytest.mark.sanitize
@pytest.mark.parametrize("mode", list(INPUT_MODES))
def test_fifo_and_directory_inputs_are_refused_at_once(gdt_bin, cloud, tmp_path, mode):
    os.mkfifo(tmp_path / "fifo.las")
    (tmp_path / "dir.las").mkdir()
    for name, why in [("fifo.las", "is a FIFO"), ("dir.las", "is a directory")]:
        # a FIFO that nobody writes: opening it for reading would block
        # forever, so a hang ends in TimeoutExpired and fails the test
        r = run([gdt_bin, tmp_path / name, *INPUT_MODES[mode], "-o", tmp_path / "o.ply"],
                timeout=20)
        refused(r, 3, name, why)
        # and also when it comes after a good input
        r = run([gdt_bin, cloud, tmp_path / name, *INPUT_MODES[mode], "-o",
                 tmp_path / "o.ply"], timeout=20)
        refused(r, 3, name, why)
    assert not (tmp_path / "o.ply").exists()
    assert not (tmp_path / "o.ply.gdt-job").exists()


@pytest.mark.parametrize("mode", ["tiled", "info"])
def test_stdin_on_a_pipe_is_refused(gdt_bin, cloud, tmp_path, mode):
    r = run([gdt_bin, "/dev/stdin", *INPUT_MODES[mode], "-o", tmp_path / "o.ply"],
            input="not read\n", timeout=20)
    refused(r, 3, "/dev/stdin", "FIFO", "regular file")


# ------------------------------------------------ --device syntax

@pytest.mark.parametrize("spec", ["a:b:c", "1:2:3", "x", "1:", ":1", "-1", "1.5", "cpu0",
                                  "0:x"])
def test_malformed_device_is_a_usage_error(gdt_bin, cloud, tmp_path, spec):
    r = run([gdt_bin, cloud, "--device", spec, "-o", tmp_path / "o.ply"])
    refused(r, 2, spec, "PLATFORM:DEVICE")
    assert list(tmp_path.iterdir()) == []


def test_missing_device_stays_a_device_error(gdt_bin, cloud, tmp_path):
    r = run([gdt_bin, cloud, "--tile", "128", "--device", "97:3", "-o", tmp_path / "o.ply"],
            timeout=300)
    refused(r, 5, "97:3")


# ------------------------------------------------ signals

def handlers_installed(pid):
    """True when pid catches SIGINT and SIGTERM (/proc/PID/status SigCgt);
    None when the process is gone."""
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("SigCgt:"):
                    mask = int(line.split()[1], 16)
                    return all(mask & (1 << (s - 1)) for s in (signal.SIGINT, signal.SIGTERM))
    except OSError:
        return None
    return False


def signal_after_start(cmd, sig, delay, env=None, limit=60, wait_handlers=True):
    """Starts cmd, waits until its handlers are installed (unless not
    wait_handlers: then delay counts from the spawn), sleeps delay seconds,
    sends sig; returns (CompletedProcess-like rc, stderr)."""
    p = subprocess.Popen([str(c) for c in cmd], stdout=subprocess.DEVNULL,
                         stderr=subprocess.PIPE, text=True, env=env)
    try:
        t0 = time.monotonic()
        while wait_handlers:
            state = handlers_installed(p.pid)
            if state:
                break
            if state is None or p.poll() is not None:
                p.wait()
                pytest.fail(f"exited ({p.returncode}) before SIGINT/SIGTERM handlers were "
                            f"seen: {p.stderr.read()}")
            if time.monotonic() - t0 > 20:
                pytest.fail("no SIGINT/SIGTERM handlers after 20 s")
            time.sleep(0.0002)
        if delay:
            time.sleep(delay)
        p.send_signal(sig)
        err = p.communicate(timeout=limit)[1]
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    return p.returncode, err


def assert_interrupted(rc, err, what):
    assert rc in (130, 0), f"{what}: exit {rc}, expected 130 (or 0 if done first)\n{err}"
    if rc == 130:
        lines = err.strip().splitlines()
        assert lines and "(interrupted)" in lines[-1], f"{what}: {err}"


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
@pytest.mark.parametrize("delay_ms", [0, 10, 30, 50])
@pytest.mark.parametrize("mode", ["tiled", "reference", "info"])
def test_signal_at_start_up(gdt_bin, big_cloud, tmp_path, sig, delay_ms, mode):
    """From the moment the handlers are seen installed, a signal stops every
    mode with 130 and 'interrupted', never the default action."""
    args = {"tiled": ["--tile", "1024"], "reference": ["--reference"],
            "info": ["--info"]}[mode]
    rc, err = signal_after_start([gdt_bin, big_cloud, *args, "-o", tmp_path / "o.ply"], sig,
                                 delay_ms / 1000.0)
    assert_interrupted(rc, err, f"{mode} + {sig.name} at +{delay_ms} ms")
    if rc == 130:
        assert not (tmp_path / "o.ply").exists()


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
@pytest.mark.parametrize("delay_ms", [10, 30, 50])
@pytest.mark.parametrize("mode", ["tiled", "reference"])
def test_signal_while_the_libraries_load(gdt_bin, big_cloud, tmp_path, sig, delay_ms, mode):
    """Counted from the spawn: the launcher links only the C library and
    installs its handlers before it loads the program's module, so even a
    signal while OpenVDB, TBB and the rest are loaded and relocated (tens of
    milliseconds) stops the run with 130, never the default action (-2, -15)."""
    args = {"tiled": ["--tile", "1024"], "reference": ["--reference"]}[mode]
    rc, err = signal_after_start([gdt_bin, big_cloud, *args, "-o", tmp_path / "o.ply"], sig,
                                 delay_ms / 1000.0, wait_handlers=False)
    assert_interrupted(rc, err, f"{mode} + {sig.name} at +{delay_ms} ms from the spawn")


def test_launcher_without_its_module(gdt_bin, tmp_path):
    """The launcher copied away from its module says what it looked for."""
    exe = tmp_path / "gdt-tile"
    shutil.copy(gdt_bin, exe)
    r = run([exe, "--version"])
    assert r.returncode == 7, r
    assert "GDT-7003" in r.stderr and str(tmp_path / "libgdt-tile.so") in r.stderr, r.stderr


@pytest.mark.sanitize
def test_signal_during_single_tile_is_not_ignored(gdt_bin, big_cloud, tmp_path):
    rc, err = signal_after_start([gdt_bin, big_cloud, "--single-tile", "--tile", "1024",
                                  "-o", tmp_path / "o.ply"], signal.SIGINT, 0.1)
    assert rc == 130, f"exit {rc}\n{err}"
    assert "(interrupted)" in err and not (tmp_path / "o.ply").exists()


@pytest.mark.slow
@pytest.mark.parametrize("mode,delay", [("tiled", 0.2), ("tiled", 0.8), ("single-tile", 0.4)])
def test_signal_during_the_kernel_build(gdt_bin, root, cloud, tmp_path, mode, delay):
    """A cold kernel cache: the OpenCL compiler runs for seconds after pass 1
    (it removes its files on SIGINT, failing the build); the run must report
    the interruption, not the build failure it caused, and stop after the
    program being built, not build the others first (seconds each)."""
    env = dict(os.environ, XDG_CACHE_HOME=str(tmp_path / "cache"))
    env.pop("POCL_CACHE_DIR", None)
    args = ["--tile", "128"] if mode == "tiled" else ["--single-tile", "--tile", "128"]
    rc, err = signal_after_start([gdt_bin, cloud, *args, "-o", tmp_path / "o.ply", "-q"],
                                 signal.SIGINT, delay, env=env, limit=300)
    assert rc == 130, f"exit {rc}\n{err}"
    assert "(interrupted)" in err and "clBuildProgram" not in err, err
    assert not (tmp_path / "o.ply").exists()
    # the core builds every kernel file once (one program each)
    built = list((tmp_path / "cache" / "gdt-tile" / "pocl" / "programs").glob("*.bin"))
    assert len(built) < len(list((root / "kernels").glob("*.cl"))), built


if __name__ == "__main__":
    sys.exit(pytest.main([__file__, "-v"]))
