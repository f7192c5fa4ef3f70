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
