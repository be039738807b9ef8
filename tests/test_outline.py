"""A sphere's outline without a mask (mi_dsbrdf.app.outline): found from the
pixels that differ from a black background, robust to a dim limb and to the
unlit side; refused, asking for a mask, when it cannot be trusted."""
import math

import mitsuba as mi
import numpy as np
import pytest

from mi_dsbrdf.app.outline import boundary_points, bright_region, fit_circle, fit_outline
from mi_dsbrdf.app.photo import photo_scene, sphere_scene
from mi_dsbrdf.errors import InputError
from mi_dsbrdf.inference.latlong import latlong_directions

DIFFUSE = {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.5}}


def plain_sphere(shape, circle, shade, ss=8) -> np.ndarray:
    """(H, W, 3): a sphere rasterised by ``ss`` x ``ss`` samples a pixel, each
    sample's radiance ``shade(nx, ny, nz)`` (camera axes: x right, y up, z towards
    the camera) on the disc (cx, cy, r), 0 off it."""
    h, w = shape
    cx, cy, r = circle
    o = (np.arange(ss) + 0.5) / ss
    x = (np.arange(w)[:, None] + o[None, :]).ravel()
    y = (np.arange(h)[:, None] + o[None, :]).ravel()
    nx, ny = (x[None, :] - cx) / r, -(y[:, None] - cy) / r
    rho2 = nx ** 2 + ny ** 2
    nz = np.sqrt(np.clip(1 - rho2, 0, None))
    value = np.where(rho2 < 1, shade(nx, ny, nz), 0.0)
    value = value.reshape(h, ss, w, ss).mean(axis=(1, 3))
    return np.repeat(value[..., None], 3, axis=2)


def render(size, circle, bsdf, light, spp=32) -> np.ndarray:
    """(H, W, 3) Mitsuba render of a unit sphere seen as ``circle`` by the
    orthographic camera of the photograph workflow (camera on +z)."""
    s = sphere_scene(size, circle)
    s["object"]["bsdf"], s["light"] = bsdf, light
    return np.array(mi.render(mi.load_dict(s), spp=spp, seed=0), dtype=np.float64)


def towards(deg, azimuth=30.0) -> np.ndarray:
    """Unit direction ``deg`` degrees from the camera (+z), at ``azimuth`` degrees
    around it."""
    a, b = math.radians(deg), math.radians(azimuth)
    return np.array([math.sin(a) * math.cos(b), math.sin(a) * math.sin(b), math.cos(a)])


def point(deg, distance=5.0):
    return {"type": "point", "position": [float(v) for v in distance * towards(deg)],
            "intensity": {"type": "rgb", "value": (distance - 1) ** 2}}


def directional(deg):
    return {"type": "directional", "direction": [float(v) for v in -towards(deg)],
            "irradiance": {"type": "rgb", "value": 1.0}}


def cone_map(deg, axis=(0.0, 0.0, 1.0), h=32, w=64):
    """An envmap lit (radiance 1) within ``deg`` degrees of ``axis``, black elsewhere
    (so black behind the sphere, where the camera sees it)."""
    lit = latlong_directions(h, w) @ np.asarray(axis) > math.cos(math.radians(deg))
    return {"type": "envmap", "bitmap": mi.Bitmap(np.repeat(lit[..., None], 3, axis=2).astype(np.float32))}


def assert_close(fitted, circle, tol=0.5):
    assert np.max(np.abs(np.subtract(fitted, circle))) < tol, (fitted, circle)


# --- the plain reference: analytic discs, no renderer --------------------------------

def test_boundary_points_sit_on_an_edge_where_the_coverage_puts_them():
    """A half-plane x < 10.3 of constant radiance: each boundary point lies on the
    edge, whatever its pixel's coverage."""
    img = np.zeros((16, 24, 3))
    img[:, :10] = 1.0
    img[:, 10] = 0.3
    region, above = bright_region(img)
    pts = boundary_points(region, above)
    assert len(pts) == 16
    np.testing.assert_allclose(pts[:, 0], 10.3)


@pytest.mark.parametrize("seed", range(3))
def test_analytic_discs_are_fitted_with_a_bright_or_a_dim_limb_and_half_lit(seed):
    rng = np.random.default_rng(seed)
    for _ in range(4):
        r = rng.uniform(14, 28)
        circle = (rng.uniform(r + 2, 70 - r), rng.uniform(r + 2, 62 - r), r)
        flat = plain_sphere((64, 72), circle, lambda nx, ny, nz: np.ones_like(nz))
        assert_close(fit_outline(flat), circle, 0.15)
        dim = plain_sphere((64, 72), circle, lambda nx, ny, nz: nz)               # lit from the camera
        assert_close(fit_outline(dim), circle, 0.3)
        half = plain_sphere((64, 72), circle, lambda nx, ny, nz: np.clip(nx, 0, None))   # lit from the side
        assert_close(fit_outline(half), circle, 0.3)
        crescent = plain_sphere((64, 72), circle,                                 # lit from behind
                                lambda nx, ny, nz: np.clip(0.866 * nx - 0.5 * nz, 0, None))
        assert_close(fit_outline(crescent), circle, 0.5)


def test_a_disc_cut_by_the_frame_is_fitted_from_its_outline_inside_it():
    circle = (60.4, 30.2, 20.3)
    assert_close(fit_outline(plain_sphere((64, 64), circle, lambda nx, ny, nz: nz)), circle, 0.3)


def test_a_lit_part_that_ends_near_the_outline_is_refused():
    """Lit 30 degrees off the camera, the unlit side is a thin crescent whose edge
    bends like the outline: a circle between the two would fit both."""
    circle = (36.2, 32.7, 24.1)
    img = plain_sphere((64, 72), circle, lambda nx, ny, nz: np.clip(0.5 * nx + 0.866 * nz, 0, None))
    with pytest.raises(InputError, match="not a circle.*give a mask of the sphere \\(--mask\\)"):
        fit_outline(img)


def test_a_background_that_is_not_black_or_no_sphere_is_refused():
    circle = (36.2, 32.7, 20.1)
    img = plain_sphere((64, 72), circle, lambda nx, ny, nz: nz)
    with pytest.raises(InputError, match="background is not black.*--mask"):
        fit_outline(img + 0.05)
    noisy = np.abs(np.random.default_rng(0).normal(0, 1e-3, img.shape))
    fit_outline(img + noisy)                          # black within its noise: accepted
    with pytest.raises(InputError, match="--mask"):
        fit_outline(noisy)
    square = np.zeros((64, 72, 3))
    square[10:50, 12:52] = 1.0
    with pytest.raises(InputError, match="--mask"):
        fit_outline(square)


def test_mask_fit_is_unchanged():
    yy, xx = np.mgrid[0:48, 0:56] + 0.5
    mask = (xx - 24.3) ** 2 + (yy - 21.6) ** 2 <= 15.2 ** 2
    assert_close(fit_circle(mask), (24.3, 21.6, 15.2), 0.3)
    square = np.zeros((48, 48), bool)
    square[8:40, 8:40] = True
    with pytest.raises(InputError, match="mask's outline is not a circle"):
        fit_circle(square)


# --- rendered spheres whose limb is dark ---------------------------------------------

CIRCLE = (41.3, 37.6, 24.2)
SIZE = (84, 76)


@pytest.mark.parametrize("name, bsdf, light", [
    ("point light at 90 deg: half lit", DIFFUSE, point(90)),
    ("far point light at 90 deg", {"type": "dsbrdf", "material": "gold-metallic-paint"}, point(90, 20.0)),
    ("directional light at 90 deg", DIFFUSE, directional(90)),
    ("Lambertian lit from the camera: limb dark by cos", DIFFUSE, directional(0)),
    ("directional light behind: a crescent", DIFFUSE, directional(135)),
    ("map lit only around the camera", DIFFUSE, cone_map(40)),
    ("map lit from the side", {"type": "dsbrdf", "material": "blue-acrylic"}, cone_map(60, (1.0, 0.3, 0.5))),
])
def test_rendered_spheres_with_a_dark_limb_are_fitted(name, bsdf, light):
    img = render(SIZE, CIRCLE, bsdf, light)
    assert_close(fit_outline(img), CIRCLE, 0.5)
    _, circle = photo_scene(img, light="envmap")            # the photograph workflow uses it
    assert circle == fit_outline(img)


def test_rendered_spheres_that_cannot_be_trusted_are_refused():
    # a point light 30 degrees off the camera: the lit part ends near the outline
    img = render(SIZE, CIRCLE, {"type": "dsbrdf", "material": "gold-metallic-paint"}, point(30))
    with pytest.raises(InputError, match="not a circle.*--mask"):
        fit_outline(img)
    # a map seen behind the sphere: the background is not black
    img = render(SIZE, CIRCLE, DIFFUSE, {"type": "constant", "radiance": {"type": "rgb", "value": 0.3}})
    with pytest.raises(InputError, match="background is not black.*--mask"):
        photo_scene(img)
