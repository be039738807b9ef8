"""The summary of a batch (:mod:`mi_dsbrdf.app.batch`): ``summary.csv``, one row per
image with its status, time, light and the recovered material's parameters, and
``summary.html``, the same with thumbnails of each result folder's previews."""
from __future__ import annotations

import csv
import html
import json
import os
import urllib.parse

from mi_dsbrdf.errors import MiDsbrdfError

#: the statuses ``recover_many`` yields: recovered now, complete from an earlier run, failed
DONE, SKIPPED, FAILED = "done", "skipped", "failed"


def one_line_reason(e: BaseException) -> str:
    """An exception as one line: its message's first line (prefixed with its type
    when it is not one of the package's errors)."""
    text = (str(e).strip().splitlines() or [""])[0]
    if isinstance(e, (MiDsbrdfError, OSError)):
        return text or type(e).__name__
    return "%s: %s" % (type(e).__name__, text) if text else type(e).__name__


def complete(folder) -> bool:
    """Whether ``folder`` holds a complete result (log.json is written last)."""
    return os.path.isfile(os.path.join(folder, "log.json"))


#: the previews the summary shows, in its columns' order
THUMBNAILS = ("input.png", "rerender.png", "residual.png", "material.png", "illumination.png")


def _flat(prefix, value) -> dict:
    """{prefix_i_j: number} of a nested list (a material's parameter array)."""
    if isinstance(value, list):
        d = {}
        for i, v in enumerate(value):
            d.update(_flat("%s_%d" % (prefix, i), v))
        return d
    return {prefix: value}


def _light_text(folder, log) -> str:
    """One line on the recovered light: its kind, direction and intensity, or the map's size."""
    try:
        with open(os.path.join(folder, "light.json")) as f:
            light = json.load(f)
        return "%s (%s) intensity %.4g" % (light["type"], " ".join("%.3f" % v for v in light["direction"]),
                                           light["intensity"])
    except (OSError, ValueError, KeyError, TypeError):
        size = log.get("map_size")
        return "envmap %dx%d" % tuple(size) if size else ""


def summary_rows(out, names, failures=None, seconds=None) -> list:
    """One dict per row of the summary: name, status, reason, seconds (the
    recovery's wall time: its stages, or as measured for a failure), the
    re-render's relative L1 residual over the used pixels, peak memory,
    the final negative log posterior, the light's summary, the result's flags
    (log.json's, joined by "; "), and the material's
    parameters flattened (``log_kappa_0_1``, ...), from each result folder."""
    failures, seconds = failures or {}, seconds or {}
    table = []
    for name in names:
        folder = os.path.join(out, name)
        row = {"name": name, "status": FAILED if name in failures else "", "reason": failures.get(name, "")}
        log = {}
        if name not in failures and complete(folder):
            try:
                with open(os.path.join(folder, "log.json")) as f:
                    log = json.load(f)
                with open(os.path.join(folder, "material.json")) as f:
                    material = json.load(f)
            except (OSError, ValueError) as e:
                row.update(status=FAILED, reason="its result folder does not read: %s" % one_line_reason(e))
            else:
                stages = log.get("stages", {}).values()
                rounds = log.get("rounds") or [{}]
                row.update(status=DONE, residual="%.4f" % log["residual"] if "residual" in log else "",
                           seconds="%.2f" % sum(s.get("seconds", 0) for s in stages),
                           peak_memory_mb="%.0f" % max([s.get("peak_memory_mb", 0) for s in stages] or [0]),
                           neg_log_posterior="%.6g" % rounds[-1]["neg_log_posterior"]
                           if "neg_log_posterior" in rounds[-1] else "",
                           light=_light_text(folder, log), flags="; ".join(log.get("flags") or []))
                for key in ("log_kappa", "log_gamma", "chromaticity", "psi"):
                    if key in material:
                        row.update(_flat(key, material[key]))
        elif name not in failures:
            row.update(status=FAILED, reason="no result (interrupted?); a rerun does it")
        if row.get("seconds") is None and name in seconds:
            row["seconds"] = "%.2f" % seconds[name]
        table.append(row)
    return table


def write_summary(out, names, failures=None, seconds=None) -> None:
    """``out/summary.csv`` and ``out/summary.html`` of the rows ``names``
    (:func:`summary_rows`); each written to a temporary file and renamed."""
    table = summary_rows(out, names, failures, seconds)
    columns = []
    for row in table:
        columns += [k for k in row if k not in columns]
    tmp = os.path.join(out, ".summary.csv.tmp")
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, columns, restval="")
        w.writeheader()
        w.writerows(table)
    os.replace(tmp, os.path.join(out, "summary.csv"))
    tmp = os.path.join(out, ".summary.html.tmp")
    with open(tmp, "w") as f:
        f.write(_html(out, table))
    os.replace(tmp, os.path.join(out, "summary.html"))


def _html(out, table) -> str:
    e = html.escape
    done = sum(r["status"] == DONE for r in table)
    head = ["name", "status"] + [t[:-4] for t in THUMBNAILS] + ["light", "residual", "seconds", "peak MB",
                                                                 "-log posterior", "flags", "reason"]
    lines = ["<!DOCTYPE html>", "<html><head><meta charset=\"utf-8\"><title>mi-dsbrdf batch</title>",
             "<style>body{font-family:sans-serif}table{border-collapse:collapse}td,th{border:1px solid #ccc;"
             "padding:4px;vertical-align:middle}img{width:96px;image-rendering:pixelated}"
             ".failed{background:#fee}</style></head><body>",
             "<h1>mi-dsbrdf batch</h1><p>%d rows: %d recovered, %d failed</p>" % (
                 len(table), done, len(table) - done),
             "<table><tr>%s</tr>" % "".join("<th>%s</th>" % e(h) for h in head)]
    for r in table:
        cells = [e(r["name"]), e(r["status"])]
        for t in THUMBNAILS:
            if os.path.isfile(os.path.join(out, r["name"], t)):
                href = urllib.parse.quote("%s/%s" % (r["name"], t))
                cells.append("<a href=\"%s\"><img src=\"%s\" alt=\"%s\"></a>" % (href, href, e(t)))
            else:
                cells.append("")
        cells += [e(str(r.get(k, ""))) for k in ("light", "residual", "seconds", "peak_memory_mb",
                                                 "neg_log_posterior", "flags", "reason")]
        lines.append("<tr class=\"%s\">%s</tr>" % (e(r["status"]), "".join("<td>%s</td>" % c for c in cells)))
    lines += ["</table></body></html>", ""]
    return "\n".join(lines)
