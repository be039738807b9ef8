"""Small shared helpers for the tests."""
import functools
import importlib.util
import os

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def glossy_function(theta_h, theta_d, phi_d):
    """A smooth glossy RGB BRDF of the MERL angles (1/sr), for synthetic tables."""
    lobe = 0.15 + 4.0 * np.exp(-(theta_h / 0.12) ** 2) * (1 + np.sin(theta_d) ** 4)
    return np.stack([lobe, 0.8 * lobe, 0.6 * lobe], -1)


@functools.lru_cache(maxsize=None)
def benchmark(name):
    """The script ``benchmarks/<name>.py`` as a module (loaded from its file once; a
    script, not a package module, it imports only the package)."""
    spec = importlib.util.spec_from_file_location("benchmark_" + name, os.path.join(ROOT, "benchmarks", name + ".py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
