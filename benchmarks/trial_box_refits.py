"""TRIAL (seventeenth session): natural-light validation with the curve box and the lobe
energy bound taken from the leave-one-out library's refits (the other priors on the FPCA
scores). Needs the refit trial's cached models (out/loo_models/*-refit.npz).

    MI_DSBRDF_TRIAL_BOX=refits .venv/bin/python benchmarks/trial_box_refits.py
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import natural_light as nl  # noqa: E402
from experiments import DATA, run_on_cluster  # noqa: E402

assert os.environ.get("MI_DSBRDF_TRIAL_BOX") == "refits"
out = os.path.join(nl.OUT, "trial_box_refits")
run_on_cluster(nl.cases("validation", {}), out, DATA, 2)
print(nl.summary(out))
print(nl.against_table(out, os.path.join(nl.OUT, "validation", nl.SHIPPED_SETTING)))
