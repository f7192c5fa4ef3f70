"""scripts/gpu_check.sh, the one command for a GPU machine, run here on the
OpenCL CPU device (--cpu): the bundle it carries (the core driver and
gdt-tile with their libraries, the C library too, the kernels) works from
its own folder, with this machine's C library or its own, prints the table,
and a failing check fails it; without an NVIDIA driver it says so in one
line (exit 3)."""
import os
import pathlib
import shutil
import subprocess

import pytest


def has_nvidia_opencl():
    r = subprocess.run(["ldconfig", "-p"], capture_output=True, text=True)
    return "libnvidia-opencl.so.1" in r.stdout


@pytest.fixture(scope="module")
def bundle(root, tmp_path_factory, tools_dir):
    if not (tools_dir / "gcd_run").exists():
        pytest.fail("gcd_run not built (set GDT_BUILD_DIR)")
    d = tmp_path_factory.mktemp("gpu-bundle") / "b"
    r = subprocess.run([root / "scripts" / "gpu_check.sh", "--make-bundle", d, "--build-dir",
                        tools_dir.parent], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    # the bundle stands alone: moved away from the source tree, it still runs
    moved = d.parent / "moved"
    shutil.move(str(d), str(moved))
    return moved


def run(bundle, *args, timeout=600):
    env = {k: v for k, v in os.environ.items() if k != "GDT_KERNEL_DIR"}
    return subprocess.run([bundle / "gpu_check.sh", *args], capture_output=True, text=True,
                          env=env, timeout=timeout)


@pytest.mark.parametrize("libc", [[], ["--own-libc"]])
def test_cpu_run_prints_the_table(bundle, libc):
    r = run(bundle, "--cpu", "--sizes", "8K", "--perf-sizes", "20K 30K", "--e2e-sizes", "40K",
            *libc)
    if r.returncode == 77 or "no OpenCL" in r.stdout + r.stderr:
        pytest.skip("no OpenCL CPU device")
    assert r.returncode == 0, r.stdout + r.stderr
    lines = r.stdout.splitlines()
    assert lines[0].startswith("gpu_check: ") and "glibc" in lines[0], lines[0]
    assert ("the bundle's glibc" in lines[0]) == bool(libc), lines[0]
    rows = [ln.split() for ln in lines if ln.split()[:1] in (["uniform"], ["lidar"], ["grid"])]
    assert [(k, n, res) for k, n, res, *_ in rows] == [
        ("uniform", "8000", "equal"), ("lidar", "8000", "equal"), ("grid", "8000", "equal")]
    perf = [ln.split() for ln in lines if ln.split()[:1] in (["20000"], ["30000"])]
    # with the static CGAL harness in the bundle: its seconds and the ratio
    cgal = (bundle / "cgal_bench").exists()
    assert len(perf) == 2 and all(len(p) == (13 if cgal else 11) for p in perf), r.stdout
    assert lines[-1].startswith("gpu_check: ") and lines[-1].endswith(" s"), lines[-1]
    # end to end: gdt-tile from the bundle with one and two queues, the
    # tile side its choice for a CPU device, the busy share a percentage
    e2e = [ln.split() for ln in lines if ln.split()[:1] == ["40000"]]
    assert [(p[0], p[1], p[2]) for p in e2e] == [("40000", "4096", "1"), ("40000", "4096", "2")], \
        r.stdout
    for p in e2e:
        wall, tiles, core, busy = (float(v) for v in p[3:7])
        assert 0 < tiles < wall and 0 < core and 0 < busy <= 100, p
    for p in perf:
        if cgal:
            assert float(p[11]) > 0 and float(p[12]) > 0, p
            # x = CGAL / core from the unrounded seconds, printed to 0.1; the
            # two seconds are printed to 1 ms: x lies within what they allow
            c, t, x = float(p[11]), float(p[9]), float(p[12])
            lo = (c - 0.0005) / (t + 0.0005)
            hi = (c + 0.0005) / (t - 0.0005) if t > 0.0005 else float("inf")
            assert lo - 0.0501 <= x <= hi + 0.0501, p
        phases = [float(v) for v in p[2:9]]
        # Each of the seven phases and the total is printed rounded to 1 ms, so the
        # printed phases may exceed the printed total by up to 8 half-milliseconds.
        assert float(p[9]) > 0 and sum(phases) <= float(p[9]) * 1.01 + 8 * 5e-4, p


def test_the_cgal_harness_is_static(bundle, tools_dir):
    """The bundle's CGAL program loads no library: it runs where CGAL, GMP and
    MPFR are not installed, whatever the C library."""
    if not (tools_dir / "cgal_bench").exists():
        pytest.skip("CGAL is not installed here")
    exe = bundle / "cgal_bench"
    assert exe.exists(), "CGAL is installed but the bundle has no static harness"
    r = subprocess.run(["ldd", exe], capture_output=True, text=True)
    assert "not a dynamic executable" in r.stdout + r.stderr, r.stdout
    with open(exe, "rb") as f:
        head = f.read(4096)
    assert b"ld-linux" not in head  # no program interpreter (.interp)


def test_a_failing_run_fails_the_check(bundle):
    r = run(bundle, "--cpu", "--sizes", "8K", "--perf-sizes", "20K", "--timeout", "0.01")
    assert r.returncode == 1, r.stdout + r.stderr
    assert "FAILED" in r.stdout


def test_without_an_nvidia_driver_it_says_so(bundle):
    if has_nvidia_opencl():
        pytest.skip("this machine has an NVIDIA OpenCL driver")
    r = run(bundle)
    assert r.returncode == 3
    assert r.stdout.strip().splitlines() == [
        "gpu_check: no NVIDIA OpenCL driver (libnvidia-opencl.so.1) on this machine; "
        "nothing run"]


def test_outside_a_bundle_it_refuses(root):
    r = subprocess.run([root / "scripts" / "gpu_check.sh", "--cpu"], capture_output=True,
                       text=True)
    assert r.returncode == 2 and "run from a bundle" in r.stderr
