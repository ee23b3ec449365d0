"""``petgap-post`` for the ``[flow]`` step: the leak of each step, its maps, the leakage curve.

Reads what :mod:`petgap.app.flow_step` stored (``flow.*`` attributes, the
``flow_pressure`` and ``flow_flux_*`` maps), adds the flow's columns to the step's
table row, and draws per step the pressure and flux-magnitude maps and per sweep the
leakage curve: transmissivity and flow factor against load and against the mean gap,
and the percolation of the open region against the contact fraction, with the critical
contact fraction the sweep brackets (:func:`percolation_threshold`).
"""
from dataclasses import dataclass

import numpy as np

from petgap import analysis
from petgap.app.figures import pyplot
from petgap.app.flow_step import FLOW_FIELDS
from petgap.app.overview import draw_map, finish_maps

#: The table's flow columns and the step attributes they come from.
FLOW_ATTRIBUTES = {
    "flow_direction": ("flow.direction", str), "flow_leak_rate": ("flow.leak_rate", float),
    "flow_transmissivity": ("flow.transmissivity", float),
    "flow_factor": ("flow.flow_factor", float), "flow_percolates": ("flow.percolates", bool),
    "flow_open_fraction": ("flow.open_fraction", float),
    "flow_largest_cluster_fraction": ("flow.largest_cluster_fraction", float),
    "flow_spanning_fraction": ("flow.spanning_fraction", float),
    "flow_converged": ("flow.converged", bool), "flow_reason": ("flow.reason", str),
    "flow_iterations": ("flow.iterations", int), "flow_conservation": ("flow.conservation", float),
}
FLOW_COLUMNS = list(FLOW_ATTRIBUTES)


@dataclass
class FlowMaps:
    """Block-averaged flow maps of one step (root rank): pressure (mean over the pixels that
    carry fluid; NaN in a block with none) and flux magnitude, and the result file's
    ``(length, pressure)`` units ("1": the scene's own)."""
    pressure: object
    flux: object
    title: str
    units: tuple = ("1", "1")


def analyse_flow(group, attrs, grid, max_pixels, title):
    """The flow columns of a step and its :class:`FlowMaps` (None without a flow; collective)."""
    row = {column: attrs.find([name], column, required=False, kind=kind)[0]
           for column, (name, kind) in FLOW_ATTRIBUTES.items()}
    if row["flow_leak_rate"] is None or not all(name in group for name in FLOW_FIELDS):
        return row, None
    # deferred: importing h5py picks its MPI build, which only a post run needs
    from petgap.io.results import read_field
    pressure = read_field(group, "flow_pressure", grid)
    flux = np.hypot(read_field(group, "flow_flux_x", grid), read_field(group, "flow_flux_y", grid))
    wet = np.isfinite(pressure)
    sums = analysis.block_map(grid, np.where(wet, pressure, 0.0), max_pixels=max_pixels)
    share = analysis.block_map(grid, wet, max_pixels=max_pixels)
    magnitude = analysis.block_map(grid, flux, max_pixels=max_pixels)
    if grid.comm.rank != 0:
        return row, None
    with np.errstate(invalid="ignore", divide="ignore"):
        sums.values = np.where(share.values > 0, sums.values / share.values, np.nan)
    return row, FlowMaps(pressure=sums, flux=magnitude, title=title)


def draw_flow_maps(maps, path):
    """The pressure map and the flux magnitude map of one step side by side."""
    plt = pyplot()
    finish_maps(plt, flow_figure(plt, maps), maps.title, path)


def flow_figure(plt, maps):
    """The figure of :func:`draw_flow_maps`: axes in the length unit, the pressure's colour
    bar in the pressure unit, the flux's in length^2 per time (a volume per time per unit
    width; the time is the viscosity's unit over the pressure's, as in the result file)."""
    length, pressure = maps.units
    fig, axes = plt.subplots(1, 2, figsize=(10.4, 4.6))
    draw_map(fig, axes[0], maps.pressure, "fluid pressure $p$ (blank: no flow)", "coolwarm",
             length=length, bar_unit=pressure)
    flux = "1" if length in (None, "", "1") else f"{length}$^{{2}}$ / time"
    draw_map(fig, axes[1], maps.flux, "flux per unit width $|q|$", "Blues", length=length,
             bar_unit=flux)
    return fig


def percolation_threshold(rows):
    """The contact fractions between which the open region stops percolating in a sweep.

    ``{"c_below": c, "c_above": c, "c_critical": midpoint}`` from the largest contact
    fraction of a step that percolates and the smallest of one that does not (above
    it), or None when the sweep does not bracket the threshold.
    """
    steps = [(r["c"], bool(r["flow_percolates"])) for r in rows
             if r.get("flow_percolates") is not None and r.get("c") is not None]
    wet = [c for c, p in steps if p]
    dry = [c for c, p in steps if not p and (not wet or c > max(wet))]
    if not wet or not dry:
        return None
    below, above = max(wet), min(dry)
    return {"c_below": below, "c_above": above, "c_critical": 0.5 * (below + above)}


def draw_leakage_curve(rows, path, title):
    """Transmissivity and flow factor against load and mean gap; percolation against c."""
    plt = pyplot()
    rows = sorted((r for r in rows if r.get("flow_leak_rate") is not None),
                  key=lambda r: r["mean_pressure"])
    load = np.array([r["mean_pressure"] for r in rows])
    gap = np.array([r["mean_gap"] for r in rows])
    k = np.array([r["flow_transmissivity"] for r in rows])
    factor = np.array([r["flow_factor"] for r in rows])
    c = np.array([r["c"] for r in rows])
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.3))
    wet = k > 0
    for ax, x, xlabel in ((axes[0], load, "mean pressure $P_0$"),
                          (axes[1], gap, r"mean gap $\bar g$")):
        ax.semilogy(x[wet], k[wet], "o-", label=r"transmissivity $K = 12 \mu Q L / (W \Delta p)$")
        ax.semilogy(x[wet], gap[wet] ** 3, "--", color="grey", label=r"$\bar g^3$ (parallel plates)")
        if np.any(~wet):
            ax.plot(x[~wet], np.full(np.count_nonzero(~wet), k[wet].min() if wet.any() else 1),
                    "x", color="tab:red", label="no percolation ($Q = 0$)")
        ax.set_xlabel(xlabel)
        ax.set_ylabel("$K$")
        ax.legend(fontsize=8)
    ax = axes[2]
    ax.plot(c, [r["flow_largest_cluster_fraction"] for r in rows], "o-",
            label="largest open cluster / area")
    ax.plot(c, [r["flow_spanning_fraction"] for r in rows], "s-", label="spanning clusters / area")
    ax.plot(c, factor / max(factor.max(initial=0), 1e-300), "^:", label="flow factor (scaled)")
    threshold = percolation_threshold(rows)
    if threshold is not None:
        ax.axvspan(threshold["c_below"], threshold["c_above"], color="tab:red", alpha=0.15,
                   label=f"percolation threshold, c = {threshold['c_below']:.3g}"
                         f"-{threshold['c_above']:.3g}")
    ax.set_xlabel("contact fraction $c$")
    ax.set_ylabel("fraction")
    ax.legend(fontsize=8)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def flow_rows(rows):
    """The rows of steps with a flow."""
    return [r for r in rows if r.get("flow_leak_rate") is not None]


def threshold_text(rows):
    """The percolation threshold of a sweep in words (for the report)."""
    threshold = percolation_threshold(rows)
    if threshold is None:
        wet = [r for r in rows if r.get("flow_percolates")]
        return ("Every step percolates" if len(wet) == len(rows) else
                "No step percolates") + ": the steps do not bracket the percolation threshold"
    return (f"The open region stops percolating between c = {threshold['c_below']:.4g} and "
            f"c = {threshold['c_above']:.4g} (critical contact fraction about "
            f"{threshold['c_critical']:.3g})")
