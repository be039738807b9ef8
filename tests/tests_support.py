"""Small shared helpers for the tests."""
import numpy as np


def glossy_function(theta_h, theta_d, phi_d):
    """A smooth glossy RGB BRDF of the MERL angles (1/sr), for synthetic tables."""
    lobe = 0.15 + 4.0 * np.exp(-(theta_h / 0.12) ** 2) * (1 + np.sin(theta_d) ** 4)
    return np.stack([lobe, 0.8 * lobe, 0.6 * lobe], -1)
