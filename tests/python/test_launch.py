"""A parallel launcher (mpirun, srun) starting several gdt-tile processes:
only the tiled run and --resume are shared between ranks (test_mpi.py);
every other mode, and any parallel launch of a build without MPI, is refused
on every rank before it touches anything (exit 2, GDT-2951 or GDT-2950, said
once, by rank 0); one rank runs as a plain process."""
import shutil
import sys

import pytest

from mpi_util import ROOT_OK, clean_env


def cloud(runner, root, tmp_path):
    path = tmp_path / "c.las"
    r = runner([sys.executable, root / "scripts" / "gen_cloud.py", path, "--points", "3000",
                "--seed", "4", "-q"])
    assert r.returncode == 0, r.stderr
    return path


def has_mpi(gdt_bin, runner):
    r = runner([gdt_bin, "--version"])
    assert r.returncode == 0, r.stderr
    return "mpi: yes" in r.stdout


@pytest.mark.sanitize
@pytest.mark.parametrize("variables,rank0", [
    ({"OMPI_COMM_WORLD_SIZE": "4", "OMPI_COMM_WORLD_RANK": "0"}, True),
    ({"OMPI_COMM_WORLD_SIZE": "4", "OMPI_COMM_WORLD_RANK": "3"}, False),
    ({"PMI_SIZE": "2", "PMI_RANK": "0"}, True),
    ({"PMI_SIZE": "2", "PMI_RANK": "1"}, False),
    ({"PMIX_RANK": "1"}, False),
])
@pytest.mark.parametrize("mode", [(), ("--reference",), ("--info",), ("--single-tile",)])
def test_ranks_refuse_before_touching_anything(gdt_bin, runner, root, tmp_path, variables,
                                               rank0, mode):
    mpi = has_mpi(gdt_bin, runner)
    if mpi and mode == ():
        pytest.skip("the tiled run of an MPI build is shared: test_mpi.py, under mpirun")
    c = cloud(runner, root, tmp_path)
    before = sorted(p.name for p in tmp_path.iterdir())
    out = tmp_path / "o.ply"
    r = runner([gdt_bin, c, "-o", out, *mode], env=clean_env(**variables))
    assert r.returncode == 2, r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # no output, no job
    if rank0:
        code = "GDT-2951" if mpi else "GDT-2950"
        assert code in r.stderr and "rank 0 of" in r.stderr and "one rank" in r.stderr
        if not mpi:
            assert "without MPI" in r.stderr and "-np 1" in r.stderr
    else:
        assert r.stderr == "", r.stderr


@pytest.mark.parametrize("variables", [
    {"OMPI_COMM_WORLD_SIZE": "1", "OMPI_COMM_WORLD_RANK": "0"},
    {"PMI_SIZE": "1", "PMI_RANK": "0"},
    {"PMIX_RANK": "0"},
    {"OMPI_COMM_WORLD_SIZE": "x2", "OMPI_COMM_WORLD_RANK": "0"},  # not a number: ignored
])
def test_one_rank_runs_as_a_plain_process(gdt_bin, runner, root, tmp_path, variables):
    c = cloud(runner, root, tmp_path)
    plain, ranked = tmp_path / "plain.ply", tmp_path / "ranked.ply"
    r = runner([gdt_bin, c, "-o", plain, "--tile", "64", "-q"], env=clean_env())
    assert r.returncode == 0, r.stderr
    r = runner([gdt_bin, c, "-o", ranked, "--tile", "64", "-q"], env=clean_env(**variables))
    assert r.returncode == 0, r.stderr
    assert plain.read_bytes() == ranked.read_bytes()


@pytest.mark.sanitize
@pytest.mark.skipif(shutil.which("mpirun") is None, reason="Open MPI's mpirun is not installed")
def test_under_mpirun_without_mpi(gdt_bin, runner, root, tmp_path):
    """A build without MPI under a real mpirun: refused once, nothing made;
    one rank runs."""
    if has_mpi(gdt_bin, runner):
        pytest.skip("this build has MPI: test_mpi.py")
    c = cloud(runner, root, tmp_path)
    out = tmp_path / "o.ply"
    env = clean_env(**ROOT_OK)
    r = runner(["mpirun", "--oversubscribe", "-np", "2", gdt_bin, c, "-o", out], env=env,
               timeout=120)
    assert r.returncode == 2, r.stdout + r.stderr
    assert r.stderr.count("GDT-2950") == 1, r.stderr
    assert not out.exists() and not (tmp_path / "o.ply.gdt-job").exists()
    r = runner(["mpirun", "-np", "1", gdt_bin, c, "-o", out, "-q"], env=env, timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr
    assert out.exists()
