"""What the scripts of ``benchmarks/`` share.

* where things live: :data:`DATA` (the MERL fits and light probes, outside the
  repository), :data:`OUT` (per-case outputs, git-ignored), :data:`RESULTS`
  (the small summaries the README and docs quote), :data:`DOCS`;
* the synthetic cases of :func:`mi_dsbrdf.evaluation.experiment.run_case`
  (:func:`make_case`) and their resumable runner on Dask (:func:`run_cases`,
  :func:`run_on_cluster`);
* the natural-light case sets (:data:`VALIDATION_MATERIALS` x
  :data:`VALIDATION_PROBES`, :data:`REPORT_MATERIALS` x :data:`REPORT_PROBES`)
  and the names of settings (:func:`setting_name`, :func:`parse_config`);
* helpers of the reports (:func:`measure`, :func:`tonemap`), and the posterior
  band's table with the temperature its coverage chooses (:func:`posterior_table`,
  :func:`choose_temperature`).
"""
from __future__ import annotations

import json
import os
import re
import time

import numpy as np

from mi_dsbrdf.backend import one_blas_thread
from mi_dsbrdf.model.build import gmm_structure

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
#: the MERL fits (``merl/merl_nbrdf_weights.npz``) and light probes (``envmaps/``)
DATA = os.path.join(ROOT, "..", "shared", "data")
#: per-case outputs (git-ignored)
OUT = os.path.join(ROOT, "out")
#: the small summaries the README and docs quote (benchmarks/README.md lists them)
RESULTS = os.path.join(ROOT, "benchmarks", "results")
DOCS = os.path.join(ROOT, "docs")
#: leave-one-out models, shared by every benchmark
CACHE = os.path.join(OUT, "loo_models")
#: the synthetic cases' image size (pixels) and recovered map size (texels)
RES, MAP = 64, [32, 64]

# --- the natural-light case sets ------------------------------------------------------------

#: validation: the only cases settings and weights are chosen on. Two materials of each
#: kind (acrylic or phenolic, metallic paint or paint, fabric, plastic, foam or rubber,
#: metal), then eight drawn at random (numpy ``default_rng(15)``) from the library
#: materials in neither set, six from the shipped GMM's cluster 2 and two from its
#: cluster 3, so that the set holds the clusters in the library's proportions
VALIDATION_MATERIALS = ["violet-acrylic", "silver-metallic-paint", "blue-fabric", "yellow-plastic",
                        "polyurethane-foam", "nickel",
                        "specular-blue-phenolic", "dark-red-paint", "white-fabric", "gray-plastic",
                        "neoprene-rubber", "brass",
                        "color-changing-paint2", "purple-paint", "special-walnut-224", "gold-metallic-paint2",
                        "teflon", "pink-plastic", "blue-metallic-paint2", "yellow-phenolic"]
#: an indoor probe, an overcast urban panorama and a sunlit quarry (a small bright source)
VALIDATION_PROBES = ["probulator/wells.hdr", "polyhaven/pedestrian_overpass_1k.hdr", "polyhaven/quarry_01_1k.hdr"]
#: report: 12 other materials, by GMM cluster of the shipped model (0: foams and
#: fabrics; 1: metals, acrylics, phenolics; 2: paints, rubbers, fabrics; 3: the
#: rest), and six other probes (four indoor/outdoor probes, a hard low sun, a sunset)
REPORT_MATERIALS = ["light-brown-fabric",
                    "blue-acrylic", "alum-bronze", "specular-red-phenolic", "white-marble",
                    "pink-fabric", "orange-paint", "pure-rubber",
                    "gold-metallic-paint", "red-fabric", "pvc", "pink-felt"]
REPORT_PROBES = ["probulator/grace.hdr", "probulator/ennis.hdr", "probulator/pisa.hdr", "probulator/uffizi.hdr",
                 "polyhaven/blouberg_sunrise_2_1k.hdr", "polyhaven/venice_sunset_1k.hdr"]
#: a measured BRDF whose peak / off-peak ratio is below this is near-Lambertian; its
#: recovery has no highlight when its ratio is below HIGHLIGHT_LIMIT times the measured one
NEAR_LAMBERTIAN, HIGHLIGHT_LIMIT = 1.5, 1.5
assert not set(VALIDATION_MATERIALS) & set(REPORT_MATERIALS)
assert not set(VALIDATION_PROBES) & set(REPORT_PROBES)


def parse_config(items) -> dict:
    """``["w_entropy=300", "map_levels=1"]`` -> {"w_entropy": 300.0, "map_levels": 1}; the
    parts of a :func:`setting_name` (``["w_entropy300", "map_levels1"]``) read alike."""
    out = {}
    for item in items or []:
        k, v = (item.split("=", 1) if "=" in item
                else re.fullmatch(r"(.*?)(-?[0-9.]+(?:e[-+]?[0-9]+)?)", item).groups())
        out[k] = int(v) if v.lstrip("-").isdigit() else float(v)
    return out


def setting_name(config, gmm=None, bases=None, start=None) -> str:
    """``w_gmm100-w_gradient30000``, with ``gmm-full-2-0.01-`` before it for a GMM
    structure other than the build's, ``bases12-`` before that for another number
    of bases and ``start0-`` before that for one reflectance start; ``defaults`` for
    none of them."""
    name = "-".join("%s%g" % (k, v) for k, v in sorted(config.items()))
    if gmm is not None:
        name = "-".join(["gmm"] + [str(p) for p in gmm_structure(gmm)] + ([name] if name else []))
    if bases is not None:
        name = "-".join(["bases%d" % bases] + ([name] if name else []))
    if start is not None:
        name = "-".join(["start%d" % start] + ([name] if name else []))
    return name or "defaults"


def parse_setting(name) -> tuple:
    """(GMM structure or None, Config overrides, number of bases or None, the one
    reflectance start or None) of a :func:`setting_name`."""
    parts = [] if name == "defaults" else name.split("-")
    start = None
    if re.fullmatch(r"start[0-9]+", parts[0] if parts else ""):
        start, parts = int(parts[0][5:]), parts[1:]
    bases = None
    if re.fullmatch(r"bases[0-9]+", parts[0] if parts else ""):
        bases, parts = int(parts[0][5:]), parts[1:]
    gmm = None
    if parts[:1] == ["gmm"]:
        n = 2 if parts[1] == "bic" else 4
        gmm, parts = ":".join(parts[1:n]), parts[n:]
    return gmm, parse_config(parts), bases, start


# --- cases and their runner ------------------------------------------------------------------

def make_case(group, kind, material, priors=True, **kw) -> dict:
    """A case of :func:`~mi_dsbrdf.evaluation.experiment.run_case` (a 64 px sphere,
    a 32x64 map, 3 rounds of 15 iterations, this tool, unless ``kw`` says otherwise)
    with a unique ``id`` made of its group, method, material, shape, light (and
    budget, in the ``budget`` group) and priors."""
    c = {"group": group, "kind": kind, "material": material, "priors": priors, "res": RES, "map": MAP,
         "rounds": 3, "iters": 15, "shape": "sphere", "method": "dsbrdf"}
    c.update(kw)
    tag = [group, c["method"], material, c["shape"]]
    tag += ["%ddeg" % c["angle"]] if kind == "point" else [os.path.splitext(os.path.basename(c["probe"]))[0]]
    if group == "budget":
        tag += ["%dx%d" % tuple(c["map"])]
        if c["method"] == "dsbrdf":
            tag += ["r%d" % c["rounds"], "i%d" % c["iters"]]
        elif c["method"] != "mean-constant":                  # the do-nothing baseline has no budget
            tag += ["i%d" % c["iters"], "spp%d" % c["spp"]]
    tag += ["priors" if priors else "nopriors"]
    c["id"] = "-".join(tag)
    return c


def _expected_seconds(c) -> float:
    """A rough cost, to start the long cases first."""
    if c["kind"] == "point":
        return 10.0
    if c["method"] == "dsbrdf":
        return c["rounds"] * c["iters"] * c["map"][0] / 8
    return c["iters"] * c.get("spp", 0) / 40


def save_result(result: dict, out: str) -> str:
    """Write ``<id>.json`` (and ``<id>.npz`` with the images) atomically."""
    os.makedirs(out, exist_ok=True)
    cid = result["case"]["id"]
    images = result.pop("images", {})
    if images:
        tmp = os.path.join(out, ".%s.npz" % cid)
        np.savez_compressed(tmp, **images)
        os.replace(tmp, os.path.join(out, cid + ".npz"))
    tmp = os.path.join(out, ".%s.json" % cid)
    with open(tmp, "w") as f:
        json.dump(result, f, indent=1, sort_keys=True)
    path = os.path.join(out, cid + ".json")
    os.replace(tmp, path)        # the json last: it marks the case done
    return path


def run_cases(todo, client, out, data=DATA, cache=CACHE, threads=1, log=print) -> dict:
    """Run the cases not yet in ``out`` on a Dask ``client``; returns {"done", "skipped", "failed"}."""
    from dask.distributed import as_completed
    from mi_dsbrdf.evaluation.experiment import run_case
    pending = [c for c in todo if not os.path.exists(os.path.join(out, c["id"] + ".json"))]
    pending.sort(key=_expected_seconds, reverse=True)
    summary = {"done": [], "skipped": len(todo) - len(pending), "failed": {}}
    log("%d cases, %d already done, %d to run" % (len(todo), summary["skipped"], len(pending)))
    futures = {client.submit(run_case, c, os.path.abspath(data), os.path.abspath(cache), threads,
                             key="case-" + c["id"], pure=False): c for c in pending}
    t0 = time.perf_counter()
    for i, fut in enumerate(as_completed(futures), 1):
        c = futures[fut]
        try:
            r = fut.result()
        except Exception as e:  # noqa: BLE001  (one failed case must not stop the others)
            summary["failed"][c["id"]] = "%s: %s" % (type(e).__name__, e)
            log("[%d/%d] %s FAILED: %s" % (i, len(pending), c["id"], summary["failed"][c["id"]]))
            continue
        save_result(r, out)
        summary["done"].append(c["id"])
        log("[%d/%d] %-60s Eq.20 (paper) %.3f  %5.0f s  (%.0f s elapsed)%s" % (
            i, len(pending), c["id"], r["brdf_eq20_paper"], r["seconds"], time.perf_counter() - t0,
            "" if r["finite"] else "  NON-FINITE"))
    return summary


def run_on_cluster(todo, out, data=DATA, workers=2, scheduler=None, cache=CACHE) -> dict:
    """:func:`run_cases` on the Dask scheduler at ``scheduler``, or on a LocalCluster
    of ``workers`` single-threaded processes; prints and returns the summary."""
    one_blas_thread()                                   # workers inherit it: one thread per case
    from dask.distributed import Client, LocalCluster
    if scheduler:
        client = Client(scheduler)
    else:
        client = Client(LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                     dashboard_address=None))
    try:
        t0 = time.perf_counter()
        s = run_cases(todo, client, out, data, cache)
        print("%d done, %d skipped, %d failed in %.0f s" % (len(s["done"]), s["skipped"], len(s["failed"]),
                                                             time.perf_counter() - t0))
    finally:
        client.close()
    return s


def have_data(data) -> bool:
    """Whether ``data`` holds the MERL fits the cases render."""
    return os.path.exists(os.path.join(data, "merl", "merl_nbrdf_weights.npz"))


# --- reports ---------------------------------------------------------------------------------

def measure(r, key):
    """A result's measure ``key``; ``"relight"``: the mean relit error over its
    probes; None if the result has no such measure."""
    if key == "relight":
        return float(np.mean(list(r["relight"].values())))
    return r.get(key)


def tonemap(img, ref) -> np.ndarray:
    """An HDR image for display: over ``ref`` (its white), clipped to [0, 1], gamma 2.2."""
    return np.clip(np.asarray(img, np.float64) / max(ref, 1e-12), 0, 1) ** (1 / 2.2)


# --- the posterior band's summary (natural_light.py, experiments.py --posterior) ---------------

def own_rows(rows) -> list:
    """This tool's results among ``rows`` (a report folder also holds the Adam baselines')."""
    return [r for r in rows if r["case"].get("method", "dsbrdf") == "dsbrdf"]


#: the target band of the posterior's coverage of the truth on observed (theta_h,
#: theta_d) cells (median over cases); the temperature chosen on validation is the
#: one whose median lies nearest the band's middle
COVERAGE_TARGET = (0.75, 0.95)


def recovered_glossy(r) -> bool:
    """A near-Lambertian material (measured peak / off-peak below NEAR_LAMBERTIAN)
    recovered with a highlight (at least HIGHLIGHT_LIMIT times the measured ratio)."""
    return r["truth_highlight_ratio"] < NEAR_LAMBERTIAN and r["highlight_ratio"] >= HIGHLIGHT_LIMIT * r[
        "truth_highlight_ratio"]


def posterior_rows(rows) -> list:
    """This tool's results that carry a posterior band (``posterior``)."""
    return [r for r in own_rows(rows) if "posterior" in r]


def posterior_table(rows) -> str:
    """Markdown: per temperature, the median over cases of the 90 % band's coverage
    of the truth and its width (log(rho + 1e-6)), on observed cells and elsewhere,
    and the median of the cases' width ratio; then the chosen temperature and the
    Laplace approximation's share of a recovery's time."""
    rows = posterior_rows(rows)
    if not rows:
        return ""
    temps = sorted(rows[0]["posterior"]["temperature"], key=float)
    md = ["| temperature | coverage, observed | coverage, unobserved | width, observed | width, unobserved | "
          "width observed / unobserved | map coverage |", "|---|---|---|---|---|---|---|"]
    for t in temps:
        b = [r["posterior"]["temperature"][t] for r in rows]
        med = {k: float(np.nanmedian([x.get(k, np.nan) for x in b])) for k in b[0]}
        ratio = float(np.nanmedian([x["width_observed"] / x["width_unobserved"] for x in b]))
        shipped = [name for name, key in (("material", "default"), ("map", "map_default"))
                   if float(t) == rows[0]["posterior"].get(key)]
        md.append("| %s%s | %.2f | %.2f | %.2f | %.2f | %.2f | %s |" % (
            t, " (shipped: %s)" % ", ".join(shipped) if shipped else "", med["coverage_observed"],
            med["coverage_unobserved"], med["width_observed"], med["width_unobserved"], ratio,
            "%.2f" % med["map_coverage"] if "map_coverage" in med else "–"))
    share = np.median([r["posterior"]["seconds"] / r["seconds"] for r in rows])
    md += ["", "%d cases; the temperature whose median coverage is nearest %.2f: %s for the material (observed "
           "cells), %s for the map. The posterior (the material's and the map's) takes %.1f %% of a recovery's time "
           "(median)."
           % (len(rows), np.mean(COVERAGE_TARGET), choose_temperature(rows),
              choose_temperature(rows, "map_coverage"), 100 * share)]
    return "\n".join(md)


def choose_temperature(rows, measure="coverage_observed") -> str:
    """The temperature (a key of ``posterior.temperature``) whose median ``measure``
    (the material's coverage on observed cells, or ``map_coverage``) over ``rows``
    lies nearest the middle of COVERAGE_TARGET; "–" if no row has it."""
    rows = [r for r in posterior_rows(rows) if all(measure in b for b in r["posterior"]["temperature"].values())]
    if not rows:
        return "–"
    middle = np.mean(COVERAGE_TARGET)
    return min(rows[0]["posterior"]["temperature"], key=lambda t: abs(float(np.nanmedian(
        [r["posterior"]["temperature"][t][measure] for r in rows])) - middle))
