"""What inference returns: one :class:`Recovery` for every kind of light."""
from __future__ import annotations

import dataclasses

import numpy as np

from mi_dsbrdf.brdf.dsbrdf import Material


@dataclasses.dataclass(frozen=True)
class Recovery:
    """The MAP estimate of one image (like scipy's result objects: plain fields).

    Attributes
    ----------
    material : the recovered :class:`~mi_dsbrdf.brdf.dsbrdf.Material` (basis form)
    psi : (k,) basis coefficients; chromaticity : (R, 3) lobe chromaticities
    illumination : (H, W, 3) float64 lat-long radiance map (Mitsuba's envmap
        convention), texels no observed pixel sees exactly 0; None for a point
        or directional light
    seen : (H, W) bool, the texels some observed pixel sees; None without a map
    light : {"type": "directional" | "point", "direction": (3,) unit vector from
        the object towards the light, "intensity": irradiance (directional) or
        W/sr (point), "position": (3,) (point)}; None for a map
    log : one dict per logged round: "pass", "round", "neg_log_posterior",
        the posterior's terms, "seconds"
    illumination_spread : (H, W, 3) the posterior's standard deviation of the
        log map per texel (:func:`~mi_dsbrdf.inference.uncertainty.illumination_spread`;
        0 where no pixel sees); None for a point or directional light
    posterior_seconds : the time the material's posterior and the map's spread took
        (within the recovery's)
    laplace : the material's posterior at the MAP
        (:class:`~mi_dsbrdf.inference.uncertainty.Laplace`); ``material`` carries
        its covariance (``Material.covariance_factor``)
    """
    material: Material
    psi: np.ndarray
    chromaticity: np.ndarray
    illumination: np.ndarray = None
    seen: np.ndarray = None
    light: dict = None
    log: list = dataclasses.field(default_factory=list)
    laplace: object = None
    illumination_spread: np.ndarray = None
    posterior_seconds: float = 0.0

    @property
    def neg_log_posterior(self) -> float:
        """The last logged negative log posterior."""
        return float(self.log[-1]["neg_log_posterior"])

    @property
    def seconds(self) -> float:
        return float(self.log[-1]["seconds"]) if self.log else 0.0
