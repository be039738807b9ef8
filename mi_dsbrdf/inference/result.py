"""What inference returns: one :class:`Recovery` for every kind of light."""
from __future__ import annotations

import dataclasses

import numpy as np

from mi_dsbrdf.brdf.dsbrdf import NO_HIGHLIGHT, Material


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
    highlight_doubt : for a material recovered with a highlight, the posterior's
        probability that it has none
        (:func:`~mi_dsbrdf.inference.uncertainty.highlight_doubt`); None otherwise
    other_mode : the other route's answer where the second route ran
        (``Config.second_route_highlight``): a second mode of the same posterior,
        as a :class:`~mi_dsbrdf.brdf.dsbrdf.Material`; None otherwise
    other_mode_gap : its negative log posterior above the answer's (>= 0)
    highlight_change : under a map, the relative change of the answer's image when
        the highlight pairs integrate each pixel's mirror direction over its area
        (:func:`~mi_dsbrdf.inference.lobes.highlight_change`); None if not checked
    highlight_texels : the highlight pairs' texels per pixel the answer was fitted
        with (``Config.highlight_texels`` where ``highlight_change`` reached
        ``Config.highlight_check``, else 0); its re-render needs the same
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
    other_mode: Material = None
    other_mode_gap: float = None
    highlight_doubt: float = None
    highlight_change: float = None
    highlight_texels: int = 0

    @property
    def neg_log_posterior(self) -> float:
        """The last logged negative log posterior."""
        return float(self.log[-1]["neg_log_posterior"])

    @property
    def flags(self) -> list:
        """One line for each part of the answer the photograph may not support: so
        far a doubted highlight (:meth:`highlight_flag`)."""
        line = self.highlight_flag()
        return [] if line is None else [line]

    def highlight_flag(self, where=None) -> str | None:
        """One line when the recovered highlight's :attr:`highlight_doubt` is at least
        :data:`~mi_dsbrdf.inference.uncertainty.HIGHLIGHT_DOUBT` (near-Lambertian
        materials, under a sun above all, can come back glossy), else None;
        ``where``: the place on the object it lights, in words, if known."""
        from mi_dsbrdf.inference.uncertainty import HIGHLIGHT_DOUBT
        if self.highlight_doubt is None or self.highlight_doubt < HIGHLIGHT_DOUBT:
            return None
        return ("the highlight%s may be the prior's, not the photograph's: the posterior gives %.0f %% to a material "
                "with none (peak / off-peak at the mirror direction below %.1f; the answer's is %.1f); "
                "material.png shows the band" % ("" if where is None else " (on the object's %s)" % where,
                                                 100 * self.highlight_doubt, NO_HIGHLIGHT,
                                                 self.material.highlight_ratio()))

    @property
    def seconds(self) -> float:
        return float(self.log[-1]["seconds"]) if self.log else 0.0
