"""What a run looks like: maps of each step, the curves of a sweep, the spectrum, the patches.

``petgap-post`` draws these for every result file besides the paper's Figs. 2-4
(:mod:`petgap.app.figures`).  Everything here runs on the rank that draws, from
small arrays: maps arrive block-averaged (:func:`petgap.analysis.block_map`),
curves as table rows.  Lengths are in the scene's length unit, pressures in its
pressure unit (``E*`` sets the scale when ``contact_modulus = 1``).
"""
import math
from dataclasses import dataclass

import numpy as np

from petgap import analysis
from petgap.app.figures import pyplot

#: Map pixels per axis in the figures (the saved arrays use the same maps).
FIGURE_MAP_PIXELS = 512
#: PSD bins below this fraction of the largest are round-off (not drawn).
ROUND_OFF_PSD = 1e-12
#: The pressure map's colour scale ends at this percentile of the pressures in contact: one
#: hot pixel (a peak of a rough map, a corner of a flat punch, the edge of a free map) bears
#: many times the pressure of the rest and would otherwise leave the map one colour.
PRESSURE_PERCENTILE = 99.0


def unit_label(symbol, unit, power=1):
    """An axis label with its unit: ``$x$ (nm)``, ``PSD (nm$^4$)``; ``"1"`` (the scene's own
    units) reads "scene units"."""
    if unit in (None, "", "1"):
        return f"{symbol} (scene units)"
    if power == 1:
        return f"{symbol} ({unit})"
    return f"{symbol} ({unit}$^{{{power}}}$)"


@dataclass
class StepMaps:
    """Block-averaged fields of one step (root rank): any of topography, gap, pressure,
    contact (the contact set's block fractions), each a :class:`petgap.analysis.Map`."""
    maps: dict
    contact_fraction: float
    title: str
    #: ``(length unit, pressure unit)`` of the fields (the result file's).
    units: tuple = ("1", "1")

    def save(self, path):
        """The maps as ``.npz``: ``<name>`` block means, ``<name>_counts`` pixels per block,
        ``factor`` and ``extent`` (x0, x1, y0, y1) of the map."""
        arrays = {}
        for name, m in self.maps.items():
            arrays[name] = m.values
            arrays[f"{name}_counts"] = m.counts
        some = next(iter(self.maps.values()))
        np.savez_compressed(path, factor=some.factor, extent=np.asarray(some.extent),
                            contact_fraction=self.contact_fraction, **arrays)


def draw_maps(step_maps, path):
    """Topography, gap, pressure and contact (with the contact edge drawn) side by side."""
    plt = pyplot()
    panels = [(name, label, cmap) for name, label, cmap in (
        ("topography", "topography $h$", "terrain"), ("gap", "gap $g$", "magma"),
        ("pressure", "pressure $p$", "viridis"), ("contact", "contact", "Greys"))
        if name in step_maps.maps]
    ncol = 2 if len(panels) > 1 else 1
    nrow = math.ceil(len(panels) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(5.2 * ncol, 4.6 * nrow), squeeze=False)
    for ax in axes.flat[len(panels):]:
        ax.set_visible(False)
    length, pressure = step_maps.units
    for ax, (name, label, cmap) in zip(axes.flat, panels):
        m = step_maps.maps[name]
        kwargs = {"vmin": 0.0, "vmax": 1.0} if name == "contact" else {}
        if name == "pressure":
            kwargs, label = _pressure_scale(m.values, label)
        if name == "contact" and 0 < step_maps.contact_fraction < 1:
            x = (np.arange(m.values.shape[0]) + 0.5) * (m.extent[1] / m.values.shape[0])
            y = (np.arange(m.values.shape[1]) + 0.5) * (m.extent[3] / m.values.shape[1])
            ax.contour(x, y, m.values.T, levels=[0.5], colors="tab:red", linewidths=0.6)
            label = f"contact, c = {step_maps.contact_fraction:.4g} (edge in red)"
        draw_map(fig, ax, m, label, cmap, length=length,
                 bar_unit=None if name == "contact" else
                 (pressure if name == "pressure" else length),
                 extend="max" if name == "pressure" and "vmax" in kwargs else "neither",
                 **kwargs)
    finish_maps(plt, fig, step_maps.title, path)


def draw_map(fig, ax, m, label, cmap, length="1", bar_unit=None, extend="neither", **kwargs):
    """One :class:`petgap.analysis.Map` on ``ax``, titled, its axes in ``length``, with its
    colour bar (labelled with ``bar_unit`` if given)."""
    image = ax.imshow(m.values.T, origin="lower", extent=m.extent, cmap=cmap,
                      interpolation="nearest", aspect="equal", **kwargs)
    blocks = "" if m.factor == 1 else f"  [{m.factor}x{m.factor} block means]"
    ax.set_title(label + blocks, fontsize=9)
    ax.set_xlabel(unit_label("$x$", length))
    ax.set_ylabel(unit_label("$y$", length))
    bar = fig.colorbar(image, ax=ax, shrink=0.85, extend=extend)
    if bar_unit is not None:
        bar.set_label(unit_label(label.split(",")[0].split(" (")[0], bar_unit))


def finish_maps(plt, fig, title, path):
    """Title, lay out, save and close a figure of maps."""
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _pressure_scale(values, label):
    """The pressure map's colour range, from 0 to :data:`PRESSURE_PERCENTILE` of the
    pressures in contact when the largest lies far above it, and the title saying so."""
    bearing = values[np.isfinite(values) & (values > 0)]
    if bearing.size == 0:
        return {}, label
    top = float(np.percentile(bearing, PRESSURE_PERCENTILE))
    if not 0 < top < float(bearing.max()):
        return {}, label
    return {"vmin": 0.0, "vmax": top}, (f"{label}, clipped at its {PRESSURE_PERCENTILE:g}th "
                                        f"percentile (max {float(bearing.max()):.3g})")


@dataclass
class SweepFits:
    """The fitted laws of one file's sweep (:mod:`petgap.analysis.load_curves`)."""
    kappa: object
    gap_law: object

    def to_dict(self):
        def plain(v):
            return v if v is None or math.isfinite(v) else None
        k, g = self.kappa, self.gap_law
        return {"kappa_rep_fit": plain(k.kappa), "kappa_rep_fit_points": k.npoints,
                "kappa_rep_fit_c_max": k.c_max,
                "gamma": None if g is None else plain(g.gamma),
                "gap_law_prefactor": None if g is None else plain(g.prefactor),
                "gap_law_points": 0 if g is None else g.npoints,
                "rms_height": None if g is None else g.rms_height}


def sweep_fits(rows, rms_height):
    """Fits of the non-adhesive steps among ``rows`` (table rows of one file)."""
    hard = [r for r in rows if r["interaction"] == "hard-wall"]
    x = [_reduced_load(r) for r in hard]
    kappa = analysis.fit_kappa_rep(x, [r["c"] for r in hard])
    gap_law = None
    if rms_height is not None and math.isfinite(rms_height) and rms_height > 0:
        gap_law = analysis.fit_gap_law([_num(r["mean_gap"]) for r in hard],
                                       [_num(r["mean_pressure"]) for r in hard], rms_height)
    return SweepFits(kappa, gap_law)


def _num(v):
    return math.nan if v is None else float(v)


def _reduced_load(row):
    p, s, e = (_num(row[k]) for k in ("mean_pressure", "rms_slope", "contact_modulus"))
    return p / (s * e)


def draw_sweep(rows, fits, path, title):
    """c against P0/(h0' E*) with the kappa_rep line; mean gap against load with the
    exponential law; F_att and 1/kappa_att against load if there are adhesive steps."""
    plt = pyplot()
    hard = [r for r in rows if r["interaction"] == "hard-wall"]
    sticky = [r for r in rows if r["interaction"] != "hard-wall"]
    length, pressure = (rows[0].get("length_unit", "1"), rows[0].get("pressure_unit", "1")) \
        if rows else ("1", "1")
    ncol = 3 if sticky else 2
    fig, axes = plt.subplots(1, ncol, figsize=(4.6 * ncol, 4.0))
    ax = axes[0]
    for group, marker, name in ((hard, "o", "hard wall"), (sticky, "s", "adhesive")):
        if group:
            ax.plot([_reduced_load(r) for r in group], [_num(r["c"]) for r in group], marker,
                    mfc="none", label=name)
    k = fits.kappa
    if k.npoints and math.isfinite(k.kappa):
        xs = np.array([x for x in (_reduced_load(r) for r in hard) if x > 0])
        line = np.linspace(0, xs.max(), 50)
        ax.plot(line, k.kappa * line, "k--", lw=1,
                label=rf"$\kappa_{{rep}}$ = {k.kappa:.3g} (fit, c $\leq$ {k.c_max:g}, "
                      f"{k.npoints} pts)")
    ax.set_xlabel(r"$P_0 / (h_0' E^*)$")
    ax.set_ylabel("contact fraction $c$")
    ax.set_title("contact area against load", fontsize=9)
    ax.legend(fontsize=7)

    ax = axes[1]
    g = [_num(r["mean_gap"]) for r in hard]
    p = [_num(r["mean_pressure"]) for r in hard]
    if hard:
        ax.semilogy(g, p, "o", mfc="none", label="hard wall")
    law = fits.gap_law
    if law is not None and math.isfinite(law.gamma):
        gs = np.linspace(min(g), max(g), 50)
        ax.semilogy(gs, law.load(gs), "k--", lw=1,
                    label=rf"$\exp(-\bar g / \gamma h_0)$, $\gamma$ = {law.gamma:.3g}")
    ax.set_xlabel(unit_label(r"mean gap $\bar g$", length))
    ax.set_ylabel(unit_label(r"mean pressure $P_0$", pressure))
    ax.set_title("load against mean gap", fontsize=9)
    if hard:
        ax.legend(fontsize=7)

    if sticky:
        ax = axes[2]
        load = [_num(r["mean_pressure"]) for r in sticky]
        ax.plot(load, [-_num(r["F_att"]) for r in sticky], "s", mfc="none",
                label=r"$-F_{att}$ (all pixels)")
        ax.set_xlabel(unit_label(r"mean pressure $P_0$", pressure))
        ax.set_ylabel(r"$-F_{att}$ (force per cell: pressure $\times$ length$^2$)")
        twin = ax.twinx()
        twin.plot(load, [_num(r["inv_kappa_att"]) for r in sticky], "^", color="tab:orange",
                  mfc="none", label=r"$1/\kappa_{att}$")
        twin.set_ylabel(r"$1/\kappa_{att}$")
        ax.set_title("adhesion against load", fontsize=9)
        lines = ax.get_legend_handles_labels()
        more = twin.get_legend_handles_labels()
        ax.legend(lines[0] + more[0], lines[1] + more[1], fontsize=7)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


@dataclass
class SurfaceView:
    """Statistics and radially averaged PSD of one file's topography (every rank)."""
    statistics: object
    q: np.ndarray
    psd: np.ndarray
    model: np.ndarray        # Eq. 5 on ``q`` (None unless the surface is self-affine)
    model_label: str
    topography: object       # its :class:`petgap.analysis.Map` (values on the root only)
    row: dict = None         # the surface-statistics table row
    length_unit: str = "1"   # of heights and lengths (the result file's)


def draw_psd(view, path, title):
    """The radially averaged PSD against the Eq. 5 model it was generated from."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(5.5, 4.2))
    # a band-limited surface has modes beyond its cutoff at round-off (1e-30 of the peak):
    # they are not drawn, so that the axis shows the spectrum
    floor = ROUND_OFF_PSD * float(np.max(view.psd)) if view.psd.size else 0.0
    keep = view.psd > floor
    hidden = int(np.count_nonzero(~keep))
    ax.loglog(view.q[keep], view.psd[keep], ".", ms=4, label="radial average of the topography"
              + (f" ({hidden} bins below {ROUND_OFF_PSD:g} of the peak not shown)"
                 if hidden else ""))
    if view.model is not None:
        use = view.model > 0
        ax.loglog(view.q[use], view.model[use], "k--", lw=1, label=view.model_label)
    unit = view.length_unit
    ax.set_xlabel(r"wavevector $|q|$" + ("" if unit in ("", "1") else f" (1/{unit})")
                  + (" (1/scene length)" if unit in ("", "1") else ""))
    ax.set_ylabel(unit_label(r"PSD $C(q)$", unit, 4) if unit not in ("", "1") else
                  r"PSD $C(q)$ (scene length$^4$)")
    s = view.statistics
    ax.set_title(f"{title}\n$h_0$ = {s.rms_height:.4g}, $h_0'$ = {s.rms_slope:.4g}, "
                 f"$h_0''$ = {s.rms_curvature:.4g} (spectral)", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def draw_patches(series, path, title, length_unit="1"):
    """Patch-area distributions (number of patches per logarithmic area bin), one per step."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(5.5, 4.2))
    for label, patches in series:
        edges, counts = patches.area_distribution()
        if counts.size == 0:
            continue
        centres = np.sqrt(edges[:-1] * edges[1:])
        keep = counts > 0
        ax.loglog(centres[keep], counts[keep] / np.diff(edges)[keep], "o-", ms=3, mfc="none",
                  label=f"{label}: {patches.count} patches")
    ax.set_xlabel(unit_label("patch area", length_unit, 2))
    ax.set_ylabel("patches per unit area (density)")
    ax.set_title(title, fontsize=9)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
