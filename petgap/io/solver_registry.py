"""The registry of solvers: what each solver type takes, and the rules of what combines.

One table, asked by everyone who needs to know what can be solved: the scene schema
(:mod:`petgap.io.scene`, the ``[solver]`` and ``[control]`` sections), the builder
(:mod:`petgap.app.build`), :func:`petgap.solve` (:mod:`petgap.solvers.dispatch`) and
``petgap study`` (its precision ladder).  Each rule is stated here once, as a
:class:`Refusal` that names the input refused, what is wrong and what is allowed; each
caller words the keys in its own terms (a scene says ``solver.precision = "mixed"``,
:func:`petgap.solve` says ``precision 'mixed'``) and raises it on every rank alike.

It is plain data over the words a scene uses -- controls ``"load"``, ``"mean-gap"``,
``"indentation"``; an interaction adhesive or not (the hard wall); a periodic cell or a
free boundary; precisions ``"double"``, ``"single"``, ``"mixed"`` -- and imports
nothing, so that the schema, which the data flow places below the solvers, asks the
same table as they do.

Solver types
------------
``pcg``
    petgap's own preconditioned projected conjugate gradients, in the formulation that
    suits the problem (:func:`resolve`): on the pressure for the hard wall under load or
    indentation, on a free boundary, and in single or mixed precision; on the gap
    otherwise (adhesion; the hard wall under mean-gap control on a periodic cell).
``pcg-pressure``
    Polonsky-Keer on the pressure: the hard wall only, in any precision.
``pcg-gap``
    Projected conjugate gradients on the gap, preconditioned by the compliance.
``bncg``, ``blmvm``, ``bqnls``, ``gpcg``
    TAO's bound-constrained minimisers on the gap.

How a control is reached (:func:`method`): mean-gap control by a TAO built-in a secant on
the multiplier around load solves, and mean-gap control of the hard wall on a free
boundary the indentation whose solution has that mean gap.  On a free boundary only the
pressure solver works on the map itself; the solvers on the gap, which need the
half-space's stiffness, solve the map's padded periodic cell.
"""
from dataclasses import dataclass

#: The controls a solve takes (``control.kind`` of a scene, ``kind`` of a control object).
CONTROLS = ("load", "mean-gap", "indentation")
#: Floating-point modes of a solve: double; single (a problem on a single-precision
#: grid); mixed (a double problem solved first on its single twin, then refined).
PRECISIONS = ("double", "single", "mixed")
#: Smallest tolerance of a single-precision solve: at least three times the rounding of
#: the displacement in 32 bits (a few units in the last place of ``max|u|``, where the
#: contact points are), so that edge points flipping in and out of contact on that
#: rounding do not decide when a solve ends (docs/accuracy.md, "Precision").  Mixed
#: precision runs its single-precision part to it.
SINGLE_TOLERANCE_FLOOR = 3e-6
#: Why adhesion is solved in double only: the gap solver's ``K (g + h)`` in 32 bits, and
#: mixed precision's best case measured in double (docs/accuracy.md, "Adhesion: double
#: only"; ``benchmarks/adhesive_precision.py``).
ADHESIVE_PRECISION = (
    "is for non-adhesive contact: adhesion is solved in double only.  In 32 bits the gap "
    "solver's elastic pressure K (g + h) rounds by 3e-5 to 1.2e-4 h0' E* (1024^2-4096^2), "
    "ten to forty times the pressure solver's floor, so a single solve would stop at 1e-4 "
    "to 4e-4, and a mixed one would save at most 12-33 % of the double solve's time and "
    "none of its memory (docs/accuracy.md, \"Adhesion: double only\")")
#: Other names of solver types: TAO's ``python`` type is how petgap's own solvers run.
ALIASES = {"python": "pcg"}


@dataclass(frozen=True)
class SolverType:
    """One solver type and what it takes.

    Attributes
    ----------
    name : str
    summary : str
    adhesive : bool
        Whether it takes an adhesive interaction (every type takes the hard wall).
    controls : tuple of str
        The controls it solves on a periodic cell.
    free_controls : tuple of str
        The controls it solves on a free boundary.
    precisions : tuple of str
    """

    name: str
    summary: str
    adhesive: bool = True
    controls: tuple = ("load", "mean-gap")
    free_controls: tuple = ("load", "mean-gap")
    precisions: tuple = ("double",)


_TAO = ("TAO's bound-constrained {} on the gap, in dimensionless variables; mean-gap "
        "control by a secant on the multiplier")

#: Every solver type, in the order they are listed to users.
SOLVERS = {solver.name: solver for solver in (
    SolverType("pcg", "petgap's preconditioned projected conjugate gradients, on the "
               "pressure or on the gap as the problem suits (resolve)",
               free_controls=CONTROLS, precisions=PRECISIONS),
    SolverType("pcg-pressure", "Polonsky-Keer conjugate gradients on the pressure, "
               "preconditioned by the stiffness on the contact set", adhesive=False,
               free_controls=CONTROLS, precisions=PRECISIONS),
    SolverType("pcg-gap", "projected conjugate gradients on the gap, preconditioned by the "
               "compliance"),
    SolverType("bncg", _TAO.format("nonlinear conjugate gradients")),
    SolverType("blmvm", _TAO.format("limited-memory variable-metric method")),
    SolverType("bqnls", _TAO.format("quasi-Newton line search")),
    SolverType("gpcg", _TAO.format("gradient-projection conjugate gradients")),
)}
#: The names of the solver types.
SOLVER_NAMES = tuple(SOLVERS)
#: The solver types that run as petgap's own conjugate gradients (a TAO ``python`` type).
PETGAP_TYPES = ("pcg", "pcg-pressure", "pcg-gap")
#: The names under which the pressure solver runs the hard wall (``pcg`` resolving to it).
PRESSURE_SOLVERS = ("pcg", "pcg-pressure")


def resolve(solver, control, adhesive, periodic, precision="double"):
    """The type that runs when ``solver`` is asked for: ``"pcg"`` picks its formulation.

    On the pressure where that solver applies and is the faster (the hard wall under
    load or indentation; a free boundary, whose map has no fast stiffness; single and
    mixed precision), on the gap otherwise: adhesion, and the hard wall under mean-gap
    control on a periodic cell.  Other types are themselves.
    """
    if solver != "pcg":
        return solver
    if adhesive:
        return "pcg-gap"
    if precision != "double" or control in ("load", "indentation") or not periodic:
        return "pcg-pressure"
    return "pcg-gap"


def grid_precision(precision):
    """The precision of the grid a solve in ``precision`` runs on.

    A single solve runs on a single-precision grid; double and mixed on a double grid
    (mixed makes the single twin of the double problem itself).
    """
    return "single" if precision == "single" else "double"


def method(kind, control, periodic):
    """How the resolved type ``kind`` reaches ``control``.

    ``"padded cell"`` (a free boundary solved on its padded periodic cell by a solver on
    the gap), ``"indentation"`` (mean gap of the hard wall on a free boundary, through
    the indentation), ``"multiplier"`` (mean-gap control of a TAO built-in) or
    ``"direct"`` (the solver under the control itself; the gap solver takes adhesive
    load control so, :func:`petgap.solvers.gap_start.cold_start`).
    """
    if not periodic and kind != "pcg-pressure":
        return "padded cell"
    if kind == "pcg-pressure":
        return "indentation" if control == "mean-gap" and not periodic else "direct"
    if kind == "pcg-gap":
        return "direct"
    return "multiplier" if control == "mean-gap" else "direct"


# ----------------------------------------------------------------- the rules
@dataclass(frozen=True)
class Refusal:
    """A combination that is not solved: the input refused, why, and what is allowed.

    ``key`` is the input refused (``"solver"``, ``"precision"``, ``"control"``,
    ``"load"``, ``"tolerance"``) and ``value`` its value; ``problem`` reads after them;
    ``facts`` are the ``(key, value)`` of the other inputs that make it wrong
    (``"interaction"``: adhesive or not, ``"boundary"``: periodic or not, and the keys
    above).  :meth:`message` words them with a caller's names of the keys.
    """

    key: str
    value: object
    problem: str
    allowed: str = ""
    facts: tuple = ()

    def detail(self, name):
        """``problem`` and the facts behind it, the keys worded by ``name(key, value)``."""
        if not self.facts:
            return self.problem
        return f"{self.problem} (here: {', '.join(name(k, v) for k, v in self.facts)})"

    def message(self, name=None):
        """The whole sentence, keys worded by ``name`` (default: :func:`api_name`)."""
        name = name or api_name
        allowed = f"; allowed: {self.allowed}" if self.allowed else ""
        return f"{name(self.key, self.value)} {self.detail(name)}{allowed}"


def api_name(key, value):
    """A key and its value as :func:`petgap.solve` and :func:`petgap.contact` word them."""
    if key == "control":
        return f"{value} control"
    if key == "interaction":
        return "an adhesive interaction" if value else "the hard wall"
    if key == "boundary":
        return "a periodic cell" if value else "a free boundary"
    return f"{key} {value!r}"


@dataclass(frozen=True)
class Case:
    """What a solve combines; a field that is None is not known, and its rules wait.

    ``solver`` as asked (``"pcg"`` too), ``control`` one of :data:`CONTROLS`,
    ``adhesive`` and ``periodic`` booleans, ``precision`` one of :data:`PRECISIONS`,
    ``grid`` the precision of the problem's grid, ``loads`` the mean pressures of load
    control, ``tolerance`` the solve's.
    """

    solver: str = None
    control: str = None
    adhesive: bool = None
    periodic: bool = None
    precision: str = None
    grid: str = None
    loads: tuple = ()
    tolerance: float = None

    @property
    def kind(self):
        """The type that runs (:func:`resolve`), or None while the solver is not known."""
        if self.solver is None:
            return None
        return resolve(self.solver, self.control, bool(self.adhesive),
                       self.periodic is not False, self.precision or "double")


def choice_refusal(key, value, choices):
    """Why ``value`` is not one of ``choices`` (a solver or a precision), or None."""
    if value in choices:
        return None
    return Refusal(key, value, f"is not one of {', '.join(choices)}")


def refusals(case):
    """Every rule ``case`` breaks, as :class:`Refusal` s, in the order they are told."""
    found = [None if case.solver is None else
             choice_refusal("solver", case.solver, SOLVER_NAMES),
             None if case.precision is None else
             choice_refusal("precision", case.precision, PRECISIONS)]
    if any(found):
        return [r for r in found if r is not None]
    for rule in (_precision, _indentation, _interaction, _tension, _single_tolerance):
        found.append(rule(case))
    return [r for r in found if r is not None]


def refusal(case):
    """The first rule ``case`` breaks (see :func:`refusals`), or None."""
    found = refusals(case)
    return found[0] if found else None


def check(case):
    """Raise ValueError with the :meth:`Refusal.message` of the first rule ``case`` breaks."""
    found = refusal(case)
    if found is not None:
        raise ValueError(found.message())


def control_words(control):
    """A control object's part of a :class:`Case`: its ``kind`` and, under load, its load.

    Any object with ``kind`` (one of :data:`CONTROLS`) and ``value`` will do
    (:class:`petgap.mechanics.problem.Load`, ``MeanGap``, ``Indentation``).
    """
    return {"control": control.kind,
            "loads": (control.value,) if control.kind == "load" else ()}


def _precision(case):
    """Single and mixed precision: the pressure solver, the hard wall, a periodic cell."""
    precision, grid = case.precision, case.grid
    if precision is None:
        return None
    if grid is not None and grid != grid_precision(precision):
        return Refusal("precision", precision, f"on a {grid}-precision grid: single solves "
                       f"a problem on a single-precision grid, double and mixed one on a "
                       f"double grid", " or ".join(p for p in PRECISIONS
                                                   if grid_precision(p) == grid))
    if precision == "double":
        return None
    if case.adhesive:
        return Refusal("precision", precision, ADHESIVE_PRECISION, "double",
                       (("interaction", True),))
    facts = tuple(fact for fact, wrong in (
        (("boundary", False), case.periodic is False),
        (("solver", case.solver), case.solver is not None
         and precision not in SOLVERS[case.solver].precisions),
        (("control", case.control), case.control not in (None, "load", "mean-gap")))
        if wrong)
    if not facts:
        return None
    return Refusal("precision", precision, "is for non-adhesive contact on a periodic cell "
                   "under load or mean-gap control, solved by pcg or pcg-pressure",
                   "double", facts)


def _indentation(case):
    """Indentation: a free boundary, the hard wall, the pressure solver."""
    if case.control != "indentation":
        return None
    if case.periodic and not any("indentation" in s.controls for s in SOLVERS.values()):
        return Refusal("control", "indentation", "needs a free boundary: on a periodic cell "
                       "an approach fixes no load", "load or mean-gap control, or a free "
                       "boundary")
    if case.adhesive:
        return Refusal("control", "indentation", "is for the hard wall: adhesion on a free "
                       "boundary is solved on its padded cell, under load or mean-gap "
                       "control", "load or mean-gap control, or the hard wall",
                       (("interaction", True),))
    if case.solver is not None and "indentation" not in SOLVERS[case.kind].free_controls:
        return Refusal("solver", case.solver, "does not solve indentation control (the "
                       "pressure solver does)", " or ".join(PRESSURE_SOLVERS))
    return None


def _interaction(case):
    """The pressure solver is for the hard wall."""
    if case.adhesive and case.solver is not None and not SOLVERS[case.solver].adhesive:
        return Refusal("solver", case.solver, "is Polonsky-Keer on the pressure, for "
                       "non-adhesive contact", "pcg, pcg-gap or a TAO solver with adhesion",
                       (("interaction", True),))
    return None


def _tension(case):
    """No tension without adhesion: the hard wall carries no tensile load."""
    if case.adhesive is not False:
        return None
    tensile = [load for load in case.loads if load < 0]
    if not tensile:
        return None
    return Refusal("load", tensile[0], "is tensile, which a non-adhesive contact cannot "
                   "carry", "a load >= 0, or an adhesive interaction",
                   (("interaction", False),))


def _single_tolerance(case):
    """A single-precision solve stops no tighter than :data:`SINGLE_TOLERANCE_FLOOR`."""
    if case.precision != "single" or case.tolerance is None \
            or case.tolerance >= SINGLE_TOLERANCE_FLOOR:
        return None
    return Refusal("tolerance", case.tolerance, "is below what single precision resolves: "
                   "the gap is a difference of heights with 7 significant digits",
                   f'>= {SINGLE_TOLERANCE_FLOOR:g} with precision "single", or precision '
                   f'"mixed" to refine in double', (("precision", "single"),))
