"""No thread but the main one adds a variable to the process environment or
removes one.

glibc's getenv reads the environment without a lock, and adding a variable
reallocates the array it reads: done while another thread runs getenv, it
crashes that thread.  The OpenCL core starts on a thread of its own beside
pass 1, whose libraries call getenv (blosc, inside the tile index's write);
PoCL once added HWLOC_PLUGINS_PATH from there, a crash in about one run of
fifty on a small cloud with --tile given.  The LD_PRELOAD shim
tests/tools/env_guard.c logs every such change made off the main thread; each
mode of the program runs under it here and the log must hold nothing but the
shim's own "loaded" lines (which show that it was in effect)."""
import subprocess

import pytest

import mpi_util as mu
import resume_util as ru
import tiled_util as tu


@pytest.fixture(scope="module")
def shim(tool):
    return tool("libgdt_env_guard.so")


@pytest.fixture(scope="module")
def clouds(tmp_path_factory):
    d = tmp_path_factory.mktemp("env")
    las = tu.gen_cloud(d / "c.las", 20000, 261, "dem")
    laz = tu.gen_cloud(d / "c14.las", 20000, 5, "lidar", "--las-version", "1.4",
                       "--point-format", "6")
    return {"las": las, "las14": laz}


def guarded(shim, log, cmd, mpi=False, timeout=300):
    """Runs cmd with the shim preloaded (under mpirun: in every rank only)."""
    env = mu.clean_env()
    log.unlink(missing_ok=True)
    if mpi:
        env.update(mu.ROOT_OK)
        env["POCL_MAX_PTHREAD_COUNT"] = "1"
        cmd = ["mpirun", "--oversubscribe", "-np", "2", "-x", f"LD_PRELOAD={shim}", "-x",
               f"GDT_TEST_ENV_LOG={log}", *cmd]
    else:
        env["LD_PRELOAD"] = str(shim)
        env["GDT_TEST_ENV_LOG"] = str(log)
    return subprocess.run([str(c) for c in cmd], capture_output=True, text=True, env=env,
                          timeout=timeout)


def assert_clean(r, log, what, ranks=1):
    assert r.returncode == 0, f"{what}: rc={r.returncode}\n{r.stderr}"
    lines = log.read_text().splitlines() if log.exists() else []
    # more "loaded" lines come from child processes (PoCL runs its linker
    # when it builds kernels that are not in its cache)
    assert lines.count("loaded") >= ranks, f"{what}: the shim was not in effect: {lines}"
    changes = [x for x in lines if x != "loaded"]
    assert not changes, f"{what}: the environment changed off the main thread:\n" + \
        "\n".join(changes)


def test_no_thread_changes_the_environment(gdt_bin, shim, clouds, tmp_path):
    las, las14 = clouds["las"], clouds["las14"]
    log = tmp_path / "env.log"
    cases = {
        # --tile given: the core's thread is the first to list the devices
        "tiled --tile 64, DEM": [las, "--tile", "64", "--dem", tmp_path / "a.tif",
                                 "--dem-res", "0.07", "--preview", tmp_path / "a.png"],
        "tiled, tile chosen for the device": [las],
        "tiled, two queues on one device, trimmed": [las, "--tile", "64", "--device", "0,0",
                                                     "--max-edge", "2"],
        "tiled LAS 1.4, OBJ": [las14, "--tile", "128", "-o", tmp_path / "o.obj"],
        "tiled, ground filter, LandXML": [las, "--tile", "64", "--ground", "pmf", "-o",
                                          tmp_path / "o.xml"],
        "single tile, DEM": [las, "--single-tile", "--dem", tmp_path / "s.tif"],
        "reference, DEM": [las, "--reference", "--dem", tmp_path / "r.tif"],
    }
    for what, args in cases.items():
        out = [] if "-o" in args else ["-o", tmp_path / "out.ply"]
        r = guarded(shim, log, [gdt_bin, *args, *out, "-q"])
        assert_clean(r, log, what)
        for p in tmp_path.glob("*.ply"):
            p.unlink()


def test_no_thread_changes_the_environment_on_resume(gdt_bin, shim, clouds, tmp_path):
    """A job killed in its tile stage, resumed under the shim."""
    log = tmp_path / "env.log"
    out = tmp_path / "k.ply"
    p = ru.Run([gdt_bin, clouds["las"], "--tile", "64", "-o", out, "--dem", tmp_path / "k.tif"])
    p.stop_in("tiles", 0.0)
    p.finish()
    assert p.killed, f"the first run was not stopped in its tile stage:\n{p.stderr}"
    r = guarded(shim, log, [gdt_bin, "--resume", tmp_path / "k.ply.gdt-job", "-q"])
    assert_clean(r, log, "--resume")
    assert out.exists()


def test_no_thread_changes_the_environment_under_mpirun(gdt_bin, shim, clouds, tmp_path):
    why = mu.why_no_mpi(gdt_bin)
    if why is not None:
        pytest.skip(why)
    log = tmp_path / "env.log"
    for what, args in {"K = 2, --tile 64, DEM": ["--tile", "64", "--dem", tmp_path / "m.tif"],
                       "K = 2, tile chosen for the device": []}.items():
        r = guarded(shim, log, [gdt_bin, clouds["las"], "-o", tmp_path / "m.ply", "-q", *args],
                    mpi=True)
        assert_clean(r, log, what, ranks=2)
        (tmp_path / "m.ply").unlink()
