"""The colour of each probe's light, and the light-colour prior's spreads.

For every validation and report probe at the maps' 32x64: the
solid-angle-weighted mean radiance (what a white sphere sees) as a
chromaticity, and its colour temperature and tint (the axes of
:class:`~mi_dsbrdf.inference.illumination_priors.LightColourPrior`). The
spreads ``Config.light_temperature_sigma`` and ``light_tint_sigma`` are the root
mean square of the two over the *validation* probes only
(``benchmark_cases.VALIDATION_PROBES``); the report probes are listed beside,
not used. Prints a markdown table; a second or so.

    .venv/bin/python benchmarks/light_colours.py [--data ../shared/data]
"""
from __future__ import annotations

import argparse
import os

import numpy as np

from mi_dsbrdf.evaluation.benchmark_cases import DATA, REPORT_PROBES, VALIDATION_PROBES
from mi_dsbrdf.evaluation.experiment import downsample
from mi_dsbrdf.inference.illumination_priors import LIGHT_AXES, LightColourPrior
from mi_dsbrdf.inference.images import read_image


def light_colour(probe, data=DATA, size=(32, 64)) -> tuple:
    """(chromaticity (3,), (temperature, tint)) of a probe's mean light."""
    env = downsample(read_image(os.path.join(data, "envmaps", probe)), *size)
    log_m = LightColourPrior.colour(np.log(np.maximum(env, 1e-30)))
    m = np.exp(log_m)
    return m / m.sum(), log_m @ LIGHT_AXES


def spreads(probes, data=DATA) -> np.ndarray:
    """(temperature, tint) root mean square over ``probes``."""
    y = np.array([light_colour(p, data)[1] for p in probes])
    return np.sqrt((y ** 2).mean(axis=0))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default=DATA, help="the folder holding envmaps/ (default %(default)s)")
    args = ap.parse_args(argv)
    print("| probe | set | chromaticity | temperature | tint |\n|---|---|---|---|---|")
    for probes, name in ((VALIDATION_PROBES, "validation"), (REPORT_PROBES, "report")):
        for p in probes:
            c, (t, g) = light_colour(p, args.data)
            print("| %s | %s | (%.3f, %.3f, %.3f) | %+.3f | %+.3f |" % (os.path.basename(p), name, *c, t, g))
    t, g = spreads(VALIDATION_PROBES, args.data)
    print("\nRoot mean square over the validation probes: temperature %.3f, tint %.3f "
          "(Config.light_temperature_sigma, light_tint_sigma)" % (t, g))


if __name__ == "__main__":
    main()
