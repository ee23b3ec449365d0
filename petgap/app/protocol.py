"""What a scene asks to be solved, step by step, and how the steps chain.

A run is a list of steps, each one solve written as one group of the result
file.  Steps form *chains*: each step is warm-started from the previous step of
its chain.

* A plain sweep (``control.kind`` = ``load`` or ``mean-gap``) is one chain, one
  step per value, with the scene's interaction.
* The paper's protocol (``control.reference = "non-adhesive"``, section 4 and
  Fig. 3): one chain of non-adhesive steps at the given loads, then one chain
  of adhesive steps, each at the mean gap that the matching non-adhesive step
  found.  Both chains are stored, so the adhesive gap distributions can be
  normalised by the non-adhesive ``g0`` and ``c``, as in Fig. 3.  A list of
  works of adhesion repeats the adhesive steps once per ``w``, in the order
  given, against the one reference; each ``w`` is a chain of its own
  (:meth:`petgap.app.build.Model.sweep_steps`), started cold.
"""
from dataclasses import dataclass
from typing import Optional

from petgap.mechanics.interactions import law_class
from petgap.mechanics.problem import Indentation, Load, MeanGap


@dataclass(frozen=True)
class Step:
    """One planned solve.

    Attributes
    ----------
    index : int
        Position in the run and in the result file (``step_0000``...).
    chain : str
        ``"sweep"``, ``"reference"`` (non-adhesive reference) or ``"adhesive"``.
    adhesive : bool
        Whether the scene's adhesive interaction applies (else the hard wall).
    control : Load, MeanGap or None
        ``None`` when the value comes from ``reference_step``'s mean gap.
    reference_step : int or None
        Index of the step whose mean gap this step imposes.
    work : float or None
        The work of adhesion of this step, where the scene lists several (else None:
        the scene's one).
    """

    index: int
    chain: str
    adhesive: bool
    control: Optional[object]
    reference_step: Optional[int] = None
    work: Optional[float] = None

    def attrs(self):
        """Attributes describing the plan of this step (for its HDF5 group)."""
        return {"chain": self.chain, "adhesive": self.adhesive,
                "reference_step": -1 if self.reference_step is None else self.reference_step}


def plan(scene):
    """The steps of a scene, in the order they run (empty for ``control.kind = "none"``)."""
    control = scene.control
    if control.kind == "none":
        return []
    adhesive = law_class(scene.interaction.kind).adhesive
    make = {"load": Load, "mean-gap": MeanGap, "indentation": Indentation}[control.kind]
    values = list(control.values)
    if control.reference == "non-adhesive":
        steps = [Step(i, "reference", False, Load(v)) for i, v in enumerate(values)]
        works = scene.interaction.work_of_adhesion
        series = list(works) if len(works) > 1 else [None]
        for work in series:
            first = len(steps)
            steps += [Step(first + i, "adhesive", True, None, reference_step=i, work=work)
                      for i in range(len(values))]
        return steps
    return [Step(i, "sweep", adhesive, make(v)) for i, v in enumerate(values)]


def control_of(step):
    """The control of a planned step for :func:`petgap.solvers.sweeps.sweep`.

    A step of the adhesive chain imposes the mean gap its reference step found,
    known only once that step is solved: a callable of the states before it.
    """
    if step.control is not None:
        return step.control
    reference = step.reference_step

    def mean_gap_of_reference(states):
        return MeanGap(states[reference].mean_gap)
    return mean_gap_of_reference
