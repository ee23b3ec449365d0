"""Scenes: one TOML file describes one run.

A scene is a TOML file (read with the standard library's :mod:`tomllib`) with one
table per stage of a run: ``[grid]``, ``[surface]``, ``[material]``,
``[interaction]``, ``[control]``, ``[solver]``, ``[output]``, ``[units]`` and ``[flow]``.  Its schema is
declared once, in this module, as frozen dataclasses whose fields carry a
:class:`Key` (type, default, allowed values, documentation); validation, the
defaults, the error messages and :func:`describe_schema` are all derived from
that declaration.  To add a section, write another ``@dataclass(frozen=True)``
whose fields are :func:`key` s and add it as a field of :class:`Scene`.

Units
-----
petgap has no built-in unit system: every length (``a0``, wavelengths, the
interaction range, mean gaps) is in the same length unit, and every pressure
(``contact_modulus``, loads) in the same pressure unit; the work of adhesion is
pressure x length.  Where a length is asked for, a string ``"<number> a0"`` is
accepted too and means that many pixels (``"32 a0"`` = 32 x ``grid.a0``).

Validation
----------
Unknown sections and keys are errors (with the nearest known name suggested);
so are keys that do not apply to the chosen ``kind``.  Every error is a
:class:`SceneError` whose message names the dotted key (``surface.hurst``), the
offending value and what is allowed, except the errors of a topography file, which
lead with the file and its reason (it is the file that is wrong, not the key that
names it); all errors of a file are reported at once.  A scene is parsed on rank 0
only and the result, or the error, is broadcast, so that every rank of the
communicator returns the same scene or raises the same :class:`SceneError` and none
is left waiting in a collective.
"""
import dataclasses
import difflib
import json
import math
import numbers
import re
import tomllib
from dataclasses import dataclass, field, fields
from pathlib import Path

from petgap.io import solver_registry as registry
from petgap.io.solver_registry import SINGLE_TOLERANCE_FLOOR
from petgap.parallel.collective import root_decides

__all__ = ["SceneError", "Scene", "GridSection", "SurfaceSection", "MaterialSection",
           "InteractionSection", "ControlSection", "SolverSection", "OutputSection", "UnitsSection",
           "ChecksSection", "FlowSection",
           "schema_default",
           "describe_schema", "to_toml"]


class SceneError(ValueError):
    """An invalid scene.  ``errors`` holds one line per problem found."""

    def __init__(self, message, errors=()):
        super().__init__(message)
        self.errors = tuple(errors) if errors else (message,)

    def __reduce__(self):  # keeps ``errors`` when rank 0's verdict is broadcast
        return (type(self), (str(self), self.errors))


class _Required:
    def __repr__(self):
        return "REQUIRED"


#: Default of a key that must be given (when it applies).
REQUIRED = _Required()


@dataclass(frozen=True)
class Derived:
    """A default computed from the other values of the section and earlier sections.

    ``func(values, ctx)`` gets the section's values so far and the sections
    already built (by name); ``text`` documents the rule in the schema table.
    """
    func: object
    text: str


class _Invalid(Exception):
    """A value failed validation: ``problem`` says why, ``allowed`` what would do."""

    def __init__(self, problem, allowed):
        super().__init__(problem)
        self.problem, self.allowed = problem, allowed


class _Missing(Exception):
    """A derived default that cannot be derived: the message says why (an error)."""


class _Skip(Exception):
    """A value cannot be checked because something it depends on was invalid."""


# ----------------------------------------------------------------- value types
def _is_number(value):
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _range_phrase(lo, hi, lo_open=False, hi_open=False):
    """``"> 0"``, ``">= 1"``, ``"in (0, 1)"``, ``"in (0, 0.1]"`` or ``""``."""
    if lo is not None and hi is not None:
        return f"in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
    if lo is not None:
        return f"{'>' if lo_open else '>='} {lo:g}"
    if hi is not None:
        return f"{'<' if hi_open else '<='} {hi:g}"
    return ""


class _Type:
    """Base of the value types: ``convert`` checks and normalises a TOML value."""
    name = "value"

    def convert(self, value, ctx):
        raise NotImplementedError

    def allowed(self):
        return self.name

    def default_text(self, default):
        return _toml_repr(default)


class Int(_Type):
    """An integer (TOML integer; booleans and floats are refused)."""
    name = "integer"

    def __init__(self, minimum=None, maximum=None):
        self.minimum, self.maximum = minimum, maximum

    def allowed(self):
        return f"an integer {_range_phrase(self.minimum, self.maximum)}".strip()

    def convert(self, value, ctx):
        if not isinstance(value, int) or isinstance(value, bool):
            raise _Invalid("not an integer", self.allowed())
        if (self.minimum is not None and value < self.minimum) or \
                (self.maximum is not None and value > self.maximum):
            raise _Invalid("out of range", self.allowed())
        return value


class Float(_Type):
    """A finite real number (TOML integer or float) within optional bounds."""
    name = "number"

    def __init__(self, minimum=None, maximum=None, min_open=False, max_open=False):
        self.minimum, self.maximum = minimum, maximum
        self.min_open, self.max_open = min_open, max_open

    def _range(self):
        return _range_phrase(self.minimum, self.maximum, self.min_open, self.max_open)

    def allowed(self):
        return f"a number {self._range()}" if self._range() else "a finite number"

    def _check_range(self, x):
        lo, hi = self.minimum, self.maximum
        if (lo is not None and (x < lo or (self.min_open and x == lo))) or \
                (hi is not None and (x > hi or (self.max_open and x == hi))):
            raise _Invalid("out of range", self.allowed())

    def convert(self, value, ctx):
        if not _is_number(value):
            raise _Invalid("not a number", self.allowed())
        x = float(value)
        if not math.isfinite(x):
            raise _Invalid("not finite", self.allowed())
        self._check_range(x)
        return x


_PIXELS = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*a0\s*$")


class Length(Float):
    """A length: a number in physical units, or ``"<number> a0"`` meaning pixels."""
    name = "length"

    def allowed(self):
        b = f" {self._range()}" if self._range() else ""
        return f'a length{b} (a number in physical units, or a string like "32 a0" in pixels)'

    def convert(self, value, ctx):
        if isinstance(value, str):
            m = _PIXELS.match(value)
            if not m:
                raise _Invalid('not a length', self.allowed())
            grid = ctx.get("grid")
            if grid is None:
                raise _Skip  # the pixel size itself was invalid and is reported already
            x = float(m.group(1)) * grid.a0
            if not math.isfinite(x):
                raise _Invalid("not finite", self.allowed())
            self._check_range(x)
            return x
        if not _is_number(value):
            raise _Invalid("not a length", self.allowed())
        return super().convert(value, ctx)


class Choice(_Type):
    """One of a fixed set of strings."""
    name = "string"

    def __init__(self, *choices):
        self.choices = tuple(choices)

    def allowed(self):
        return "one of " + ", ".join(json.dumps(c) for c in self.choices)

    def convert(self, value, ctx):
        if not isinstance(value, str):
            raise _Invalid("not a string", self.allowed())
        if value not in self.choices:
            close = difflib.get_close_matches(value, self.choices, n=1, cutoff=0.5)
            hint = f" (did you mean {json.dumps(close[0])}?)" if close else ""
            raise _Invalid(f"not a valid choice{hint}", self.allowed())
        return value


class Bool(_Type):
    name = "boolean"

    def allowed(self):
        return "true or false"

    def convert(self, value, ctx):
        if not isinstance(value, bool):
            raise _Invalid("not a boolean", self.allowed())
        return value


class Str(_Type):
    name = "string"

    def allowed(self):
        return "a non-empty string"

    def convert(self, value, ctx):
        if not isinstance(value, str) or not value:
            raise _Invalid("not a non-empty string", self.allowed())
        return value


class NameOrIndex(_Type):
    """A non-empty string or an integer >= 0 (a channel of a file, by name or index)."""
    name = "string or integer"

    def allowed(self):
        return "a name (a non-empty string) or an index (an integer >= 0)"

    def convert(self, value, ctx):
        if isinstance(value, int) and not isinstance(value, bool) and value >= 0:
            return value
        if isinstance(value, str) and value:
            return value
        raise _Invalid("neither a non-empty string nor an integer >= 0", self.allowed())


class FilePath(Str):
    """An existing file; relative paths are relative to the scene file's directory."""
    name = "path"

    def allowed(self):
        return "the path of an existing file (relative paths start at the scene file's directory)"

    def convert(self, value, ctx):
        super().convert(value, ctx)
        path = Path(value).expanduser()
        if not path.is_absolute():
            path = Path(ctx["_base_dir"]) / path
        path = path.resolve()
        if not path.is_file():
            raise _Invalid(f"no such file ({path})", self.allowed())
        return str(path)


class Numbers(_Type):
    """A number or a non-empty list of numbers, each checked by ``element``; gives a tuple."""
    name = "number or list"

    def __init__(self, element):
        self.element = element

    def allowed(self):
        return f"{self.element.allowed()}, or a non-empty list of such values"

    def convert(self, value, ctx):
        items = value if isinstance(value, list) else [value]
        if not items:
            raise _Invalid("an empty list", self.allowed())
        out = []
        for i, item in enumerate(items):
            try:
                out.append(self.element.convert(item, ctx))
            except _Invalid as exc:
                where = f"item {i} ({_toml_repr(item)}) is " if isinstance(value, list) else ""
                raise _Invalid(where + exc.problem, self.allowed()) from None
        return tuple(out)


class StrList(_Type):
    """A list of distinct strings from a fixed set; gives a tuple."""
    name = "list of strings"

    def __init__(self, *choices):
        self.choices = tuple(choices)

    def allowed(self):
        return "a list of distinct values from " + ", ".join(json.dumps(c) for c in self.choices)

    def convert(self, value, ctx):
        if not isinstance(value, list):
            raise _Invalid("not a list", self.allowed())
        for item in value:
            if not isinstance(item, str) or item not in self.choices:
                raise _Invalid(f"{_toml_repr(item)} is not a valid choice", self.allowed())
        if len(set(value)) != len(value):
            raise _Invalid("has repeated entries", self.allowed())
        return tuple(value)

    def default_text(self, default):
        return _toml_repr(list(default))


class OptionTable(_Type):
    """A table of PETSc options: names (leading ``-`` optional) to scalar values.

    Gives a tuple of ``(name, value)`` string pairs, names without the dash,
    booleans as ``"true"``/``"false"`` and an empty string for a bare flag.
    """
    name = "table"

    def allowed(self):
        return ('a table of PETSc option names to strings, numbers or booleans, '
                'e.g. {tao_monitor = "", tao_max_funcs = 1000}')

    def convert(self, value, ctx):
        if not isinstance(value, dict):
            raise _Invalid("not a table", self.allowed())
        out = []
        for name, v in value.items():
            bare = name.lstrip("-")
            if not bare or not re.fullmatch(r"[A-Za-z0-9_]+", bare):
                raise _Invalid(f"{json.dumps(name)} is not a PETSc option name", self.allowed())
            if isinstance(v, bool):
                v = "true" if v else "false"
            elif _is_number(v):
                if not math.isfinite(v):
                    raise _Invalid(f"option {bare} is not finite", self.allowed())
                v = repr(v)
            elif not isinstance(v, str):
                raise _Invalid(f"option {bare} has a {type(v).__name__} value", self.allowed())
            out.append((bare, v))
        return tuple(out)

    def default_text(self, default):
        return "{}" if not default else _toml_repr(dict(default))


# ------------------------------------------------------------------- the keys
@dataclass(frozen=True)
class Key:
    """One key of a section: its type, default, documentation and applicability.

    ``when = (other, values)`` makes the key apply only when the section's key
    ``other`` (declared earlier) has one of ``values``; otherwise giving the
    key is an error and its value is ``None``.
    """
    type: _Type
    default: object = REQUIRED
    doc: str = ""
    when: tuple = None

    def default_text(self):
        if self.default is REQUIRED:
            return "required"
        if isinstance(self.default, Derived):
            return self.default.text
        if self.default is None:
            return "(none)"
        return self.type.default_text(self.default)


def key(type, default=REQUIRED, doc="", when=None):
    """Declare a section field: a dataclass field carrying its :class:`Key`."""
    if when is not None:
        when = (when[0], tuple(when[1]))
    return field(default=None, metadata={"key": Key(type, default, doc, when)})


def _keys(section_cls):
    return {f.name: f.metadata["key"] for f in fields(section_cls)}


# --------------------------------------------------------------- the sections
#: The largest ``grid.nx`` or ``grid.ny``: the FFT and contact kernels index a
#: rank's slab with 32-bit integers (the slab limit per rank is checked when a
#: run is built, see :func:`petgap.app.build.check_size`).
MAX_PIXELS = 2**31 - 1
_LARGEST = 1.7976931348623157e308


def _file_grid(ctx):
    """What a scene's topography file says about the grid, or None (no file surface).

    ``{"shape": (nx, ny), "size": (Lx, Ly) or None}``, the size in the scene's
    ``units.length`` when the file and the scene both name a unit.  Read once per
    scene, from the raw tables (the surface section is validated after the grid).
    """
    if "_file_grid" in ctx:
        return ctx["_file_grid"]
    data = ctx.get("_data", {})
    surface = data.get("surface", {}) if isinstance(data.get("surface"), dict) else {}
    found = None
    if surface.get("kind") == "file" and isinstance(surface.get("path"), str):
        path = Path(surface["path"]).expanduser()
        if not path.is_absolute():
            path = Path(ctx["_base_dir"]) / path
        units = data.get("units", {}) if isinstance(data.get("units"), dict) else {}
        read_header = ctx.get("_read_header")
        if read_header is None:
            found = {"error": "the scene was read without a reader of topography files "
                              "(petgap.load_scene and the petgap command have one)"}
        else:
            try:
                found = read_header(path, surface.get("dataset"), surface.get("channel"),
                                    units.get("length", "1"))
            except Exception as exc:  # the surface section reports the file; no grid from it
                found = {"error": str(exc), "unreadable": True}
    ctx["_file_grid"] = found
    return found


def _grid_from_file(what):
    def derive(values, ctx):
        header = _file_grid(ctx)
        if header is None:
            raise _Missing("it is required (unless surface.kind = \"file\", whose file "
                           "gives it)")
        if "unreadable" in header:
            raise _Skip  # the file's own error, reported once by the surface section
        if "error" in header:
            raise _Missing(f"the topography file would give it, but: {header['error']}")
        if what == "nx":
            return header["shape"][0]
        if what == "ny":
            return header["shape"][1] if not values.get("_given_nx") else \
                (header["shape"][1] if values["nx"] == header["shape"][0] else values["nx"])
        size = header["size"]
        if size is None:
            return 1.0
        dx, dy = size[0] / header["shape"][0], size[1] / header["shape"][1]
        return dx if what == "dx" else dy
    return derive


def _file_unit(values, ctx):
    """The unit a topography file names (in petgap's spelling), or "1"."""
    header = _file_grid(ctx)
    if header is None or "error" in header or not header.get("unit"):
        return "1"
    return header["unit"]


def _default_ny(values, ctx):
    header = _file_grid(ctx)
    if header is not None and "error" not in header and not values.get("_given_nx"):
        return header["shape"][1]
    return values["nx"]


def _default_a0(values, ctx):
    header = _file_grid(ctx)
    if header is None or "error" in header or header["size"] is None:
        return 1.0
    return header["size"][0] / header["shape"][0]


@dataclass(frozen=True)
class GridSection:
    """The periodic grid: ``nx x ny`` pixels of ``dx x dy`` (``a0`` both, by default); the
    system is ``nx dx x ny dy``.  With a topography file, the file gives what the scene
    leaves out: its pixels and, if it knows its physical size, the pixel size."""
    nx: int = key(Int(minimum=1), Derived(_grid_from_file("nx"), "the file's, for a "
                                          "topography file; otherwise required"),
                  f"number of pixels along x (the distributed axis), at most {MAX_PIXELS}")
    ny: int = key(Int(minimum=1), Derived(_default_ny, "the file's, for a topography file; "
                                          "otherwise nx"),
                  f"number of pixels along y, at most {MAX_PIXELS}")
    a0: float = key(Float(minimum=0, min_open=True),
                    Derived(_default_a0, "the file's pixel size along x if it knows its "
                            "physical size, otherwise 1"),
                    "pixel size, in the length unit of the run (\"N a0\" lengths count it)")
    dx: float = key(Float(minimum=0, min_open=True), Derived(lambda v, ctx: (
        _grid_from_file("dx")(v, ctx) if _sized(ctx) and not v.get("_given_a0") else v["a0"]),
        "a0 (the file's, if it knows its size)"), "pixel size along x")
    dy: float = key(Float(minimum=0, min_open=True), Derived(lambda v, ctx: (
        _grid_from_file("dy")(v, ctx) if _sized(ctx) and not v.get("_given_a0") else v["a0"]),
        "a0 (the file's, if it knows its size)"), "pixel size along y")

    @staticmethod
    def _check(values, ctx, problems):
        nx, ny, a0 = values["nx"], values["ny"], values["a0"]
        for name, n in (("nx", nx), ("ny", ny)):
            if n > MAX_PIXELS and (name == "nx" or values.get("_given_ny")):  # not ny = nx
                problems.append((name, n, "is beyond the index range of petgap's kernels "
                                 "(32-bit)", f"an integer in [1, {MAX_PIXELS}]"))
        if max(nx, ny) > MAX_PIXELS:
            return
        if not math.isfinite(2 * math.pi / a0):
            problems.append(("a0", a0, "is so small that the largest wavevector 2 pi / a0 "
                             "overflows", f"a0 >= {2 * math.pi / _LARGEST:.3g}"))
        elif not math.isfinite(max(nx, ny) * a0):
            problems.append(("a0", a0, f"is so large that the system size {max(nx, ny)} a0 "
                             f"overflows", f"a0 <= {_LARGEST / max(nx, ny):.3g}"))

    @property
    def shape(self):
        """``(nx, ny)``."""
        return (self.nx, self.ny)

    @property
    def size(self):
        """Physical size ``(Lx, Ly) = (nx dx, ny dy)``."""
        return (self.nx * self.dx, self.ny * self.dy)


def _sized(ctx):
    header = _file_grid(ctx)
    return header is not None and "error" not in header and header["size"] is not None


def _half_smaller_side(values, ctx):
    grid = ctx.get("grid")
    if grid is None:
        raise _Skip
    return min(grid.size) / 2


#: Surface kinds that are indenters (solved on a free boundary unless said otherwise).
INDENTERS = ("paraboloid", "sphere", "flat-punch", "cylinder")


def _default_periodic(values, ctx):
    if values["kind"] == "self-affine":
        return True
    if values["kind"] == "file":
        header = _file_grid(ctx)
        return bool(header is not None and "error" not in header and header.get("periodic"))
    return False


@dataclass(frozen=True)
class SurfaceSection:
    """The rigid rough surface: a self-affine random surface, or a topography file."""
    kind: str = key(Choice("self-affine", "file", *INDENTERS), "self-affine",
                    "how the topography is made: a self-affine random surface, a "
                    "topography file, or an indenter centred on the map (paraboloid: "
                    "Hertz's -r^2 / 2R; sphere: the spherical cap; flat-punch: a flat "
                    "circular face, the body around it one radius below; cylinder: "
                    "-x^2 / 2R, its axis along y)")
    hurst: float = key(Float(0, 1, min_open=True, max_open=True), REQUIRED,
                       "Hurst exponent H; the PSD falls as q^-2(1+H) between the cutoffs",
                       when=("kind", ["self-affine"]))
    lambda_min: float = key(Length(minimum=0, min_open=True), REQUIRED,
                            "short-wavelength cutoff (q2 = 2 pi / lambda_min); at least 2 a0, "
                            "and the paper uses >= 32 a0 to resolve contact edges",
                            when=("kind", ["self-affine"]))
    lambda_max: float = key(Length(minimum=0, min_open=True),
                            Derived(_half_smaller_side, "min(Lx, Ly) / 2"),
                            "long-wavelength cutoff (q1 = 2 pi / lambda_max): the PSD is flat "
                            "below q1; lambda_min < lambda_max <= max(Lx, Ly)",
                            when=("kind", ["self-affine"]))
    rms_slope: float = key(Float(minimum=0, min_open=True),
                           Derived(lambda v, ctx: 0.1 if v.get("rms_height") is None else None,
                                   "0.1 unless rms_height is given"),
                           "rms slope h0' = sqrt(<|grad h|^2>) the surface is scaled to; "
                           "give rms_slope or rms_height, not both",
                           when=("kind", ["self-affine"]))
    rms_height: float = key(Length(minimum=0, min_open=True), None,
                            "rms height h0 the surface is scaled to, instead of rms_slope",
                            when=("kind", ["self-affine"]))
    seed: int = key(Int(minimum=0), 1,
                    "seed of the random phases and amplitudes; the surface does not depend "
                    "on the number of ranks", when=("kind", ["self-affine"]))
    path: str = key(FilePath(), REQUIRED,
                    "topography file: .npy, or HDF5 (.h5, .hdf5; a petgap result file will do), "
                    "holding an (nx, ny) array of heights in length units, or a measured map "
                    "in any format SurfaceTopography reads (e.g. .ibw, .top, .nc, .mat, text "
                    "matrix or x-y-z; heights converted to units.length when both units are "
                    "known); relative to the scene file's directory", when=("kind", ["file"]))
    dataset: str = key(Str(), None, "HDF5 dataset to read (default: \"topography\" if present, "
                       "otherwise the only 2D dataset)", when=("kind", ["file"]))
    channel: str = key(NameOrIndex(), None, "data channel of an instrument file with several, "
                       "by name or index (`petgap check` lists them; default: the file's "
                       "default channel)", when=("kind", ["file"]))
    detrend: str = key(Choice("none", "center", "height", "slope", "curvature", "lines"),
                       "none",
                       "trend removed from the map (SurfaceTopography's modes): its mean "
                       "(center), the least-squares plane (height), the plane of the mean "
                       "slope (slope) or the least-squares quadratic surface (curvature); "
                       "or each scan line's own straight line (lines: along x, for AFM maps "
                       "whose lines show steps)",
                       when=("kind", ["file"]))
    lambda_cutoff: float = key(Length(minimum=0, min_open=True), None,
                               "short-wavelength cutoff of a measured map: wavelengths "
                               "shorter than it (|q| > 2 pi / lambda_cutoff) are removed, "
                               "after the trend; e.g. instrument noise below the tip radius",
                               when=("kind", ["file"]))
    undefined: str = key(Choice("refuse", "harmonic"), "refuse",
                         "undefined points (NaN, masked) in the map: refuse it, or fill them "
                         "with the harmonic function that matches their surroundings",
                         when=("kind", ["file"]))

    radius: float = key(Length(minimum=0, min_open=True), REQUIRED,
                        "radius of the indenter (of curvature for paraboloid, sphere and "
                        "cylinder; of the face for flat-punch)", when=("kind", list(INDENTERS)))
    periodic: bool = key(Bool(), Derived(_default_periodic, "true for a self-affine surface; "
                                         "for a file what the file says (false if it says "
                                         "nothing); false for an indenter"),
                         "solve on a periodic cell (the surface repeats) or on a free "
                         "boundary (the map alone on an infinite half-space, no images)")

    @staticmethod
    def _check(values, ctx, problems):
        header = _file_grid(ctx) if values["kind"] == "file" else None
        if header is not None and "unreadable" in header:
            problems.append((None, None, header["error"], None))  # it leads with the file
        if values["kind"] in INDENTERS:
            _check_radius(values, ctx.get("grid"), problems)
        if values["kind"] != "self-affine":
            return
        grid = ctx.get("grid")
        lmin, lmax = values.get("lambda_min"), values.get("lambda_max")
        for name, length in (("lambda_min", lmin), ("lambda_max", lmax)):
            if isinstance(length, float) and not math.isfinite(2 * math.pi / length):
                problems.append((name, length, f"is so small that the wavevector 2 pi / {name} "
                                 f"overflows", f"{name} >= {2 * math.pi / _LARGEST:.3g}"))
                return
        if grid is not None and isinstance(lmin, float) and lmin < 2 * grid.a0:
            problems.append(("lambda_min", lmin, "is below the Nyquist wavelength",
                             f"lambda_min >= 2 a0 = {2 * grid.a0:g}"))
        if isinstance(lmin, float) and isinstance(lmax, float) and not lmin < lmax:
            problems.append(("lambda_max", lmax, f"is not larger than lambda_min = {lmin:g}",
                             "lambda_min < lambda_max"))
        if grid is not None and isinstance(lmax, float) and lmax > max(grid.size):
            problems.append(("lambda_max", lmax, "is larger than the system",
                             f"lambda_max <= max(Lx, Ly) = {max(grid.size):g}"))
        if values.get("_given_rms_slope") and values.get("rms_height") is not None:
            problems.append(("rms_slope", values["rms_slope"],
                             f"is given together with rms_height = {values['rms_height']:g}",
                             "exactly one of rms_slope and rms_height (rms_slope = 0.1 if "
                             "neither is given)"))


def _check_radius(values, grid, problems):
    """An indenter's radius must span a pixel.  A smaller one is not resolved: a sphere's
    cap falls between the pixels (the surface is flat), a flat punch is one pixel, and a
    paraboloid's or cylinder's slope passes 1 within a pixel of the apex, outside the
    small-slope half-space, on its way to depths whose squares overflow."""
    if grid is not None and values["radius"] < min(grid.dx, grid.dy):
        problems.append(("radius", values["radius"], f"is smaller than a pixel: the "
                         f"{values['kind']} is not resolved by the grid",
                         f"radius >= {min(grid.dx, grid.dy):g} (a pixel, min(dx, dy))"))


@dataclass(frozen=True)
class MaterialSection:
    """The elastic half-space."""
    contact_modulus: float = key(Float(minimum=0, min_open=True), 1.0,
                                 "contact modulus E* = 1 / ((1 - nu1^2)/E1 + (1 - nu2^2)/E2), "
                                 "in the pressure unit of the run")


#: The adhesive laws of ``[interaction] kind``, each with what its ``range`` means.  The
#: laws themselves, and the registry mapping these names to them, are in
#: :mod:`petgap.mechanics.interactions` (which this schema cannot import: the scene
#: ranks below the mechanics; ``tests/mechanics/test_interactions.py`` keeps the two
#: lists equal).
ADHESIVE_LAWS = {
    "exponential": "v(g) = -w exp(-g / rho), range = rho (the paper's Eq. 6)",
    "maugis-dugdale": "v(g) = -w (1 - g / delta) for g < delta and 0 beyond (a constant "
                      "attraction w / delta), range = delta",
    "lennard-jones-9-3": "v(g) = (w / 2) ((z0 / (z0 + g))^9 - 3 (z0 / (z0 + g))^3), the 9-3 "
                         "potential with the wall at its minimum, range = z0",
    "squared-exponential": "v(g) = -w exp(-g^2 / (2 rho^2)), range = rho",
}


@dataclass(frozen=True)
class InteractionSection:
    """The surface interaction: hard-wall repulsion, plus an adhesive law if asked."""
    kind: str = key(Choice("hard-wall", *ADHESIVE_LAWS), "hard-wall",
                    "hard-wall: g >= 0 only; the others add an attraction v(g): " +
                    "; ".join(f"{name}: {law}" for name, law in ADHESIVE_LAWS.items()))
    work_of_adhesion: tuple = key(Numbers(Float(minimum=0, min_open=True)), REQUIRED,
                                  "w, energy per area (pressure x length): -v(0), the energy "
                                  "per area it takes to separate the surfaces from contact; "
                                  "a list of values (with control.reference = "
                                  "\"non-adhesive\") solves the adhesive steps once per w, "
                                  "in order, against one non-adhesive reference (paper "
                                  "Fig. 3)",
                                  when=("kind", list(ADHESIVE_LAWS)))
    range: float = key(Length(minimum=0, min_open=True), REQUIRED,
                       "the length scale of the attraction (rho, delta or z0; see kind)",
                       when=("kind", list(ADHESIVE_LAWS)))
    resolution_check: str = key(Choice("warn", "error", "off"), "warn",
                                "what to do when the grid does not resolve the range or the "
                                "process zone of the attraction",
                                when=("kind", list(ADHESIVE_LAWS)))


class _ControlValues(Numbers):
    """Loads (pressures, any sign) or mean gaps (lengths), depending on control.kind."""

    def __init__(self):
        super().__init__(Float())

    def allowed(self):
        return ("for kind = \"load\": a mean pressure or a list of them; for kind = \"mean-gap\" "
                "or \"indentation\": a length > 0 (number or \"<n> a0\") or a list of them")

    def convert(self, value, ctx):
        element = Length(minimum=0, min_open=True) if ctx["_section"].get("kind") in \
            ("mean-gap", "indentation") else Float()
        try:
            return Numbers(element).convert(value, ctx)
        except _Invalid as exc:
            raise _Invalid(exc.problem, self.allowed()) from None

    def default_text(self, default):
        return "required"


@dataclass(frozen=True)
class ControlSection:
    """What is imposed: the mean pressure (load), the mean gap, or nothing (surface only).

    ``values`` sweeps: one solution per value, each step starting from the
    previous one.  Loads are mean pressures in the run's pressure unit (the
    same unit as ``material.contact_modulus``; with E* = 1 they are in units of
    E*), positive in compression.
    """
    kind: str = key(Choice("load", "mean-gap", "indentation", "none"), "none",
                    "load: impose the mean pressure; mean-gap: impose the mean gap; "
                    "indentation: impose the rigid approach past first contact (free "
                    "boundary only); none: only make and analyse the surface")
    values: tuple = key(_ControlValues(), REQUIRED,
                        "mean pressures (load; > 0 for a hard wall, any sign with adhesion), "
                        "mean gaps (mean-gap; lengths > 0) or depths (indentation; lengths "
                        "> 0) to sweep", when=("kind", ["load", "mean-gap", "indentation"]))
    reference: str = key(Choice("non-adhesive"), None,
                         "non-adhesive: the paper's protocol; values are loads of a non-adhesive "
                         "reference run, and each adhesive step is solved at the mean gap that "
                         "reference found (needs an adhesive interaction.kind)",
                         when=("kind", ["load"]))

    @staticmethod
    def _check(values, ctx, problems):
        vals = values.get("values")
        case = _case(ctx, control=values["kind"],
                     loads=vals if values["kind"] == "load" and isinstance(vals, tuple) else ())
        _refused(case, ("control", "load"), ctx, problems, values=vals)
        interaction = ctx.get("interaction")
        if values["kind"] == "load" and isinstance(vals, tuple) and interaction is not None \
                and interaction.kind == "hard-wall" and 0 in vals:
            problems.append(("values", list(vals), f"item {vals.index(0)} (0) is a zero load "
                             f"with a hard-wall interaction, where the surfaces only touch",
                             "loads > 0 with the hard wall (a step that carries something)"))
        works = getattr(interaction, "work_of_adhesion", None)
        if values.get("reference") is None and isinstance(works, tuple) and len(works) > 1:
            problems.append(("reference", None,
                             f"interaction.work_of_adhesion is a list of {len(works)} values, "
                             f"a series that needs one non-adhesive reference",
                             "reference = \"non-adhesive\" with a list of works of adhesion, "
                             "or one work_of_adhesion"))
        if values.get("reference") is not None and interaction is not None \
                and interaction.kind == "hard-wall":
            problems.append(("reference", values["reference"],
                             f"needs an adhesive interaction, and interaction.kind = "
                             f"{json.dumps(interaction.kind)}",
                             "reference only with an adhesive interaction.kind (" +
                             ", ".join(json.dumps(k) for k in ADHESIVE_LAWS) + ")"))


def _case(ctx, **known):
    """What a scene combines, in the registry's words, from the sections built so far."""
    interaction, surface = ctx.get("interaction"), ctx.get("surface")
    return registry.Case(adhesive=None if interaction is None else
                         interaction.kind != "hard-wall",
                         periodic=None if surface is None else surface.periodic, **known)


#: The scene's key of each input the registry's rules name.
_SCENE_KEYS = {"solver": "solver.tao_type", "precision": "solver.precision",
               "tolerance": "solver.tolerance", "control": "control.kind",
               "load": "control.values"}


def _refused(case, keys, ctx, problems, values=None):
    """Add the registry's refusals of ``case`` that blame ``keys`` to a section's problems."""
    def name(key, value):
        if key == "interaction":
            return f"interaction.kind = {json.dumps(ctx['interaction'].kind)}"
        if key == "boundary":
            return f"surface.periodic = {_toml_repr(value)}"
        return f"{_SCENE_KEYS[key]} = {_toml_repr(value)}"

    for refusal in registry.refusals(case):
        if refusal.key not in keys:
            continue
        key = _SCENE_KEYS[refusal.key].split(".")[1]
        if refusal.key == "load":  # one of the section's values
            problems.append((key, list(values), f"item {values.index(refusal.value)} "
                             f"({refusal.value:g}) {refusal.detail(name)}", refusal.allowed))
        else:
            problems.append((key, refusal.value, refusal.detail(name), refusal.allowed))


@dataclass(frozen=True)
class SolverSection:
    """The minimiser and its stopping rule.

    ``petsc_options`` is a tuple of ``(name, value)`` pairs, names without the
    leading dash; options given after ``--`` on the command line come later and
    take precedence.
    """
    tao_type: str = key(Choice(*registry.SOLVER_NAMES), "pcg",
                        "pcg: petgap's preconditioned projected conjugate gradients (on the "
                        "pressure for non-adhesive load control, on the gap otherwise; "
                        "pcg-pressure / pcg-gap force one); the others are TAO "
                        "bound-constrained solvers on the gap (much slower; see "
                        "docs/benchmarks.md)")
    tolerance: float = key(Float(0, 0.1, min_open=True), 1e-8,
                           "relative convergence tolerance (KKT violation in pressure / (h0' E*), "
                           "mean-constraint residual / h0)")
    max_iterations: int = key(Int(minimum=1), 10000, "iteration limit per sweep step")
    petsc_options: tuple = key(OptionTable(), (), "extra PETSc options database entries")
    planner: str = key(Choice("auto", "estimate", "measure", "patient"), "auto",
                       "FFTW planner effort (measured plans are cached as wisdom on disk); "
                       "auto: estimate for a run of one solve, whose planning would cost "
                       "more than faster transforms save, measure for a sweep")
    precision: str = key(Choice(*registry.PRECISIONS), "double",
                         "floating point of the solve: double; single (fields and transforms "
                         "in 32 bits, sums in 64; half the memory, tolerance at least "
                         f"{SINGLE_TOLERANCE_FLOOR:g}); mixed (a single solve refined in "
                         "double to the tolerance). "
                         "single and mixed: non-adhesive, periodic, the pressure solver; "
                         "docs/accuracy.md has the trade")

    @staticmethod
    def _check(values, ctx, problems):
        control = ctx.get("control")
        case = _case(ctx, solver=values["tao_type"], precision=values["precision"],
                     tolerance=values["tolerance"],
                     control=None if control is None or control.kind == "none"
                     else control.kind)
        _refused(case, ("solver", "precision", "tolerance"), ctx, problems)

    def petsc_args(self):
        """The options as a command-line style list ``["-name", "value", ...]``."""
        args = []
        for name, value in self.petsc_options:
            args.append(f"-{name}")
            if value != "":
                args.append(value)
        return args


@dataclass(frozen=True)
class OutputSection:
    """What goes into the HDF5 result file."""
    fields: tuple = key(StrList("topography", "gap", "pressure", "displacement"),
                        ("topography", "gap", "pressure"),
                        "fields written as global datasets")
    statistics: bool = key(Bool(), True, "write surface and contact statistics as attributes")


@dataclass(frozen=True)
class UnitsSection:
    """Names of the units the scene's numbers are in, for labels and result files.

    petgap converts nothing: every length of the scene (``grid.a0``, wavelengths,
    heights, mean gaps, ``interaction.range``) is a number in ``length`` and every
    pressure (loads, ``material.contact_modulus``) a number in ``pressure``; results
    come out in the same units and result files say so in their ``units``
    attributes.  ``"1"`` (the default, UDUNITS' dimensionless) reads as "in the
    scene's own units": pixels when ``a0 = 1``, ``E*`` when ``contact_modulus = 1``.
    """
    length: str = key(Str(), Derived(_file_unit, "the topography file's unit if it names "
                                          "one, otherwise \"1\""),
                      "unit of every length, as a UDUNITS string (e.g. \"um\", \"nm\", \"m\"; "
                      "\"1\": the scene's own unit); a topography file's heights and size are "
                      "converted to it from the file's unit (m, mm, um, nm, Angstrom; also "
                      "spelt micron, \u00b5m, angstrom, \u00c5)")
    pressure: str = key(Str(), "1", "unit of every pressure, as a UDUNITS string "
                        "(e.g. \"MPa\", \"Pa\"; \"1\": the scene's own unit)")


@dataclass(frozen=True)
class ChecksSection:
    """What a run does with valid but implausible input: an rms slope beyond the
    small-slope half-space or absurd for the units, a load beyond rough contact, contact
    patches a few pixels across (:mod:`petgap.mechanics.plausibility`)."""
    plausibility: str = key(Choice("warn", "error", "off"), "warn",
                            "implausible input (the number, the limit and what to do): a "
                            "warning, an error before anything is solved (a patch size: "
                            "after the step that shows it), or nothing")


@dataclass(frozen=True)
class FlowSection:
    """Flow through the gaps after each contact step: the Reynolds equation on the gap.

    ``kind = "reynolds"`` solves steady thin-film flow ``div(g^3 grad p) = 0`` on the
    gap of every non-adhesive step (``petgap.flow``) and stores the leak rate, the
    transmissivity, the flow factor, the percolation of the open region and the
    pressure and flux maps beside the gap.  A periodic surface is a periodic cell (the
    drop imposed across the period); a free boundary has inlet and outlet edges across
    ``direction`` and sealed sides.
    """
    kind: str = key(Choice("none", "reynolds"), "none",
                    "none: no flow; reynolds: the Reynolds equation on each step's gap")
    viscosity: float = key(Float(minimum=0, min_open=True), 1.0,
                           "dynamic viscosity mu, in pressure x time (the leak rate comes out "
                           "in length^3 per that time)", when=("kind", ["reynolds"]))
    pressure_drop: float = key(Float(minimum=0, min_open=True), 1.0,
                               "pressure drop dp along direction, across the period or from "
                               "inlet to outlet, in the pressure unit",
                               when=("kind", ["reynolds"]))
    direction: str = key(Choice("x", "y"), "x", "the direction of the mean flow",
                         when=("kind", ["reynolds"]))

    @staticmethod
    def _check(values, ctx, problems):
        if values["kind"] == "none":
            return
        grid, interaction, control = ctx.get("grid"), ctx.get("interaction"), ctx.get("control")
        if grid is not None:
            n = grid.shape[0 if values["direction"] == "x" else 1]
            if n < 2:
                problems.append(("direction", values["direction"],
                                 f"the map has {n} pixel along {values['direction']}, too few "
                                 f"for a pressure drop", "a direction with at least 2 pixels"))
        if interaction is not None and interaction.kind != "hard-wall" and \
                (control is None or control.reference is None):
            problems.append(("kind", values["kind"],
                             f"every step is adhesive (interaction.kind = "
                             f"{json.dumps(interaction.kind)}), and where the gap is below "
                             f"the interaction range the surfaces attract across it: that is "
                             f"no thin viscous film the Reynolds equation describes",
                             "flow with a hard-wall interaction, or with control.reference = "
                             "\"non-adhesive\" (the flow then runs on the non-adhesive steps)"))


def _section(cls, doc=None):
    return field(default=None, metadata={"section": cls, "doc": doc or cls.__doc__})


# ------------------------------------------------------------------ the scene
@dataclass(frozen=True)
class Scene:
    """A validated scene: one frozen section per TOML table, plus its provenance.

    Attributes
    ----------
    grid, surface, material, interaction, control, solver, output
        The sections (see :func:`describe_schema`).  Keys that do not apply to
        the chosen ``kind`` are ``None``; lengths are in physical units.
    text : str
        The TOML text exactly as read (for provenance).
    path : str or None
        The scene file, if read from one.
    base_dir : str
        Directory that relative paths in the scene start from.
    """
    grid: GridSection = _section(GridSection)
    surface: SurfaceSection = _section(SurfaceSection)
    material: MaterialSection = _section(MaterialSection)
    interaction: InteractionSection = _section(InteractionSection)
    control: ControlSection = _section(ControlSection)
    solver: SolverSection = _section(SolverSection)
    output: OutputSection = _section(OutputSection)
    units: UnitsSection = _section(UnitsSection)
    checks: ChecksSection = _section(ChecksSection)
    flow: FlowSection = _section(FlowSection)
    text: str = ""
    path: str = None
    base_dir: str = "."

    @classmethod
    def from_file(cls, path, comm=None, *, read_header=None):
        """Read and validate a scene file on rank 0 of ``comm`` (default COMM_WORLD).

        Every rank returns the same :class:`Scene` or raises the same
        :class:`SceneError` (also for a missing or unreadable file and for
        malformed TOML, whose message gives the line and column).
        """
        path = Path(path)

        def parse():
            try:
                text = path.read_text(encoding="utf-8-sig")  # a byte-order mark is no error
            except FileNotFoundError:
                raise SceneError(f"scene file {path} not found") from None
            except (OSError, UnicodeDecodeError) as exc:
                raise SceneError(f"cannot read scene file {path}: {exc}") from None
            return _parse(text, path.resolve().parent, str(path), str(path), read_header)

        return cls._from_root(parse, comm)

    @classmethod
    def from_text(cls, text, comm=None, base_dir=None, source="<scene>", *, read_header=None):
        """Validate scene text (rank 0's copy) and return it on every rank of ``comm``.

        ``base_dir`` (default: the current directory) is where relative paths start.
        """
        base = Path(base_dir if base_dir is not None else ".").resolve()
        return cls._from_root(lambda: _parse(text, base, source, None, read_header), comm)

    @classmethod
    def from_dict(cls, data, comm=None, base_dir=None, *, read_header=None):
        """Validate a scene given as nested mappings (``{"grid": {"nx": 256}, ...}``).

        For scenes made in code (benchmarks, notebooks, tests): the mappings are
        written as TOML text (the scene's :attr:`text`, as stored in a result
        file) and validated like a file.
        """
        return cls.from_text(to_toml(data), comm, base_dir=base_dir, source="<scene dict>",
                             read_header=read_header)

    @classmethod
    def _from_root(cls, parse, comm):
        if comm is None:
            # deferred: the schema (validation, describe_schema) needs no MPI
            from mpi4py import MPI
            comm = MPI.COMM_WORLD
        return _build(root_decides(comm, parse))

    def case(self):
        """What the scene's solves combine, in the words of :mod:`petgap.io.solver_registry`.

        (A scene of the paper's protocol, ``control.reference``, has adhesive steps.)
        """
        control = self.control
        return _case({"interaction": self.interaction, "surface": self.surface},
                     solver=self.solver.tao_type, precision=self.solver.precision,
                     tolerance=self.solver.tolerance,
                     control=None if control.kind == "none" else control.kind)

    def to_dict(self):
        """The resolved scene as nested plain data (JSON-serialisable), without the text."""
        out = {}
        for f in fields(self):
            if "section" in f.metadata:
                section = getattr(self, f.name)
                out[f.name] = {k: (dict(v) if k == "petsc_options" else
                                   list(v) if isinstance(v, tuple) else v)
                               for k, v in dataclasses.asdict(section).items()}
        return out

    def to_json(self):
        """:meth:`to_dict` as compact JSON text."""
        return json.dumps(self.to_dict(), sort_keys=False, separators=(",", ":"))


def to_toml(data):
    """Nested mappings of sections and keys as TOML text (inline tables below the sections)."""
    lines = []
    for name, table in data.items():
        if not isinstance(table, dict):
            raise SceneError(f"{name} = {_toml_repr(table)}: is not a table; "
                             f"allowed: a [{name}] section")
        lines.append(f"[{_toml_key(name)}]")
        lines += [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in table.items()]
        lines.append("")
    return "\n".join(lines)


def _toml_key(key):
    key = str(key)
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else json.dumps(key)


def _toml_value(value):
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, numbers.Integral):
        return str(int(value))
    if isinstance(value, numbers.Real):
        value = float(value)
        return repr(value) if math.isfinite(value) else ("nan" if value != value else
                                                         ("inf" if value > 0 else "-inf"))
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{_toml_key(k)} = {_toml_value(v)}"
                               for k, v in value.items()) + "}"
    raise SceneError(f"{value!r}: a {type(value).__name__} has no TOML form; allowed: numbers, "
                     f"strings, booleans, lists and tables")


def schema_default(section, name):
    """The plain default of key ``section.name`` (``None`` if it has none or is unknown).

    Used to compare a stored scene with a newer schema: a key that a file does not
    have, and whose value is its default, changes nothing that was computed.
    """
    for sec_name, cls, _ in _sections():
        if sec_name == section:
            k = _keys(cls).get(name)
            if k is None or k.default is REQUIRED or isinstance(k.default, Derived):
                return None
            return list(k.default) if isinstance(k.default, tuple) else k.default
    return None


def _sections():
    return [(f.name, f.metadata["section"], f.metadata["doc"]) for f in fields(Scene)
            if "section" in f.metadata]


# ---------------------------------------------------------------- the parser
def _toml_repr(value):
    """A value written the way it would appear in TOML (truncated if long)."""
    if isinstance(value, bool):
        text = "true" if value else "false"
    elif isinstance(value, str):
        text = json.dumps(value)
    elif isinstance(value, float):
        text = repr(value)
    elif isinstance(value, (list, tuple)):
        text = "[" + ", ".join(_toml_repr(v) for v in value) + "]"
    elif isinstance(value, dict):
        text = "{" + ", ".join(f"{k} = {_toml_repr(v)}" for k, v in value.items()) + "}"
    else:
        text = str(value)
    return text if len(text) <= 80 else text[:77] + "..."


def _parse(text, base_dir, source, path, read_header=None):
    """Validate scene text; return the plain payload :func:`_build` turns into a Scene."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{source}: not valid TOML: {exc}") from None

    errors = []
    sections = _sections()
    names = [name for name, _, _ in sections]
    all_keys = {name: _keys(cls) for name, cls, _ in sections}

    for top, value in data.items():
        if top in all_keys:
            if not isinstance(value, dict):
                errors.append(f"{top} = {_toml_repr(value)}: is not a table; "
                              f"allowed: a [{top}] section")
            continue
        if isinstance(value, dict):
            errors.append(f"[{top}]: unknown section{_suggest_section(top, names)}; "
                          f"allowed: the sections {', '.join(names)}")
        else:
            owners = [s for s in names if top in all_keys[s]]
            hint = f" (did you mean {owners[0]}.{top}, in section [{owners[0]}]?)" if owners \
                else _suggest_section(top, names)
            errors.append(f"{top} = {_toml_repr(value)}: unknown top-level key{hint}; "
                          f"allowed: keys inside the sections {', '.join(names)}")

    ctx = {"_base_dir": str(base_dir), "_data": data, "_read_header": read_header}
    payload = {}
    for name, cls, _ in sections:
        table = data.get(name, {})
        if not isinstance(table, dict):
            ctx[name] = None
            continue
        values = _parse_section(name, cls, table, ctx, all_keys, errors)
        payload[name] = values
        ctx[name] = None if values is None else cls(**values)

    if errors:
        if len(errors) == 1:
            raise SceneError(f"{source}: {errors[0]}", errors)
        lines = "\n".join(f"  - {e}" for e in errors)
        raise SceneError(f"{source}: {len(errors)} errors:\n{lines}", errors)
    return {"sections": payload, "text": text, "path": path, "base_dir": str(base_dir)}


def _suggest_section(name, names):
    close = difflib.get_close_matches(name, names, n=1, cutoff=0.6)
    return f" (did you mean [{close[0]}]?)" if close else ""


def _parse_section(name, cls, table, ctx, all_keys, errors):
    """Check one table against its section class; return its values or None if invalid."""
    keys = all_keys[name]
    n_errors = len(errors)
    for k, v in table.items():
        if k not in keys:
            errors.append(_unknown_key(name, k, v, all_keys))

    values, invalid, derived = {}, set(), []
    ctx["_section"] = values
    for k, spec in keys.items():
        dotted = f"{name}.{k}"
        applies = True
        if spec.when is not None:
            other, allowed_values = spec.when
            if other in invalid:
                invalid.add(k)
                continue
            applies = values.get(other) in allowed_values
        if k in table:
            raw = table[k]
            if not applies:
                other, allowed_values = spec.when
                which = " or ".join(f"{name}.{other} = {json.dumps(a)}" for a in allowed_values)
                errors.append(f"{dotted} = {_toml_repr(raw)}: does not apply with "
                              f"{name}.{other} = {_toml_repr(values.get(other))}; "
                              f"allowed: only with {which}")
                invalid.add(k)
                continue
            try:
                values[k] = spec.type.convert(raw, ctx)
                values[f"_given_{k}"] = True
            except _Invalid as exc:
                errors.append(f"{dotted} = {_toml_repr(raw)}: {exc.problem}; "
                              f"allowed: {exc.allowed}")
                invalid.add(k)
            except _Skip:
                invalid.add(k)
        elif not applies:
            values[k] = None
        elif spec.default is REQUIRED:
            condition = ""
            if spec.when is not None:
                condition = f" when {name}.{spec.when[0]} = {_toml_repr(values[spec.when[0]])}"
            errors.append(f"{dotted} is missing: it is required{condition}; "
                          f"allowed: {spec.type.allowed()}")
            invalid.add(k)
        elif isinstance(spec.default, Derived):
            derived.append(k)
        else:
            values[k] = spec.default
    for k in derived:
        try:
            values[k] = keys[k].default.func(values, ctx)
        except _Missing as exc:
            errors.append(f"{name}.{k} is missing: {exc}; allowed: {keys[k].type.allowed()}")
            invalid.add(k)
        except (_Skip, KeyError):
            invalid.add(k)

    if not invalid and len(errors) == n_errors and hasattr(cls, "_check"):
        problems = []  # (key, value, problem, allowed); key None: problem is the whole line
        cls._check(values, ctx, problems)
        for k, value, problem, allowed in problems:
            errors.append(problem if k is None else
                          f"{name}.{k} = {_toml_repr(value)}: {problem}; allowed: {allowed}")
    ctx.pop("_section", None)
    if invalid or len(errors) != n_errors:
        return None
    return {k: v for k, v in values.items() if not k.startswith("_")}


def _unknown_key(section, k, value, all_keys):
    known = list(all_keys[section])
    close = difflib.get_close_matches(k, known, n=1, cutoff=0.6)
    if close:
        hint = f" (did you mean {section}.{close[0]}?)"
    else:
        owners = [s for s, keys in all_keys.items() if k in keys and s != section]
        hint = f" (did you mean {owners[0]}.{k}, in section [{owners[0]}]?)" if owners else ""
    return (f"{section}.{k} = {_toml_repr(value)}: unknown key{hint}; "
            f"allowed: the keys of [{section}]: {', '.join(known)}")


def _build(payload):
    sections = {name: cls(**payload["sections"][name]) for name, cls, _ in _sections()}
    return Scene(**sections, text=payload["text"], path=payload["path"],
                 base_dir=payload["base_dir"])


# ------------------------------------------------------------------ the docs
def describe_schema():
    """A markdown description of every section and key: type, default, allowed values, doc."""
    out = ["| key | type | default | allowed | description |",
           "|---|---|---|---|---|"]
    for name, cls, doc in _sections():
        first = " ".join((doc or "").strip().split("\n\n")[0].split())
        out.append(f"| **[{name}]** | | | | {_md(first)} |")
        for k, spec in _keys(cls).items():
            description = spec.doc
            if spec.when is not None:
                which = " or ".join(f'`{spec.when[0]} = "{a}"`' for a in spec.when[1])
                description += f" (only with {which})"
            out.append(f"| `{name}.{k}` | {spec.type.name} | {_md(spec.default_text())} | "
                       f"{_md(spec.type.allowed())} | {_md(description)} |")
    return "\n".join(out) + "\n"


def _md(text):
    return str(text).replace("|", "\\|")
