"""Measured topographies in the instruments' own file formats, read by SurfaceTopography.

petgap reads its own interchange formats (``.npy``, HDF5) slab by slab
(:mod:`petgap.surfaces.topography`); every other file goes to SurfaceTopography
(ContactEngineering's reader library, https://github.com/ContactEngineering/SurfaceTopography),
which detects the format from the content and knows the instruments' metadata: the
physical size of the map and the unit of its heights.  Formats read and tested here
(tests/surfaces/test_measured.py): Igor binary waves (``.ibw``), WSxM (``.top``),
netCDF as SurfaceTopography writes it (``.nc``), MATLAB (``.mat``), plain-text height
matrices and x-y-z columns (``.txt``, ``.asc``).  SurfaceTopography reads many more
(Gwyddion, Digital Instruments/Bruker, Zygo DATX, Sensofar, Keyence, x3p, OPDx, ...)
through the same call; they are not tested by petgap.

A map is read whole on rank 0 (instrument files are small next to a solve:
a 4096^2 map is 128 MiB), conditioned there with SurfaceTopography's own methods
(undefined points filled, trend removed, heights in the requested unit) and handed
to each rank as its slab.  Errors are decided on rank 0 and raised on every rank.
"""
import contextlib
import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mpi4py import MPI


#: Trend removal of :func:`read_measured`: SurfaceTopography's ``detrend`` modes
#: (``center``: the mean; ``height``: the plane of least squares, which minimises the rms
#: height; ``slope``: the plane of the mean slope, which minimises the rms slope;
#: ``curvature``: the quadratic surface of least squares).
DETRENDS = ("none", "center", "height", "slope", "curvature")
#: What to do with undefined points (NaN or masked) in a map.
UNDEFINED = ("refuse", "harmonic")


@dataclass
class Measurement:
    """A measured map and what its file says about it (on rank 0; ``heights`` None elsewhere).

    Attributes
    ----------
    heights : ndarray, shape ``(nx, ny)``
        Heights in ``unit`` (axis 0 along x).
    physical_size : tuple or None
        ``(Lx, Ly)`` in ``unit``, if the file knows it.
    unit : str or None
        Length unit of heights and sizes, if the file knows it.
    periodic : bool
        Whether the file says the map is periodic.
    reader : str
        SurfaceTopography's reader class that read it (the format).
    channel : str
        The data channel read.
    undefined : int
        Undefined points in the file (filled if ``undefined = "harmonic"``).
    """
    heights: np.ndarray
    physical_size: tuple
    unit: str
    periodic: bool
    reader: str
    channel: str
    undefined: int


def surface_topography():
    """The SurfaceTopography package (imported on first use, its import-time output muted)."""
    with contextlib.redirect_stdout(io.StringIO()):
        import SurfaceTopography  # deferred: only measured maps need it, and it is slow to load
    return SurfaceTopography


def condition_map(heights, path, *, detrend="none", undefined="refuse"):
    """A map already read (``.npy``, HDF5: no unit, pixel-sized), conditioned like a measured
    one (:func:`read_measured`); its :class:`Measurement`.  ``path`` names it in errors."""
    heights = np.asarray(heights)
    if heights.ndim != 2 or heights.dtype.kind != "f":
        raise ValueError(f"topography {path} holds a {heights.ndim}D {heights.dtype} array; "
                         f"a topography is a 2D floating-point array")
    topography = surface_topography().Topography(np.ma.masked_invalid(heights),
                                                 tuple(float(n) for n in heights.shape))
    return _condition(path, topography, "petgap", "(the array)", None, detrend, undefined,
                      None)


def _open_channel(path, channel):
    """SurfaceTopography's reader of ``path`` and its 2D data channel (by name, or the
    file's default); ValueError naming the file otherwise."""
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            reader = surface_topography().open_topography(str(path))
    except Exception as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ValueError(f"cannot read topography {path}: SurfaceTopography does not recognise "
                         f"its format ({first})") from None
    names = [c.name for c in reader.channels]
    if channel is not None and channel not in names:
        raise ValueError(f"topography {path} has no channel {channel!r}; channels: "
                         f"{', '.join(repr(n) for n in names)}")
    chosen = reader.default_channel if channel is None else reader.channels[names.index(channel)]
    if chosen.dim != 2:
        raise ValueError(f"topography {path} (channel {chosen.name!r}) is a line scan with "
                         f"{chosen.nb_grid_pts} points; petgap needs a 2D map")
    return reader, chosen


def read_measured(path, *, channel=None, unit=None, detrend="none", undefined="refuse"):
    """Read and condition a measured map with SurfaceTopography (the calling rank alone).

    Parameters
    ----------
    path : str or os.PathLike
    channel : str, optional
        The data channel (by name) of a file with several; default: the file's default.
    unit : str, optional
        Length unit wanted (``"um"``, ``"nm"``, ...): heights and sizes are converted
        from the file's unit.  ``None`` keeps the file's.
    detrend : str
        One of :data:`DETRENDS`: remove the mean (``center``), a plane (``height``: least
        squares; ``slope``: the mean slope) or a quadratic surface (``curvature``).
    undefined : str
        One of :data:`UNDEFINED`: refuse a map with undefined points, or fill them
        with the harmonic function that matches the defined points around them.

    Raises
    ------
    ValueError
        The format is not recognised, the file is a line scan, the channel does not
        exist, the map has undefined points (with ``refuse``), a unit cannot be
        converted; the message names the file and what is allowed.
    """
    if detrend not in DETRENDS:
        raise ValueError(f"detrend = {detrend!r} is not allowed; allowed: {', '.join(DETRENDS)}")
    if undefined not in UNDEFINED:
        raise ValueError(f"undefined = {undefined!r} is not allowed; allowed: "
                         f"{', '.join(UNDEFINED)}")
    if not Path(path).exists():
        raise FileNotFoundError(f"topography file {path} does not exist")
    if not Path(path).is_file():
        raise ValueError(f"topography path {path} is not a file")
    reader, chosen = _open_channel(path, channel)
    sizes = chosen.physical_sizes
    kwargs = {} if sizes is not None else {"physical_sizes": tuple(float(n) for n in
                                                                   chosen.nb_grid_pts)}
    with contextlib.redirect_stdout(io.StringIO()):
        topography = reader.topography(channel_index=chosen.index, **kwargs)
    return _condition(path, topography, type(reader).__name__, str(chosen.name), unit,
                      detrend, undefined, sizes)


def _condition(path, topography, reader, channel, unit, detrend, undefined, sizes):
    """Fill, convert and detrend a read topography; its :class:`Measurement`."""
    missing = int(np.count_nonzero(np.ma.getmaskarray(topography.heights()))) \
        if topography.has_undefined_data else 0
    if missing and undefined == "refuse":
        raise ValueError(f"topography {path} has {missing} undefined points (NaN or masked); "
                         f"set surface.undefined = \"harmonic\" to fill them, or fill them "
                         f"before")
    if missing:
        topography = topography.interpolate_undefined_data("harmonic")
    file_unit = topography.unit
    if unit is not None and file_unit is not None and unit != file_unit:
        try:
            topography = topography.to_unit(unit)
            topography.heights()        # the conversion is lazy: make it fail here
        except Exception as exc:
            raise ValueError(f"topography {path}: cannot convert its unit {file_unit!r} to "
                             f"{unit!r}: {exc}") from None
    if detrend != "none":
        topography = topography.detrend(detrend_mode=detrend)
    heights = np.ma.getdata(topography.heights()).astype(np.float64, copy=True)
    return Measurement(heights=heights,
                       physical_size=None if sizes is None else
                       tuple(float(s) for s in topography.physical_sizes),
                       unit=topography.unit, periodic=bool(topography.is_periodic),
                       reader=reader, channel=channel, undefined=missing)


def read_header(path, channel=None, unit=None):
    """Shape, physical size and unit of a measured map, without its heights (calling rank).

    ``{"shape": (nx, ny), "size": (Lx, Ly) or None, "unit": str or None, "periodic":
    bool}``; the size is converted to ``unit`` when the file and ``unit`` both name one;
    ``periodic`` is the file's own say (instrument maps are not, as a rule).
    """
    _, chosen = _open_channel(path, channel)
    size, file_unit = chosen.physical_sizes, chosen.unit
    if size is not None and unit is not None and file_unit is not None and unit != file_unit:
        from SurfaceTopography.Support.UnitConversion import get_unit_conversion_factor  # deferred: with the package
        try:
            factor = get_unit_conversion_factor(file_unit, unit)
        except Exception as exc:
            raise ValueError(f"topography {path}: cannot convert its unit {file_unit!r} to "
                             f"{unit!r}: {exc}") from None
        size, file_unit = tuple(factor * float(v) for v in size), unit
    return {"shape": tuple(int(n) for n in chosen.nb_grid_pts),
            "size": None if size is None else tuple(float(v) for v in size), "unit": file_unit,
            "periodic": bool(getattr(chosen, "is_periodic", False))}


def scatter_rows(grid, heights):
    """Each rank's rows ``grid.x_slice`` of a global array held by rank 0 (collective)."""
    comm = grid.comm
    counts = comm.gather((grid.x_slice.stop - grid.x_slice.start) * grid.ny, root=0)
    local = np.empty(grid.local_shape)
    if comm.rank == 0:
        send = np.ascontiguousarray(heights, dtype=np.float64)
        offsets = np.concatenate([[0], np.cumsum(counts[:-1])])
        comm.Scatterv([send, counts, offsets, MPI.DOUBLE], local, root=0)
    else:
        comm.Scatterv(None, local, root=0)
    return local
