"""scripts/bench_dem.py at a tiny size: it runs to the end (exit 0 or 1: the timing
targets are not the point here), prints its tables and writes every figure."""
import json
import os
import pathlib
import shutil
import subprocess
import sys

import pytest

from conftest import build_dir

ROOT = pathlib.Path(__file__).resolve().parents[2]


@pytest.mark.skipif(shutil.which("gdal_grid") is None,
                    reason="GDAL's tools (Debian gdal-bin) are not installed")
def test_bench_dem_runs_at_a_tiny_size(gdt_bin, tmp_path):
    js = tmp_path / "b.json"
    cmd = [sys.executable, ROOT / "scripts" / "bench_dem.py", "--build-dir", build_dir(),
           "--points", "50k", "--subset", "20k", "--repeat", "2", "--threads", "2",
           "--tile", "256", "--tmpdir", tmp_path, "--json", js]
    r = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, timeout=600,
                       env=dict(os.environ))
    assert r.returncode in (0, 1), r.stderr
    out = r.stdout
    for word in ("no DEM", "DEM 1 m", "DEM 0.35 m", "gdal_grid linear", "gdt-tile --dem"):
        assert word in out, out
    assert out.count("PASS") + out.count("MISS") == 4, out
    d = json.loads(js.read_text())
    assert set(d) >= {"config", "cloud", "runs", "targets", "subset", "pass"}
    assert [x["dem_res"] for x in d["runs"]] == [None, 1.0, 0.35]
    for x in d["runs"]:
        assert x["wall_s"] > 0 and x["peak_rss_bytes"] > 0
    for x in d["runs"][1:]:
        assert {"time_ratio", "rss_ratio", "time_pass", "rss_pass"} <= set(x)
        # each round against the no-DEM run of the same round, not the best of them
        base = d["runs"][0]["walls_s"]
        assert len(base) == 2 and len(x["walls_s"]) == 2
        assert x["round_ratios"] == [w / b for w, b in zip(x["walls_s"], base)]
        assert x["median_round_ratio"] == sum(x["round_ratios"]) / 2
    assert out.count("median") == 2, out
    # the second round starts with the second configuration
    order = [ln.split(" run ")[0].strip() for ln in r.stderr.splitlines()
             if " run " in ln and "/2:" in ln and not ln.strip().startswith("subset")]
    assert order == ["no DEM", "DEM 1 m", "DEM 0.35 m", "DEM 1 m", "DEM 0.35 m", "no DEM"], order
    # each configuration ran once untimed before the rounds
    warm = [ln.split(" warm-up run ")[0].strip() for ln in r.stderr.splitlines()
            if "warm-up run (not counted)" in ln]
    assert warm == ["no DEM", "DEM 1 m", "DEM 0.35 m", "subset gdt-tile", "subset gdal_grid"], \
        r.stderr
    first_timed = next(i for i, ln in enumerate(r.stderr.splitlines()) if "run 1/2:" in ln)
    assert all(i < first_timed for i, ln in enumerate(r.stderr.splitlines())
               if "warm-up run" in ln and not ln.strip().startswith("subset")), r.stderr
    assert len(d["targets"]) == 4 and d["pass"] == all(t["pass"] for t in d["targets"])
    assert (r.returncode == 0) == d["pass"]
    s = d["subset"]
    assert s["points"] == 20000 and s["gdt"]["wall_s"] > 0 and s["gdal_grid"]["wall_s"] > 0
    assert s["cells_both"] > 0.9 * s["cells_ours"] > 1000
    assert s["agree_fraction"] > 0.9  # co-circular points of the grid patches aside
    assert list(tmp_path.iterdir()) == [js]  # the temporary folder is gone
