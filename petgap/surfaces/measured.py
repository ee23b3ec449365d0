"""Measured topographies in the instruments' own file formats, read by SurfaceTopography.

petgap reads its own interchange formats (``.npy``, HDF5) slab by slab
(:mod:`petgap.surfaces.topography`); every other file goes to SurfaceTopography
(ContactEngineering's reader library, https://github.com/ContactEngineering/SurfaceTopography),
which reads the format the extension names and knows the instruments' metadata: the
physical size of the map and the unit of its heights.  Formats read and tested here
(tests/surfaces/test_measured.py): Igor binary waves (``.ibw``), WSxM (``.top``),
netCDF as SurfaceTopography writes it (``.nc``), MATLAB (``.mat``), plain-text height
matrices and x-y-z columns (``.txt``, ``.asc``).  SurfaceTopography reads many more
(Gwyddion, Digital Instruments/Bruker, Zygo DATX, Sensofar, Keyence, x3p, OPDx, ...)
through the same call; they are not tested by petgap.

Orientation, one rule for every reader: ``heights[i, j]`` is the point ``(x_i, y_j)``,
and the first index, x (the axis petgap distributes over the ranks), is the file's rows:
the first axis of an array (``.npy``, HDF5, MATLAB, netCDF as SurfaceTopography writes it,
whose variable is ``heights(x, y)``) and the lines of a text matrix, so that one array
written to any of these files is one map, ``nx`` its number of rows.  x-y-z columns name
each point's x and y.  Instrument images (Igor, WSxM, Gwyddion, ...) come as
SurfaceTopography gives them: x along the scan lines, the image's horizontal axis as the
instrument shows it.  A text matrix's header size (``Width``, along a line) is then
``Ly``.

A map is read whole on rank 0 (instrument files are small next to a solve:
a 4096^2 map is 128 MiB), conditioned there with SurfaceTopography's own methods
(undefined points filled, trend removed, heights in the requested unit) and handed
to each rank as its slab.  Errors are decided on rank 0 and raised on every rank.

A file's extension chooses the readers tried: the readers SurfaceTopography lists for
it (any of its text readers for a text file), so that a file whose content is not what
its name says is refused with both named, rather than read by another reader that
accepts anything (SurfaceTopography's SRTM reader takes any file of ``2 n^2`` bytes as
an ``n x n`` map); a file whose extension no reader claims is detected by content among
the readers that check a signature.  Every error leads with the file and the reason.

Third-party readers must not hang a run.  Two bounds see to it: a file that starts as a
WSxM file must hold its header's ``[Header end]`` line (SurfaceTopography's WSxM reader
reads header lines until it meets that one, and at the end of a file cut inside its
header reads empty lines forever), and every call into SurfaceTopography runs under a
time limit (:func:`time_bound`) that interrupts the reader where it loops in Python.
"""
import _thread
import contextlib
import io
import math
import os
import signal
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mpi4py import MPI


#: Trend removal of :func:`read_measured`: SurfaceTopography's ``detrend`` modes
#: (``center``: the mean; ``height``: the plane of least squares, which minimises the rms
#: height; ``slope``: the plane of the mean slope, which minimises the rms slope;
#: ``curvature``: the quadratic surface of least squares), and ``lines``
#: (:func:`level_lines`), which SurfaceTopography does not have.
DETRENDS = ("none", "center", "height", "slope", "curvature", "lines")


def level_lines(heights):
    """``heights`` with the straight line of least squares taken off each line along x
    (``heights[:, j]``), each line's own.

    An AFM scans line by line along x; between lines the tip's height drifts (thermal
    drift, the feedback, the piezo's creep), so each line carries its own offset and tilt,
    which a plane fitted to the whole map cannot remove: the map shows stripes along x,
    and the steps between lines are slopes along y that no surface has.  Levelling each
    line removes them, and with them any real slope along x longer than a line: use it on
    maps whose lines show such steps, not on maps of a surface with a known tilt or form.
    """
    heights = np.asarray(heights, dtype=np.float64)
    n = heights.shape[0]
    x = np.arange(n) - (n - 1) / 2          # centred: offset and slope are independent
    offset = heights.mean(axis=0)
    slope = (x @ heights) / (x @ x) if n > 1 else np.zeros(heights.shape[1])
    return heights - offset[None, :] - x[:, None] * slope[None, :]
#: What to do with undefined points (NaN or masked) in a map.
UNDEFINED = ("refuse", "harmonic")

#: The length units petgap converts between, by the spellings it accepts (scenes, files and
#: SurfaceTopography's readers), each to its canonical name: the one results and figures
#: print.  ASCII names where there is one ("um", not the micro sign), so that labels and
#: attributes read the same everywhere.
LENGTH_UNITS = {
    "m": "m", "meter": "m", "metre": "m", "meters": "m", "metres": "m",
    "mm": "mm", "millimeter": "mm", "millimetre": "mm",
    "um": "um", "\u00b5m": "um", "\u03bcm": "um", "micron": "um", "microns": "um",
    "micrometer": "um", "micrometre": "um",
    "nm": "nm", "nanometer": "nm", "nanometre": "nm",
    "\u00c5": "\u00c5", "\u212b": "\u00c5", "A": "\u00c5", "angstrom": "\u00c5",
    "Angstrom": "\u00c5", "angstroms": "\u00c5",
    "pm": "pm", "km": "km",
}
#: Metres per canonical unit.
METRES = {"m": 1.0, "mm": 1e-3, "um": 1e-6, "nm": 1e-9, "\u00c5": 1e-10, "pm": 1e-12,
          "km": 1e3}


def allowed_length_units():
    """The units :data:`LENGTH_UNITS` accepts, each with its other spellings, in words."""
    spellings = {}
    for name, canonical in LENGTH_UNITS.items():
        spellings.setdefault(canonical, []).append(name)
    return ", ".join(c + (f" ({', '.join(n for n in names if n != c)})" if len(names) > 1
                          else "") for c, names in spellings.items())


def length_unit(name, key="units.length"):
    """The canonical name of a length unit (:data:`LENGTH_UNITS`), or a ValueError naming
    ``key``, the value and the spellings allowed."""
    canonical = LENGTH_UNITS.get(str(name).strip())
    if canonical is None:
        canonical = LENGTH_UNITS.get(str(name).strip().lower())
    if canonical is None:
        raise ValueError(f"{key} = {name!r} is not a length unit petgap converts; allowed: "
                         f"{allowed_length_units()}, or \"1\" to keep the "
                         f"file's numbers")
    return canonical


def canonical_file_unit(name):
    """A file's own unit in canonical spelling; None if the file names none, and the name as
    the file gives it if it is not a length (a phase or current channel)."""
    if name is None:
        return None
    return LENGTH_UNITS.get(str(name).strip(), str(name))


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
    check_map_shape(path, heights.shape)
    topography = surface_topography().Topography(np.ma.masked_invalid(heights),
                                                 tuple(float(n) for n in heights.shape))
    return _condition(path, topography, "petgap", "(the array)", None, detrend, undefined,
                      None)


def check_file(path):
    """Raise unless ``path`` is a regular file with content: FileNotFoundError, or a
    ValueError naming it (a directory, an empty file)."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"topography file {path} does not exist")
    if not path.is_file():
        raise ValueError(f"topography path {path} is not a file")
    if path.stat().st_size == 0:
        raise ValueError(f"topography file {path} is empty (0 bytes)")


#: The fewest points along each axis of a map: one row or column is a line scan.
MIN_POINTS = 2


def check_map_shape(what, shape):
    """Raise a ValueError naming ``what`` unless ``shape`` is a map: 2D, at least
    :data:`MIN_POINTS` points along each axis (whatever the number of ranks)."""
    if len(shape) == 2 and min(shape) < MIN_POINTS:
        raise ValueError(f"topography {what} has {shape[0]} x {shape[1]} points: a line scan "
                         f"(or nothing), not a map; allowed: at least {MIN_POINTS} points along "
                         f"x and along y")


#: A call into SurfaceTopography may take :data:`READ_SECONDS` plus
#: :data:`READ_SECONDS_PER_MIB` per MiB of the file before it is interrupted: a slow
#: disk and a text reader parsing a large map stay well inside it, a reader looping
#: at the end of a file does not.
READ_SECONDS = 60.0
READ_SECONDS_PER_MIB = 2.0


class _Overtime(BaseException):
    """Raised in the main thread by :func:`time_bound`'s timer; not an Exception, so that
    a reader's ``except Exception`` (format detection tries one reader after another)
    does not swallow it."""


@contextlib.contextmanager
def time_bound(path, what="SurfaceTopography's reader"):
    """Interrupt the block (a call into a third-party reader of ``path``) when it runs
    longer than its limit (:data:`READ_SECONDS`, :data:`READ_SECONDS_PER_MIB`); a
    ValueError naming the file then.

    A timer thread simulates a signal in the main thread (``_thread.interrupt_main``;
    no signal reaches the process, so MPI's threads are not disturbed), whose handler
    raises where the reader is, at its next Python instruction: a loop in Python (as the
    WSxM reader's) is stopped, a single long call into C is not.  Off the main thread no
    signal handler can be set, and the block runs unbounded.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    seconds = READ_SECONDS + READ_SECONDS_PER_MIB * os.path.getsize(path) / 2**20
    state = {"done": False, "fired": False}

    def fire():
        state["fired"] = True
        _thread.interrupt_main(signal.SIGALRM)

    def interrupt(signum, frame):
        if state["fired"] and not state["done"]:
            raise _Overtime
        if callable(old):   # a real SIGALRM, meant for whoever handled it before
            old(signum, frame)

    old = signal.signal(signal.SIGALRM, interrupt)
    timer = threading.Timer(seconds, fire)
    timer.daemon = True
    timer.start()
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            yield
    except _Overtime:
        raise ValueError(f"topography file {path}: {what} did not finish within {seconds:.3g} s "
                         f"and was stopped (a damaged or cut file makes some readers loop); "
                         f"check the file, or convert it to .npy or HDF5") from None
    finally:
        state["done"] = True
        timer.cancel()
        signal.signal(signal.SIGALRM, old)


#: SurfaceTopography's text readers (by format): a text file may be any of them.
TEXT_FORMATS = ("xyz", "asc")
#: Formats never tried unless the extension names them: SRTM height files have no
#: signature, and the reader takes any file of ``2 n^2`` bytes as an ``n x n`` map.
UNSIGNED_FORMATS = ("hgt",)


def readers_for(path):
    """The SurfaceTopography readers to try on ``path``, in SurfaceTopography's order,
    and whether its extension chose them (module docstring)."""
    readers = surface_topography().IO.readers
    suffix = Path(path).suffix.lower().lstrip(".")
    claim = {r.format() for r in readers if suffix in getattr(r, "_file_extensions", ())}
    if claim & set(TEXT_FORMATS):
        claim |= set(TEXT_FORMATS)
    if claim:
        return [r for r in readers if r.format() in claim], True
    return [r for r in readers if r.format() not in UNSIGNED_FORMATS], False


#: SurfaceTopography's readers of text matrices: they take a file's lines as y (its x runs
#: along a line, as across an image).  petgap takes a matrix's lines as x, the first index,
#: as it takes the first axis of every array it reads (``.npy``, HDF5, MATLAB, netCDF), so
#: that one array written to any of these files is one map (module docstring).
LINES_ARE_X = ("asc",)


def _transposed(reader):
    """Whether petgap's map is the transpose of what ``reader`` gives (:data:`LINES_ARE_X`)."""
    return reader.format() in LINES_ARE_X


def _transpose(topography, sizes):
    """A read topography with its axes exchanged, and its header's physical size."""
    heights = topography.heights()
    swapped = surface_topography().Topography(
        np.ma.masked_array(np.ma.getdata(heights).T, mask=np.ma.getmaskarray(heights).T),
        tuple(float(v) for v in topography.physical_sizes)[::-1], unit=topography.unit,
        periodic=topography.is_periodic)
    return swapped, None if sizes is None else tuple(sizes)[::-1]


#: First line of a WSxM file, and the line that ends its header.
WSXM_SIGNATURE, WSXM_HEADER_END = b"WSxM file copyright", b"[Header end]"


def check_wsxm_header(path, limit=1 << 20):
    """Raise a ValueError naming ``path`` if it starts as a WSxM file but its header
    has no ``[Header end]`` line (within the header size it states, or ``limit``
    bytes): SurfaceTopography's WSxM reader would read empty lines forever."""
    with open(path, "rb") as f:
        if f.read(len(WSXM_SIGNATURE)) != WSXM_SIGNATURE:
            return
        f.seek(0)
        head = f.read(limit)
    lines = head.splitlines()
    stated = None
    if len(lines) > 2 and lines[2].startswith(b"Image header size:"):
        try:
            stated = int(lines[2].split(b":", 1)[1])
        except ValueError:
            pass
    within = head if stated is None else head[:max(stated, 0)]
    if WSXM_HEADER_END not in [line.strip() for line in within.splitlines()]:
        says = "" if stated is None else f", of the {stated} its header states"
        raise ValueError(f"topography file {path}: a WSxM file cut inside its header (no "
                         f"[Header end] line in its {len(within)} bytes{says}); the file is "
                         f"truncated or damaged")


def _first_line(exc):
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def _open_reader(path):
    """The first of :func:`readers_for` that accepts ``path``; ValueError naming the file
    and, if its extension chose the readers, what the extension says."""
    check_wsxm_header(path)
    candidates, by_extension = readers_for(path)
    failures = []
    with time_bound(path):
        for reader in candidates:
            try:
                return reader(str(path))
            except Exception as exc:
                failures.append(f"{reader.__name__}: {_first_line(exc)}")
    if by_extension:
        names = " or ".join(dict.fromkeys(r._name for r in candidates))
        raise ValueError(f"topography file {path}: its extension {Path(path).suffix} says "
                         f"{names}, but the content is not: SurfaceTopography does not "
                         f"recognise its format ({'; '.join(failures)})")
    raise ValueError(f"topography file {path}: SurfaceTopography does not recognise its "
                     f"format (no reader claims the extension {Path(path).suffix or '(none)'}, "
                     f"and none of them recognises the content)")


def _open_channel(path, channel):
    """SurfaceTopography's reader of ``path`` and its 2D data channel (by name, or the
    file's default), checked (:func:`check_channel`); ValueError naming the file otherwise."""
    check_file(path)
    reader = _open_reader(path)
    chosen = reader.default_channel if channel is None else \
        choose_channel(path, reader.channels, channel)
    if chosen.dim != 2:
        raise ValueError(f"topography {path} (channel {chosen.name!r}) is a line scan with "
                         f"{chosen.nb_grid_pts} points; petgap needs a 2D map")
    check_channel(path, chosen)
    return reader, chosen


def choose_channel(path, channels, channel):
    """The channel ``channel`` names among a file's ``channels``: by its index (an int, or a
    string of digits that is no channel's name) or by its name, which must then be one
    channel's only; a ValueError naming ``surface.channel`` and listing the channels with
    their indices otherwise."""
    names = [str(c.name) for c in channels]
    listing = ", ".join(f"{i}: {n!r}" for i, n in enumerate(names))
    if isinstance(channel, str) and channel in names:
        found = [i for i, n in enumerate(names) if n == channel]
        if len(found) > 1:
            raise ValueError(f"surface.channel = {channel!r}: topography {path} has "
                             f"{len(found)} channels of that name (indices "
                             f"{', '.join(map(str, found))}); allowed: a channel's index, "
                             f"channels: {listing}")
        return channels[found[0]]
    index = channel if isinstance(channel, int) and not isinstance(channel, bool) else \
        int(channel) if isinstance(channel, str) and channel.isdigit() else None
    if index is None or not 0 <= index < len(channels):
        raise ValueError(f"surface.channel = {channel!r}: topography {path} has no channel "
                         f"{channel!r}; allowed: a name or an index of its channels: {listing}")
    return channels[index]


def check_channel(path, channel):
    """What a reader's header says about a 2D channel, checked before its data are read: a
    map (:func:`check_map_shape`), a positive finite physical size, and as many bytes in
    the file as the header promises where the reader says where its data start."""
    check_map_shape(path, tuple(channel.nb_grid_pts))
    sizes = channel.physical_sizes
    if sizes is not None and not all(math.isfinite(float(v)) and float(v) > 0 for v in sizes):
        raise ValueError(f"topography file {path}: its header gives the physical size "
                         f"{' x '.join(f'{float(v):g}' for v in sizes)} {channel.unit or ''}; "
                         f"allowed: a size > 0 and finite along x and y (a damaged header?)")
    tags = getattr(channel, "tags", None) or {}
    if "file_offset" in tags and "dtype" in tags:
        need = int(np.prod(channel.nb_grid_pts)) * np.dtype(tags["dtype"]).itemsize
        held = os.path.getsize(path) - int(tags["file_offset"])
        if held < need:
            raise ValueError(f"topography file {path} is truncated: its header promises "
                             f"{channel.nb_grid_pts[0]} x {channel.nb_grid_pts[1]} heights "
                             f"({need} bytes), the file holds {max(held, 0)} bytes of data")


def read_measured(path, *, channel=None, unit=None, detrend="none", undefined="refuse"):
    """Read and condition a measured map with SurfaceTopography (the calling rank alone).

    Parameters
    ----------
    path : str or os.PathLike
    channel : str or int, optional
        The data channel of a file with several, by name or index
        (:func:`choose_channel`); default: the file's default.
    unit : str, optional
        Length unit wanted (``"um"``, ``"nm"``, ...; a scene's ``units.length``): heights
        and sizes are converted from the file's unit.  ``None`` keeps the file's.
    detrend : str
        One of :data:`DETRENDS`: remove the mean (``center``), a plane (``height``: least
        squares; ``slope``: the mean slope) or a quadratic surface (``curvature``).
    undefined : str
        One of :data:`UNDEFINED`: refuse a map with undefined points, or fill them
        with the harmonic function that matches the defined points around them.

    Raises
    ------
    ValueError
        The file is empty, cut or damaged, its format is not recognised (or not the one
        its extension says), it is a line scan, the channel does not exist, the map has
        undefined points (with ``refuse``) or no defined point, a unit cannot be
        converted; the message leads with the file and says what is allowed.
    """
    if detrend not in DETRENDS:
        raise ValueError(f"detrend = {detrend!r} is not allowed; allowed: {', '.join(DETRENDS)}")
    if undefined not in UNDEFINED:
        raise ValueError(f"undefined = {undefined!r} is not allowed; allowed: "
                         f"{', '.join(UNDEFINED)}")
    reader, chosen = _open_channel(path, channel)
    sizes = chosen.physical_sizes
    kwargs = {} if sizes is not None else {"physical_sizes": tuple(float(n) for n in
                                                                   chosen.nb_grid_pts)}
    with time_bound(path):
        try:
            topography = reader.topography(channel_index=chosen.index, **kwargs)
        except Exception as exc:
            raise ValueError(f"topography file {path}: SurfaceTopography cannot read its "
                             f"heights ({type(exc).__name__}: {_first_line(exc)}); the file "
                             f"is truncated or damaged") from None
    if _transposed(reader):
        topography, sizes = _transpose(topography, sizes)
    return _condition(path, topography, type(reader).__name__, str(chosen.name), unit,
                      detrend, undefined, sizes)


def _condition(path, topography, reader, channel, unit, detrend, undefined, sizes):
    """Fill, convert and detrend a read topography; its :class:`Measurement`."""
    missing = int(np.count_nonzero(np.ma.getmaskarray(topography.heights()))) \
        if topography.has_undefined_data else 0
    if missing and missing == int(np.prod(topography.nb_grid_pts)):
        raise ValueError(f"topography {path}: every point is undefined (all {missing} are NaN "
                         f"or masked): there is no map to solve, nor anything to fill from")
    if missing and undefined == "refuse":
        raise ValueError(f"topography {path} has {missing} undefined points (NaN or masked); "
                         f"set surface.undefined = \"harmonic\" to fill them, or fill them "
                         f"before")
    if missing:
        topography = topography.interpolate_undefined_data("harmonic")
    unit_of_file = canonical_file_unit(topography.unit)
    factor = 1.0 if unit is None or unit_of_file is None else \
        conversion_factor(path, unit_of_file, unit)
    if detrend not in ("none", "lines"):
        topography = topography.detrend(detrend_mode=detrend)
    heights = np.ma.getdata(topography.heights()).astype(np.float64, copy=True)
    if detrend == "lines":
        heights = level_lines(heights)
    if factor != 1.0:
        heights *= factor
    return Measurement(heights=heights,
                       physical_size=None if sizes is None else
                       tuple(factor * float(s) for s in topography.physical_sizes),
                       unit=unit_of_file if unit is None or unit_of_file is None else
                       length_unit(unit),
                       periodic=bool(topography.is_periodic), reader=reader, channel=channel,
                       undefined=missing)


def conversion_factor(path, unit_of_file, unit):
    """The factor from the file's length unit to ``unit`` (the scene's ``units.length``);
    a ValueError naming the key, the value and what is allowed otherwise: ``units.length``
    for a unit petgap does not know, ``surface.channel`` for a channel whose unit is not a
    length."""
    try:
        wanted = length_unit(unit)
    except ValueError:
        raise ValueError(f"units.length = {unit!r}: topography {path}: cannot convert its unit "
                         f"{unit_of_file!r} to {unit!r}, which is not a length unit petgap "
                         f"converts; allowed: {allowed_length_units()}, or "
                         f"\"1\" to keep the file's numbers") from None
    if canonical_file_unit(unit_of_file) not in METRES:
        raise ValueError(f"surface.channel: topography {path}: the channel's unit "
                         f"{unit_of_file!r} is not a length, so its heights cannot be converted "
                         f"to units.length = {unit!r} (a phase or current channel? "
                         f"surface.channel chooses another; units.length = \"1\" keeps the "
                         f"numbers as they are)")
    return METRES[canonical_file_unit(unit_of_file)] / METRES[wanted]


def read_header(path, channel=None, unit=None):
    """Shape, physical size and unit of a measured map, without its heights (calling rank).

    ``{"shape": (nx, ny), "size": (Lx, Ly) or None, "unit": str or None, "periodic":
    bool}``; the size is converted to ``unit`` when the file and ``unit`` both name one;
    ``periodic`` is the file's own say (instrument maps are not, as a rule).  Raises what
    :func:`read_measured` raises about the file's header.
    """
    reader, chosen = _open_channel(path, channel)
    size, unit_of_file = chosen.physical_sizes, canonical_file_unit(chosen.unit)
    shape = tuple(int(n) for n in chosen.nb_grid_pts)
    if _transposed(reader):
        shape, size = shape[::-1], None if size is None else tuple(size)[::-1]
    if unit is not None and unit_of_file is not None:
        factor = conversion_factor(path, unit_of_file, unit)
        size = None if size is None else tuple(factor * float(v) for v in size)
        unit_of_file = length_unit(unit)
    return {"shape": shape, "size": None if size is None else tuple(float(v) for v in size),
            "unit": unit_of_file, "periodic": bool(getattr(chosen, "is_periodic", False))}


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
