"""Plain tables of the commands' results: CSV and JSON values without NumPy or NaN."""
import csv
import json
import math

import numpy as np


def plain(value):
    """A JSON/CSV-friendly scalar: NaN and inf become None, NumPy scalars Python ones."""
    if isinstance(value, (np.floating, float)):
        value = float(value)
        return value if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value


def plain_rows(rows, columns):
    """``rows`` (mappings) reduced to ``columns``, each value :func:`plain` (missing: None)."""
    return [{k: plain(r.get(k)) for k in columns} for r in rows]


def write_csv(path, rows, columns):
    """Write plain rows as CSV, a missing value (None) as an empty field."""
    with open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=columns)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: "" if row[k] is None else row[k] for k in columns})


def write_json(path, doc):
    """Write a JSON document, indented one space, ending with a newline."""
    with open(path, "w") as fh:
        json.dump(doc, fh, indent=1)
        fh.write("\n")
