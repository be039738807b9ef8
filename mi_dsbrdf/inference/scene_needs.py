"""What a scene needs — the one place that decides what inference leaves out.

Given the loaded Mitsuba scene, the observed image and its mask, decide:

* the light: an ``envmap`` (non-parametric illumination block) or a point /
  directional emitter (direction + intensity by Powell's method, no envmap block);
* the colour pass: none for a grey image (all channels equal within 0.1 %);
* visibility rays: none for a convex object (a sphere, a convex mesh, a planar
  shape) alone in the scene, whose surface never shadows itself; otherwise shadow
  rays through the whole scene, so that a non-convex object shadows itself and
  every other shape shadows it;
* the light other shapes reflect onto the object: one bounce off each with a
  ``diffuse`` BSDF of constant reflectance (:mod:`~mi_dsbrdf.inference.bounce`),
  none off the others (the log names them);
* the lobes and bases of the reflectance model.

Each decision comes with its reason, printed in the inference log. Errors on
scenes that inference cannot handle are raised here, before any work.
"""
from __future__ import annotations

import dataclasses

import mitsuba as mi
import numpy as np
import trimesh

from mi_dsbrdf.errors import SceneError
from mi_dsbrdf.inference.bounce import diffuse_albedo
from mi_dsbrdf.plugins import bsdf_classes

GREY_TOLERANCE = 1e-3
#: other shapes named in the visibility reason (the rest are counted)
MAX_NAMED = 5


@dataclasses.dataclass(frozen=True)
class SceneNeeds:
    light: str              # "envmap", "point" or "directional"
    colour_pass: bool       # a second, colour pass after the grey one
    visibility: bool        # trace shadow rays (non-convex object, or other shapes)
    n_lobes: int
    n_bases: int
    reasons: tuple          # one line per decision, for the log
    surfaces: tuple = ()    # other shapes whose light onto the object is modelled (bounce_surfaces)

    @property
    def envmap_block(self) -> bool:
        return self.light == "envmap"


def light_kind(emitter) -> str:
    name = emitter.class_name() if hasattr(emitter, "class_name") else str(emitter).split("[")[0]
    flags = emitter.flags()
    if emitter.is_environment() and "Environment" in name:
        return "envmap"
    if mi.has_flag(flags, mi.EmitterFlags.DeltaDirection):
        return "directional"
    if mi.has_flag(flags, mi.EmitterFlags.DeltaPosition):
        if "PointLight" in name:
            return "point"
        raise SceneError("a %s is not supported (its emission depends on direction): use a point light at its "
                         "position, a directional light or an envmap" % name.strip())
    raise SceneError("the light must be an envmap, a point or a directional emitter; got %s" % name.strip())


def is_convex(shape) -> tuple:
    """(convex?, reason) for a Mitsuba shape."""
    name = str(shape).split("[")[0].strip()
    if name == "Sphere":
        return True, "a sphere is convex"
    if name in ("Rectangle", "Disk"):
        return True, "a planar %s never shadows itself" % name.lower()
    if shape.is_mesh():
        params = mi.traverse(shape)
        v = np.array(params["vertex_positions"], dtype=np.float64).reshape(-1, 3)
        f = np.array(params["faces"], dtype=np.int64).reshape(-1, 3)
        mesh = trimesh.Trimesh(v, f, process=True)
        if mesh.is_convex:
            return True, "the mesh is convex (trimesh)"
        return False, "the mesh is not convex (trimesh): it can shadow itself"
    return False, "%s: convexity unknown, assumed non-convex" % name


def other_shapes(scene, obj) -> list:
    """The shapes of ``scene`` other than ``obj``, each as ``"id (kind)"``, or the
    kind alone for a shape without an id; they occlude the object's light."""
    names = []
    for shape in scene.shapes():
        if shape == obj:
            continue
        kind = str(shape).split("[")[0].strip().lower()
        sid = shape.id()
        names.append("%s (%s)" % (sid, kind) if sid and not sid.startswith("_unnamed") else kind)
    return names


def bounce_surfaces(scene, obj) -> tuple:
    """(the other shapes of ``scene`` whose light onto ``obj`` is modelled: a
    ``diffuse`` BSDF of constant reflectance; the reason, one line)."""
    modelled, names, left = [], [], []
    for shape, name in zip([s for s in scene.shapes() if s != obj], other_shapes(scene, obj)):
        rho = diffuse_albedo(shape)
        if rho is None:
            left.append("%s (a %s BSDF)" % (name, shape.bsdf().class_name() if shape.bsdf() else "missing"))
        else:
            modelled.append(shape)
            names.append("%s (diffuse, reflectance %s)" % (name, " ".join("%.3g" % v for v in rho)))
    why = "one bounce off %s" % ", ".join(names[:MAX_NAMED]) if names else "none"
    if left:
        why += "; not modelled off %s: only a diffuse of constant reflectance is" % ", ".join(left[:MAX_NAMED])
    return tuple(modelled), why


def needs_visibility(scene, obj, light=None) -> tuple:
    """(shadow rays?, reason) for the object ``obj`` of ``scene``: yes when it is not
    convex (:func:`is_convex`: it can shadow itself) or when other shapes share the
    scene (:func:`other_shapes`: they can shadow it). ``light``: the light's kind
    (:func:`light_kind`) or None; it only words the reason."""
    convex, why = is_convex(obj)
    others = other_shapes(scene, obj)
    if others:
        shown = others[:MAX_NAMED] + (["%d more" % (len(others) - MAX_NAMED)] if len(others) > MAX_NAMED else [])
        why += "; %s in the scene can shadow it, traced through the whole scene: %s" % (
            "another shape" if len(others) == 1 else "%d other shapes" % len(others), ", ".join(shown))
    elif light not in (None, "envmap") and convex:
        why += "; no other shape, so a %s light casts no other shadow on it" % light
    return not convex or bool(others), why


def is_grey(image, mask=None, tol=GREY_TOLERANCE) -> bool:
    """True when every masked pixel has equal channels within ``tol`` (relative)."""
    img = np.asarray(image, dtype=np.float64)
    if img.ndim != 3 or img.shape[2] < 3:
        return True
    px = img[mask] if mask is not None else img.reshape(-1, img.shape[2])
    mean = px[:, :3].mean(axis=1, keepdims=True)
    return bool(np.all(np.abs(px[:, :3] - mean) <= tol * np.maximum(mean, 1e-12)))


def dsbrdf_object(scene):
    """The one shape of ``scene`` with a ``dsbrdf`` BSDF; SceneError otherwise."""
    dsbrdf = bsdf_classes(mi.variant())["dsbrdf"]
    objects = [s for s in scene.shapes() if isinstance(s.bsdf(), dsbrdf)]
    if len(objects) != 1:
        raise SceneError("inference needs exactly one object with a dsbrdf BSDF, found %d" % len(objects))
    return objects[0]


def decide(scene, image, mask=None, n_lobes=3, n_bases=10, visibility=None, surfaces=None) -> SceneNeeds:
    """The needs of ``scene`` (a loaded mi.Scene) observed as ``image`` (H, W, C).
    ``visibility``: :func:`needs_visibility` of the scene's object and light, and
    ``surfaces``: :func:`bounce_surfaces` of it, when the caller has them already
    (a mesh's convexity is not tested twice)."""
    emitters = scene.emitters()
    if len(emitters) != 1:
        raise SceneError("inference needs exactly one light in the scene, found %d" % len(emitters))
    obj = dsbrdf_object(scene)
    reasons = []
    light = light_kind(emitters[0])
    reasons.append("light: %s -> %s" % (light, "illumination-map block" if light == "envmap"
                                       else "direction + intensity by Powell's method, no envmap block"))
    grey = is_grey(image, mask)
    reasons.append("colour pass: %s" % ("no (the image is grey)" if grey else "yes (the image has colour)"))
    trace, why = needs_visibility(scene, obj, light) if visibility is None else visibility
    reasons.append("visibility rays: %s (%s)" % ("yes" if trace else "no", why))
    modelled = ()
    if other_shapes(scene, obj):
        modelled, why = bounce_surfaces(scene, obj) if surfaces is None else surfaces
        reasons.append("light the other shapes reflect onto the object: %s" % why)
    reasons.append("reflectance: %d lobes, %d bases" % (n_lobes, n_bases))
    return SceneNeeds(light, not grey, trace, n_lobes, n_bases, tuple(reasons), modelled)
