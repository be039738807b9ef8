"""Batch recovery (``mi-dsbrdf batch``): throughput with one and two workers and on
a Dask LocalCluster, an interruption at half way and its rerun, broken rows.

The batch: 40 rows of 128x128 spheres, 37 of them photographs of MERL
materials (their measured data through Mitsuba's ``merl`` plugin) under the
shared probes, rendered by Mitsuba (``scenes/sphere_envmap.xml``, 64 spp), and
three broken rows (a missing file, an image with NaN pixels, a mask of the wrong
size). Every run starts from an empty output folder and goes through the CLI in
a process of its own, as a user runs it:

* ``--workers 1`` (the rows in one process, Dr.Jit on every core);
* ``--workers 2`` (two worker processes, Dr.Jit on one core each);
* ``--scheduler`` on a ``dask.distributed.LocalCluster`` of two single-threaded
  worker processes;
* ``--workers 2`` interrupted (SIGINT, as Ctrl-C) once half the good rows are
  complete, then rerun into the same folder.

It prints each run's wall time and throughput (rows a minute), the ratios to one
worker (target: two workers >= 1.8x; the LocalCluster within 10 % of two
workers) and the ceiling on that ratio, the machine's cores over those one
worker keeps busy (CPU time / wall time), the rows each run recovered and failed (target: 37 and 3, exit code
1), and for the rerun the rows recomputed that were complete before it (target:
none). Needs ../shared/data.

    .venv/bin/python benchmarks/batch_throughput.py            # ~15 min (--preset fast)

Writes benchmarks/results/batch_throughput.json.
"""
import argparse
import csv
import json
import os
import platform
import resource
import shutil
import signal
import subprocess
import sys
import time

from mi_dsbrdf.evaluation.benchmark_cases import DATA, OUT, REPORT_MATERIALS, RESULTS, VALIDATION_MATERIALS, \
    have_data

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PROBES = ["probulator/grace.hdr", "probulator/ennis.hdr", "polyhaven/quarry_01_1k.hdr",
          "polyhaven/pedestrian_overpass_1k.hdr"]
RES, SPP, GOOD = 128, 64, 37
#: targets: two workers against one, the LocalCluster against two workers
MIN_TWO_WORKERS, MAX_CLUSTER_GAP = 1.8, 0.10


def make_batch(folder, data):
    """Render the 37 photographs and write the 40-row manifest into ``folder``;
    returns the manifest's path."""
    import mitsuba as mi
    import numpy as np

    import mi_dsbrdf  # noqa: F401  (variant, plugins)
    from mi_dsbrdf.app.io import write_exr
    from mi_dsbrdf.app.scenes import scene_path
    os.makedirs(folder, exist_ok=True)
    nbrdf = os.path.join(data, "merl", "merl_nbrdf_weights.npz")
    xml = open(scene_path("sphere_envmap")).read()
    shutil.copyfile(scene_path("sphere_envmap"), os.path.join(folder, "scene.xml"))
    shutil.copytree(os.path.join(os.path.dirname(scene_path("sphere_envmap")), "textures"),
                    os.path.join(folder, "textures"), dirs_exist_ok=True)
    materials = (REPORT_MATERIALS + VALIDATION_MATERIALS)[:10]
    rows = []
    for i in range(GOOD):
        material, probe = materials[i % len(materials)], PROBES[i // len(materials)]
        name = "%02d-%s-%s" % (i, material, os.path.splitext(os.path.basename(probe))[0])
        truth = xml.replace('<bsdf type="dsbrdf" id="material"/>',
                            '<bsdf type="merl"><string name="nbrdf" value="%s"/><string name="material" '
                            'value="%s"/></bsdf>' % (nbrdf, material))
        scene = mi.load_string(truth, envmap=os.path.join(data, "envmaps", probe), res=str(RES), spp=str(SPP))
        write_exr(os.path.join(folder, name + ".exr"), np.array(mi.render(scene, seed=i), dtype=np.float32))
        rows.append({"name": name, "image": name + ".exr", "scene": "scene.xml", "mask": ""})
    img = np.array(mi.Bitmap(os.path.join(folder, rows[0]["image"])), dtype=np.float32)
    img[RES // 2, RES // 2] = np.nan
    write_exr(os.path.join(folder, "nan.exr"), img)
    mi.Bitmap(np.ones((RES // 2, RES // 2), np.float32)).write(os.path.join(folder, "small-mask.exr"))
    rows += [{"name": "broken-missing", "image": "missing.exr", "scene": "scene.xml", "mask": ""},
             {"name": "broken-nan", "image": "nan.exr", "scene": "scene.xml", "mask": ""},
             {"name": "broken-mask", "image": rows[1]["image"], "scene": "scene.xml", "mask": "small-mask.exr"}]
    path = os.path.join(folder, "manifest.csv")
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, ["name", "image", "mask", "scene"])
        w.writeheader()
        w.writerows(rows)
    return path


def _command(manifest, out, preset, extra):
    return [sys.executable, "-m", "mi_dsbrdf.app.cli", "batch", manifest, "--out", out, "--preset", preset] + extra


def _statuses(out) -> dict:
    with open(os.path.join(out, "summary.csv")) as f:
        return {r["name"]: r["status"] for r in csv.DictReader(f)}


def _complete(out) -> dict:
    """{row: its log.json's modification time} of the complete rows in ``out``."""
    found = {}
    for name in os.listdir(out):
        log = os.path.join(out, name, "log.json")
        if os.path.isfile(log):
            found[name] = os.stat(log).st_mtime_ns
    return found


def timed_run(manifest, out, preset, extra) -> dict:
    """One batch from an empty ``out``: wall time, exit code, rows done and failed, and
    the cores its processes kept busy on average (CPU time / wall time)."""
    shutil.rmtree(out, ignore_errors=True)
    cpu0 = _children_cpu()
    t0 = time.perf_counter()
    proc = subprocess.run(_command(manifest, out, preset, extra), stdout=subprocess.DEVNULL,
                          stderr=subprocess.PIPE, text=True)
    seconds = time.perf_counter() - t0
    busy = (_children_cpu() - cpu0) / seconds
    status = _statuses(out)
    done = sum(s == "done" for s in status.values())
    return {"seconds": seconds, "exit_code": proc.returncode, "done": done,
            "failed": sum(s == "failed" for s in status.values()), "rows_per_minute": 60.0 * done / seconds,
            "busy_cores": busy,
            "failure_lines": [line for line in proc.stderr.splitlines() if line.startswith("  broken")]}


def _children_cpu() -> float:
    """CPU seconds (user + system) of this process's finished children and theirs."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def interrupted_run(manifest, out, preset) -> dict:
    """``--workers 2``, SIGINT once half the good rows are complete, then the
    rerun: the rows it recomputed that were complete before it."""
    shutil.rmtree(out, ignore_errors=True)
    proc = subprocess.Popen(_command(manifest, out, preset, ["--workers", "2"]), stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    while proc.poll() is None and (not os.path.isdir(out) or len(_complete(out)) < GOOD // 2):
        time.sleep(0.5)
    proc.send_signal(signal.SIGINT)
    code = proc.wait()
    before = _complete(out)
    leftovers = sorted(n for n in os.listdir(out) if n.startswith("."))
    t0 = time.perf_counter()
    rerun = subprocess.run(_command(manifest, out, preset, ["--workers", "2"]), stdout=subprocess.DEVNULL,
                           stderr=subprocess.DEVNULL)
    after = _complete(out)
    return {"interrupt_exit_code": code, "complete_at_interrupt": len(before), "staging_leftovers": leftovers,
            "rerun_seconds": time.perf_counter() - t0, "rerun_exit_code": rerun.returncode,
            "complete_after_rerun": len(after),
            "recomputed": sorted(n for n, t in before.items() if after.get(n) != t),
            "rerun_statuses": _statuses(out)}


def _cluster_run(manifest, out, preset) -> dict:
    """The batch on a LocalCluster of two single-threaded worker processes."""
    from dask.distributed import LocalCluster
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        return timed_run(manifest, out, preset, ["--scheduler", cluster.scheduler_address])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--preset", default="fast", help="the rows' settings (default fast)")
    ap.add_argument("--data", default=DATA)
    ap.add_argument("--out", default=os.path.join(RESULTS, "batch_throughput.json"))
    args = ap.parse_args(argv)
    if not have_data(args.data):
        sys.exit("batch_throughput: needs the shared data (%s)" % args.data)
    work = os.path.join(OUT, "batch_throughput")
    manifest = make_batch(os.path.join(work, "rows"), args.data)
    runs = {}
    for name, extra in (("one_worker", ["--workers", "1"]), ("two_workers", ["--workers", "2"])):
        runs[name] = timed_run(manifest, os.path.join(work, name), args.preset, extra)
        print("%-12s %6.0f s  %5.2f rows/min  %d done, %d failed, exit %d, %.2f cores busy" % (
            name, runs[name]["seconds"], runs[name]["rows_per_minute"], runs[name]["done"], runs[name]["failed"],
            runs[name]["exit_code"], runs[name]["busy_cores"]), flush=True)
    runs["local_cluster"] = r = _cluster_run(manifest, os.path.join(work, "local_cluster"), args.preset)
    print("%-12s %6.0f s  %5.2f rows/min  %d done, %d failed, exit %d" % (
        "LocalCluster", r["seconds"], r["rows_per_minute"], r["done"], r["failed"], r["exit_code"]), flush=True)
    resume = interrupted_run(manifest, os.path.join(work, "interrupted"), args.preset)
    two = runs["two_workers"]["rows_per_minute"] / runs["one_worker"]["rows_per_minute"]
    gap = runs["local_cluster"]["rows_per_minute"] / runs["two_workers"]["rows_per_minute"] - 1.0
    # one worker keeping b cores busy leaves at most cores / b to gain from more workers
    ceiling = os.cpu_count() / runs["one_worker"]["busy_cores"]
    print("two workers / one: %.2fx (target >= %g; at most %.2fx on %d cores, as one worker keeps %.2f busy); "
          "LocalCluster / two workers: %+.0f %% (target within %.0f %%)"
          % (two, MIN_TWO_WORKERS, ceiling, os.cpu_count(), runs["one_worker"]["busy_cores"], 100 * gap,
             100 * MAX_CLUSTER_GAP))
    print("broken rows, one line each: %s" % " | ".join(runs["two_workers"]["failure_lines"]))
    print("interrupted with %d of %d rows complete (exit %d, staging folders left: %d); the rerun: %d complete, "
          "%d of them recomputed, exit %d" % (
              resume["complete_at_interrupt"], GOOD, resume["interrupt_exit_code"],
              len(resume["staging_leftovers"]), resume["complete_after_rerun"], len(resume["recomputed"]),
              resume["rerun_exit_code"]))
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w") as f:
        json.dump({"runs": runs, "interrupted": resume, "two_workers_ratio": two, "cluster_gap": gap,
                   "two_workers_ceiling": ceiling,
                   "targets": {"two_workers_ratio": MIN_TWO_WORKERS, "cluster_gap": MAX_CLUSTER_GAP},
                   "rows": {"good": GOOD, "broken": 3, "res": RES, "preset": args.preset},
                   "machine": "%s, %d cores" % (platform.machine(), os.cpu_count()),
                   "command": "python benchmarks/batch_throughput.py --preset %s" % args.preset},
                  f, indent=1, sort_keys=True)


if __name__ == "__main__":
    main()
