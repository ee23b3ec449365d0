"""Applications on top of the library: the command lines, the scene runner and the one-call solve.

Modules
-------
:mod:`.run`
    The ``petgap`` command (``run``, ``check``, ``schema``, ``study``) and
    :func:`run_scene`, which runs a :class:`~petgap.io.scene.Scene` and writes
    its result file.
:mod:`.protocol`
    The steps a scene asks for and how they chain (sweeps, the paper's
    non-adhesive reference protocol).
:mod:`.study`
    ``petgap study``: what accuracy a scene's tolerance and resolution buy, and
    at what cost.
:mod:`.post`
    ``petgap-post``: tables and figures of the paper's quantities from result
    files.
:mod:`.contact`
    :func:`petgap.contact <petgap.app.contact.contact>`: a global height map in,
    the solved contact and its statistics out (:class:`ContactResult`).  Import
    the function from :mod:`petgap` or :mod:`petgap.app.contact`; this package
    does not re-export it, so that ``petgap.app.contact`` stays the module.
:mod:`.argtypes`
    Argument types shared by the command lines.
"""
from petgap.app.contact import ContactResult
from petgap.app.run import RunResult, run_scene

__all__ = ["run_scene", "RunResult", "ContactResult"]
