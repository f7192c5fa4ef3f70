"""scripts/differential.py: agreeing seeds pass, a run whose DEM differs is
reported with the commands that repeat it, and the script exits 1."""
import os
import pathlib
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "scripts" / "differential.py"


def run(args, tmp_path):
    return subprocess.run([sys.executable, str(SCRIPT), "--workdir", str(tmp_path / "w"),
                           "--mpi-every", "0", *args], capture_output=True, text=True,
                          timeout=900)


def test_agreeing_seeds(gdt_bin, tmp_path):
    r = run(["--build-dir", str(gdt_bin.parent.parent), "--seeds", "259:261"], tmp_path)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "2 of 2 seeds agreed" in r.stdout
    assert r.stdout.count(": agree (4 runs)") == 2, r.stdout
    # files of agreeing seeds are removed
    assert not list((tmp_path / "w").glob("seed-*"))


def test_a_differing_dem_is_reported(gdt_bin, tmp_path):
    """A gdt-tile that changes one byte of its DEM at --tile 256."""
    fake = tmp_path / "fake" / "tiler"
    fake.mkdir(parents=True)
    exe = fake / "gdt-tile"
    exe.write_text(f"""#!/bin/sh
"{gdt_bin}" "$@"
rc=$?
case " $* " in *" --tile 256 "*)
  for a in "$@"; do
    case "$a" in *.tif) printf 'x' | dd of="$a" bs=1 seek=4000 conv=notrunc 2>/dev/null ;; esac
  done ;;
esac
exit $rc
""")
    os.chmod(exe, 0o755)
    r = run(["--build-dir", str(tmp_path / "fake"), "--seeds", "260:261"], tmp_path)
    assert r.returncode == 1, r.stdout + r.stderr
    assert "seed 260" in r.stdout and "DIFFERENT" in r.stdout, r.stdout
    assert "t256: the DEM differs from the reference's" in r.stdout, r.stdout
    assert "0 of 1 seeds agreed" in r.stdout
    # the failing seed keeps its files and prints how to repeat every run
    assert (tmp_path / "w" / "seed-260" / "t256.tif").exists()
    assert f"ref: {exe} " in r.stdout
