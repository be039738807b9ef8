"""What a perfect split of colour between light and material would gain, from
stored results alone (no inference).

For each case of a results folder (``natural_light.py`` output), the recovered
map's mean colour is replaced by the truth's: the relit images (stored as
truth and recovery, ``experiment._normalised_pair``) are scaled per channel by
recovered / true mean map colour, which is exact for a colour change shared by
all lobes, and so is the map. Prints, against doing nothing, the relit and map
wins and medians as recovered, with the true mean colour ("oracle"), and with
the map's mean forced to white ("grey world").

    .venv/bin/python benchmarks/colour_oracle.py benchmarks/results/natural_light/report/defaults
    .venv/bin/python benchmarks/colour_oracle.py benchmarks/results/natural_light/validation/gmm_volume0-grey_texel_samples1-texel_samples2
"""
from __future__ import annotations

import argparse
import glob
import json
import os

import numpy as np

from mi_dsbrdf.evaluation.metrics import scale_invariant_log_error


def case_errors(npz) -> dict:
    """{variant: (relit error (mean over the relighting probes), map error)} of one case."""
    z = np.load(npz)
    truth, rec = (z["illumination"][i].astype(np.float64) for i in (0, 1))
    seen = rec.sum(axis=-1) > 0
    t_mean, r_mean = truth[seen].mean(axis=0), rec[seen].mean(axis=0)
    gains = {"recovered": np.ones(3), "oracle": t_mean / r_mean, "grey world": r_mean.mean() / r_mean}
    out = {}
    for name, g in gains.items():
        # the map times g; the material's colour over g: each relit channel over g
        relit = [scale_invariant_log_error(z[k][1].astype(np.float64) / g, z[k][0].astype(np.float64),
                                           z[k][0].astype(np.float64).sum(axis=-1) > 0)
                 for k in z.files if k != "illumination"]
        out[name] = (float(np.mean(relit)), scale_invariant_log_error(rec * g, truth, seen))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("folder")
    args = ap.parse_args(argv)
    rows = []
    for npz in sorted(glob.glob(os.path.join(args.folder, "*-dsbrdf-*.npz"))):
        if "-dsbrdf-adam-" in npz:
            continue
        with open(npz[:-4] + ".json") as f:
            base = json.load(f)["baseline"]
        rows.append((case_errors(npz), float(np.mean(list(base["relight"].values()))), base["illumination_error"]))
    print("%d cases of %s\n\n| colour | relit: wins, median ratio | map: wins, median ratio |\n|---|---|---|"
          % (len(rows), args.folder))
    for name in ("recovered", "oracle", "grey world"):
        relit = np.array([(e[name][0], b) for e, b, _ in rows])
        maps = np.array([(e[name][1], m) for e, _, m in rows])
        print("| %s | %d, %.2f× | %d, %.2f× |" % (name, (relit[:, 0] < relit[:, 1]).sum(),
                                                np.median(relit[:, 0] / relit[:, 1]),
                                                (maps[:, 0] < maps[:, 1]).sum(), np.median(maps[:, 0] / maps[:, 1])))


if __name__ == "__main__":
    main()
