"""Is a slower run the code or the machine? The 128-pixel natural-light case of
``inference_cases.py`` (two passes, the benchmarked preset) timed with this
checkout and with another commit's code, in turn, each in its own process, on
the same machine at the same hour.

This machine's speed drifts from day to day (the README's run-time table has
runs 1.5x apart for the same code), so a run-time target measured on one day
cannot tell a code regression from a slow day; this can. The other commit is
checked out into a temporary ``git worktree`` and removed afterwards; it runs
with its own defaults (its own ``PRESETS["benchmarked"]``) on the same image.

    .venv/bin/python benchmarks/speed_against_commit.py 50f42ad [--runs 2]

Writes benchmarks/results/speed_against_commit.json (the README quotes it).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, "benchmarks", "results", "speed_against_commit.json")

#: run in a child process with a code root on sys.path: prints the seconds of one inference
CHILD = r"""
import sys, time
sys.path[:0] = [sys.argv[1], sys.argv[1] + "/benchmarks"]
from inference_cases import envmap_case
from mi_dsbrdf.config import PRESETS
from mi_dsbrdf.inference import recover_envmap
from mi_dsbrdf.model import model_file as model_data
model = model_data.shipped_model()
_, img, ts = envmap_case()
try:    # the app's pixels (the silhouette ring dropped); commits before it had none
    from mi_dsbrdf.inference.pixels import usable_pixels
    mask = usable_pixels(ts.mask, img)
except ImportError:
    mask = ts.mask
t0 = time.perf_counter()
recover_envmap(ts, img, mask, model, PRESETS["benchmarked"])
print(time.perf_counter() - t0)
"""


def time_once(root) -> float:
    out = subprocess.run([sys.executable, "-c", CHILD, root], capture_output=True, text=True, check=True,
                         env=dict(os.environ, PYTHONPATH=root))
    return float(out.stdout.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("commit", help="the other commit (anything git rev-parse takes)")
    ap.add_argument("--runs", type=int, default=2, help="runs of each, in turn")
    args = ap.parse_args(argv)
    sha = subprocess.run(["git", "-C", ROOT, "rev-parse", args.commit], capture_output=True, text=True,
                         check=True).stdout.strip()
    seconds = {"this checkout": [], sha[:7]: []}
    with tempfile.TemporaryDirectory() as tmp:
        other = os.path.join(tmp, "other")
        subprocess.run(["git", "-C", ROOT, "worktree", "add", "-q", "--detach", other, sha], check=True)
        try:
            for _ in range(args.runs):
                for name, root in (("this checkout", ROOT), (sha[:7], other)):
                    seconds[name].append(time_once(root))
                    print("%s: %.1f s" % (name, seconds[name][-1]), flush=True)
        finally:
            subprocess.run(["git", "-C", ROOT, "worktree", "remove", "--force", other], check=True)
    medians = {k: float(np.median(v)) for k, v in seconds.items()}
    head = subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                          check=True).stdout.strip()
    out = {"command": "python benchmarks/speed_against_commit.py %s --runs %d" % (args.commit, args.runs),
           "this_checkout_head": head, "other": sha, "seconds": seconds, "medians": medians,
           "ratio": medians["this checkout"] / medians[sha[:7]]}
    with open(OUT, "w") as f:
        json.dump(out, f, indent=1)
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
