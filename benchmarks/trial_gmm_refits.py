"""TRIAL (seventeenth session, reverted): natural-light validation with the GMM fitted to the
leave-one-out library's refits, every other prior (hue, chromaticity, curve box) on the FPCA
scores and full fits. Needs the refit trial's cached models (out/loo_models/*-refit.npz).

    MI_DSBRDF_TRIAL_GMM=refits .venv/bin/python benchmarks/trial_gmm_refits.py
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import natural_light as nl  # noqa: E402
from experiments import DATA, run_on_cluster  # noqa: E402

if __name__ == "__main__":
    assert os.environ.get("MI_DSBRDF_TRIAL_GMM") == "refits"
    out = os.path.join(nl.OUT, "trial_gmm_refits")
    run_on_cluster(nl.cases("validation", {}), out, DATA, 2)
    print(nl.summary(out))
    print(nl.against_table(out, os.path.join(nl.OUT, "validation", nl.SHIPPED_SETTING)))
