#!/usr/bin/env python3
"""Eq. 16 against the measured attraction, split by where it acts: the table of docs/paper.md.

Reads a ``gap-analysis.json`` written by ``petgap-post`` for adhesive steps and their
non-adhesive references (runs/eq16_*.toml; runs/README.md has the commands) and prints,
per adhesive step: ``rho / g0`` (``g0`` of the reference), the measured ``1/kappa_att``
(``-F_att / (h0' E* A_rep)``, every pixel), its shares from pixels in repulsive contact
(where the exponential law still pulls with ``w / rho``), from gaps below ``0.1 g0`` (the
near-edge window of the power-law gap distribution) and from larger gaps, and Eq. 16 as
printed and with ``Gamma(2/3)`` (the exact integral), over the measured non-contact and
near-edge parts.  The shares come from petgap-post's ``force_by_gap`` (Fig. 4 from data):
per unit ``ln(g / g0)`` in bins of a tenth of a decade.

Usage::

    python docs/figures/eq16_table.py out/eq16/post/gap-analysis.json
"""
import json
import math
import sys


def main(path):
    data = json.loads(open(path).read())
    rows = data["rows"]
    references = {(r["file"], r["step"]): r for r in rows}
    # with --reference, one non-adhesive row serves every adhesive step
    hard = [r for r in rows if r.get("interaction") != "exponential"]
    common = hard[0] if len(hard) == 1 else None
    by_gap = {(f["file"], f["step"]): f for f in data["force_by_gap"]}
    print("| file | rho / a0 | w / (E* a0) | g0 / a0 | rho / g0 | 1/kappa_att | in contact | "
          "g < 0.1 g0 | g >= 0.1 g0 | Eq. 16 printed | Eq. 16 exact | exact / non-contact | "
          "exact / near-edge |")
    print("|" + "---|" * 13)
    for r in rows:
        if r.get("interaction") != "exponential" or (r["file"], r["step"]) not in by_gap:
            continue
        reference = references.get((r["file"], r["reference_step"]), common or r)
        g0 = reference["g0"]
        f = by_gap[(r["file"], r["step"])]
        width = math.log(f["x"][1] / f["x"][0])
        near = sum(s for x, s in zip(f["x"], f["share"]) if x < 0.1) * width
        far = sum(s for x, s in zip(f["x"], f["share"]) if x >= 0.1) * width + f["outside_share"]
        inv = r["inv_kappa_att"]
        exact = r["inv_kappa_att_eq16_exact"]
        print(f"| {r['file']} | {r['range']:g} | {r['work_of_adhesion']:g} | {g0:.1f} | "
              f"{r['range'] / g0:.3f} | {inv:.3f} | {f['contact_share']:.2f} | {near:.2f} | "
              f"{far:.2f} | {r['inv_kappa_att_eq16_printed']:.4f} | {exact:.4f} | "
              f"{exact / (inv * (near + far)):.2f} | {exact / (inv * near):.2f} |")


if __name__ == "__main__":
    main(sys.argv[1])
