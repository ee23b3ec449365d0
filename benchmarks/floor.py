"""The FFT-pair floor measured by the benchmarks themselves (benchmarks/fft_floor.c).

``fft_floor(n, ranks)`` builds ``fft_floor.c`` with ``mpicc`` on first use (into
``$PETGAP_BENCH_BUILD`` or a directory under the system's temporary directory;
rebuilt when the source is newer) and returns the median seconds of one r2c + c2r
FFTW-MPI pair of an ``n x n`` field on ``ranks`` processes.
"""
import os
import re
import subprocess
import tempfile
from pathlib import Path

SOURCE = Path(__file__).resolve().with_name("fft_floor.c")


def _binary():
    build = Path(os.environ.get("PETGAP_BENCH_BUILD",
                                Path(tempfile.gettempdir()) / "petgap-bench-build"))
    build.mkdir(parents=True, exist_ok=True)
    binary = build / "fft_floor"
    if not binary.exists() or binary.stat().st_mtime < SOURCE.stat().st_mtime:
        subprocess.run(["mpicc", "-O3", "-o", str(binary), str(SOURCE),
                        "-lfftw3_mpi", "-lfftw3", "-lm"], check=True)
    return binary


def fft_floor_command(n, ranks, repeats=15):
    """The command line that measures the floor (for scripts that run it themselves)."""
    return ["mpirun", "-n", str(ranks), "--oversubscribe", str(_binary()), str(n), str(repeats)]


def fft_floor(n, ranks, repeats=15):
    """Median seconds of one FFTW-MPI r2c + c2r pair of an ``n x n`` field on ``ranks`` ranks."""
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    out = subprocess.run(fft_floor_command(n, ranks, repeats), capture_output=True, text=True,
                         env=env, timeout=900, check=True).stdout
    return float(re.search(r"median_pair_s=([0-9.eE+-]+)", out).group(1))
