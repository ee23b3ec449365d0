"""The paper's figures from analysed steps: Fig. 2 (gap distributions), Fig. 3
(adhesive gap distributions, normalised by a non-adhesive reference) and Fig. 4
(the integrand of Eq. 16).

The series and their legend labels are pure functions of the analysed steps
(the same on every rank, recorded in ``petgap-post``'s JSON table); drawing
happens on one rank.  Paper: Monti, Sanner & Pastewka, Tribology Letters 2021,
DOI 10.1007/s11249-021-01454-6.
"""
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from petgap import analysis

#: rho / g0 of the Fig. 4 curves (the paper's).
FIG4_RHO_OVER_G0 = (0.01, 0.1, 1.0)


def pyplot():
    """matplotlib's pyplot on the Agg backend (no display needed).

    Imported on first use, so that the commands start, and run on every rank
    but the one that draws, without loading matplotlib.
    """
    import matplotlib  # deferred: only the rank that draws loads matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # deferred, after choosing the Agg backend
    return plt


def _power_law_line(ax, xs):
    xs = [x for x in xs if x.size]
    if not xs:
        lo, hi = 1e-4, 10.0
    else:
        lo = min(float(x[x > 0].min()) for x in xs if np.any(x > 0))
        hi = max(float(x.max()) for x in xs)
    grid = np.geomspace(lo, hi, 50)
    ax.plot(grid, grid ** (-1.0 / 3.0), "k--", lw=1.2, label="Eq. 13: $(g/g_0)^{-1/3}$",
            zorder=5)


def _number(value):
    """``32`` for 32.0000001, else three significant digits."""
    if value is None or not math.isfinite(value):
        return "?"
    near = round(value)
    return f"{near:d}" if near and abs(value - near) <= 1e-6 * abs(value) else f"{value:.3g}"


@dataclass
class Fig2Series:
    """One series of Fig. 2: its step, legend label and marker."""
    result: object  # petgap.app.post.StepResult
    label: str
    marker: str
    filled: bool


@dataclass
class Fig2Legend:
    series: list
    title: str


#: Fig. 2 markers by rank of lambda_min (the smallest filled, as in the paper).
FIG2_MARKERS = ("o", "o", "s", "^", "D", "v", "<", ">")


def fig2_series(results):
    """Legend labels and markers of Fig. 2 (pure; the same on every rank).

    Each series is labelled with what tells it apart, in the paper's parameters:
    ``lambda_min`` in pixels always (where known), ``lambda_max / lambda_min`` and
    ``L / lambda_max`` where they differ between the series; the parameters that
    all series share go into the legend title.  Series whose labels would still be
    equal get ``(file:step)``; series without ``lambda_min`` are labelled
    ``file:step``.  Markers: the smallest ``lambda_min`` filled circles, the next
    open circles (the paper's Fig. 2), further ones open squares, triangles, ...
    """
    def params(r):
        row = r.row
        lmin, lmax = row["lambda_min"], row["lambda_max"]
        lx, ly = row["nx"] * row["dx"], row["ny"] * row["dy"]
        return {"lmin": r.meta["lambda_min_a0"],
                "ratio": lmax / lmin if lmin and lmax else None,
                "L": (lx / lmax, ly / lmax) if lmax else None}

    plotted = [r for r in results if np.any(r.y > 0)]
    info = [params(r) for r in plotted]

    def varies(key):
        values = {_key(p[key]) for p in info if p[key] is not None}
        return len(values) > 1

    def text(key, value):
        if key == "lmin":
            return f"$\\lambda_{{min}} = {_number(value)}\\,a_0$"
        if key == "ratio":
            return f"$\\lambda_{{max}}/\\lambda_{{min}} = {_number(value)}$"
        lx, ly = value
        both = _number(lx) if _key(lx) == _key(ly) else f"{_number(lx)} \\times {_number(ly)}"
        return f"$L/\\lambda_{{max}} = {both}$"

    shown = ["lmin"] + [k for k in ("ratio", "L") if varies(k)]
    title = []
    for key in ("ratio", "L"):
        known = [p[key] for p in info if p[key] is not None]
        if key not in shown and known:
            title.append(text(key, known[0]))
    labels = [", ".join(text(k, p[k]) for k in shown if p[k] is not None)
              if p["lmin"] is not None else "" for p in info]
    _disambiguate(labels, plotted)
    lmins = sorted({_key(p["lmin"]) for p in info if p["lmin"] is not None})
    series = []
    for r, p, label in zip(plotted, info, labels):
        rank = lmins.index(_key(p["lmin"])) if p["lmin"] is not None else 0
        series.append(Fig2Series(r, label, FIG2_MARKERS[min(rank, len(FIG2_MARKERS) - 1)],
                                 rank == 0))
    return Fig2Legend(series, ", ".join(title))


def _disambiguate(labels, results):
    """Make ``labels`` unique in place: ``file:step`` for empty labels, appended to equal ones
    (the file's stem, or its path where stems coincide)."""
    def where(i, full):
        name = results[i].row["file"] if full else Path(results[i].row["file"]).stem
        return f"{name}:{results[i].row['step']}"

    groups = {}
    for i, label in enumerate(labels):
        groups.setdefault(label, []).append(i)
    for label, members in groups.items():
        if label and len(members) == 1:
            continue
        full = len({where(i, False) for i in members}) < len(members)
        for i in members:
            labels[i] = f"{label} ({where(i, full)})" if label else where(i, full)


def _key(value):
    """A hashable, round-off-insensitive key of a number or a tuple of numbers."""
    if isinstance(value, tuple):
        return tuple(_key(v) for v in value)
    return float(f"{value:.9g}")


def figure2(legend, results, path):
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(5.5, 4.2))
    for s in legend.series:
        keep = s.result.y > 0
        ax.loglog(s.result.x[keep], s.result.y[keep], s.marker, ms=4,
                  fillstyle="full" if s.filled else "none", label=s.label)
    _power_law_line(ax, [r.x for r in results])
    _finish(fig, ax, path, "$g/g_0$", r"$p(g)\,/\,(2\pi c / 3 g_0)$",
            "Gap distribution of non-contacting points (Fig. 2)", fontsize=7,
            title=legend.title or None, title_fontsize=7)


@dataclass
class Fig3Series:
    """One series of Fig. 3: a step, the reference it is normalised by, its label."""
    result: object  # petgap.app.post.StepResult
    reference: object
    is_reference: bool
    label: str


def fig3_series(groups):
    """The series of Fig. 3, each distinct reference once, then its members (pure)."""
    out = []
    for g in groups:
        ref = g.reference
        for r in [ref] + g.members:
            if not r.distribution.centres.size:
                continue
            inv = r.row["inv_kappa_att"] if r.adhesive else 0.0
            label = f"$1/\\kappa_{{att}}$ = {inv:.2g}" if inv is not None and math.isfinite(inv) \
                else f"{Path(r.row['file']).stem}:{r.row['step']}"
            label += f", $A_{{rep}}/A_0$ = {r.row['c']:.3g}"
            if len(groups) > 1:
                label += f" (ref. {Path(ref.row['file']).stem}:{ref.row['step']})"
            out.append(Fig3Series(r, ref, r is ref, label))
    return out


def figure3(series, path):
    """Fig. 3: each series normalised by its (non-adhesive) reference's c and g0."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(5.5, 4.2))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    xs, rhos = [], {}
    for k, s in enumerate(series):
        c, g0 = s.reference.row["c"], s.reference.row["g0"]
        x, y = analysis.collapse(s.result.distribution, None, c, g0)
        keep = y > 0
        ax.loglog(x[keep], y[keep], "o" if s.is_reference else "s", ms=4,
                  color=colours[k % len(colours)],
                  fillstyle="full" if s.is_reference else "none", label=s.label)
        xs.append(x)
        if s.result.meta["rho"]:   # one line per value as labelled
            rhos.setdefault(f"{s.result.meta['rho'] / g0:.3g}", s.result.meta["rho"] / g0)
    _power_law_line(ax, xs)
    for text, rho in sorted(rhos.items(), key=lambda item: item[1]):
        ax.axvline(rho, color="0.5", ls=":", lw=1.2, label=f"$\\rho/g_0$ = {text}")
    _finish(fig, ax, path, "$g/g_0$ (non-adhesive $g_0$)",
            r"$p(g)\,/\,(2\pi c / 3 g_0)$ (non-adhesive $c$, $g_0$)",
            "Adhesive gap distributions (Fig. 3)", fontsize=7)


def figure4(path, data=()):
    """Fig. 4: the integrand of Eq. 16 for the paper's ``rho / g0``, and, for each adhesive
    step in ``data`` (``(label, force_by_gap dict)``), the measured share of ``F_att``
    per unit ``ln(g/g0)`` (:func:`petgap.analysis.attractive_force_by_gap`) beside the
    analytic curve at its own ``rho / g0`` (dotted; the exponential law's only, whose
    ``rho_over_g0`` is given)."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(5.5, 4.2))
    x = np.geomspace(1e-5, 1e2, 400)
    curves = analysis.fig4_integrand(x, FIG4_RHO_OVER_G0)
    for r, y in zip(FIG4_RHO_OVER_G0, curves):
        ax.semilogx(x, y, label=f"$\\rho/g_0$ = {r:g}")
    for label, found in data:
        r = found["rho_over_g0"]
        keep = np.asarray(found["share"]) > 0
        at = f", $\\rho/g_0$ = {r:.3g}" if r else ""
        line, = ax.semilogx(np.asarray(found["x"])[keep], np.asarray(found["share"])[keep],
                            "o", ms=3, mfc="none",
                            label=f"{label}: data{at} (contact {found['contact_share']:.0%})")
        if r:
            ax.semilogx(x, analysis.fig4_integrand(x, r), ":", color=line.get_color(), lw=1)
    _finish(fig, ax, path, "$g/g_0$", r"$x\,f(x)$: share of $F_{att}$ per unit $\ln(g/g_0)$",
            "Integrand of Eq. 16 (Fig. 4)", fontsize=8)


def _finish(fig, ax, path, xlabel, ylabel, heading, **legend):
    """Label the axes, heading and legend of a one-panel figure, save it and free it."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(heading, fontsize=10)
    ax.legend(**legend)
    fig.tight_layout()
    fig.savefig(path, dpi=150)
    pyplot().close(fig)
