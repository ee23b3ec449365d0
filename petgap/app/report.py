"""The report of a ``petgap-post`` run: one HTML page with the key numbers, the solver's
status per step, the provenance of every input and every figure.

The page is self-contained (PNG figures embedded as base64 data, other formats
linked relatively), so it can be mailed or archived on its own, and needs no
JavaScript or network to show.  A step that did not converge is flagged in red
in the status table and in the summary at the top: non-convergence is a result,
shown rather than hidden.
"""
import base64
import datetime
import html
import math
from pathlib import Path

from petgap._version import __version__
from petgap.app.flow_post import threshold_text

REPORT = "report.html"

#: Columns of the steps table: (row key, heading, format).
STEP_COLUMNS = [
    ("step", "step", "d"), ("interaction", "interaction", "s"), ("control", "control", "s"),
    ("control_value", "value", ".4g"), ("c", "c", ".4g"), ("mean_pressure", "P0", ".4g"),
    ("mean_gap", "mean gap", ".4g"), ("d_rep", "d_rep", ".4g"), ("g0", "g0", ".4g"),
    ("exponent", "p(g) exponent", ".3f"), ("patches", "patches", "d"),
    ("kappa_rep", "kappa_rep", ".3g"), ("F_att", "F_att", ".4g"),
    ("inv_kappa_att", "1/kappa_att", ".3g"),
]
STATUS_COLUMNS = [
    ("step", "step", "d"), ("solver", "solver", "s"), ("converged", "converged", "s"),
    ("reason", "reason", "s"), ("iterations", "iterations", "d"),
    ("kkt_pressure", "KKT (pressure)", ".2e"), ("kkt_gap", "KKT (gap)", ".2e"),
    ("wall_time", "wall time / s", ".3g"),
]
#: Columns of the flow table (steps with a ``[flow]`` result).
FLOW_COLUMNS = [
    ("step", "step", "d"), ("c", "c", ".4g"), ("mean_pressure", "P0", ".4g"),
    ("mean_gap", "mean gap", ".4g"), ("flow_leak_rate", "leak rate Q", ".4g"),
    ("flow_transmissivity", "transmissivity K", ".4g"), ("flow_factor", "flow factor", ".4g"),
    ("flow_percolates", "percolates", "s"), ("flow_open_fraction", "open", ".4g"),
    ("flow_largest_cluster_fraction", "largest cluster", ".4g"),
    ("flow_converged", "converged", "s"), ("flow_reason", "reason", "s"),
    ("flow_iterations", "iterations", "d"), ("flow_conservation", "mass balance", ".1e"),
]
SURFACE_COLUMNS = [
    ("nx", "nx", "d"), ("ny", "ny", "d"), ("dx", "dx", ".4g"), ("dy", "dy", ".4g"),
    ("rms_height", "h0", ".4g"), ("rms_slope", "h0'", ".4g"),
    ("rms_curvature", "h0''", ".4g"), ("rms_slope_fd", "h0' (FD, periodic)", ".4g"),
    ("rms_slope_fd_inner", "h0' (FD, inside)", ".4g"),
    ("rms_curvature_fd_inner", "h0'' (FD, inside)", ".4g"), ("kind", "surface", "s"),
    ("hurst", "H", ".3g"),
    ("lambda_min", "lambda_min", ".4g"), ("lambda_max", "lambda_max", ".4g"),
]

_STYLE = """
body { font-family: sans-serif; margin: 2em auto; max-width: 1150px; color: #222; }
h1 { font-size: 1.6em; margin-bottom: 0.2em; } h2 { border-bottom: 1px solid #ccc; }
table { border-collapse: collapse; margin: 0.5em 0 1.2em; font-size: 0.85em; }
th, td { border: 1px solid #ccc; padding: 3px 7px; text-align: right; }
th { background: #eef2f7; } td.text { text-align: left; }
tr.failed td { background: #fde2e2; } .failed-note { color: #b00020; font-weight: bold; }
.ok-note { color: #1b5e20; font-weight: bold; }
figure { margin: 1em 0 2em; } figcaption { font-weight: bold; margin-bottom: 0.3em; }
figure img { max-width: 100%; border: 1px solid #ddd; }
pre { background: #f6f6f6; padding: 0.6em; overflow-x: auto; font-size: 0.8em; }
.meta { color: #555; font-size: 0.9em; }
"""


def _cell(value, fmt):
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "<td>&ndash;</td>"
    if fmt == "s" or isinstance(value, bool):
        return f'<td class="text">{html.escape(str(value))}</td>'
    try:
        text = format(int(value) if fmt == "d" else float(value), fmt)
    except (TypeError, ValueError):
        return f'<td class="text">{html.escape(str(value))}</td>'
    return f"<td>{text}</td>"


def _table(rows, columns, failed=None):
    head = "".join(f"<th>{html.escape(h)}</th>" for _, h, _ in columns)
    body = []
    for row in rows:
        cls = ' class="failed"' if failed and failed(row) else ""
        body.append(f"<tr{cls}>" + "".join(_cell(row.get(k), f) for k, _, f in columns)
                    + "</tr>")
    return f"<table><tr>{head}</tr>{''.join(body)}</table>"


def not_converged(row):
    """True for a step whose solver reported no convergence."""
    return row.get("converged") is False


def flow_failed(row):
    """A flow solve that did not converge (a step that does not percolate did not solve)."""
    return row.get("flow_converged") is False


def _image(directory, name):
    path = Path(directory) / name
    if path.suffix.lower() == ".png" and path.is_file():
        data = base64.b64encode(path.read_bytes()).decode("ascii")
        return f'<img src="data:image/png;base64,{data}" alt="{html.escape(name)}">'
    if path.suffix.lower() == ".pdf":
        return f'<a href="{html.escape(name)}">{html.escape(name)}</a>'
    return f'<img src="{html.escape(name)}" alt="{html.escape(name)}">'


def render(directory, *, inputs, figures, rows, surfaces, sweeps, command_line, provenance):
    """The report's HTML text (see :func:`write_report`)."""
    directory = Path(directory)
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    failed = [r for r in rows if not_converged(r)]
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>petgap report</title>"
             f"<style>{_STYLE}</style></head><body>",
             "<h1>petgap report</h1>",
             f"<p class='meta'>{len(inputs)} result file(s), {len(rows)} step(s); written "
             f"{now} by petgap-post {html.escape(__version__)}: "
             f"<code>{html.escape(command_line)}</code></p>"]
    if failed:
        steps = ", ".join(f"{Path(r['file']).name}:{r['step']}" for r in failed)
        parts.append(f"<p class='failed-note'>{len(failed)} step(s) did not converge: "
                     f"{html.escape(steps)}. Their numbers are shown as the solver left them.</p>")
    elif rows:
        parts.append("<p class='ok-note'>Every step converged.</p>")
    for path in inputs:
        key = str(path)
        mine = [r for r in rows if r["file"] == key]
        prov = provenance.get(key, {})
        parts.append(f"<h2>{html.escape(key)}</h2>")
        meta = [("scene", prov.get("scene_path")), ("command line", prov.get("command_line")),
                ("MPI ranks", prov.get("mpi_size")), ("host", prov.get("hostname")),
                ("started", prov.get("start_time")), ("ended", prov.get("end_time")),
                ("complete", prov.get("complete")), ("petgap", prov.get("petgap_version")),
                ("PETSc options", prov.get("petsc_options"))]
        parts.append("<table>" + "".join(
            f"<tr><th>{html.escape(k)}</th><td class='text'>{html.escape(str(v))}</td></tr>"
            for k, v in meta if v not in (None, "")) + "</table>")
        surface = [s for s in surfaces if s.get("file") == key]
        if surface:
            parts.append("<h3>Surface</h3>" + _table(surface, SURFACE_COLUMNS))
        if mine:
            parts.append("<h3>Results per step</h3>" + _table(mine, STEP_COLUMNS, not_converged))
            parts.append("<h3>Solver status per step</h3>"
                         + _table(mine, STATUS_COLUMNS, not_converged))
        flowing = [r for r in mine if r.get("flow_leak_rate") is not None]
        if flowing:
            parts.append("<h3>Flow through the gaps</h3><p>Reynolds flow on each step's gap, "
                         f"along {html.escape(str(flowing[0].get('flow_direction')))}; "
                         "transmissivity K = 12 mu Q L / (W dp), flow factor K / (mean gap)^3. "
                         f"{html.escape(threshold_text(flowing))}.</p>"
                         + _table(flowing, FLOW_COLUMNS, flow_failed))
        fits = sweeps.get(key)
        if fits and len(mine) >= 2:
            parts.append("<h3>Laws of the sweep</h3>" + _table([fits], [
                ("kappa_rep_fit", "kappa_rep (fit)", ".4g"),
                ("kappa_rep_fit_points", "points", "d"), ("gamma", "gamma", ".4g"),
                ("gap_law_points", "points", "d")]))
        if prov.get("scene"):
            parts.append("<details><summary>scene</summary><pre>"
                         f"{html.escape(str(prov['scene']))}</pre></details>")
        for fig in figures:
            if fig.get("input") == key:
                parts.append(_figure(directory, fig))
    shared = [f for f in figures if f.get("input") is None]
    if shared:
        parts.append("<h2>Figures of all inputs</h2>")
        parts += [_figure(directory, f) for f in shared]
    parts.append("</body></html>")
    return "\n".join(parts)


def _figure(directory, fig):
    return (f"<figure><figcaption>{html.escape(fig['title'])}</figcaption>"
            f"{_image(directory, fig['file'])}</figure>")


def write_report(directory, **content):
    """Write :data:`REPORT` into ``directory`` (one rank); returns its path.

    ``content``: ``inputs`` (result paths), ``figures`` (the manifest's entries:
    file, title, kind, input, step), ``rows`` (the analysis table's rows),
    ``surfaces`` (surface-statistics rows), ``sweeps`` (fits per input),
    ``command_line`` and ``provenance`` (root attributes per input).
    """
    path = Path(directory) / REPORT
    path.write_text(render(directory, **content), encoding="utf-8")
    return path
