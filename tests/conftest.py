"""Pytest under ``mpirun -n P``: every rank runs every test on its own data.

* A test's outcome is combined across ranks: if it fails on any rank it fails on
  all, and the report names the ranks, so no rank walks on into the next test's
  collectives while another is still stuck in this one.
* ``mpi_tmp_path`` is one directory shared by all ranks (rank 0 creates it).
* ``run_cli`` runs a command (``mpirun`` included) as a subprocess from rank 0
  while the other ranks wait without spinning, and hands every rank the result.
* After each test PETSc's deferred garbage is collected collectively.
"""
import contextlib
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest
from mpi4py import MPI
from petsc4py import PETSc

from petgap.parallel.collective import root_decides

COMM = MPI.COMM_WORLD
ROOT = Path(__file__).resolve().parents[1]


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    report = outcome.get_result()
    if call.when not in ("setup", "call"):
        return
    failed = COMM.allgather(bool(report.failed))
    if any(failed) and not report.failed:
        ranks = [r for r, f in enumerate(failed) if f]
        report.outcome = "failed"
        report.longrepr = f"{item.nodeid} failed on rank(s) {ranks} of {COMM.size}"
    elif report.failed and COMM.size > 1:
        report.sections.append(("mpi", f"this is rank {COMM.rank} of {COMM.size}; "
                                        f"failed on ranks {[r for r, f in enumerate(failed) if f]}"))


@pytest.fixture(autouse=True)
def _petsc_garbage():
    yield
    PETSc.garbage_cleanup()


@pytest.fixture
def comm():
    """The communicator the suite runs on (``COMM_WORLD`` under mpirun)."""
    return COMM


@contextlib.contextmanager
def shared_directory(comm=COMM, prefix="petgap-test-"):
    """A temporary directory shared by all ranks of ``comm`` (rank 0 makes and removes it)."""
    path = tempfile.mkdtemp(prefix=prefix) if comm.rank == 0 else None
    path = Path(comm.bcast(path, root=0))
    try:
        yield path
    finally:
        comm.Barrier()
        if comm.rank == 0:
            shutil.rmtree(path, ignore_errors=True)


@pytest.fixture
def mpi_tmp_path():
    """A temporary directory shared by all ranks, removed afterwards."""
    with shared_directory() as path:
        yield path


def write_shared(comm, path, text):
    """Write ``text`` to ``path`` on rank 0; every rank returns ``path`` once it exists."""
    if comm.rank == 0:
        path.write_text(text)
    comm.Barrier()
    return path


def wait_for_root(func, comm=COMM, poll=0.02):
    """Run ``func()`` on rank 0 while other ranks sleep-poll; return its result everywhere.

    A plain ``bcast`` would make Open MPI's waiting ranks spin at 100 % CPU and
    starve the subprocesses ``func`` starts on a two-core machine.
    """
    return root_decides(comm, func, poll=poll)


def clean_env(extra=None):
    """The environment for a child ``mpirun``: without the parent job's Open MPI/PMIx variables."""
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("OMPI_COMM_WORLD", "OMPI_MCA_orte", "OMPI_MCA_ess", "OMPI_MCA_pmix",
                                "PMIX_", "OMPI_FILE_LOCATION", "OMPI_UNIVERSE", "OMPI_FIRST_RANKS",
                                "OMPI_APP_CTX", "OMPI_NUM_APP_CTX", "OMPI_ARGV", "OMPI_COMMAND",
                                "OMPI_MCA_initial_wdir", "OMPI_MCA_num_procs", "OMPI_MCA_cpu_type",
                                "OMPI_MCA_shmem_RUNTIME", "OPAL_", "OMPI_MCA_mpi_oversubscribe",
                                "OMPI_MCA_orte_", "HFI_", "IPATH_"))}
    env.setdefault("OMPI_ALLOW_RUN_AS_ROOT", "1")
    env.setdefault("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
    env["PYTHONUNBUFFERED"] = "1"
    env.update(extra or {})
    return env


@pytest.fixture
def run_cli():
    """``run_cli(args, ranks=None, timeout=...)``: run a command the way a user would.

    With ``ranks`` the command runs under ``mpirun -n ranks --oversubscribe``.
    Returns a ``subprocess.CompletedProcess`` on every rank.
    """
    def run(args, ranks=None, timeout=300, cwd=None, env=None, input=None):
        args = [str(a) for a in args]
        if ranks is not None:
            args = ["mpirun", "-n", str(ranks), "--oversubscribe"] + args
        def call():
            return subprocess.run(args, capture_output=True, text=True, timeout=timeout,
                                  cwd=cwd, env=clean_env(env), input=input)
        return wait_for_root(call)
    return run


PYTHON = sys.executable
