"""Measured or stored topographies: read straight into each rank's slab.

A topography file holds one global ``(nx, ny)`` array of heights, axis 0 along x,
in the length units of the grid (the conventions of :mod:`petgap.parallel.grid`).  Each
rank reads only its rows ``grid.x_slice``: ``.npy`` files through a read-only
memory map, HDF5 files (``.h5``, ``.hdf5``) through h5py's ``mpio`` driver with
one collective hyperslab read.

Errors are collective: whatever is wrong with a file is decided on rank 0 (or by
an allreduce over the slabs, for non-finite values) and raised as the same
exception on every rank, so no rank is left waiting in a collective call.
"""
import io
import json
import os
from pathlib import Path

import numpy as np
from mpi4py import MPI

from petgap.parallel.collective import root_decides
from petgap.surfaces.measured import (check_file, check_map_shape, condition_map, read_header,
                                      read_measured, scatter_rows)
from petgap.surfaces.statistics import check_local_field

#: File name extensions load_topography reads itself, slab by slab (others go to
#: SurfaceTopography).
SUFFIXES = (".npy", ".h5", ".hdf5")
#: Dataset read from an HDF5 file when none is named.
DEFAULT_DATASET = "topography"


def load_topography(grid, path, dataset=None, *, channel=None, unit=None, detrend="none",
                    undefined="refuse"):
    """This rank's slab of the topography stored in ``path``.

    ``.npy`` and HDF5 files are read slab by slab; any other file is a measured map
    read by SurfaceTopography (:mod:`petgap.surfaces.measured`), conditioned as asked
    (``channel``, ``unit``, ``detrend``, ``undefined``: see
    :func:`petgap.surfaces.measured.read_measured`; with ``detrend`` or ``undefined =
    "harmonic"`` a ``.npy`` or HDF5 map is conditioned the same way, read whole on
    rank 0).

    Parameters
    ----------
    grid : petgap.parallel.grid.Grid
        The file's array must have shape ``grid.shape``.
    path : str or os.PathLike
        A ``.npy`` file or an HDF5 file (``.h5``, ``.hdf5``).
    dataset : str, optional
        HDF5 only: the dataset to read.  Default: ``"topography"`` if present,
        otherwise the file's only 2D dataset.

    Returns
    -------
    ndarray of float64, shape ``grid.local_shape``
        Heights on rows ``grid.x_slice``; float16/32 data are converted.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist (on every rank).
    ValueError
        On every rank, if the extension is not one of :data:`SUFFIXES`, the file
        cannot be read as its extension says, the (chosen) dataset is missing,
        ambiguous or not 2D, its shape differs from ``grid.shape``, its data are
        not floating point, or it holds NaN or infinite values (their count and
        the first global index ``(i, j)`` are given).
    """
    comm = grid.comm
    path = Path(path)
    own = path.suffix.lower() in SUFFIXES
    if not own or detrend != "none" or undefined != "refuse":
        def read():
            m = read_map(path, dataset, channel=channel, unit=unit, detrend=detrend,
                         undefined=undefined)
            if m.heights.shape != tuple(grid.shape):
                raise ValueError(f"topography {path} has shape {m.heights.shape}, but the grid "
                                 f"is {tuple(grid.shape)}")
            held.append(m.heights)
        held = []
        root_decides(comm, read)
        local = scatter_rows(grid, held[0] if comm.rank == 0 else None)
        _check_finite(grid, local, path)
        return local
    found = None
    if comm.rank == 0:
        try:
            found = ("ok", _inspect(path, dataset, grid.shape))
        except FileNotFoundError as exc:
            found = ("FileNotFoundError", str(exc))
        except Exception as exc:  # anything else rank 0 trips on: a ValueError everywhere
            found = ("ValueError", str(exc) if isinstance(exc, ValueError)
                     else f"cannot read topography {path}: {type(exc).__name__}: {exc}")
    status, info = comm.bcast(found, root=0)
    if status != "ok":
        raise (FileNotFoundError if status == "FileNotFoundError" else ValueError)(info)

    kind, name = info
    error = None
    try:
        if kind == "npy":
            local = _read_npy_slab(grid, path)
        else:
            local = _read_hdf5_slab(grid, path, name)
    except Exception as exc:  # e.g. the file changed under us: fail together, not hang
        local, error = None, f"rank {comm.rank}: {type(exc).__name__}: {exc}"
    errors = [e for e in comm.allgather(error) if e is not None]
    if errors:
        raise ValueError(f"cannot read topography {path}: " + "; ".join(errors))

    _check_finite(grid, local, path if name is None else f"{path}:{name}")
    return local


def map_header(path, dataset=None, channel=None, length_unit="1"):
    """What a topography file says about its grid, read on the calling rank without its
    heights: ``{"shape": (nx, ny), "size": (Lx, Ly) or None, "unit": ..., "periodic": bool}``.

    ``.npy`` maps know only their shape (not periodic: nothing says so); HDF5 maps also
    whether they are periodic (:func:`_says_periodic`); instrument files (via
    :func:`petgap.surfaces.measured.read_header`) also their physical size, converted to
    ``length_unit`` unless that is ``"1"`` (the scene's own unit).  The reader the scene
    parser uses to take the grid from the file (``Scene.from_file(..., read_header=)``).
    """
    path = Path(path)
    if path.suffix.lower() not in SUFFIXES:
        return read_header(path, channel, None if length_unit == "1" else length_unit)
    kind, name = _inspect(path, dataset, None)
    periodic = False
    if kind == "npy":
        shape = np.load(path, mmap_mode="r").shape
    else:
        with _import_h5py().File(path, "r") as f:
            shape = f[name].shape
            periodic = _says_periodic(f, name)
    return {"shape": tuple(int(n) for n in shape), "size": None, "unit": None,
            "periodic": periodic}


def _says_periodic(f, name):
    """Whether an HDF5 file says its map is periodic: a ``periodic`` attribute of the
    dataset, or, in a petgap result, the surface.periodic of the scene that made it."""
    if "periodic" in f[name].attrs:
        return bool(f[name].attrs["periodic"])
    scene = f.attrs.get("scene_resolved")
    if scene is None:
        return False
    try:
        surface = json.loads(scene).get("surface", {})
    except (TypeError, ValueError):
        return False
    return bool(surface.get("periodic", surface.get("kind") == "self-affine"))


def read_map(path, dataset=None, *, channel=None, unit=None, detrend="none",
             undefined="refuse"):
    """A whole map, read and conditioned on the calling rank alone: its
    :class:`petgap.surfaces.measured.Measurement`.

    ``.npy`` and HDF5 files are read here (they carry no unit or size), every other
    file by SurfaceTopography (:func:`petgap.surfaces.measured.read_measured`); both
    are then conditioned alike (``detrend``, ``undefined``).  For ``petgap check``
    and for runs that condition a map; plain runs read ``.npy`` and HDF5 slab by slab.
    """
    path = Path(path)
    if path.suffix.lower() not in SUFFIXES:
        if dataset is not None:
            raise ValueError(f"dataset={dataset!r} is given, but {path} is not an HDF5 file "
                             f"(instrument files have channels: surface.channel)")
        return read_measured(path, channel=channel, unit=unit, detrend=detrend,
                             undefined=undefined)
    if channel is not None:
        raise ValueError(f"channel={channel!r} is given, but {path} is a {path.suffix} file "
                         f"(channels exist in instrument files)")
    kind, name = _inspect(path, dataset, None)
    if kind == "npy":
        heights = np.load(path)
    else:
        with _import_h5py().File(path, "r") as f:
            heights = f[name][...]
    return condition_map(heights, path if name is None else f"{path}:{name}", detrend=detrend,
                         undefined=undefined)


def save_topography_npy(grid, h_local, path):
    """Write the distributed heights to one ``.npy`` file of shape ``grid.shape``.

    For tests, benchmarks and interchange; runs write HDF5.  The ranks write
    their slabs in turn (rank 0 also writes the header), handing a token from
    rank to rank, so no rank ever holds more than its own slab — but the writes
    are serial, so throughput is that of one process.  (Gathering the field on
    rank 0 would also do for ``.npy``, at the price of the whole field in one
    process's memory.)  An existing file is overwritten, as with ``np.save``.

    Parameters
    ----------
    grid : petgap.parallel.grid.Grid
    h_local : ndarray, shape ``grid.local_shape``
    path : str or os.PathLike
        Must end in ``.npy``.

    Raises
    ------
    ValueError
        On every rank, for a wrong suffix or slab shape.
    OSError
        On every rank, if any rank fails to write.
    """
    comm = grid.comm
    path = Path(path)
    if path.suffix != ".npy":
        raise ValueError(f"path {str(path)!r} must end in .npy")
    h_local = np.ascontiguousarray(check_local_field(grid, h_local, "h_local"), dtype="<f8")
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f8", "fortran_order": False,
                                                  "shape": grid.shape})
    header = header.getvalue()

    failure = comm.recv(source=comm.rank - 1, tag=7) if comm.rank > 0 else None
    if failure is None:
        try:
            with open(path, "wb" if comm.rank == 0 else "r+b") as f:
                if comm.rank == 0:
                    f.write(header)
                f.seek(len(header) + 8 * grid.x_slice.start * grid.ny)
                f.write(h_local.data)
        except OSError as exc:
            failure = f"rank {comm.rank} could not write {path}: {exc}"
    if comm.rank < comm.size - 1:
        comm.send(failure, dest=comm.rank + 1, tag=7)
    failure = comm.bcast(failure, root=comm.size - 1)
    if failure is not None:
        raise OSError(failure)


# --------------------------------------------------------------------- helpers
def _inspect(path, dataset, shape):
    """Rank 0: check ``path`` without reading its data; return ``(kind, dataset name)``."""
    check_file(path)
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise ValueError(f"topography file {path} has the unknown extension {path.suffix!r}; "
                         f"allowed: {', '.join(SUFFIXES)}")
    if suffix == ".npy":
        if dataset is not None:
            raise ValueError(f"dataset={dataset!r} is given, but {path} is a .npy file "
                             f"(datasets exist only in HDF5 files)")
        try:
            array = np.load(path, mmap_mode="r")
        except Exception as exc:
            raise ValueError(f"cannot read {path} as a .npy file: {exc}") from None
        if not isinstance(array, np.ndarray):
            raise ValueError(f"{path} does not hold a single array")
        _check_layout(f"{path}", array.shape, array.dtype, shape)
        return "npy", None

    h5py = _import_h5py()
    try:
        f = h5py.File(path, "r")
    except Exception as exc:
        raise ValueError(f"cannot read {path} as an HDF5 file: {exc}") from None
    with f:
        name = _choose_dataset(f, dataset, path)
        _check_layout(f"{path}:{name}", f[name].shape, f[name].dtype, shape)
    return "hdf5", name


def _check_layout(what, file_shape, dtype, shape):
    if len(file_shape) != 2:
        raise ValueError(f"topography {what} is {len(file_shape)}D with shape {tuple(file_shape)}; "
                         f"a topography must be 2D, shape (nx, ny)")
    check_map_shape(what, tuple(file_shape))
    if np.dtype(dtype).kind != "f":
        raise ValueError(f"topography {what} has data type {np.dtype(dtype)}, which is not "
                         f"floating point; heights must be float16, float32 or float64")
    if shape is not None and tuple(file_shape) != tuple(shape):
        raise ValueError(f"topography {what} has shape {tuple(file_shape)}, but the grid is "
                         f"{tuple(shape)}")


def _choose_dataset(f, dataset, path):
    """Name of the dataset to read: the one asked for, ``topography``, or the only 2D one."""
    h5py = _import_h5py()
    datasets = {}

    def collect(name, obj):  # returns None: a value would stop the visit
        if isinstance(obj, h5py.Dataset):
            datasets[name] = obj.shape
    f.visititems(collect)
    listing = ", ".join(f"{n} {s}" for n, s in datasets.items()) or "none"
    if dataset is not None:
        name = str(dataset).strip("/")
        if name not in datasets:
            raise ValueError(f"{path} has no dataset {dataset!r}; datasets: {listing}")
        return name
    if DEFAULT_DATASET in datasets:
        return DEFAULT_DATASET
    two_d = [n for n, s in datasets.items() if len(s) == 2]
    if len(two_d) != 1:
        raise ValueError(f"{path} has no dataset {DEFAULT_DATASET!r} and "
                         f"{'no' if not two_d else len(two_d)} 2D datasets (datasets: {listing}); "
                         f"pass dataset= to choose one")
    return two_d[0]


def _read_npy_slab(grid, path):
    array = np.load(path, mmap_mode="r")
    local = np.empty(grid.local_shape)
    local[...] = array[grid.x_slice]  # only these rows are paged in
    del array
    return local


def _read_hdf5_slab(grid, path, name):
    h5py = _import_h5py()
    local = np.empty(grid.local_shape)
    rows = np.s_[grid.x_slice.start:grid.x_slice.stop, :]
    if h5py.get_config().mpi:
        with h5py.File(path, "r", driver="mpio", comm=grid.comm) as f:
            dset = f[name]
            with dset.collective:
                dset.read_direct(local, source_sel=rows)
    else:  # serial h5py: every rank reads its own rows independently (read-only, so safe)
        with h5py.File(path, "r") as f:
            f[name].read_direct(local, source_sel=rows)
    return local


#: Largest height magnitude accepted.  Statistics and the solvers square heights and
#: sum them over up to 2^62 points (rms height, energies), and multiply them by
#: wavevectors: beyond about 1e150 such sums overflow double precision.  No unit of
#: length makes a real surface that rough; such numbers are a wrong unit or a corrupt file.
MAX_HEIGHT = 1e100


def _check_finite(grid, local, what):
    """Raise on every rank if any rank's slab holds NaN or inf (count and first global index),
    or heights beyond :data:`MAX_HEIGHT` in magnitude."""
    bad = ~np.isfinite(local)
    count = int(np.count_nonzero(bad))
    first = grid.x_slice.start * grid.ny + int(np.argmax(bad)) if count else grid.npoints
    count = grid.comm.allreduce(count, op=MPI.SUM)
    if count:
        first = grid.comm.allreduce(first, op=MPI.MIN)
        raise ValueError(f"topography {what} holds {count} non-finite values (NaN or inf); "
                         f"the first at global index (i, j) = {divmod(first, grid.ny)}")
    largest = grid.comm.allreduce(float(np.max(np.abs(local), initial=0.0)), op=MPI.MAX)
    if largest > MAX_HEIGHT:
        raise ValueError(f"topography {what} holds heights up to {largest:.3g} in magnitude; "
                         f"at most {MAX_HEIGHT:g} is allowed (squared sums of such heights "
                         f"overflow): is the file in the unit the scene assumes?")


def _import_h5py():
    """h5py, its MPI build when available (Debian picks the serial one unless told)."""
    os.environ.setdefault("H5PY_ALWAYS_USE_MPI", "1")
    import h5py  # deferred: the environment must choose the MPI build first, and .npy needs no h5py
    return h5py
