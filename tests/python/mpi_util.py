"""What the tests that start gdt-tile under mpirun share: Open MPI's
permission to run as root (CI runs as root), the variables by which a
launcher tells a process it is a rank (removed, so that a test run inside a
launcher still starts plain processes), and whether this gdt-tile has MPI."""
import os
import shutil
import subprocess

ROOT_OK = {"OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1"}
LAUNCH_VARS = ("OMPI_COMM_WORLD_SIZE", "OMPI_COMM_WORLD_RANK", "OMPI_COMM_WORLD_LOCAL_RANK",
               "PMI_SIZE", "PMI_RANK", "MPI_LOCALRANKID", "PMIX_RANK")


def clean_env(**extra):
    """The test process's environment without the launcher's variables, plus extra."""
    env = {k: v for k, v in os.environ.items() if k not in LAUNCH_VARS}
    env.update(extra)
    return env


def why_no_mpi(gdt_bin):
    """None when mpirun exists and gdt_bin was built with MPI, else the reason."""
    if shutil.which("mpirun") is None:
        return "Open MPI's mpirun is not installed"
    r = subprocess.run([str(gdt_bin), "--version"], capture_output=True, text=True)
    if "mpi: yes" not in r.stdout:
        return "this gdt-tile was built without MPI"
    return None
