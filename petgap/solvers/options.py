"""The PETSc options a petgap run reads, checked before anything runs.

PETSc's database cannot say which options were read (petsc4py wraps no "used"
query), so a run's options are checked against :data:`KNOWN_OPTIONS` and
:data:`KNOWN_PREFIXES` first: a misspelt name is found before the run rather than
ignored, and a malformed value is named instead of ending in PETSc's error code.
"""
import difflib
import math
import re

from petgap.solvers.settings import PETGAP_OPTIONS

#: The PETSc options a petgap run reads, with the kind of value each takes:
#: ``"int"``, ``"real"``, ``"bool"`` (a bare flag is true), ``"word"`` (any
#: text, checked elsewhere: ``tao_type``), ``"viewer"`` (an optional viewer
#: spec such as ``ascii:file.txt``), ``"flag"`` (no value), ``"precision"``
#: (``single`` or ``double``).  PETSc's database
#: cannot say which options were read (petsc4py wraps no "used" query, and
#: petgap pushes and pops its options around every solve), so they are checked
#: against this list before anything runs: a misspelt name is found before
#: the run rather than ignored, and a malformed value is named instead of
#: ending in PETSc's error code.
KNOWN_OPTIONS = {
    # TAO, read by TaoSetFromOptions for every type (petgap's own run as TAO "python")
    "tao_type": "word", "tao_max_it": "int", "tao_max_funcs": "int",
    "tao_gatol": "real", "tao_grtol": "real", "tao_gttol": "real", "tao_catol": "real",
    "tao_crtol": "real", "tao_fmin": "real", "tao_steptol": "real", "tao_trust0": "real",
    "tao_monitor": "viewer", "tao_smonitor": "viewer", "tao_cmonitor": "viewer",
    "tao_gmonitor": "viewer", "tao_xmonitor": "viewer", "tao_monitor_cancel": "bool",
    "tao_view": "viewer", "tao_converged_reason": "viewer", "tao_view_solution": "viewer",
    "tao_view_gradient": "viewer", "tao_view_stepdirection": "viewer",
    "tao_view_ls_residual": "viewer", "tao_recycle_history": "bool", "tao_mf_hessian": "bool",
    "tao_fd_gradient": "bool", "tao_fd_hessian": "bool", "tao_subset_type": "word",
    "tao_ls_type": "word",
    # petgap's own (the settings of petgap.solvers.settings.read_settings)
    **{name: kind for name, (_, kind) in PETGAP_OPTIONS.items()},
    # PETSc at large (profiling, debugging), read at initialisation or finalisation
    "log_view": "viewer", "log_view_memory": "bool", "log_all": "bool", "log_trace": "viewer",
    "log_exclude": "word", "options_left": "bool", "options_view": "viewer",
    "options_monitor": "viewer", "memory_view": "bool", "malloc_debug": "bool",
    "malloc_dump": "bool", "malloc_view": "bool", "info": "viewer", "help": "flag",
    "on_error_abort": "flag", "fp_trap": "bool", "no_signal_handler": "bool",
    "check_pointer_intensity": "int", "objects_dump": "flag",
}

#: Prefixes of the options of one TAO type, its line search and its inner
#: solvers (read only when that type runs, and too many to list).
KNOWN_PREFIXES = ("tao_ls_", "tao_bncg_", "tao_blmvm_", "tao_bqnls_", "tao_bqnk_", "tao_bnk_",
                  "tao_gpcg_", "tao_bnls_", "tao_bntr_", "tao_bntl_", "tao_view_",
                  "tao_monitor_", "tao_draw_", "tao_ksp_", "tao_pc_", "tao_mat_lmvm_",
                  "tao_bqnls_mat_lmvm_",
                  # the flow step's Krylov solver and multigrid (petgap.flow, prefix flow_)
                  "flow_ksp_", "flow_pc_", "flow_mg_")

_TRUE_FALSE = ("true", "false", "yes", "no", "on", "off", "1", "0")
_SPECIAL = ("petsc_default", "default", "petsc_decide", "decide", "petsc_determine",
            "determine")
_INT = re.compile(r"^[-+]?\d+$")


def option_problem(name, value):
    """What is wrong with the value of the known option ``name``, or None.

    Parses as PETSc will (integers, also ``1e3``; reals; booleans
    ``true/false/yes/no/on/off/1/0``, a bare flag is true; PETSc's
    ``DEFAULT``/``DECIDE`` names) and returns ``(problem, allowed)``.
    """
    kind = KNOWN_OPTIONS.get(name)
    text = "" if value is None else str(value).strip()
    if kind == "int":
        if text == "":
            return "has no value", "an integer, e.g. 100"
        if _INT.match(text) or text.lower() in _SPECIAL:
            return None
        try:
            x = float(text)
        except ValueError:
            return "is not an integer", "an integer, e.g. 100"
        if math.isfinite(x) and x == int(x):
            return None
        return "is not an integer", "an integer, e.g. 100"
    if kind == "real":
        if text == "":
            return "has no value", "a real number, e.g. 1e-8"
        if text.lower() in _SPECIAL:
            return None
        try:
            x = float(text)
        except ValueError:
            return "is not a number", "a real number, e.g. 1e-8"
        return None if not math.isnan(x) else ("is not a number", "a real number, e.g. 1e-8")
    if kind == "bool":
        if text == "" or text.lower() in _TRUE_FALSE:
            return None
        return "is not a boolean", "true or false (yes/no, on/off, 1/0), or no value (true)"
    if kind == "flag" and text:
        return "takes no value", "the bare option"
    if kind == "precision" and text not in ("single", "double"):
        return "is not a precision", "single or double"
    return None


def check_petsc_options(options):
    """Check PETSc options ``{name: value}`` (names without the dash).

    Returns ``(errors, unknown)``: ``errors`` a list of ``(name, value, problem,
    allowed)`` for malformed values of known options, ``unknown`` a list of
    ``(name, suggestion or None)`` for names petgap does not read (see
    :data:`KNOWN_OPTIONS` and :data:`KNOWN_PREFIXES`).
    """
    errors, unknown = [], []
    for raw, value in dict(options or {}).items():
        name = str(raw).lstrip("-")
        if name in KNOWN_OPTIONS:
            problem = option_problem(name, value)
            if problem is not None:
                errors.append((name, value, *problem))
        elif not name.startswith(KNOWN_PREFIXES):
            close = difflib.get_close_matches(name, list(KNOWN_OPTIONS), n=1, cutoff=0.75)
            unknown.append((name, close[0] if close else None))
    return errors, unknown
