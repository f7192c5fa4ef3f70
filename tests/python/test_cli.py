"""Command-line contract: strict parsing, help, version, exit codes."""
import json
import re

import pytest

BAD_VALUES = [
    ["--tile", "12abc"],
    ["--tile", "4095"],          # not a power of two
    ["--tile", "32"],            # below range
    ["--tile", "32768"],         # above range
    ["--tile", ""],
    ["--tile", "+64"],
    ["--tile=1e3"],
    ["--cell", "0"],
    ["--cell", "-1"],
    ["--cell", "nan"],
    ["--cell", "1.5x"],
    ["--halo", "-1"],
    ["--halo", "3.5"],
    ["--threads", "0"],
    ["--threads", "two"],
    ["--mem-budget", "12Q"],
    ["--mem-budget", "100"],     # below 16M
    ["--mem-budget", "8M"],
    ["--mem-budget", "-4G"],
    ["--quantum", "0"],
    ["--quantum", "inf"],
    ["--dup", "last"],
    ["--device", ""],
    ["--no-such-option"],
    ["--check=yes"],
]


@pytest.mark.parametrize("args", BAD_VALUES, ids=lambda a: " ".join(a) or "empty")
def test_bad_values_are_usage_errors(gdt_bin, runner, tmp_path, args):
    cloud = tmp_path / "c.las"
    cloud.write_bytes(b"")
    r = runner([gdt_bin, cloud, *args])
    assert r.returncode == 2, r.stderr
    assert "gdt-tile: error GDT-2" in r.stderr


def test_missing_value(gdt_bin, runner):
    r = runner([gdt_bin, "x.las", "--tile"])
    assert r.returncode == 2
    assert "--tile needs a value" in r.stderr


def test_no_input(gdt_bin, runner):
    r = runner([gdt_bin])
    assert r.returncode == 2
    assert "no input" in r.stderr


def test_conflicting_modes(gdt_bin, runner):
    r = runner([gdt_bin, "x.las", "--info", "--reference"])
    assert r.returncode == 2
    assert "cannot be combined" in r.stderr


def test_help_lists_every_option_and_exit_code(gdt_bin, runner):
    r = runner([gdt_bin, "--help"])
    assert r.returncode == 0
    for opt in ["-o", "--tile", "--cell", "--halo", "--job", "--restart", "--resume",
                "--device", "--threads", "--mem-budget", "--quantum", "--dup", "--check",
                "--json", "-q", "-v", "--info", "--reference", "--version"]:
        assert re.search(r"(^|[ ,])" + re.escape(opt) + r"\b", r.stdout), opt
    for code in ["0", "2", "3", "4", "5", "6", "7", "130"]:
        assert re.search(r"^\s+" + code + r"\s+\S", r.stdout, re.M), code


def test_version(gdt_bin, runner):
    r = runner([gdt_bin, "--version"])
    assert r.returncode == 0
    assert re.match(r"gdt-tile \d+\.\d+\.\d+\n", r.stdout)


def test_resume_without_a_job_says_so(gdt_bin, runner, tmp_path):
    r = runner([gdt_bin, "--resume", tmp_path / "nojob"], cwd=tmp_path)
    assert r.returncode == 6, r.stderr
    assert "GDT-6902" in r.stderr and "no job" in r.stderr
    r = runner([gdt_bin, "--resume", tmp_path / "nojob", "--restart"], cwd=tmp_path)
    assert r.returncode == 2, r.stderr


@pytest.mark.sanitize
def test_missing_input_is_bad_input(gdt_bin, runner, tmp_path):
    r = runner([gdt_bin, tmp_path / "nope.las", "--info"])
    assert r.returncode == 3
    assert "nope.las" in r.stderr


@pytest.mark.sanitize
def test_unknown_format_is_bad_input(gdt_bin, runner, tmp_path):
    f = tmp_path / "cloud.xyz"
    f.write_text("1 2 3\n4 5 6\n")
    r = runner([gdt_bin, f, "--info"])
    assert r.returncode == 3
    assert "cloud.xyz" in r.stderr and "unknown format" in r.stderr


@pytest.mark.sanitize
def test_empty_file_is_bad_input(gdt_bin, runner, tmp_path):
    f = tmp_path / "empty.las"
    f.write_bytes(b"")
    r = runner([gdt_bin, f, "--info"])
    assert r.returncode == 3
    assert "empty" in r.stderr


def test_info_on_real_las(gdt_bin, runner, data_dir, tmp_path):
    import laspy
    path = data_dir / "autzen_trim.las"
    js = tmp_path / "info.json"
    r = runner([gdt_bin, path, "--info", "--json", js])
    assert r.returncode == 0, r.stderr
    las = laspy.read(path)
    assert f"points       : {len(las.points)}" in r.stdout
    assert "LAS 1.2, point format 3" in r.stdout
    info = json.loads(js.read_text())
    assert info["points"] == len(las.points)
    xy = set(zip(las.X.tolist(), las.Y.tolist()))
    assert info["distinct_xy"] == len(xy)
    assert info["duplicates"] == len(las.points) - len(xy)
    assert info["lattice"] == [las.header.scales[0], las.header.scales[1],
                               las.header.offsets[0], las.header.offsets[1]]
    assert info["lattice_box"] == [int(las.X.min()), int(las.Y.min()),
                                   int(las.X.max()), int(las.Y.max())]


def test_info_several_inputs_are_one_cloud(gdt_bin, runner, data_dir, tmp_path):
    path = data_dir / "autzen_trim.las"
    js = tmp_path / "info.json"
    r = runner([gdt_bin, path, path, "--info", "--json", js])
    assert r.returncode == 0, r.stderr
    info = json.loads(js.read_text())
    one = json.loads(runner([gdt_bin, path, "--info", "--json", tmp_path / "one.json"]) and
                     (tmp_path / "one.json").read_text())
    assert info["points"] == 2 * one["points"]
    assert info["distinct_xy"] == one["distinct_xy"]
    assert info["duplicates"] == info["points"] - one["distinct_xy"]


def test_info_tile_plan(gdt_bin, runner, data_dir, tmp_path):
    path = data_dir / "autzen_trim.las"
    js = tmp_path / "info.json"
    r = runner([gdt_bin, path, "--info", "--tile", "64", "--json", js])
    assert r.returncode == 0, r.stderr
    assert "tile plan" in r.stdout
    plan = json.loads(js.read_text())["tile_plan"]
    assert plan["tile"] == 64 and plan["cell_auto"]
    assert plan["tiles"] + plan["empty_tiles"] == plan["tiles_x"] * plan["tiles_y"]
    assert plan["min_points"] <= plan["median_points"] <= plan["max_points"]
    # auto cell: about N*N/4 = 1024 points per tile on average over non-empty tiles
    mean = 110000 / plan["tiles"]
    assert 200 <= mean <= 5000, mean
    r2 = runner([gdt_bin, path, "--info", "--tile", "64", "--cell", "1", "--halo", "0",
                 "--json", js])
    assert r2.returncode == 0, r2.stderr
    plan2 = json.loads(js.read_text())["tile_plan"]
    assert not plan2["cell_auto"] and plan2["halo_texels"] == 0


def test_single_tile_beyond_one_tile_says_so(gdt_bin, runner, data_dir, tmp_path):
    # 110000 points do not fit one 64 x 64 tile: --single-tile refuses, the
    # tiled pipeline takes it.
    out = tmp_path / "out.ply"
    r = runner([gdt_bin, data_dir / "autzen_trim.las", "--tile", "64", "--single-tile", "-o", out])
    assert r.returncode == 2, r.stderr
    assert "GDT-2102" in r.stderr and "110000 points" in r.stderr
    assert not out.exists()


@pytest.mark.parametrize("args", [
    ["--info", "--job", "j"],
    ["--reference", "--keep-job"],
    ["--single-tile", "--job", "j"],
    ["--info", "--single-tile"],
])
def test_job_options_only_for_tiled_runs(gdt_bin, runner, data_dir, tmp_path, args):
    r = runner([gdt_bin, data_dir / "100-points.las", "-o", tmp_path / "o.ply", *args],
               cwd=tmp_path)
    assert r.returncode == 2, r.stderr
    assert not (tmp_path / "o.ply").exists()


def test_device_only_for_runs(gdt_bin, runner, data_dir):
    r = runner([gdt_bin, data_dir / "100-points.las", "--info", "--device", "cpu"])
    assert r.returncode == 2
    assert "--device" in r.stderr


def test_missing_device_is_exit_5(gdt_bin, runner, data_dir, tmp_path):
    out = tmp_path / "out.ply"
    r = runner([gdt_bin, data_dir / "100-points.las", "--tile", "64", "--device", "7:7",
                "-o", out])
    assert r.returncode == 5, r.stderr
    assert "CL_" in r.stderr
    assert not out.exists()


def test_one_tile_run_equals_reference(gdt_bin, runner, data_dir, tmp_path):
    core, ref = tmp_path / "core.ply", tmp_path / "ref.ply"
    src = data_dir / "autzen_trim.las"
    r = runner([gdt_bin, src, "--tile", "1024", "--single-tile", "-q", "-o", core])
    assert r.returncode == 0, r.stderr
    assert runner([gdt_bin, src, "--reference", "-q", "-o", ref]).returncode == 0
    # unique triangulation, same vertex and face order rules: the same bytes
    assert core.read_bytes() == ref.read_bytes()
