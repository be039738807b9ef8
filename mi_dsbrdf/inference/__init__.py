"""Reflectance and illumination recovery from one image (paper §4-5).

Data flow: scene + image -> :mod:`~.scene_needs` (what the scene needs) ->
:mod:`~.forward` (deterministic texel sums over Mitsuba geometry, the ``dsbrdf``
plugin by Dr.Jit) -> :mod:`~.objective` (the posterior: :mod:`~.likelihood`,
reflectance priors of :mod:`mi_dsbrdf.model.priors`, :mod:`~.illumination_priors`)
-> the blocks (:mod:`~.envmap`, :mod:`~.light`, :mod:`~.reflectance`) and the
uncertainty at their answer (:mod:`~.uncertainty`) -> :class:`~.result.Recovery`.
Lat-long conventions are in :mod:`~.latlong`.
"""
from mi_dsbrdf.inference.envmap import recover_envmap
from mi_dsbrdf.inference.light import recover_light
from mi_dsbrdf.inference.result import Recovery

__all__ = ["recover_envmap", "recover_light", "Recovery"]
