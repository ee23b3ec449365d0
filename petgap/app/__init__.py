"""The applications: what a user runs, on top of the library.

``main``
    The ``petgap`` command: one parser dispatching to ``run``, ``check``,
    ``schema`` and ``study``.
``build``
    A scene turned into the objects that are solved (grid, surface, problems,
    planned steps); used by every command, the benchmarks and the tests.
``protocol``
    The steps a scene asks for and how they chain (the paper's protocol:
    non-adhesive reference steps, then adhesive steps at their mean gaps).
``run``
    ``petgap run``: the steps solved in one sweep and written to a result file.
``study``, ``study_report``
    ``petgap study``: the speed/accuracy trade of a scene, and its outputs.
``post``, ``figures``, ``tables``
    ``petgap-post``: the paper's tables and Figs. 2-4 from result files.
``contact``
    :func:`petgap.contact <petgap.app.contact.contact>`: a global height map in,
    the solved contact and its statistics out (:class:`ContactResult`).  Import
    the function from :mod:`petgap` or :mod:`petgap.app.contact`; this package
    does not re-export it, so that ``petgap.app.contact`` stays the module.
``argtypes``
    Command-line argument types and the rank-0-only parser.
"""
from petgap.app.contact import ContactResult
from petgap.app.run import RunResult, run_scene

__all__ = ["run_scene", "RunResult", "ContactResult"]
