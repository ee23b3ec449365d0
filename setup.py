"""Build petgap's compiled parts: the FFTW-MPI binding and the solvers' kernels.

The package's metadata, dependencies and console scripts are in ``pyproject.toml``;
this file only declares the Cython extensions, which need computed flags.  The
binding (``petgap/parallel/_fftw_mpi.pyx``) is compiled against Debian's FFTW 3.3 MPI
library and Open MPI; include and link flags come from ``mpicc --showme`` so that
no compiler wrapper has to be set in the environment.
"""
import os
import shlex
import subprocess

import mpi4py
import numpy
from Cython.Build import cythonize
from setuptools import Extension, find_packages, setup


def mpicc_flags(kind):
    """Return the flags that ``mpicc --showme:<kind>`` prints (empty if absent)."""
    try:
        out = subprocess.run(["mpicc", f"--showme:{kind}"], capture_output=True,
                             text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        return []
    return shlex.split(out)


compile_flags = mpicc_flags("compile")

# petgap is always compiled on the machine that runs it (scripts/bootstrap.sh),
# so the kernels may use its full vector width: -march=native halves the cost of
# the Fourier multiply (square root and division per mode) on AVX2/AVX-512
# machines.  PETGAP_PORTABLE_BUILD=1 builds for the baseline x86-64 instead,
# e.g. for a cluster whose login node differs from its compute nodes.
optimise = ["-O3", "-fno-math-errno", "-Wno-unused-function"]
if not os.environ.get("PETGAP_PORTABLE_BUILD"):
    optimise.append("-march=native")
link_flags = mpicc_flags("link")

extension = Extension(
    "petgap.parallel._fftw_mpi",
    sources=["petgap/parallel/_fftw_mpi.pyx"],
    include_dirs=[numpy.get_include(), mpi4py.get_include()]
    + [f[2:] for f in compile_flags if f.startswith("-I")],
    library_dirs=[f[2:] for f in link_flags if f.startswith("-L")],
    libraries=["fftw3_mpi", "fftw3", "m"] + [f[2:] for f in link_flags if f.startswith("-l")],
    extra_compile_args=optimise,
    define_macros=[("NPY_NO_DEPRECATED_API", "NPY_1_7_API_VERSION")],
)

# The same binding on FFTW's single-precision library (petgap/parallel/_fftw_body.pxi
# is the source of both).
extension_single = Extension(
    "petgap.parallel._fftw_mpi_single",
    sources=["petgap/parallel/_fftw_mpi_single.pyx"],
    include_dirs=extension.include_dirs,
    library_dirs=extension.library_dirs,
    libraries=["fftw3f_mpi", "fftw3f", "m"] + [f[2:] for f in link_flags if f.startswith("-l")],
    extra_compile_args=optimise,
    define_macros=[("NPY_NO_DEPRECATED_API", "NPY_1_7_API_VERSION")],
)

kernels = Extension(
    "petgap.solvers._kernels",
    sources=["petgap/solvers/_kernels.pyx"],
    extra_compile_args=optimise,
    define_macros=[("NPY_NO_DEPRECATED_API", "NPY_1_7_API_VERSION")],
)

# The interaction laws' per-point kernels (petgap.mechanics.interactions).
laws = Extension(
    "petgap.mechanics.interactions._laws",
    sources=["petgap/mechanics/interactions/_laws.pyx"],
    extra_compile_args=optimise,
    define_macros=[("NPY_NO_DEPRECATED_API", "NPY_1_7_API_VERSION")],
)

# Kernels on the contact set stored as index lists (petgap.solvers.pressure_cg).
contact_set = Extension(
    "petgap.solvers._contact_set",
    sources=["petgap/solvers/_contact_set.pyx"],
    extra_compile_args=optimise,
    define_macros=[("NPY_NO_DEPRECATED_API", "NPY_1_7_API_VERSION")],
)

setup(
    packages=find_packages(include=["petgap", "petgap.*"]),
    ext_modules=cythonize([extension, extension_single, kernels, laws, contact_set],
                          language_level=3,
                          compiler_directives={"boundscheck": False, "wraparound": False,
                                               "cdivision": True, "initializedcheck": False}),
)
