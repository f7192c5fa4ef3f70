"""gdt-tile --resume DIR writes the DEM (and preview) its job's command asked
for, with the same bytes, and refuses a --dem of its own."""

from tiled_util import gen_cloud, run


def test_resume_writes_the_recorded_dem(gdt_bin, tmp_path):
    las = gen_cloud(tmp_path / "c.las", 20_000, 4)
    out, tif, png, job = (tmp_path / n for n in ("o.ply", "d.tif", "p.png", "job"))
    cmd = [gdt_bin, las, "-q", "-o", out, "--tile", 128, "--dem", tif, "--dem-res", "0.5",
           "--dem-nodata", "-32768", "--preview", png, "--concavity", "2", "--job", job,
           "--keep-job"]
    r = run(cmd)
    assert r.returncode == 0, r.stderr
    want = (out.read_bytes(), tif.read_bytes(), png.read_bytes())
    for p in (out, tif, png):
        p.unlink()
    r = run([gdt_bin, "--resume", job, "-q"])
    assert r.returncode == 0, r.stderr
    assert (out.read_bytes(), tif.read_bytes(), png.read_bytes()) == want
    r = run([gdt_bin, "--resume", job, "-q", "--dem", tmp_path / "x.tif"])
    assert r.returncode == 2 and "GDT-2606" in r.stderr, r.stderr
    assert not (tmp_path / "x.tif").exists()
    # a run of the same job without --dem records that: its resume writes no DEM
    r = run([gdt_bin, las, "-q", "-o", out, "--tile", 128, "--concavity", "2", "--job", job,
             "--keep-job"])
    assert r.returncode == 0, r.stderr
    tif.unlink()
    r = run([gdt_bin, "--resume", job, "-q"])
    assert r.returncode == 0, r.stderr
    assert not tif.exists()


def test_dem_bytes_do_not_depend_on_the_cpus(gdt_bin, tmp_path):
    """The COG step compresses blocks on all CPUs: one CPU gives the same bytes."""
    import os
    import subprocess
    las = gen_cloud(tmp_path / "c.las", 30_000, 6)
    outs = []
    for name, cpus in (("all", None), ("one", {0})):
        tif = tmp_path / f"{name}.tif"
        cmd = [str(c) for c in (gdt_bin, las, "-q", "-o", tmp_path / f"{name}.ply",
                                "--reference", "--dem", tif, "--dem-res", "0.05")]
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=300,
                           preexec_fn=(lambda: os.sched_setaffinity(0, cpus)) if cpus else None)
        assert r.returncode == 0, r.stderr
        outs.append(tif.read_bytes())
    assert outs[0] == outs[1]
