"""Two-panel Fig. 2 in the paper's layout, from the tables petgap-post wrote.

    python docs/figures/plot_fig2.py docs/figures/fig2a_H03/gap-analysis.json \
        docs/figures/fig2b_H08/gap-analysis.json --output docs/figures/fig2.png

Only re-draws what petgap-post computed (its gap-analysis.json: per step the histogram
``edges``/``density`` and the row's ``c``, ``g0``), with the collapse of
``petgap.analysis.collapse``: x = g / g0, y = 3 g0 (1 - c) density / (2 pi c).  Colour
marks lambda_max / lambda_min, filled symbols lambda_min = 32 a0, open symbols 128 a0, as
in the paper.  Bins holding fewer than --min-count pixels (default 10) are left out.
(petgap-post's own fig2-gap-distribution.png draws the same points, one panel per call,
colouring each file separately; its labels name lambda_min, and lambda_max / lambda_min and
L / lambda_max where the files differ.)
"""
import argparse
import json
import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402


def series(path, min_count=0):
    doc = json.load(open(path))
    rows = {(r["file"], r["step"]): r for r in doc["rows"]}
    out = []
    for d in doc["distributions"]:
        r = rows[(d["file"], d["step"])]
        if not d["edges"] or r["c"] is None or r["g0"] is None:
            continue
        edges = np.asarray(d["edges"], float)
        dens = np.asarray([np.nan if v is None else v for v in d["density"]], float)
        x = np.sqrt(edges[:-1] * edges[1:]) / r["g0"]
        y = 3 * r["g0"] * (1 - r["c"]) * dens / (2 * math.pi * r["c"])
        counts = np.asarray(d["counts"])
        keep = np.isfinite(y) & (y > 0) & (counts >= min_count)
        out.append(dict(x=x[keep], y=y[keep], lmin=round(r["lambda_min"] / r["dx"]),
                        ratio=round(r["lambda_max"] / r["lambda_min"]), c=r["c"],
                        hurst=None))
    return out


def main():
    p = argparse.ArgumentParser()
    p.add_argument("tables", nargs="+", help="gap-analysis.json files, one per panel")
    p.add_argument("--titles", nargs="+", default=["(a) H = 0.3", "(b) H = 0.8"])
    p.add_argument("--output", default="fig2.png")
    p.add_argument("--min-count", type=int, default=10,
                   help="leave out bins with fewer pixels (Poisson noise > 30 %%; default 10)")
    args = p.parse_args()
    ratios = sorted({s["ratio"] for t in args.tables for s in series(t)})
    colours = dict(zip(ratios, plt.rcParams["axes.prop_cycle"].by_key()["color"]))
    fig, axes = plt.subplots(1, len(args.tables), figsize=(5.2 * len(args.tables), 4.4),
                             sharey=True)
    axes = np.atleast_1d(axes)
    for ax, table, title in zip(axes, args.tables, args.titles):
        data = series(table, args.min_count)
        for s in sorted(data, key=lambda s: (s["lmin"], s["ratio"])):
            open_ = s["lmin"] != 32
            ax.loglog(s["x"], s["y"], "o", ms=3.8, mew=1.0, color=colours[s["ratio"]],
                      fillstyle="none" if open_ else "full")
        xs = np.geomspace(1e-6, 10, 50)
        ax.loglog(xs, xs ** (-1 / 3), "k--", lw=1.3)
        ax.set_xlim(5e-7, 20)
        ax.set_ylim(0.1, 200)
        ax.set_xlabel("$g/g_0$")
        ax.set_title(title, fontsize=11)
        ax.grid(True, which="major", lw=0.3, alpha=0.5)
        handles = [Line2D([], [], ls="", marker="o", color=colours[r], label=f"{r}")
                   for r in ratios if any(s["ratio"] == r for s in data)]
        handles.append(Line2D([], [], ls="", marker="o", color="0.3",
                              label=r"$\lambda_{min} = 32\,a_0$"))
        if any(s["lmin"] != 32 for s in data):
            handles.append(Line2D([], [], ls="", marker="o", color="0.3", fillstyle="none",
                                  label=r"$\lambda_{min} = 128\,a_0$"))
        handles.append(Line2D([], [], ls="--", color="k", label="Eq. 13: $(g/g_0)^{-1/3}$"))
        ax.legend(handles=handles, title=r"$\lambda_{max}/\lambda_{min}$", fontsize=8,
                  title_fontsize=8, loc="lower left", ncol=2)
    axes[0].set_ylabel(r"$p(g)\,/\,(2\pi c/3g_0)$, $p$ normalised to $1-c$")
    fig.tight_layout()
    fig.savefig(args.output, dpi=150)


if __name__ == "__main__":
    main()
