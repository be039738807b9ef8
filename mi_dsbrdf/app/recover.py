"""``mi_dsbrdf.recover`` and ``mi-dsbrdf recover``: scene + image -> checked inputs
-> inference -> :class:`~mi_dsbrdf.app.result.Result` (-> the result directory).

Every check runs before any work and before anything is written; the result
directory (see :mod:`mi_dsbrdf.app.result`) is written whole or not at all.
"""
from __future__ import annotations

import dataclasses
import os
import time

import mitsuba as mi
import numpy as np
from tqdm import tqdm

from mi_dsbrdf.app.io import as_mask, check_image, check_out, read_mask
from mi_dsbrdf.app.result import RESULT_FILES, Result, relative_residual, stage_row
from mi_dsbrdf.app.memory import check_memory, memory_needs
from mi_dsbrdf.app.working_grid import (WorkingGrid, rerender as grid_rerender, usable_blocks, working_grid,
                                        working_scene)
from mi_dsbrdf.config import PRESETS, Config, preset
from mi_dsbrdf.errors import InputError, SceneError
from mi_dsbrdf.inference.envmap import recover_envmap
from mi_dsbrdf.inference.forward import TexelSum
from mi_dsbrdf.inference.images import as_radiance, read_image
from mi_dsbrdf.inference.light import SEARCH_CANDIDATES, recover_light
from mi_dsbrdf.inference.lobes import observed_directions
from mi_dsbrdf.inference.pixels import white_levels
from mi_dsbrdf.inference.reflectance import reflectance_starts
from mi_dsbrdf.inference.scene_needs import bounce_surfaces, decide, dsbrdf_object
from mi_dsbrdf.model.model_file import shipped_model

#: fewest usable pixels inference accepts: 16 reflectance unknowns and up to 3 of
#: the light (a few pixels give a confident, wrong light)
MIN_PIXELS = 100


def resolve_config(config) -> Config:
    """``config`` as a Config: None is ``Config()``, a string names a preset
    (:data:`~mi_dsbrdf.config.PRESETS`; ConfigError if unknown); InputError for
    anything else."""
    if config is None:
        return Config()
    if isinstance(config, str):
        return preset(config)
    if not isinstance(config, Config):
        raise InputError("config must be a mi_dsbrdf.Config or a preset name (%s), got %s"
                         % (", ".join(PRESETS), type(config).__name__))
    return config


def recover(scene, image, mask=None, config: Config | str = None, progress=None, srgb=False,
            white_level=None, model=None) -> Result:
    """Recover the reflectance and the light of one image of known geometry.

    Parameters
    ----------
    scene : path of a Mitsuba scene XML, a scene dict (``mi.load_dict`` form) or an
        ``mi.Scene``: a camera, exactly one object with a ``dsbrdf`` BSDF and one
        light (``envmap``, ``directional`` or ``point``) whose values are ignored
    image : path of a linear HDR image (EXR/HDR), or an (H, W, 3) float array of
        radiance, film-sized
    mask : optional path or (H, W) array (bool, or numbers: above half the
        maximum is used)
    config : :class:`~mi_dsbrdf.config.Config`, or the name of a preset
        (``"default"``, ``"fast"``: :data:`~mi_dsbrdf.config.PRESETS`); default ``Config()``
    progress : None (quiet); True: what the scene needs printed before the work,
        a tqdm bar per pass (its total and ETA), the final re-render announced;
        or a callable given each logged round (a dict)
    srgb : linearise an 8-bit image (file or uint8 array) from sRGB instead of
        refusing it
    white_level : the camera's white level in the image's (linear) units: one
        number, or one per channel (R, G, B); pixels with a channel at or above it
        are left out as clipped. Without it, clipping is found as plateaus of each
        channel's maximum (:mod:`mi_dsbrdf.inference.pixels`)
    model : the reflectance model (:class:`~mi_dsbrdf.model.model_file.ReflectanceModel`, e.g.
        one built from a library of your own); default the shipped one

    Returns
    -------
    :class:`~mi_dsbrdf.app.result.Result`; ``.save(folder)`` writes the result directory.

    Raises
    ------
    InputError, SceneError, ConfigError : bad input, with a one-line message.
    """
    began = time.perf_counter()
    cfg = resolve_config(config)
    levels = white_levels(white_level)
    scene, source = _scene(scene)
    # the memory the settings need, priced before the image is read (ConfigError if over)
    film = scene.sensors()[0].film().crop_size()
    envmap, visibility = memory_needs(scene)
    obj = dsbrdf_object(scene)
    bounce = bounce_surfaces(scene, obj)
    check_memory(cfg, WorkingGrid.of(film, cfg.working_pixels), envmap, visibility[0],
                 surfaces=len(bounce[0]) if visibility[0] else 0)
    obs, user_mask = load_inputs(image, mask, srgb)
    h, w = obs.shape[:2]
    if (w, h) != (int(film[0]), int(film[1])):
        raise InputError("%s is %dx%d but the scene's film is %dx%d" % (_name(image), w, h, film[0], film[1]))
    model = shipped_model() if model is None else model
    # a film of more than cfg.working_pixels pixels: inference on its block means
    # (mi_dsbrdf.app.working_grid); else on the image itself
    grid, on_object = working_grid(scene, obj, user_mask, cfg.working_pixels)
    work = grid.mean(obs)
    needs = decide(scene, work, None if user_mask is None else grid.all(user_mask), model.basis.n_lobes,
                   model.basis.n_bases, visibility, bounce)
    ts = TexelSum(working_scene(scene, grid), obj, cfg.map_size if needs.envmap_block else (1, 1),
                  visibility=needs.visibility, to_world=envmap_rotation(scene) if needs.envmap_block else None,
                  samples=cfg.texel_samples if needs.envmap_block else 1,     # the re-render as inference saw it
                  pixel_rays=cfg.pixel_rays, surfaces=needs.surfaces)
    keep = usable_blocks(grid, ts.mask, on_object, obs, user_mask, levels)
    if keep.sum() < MIN_PIXELS:
        raise InputError("only %d usable pixels (on the object, inside the mask, unsaturated, off the silhouette); "
                         "inference needs at least %d: use a larger image or mask" % (int(keep.sum()), MIN_PIXELS))
    stages = {"checks": stage_row(began)}
    report, close = _progress(progress, cfg, needs, model)
    t0 = time.perf_counter()
    try:
        if needs.envmap_block:
            rec = recover_envmap(ts, work, keep, model, cfg, colour=needs.colour_pass, progress=report)
            # the re-render as the answer was fitted: with the highlight pairs if it was
            lit = ts.with_highlights(rec.highlight_texels)
            light, L = None, rec.illumination.reshape(-1, 3)
        else:
            point = (centre(obj), point_light_distance(scene, obj)) if needs.light == "point" else None
            rec = recover_light(ts, work, keep, model, cfg, progress=report, point=point, colour=needs.colour_pass)
            light = {"type": needs.light, "direction": [float(v) for v in rec.light["direction"]],
                     "intensity": float(rec.light["intensity"])}
            if point is not None:
                light["position"] = [float(v) for v in rec.light["position"]]
                lit = ts.with_point(rec.light["position"])
            else:
                lit = ts.with_directions(np.asarray(rec.light["direction"])[None], [1.0])
            L = np.full((1, 3), rec.light["intensity"])
    finally:
        close()
    stages["inference"] = stage_row(t0)
    t1 = time.perf_counter()
    if _printing(progress):
        print("  re-rendering %d pixels under the recovered material and light" % (
            len(lit.pixels) if on_object is None else int(on_object.sum())), flush=True)
    rerender = grid_rerender(grid, lit, rec.material, L, cfg.map_pairs, on_object)
    stages["re-render"] = stage_row(t1)
    t2 = time.perf_counter()
    # where the image looked in (theta_h, theta_d), stored with the material (a map's
    # texels from their centres: a quarter of the pairs, the same cells within a texel)
    view = lit.with_map_size(lit.map_size) if needs.envmap_block else lit
    material = rec.material.with_observed(observed_directions(view, L, np.nonzero(keep.reshape(-1)[view.pixels])[0]))
    stages["observed directions"] = stage_row(t2)
    used = grid.repeat(keep)
    flags = rec.flags
    if rec.highlight_flag() is not None:
        # a doubted highlight: where on the object it lights (against the posterior's
        # flattest sample)
        t3 = time.perf_counter()
        flags = [rec.highlight_flag(highlight_place(grid, lit, rec.material, L, cfg.map_pairs, on_object,
                                                    rerender, used))]
        stages["highlight place"] = stage_row(t3)
    rows = rec.log
    from mi_dsbrdf import __version__
    log = {"version": __version__, "config": dataclasses.asdict(cfg),
           "scene": source if isinstance(source, str) else None,
           "image": os.fspath(image) if isinstance(image, (str, os.PathLike)) else None,
           "image_size": [h, w], "map_size": list(cfg.map_size) if needs.envmap_block else None,
           "stages": stages, "needs": list(needs.reasons), "rounds": rows, "used_pixels": int(keep.sum()),
           "working_grid": grid.log(),
           "seconds": rec.seconds,
           "unseen_texels": rows[-1].get("unseen_texels") if rows else None,
           "highlight_doubt": rec.highlight_doubt, "flags": flags,
           "highlight_change": rec.highlight_change, "highlight_texels": rec.highlight_texels,
           "bounce_surfaces": [s.id() for s in needs.surfaces]}
    log["residual"] = relative_residual(obs, rerender, used)
    return Result(material=material, light=light, illumination=rec.illumination, seen=rec.seen, log=log,
                  image=obs, used=used, rerender=rerender, scene_source=source,
                  illumination_std=rec.illumination_spread)


def highlight_place(grid, lit, material, L, pairs, on_object, rerender, used) -> str:
    """Where on the object ``material``'s highlight lights, in words
    (:func:`brightest_place`): the used pixels its ``rerender`` brightens most over
    the posterior's sample with the weakest highlight (of
    :meth:`~mi_dsbrdf.brdf.dsbrdf.Material.highlight_draws`, the doubt's), both
    scaled to the same sum."""
    draws, ratios = material.highlight_draws()
    flattest = draws[int(np.argmin(ratios))]
    other = grid_rerender(grid, lit, flattest, L, pairs, on_object)
    a, b = rerender.mean(axis=2), other.mean(axis=2)
    b = b * a[used].sum() / max(float(b[used].sum()), 1e-300)
    return brightest_place(a - b, used)


#: the eight directions from the object's centre :func:`brightest_place` names,
#: counter-clockwise from the right in 45 degree sectors
COMPASS = ("right", "upper right", "upper", "upper left", "left", "lower left", "lower", "lower right")


def brightest_place(excess, used) -> str:
    """"centre", "upper left", "right", ...: where the pixels of ``excess`` (H, W)
    within half of its largest value over ``used`` (H, W) bool lie: their centroid
    against the used pixels' bounding box, "centre" within 0.2 of its half-size of
    the middle, else one of :data:`COMPASS` (row 0 is the image's top)."""
    rows, cols = np.nonzero(used)
    y, x = np.nonzero(used & (excess >= 0.5 * float(excess[used].max())))
    dx = (x.mean() - (cols.min() + cols.max()) / 2) / max((cols.max() - cols.min()) / 2, 1)
    dy = ((rows.min() + rows.max()) / 2 - y.mean()) / max((rows.max() - rows.min()) / 2, 1)
    if np.hypot(dx, dy) < 0.2:
        return "centre"
    return COMPASS[int(np.round(np.degrees(np.arctan2(dy, dx)) / 45.0)) % 8]


def recover_files(scene_file, image_file, out, mask_file=None, force=False, config: Config | str = None,
                  progress=True, srgb=False, white_level=None) -> Result:
    """:func:`recover` from files, then :meth:`Result.save` into ``out`` (checked first,
    so that a bad output folder fails before the work)."""
    inputs = [f for f in (scene_file, image_file, mask_file) if isinstance(f, (str, os.PathLike))]
    check_out(out, force, RESULT_FILES, inputs)
    result = recover(scene_file, image_file, mask=mask_file, config=config, progress=progress, srgb=srgb,
                     white_level=white_level)
    result.save(out, force=force, inputs=inputs)
    return result


def load_inputs(image, mask=None, srgb=False) -> tuple:
    """((H, W, 3) float64 linear image, (H, W) bool mask or None) from paths or
    arrays, checked (InputError: unreadable, 8-bit without ``srgb``, NaN/Inf,
    negative, black, a mask of another size or empty)."""
    obs = _image(image, srgb)
    check_image(obs, _name(image))
    if mask is None:
        return obs, None
    if isinstance(mask, (str, os.PathLike)):
        return obs, read_mask(mask, obs.shape[:2])
    return obs, as_mask(mask, obs.shape[:2])


def _name(image) -> str:
    return os.fspath(image) if isinstance(image, (str, os.PathLike)) else "image"


def _scene(scene):
    """(mi.Scene, its source: the path, the dict, or None); SceneError if it has no
    camera."""
    loaded, source = _load_scene(scene)
    if not loaded.sensors():
        raise SceneError("the scene has no sensor: add the camera that took the image, its film the image's size "
                         "(e.g. <sensor type=\"perspective\"> with a <film type=\"hdrfilm\">)")
    return loaded, source


def _load_scene(scene):
    """(mi.Scene, its source) of a path, a dict or an mi.Scene (InputError if it
    does not load)."""
    if isinstance(scene, mi.Scene):
        return scene, None
    if isinstance(scene, dict):
        try:
            return mi.load_dict(scene), scene
        except Exception as e:  # noqa: BLE001  (Mitsuba raises RuntimeError subclasses with varied text)
            raise InputError("the scene dict does not load: %s" % str(e).splitlines()[-1]) from None
    if not isinstance(scene, (str, os.PathLike)):
        raise InputError("scene must be a scene XML path, a scene dict or an mi.Scene, got %s" % type(scene).__name__)
    path = os.fspath(scene)
    if not os.path.isfile(path):
        raise InputError("scene file %s does not exist" % path)
    try:
        return mi.load_file(path), path
    except Exception as e:  # noqa: BLE001
        raise InputError("scene %s does not load: %s" % (path, str(e).splitlines()[-1])) from None


def _image(image, srgb) -> np.ndarray:
    """(H, W, 3) float64 linear radiance from a path or an array (a copy: the
    caller's array is never changed)."""
    if isinstance(image, (str, os.PathLike)):
        return read_image(image, srgb=srgb)
    return as_radiance(image, srgb, "image (a %s array)" % np.asarray(image).dtype)


def _printing(progress) -> bool:
    """Whether ``progress`` asks for printed progress (True, or another true value
    that is not a callable) rather than quiet (None, False) or a callable's rows."""
    return bool(progress) and not callable(progress)


#: the progress bar of each logged pass: {pass: (description, unit)}
PASSES = {"start": ("starts", "start"), "grey": ("grey pass", "round"), "colour": ("colour pass", "round"),
          "highlights": ("highlight pass", "round"),
          "light search": ("light search", "direction"), "light": ("light pass", "round")}


def _progress(progress, cfg, needs, model):
    """(report, close): ``report`` is called with each logged row, ``close`` when
    inference ends. ``progress`` None/False: quiet; a callable: it is ``report``;
    True (or any other true value, :func:`_printing`): the scene's needs printed
    first, then one tqdm bar per pass with its total (the starts,
    ``cfg.max_rounds`` rounds, the light search's candidates) and an ETA. A pass
    that converges early ends its bar below the total."""
    if not progress:
        return None, lambda: None
    if not _printing(progress):
        return progress, lambda: None
    for line in needs.reasons:
        print("  " + line, flush=True)
    totals = {"start": len(reflectance_starts(model)), "grey": cfg.max_rounds, "colour": cfg.max_rounds,
              "highlights": cfg.max_rounds,
              "light search": SEARCH_CANDIDATES, "light": cfg.max_rounds}
    state = {"bar": None, "pass": None, "since": time.time()}

    def close():
        if state["bar"] is not None:
            # ends as of its last row (a pass is known to end when the next one's first row comes)
            bar, shift = state["bar"], time.time() - state["since"]
            bar.start_t, bar.last_print_t = bar.start_t + shift, bar.last_print_t + shift
            bar.close()
        state["bar"] = state["pass"] = None

    def report(row):
        name = row.get("pass")
        key = (row.get("route", 0), name)
        if name not in PASSES:              # the answer's row: no pass of its own
            close()
            return
        if key != state["pass"]:
            close()
            desc, unit = PASSES[name]
            bar = tqdm(total=totals[name], desc="recover: " + ("second route, " if key[0] else "") + desc,
                       unit=unit)
            bar.start_t = bar.last_print_t = state["since"]     # the pass began with the last one's row
            state["bar"], state["pass"] = bar, key
        state["bar"].set_postfix(nlp="%.4g" % row["neg_log_posterior"], refresh=False)
        state["bar"].update()
        state["since"] = time.time()        # tqdm's clock
    return report, close


def envmap_rotation(scene):
    """(4, 4) to_world of the scene's environment map, or None for the identity: the
    map is fitted in the envmap's own frame, which the saved scene.xml keeps."""
    m = np.array(scene.emitters()[0].world_transform().matrix, dtype=np.float64).reshape(4, 4)
    return None if np.allclose(m, np.eye(4)) else m


def centre(shape) -> np.ndarray:
    """(3,) centre of a shape's bounding box."""
    bbox = shape.bbox()
    return (np.array(bbox.min, dtype=np.float64) + np.array(bbox.max, dtype=np.float64)) / 2


def point_light_distance(scene, shape) -> float:
    """Distance of the scene's point light from the object's centre: inference
    recovers the light's direction and intensity and keeps this distance (one
    image barely constrains it); InputError if the light is inside the object."""
    position = np.array(mi.traverse(scene.emitters()[0])["position"], dtype=np.float64).reshape(3)
    c = centre(shape)
    bbox = shape.bbox()
    radius = 0.5 * np.linalg.norm(np.array(bbox.max, dtype=np.float64) - np.array(bbox.min, dtype=np.float64))
    distance = float(np.linalg.norm(position - c))
    if distance <= radius:
        raise InputError("the point light at %s is inside the object's bounding sphere (radius %.3g around %s): "
                         "place it outside" % (position.tolist(), radius, c.tolist()))
    return distance
