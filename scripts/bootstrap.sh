#!/usr/bin/env bash
# Set up everything petgap needs on Debian 12, idempotently and quickly when
# nothing is missing: the Debian packages listed below, a venv on /usr/bin/python3
# with system site packages (petsc4py, mpi4py, h5py-mpi come from Debian), and
# petgap built in place with its FFTW-MPI binding.  Source it: it exports the
# environment that mpirun and petgap need (PATH, Open MPI's run-as-root switch).
# The set-up runs in a subshell with `set -euo pipefail`, so that sourcing this
# file leaves the caller's shell options as they were (an interactive shell with
# `set -e` would close on the first failing command).  PETGAP_EXTRA_PACKAGES names
# Debian packages only some callers need (scripts/test.sh: chromium, in which the
# tests render the report; the main job does not).
PETGAP_ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
PETGAP_VENV=${PETGAP_VENV:-$PETGAP_ROOT/.venv}

_petgap_setup() (
set -euo pipefail

packages=(python3-petsc4py python3-mpi4py python3-h5py-mpi libfftw3-mpi-dev libfftw3-dev
          openmpi-bin libopenmpi-dev python3-numpy python3-scipy python3-matplotlib
          python3-pytest cython3 python3-dev python3-venv build-essential
          python3-xarray python3-h5netcdf
          python3-tifffile python3-xmltodict python3-defusedxml python3-openpyxl python3-yaml
          python3-dateutil python3-pil python3-requests python3-pandas
          ${PETGAP_EXTRA_PACKAGES:-})
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "petgap setup: installing ${missing[*]}" >&2
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO=sudo
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${missing[@]}" >&2
fi

if [ ! -x "$PETGAP_VENV/bin/python" ]; then
  echo "petgap setup: creating venv $PETGAP_VENV" >&2
  /usr/bin/python3 -m venv --system-site-packages "$PETGAP_VENV"
fi
# Debian's petsc4py is found through /usr/lib/petsc, a link that only petsc-dev
# provides; point the venv at the real-scalar build directly instead.
site=$("$PETGAP_VENV/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
petsc_py=$(ls -d /usr/lib/petscdir/petsc3.*/*-real/lib/python3/dist-packages 2>/dev/null | sort -V | tail -n 1)
if [ -z "$petsc_py" ]; then
  echo "petgap setup: no petsc4py found under /usr/lib/petscdir" >&2; exit 1
fi
[ "$(cat "$site/petgap-petsc4py.pth" 2>/dev/null)" = "$petsc_py" ] || echo "$petsc_py" > "$site/petgap-petsc4py.pth"

# SurfaceTopography (ContactEngineering's readers of instrument files) and the few of its
# dependencies Debian 12 does not have, from PyPI without their dependencies, so that pip
# never replaces Debian's NumPy or MPI h5py; versions that work with NumPy 1.24
# (SurfaceTopography >= 1.19 and NuMPI >= 0.8 need NumPy 2; its readers need pydantic 2).
surface_topography=(SurfaceTopography==1.18.2 muFFT==0.95.0 NuMPI==0.7.0 DiscoverVersion==0.4.0
                    tiffile==2018.10.18 igor2==0.5.15 numpyencoder==0.3.2 pydantic==2.9.2
                    pydantic-core==2.23.4 typing_extensions==4.12.2 annotated-types==0.7.0)
if ! "$PETGAP_VENV/bin/python" -c 'import SurfaceTopography' 2>/dev/null; then
  echo "petgap setup: installing SurfaceTopography into the venv (no dependencies)" >&2
  "$PETGAP_VENV/bin/python" -m pip install -q --no-deps "${surface_topography[@]}" >&2
fi

# (Re)build petgap when a source of the compiled part is newer than the build.
stamp="$PETGAP_VENV/.petgap-build-stamp"
if [ ! -f "$stamp" ] || [ -n "$(find "$PETGAP_ROOT/setup.py" "$PETGAP_ROOT/petgap" \( -name '*.pyx' -o -name '*.pxi' -o -name setup.py \) -newer "$stamp" | head -n 1)" ] \
   || ! "$PETGAP_VENV/bin/python" -c 'import petgap.parallel._fftw_mpi, petgap.parallel._fftw_mpi_single' 2>/dev/null; then
  echo "petgap setup: building petgap" >&2
  (cd "$PETGAP_ROOT" && "$PETGAP_VENV/bin/python" -m pip install --no-build-isolation --no-deps -q -e . >&2)
  touch "$stamp"
fi
)
if ! _petgap_setup; then
  echo "petgap setup failed (see the messages above)" >&2
  unset -f _petgap_setup
  return 1 2>/dev/null || exit 1
fi
unset -f _petgap_setup

export PATH="$PETGAP_VENV/bin:$PATH"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
# Open MPI in containers: no busy vader cross-memory attach warnings, no ssh agent needed.
export OMPI_MCA_btl_vader_single_copy_mechanism=none OMPI_MCA_rmaps_base_oversubscribe=1
