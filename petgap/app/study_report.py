"""What ``petgap study`` reports: its quantities, table, CSV, JSON and figure.

Pure functions of a :class:`petgap.app.study.StudyResult` (rows of plain
dicts), called on rank 0 only, apart from :func:`check_outputs`.
"""
import math
import sys
from pathlib import Path

import numpy as np

from petgap.app.figures import pyplot
from petgap.app.tables import plain_rows, write_csv, write_json
from petgap.parallel.collective import root_decides
from petgap._version import __version__

#: Output files: ``<stem>.csv``, ``<stem>.json``, ``<stem>.png``.
OUTPUT_STEM = "study"
OUTPUT_SUFFIXES = (".csv", ".json", ".png")
#: Quantities compared, in table order, and their descriptions.
QUANTITIES = {
    "c": "contact fraction A_rep / A0",
    "d_rep": "mean contact diameter pi A_rep / P_rep (Eq. 2)",
    "mean_gap": "mean gap (load control)",
    "mean_pressure": "mean pressure (mean-gap control)",
    "exponent": "exponent of the collapsed p(g) fitted over the common x = g/g0 range",
    "prefactor": "prefactor of that fit (Eq. 13: 1)",
    "F_att": "attractive force -sum dx dy v'(g) (Eq. 15; adhesive scenes)",
}
TITLES = {"c": "contact fraction c", "d_rep": "mean contact diameter d_rep",
          "mean_gap": "mean gap", "mean_pressure": "mean pressure",
          "exponent": "p(g) exponent (common x range)", "prefactor": "p(g) prefactor",
          "F_att": "attractive force F_att"}


class StudyError(ValueError):
    """A study that cannot be made as asked (reported as a user error, exit status 2)."""


COLUMNS = ["ladder", "rung", "value", "reference", "skipped", "shared_with", "nx", "ny", "a0",
           "lambda_min_a0", "tolerance", "precision", "converged", "reason", "iterations", "fft_pairs",
           "wall_time", "setup_time", "bytes_per_point", "peak_rss_mib", "kkt_pressure",
           "kkt_gap", "rms_height", "rms_slope", "adhesion_resolved", "c", "d_rep", "g0",
           "mean_gap", "mean_pressure", "exponent", "prefactor", "fit_points",
           "power_law_x_min", "power_law_decades", "F_att", "F_att_noncontact", "c_adhesive",
           "inv_kappa_att"] + \
          [f"err_{q}" for q in QUANTITIES]


def output_paths(output_dir):
    return [Path(output_dir) / f"{OUTPUT_STEM}{s}" for s in OUTPUT_SUFFIXES]


def check_outputs(output_dir, overwrite, comm):
    """Raise the same StudyError on every rank if the outputs cannot be written (rank 0 decides)."""
    def check():
        d = Path(output_dir)
        if d.exists() and not d.is_dir():
            raise StudyError(f"--output-dir {d} exists and is not a directory")
        if not overwrite:
            existing = [str(p) for p in output_paths(d) if p.exists()]
            if existing:
                raise StudyError(f"refusing to overwrite existing output {', '.join(existing)}; "
                                 f"pass --overwrite or choose another --output-dir")
        try:
            d.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise StudyError(f"cannot create --output-dir {d}: {exc}") from None
    root_decides(comm, check)


def all_rows(study):
    return [row for ladder in study.rows for row in study.rows[ladder]]


def write_outputs(study, output_dir, argv=None):
    """Write ``study.csv``, ``study.json`` and ``study.png`` (call on one rank)."""
    csv_path, json_path, png_path = output_paths(output_dir)
    rows = plain_rows(all_rows(study), COLUMNS)
    write_csv(csv_path, rows, COLUMNS)
    scene = study.scene
    doc = {"petgap_version": __version__,
           "command_line": " ".join(argv if argv is not None else sys.argv),
           "scene_path": scene.path, "scene": scene.text, "scene_resolved": scene.to_dict(),
           "settings": study.settings, "quantities": {q: QUANTITIES[q] for q in study.quantities},
           "references": {ladder: (None if i is None else study.rows[ladder][i]["rung"])
                          for ladder, i in study.references.items()},
           "notes": study.notes,
           "conventions": {
               "error": "|q - q_ref| / |q_ref| against the ladder's reference rung (the most "
                        "accurate converged one)",
               "wall_time": "solver wall time, s (slowest rank; summed over the solves of a "
                            "rung)",
               "setup_time": "grid (FFT planning), surface and problem, s",
               "fft_pairs": "elastic operator applications in transform pairs (one forward + one inverse FFT each)",
               "bytes_per_point": "peak resident memory of grid + surface + problem + solve "
                                  "above the resident memory before them, summed over ranks, "
                                  "over nx ny",
               "exponent, prefactor": "least-squares fit of log y on log x of the collapsed "
                                      "p(g) (Eq. 13) on common log bins over the fit range",
               "power_law_x_min, power_law_decades": "extent of the power law found by "
                                                     "petgap.analysis.fit_power_law (no error)",
               "F_att_noncontact, c_adhesive, inv_kappa_att": "adhesive state: the part of "
                                                              "F_att from pixels outside "
                                                              "repulsive contact, its contact "
                                                              "fraction and 1/kappa_att (no "
                                                              "error)"},
           "rows": rows}
    write_json(json_path, doc)
    figure(study, png_path)
    return [csv_path, json_path, png_path]


def figure(study, path):
    """Relative error against solver wall time, one panel per quantity, every ladder."""
    plt = pyplot()
    quantities = study.quantities
    ncols = 3
    nrows = int(math.ceil(len(quantities) / ncols))
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.2 * ncols, 3.4 * nrows), squeeze=False)
    styles = {"tolerance": ("o", "C0"), "resolution": ("s", "C3"), "precision": ("^", "C2")}
    floor = 1e-12
    for ax, q in zip(axes.flat, quantities):
        for ladder, rows in study.rows.items():
            marker, colour = styles[ladder]
            ref = study.references.get(ladder)
            pts = [(r["wall_time"], r[f"err_{q}"], r["rung"]) for i, r in enumerate(rows)
                   if not r.get("skipped") and i != ref and r.get("wall_time")
                   and r.get(f"err_{q}") is not None and math.isfinite(r[f"err_{q}"])]
            if not pts:
                continue
            t = np.array([p[0] for p in pts])
            e = np.array([p[1] for p in pts])
            shown = np.maximum(e, floor)
            reflabel = rows[ref]["rung"] if ref is not None else "-"
            ax.loglog(t, shown, "-", color=colour, lw=0.8, alpha=0.6)
            ax.loglog(t[e >= floor], shown[e >= floor], marker, color=colour, ls="none",
                      label=f"{ladder} (ref. {reflabel})")
            if np.any(e < floor):
                ax.loglog(t[e < floor], shown[e < floor], "v", color=colour, ls="none",
                          label=f"{ladder}: error < {floor:g}")
            for ti, si, ei, label in zip(t, shown, e, [p[2] for p in pts]):
                if ei < floor:
                    continue  # at the floor: the legend says so, labels would pile up
                ax.annotate(label, (ti, si), fontsize=6, xytext=(3, 3),
                            textcoords="offset points")
        lo, hi = ax.get_xlim()
        if hi < 10 * lo:  # at least a decade, so that the log axis has labelled ticks
            mid = math.sqrt(lo * hi)
            ax.set_xlim(mid / math.sqrt(10), mid * math.sqrt(10))
        ax.xaxis.set_minor_formatter(plt.NullFormatter())
        ax.set_title(TITLES[q], fontsize=9)
        ax.set_xlabel("solver wall time [s]", fontsize=8)
        ax.set_ylabel("relative error", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(True, which="major", alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=6)
    for ax in list(axes.flat)[len(quantities):]:
        ax.axis("off")
    name = Path(study.scene.path).name if study.scene.path else "scene"
    fig.suptitle(f"petgap study: {name} (errors against each ladder's most accurate rung; "
                 f"below {floor:g} drawn at {floor:g})", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def _fmt(value, spec):
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    return format(value, spec)


def format_table(study):
    """The printed table (a string)."""
    lines = []
    head = (f"{'rung':>9} {'grid':>11} {'conv':>4} {'its':>5} {'FFT':>6} {'wall s':>8} "
            f"{'B/pt':>6} " + " ".join(f"{'err ' + q:>12}" for q in study.quantities))
    for ladder, rows in study.rows.items():
        ref = study.references.get(ladder)
        scene = study.scene.grid
        title = (f"{ladder} ladder" + (f" at {scene.nx} x {scene.ny}, a0 = {scene.a0:g}"
                                        if ladder == "tolerance" else
                                        f" at tolerance {study.scene.solver.tolerance:g}"))
        if ladder == "precision":
            title += f", {scene.nx} x {scene.ny}"
        if ref is not None:
            r = rows[ref]
            values = ", ".join(f"{q} = {_fmt(r.get(q), '.6g')}" for q in study.quantities)
            title += f"; reference {r['rung']}: {values}"
        lines.append(title)
        lines.append(head)
        for i, r in enumerate(rows):
            if r.get("skipped"):
                grid = f"{r['nx']}x{r['ny']}" if r.get("nx") else "-"
                lines.append(f"{r['rung']:>9} {grid:>11} skipped: {r['skipped']}")
                continue
            errs = " ".join(f"{'ref' if i == ref else _fmt(r.get('err_' + q), '.2e'):>12}"
                            for q in study.quantities)
            lines.append(f"{r['rung']:>9} {str(r['nx']) + 'x' + str(r['ny']):>11} "
                         f"{'yes' if r['converged'] else 'NO':>4} {r['iterations']:>5d} "
                         f"{r['fft_pairs']:>6g} {r['wall_time']:>8.2f} "
                         f"{_fmt(r['bytes_per_point'], '.0f'):>6} {errs}")
        lines.append("")
    for note in study.notes:
        lines.append(f"note: {note}")
    return "\n".join(lines).rstrip() + "\n"
