"""Pair two runs of ``benchmarks/experiments.py`` case by case: accuracy in both
conventions, illumination and relit errors, and time, before and after a change.

    .venv/bin/python benchmarks/compare_experiments.py BEFORE_DIR AFTER_DIR > docs/speed_accuracy.md

Issue 14's check (the code before it, commit fe60e93, against the code after):

    git worktree add /tmp/before fe60e93 && ln -s "$PWD/out" /tmp/before/out
    (cd /tmp/before && PYTHONPATH=/tmp/before ../main/.venv/bin/python benchmarks/experiments.py \\
        --groups probe stiff point --data ../shared/data --out ../main/benchmarks/results/experiments_before_issue14)
    .venv/bin/python benchmarks/experiments.py --groups probe stiff point
    .venv/bin/python benchmarks/compare_experiments.py benchmarks/results/experiments_before_issue14 \\
        benchmarks/results/experiments > docs/speed_accuracy.md
"""
import glob
import json
import os
import sys

import numpy as np

MEASURES = [("brdf_eq20_paper", "Eq. 20 paper"), ("brdf_eq20_cosine", "Eq. 20 cosine"),
            ("illumination_error", "illumination"), ("direction_error_deg", "direction °"), ("relight", "relit")]


def load(folder) -> dict:
    return {os.path.basename(f)[:-5]: json.load(open(f)) for f in glob.glob(os.path.join(folder, "*.json"))}


def measure(r, key):
    """A result's measure ``key``; ``"relight"``: the mean relit error over its
    probes; None if the result has no such measure."""
    if key == "relight":
        return float(np.mean(list(r["relight"].values())))
    return r.get(key)


def report(before, after) -> str:
    a, b = load(before), load(after)
    ids = sorted(set(a) & set(b))
    md = ["# Accuracy and time before and after a change", "",
          "`%s` against `%s`, case by case (`benchmarks/compare_experiments.py`). Lower is better;" % (
              before, after), "seconds are one core's (two cases at a time).", "",
          "## Medians per group", "", "| group | cases | " + " | ".join(
              "%s before → after" % label for _, label in MEASURES) + " | seconds, total |",
          "|---|---|" + "---|" * len(MEASURES) + "---|"]
    for group in ("probe", "point", "stiff"):
        sel = [i for i in ids if a[i]["case"]["group"] == group]
        if not sel:
            continue
        cells = []
        for key, _ in MEASURES:
            x = [measure(a[i], key) for i in sel if measure(a[i], key) is not None]
            y = [measure(b[i], key) for i in sel if measure(b[i], key) is not None]
            cells.append("%.3f → %.3f" % (np.median(x), np.median(y)) if x and y else "–")
        md.append("| %s | %d | %s | %.0f → %.0f |" % (group, len(sel), " | ".join(cells),
                                                      sum(a[i]["seconds"] for i in sel),
                                                      sum(b[i]["seconds"] for i in sel)))
    md += ["", "## Every case", "", "| case | " + " | ".join(label for _, label in MEASURES) + " | seconds |",
           "|---|" + "---|" * len(MEASURES) + "---|"]
    for i in ids:
        cells = []
        for key, _ in MEASURES:
            x, y = measure(a[i], key), measure(b[i], key)
            cells.append("–" if x is None or y is None else "%.3f → %.3f%s" % (
                x, y, " **worse**" if y > 1.1 * x + 0.01 else ""))
        md.append("| %s | %s | %.0f → %.0f |" % (i, " | ".join(cells), a[i]["seconds"], b[i]["seconds"]))
    return "\n".join(md) + "\n"


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: compare_experiments.py BEFORE_DIR AFTER_DIR")
    sys.stdout.write(report(sys.argv[1], sys.argv[2]))
