"""Result files: one HDF5 file per run, written collectively with parallel HDF5.

Layout
------
``/`` (root attributes)
    ``petgap_version``, ``command_line`` (``sys.argv`` joined with
    :func:`shlex.join`), ``hostname`` (rank 0) and ``hosts`` (all),
    ``start_time`` / ``end_time`` (ISO 8601, UTC), ``mpi_size``, library
    versions, ``git_commit`` when petgap runs from a checkout, whatever the
    caller's ``provenance`` adds (the CLI: ``scene`` = the TOML text,
    ``scene_path``, ``scene_resolved`` = JSON of the validated scene,
    ``petsc_options``), and ``complete``: False from creation until
    :meth:`ResultFile.close` succeeds.
``/<field>`` (e.g. ``topography``)
    Global ``(nx, ny)`` float64 datasets (float32 for the fields of a single-precision
    run), axis 0 = x, written by hyperslabs of
    rows, one per rank (``grid.x_slice``), in one collective call.
``/step_0000``, ``/step_0001``, ...
    One group per sweep step: its fields, its attributes (statistics, solver
    status; nested mappings flattened to dotted names), and ``complete`` =
    True written last, after which the file is flushed.  An interrupted run
    leaves the earlier steps readable and marked complete.

Parallel HDF5 rules this module follows: every rank makes the same metadata
calls (file, group, dataset and attribute creation) with the same values, so
provenance is computed on rank 0 and broadcast; raw data move collectively,
and a rank with an empty slab still takes part (with an empty selection).

Debian's h5py picks its MPI build only if ``H5PY_ALWAYS_USE_MPI`` (or an
``mpirun`` environment) is set when h5py is first imported, so importing this
module sets ``H5PY_ALWAYS_USE_MPI=1`` if unset; :func:`require_parallel_h5py`
names the problem if h5py came in serial anyway.
"""
import dataclasses
import datetime
import errno
import os
import re
import shlex
import socket
import subprocess
import sys
from pathlib import Path

os.environ.setdefault("H5PY_ALWAYS_USE_MPI", "1")  # before the first import of h5py
import h5py  # noqa: E402
import numpy as np  # noqa: E402
from h5py import h5d, h5fd, h5p, h5s  # noqa: E402
from mpi4py import MPI  # noqa: E402

from petgap.parallel.collective import root_decides  # noqa: E402
from petgap.parallel.log import failed_everywhere  # noqa: E402
from petgap._version import __version__

__all__ = ["ResultFile", "ResultExistsError", "ResultWriteError", "write_field", "read_field",
           "flatten_attrs", "step_name", "require_parallel_h5py", "check_free_space"]

STEP_PREFIX = "step_"


class ResultExistsError(FileExistsError):
    """The result file exists and overwriting was not asked for."""


class OutputPathError(OSError):
    """The output path can never be a result file (a device, an input of the run)."""


class ResultWriteError(OSError):
    """A write into a result file failed inside HDF5 (see :meth:`ResultFile.__exit__`).

    The file is left open and must not be touched again by this process, not even
    by the implicit close at interpreter shutdown: ``abort_job`` tells
    :func:`petgap.parallel.log.report_failure` to end the job with ``MPI_Abort``.
    """
    abort_job = True


def require_parallel_h5py():
    """Raise RuntimeError unless h5py was built with, and loaded, MPI support."""
    if not h5py.get_config().mpi:
        raise RuntimeError(
            f"petgap needs h5py with MPI support (parallel HDF5), but h5py {h5py.__version__} "
            f"from {Path(h5py.__file__).parent} has none. On Debian install python3-h5py-mpi "
            f"and make sure H5PY_ALWAYS_USE_MPI=1 is set, or petgap.io.results is imported, "
            f"before anything else imports h5py")


def step_name(index):
    """Group name of sweep step ``index``: ``step_0000``, ``step_0001``, ..."""
    return f"{STEP_PREFIX}{int(index):04d}"


def _default_comm(comm):
    return MPI.COMM_WORLD if comm is None else comm


def check_output_path(path, comm=None, overwrite=False, inputs=()):
    """Raise the same error on every rank if ``path`` cannot be created as a result file.

    See :func:`output_path_error` (rank 0 looks, every rank raises).  Cheap;
    callers use it to fail before spending time on a run.
    """
    root_decides(_default_comm(comm), lambda: output_path_error(path, overwrite, inputs))


def output_path_error(path, overwrite=False, inputs=()):
    """Raise (on the calling rank alone) if ``path`` cannot be created as a result file.

    Refused whatever ``overwrite`` says, since replacing them would destroy
    something that is not a result: a directory-like path (an existing
    directory, or a name ending in a slash, which a user means as a
    directory), anything existing that is not a regular file (``/dev/null``,
    a pipe, a socket: HDF5 cannot write them) and any of ``inputs``, a mapping
    ``{description: path}`` of the files the run reads (the scene file, the
    topography), which it would overwrite before reading.  Then
    :class:`ResultExistsError` if it exists and ``overwrite`` is false,
    FileNotFoundError if its directory does not exist, PermissionError if the
    directory is not writable (read-only file system, permissions).  ``path``
    may be the string as the user typed it (a trailing slash is seen then).
    """
    raw = os.fspath(path)
    path = Path(raw)
    if raw.endswith((os.sep, os.sep + ".", os.sep + "..")) or raw in (".", ".."):
        raise IsADirectoryError(f"output path {raw} names a directory; give a file name, "
                                f"e.g. {path / 'result.h5'}")
    if path.is_dir():  # before the existence test, whose message would call it a file
        raise IsADirectoryError(f"output path {path} is a directory; give a file name")
    if path.exists() and not path.is_file():
        raise OutputPathError(f"output path {path} is not a regular file (a device, pipe or "
                              f"socket); a result must be a regular file: choose another --output")
    for what, other in dict(inputs or {}).items():
        if other and path.exists() and Path(other).exists() and os.path.samefile(path, other):
            raise OutputPathError(f"output path {path} is the {what} ({other}), which the run "
                                  f"reads; --overwrite or not, it is not replaced: choose "
                                  f"another --output")
    if path.exists() and not overwrite:
        raise ResultExistsError(
            f"refusing to overwrite the existing result file {path}; "
            f"pass --overwrite to replace it, or choose another --output")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        why = "is not a directory" if parent.exists() else "does not exist"
        raise FileNotFoundError(f"cannot create result file {path}: directory {parent} {why}")
    if not os.access(parent, os.W_OK | os.X_OK):  # EROFS counts, even for root
        raise PermissionError(f"cannot create result file {path}: directory {parent} "
                              f"is not writable (read-only file system or permissions)")


def existing_result(path):
    """The root attributes of the result file ``path``, read by the calling rank alone.

    For the decision whether an existing output is this scene's result: raises
    :class:`ResultExistsError` saying why it is not one at all -- not readable
    as HDF5 (truncated, e.g. by a job killed while creating it, or another
    format), or HDF5 without petgap's provenance -- so that a refusal always
    says why.
    """
    try:
        attrs = root_attributes(path)
    except OSError as exc:
        raise ResultExistsError(
            f"refusing to overwrite {path}: it exists but is not a readable HDF5 file "
            f"(truncated, e.g. by a run killed while creating it, or another format: {exc}); "
            f"pass --overwrite to replace it, or choose another --output") from None
    if "petgap_version" not in attrs:
        raise ResultExistsError(
            f"refusing to overwrite {path}: it is an HDF5 file but not a petgap result (no "
            f"petgap_version attribute); pass --overwrite to replace it, or choose another "
            f"--output")
    return {k: (v.decode() if isinstance(v, bytes) else v.item() if isinstance(v, np.generic)
                else v) for k, v in attrs.items()}


#: Bytes a write must leave free beyond its raw data, for HDF5 metadata (object
#: headers, attributes, B-trees: about 10 KiB per step) with ample slack.
FREE_SPACE_MARGIN = 1 << 20


def check_free_space(path, nbytes, comm=None):
    """Raise the same OSError (ENOSPC) on every rank unless ``nbytes`` more fit next to ``path``.

    A write that runs out of space inside HDF5 cannot be undone: see
    :meth:`ResultFile.__exit__`.  Checking first (the raw data plus
    :data:`FREE_SPACE_MARGIN`) turns a full disk into a clean error before the
    file is touched, so every step already written stays readable and the run
    can be continued once there is room.
    """
    comm = _default_comm(comm)
    path = Path(path)

    def check():
        parent = path.parent if str(path.parent) else Path(".")
        stat = os.statvfs(parent)
        free, need = stat.f_bavail * stat.f_frsize, int(nbytes) + FREE_SPACE_MARGIN
        if free < need:
            raise OSError(errno.ENOSPC, f"not enough free space to write to {path}: the next "
                          f"write needs about {need} bytes ({int(nbytes)} of data and "
                          f"{FREE_SPACE_MARGIN} kept for metadata), the file system has {free} "
                          f"bytes free; make room, then rerun the same command to continue")
    root_decides(comm, check)


def _git_commit():
    """``<commit>[-dirty]`` of the checkout petgap runs from, or None."""
    here = Path(__file__).resolve().parent.parent
    if not (here / ".git").exists():
        return None
    try:
        commit = subprocess.run(["git", "-C", str(here), "rev-parse", "HEAD"], capture_output=True,
                                text=True, timeout=5, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(here), "status", "--porcelain",
                                "--untracked-files=no"], capture_output=True, text=True,
                               timeout=5, check=True).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return commit + ("-dirty" if dirty else "")


def _provenance(comm, extra):
    """Root attributes describing this run, identical on every rank (rank 0's)."""
    hosts = comm.allgather(socket.gethostname())

    def describe():
        attrs = {
            "petgap_version": __version__,
            "command_line": shlex.join(sys.argv),
            "hostname": hosts[0],
            "hosts": sorted(set(hosts)),
            "start_time": datetime.datetime.now(datetime.timezone.utc).isoformat(
                timespec="seconds"),
            "mpi_size": comm.size,
            "mpi_library": MPI.Get_library_version().replace("\0", "").strip().splitlines()[0],
            "python_version": sys.version.split()[0],
            "numpy_version": np.__version__,
            "h5py_version": h5py.__version__,
            "hdf5_version": h5py.version.hdf5_version,
        }
        commit = _git_commit()
        if commit:
            attrs["git_commit"] = commit
        attrs.update(extra or {})
        return attrs
    return root_decides(comm, describe)


# ------------------------------------------------------------------ attributes
def flatten_attrs(mapping, prefix=""):
    """Flatten nested mappings and dataclasses into ``{"a.b": value}`` for HDF5 attributes.

    Values become what HDF5 stores well: numbers and booleans as NumPy
    scalars, strings as strings, sequences as arrays (of strings if any item is
    a string); ``None`` values are left out (absence means None); anything else
    is stored as ``str(value)``.
    """
    if dataclasses.is_dataclass(mapping) and not isinstance(mapping, type):
        mapping = dataclasses.asdict(mapping)
    out = {}
    for k, v in mapping.items():
        name = f"{prefix}{k}"
        if dataclasses.is_dataclass(v) and not isinstance(v, type):
            v = dataclasses.asdict(v)
        if isinstance(v, dict):
            out.update(flatten_attrs(v, prefix=f"{name}."))
        elif v is None:
            continue
        elif isinstance(v, (bool, np.bool_)):
            out[name] = np.bool_(v)
        elif isinstance(v, str):
            out[name] = v.replace("\0", "")  # HDF5 strings end at a NUL
        elif isinstance(v, (int, float, np.integer, np.floating)):
            out[name] = v
        elif isinstance(v, (list, tuple, np.ndarray)):
            arr = np.asarray(v)
            if arr.dtype.kind in "biuf":
                out[name] = arr
            else:
                out[name] = [str(x).replace("\0", "") for x in np.ravel(arr)]
        else:
            out[name] = str(v).replace("\0", "")
    return out


def _set_attrs(obj, attrs):
    """Write flattened attributes (collectively: same names and values on every rank)."""
    for k, v in flatten_attrs(attrs).items():
        if isinstance(v, list):  # list of strings: a variable-length string array
            obj.attrs.create(k, v, dtype=h5py.string_dtype())
        else:
            obj.attrs[k] = v


#: Attributes that HDF5's dimension-scale API keeps for itself (object references,
#: scale names): bookkeeping of the file format, not petgap's data.
DIMENSION_SCALE_ATTRS = frozenset({"CLASS", "NAME", "DIMENSION_LIST", "REFERENCE_LIST",
                                   "DIMENSION_LABELS"})


def read_attrs(obj):
    """Attributes of a group or dataset as a plain dict (bytes decoded, 0-d arrays unwrapped),
    without the dimension-scale bookkeeping (:data:`DIMENSION_SCALE_ATTRS`)."""
    out = {}
    for k, v in obj.attrs.items():
        if k in DIMENSION_SCALE_ATTRS:
            continue
        if isinstance(v, bytes):
            v = v.decode()
        elif isinstance(v, np.ndarray) and v.dtype.kind == "O":
            v = [x.decode() if isinstance(x, bytes) else x for x in v]
        elif isinstance(v, np.generic):
            v = v.item()
        out[k] = v
    return out


# ---------------------------------------------------------------- the fields
def _xfer(dset):
    dxpl = h5p.create(h5p.DATASET_XFER)
    if dset.file.driver == "mpio":
        dxpl.set_dxpl_mpio(h5fd.MPIO_COLLECTIVE)
    return dxpl


def _slab_spaces(dset, grid):
    """File and memory dataspaces of this rank's rows (empty selections for an empty slab)."""
    start, stop = grid.x_slice.start, grid.x_slice.stop
    rows, ny = stop - start, grid.shape[1]
    fspace = dset.id.get_space()
    mspace = h5s.create_simple((max(rows, 1), ny))
    if rows > 0:
        fspace.select_hyperslab((start, 0), (rows, ny))
    else:
        fspace.select_none()
        mspace.select_none()
    return rows, fspace, mspace


def write_field(group, name, grid, local_array):
    """Write a distributed field as the global ``(nx, ny)`` dataset ``group[name]``.

    Collective: every rank of the file's communicator calls it, with its
    ``grid.local_shape`` slab; each writes its rows ``grid.x_slice`` in one
    collective MPI-IO call (a rank without rows still takes part).  The dataset
    is float32 for a float32 slab (a single-precision run's fields: stored as
    solved, without a double copy of the slab at the write) and float64
    otherwise; :func:`read_field` reads either into float64.  A slab that is
    not C-contiguous in that type (e.g. a view of the FFT buffer) is copied
    first.  Returns the dataset.
    """
    local = np.asarray(local_array)
    if local.shape != tuple(grid.local_shape):
        raise ValueError(f"field {name!r} has local shape {local.shape}, "
                         f"the grid's slab is {tuple(grid.local_shape)}")
    dcpl = h5p.create(h5p.DATASET_CREATE)
    dcpl.set_fill_time(h5d.FILL_TIME_NEVER)  # every element is written below: no fill pass
    dtype = np.float32 if local.dtype == np.float32 else np.float64
    dset = group.create_dataset(name, shape=tuple(grid.shape), dtype=dtype, dcpl=dcpl)
    rows, fspace, mspace = _slab_spaces(dset, grid)
    buf = np.ascontiguousarray(local, dtype=dtype) if rows > 0 \
        else np.zeros((1, grid.shape[1]), dtype=dtype)
    dset.id.write(mspace, fspace, buf, dxpl=_xfer(dset))
    return dset


#: What each field is, for the ``long_name`` and ``units`` attributes of its dataset:
#: (description, "length" or "pressure").
FIELD_LABELS = {
    "topography": ("height of the rough surface", "length"),
    "gap": ("gap between the surfaces", "length"),
    "pressure": ("contact pressure, positive in compression", "pressure"),
    "displacement": ("normal surface displacement of the elastic half-space, zero mean",
                     "length"),
    "flow_pressure": ("fluid pressure of the Reynolds flow through the gap (NaN where no "
                      "fluid flows)", "pressure"),
    "flow_flux_x": ("volume flux per unit width along x, cell-centred", "flux"),
    "flow_flux_y": ("volume flux per unit width along y, cell-centred", "flux"),
}
#: Names of the coordinate datasets (dimension scales) along the grid's axes.
COORDINATES = ("x", "y")


def coordinate_values(grid):
    """Pixel positions ``i dx`` and ``j dy`` along x and y (lengths)."""
    return np.arange(grid.shape[0]) * grid.dx, np.arange(grid.shape[1]) * grid.dy


def read_field(h5, name, grid, out=None):
    """Read this rank's slab of the global dataset ``h5[name]`` (collective).

    ``h5`` is a file or group opened on the grid's communicator; ``out`` an
    optional C-contiguous float64 array of ``grid.local_shape`` to read into.
    A float32 dataset (a single-precision run's) is converted by HDF5 on the way.
    """
    dset = h5[name]
    if tuple(dset.shape) != tuple(grid.shape):
        raise ValueError(f"dataset {dset.name!r} in {dset.file.filename} has shape "
                         f"{tuple(dset.shape)}, the grid is {tuple(grid.shape)}")
    if out is None:
        out = np.empty(grid.local_shape, dtype=np.float64)
    elif out.shape != tuple(grid.local_shape) or out.dtype != np.float64 \
            or not out.flags.c_contiguous:
        raise ValueError(f"out must be a C-contiguous float64 array of shape {grid.local_shape}")
    rows, fspace, mspace = _slab_spaces(dset, grid)
    buf = out if rows > 0 else np.empty((1, grid.shape[1]))
    dset.id.read(mspace, fspace, buf, dxpl=_xfer(dset))
    return out


# ------------------------------------------------------------- the result file
class ResultFile:
    """An HDF5 result file open on every rank of a communicator.

    Make one with :meth:`create` (new run), :meth:`open_for_resume` (continue a
    sweep) or :meth:`open` (read).  All methods are collective.  Use it as a
    context manager: leaving the block normally closes the file and marks it
    ``complete``; leaving it by an exception that every rank raised closes it
    still marked incomplete; if only some ranks raised, the file is left open
    (closing is collective and the other ranks may never get there) and the
    caller is expected to abort the job, as the CLI does.

    Attributes
    ----------
    file : h5py.File
    path : pathlib.Path
    comm : mpi4py.MPI.Comm
    """

    def __init__(self, h5file, path, comm, writable):
        self.file, self.path, self.comm, self.writable = h5file, Path(path), comm, writable
        self._failure_comm = comm.Dup()  # reserved for the exception agreement in __exit__

    # ------------------------------------------------------------ opening
    @classmethod
    def create(cls, path, comm=None, overwrite=False, provenance=None):
        """Create a result file (collective) and write the provenance at its root.

        Parameters
        ----------
        path : str or Path
            The file, written in place (not renamed at the end); until
            :meth:`close` its root attribute ``complete`` is False.
        comm : mpi4py.MPI.Comm, optional
            Communicator of the grid (default ``COMM_WORLD``).
        overwrite : bool
            Replace an existing file.  Otherwise an existing file raises
            :class:`ResultExistsError` on every rank, naming ``--overwrite``.
        provenance : mapping, optional
            More root attributes (flattened; see :func:`flatten_attrs`); they
            override the standard ones of the same name.  Rank 0's copy is used.
        """
        require_parallel_h5py()
        comm = _default_comm(comm)
        check_output_path(path, comm, overwrite)
        attrs = _provenance(comm, provenance)
        h5file = h5py.File(path, "w", driver="mpio", comm=comm)
        self = cls(h5file, path, comm, writable=True)
        _set_attrs(h5file, attrs)
        h5file.attrs["complete"] = np.bool_(False)
        h5file.flush()
        return self

    @classmethod
    def open_for_resume(cls, path, comm=None):
        """Open an existing result file to continue its sweep (collective).

        The root attribute ``complete`` goes back to False until :meth:`close`.
        :meth:`completed_steps` tells which steps need no recomputing;
        :meth:`begin_step` replaces a step that was left incomplete.
        """
        require_parallel_h5py()
        comm = _default_comm(comm)
        path = Path(path)
        root_decides(comm, lambda: _check_is_result(path))
        h5file = h5py.File(path, "r+", driver="mpio", comm=comm)
        self = cls(h5file, path, comm, writable=True)
        h5file.attrs["complete"] = np.bool_(False)
        h5file.attrs["resume_count"] = int(h5file.attrs.get("resume_count", 0)) + 1
        h5file.flush()
        return self

    @classmethod
    def open_for_append(cls, path, comm=None):
        """Reopen a result file of the current run to add a step (collective).

        Unlike :meth:`open_for_resume` it changes no root attribute: a run
        keeps its file closed while it solves, so that a process killed in the
        middle of a solve cannot leave the file half-written, and reopens it
        only to write each finished step.
        """
        require_parallel_h5py()
        comm = _default_comm(comm)
        path = Path(path)
        root_decides(comm, lambda: _check_is_result(path))
        return cls(h5py.File(path, "r+", driver="mpio", comm=comm), path, comm, writable=True)

    @classmethod
    def open(cls, path, comm=None):
        """Open a result file read-only on every rank of ``comm`` (collective)."""
        require_parallel_h5py()
        comm = _default_comm(comm)
        path = Path(path)
        root_decides(comm, lambda: _check_is_result(path))
        return cls(h5py.File(path, "r", driver="mpio", comm=comm), path, comm, writable=False)

    # ------------------------------------------------------------ content
    @property
    def root(self):
        """The root group."""
        return self.file["/"]

    @property
    def complete(self):
        """Whether the file was closed after a successful run."""
        return bool(self.file.attrs.get("complete", False))

    def attrs(self, obj="/"):
        """Attributes of a group or dataset (by object or path) as a plain dict."""
        return read_attrs(self.file[obj] if isinstance(obj, str) else obj)

    def set_attrs(self, obj, attrs):
        """Write attributes (nested mappings and dataclasses flattened) on a group or dataset."""
        _set_attrs(self.file[obj] if isinstance(obj, str) else obj, attrs)

    def write_coordinates(self, grid, length_unit="1", group=None):
        """Datasets ``x`` and ``y`` (pixel positions) in ``group`` (default: root) as HDF5
        dimension scales.

        Collective.  Fields written afterwards into the same group by
        :meth:`write_field` have them attached to their two dimensions, so that
        netCDF-aware readers (xarray with h5netcdf, ParaView, Panoply) show each field
        as a map on labelled axes; each step group has its own pair (``nx + ny``
        numbers), so that a step opens on its own.  Nothing is written if the group
        has them already (a resumed run).
        """
        where = self.file if group is None else group
        if all(n in where for n in COORDINATES):
            return
        for name, values, axis in zip(COORDINATES, coordinate_values(grid), ("X", "Y")):
            dset = where.create_dataset(name, data=values)   # every rank the same data
            _set_attrs(dset, {"units": length_unit, "long_name": f"{name} position of the pixel",
                              "axis": axis})
            dset.make_scale(name)

    def write_field(self, name, grid, local_array, group=None, attrs=None, units=None):
        """:func:`write_field` into ``group`` (default: root), with optional attributes.

        ``units``: the unit of lengths and of pressures (``{"length": ..., "pressure":
        ...}``); with it a field named in :data:`FIELD_LABELS` gets its ``units`` and
        ``long_name``.  The coordinates of :meth:`write_coordinates`, if the file has
        them, become the field's dimension scales.
        """
        dset = write_field(self.file if group is None else group, name, grid, local_array)
        labels = {}
        if units is not None and name in FIELD_LABELS:
            description, kind = FIELD_LABELS[name]
            labels = {"long_name": description, "units": units[kind]}
        if attrs or labels:
            _set_attrs(dset, dict(attrs or {}, **labels))
        where = self.file if group is None else group
        if all(n in where for n in COORDINATES):
            for dim, n in enumerate(COORDINATES):
                dset.dims[dim].attach_scale(where[n])
        return dset

    def read_field(self, name, grid, group=None, out=None):
        """:func:`read_field` from ``group`` (default: root)."""
        return read_field(self.file if group is None else group, name, grid, out)

    def flush(self):
        """Flush HDF5's buffers to the file (collective)."""
        self.file.flush()

    # -------------------------------------------------------------- steps
    def steps(self):
        """Indices of all step groups, sorted."""
        return sorted(int(k[len(STEP_PREFIX):]) for k in self.file
                      if k.startswith(STEP_PREFIX) and k[len(STEP_PREFIX):].isdigit())

    def completed_steps(self):
        """Indices of the step groups whose ``complete`` attribute is True, sorted."""
        return [i for i in self.steps()
                if bool(self.file[step_name(i)].attrs.get("complete", False))]

    def step(self, index):
        """The group of step ``index``."""
        return self.file[step_name(index)]

    def begin_step(self, index, attrs=None):
        """Create the group of step ``index``, marked incomplete (collective).

        A step left incomplete by an interrupted run is replaced; a complete one
        is an error (its results would be lost).
        """
        name = step_name(index)
        if name in self.file:
            if bool(self.file[name].attrs.get("complete", False)):
                raise ValueError(f"step {index} in {self.path} is complete already; "
                                 f"it is not recomputed")
            del self.file[name]
        group = self.file.create_group(name)
        group.attrs["index"] = int(index)
        group.attrs["complete"] = np.bool_(False)
        if attrs:
            _set_attrs(group, attrs)
        return group

    def end_step(self, group, attrs=None):
        """Write the step's attributes, then ``complete = True``, then flush (collective)."""
        if attrs:
            _set_attrs(group, attrs)
        group.attrs["complete"] = np.bool_(True)
        self.file.flush()

    # ------------------------------------------------------------ closing
    def close(self, complete=True):
        """Mark the file complete (if writable and ``complete``) and close it (collective)."""
        if self.file is None:
            return
        if self.writable:
            if complete:
                self.file.attrs["end_time"] = datetime.datetime.now(
                    datetime.timezone.utc).isoformat(timespec="seconds")
            self.file.attrs["complete"] = np.bool_(bool(complete))
        self.file.close()
        self.file = None
        self._failure_comm.Free()

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.close(complete=True)
            return False
        if self.file is not None and failed_everywhere(self._failure_comm):
            if self.writable and isinstance(exc, OSError):
                # An I/O error inside HDF5 (a full disk, a failing file system).  Closing
                # would flush metadata pointing at data that never reached the disk, so
                # that the whole file, complete steps included, no longer opens
                # ("truncated file"), and h5py 3.7's close loops forever on the object
                # whose write failed.  Leave the file as its last flush made it (every
                # complete step readable), keep the handle away from the collector, and
                # let the caller end the process without closing it (ResultWriteError).
                _ABANDONED.append(self.file)
                self.file = None
                raise ResultWriteError(
                    f"writing {self.path} failed: {exc}; the file is left as its last complete "
                    f"step made it: rerun the same command to continue once the cause (a full "
                    f"disk?) is fixed") from exc
            self.close(complete=False)
        return False

    def __repr__(self):
        state = "closed" if self.file is None else ("writable" if self.writable else "read-only")
        return f"ResultFile({str(self.path)!r}, {state}, ranks={self.comm.size})"


#: Files left open after a failed write (see :meth:`ResultFile.__exit__`).
_ABANDONED = []


def root_attributes(path):
    """The root attributes of the HDF5 file ``path``, read serially by the calling rank alone.

    For a quick look before any collective open (is it this scene's unfinished
    run?); raises OSError when the file cannot be read as HDF5.
    """
    with h5py.File(path, "r") as f:
        return dict(f.attrs)


def unreadable(exc):
    """Why HDF5 could not open a file, from its OSError ``exc``: ``"truncated: ..."``
    with the bytes it has and those its superblock states, or HDF5's own words."""
    cut = re.search(r"truncated file: eof = (\d+).*stored_eof = (\d+)", str(exc))
    if cut:
        return (f"truncated: {cut[1]} bytes of the {cut[2]} its HDF5 superblock states (a "
                f"copy cut short, a full disk, or a job killed while creating it)")
    return f"not readable as HDF5 ({exc})"


def _check_is_result(path):
    if not path.is_file():
        raise FileNotFoundError(f"result file {path} not found")
    try:
        f = h5py.File(path, "r")  # rank 0 alone, serial: a quick look at the root
    except OSError as exc:
        raise OSError(f"result file {path} is {unreadable(exc)}") from None
    with f:
        if "petgap_version" not in f.attrs:
            raise ValueError(f"{path} is not a petgap result file (no petgap_version attribute)")
