#!/usr/bin/env python3
"""Exponent and prefactor of Eq. 13 over seeds, per lambda_max / lambda_min (docs/paper.md).

Reads a ``gap-analysis.json`` of ``petgap-post --fit-range LO HI`` over runs that differ
only in ``surface.seed`` (runs/fig2_seeds.sh) and prints, per ratio: the number of seeds,
the fitted exponent of ``p(g)`` over the fit range (mean, standard deviation, standard
error), and the prefactor of Eq. 13, ``A = p(g) g0 / c / (g / g0)^(-1/3)`` averaged over the
bins of the fit range with the exponent held at -1/3, over its value ``2 pi / 3``.

Usage::

    python docs/figures/seed_table.py out/fig2_seeds/post/gap-analysis.json
"""
import json
import math
import sys
from collections import defaultdict

import numpy as np


def prefactor(distribution, row):
    """Mean of ``p g0 / c x^(1/3)`` over the bins inside the fit range, over ``2 pi / 3``."""
    edges = np.asarray(distribution["edges"])
    density = np.asarray(distribution["density"])
    g = np.sqrt(edges[1:] * edges[:-1])
    x = g / row["g0"]
    inside = (x >= row["fit_range_x_min"]) & (x <= row["fit_range_x_max"]) & (density > 0)
    values = density[inside] * row["g0"] / row["c"] * x[inside] ** (1 / 3)
    return float(np.mean(values)) / (2 * math.pi / 3) if values.size else math.nan


def main(path):
    data = json.loads(open(path).read())
    distributions = {(d["file"], d["step"]): d for d in data["distributions"]}
    by_ratio = defaultdict(list)
    for row in data["rows"]:
        ratio = round(row["lambda_max"] / row["lambda_min"])
        by_ratio[ratio].append((row["exponent_fit_range"],
                                prefactor(distributions[(row["file"], row["step"])], row),
                                row["c"]))
    print("| lambda_max / lambda_min | seeds | exponent (mean +- sd) | standard error | "
          "prefactor / (2 pi / 3) (mean +- sd) | c (mean) |")
    print("|---|---|---|---|---|---|")
    for ratio in sorted(by_ratio):
        e, a, c = (np.array(v, dtype=float) for v in zip(*by_ratio[ratio]))
        n = len(e)
        print(f"| {ratio} | {n} | {e.mean():.3f} +- {e.std(ddof=1):.3f} | "
              f"{e.std(ddof=1) / math.sqrt(n):.3f} | {a.mean():.3f} +- {a.std(ddof=1):.3f} | "
              f"{c.mean():.4f} |")


if __name__ == "__main__":
    main(sys.argv[1])
