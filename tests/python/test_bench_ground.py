"""scripts/bench_ground.py at a tiny size: it runs to the end, prints its
table and writes figures that add up."""
import json
import pathlib
import subprocess
import sys

from conftest import build_dir

ROOT = pathlib.Path(__file__).resolve().parents[2]


def test_bench_ground_runs_at_a_tiny_size(gdt_bin, tmp_path):
    js = tmp_path / "b.json"
    cmd = [sys.executable, ROOT / "scripts" / "bench_ground.py", "--build-dir", build_dir(),
           "--points", "60k", "--repeat", "1", "--threads", "2", "--tile", "256",
           "--workdir", tmp_path, "--json", js, "--", "--pmf-cell", "1.5"]
    r = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    for word in ("plain", "--ground pmf", "ns/point", "ns/vertex", "with/without"):
        assert word in r.stdout, r.stdout
    d = json.loads(js.read_text())
    assert d["extra"] == ["--pmf-cell", "1.5"]
    assert 0 < d["ground_points"] < d["distinct_points"] <= 60_000
    assert d["filter_s"] > 0 and d["filter_ns_per_point"] > 0
    assert d["wall_ratio"] == d["ground"]["wall_s"] / d["plain"]["wall_s"]
