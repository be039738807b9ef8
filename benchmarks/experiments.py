"""The experiments of paper §6 on synthetic MERL renders, run in parallel on Dask.

Groups of cases (:func:`cases`; each case is run and scored by
:func:`mi_dsbrdf.evaluation.experiment.run_case`, always with a leave-one-out model):

* point: MERL materials x a point light at 30/60/90 deg from the viewer
  (``--full``: 0, 30, 60, 90, 120 and every material), with and without priors (§6.1);
* probe: MERL materials x real light probes, with and without priors (§6.2);
* stiff: chrome (mirror-like), pink felt (near-Lambertian), a light at 120 deg
  (mostly unlit), a sun thousands of times brighter than its sky, a torus (non-convex).

Error against run time, beside Adam through ``prb``, is ``benchmarks/error_vs_time.py``
(it builds its cases with :func:`make_case`, group ``budget``).

Resumable: each case writes ``<out>/<id>.json`` (and ``<id>.npz``, its relit
images) when it finishes, and a rerun skips the cases whose file exists.
Parallel on Dask: a LocalCluster of ``--workers`` single-threaded processes by
default, or ``--scheduler tcp://host:8786`` for a cluster (its workers need
this package installed, ``--data`` at the same path and one thread each,
``dask worker --nthreads 1``: Dr.Jit in several threads of one process crashed).

    .venv/bin/python benchmarks/experiments.py              # quick subset (< 30 min here)
    .venv/bin/python benchmarks/experiments.py --full
    .venv/bin/python benchmarks/experiments_report.py       # -> docs/experiments.md
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

from mi_dsbrdf.backend import one_blas_thread

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DATA = os.path.join(ROOT, "..", "shared", "data")
OUT = os.path.join(ROOT, "benchmarks", "results", "experiments")
CACHE = os.path.join(ROOT, "out", "loo_models")
QUICK_MATERIALS = ["blue-acrylic", "gold-metallic-paint", "red-fabric", "pvc"]
PROBES = ["probulator/grace.hdr", "probulator/ennis.hdr", "probulator/pisa.hdr", "probulator/uffizi.hdr",
          "probulator/wells.hdr"]
SUN_PROBE = "polyhaven/blouberg_sunrise_2_1k.hdr"
RES, MAP = 64, [32, 64]


def make_case(group, kind, material, priors=True, **kw) -> dict:
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


def cases(full=False, materials=None) -> list:
    """The case list: the quick subset, or with ``full`` every MERL material, angle and probe."""
    from mi_dsbrdf.brdf.measured import nbrdf_names
    mats = materials or (nbrdf_names(os.path.join(DATA, "merl", "merl_nbrdf_weights.npz")) if full
                         else QUICK_MATERIALS)
    angles = [0, 30, 60, 90, 120] if full else [30, 60, 90]
    probes = PROBES if full else PROBES[:1]
    out = []
    for m in mats:
        for a in angles:
            for p in (True, False):
                out.append(make_case("point", "point", m, p, angle=a))
        for probe in probes:
            for p in (True, False):
                out.append(make_case("probe", "probe", m, p, probe=probe))
    grace = PROBES[0]
    out += [make_case("stiff", "point", "chrome", angle=60), make_case("stiff", "probe", "chrome", probe=grace),
            make_case("stiff", "point", "pink-felt", angle=60), make_case("stiff", "probe", "pink-felt", probe=grace),
            make_case("stiff", "point", "gold-metallic-paint", angle=120),
            make_case("stiff", "probe", "gold-metallic-paint", probe=SUN_PROBE),
            make_case("stiff", "probe", "blue-acrylic", probe=grace, shape="torus")]
    ids = [c["id"] for c in out]
    assert len(ids) == len(set(ids)), "case ids must be unique"
    return out


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


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--full", action="store_true", help="every MERL material, angle and probe")
    ap.add_argument("--groups", nargs="*", choices=["point", "probe", "stiff"])
    ap.add_argument("--materials", nargs="*", help="materials of the point and probe groups")
    ap.add_argument("--workers", type=int, default=2, help="local worker processes (one thread each)")
    ap.add_argument("--scheduler", help="address of a Dask scheduler (default: a local cluster)")
    ap.add_argument("--data", default=DATA)
    ap.add_argument("--out", default=OUT)
    args = ap.parse_args(argv)
    if not os.path.exists(os.path.join(args.data, "merl", "merl_nbrdf_weights.npz")):
        sys.exit("the experiments need the MERL fits under %s (see ../shared/data/README.md)" % args.data)
    todo = [c for c in cases(args.full, args.materials) if not args.groups or c["group"] in args.groups]
    s = run_on_cluster(todo, args.out, args.data, args.workers, args.scheduler)
    sys.exit(1 if s["failed"] else 0)


if __name__ == "__main__":
    main()
