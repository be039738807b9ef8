"""docs/colour_split.png: what the opt-in colour split does to the map's colour
and to the relit material, on validation cases where it helps and where it hurts.

Reads the stored results of the shipped code and of the colour split
(``benchmarks/results/natural_light/validation/<folder>``, from
``natural_light.py --set validation [--config w_chromaticity=1 w_light_colour=1]``)
and draws, per case, the true map, both recovered maps (RGB; each scaled to
the truth's mean, the light's level being unobservable; tone-mapped alike) and
the material relit under the first relighting probe: truth, shipped, split.

    .venv/bin/python benchmarks/colour_split_figure.py
"""
from __future__ import annotations

import os

import numpy as np

from experiments_report import _tonemap
from natural_light import DOCS, OUT

SHIPPED, SPLIT = "gmm_volume0-grey_texel_samples1-texel_samples2", "w_chromaticity1-w_light_colour1"
#: where it helps (warm light, near-grey materials) and where it hurts (saturated materials, blue sky)
CASES = [("teflon", "wells"), ("neoprene-rubber", "wells"), ("white-fabric", "wells"),
         ("dark-red-paint", "pedestrian_overpass_1k"), ("yellow-plastic", "pedestrian_overpass_1k")]


def load(folder, material, probe):
    return np.load(os.path.join(OUT, "validation", folder, "validation-dsbrdf-%s-sphere-%s-priors.npz"
                                % (material, probe)))


def chroma(img) -> str:
    m = np.asarray(img, np.float64).reshape(-1, 3).sum(axis=0)
    return "(%.2f, %.2f, %.2f)" % tuple(m / m.sum())


def main(path=os.path.join(DOCS, "colour_split.png")):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(len(CASES), 4, figsize=(14, 2.2 * len(CASES)), squeeze=False,
                             gridspec_kw={"width_ratios": [2, 2, 2, 3]})
    for row, (material, probe) in zip(axes, CASES):
        runs = [load(f, material, probe) for f in (SHIPPED, SPLIT)]
        maps = [runs[0]["illumination"][0], runs[0]["illumination"][1], runs[1]["illumination"][1]]
        maps = [m.astype(np.float64) for m in maps]
        ref = np.percentile(maps[0].mean(-1), 98)
        for ax, m, title in zip(row[:3], maps, ("%s: true map" % probe, "shipped", "colour split")):
            ax.imshow(_tonemap(m, ref))
            ax.set_title("%s %s" % (title, chroma(m)), fontsize=7)
        relit = [k for k in runs[0].files if k != "illumination"][0]
        imgs = [runs[0][relit][0], runs[0][relit][1], runs[1][relit][1]]
        imgs = [i.astype(np.float64) for i in imgs]
        row[3].imshow(_tonemap(np.concatenate(imgs, axis=1), np.percentile(imgs[0], 99)))
        row[3].set_title("%s relit under %s: truth | shipped | colour split" % (material, relit), fontsize=7)
        for ax in row:
            ax.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    print("wrote", path)


if __name__ == "__main__":
    main()
