"""The settings of inference: one frozen, validated :class:`Config`.

Its field names are the options of ``mi-dsbrdf recover`` and ``demo`` (with
dashes: ``max_rounds`` is ``--max-rounds``). :data:`PRESETS` names the settings
the package runs under (``default`` is ``Config()``; ``fast`` the same on a
16x32 map); a variation is ``dataclasses.replace(config, map_size=(16, 32))``
(validated again).
"""
from __future__ import annotations

import dataclasses
import math
import re

from mi_dsbrdf.errors import ConfigError

#: observed pixels at which the prior weights of :class:`Config` apply as given (a
#: 64-pixel sphere covers 3000): the likelihood sums over pixels, so the weights are
#: scaled by (observed pixels / PRIOR_PIXELS) to keep the balance of likelihood and
#: priors the same at any image resolution
PRIOR_PIXELS = 3000
#: the priors of Eq. 18 (and two of ours), each weighted by Config.w_<name>
PRIOR_NAMES = ("gmm", "hue", "entropy", "gradient", "chromaticity", "light_colour")


@dataclasses.dataclass(frozen=True)
class Config:
    """Settings of :func:`mi_dsbrdf.recover` (and of
    :func:`~mi_dsbrdf.inference.recover_envmap`, :func:`~mi_dsbrdf.inference.recover_light`).

    Parameters
    ----------
    map_size : (int, int), default (32, 64)
        (H, W) texels of the lat-long illumination map (H >= 2, W >= 4).
    max_rounds : int, default 3
        Rounds of alternating illumination (or light) and reflectance blocks per pass (>= 1).
    tol : float, default 1e-3
        Relative change of the negative log posterior that ends a pass early (> 0).
    block_iters : int, default 15
        Levenberg-Marquardt iterations per reflectance block (>= 1).
    illumination_iters : int, default 60
        L-BFGS-B iterations per illumination block (>= 1).
    likelihood_scale : float, default 0.05
        Laplacian scale b of Eq. 19 in log units, the expected |log error| of a pixel (> 0).
    log_offset : float, default 1e-3
        Offset e of the likelihood's log(I + e), a fraction of the mean usable pixel (> 0):
        keeps the log of black pixels finite and bounds the weight of dark, noisy ones.
    w_gmm : float, default 300
        Weight (lambda of Eq. 18, >= 0) of the GMM prior on psi (Eq. 6), at PRIOR_PIXELS (3000) observed pixels.
    w_hue : float, default 1
        Weight (>= 0) of the hue prior (Eq. 12), at PRIOR_PIXELS (3000) observed pixels.
    w_entropy : float, default 1
        Weight (>= 0) of the illumination entropy prior (Eq. 13-15), at PRIOR_PIXELS (3000) observed pixels.
    w_gradient : float, default 30000
        Weight (>= 0) of the illumination gradient prior (Eq. 16), at PRIOR_PIXELS (3000) observed pixels;
        strong because it weighs texels by solid angle summing to one.
    w_chromaticity : float, default 1/3
        Weight (>= 0) of the prior on each lobe's colour (not in the paper), one half of
        the colour split between material and light; under a map, in the colour pass.
    w_light_colour : float, default 1
        Weight (>= 0) of the prior on the map's mean colour (near white, not in the paper),
        the other half of the colour split; both weights 0 turn the split off.
    light_temperature_sigma : float, default 0.26
        Spread (> 0, log RGB) of the light-colour prior along colour temperature (blue-orange).
    light_tint_sigma : float, default 0.05
        Spread (> 0, log RGB) of the light-colour prior along tint (green-magenta).
    gradient_eps : float, default 0.1
        eps of the hyper-Laplacian gradient prior (Eq. 16), in log radiance per polar
        texel spacing (> 0): smaller gradients are priced quadratically.
    gradient_alpha : float, default 0.5
        Exponent alpha of the gradient prior (Eq. 16), 0 < alpha < 1: the smaller, the
        heavier its tail.
    map_levels : int, default 2
        Resolution levels n (>= 1): the start runs on ``map_size`` halved n - 1 times,
        the passes on ``map_size``.
    second_route_highlight : float or None, default 2
        Highlight ratio (> 0) above which a colour image's answer under a map is checked
        against a second inference (starts judged on the full map, no grey pass); the
        lower posterior wins. None: off. About 1.5x the time of a glossy answer.
    texel_samples : int, default 2
        The colour pass lights each map texel from s x s directions (>= 1); 1 is the texel
        centres, which render lobes sharper than the texel spacing too broad.
    grey_texel_samples : int or None, default 1
        ``texel_samples`` of the start and the grey pass (>= 1); None: the same.
    highlight_texels : int, default 25
        Texels nearest each pixel's mirror direction that the highlight pairs integrate
        over the pixel's area and over the texel (>= 0; 0: never), where the answer's
        image changes by ``highlight_check`` or more with them: a lobe narrower than
        one pixel's reflected directions is then fitted and re-rendered as Mitsuba
        renders it.
    highlight_check : float, default 0.03
        The relative L1 change of the answer's image under the highlight pairs from which
        the last pass goes on with them (>= 0; 0: always). A recovery that goes on takes
        about 1.5x its time (3 of 60 validation cases, each under a small sun).
    pixel_rays : int, default 4
        Under a point or directional light, each pixel is the mean of n x n rays across its
        area, as a box-filtered camera pixel (>= 1; 1: its centre ray, several per cent off
        Mitsuba's render where a pixel straddles the terminator or a sharp highlight).
    reflectance_pairs : int, default 500000
        Pixel-texel pairs the reflectance block differentiates per step (>= 64).
    map_pairs : int, default 8388608
        Pixel-texel pairs a map's posterior works on (>= 64): more usable pixels than
        ``map_pairs`` / texels are subsampled evenly; memory is 12 bytes a pair.
    working_pixels : int, default 16384
        The most pixels inference's forward model renders (>= 256, 128 x 128 by default): a
        larger image is block-averaged to fit, by the smallest integer factor k; a working
        pixel is used only if all k x k pixels of its block are usable.
    max_memory : float or None, default None
        The most memory (GB, > 0) a recovery may need by its estimate, checked before any
        work; None: the memory available (MemAvailable).
    """
    map_size: tuple = (32, 64)
    max_rounds: int = 3
    tol: float = 1e-3
    block_iters: int = 15
    illumination_iters: int = 60
    likelihood_scale: float = 0.05
    log_offset: float = 1e-3
    w_gmm: float = 300.0
    w_hue: float = 1.0
    w_entropy: float = 1.0
    w_gradient: float = 30000.0
    w_chromaticity: float = 1.0 / 3.0
    w_light_colour: float = 1.0
    light_temperature_sigma: float = 0.26
    light_tint_sigma: float = 0.05
    gradient_eps: float = 0.1
    gradient_alpha: float = 0.5
    map_levels: int = 2
    second_route_highlight: float | None = 2.0
    texel_samples: int = 2
    grey_texel_samples: int | None = 1
    highlight_texels: int = 25
    highlight_check: float = 0.03
    pixel_rays: int = 4
    reflectance_pairs: int = 500_000
    map_pairs: int = 1 << 23
    working_pixels: int = 128 * 128
    max_memory: float | None = None

    def __post_init__(self):
        try:
            h, w = (int(v) for v in self.map_size)
        except (TypeError, ValueError):
            raise ConfigError("map_size must be (H, W), got %r" % (self.map_size,), field="map_size") from None
        if h < 2 or w < 4:
            raise ConfigError("map_size %dx%d is too small (at least 2x4)" % (h, w), field="map_size")
        object.__setattr__(self, "map_size", (h, w))
        for name, low in (("max_rounds", 1), ("block_iters", 1), ("illumination_iters", 1), ("map_levels", 1),
                          ("texel_samples", 1), ("highlight_texels", 0), ("pixel_rays", 1),
                          ("reflectance_pairs", 64), ("map_pairs", 64),
                          ("working_pixels", 256)):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < low:
                raise ConfigError("%s must be an integer >= %d, got %r" % (name, low, value), field=name)
        value = self.grey_texel_samples
        if value is not None and (not isinstance(value, int) or isinstance(value, bool) or value < 1):
            raise ConfigError("grey_texel_samples must be None or an integer >= 1, got %r" % (value,),
                              field="grey_texel_samples")
        h = self.second_route_highlight
        if h is not None and not (isinstance(h, (int, float)) and not isinstance(h, bool) and math.isfinite(h)
                                  and h > 0):
            raise ConfigError("second_route_highlight must be None or a finite number > 0, got %r" % (h,),
                              field="second_route_highlight")
        m = self.max_memory
        if m is not None and not (isinstance(m, (int, float)) and not isinstance(m, bool) and math.isfinite(m)
                                  and m > 0):
            raise ConfigError("max_memory must be None or a finite number > 0 (GB), got %r" % (m,),
                              field="max_memory")
        a = self.gradient_alpha
        if not (isinstance(a, (int, float)) and not isinstance(a, bool) and 0 < a < 1):
            raise ConfigError("gradient_alpha must be a number between 0 and 1 (exclusive), got %r" % (a,),
                              field="gradient_alpha")
        for name in ("tol", "likelihood_scale", "log_offset", "gradient_eps", "light_temperature_sigma",
                     "light_tint_sigma"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ConfigError("%s must be a finite number > 0, got %r" % (name, value), field=name)
        for name in ("w_gmm", "w_hue", "w_entropy", "w_gradient", "w_chromaticity", "w_light_colour",
                     "highlight_check"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ConfigError("%s must be a finite number >= 0, got %r" % (name, value), field=name)

    @property
    def colour_split(self) -> bool:
        """Whether a map's inference splits the image's colour between light and
        material (either weight of ``w_chromaticity``, ``w_light_colour`` above 0)."""
        return self.w_chromaticity > 0 or self.w_light_colour > 0

    def with_colour_split(self, on) -> "Config":
        """This Config with the colour split on (both weights at their defaults) or
        off (both 0)."""
        fields = {f.name: f.default for f in dataclasses.fields(Config)}
        names = ("w_chromaticity", "w_light_colour")
        return dataclasses.replace(self, **{n: fields[n] if on else 0.0 for n in names})

    def prior_weights(self, observed_pixels) -> dict:
        """The weights {"gmm", "hue", "entropy", "gradient", "chromaticity",
        "light_colour"} scaled to ``observed_pixels`` (see :data:`PRIOR_PIXELS`)."""
        n = observed_pixels / PRIOR_PIXELS
        return {t: n * getattr(self, "w_" + t) for t in PRIOR_NAMES}


#: No prior at all (likelihood only).
NO_PRIORS = {"w_" + t: 0.0 for t in PRIOR_NAMES}

#: The named settings: ``default`` (``Config()``) and ``fast`` (the same on a 16x32
#: map; the demo's).
PRESETS = {
    "default": Config(),
    "fast": Config(map_size=(16, 32)),
}


def preset(name) -> Config:
    """The Config of a preset name (:data:`PRESETS`); a one-line ConfigError listing
    the names otherwise."""
    if isinstance(name, str) and name in PRESETS:
        return PRESETS[name]
    raise ConfigError("unknown preset %r: give one of %s" % (name, ", ".join(PRESETS)))


def field_docs() -> dict:
    """{field name: its description in the :class:`Config` docstring, one line}
    (the command line's help)."""
    docs, name = {}, None
    for line in (Config.__doc__ or "").splitlines():
        m = re.match(r"^    (\w+) : ", line)
        if m:
            name = m.group(1)
            docs[name] = []
        elif name is not None and line.startswith("        "):
            docs[name].append(line.strip())
        elif line.strip():
            name = None
    return {n: " ".join(words) for n, words in docs.items()}
