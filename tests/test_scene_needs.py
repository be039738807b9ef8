"""The single place that decides what a scene needs."""
import mitsuba as mi
import numpy as np
import pytest

from mi_dsbrdf.errors import SceneError
from mi_dsbrdf.inference.scene_needs import decide
from mi_dsbrdf.app.scenes import scene_path


def colour_image(n=8):
    img = np.ones((n, n, 3))
    img[..., 0] = 2.0
    return img


def test_sphere_under_envmap_needs_envmap_and_colour_but_no_visibility():
    needs = decide(mi.load_file(scene_path("sphere_envmap"), res="16", spp="1"), colour_image())
    assert needs.light == "envmap" and needs.envmap_block
    assert needs.colour_pass and not needs.visibility
    assert len(needs.reasons) == 4 and "sphere is convex" in needs.reasons[2]


def test_directional_light_and_grey_image_leave_out_envmap_and_colour_pass():
    needs = decide(mi.load_file(scene_path("sphere_directional"), res="16", spp="1"), np.ones((8, 8, 3)))
    assert needs.light == "directional" and not needs.envmap_block
    assert not needs.colour_pass and not needs.visibility
    assert "Powell" in needs.reasons[0] and "grey" in needs.reasons[1]


def test_torus_needs_visibility():
    needs = decide(mi.load_file(scene_path("torus_envmap"), res="16", spp="1"), colour_image())
    assert needs.visibility and "not convex" in needs.reasons[2]


def test_scenes_inference_cannot_handle():
    two_lights = mi.load_dict({"type": "scene", "a": {"type": "sphere", "bsdf": {"type": "dsbrdf"}},
                               "l1": {"type": "constant"}, "l2": {"type": "point", "position": [0, 0, 3]}})
    with pytest.raises(SceneError, match="exactly one light"):
        decide(two_lights, colour_image())
    no_dsbrdf = mi.load_dict({"type": "scene", "a": {"type": "sphere", "bsdf": {"type": "diffuse"}},
                              "l": {"type": "point", "position": [0, 0, 3]}})
    with pytest.raises(SceneError, match="dsbrdf"):
        decide(no_dsbrdf, colour_image())
    constant = mi.load_dict({"type": "scene", "a": {"type": "sphere", "bsdf": {"type": "dsbrdf"}},
                             "l": {"type": "constant"}})
    with pytest.raises(SceneError, match="envmap, a point or a directional"):
        decide(constant, colour_image())
