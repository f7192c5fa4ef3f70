"""Plug-ins: PCL (the ground filter) and GDAL (the DEM writer) live in
modules beside the program's module, loaded only by the runs that use them,
so that every other run starts without loading either.  A copy of the
program without a plug-in still triangulates; a run that needs the missing
plug-in is a clear internal error (exit 7, GDT-7004 naming the module) that
writes no output and keeps its job, and with the plug-in back in place the
rerun finishes it, to the bytes of an undisturbed run."""
import pathlib
import shutil

import pytest

from tiled_util import gen_cloud, run

CASES = {
    "pcl": ("libgdt-tile-pcl.so", ["--ground", "pmf"], []),
    "gdal": ("libgdt-tile-gdal.so", ["--dem", "{out}.tif", "--dem-res", "1"], [".tif"]),
}


@pytest.fixture(scope="module")
def cloud(tmp_path_factory):
    return gen_cloud(tmp_path_factory.mktemp("plugins") / "c.las", 60_000, 11)


@pytest.mark.parametrize("name", sorted(CASES))
def test_a_missing_plugin_fails_only_the_runs_that_need_it(gdt_bin, cloud, tmp_path, name):
    module, opts, extra = CASES[name]
    build = pathlib.Path(gdt_bin).parent
    assert (build / module).exists()
    prog = tmp_path / "prog"
    prog.mkdir()
    for f in ("gdt-tile", "libgdt-tile.so"):
        shutil.copy2(build / f, prog / f)

    def args(out):
        return [cloud, "--tile", "256", "-q", "-o", f"{out}.ply",
                *(a.replace("{out}", str(out)) for a in opts)]

    plain = run([prog / "gdt-tile", cloud, "--tile", "256", "-q", "-o", tmp_path / "plain.ply"])
    assert plain.returncode == 0, plain.stderr

    out = tmp_path / "out"
    r = run([prog / "gdt-tile", *args(out)])
    assert r.returncode == 7, r.stderr
    assert "GDT-7004" in r.stderr and module in r.stderr, r.stderr
    assert r.stderr.count("GDT-") == 1, r.stderr
    assert not pathlib.Path(f"{out}.ply").exists()
    assert not (tmp_path / "out.tif").exists()
    assert (tmp_path / "out.ply.gdt-job").is_dir()

    shutil.copy2(build / module, prog / module)
    r = run([prog / "gdt-tile", *args(out)])
    assert r.returncode == 0, r.stderr
    ref = tmp_path / "ref"
    r = run([gdt_bin, *args(ref)])
    assert r.returncode == 0, r.stderr
    assert pathlib.Path(f"{out}.ply").read_bytes() == pathlib.Path(f"{ref}.ply").read_bytes()
    for e in extra:
        assert pathlib.Path(f"{out}{e}").read_bytes() == pathlib.Path(f"{ref}{e}").read_bytes()
