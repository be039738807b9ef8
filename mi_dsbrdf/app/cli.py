"""``mi-dsbrdf`` command line: argument parsing only; the work is in the library."""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys

import mitsuba as mi

from mi_dsbrdf.app.demo import run
from mi_dsbrdf.app.photo import LIGHTS, photo_scene
from mi_dsbrdf.app.recover import recover_files
from mi_dsbrdf.app.render import relight, render_to_files
from mi_dsbrdf.app.scenes import scene_path
from mi_dsbrdf.config import PRESETS
from mi_dsbrdf.errors import InputError, MiDsbrdfError
from mi_dsbrdf.model.build import GMM, build_model
from mi_dsbrdf.model.fit_problem import OBJECTIVE
from mi_dsbrdf.model.model_file import SHIPPED


def _setup(variant):
    """Switch to ``variant`` (the package's import selected llvm_ad_rgb and
    registered the plugins; they re-register on a switch)."""
    if variant:
        mi.set_variant(variant)


def _config(args):
    """The named preset with the command line's overrides (validated)."""
    overrides = {k: v for k, v in (("map_size", args.map_size), ("max_rounds", args.rounds),
                                   ("block_iters", args.iters), ("texel_samples", args.texel_samples),
                                   ("start_candidates", args.start_candidates), ("grey_rounds", args.grey_rounds))
                 if v is not None}
    if args.no_second_route:
        overrides["second_route_highlight"] = None
    cfg = dataclasses.replace(PRESETS[args.preset], **overrides)
    return cfg.with_colour_split(False) if args.no_colour_split else cfg


def cmd_render(args):
    scene = scene_path(args.scene)
    params = {}
    for p in args.param:
        if "=" not in p:
            raise InputError("--param %r: give NAME=VALUE" % p)
        name, value = p.split("=", 1)
        params[name] = value
    r = render_to_files(scene, args.out, spp=args.spp, force=args.force, **params)
    print("rendered %s in %.2f s -> %s, %s" % (args.scene, r["seconds"], r["exr"], r["png"]))


def cmd_demo(args):
    r = run(args.out, material=args.material, res=args.res, config=_config(args), spp=args.spp, force=args.force)
    print("demo: %s under a sunsky, recovered in %.0f s (doing nothing in brackets): BRDF Eq. 20 paper %.3f "
          "(%.3f), cosine %.3f (%.3f), illumination %.3f (%.3f), relit %.3f (%.3f) -> %s" % (
              r["material"], r["recover_seconds"], r["brdf_eq20_paper"], r["mean_material_eq20_paper"],
              r["brdf_eq20_cosine"], r["mean_material_eq20_cosine"], r["illumination_cosine_after_scale"],
              r["constant_map_cosine_after_scale"], r["relit_log_rmse_after_scale"],
              r["mean_material_relit_log_rmse_after_scale"], os.path.join(args.out, "report.md")))


def cmd_build_model(args):
    out = args.out or SHIPPED
    if os.path.exists(out) and not args.force:
        raise InputError("%s exists; pass --force to replace it" % out)
    if not (math.isfinite(args.fit_anchor) and args.fit_anchor >= 0):
        raise InputError("--fit-anchor must be a finite number >= 0, got %r" % args.fit_anchor)
    if not args.fit_anchor_lobes or any(r not in (0, 1, 2) for r in args.fit_anchor_lobes):
        raise InputError("--fit-anchor-lobes takes lobes 0, 1 and 2 (0 the broadest), got %s" % args.fit_anchor_lobes)
    objective = dataclasses.replace(OBJECTIVE, anchor_weight=args.fit_anchor,
                                    anchor_lobes=tuple(sorted(set(args.fit_anchor_lobes))))
    a = build_model(args.merl, out, k=args.k, exclude=args.exclude, workers=args.workers,
                    fits_from=args.fits_from, gmm=args.gmm, objective=objective,
                    complete=False if args.complete_unseen is None else (args.complete_unseen or True))
    info = json.loads(str(a["build_info"]))
    print("model with %d bases (%.1f%% of the curve variance), %d library materials, GMM of %d %s components, "
          "hue kappa_h %.3g: %s (%.0f s)" % (
              args.k, 100 * a["fpca_variance"][:args.k].sum() / a["fpca_variance"].sum(), len(a["library_names"]),
              len(a["gmm_weights"]), str(a["gmm_covariance_type"]), float(a["hue_kappa"]), out, info["seconds"]))


def _map_size(text):
    try:
        h, w = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError("map size must be HxW, e.g. 16x32; got %r" % text) from None
    return h, w     # its range is checked by Config


def cmd_recover(args):
    if (args.scene is None) == (not args.sphere):
        raise InputError("give --scene SCENE.xml, or --sphere for a photograph of a sphere (no scene file)")
    if not args.sphere and (args.light is not None or args.fov is not None):
        raise InputError("--light and --fov describe the scene --sphere builds; a --scene brings its own")
    scene = args.scene
    if args.sphere:
        scene, circle = photo_scene(args.image, args.mask, light=args.light or "envmap", fov=args.fov,
                                    srgb=args.srgb)
        print("  sphere: centre (%.1f, %.1f) px, radius %.1f px, %s camera, %s light" % (
            circle + ("orthographic" if args.fov is None else "perspective (fov %g)" % args.fov,
                      args.light or "envmap")))
    result = recover_files(scene, args.image, args.out, mask_file=args.mask, force=args.force,
                           config=_config(args), srgb=args.srgb)
    for line in result.log["needs"]:
        print("  " + line)
    if result.log.get("unseen_texels"):
        print("  %d illumination texels are seen by no pixel: left black (see illumination.png)"
              % result.log["unseen_texels"])
    print("recovered in %.1f s -> %s" % (result.seconds, args.out))


def cmd_relight(args):
    r = relight(args.material, args.out, envmap=args.envmap, shape=args.shape, scene=args.scene,
                shape_id=args.shape_id, res=args.res, spp=args.spp, force=args.force)
    print("relit in %.1f s -> %s, %s" % (r["seconds"], r["exr"], r["png"]))


def _config_arguments(p, preset):
    """--preset and the overrides of its most used settings."""
    c = PRESETS[preset]
    p.add_argument("--preset", default=preset, choices=sorted(PRESETS),
                   help="named inference settings (default %s: map %dx%d, %d rounds, %d iterations)"
                   % ((preset,) + c.map_size + (c.max_rounds, c.block_iters)))
    p.add_argument("--map-size", default=None, type=_map_size, help="illumination map HxW (overrides the preset)")
    p.add_argument("--rounds", type=int, default=None, help="rounds of alternating blocks per pass")
    p.add_argument("--iters", type=int, default=None, help="Levenberg-Marquardt iterations per reflectance block")
    p.add_argument("--texel-samples", type=int, default=None, metavar="S",
                   help="light each map texel from S x S directions in the colour pass (default 2; the start "
                        "and the grey pass run at the texel centres; 1: centres throughout, sharp highlights come "
                        "back too broad; see the README, Natural light)")
    p.add_argument("--start-candidates", type=int, default=None, metavar="N",
                   help="under a map, run the grey pass from the N best reflectance starts and go on from the "
                        "lowest posterior (default 1; 2 takes about 1.5x the time and keeps sharp highlights "
                        "under small bright lights that the coarse start can misjudge; see the README, "
                        "Natural light)")
    p.add_argument("--grey-rounds", type=int, default=None, metavar="N",
                   help="under a map, rounds of the grey pass (default: --rounds); 0 leaves it out: about a "
                        "quarter faster, level on validation but for one map win in 120 (see the README, "
                        "Natural light, Options that are not the default)")
    p.add_argument("--no-second-route", action="store_true",
                   help="under a map, return the first inference's answer even when it has a highlight (by "
                        "default such an answer is checked against a second inference whose start is judged "
                        "on the full map; about 1.5x faster, worse BRDF on glossy materials; see the README, "
                        "Natural light, The twenty-second session)")
    p.add_argument("--no-colour-split", action="store_true",
                   help="under a map, leave the image's colour in the material (the grey-world start) instead "
                        "of splitting it between light and material by a prior on each (the default; see the "
                        "README, Natural light, The colour split)")


def main(argv=None):
    ap = argparse.ArgumentParser(prog="mi-dsbrdf", description=__doc__)
    ap.add_argument("--variant", default=None, help="Mitsuba variant (default llvm_ad_rgb)")
    sub = ap.add_subparsers(dest="command", required=True)

    p = sub.add_parser("render", help="render a scene XML to EXR + PNG")
    p.add_argument("scene", help="scene XML path or shipped scene name")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--spp", type=int, default=None)
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="override a scene <default> (repeatable)")
    p.add_argument("--force", action="store_true", help="replace earlier renders of the scene in --out")
    p.set_defaults(func=cmd_render)

    p = sub.add_parser("demo", help="recover a shipped material under a generated sky, and report (main job)")
    p.add_argument("--out", default="out/demo")
    p.add_argument("--material", default="gold-metallic-paint", help="library material of the observed sphere")
    p.add_argument("--res", type=int, default=64, help="image size (default 64)")
    _config_arguments(p, "demo")
    p.add_argument("--spp", type=int, default=256, help="samples per pixel of the renders")
    p.add_argument("--force", action="store_true")
    p.set_defaults(func=cmd_demo)

    p = sub.add_parser("build-model", help="fit MERL, learn bases and priors, write the reflectance model")
    p.add_argument("--merl", required=True, help="merl_nbrdf_weights.npz or a folder of MERL .binary files")
    p.add_argument("--out", default=None, help="model file (default: the package's mi_dsbrdf/data/model.npz)")
    p.add_argument("--k", type=int, default=10, help="number of basis functions (default 10)")
    p.add_argument("--exclude", action="append", default=[], metavar="NAME",
                   help="leave this material out of bases, library and priors (repeatable)")
    p.add_argument("--workers", type=int, default=2, help="worker processes (default 2)")
    p.add_argument("--fits-from", default=None, metavar="MODEL",
                   help="reuse the full per-material fits stored in this model file")
    p.add_argument("--gmm", default=GMM, metavar="STRUCTURE",
                   help="the GMM prior's structure: 'bic' or 'full|diag|tied:components:reg' (default %s)" % GMM)
    p.add_argument("--fit-anchor", type=float, default=0.0, metavar="W",
                   help="pull each full fit's control values towards their lobe's anchor with weight W "
                        "(FitObjective.anchor_weight; default 0, off; the twenty-sixth session tried 0.003)")
    p.add_argument("--fit-anchor-lobes", type=int, nargs="+", default=[0, 1, 2], metavar="LOBE",
                   help="the lobes --fit-anchor holds (default 0 1 2)")
    p.add_argument("--complete-unseen", nargs="*", default=None, metavar="LOBE:CURVE",
                   help="functional PCA on the fits' control values completed where the measurements do not "
                        "see them (a faded lobe's gamma, a flat lobe's gamma), not where the fits left them; "
                        "on every curve, or only on those named, e.g. 0:gamma (lobe 0 the broadest)")
    p.add_argument("--force", action="store_true", help="replace an existing model file")
    p.set_defaults(func=cmd_build_model)

    p = sub.add_parser("recover", help="recover reflectance and illumination from one image")
    p.add_argument("--scene", default=None,
                   help="Mitsuba scene XML (camera, object with a dsbrdf BSDF, light); or use --sphere")
    p.add_argument("--sphere", action="store_true",
                   help="the image is a photograph of a sphere: build the scene from its outline (no XML)")
    p.add_argument("--light", default=None, choices=LIGHTS,
                   help="with --sphere: the kind of light to recover (default envmap)")
    p.add_argument("--fov", default=None, type=float,
                   help="with --sphere: horizontal field of view in degrees (default: orthographic camera)")
    p.add_argument("--image", required=True, help="observed linear HDR image (EXR/HDR), film-sized")
    p.add_argument("--srgb", action="store_true", help="the image is 8-bit sRGB (PNG/JPEG): linearise it")
    p.add_argument("--mask", default=None, help="optional mask image (white = use)")
    p.add_argument("--out", required=True, help="result directory")
    _config_arguments(p, "benchmarked")
    p.add_argument("--force", action="store_true", help="replace an earlier result directory")
    p.set_defaults(func=cmd_recover)

    p = sub.add_parser("relight", help="render a recovered material under a new map or in your own scene")
    p.add_argument("material", help="material.json (from recover) or a library material name")
    p.add_argument("--envmap", default=None, help="lat-long HDR/EXR illumination map")
    p.add_argument("--shape", default="sphere", help="with --envmap: sphere, torus or a .ply/.obj mesh")
    p.add_argument("--scene", default=None, help="your scene XML instead: the material goes on --shape-id")
    p.add_argument("--shape-id", default=None, help="with --scene: id of the shape that gets the material")
    p.add_argument("--out", required=True, help="output EXR (a PNG is written beside it)")
    p.add_argument("--res", type=int, default=256, help="with --envmap: image size")
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--force", action="store_true", help="replace an existing output file")
    p.set_defaults(func=cmd_relight)

    args = ap.parse_args(argv)
    try:
        _setup(args.variant)
        args.func(args)
    except (MiDsbrdfError, OSError) as e:
        print("mi-dsbrdf: %s" % e, file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
