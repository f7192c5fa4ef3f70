#!/usr/bin/env python3
"""make_corpus.py — writes the seed corpora of the fuzz targets.

  make_corpus.py BUILD OUT [--data DIR]

BUILD is a build folder (its gdt-tile and pcd_write_pcl are used), OUT the
folder that receives one subfolder per target (las, pcd, plycheck, job, tri, laz,
lazfile),
emptied first.  Seeds, each small enough for the targets' -max_len:
  las       the real samples of DIR (default ../shared/data) up to 16 KiB
            whole, larger ones cut to their first 16 KiB (header, VLRs and
            the first records); generated clouds of every LAS version and
            point format, GeoKeys and WKT CRS records, degenerate clouds
  lazfile   the real LAZ samples, cut the same way (the chunk table is then
            gone: the chunks are found in order); laspy (lazrs) LAZ files
            of the generated clouds of formats 0-3 and 6-8 (layered), in
            chunks of a few points, LAS 1.2 and 1.4 (with an EVLR after the
            table)
  pcd       the real PCD samples, cut the same way; PCL-written clouds in
            ascii, binary and binary_compressed with several field types,
            extra fields and invalid (NaN) points
  plycheck  meshes gdt-tile writes for small clouds (reference and tiled),
            collinear and tiny clouds (no faces)
  job       the job.db of small tiled runs kept with --keep-job
  tri       the tile files (tiles/*.tri) of those runs, up to 64 KiB each
  laz       the first chunk of each real LAZ sample of formats 0-5, framed
            for fuzz_laz (format, item version and extra bytes, points),
            whole and cut
The samples are copied into the build tree at test time, never into the
repository.  Needs numpy (the generators); run it with the project's .venv.
Exit status 0, or 1 when a generator or gdt-tile fails.
"""
import argparse
import os
import pathlib
import shutil
import subprocess
import sys
import tempfile

ROOT = pathlib.Path(__file__).resolve().parents[2]
SCRIPTS = ROOT / "scripts"
sys.path.insert(0, str(ROOT / "tests" / "python"))
CUT = 16384  # bytes of a real sample kept as a seed (the targets' -max_len)


# gdt-tile of a fuzz build runs PoCL's threads, which LeakSanitizer's exit
# scan cannot always stop; leaks are the fuzz targets' business, not the seeds'.
ENV = dict(os.environ, ASAN_OPTIONS="detect_leaks=0")


def run(cmd):
    r = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, timeout=300,
                       env=ENV)
    if r.returncode != 0:
        sys.exit(f"make_corpus: {' '.join(map(str, cmd))} failed ({r.returncode}): "
                 f"{r.stderr.strip()[-2000:]}")
    return r


def gen_cloud(out, points, *extra):
    run([sys.executable, SCRIPTS / "gen_cloud.py", out, "--points", points, "-q", *extra])


def gen_degenerate(out, kind, n, fmt):
    run([sys.executable, SCRIPTS / "gen_degenerate.py", kind, out, "--n", n, "--format", fmt])


def copy_cut(src, dst):
    dst.write_bytes(src.read_bytes()[:CUT])


def las_seeds(out, data, tmp):
    for f in sorted(data.glob("*.las")):
        copy_cut(f, out / f"real_{f.stem}.las")
    runs = [("v11_pf1", 40, "--las-version", "1.1", "--kind", "grid"),
            ("v12_pf0", 60, "--point-format", "0", "--kind", "uniform"),
            ("v12_pf3", 80, "--kind", "lidar"),
            ("v12_nocrs", 30, "--epsg", "0", "--kind", "uniform"),
            ("v13_pf3", 50, "--las-version", "1.3", "--kind", "dem"),
            ("v14_pf6", 60, "--las-version", "1.4", "--kind", "mixed"),
            ("v14_pf7", 40, "--las-version", "1.4", "--point-format", "7"),
            ("v14_pf8", 30, "--las-version", "1.4", "--point-format", "8"),
            ("v14_geotiff", 30, "--las-version", "1.4", "--crs", "geotiff"),
            ("v14_wkt_pf6", 30, "--las-version", "1.4", "--crs", "wkt")]
    for name, n, *extra in runs:
        gen_cloud(out / f"gen_{name}.las", n, "--seed", len(name), *extra)
    for kind in ("collinear", "duplicates", "one", "extreme"):
        gen_degenerate(out / f"deg_{kind}.las", kind, 50, "las")


def lazfile_seeds(out, data, tmp):
    import laspy
    from laspy.vlrs.vlrlist import VLRList

    import laz_util

    for f in sorted(data.glob("*.laz")):
        copy_cut(f, out / f"real_{f.stem}.laz")
    runs = [("v12_pf0", 60, 7, "1.2", 0), ("v12_pf1", 50, 16, "1.2", 1),
            ("v12_pf2", 40, 13, "1.2", 2), ("v12_pf3", 80, 20, "1.2", 3),
            ("v14_pf1", 45, 10, "1.4", 1), ("v14_pf3", 70, 25, "1.4", 3),
            ("v14_pf6", 60, 15, "1.4", 6), ("v14_pf7", 40, 12, "1.4", 7),
            ("v14_pf8", 35, 9, "1.4", 8)]
    for name, n, chunk, version, fmt in runs:
        las = tmp / f"laz_{name}.las"
        gen_cloud(las, n, "--seed", len(name) + fmt, "--las-version", version,
                  "--point-format", fmt, "--kind", "lidar")
        cloud = laspy.read(str(las))
        if version == "1.4":
            cloud.evlrs = VLRList([laspy.VLR("gdt_test", 7, "opaque", b"evlr" * 8)])
        laz_util.write_laz(cloud, out / f"gen_{name}.laz", chunk)


def laz_seeds(out, data):
    """fuzz_laz inputs: 4 framing bytes, then a chunk's first bytes."""
    # one point of format 0: its raw record and the coder's 4 bytes
    (out / "one_point.bin").write_bytes(bytes(4 + 20 + 4))
    base = {0: 20, 1: 28, 2: 26, 3: 34, 4: 57, 5: 63}
    for f in sorted(data.glob("*.laz")):
        b = f.read_bytes()
        if len(b) < 227:
            continue
        fmt, rl = b[104] & 0x3F, int.from_bytes(b[105:107], "little")
        offset = int.from_bytes(b[96:100], "little")
        if fmt not in base or not 0 <= rl - base[fmt] < 8:
            continue
        count = min(int.from_bytes(b[107:111], "little"), 4096)
        frame = bytes([fmt, (rl - base[fmt]) << 1]) + max(count - 1, 0).to_bytes(2, "little")
        chunk = b[offset + 8:offset + 8 + CUT - 4]
        (out / f"real_{f.stem}.bin").write_bytes(frame + chunk)
        (out / f"cut_{f.stem}.bin").write_bytes(frame + chunk[:len(chunk) // 3])


def laz14_seeds(out):
    """fuzz_laz14 inputs: the hand-made layered chunks kept for its replay."""
    for f in sorted((ROOT / "tests" / "fuzz" / "regress" / "laz14").iterdir()):
        shutil.copyfile(f, out / f.name)


def pcd_seeds(out, build, data):
    for f in sorted(data.glob("*.pcd")):
        copy_cut(f, out / f"real_{f.stem}.pcd")
    tool = build / "tests" / "pcd_write_pcl"
    runs = [("ascii_f8", "--encoding", "ascii", "--type", "F8"),
            ("ascii_f4_nan", "--encoding", "ascii", "--type", "F4", "--nan-frac", "0.2"),
            ("binary_f8", "--encoding", "binary", "--type", "F8"),
            ("binary_i4_extra", "--encoding", "binary", "--type", "I4",
             "--extra", "intensity,rgb"),
            ("binary_upper_last", "--encoding", "binary", "--case", "upper", "--xyz-last"),
            ("compressed_f8", "--encoding", "binary_compressed", "--type", "F8"),
            ("compressed_f4_normal", "--encoding", "binary_compressed", "--type", "F4",
             "--extra", "normal,label"),
            ("typed_xyzrgb", "--typed", "xyzrgb", "--encoding", "binary"),
            ("organized_nan_z", "--width", "8", "--height", "6", "--nan-frac", "0.3",
             "--nan-z-only")]
    for i, (name, *extra) in enumerate(runs):
        args = list(extra)
        if "--width" not in args:
            args += ["--width", "40"]
        run([tool, "--out", out / f"gen_{name}.pcd", "--seed", i + 1, *args])
    gen_degenerate(out / "deg_grid.pcd", "grid", 40, "pcd")


def tiled(build, cloud, job, ply, cell):
    """A tiled run of many tiny tiles (64 texels of cell CRS units), job kept."""
    run([build / "tiler" / "gdt-tile", cloud, "-o", ply, "--tile", 64, "--cell", cell,
         "--job", job, "--keep-job", "-q"])


# The tri target's -max_len (scripts/fuzz.sh): larger tile files are left out.
TRI_MAX = 65536


def ply_and_job_seeds(plyout, jobout, triout, build, tmp):
    gdt = build / "tiler" / "gdt-tile"
    clouds = []
    for n, kind in ((60, "uniform"), (120, "lidar"), (90, "grid")):
        c = tmp / f"c_{kind}.las"
        gen_cloud(c, n, "--kind", kind, "--seed", n, "--extent", 20, 20)
        clouds.append(c)
    for kind, n in (("collinear", 20), ("two", 2), ("circle", 40), ("rotgrid", 50)):
        c = tmp / f"d_{kind}.las"
        gen_degenerate(c, kind, n, "las")
        clouds.append(c)
    for c in clouds:
        run([gdt, c, "--reference", "-o", plyout / f"ref_{c.stem}.ply", "-q"])
    for c, cell in ((clouds[0], 0.1), (clouds[1], 0.05)):
        job = tmp / f"job_{c.stem}"
        ply = tmp / f"tiled_{c.stem}.ply"
        tiled(build, c, job, ply, cell)
        shutil.copyfile(ply, plyout / ply.name)
        shutil.copyfile(job / "job.db", jobout / f"{c.stem}.db")
        for tri in sorted((job / "tiles").glob("*.tri")):
            if tri.stat().st_size <= TRI_MAX:
                shutil.copyfile(tri, triout / f"{c.stem}_{tri.name}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[1])
    ap.add_argument("build", type=pathlib.Path)
    ap.add_argument("out", type=pathlib.Path)
    ap.add_argument("--data", type=pathlib.Path, default=ROOT.parent / "shared" / "data")
    a = ap.parse_args(argv)
    build = a.build.resolve()
    dirs = {t: a.out / t for t in ("las", "pcd", "plycheck", "job", "tri", "laz", "lazfile", "laz14")}
    for d in dirs.values():
        shutil.rmtree(d, ignore_errors=True)
        d.mkdir(parents=True)
    if not a.data.is_dir():
        print(f"make_corpus: no samples in {a.data}: generated seeds only", file=sys.stderr)
    with tempfile.TemporaryDirectory(prefix="gdt-corpus-") as t:
        tmp = pathlib.Path(t)
        las_seeds(dirs["las"], a.data, tmp)
        lazfile_seeds(dirs["lazfile"], a.data, tmp)
        pcd_seeds(dirs["pcd"], build, a.data)
        ply_and_job_seeds(dirs["plycheck"], dirs["job"], dirs["tri"], build, tmp)
        laz_seeds(dirs["laz"], a.data)
        laz14_seeds(dirs["laz14"])
    for t, d in dirs.items():
        files = list(d.iterdir())
        print(f"{t}: {len(files)} seeds, largest {max(f.stat().st_size for f in files)} bytes")
    return 0


if __name__ == "__main__":
    sys.exit(main())
