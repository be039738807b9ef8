"""``mi-dsbrdf`` command line: argument parsing only; the work is in the library."""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import os
import re
import signal
import sys

import mitsuba as mi
from tqdm import tqdm

from mi_dsbrdf.app.batch import FAILED, recover_many
from mi_dsbrdf.app.demo import run
from mi_dsbrdf.app.photo import LIGHTS, photo_scene
from mi_dsbrdf.app.recover import recover_files
from mi_dsbrdf.app.render import relight, render_to_files
from mi_dsbrdf.app.scenes import scene_path
from mi_dsbrdf.config import PRESETS, Config, field_docs
from mi_dsbrdf.backend import SUPPORTED_VARIANTS, check_llvm
from mi_dsbrdf.errors import ConfigError, InputError, MiDsbrdfError, VariantError
from mi_dsbrdf.model.build import GMM, build_model
from mi_dsbrdf.model.model_file import SHIPPED

#: the shorter spellings ``recover`` and ``demo`` also accept for a setting: {field: alias}
ALIASES = {"max_rounds": "--rounds", "block_iters": "--iters"}
#: the epilog of ``recover`` and ``demo``: the aliases
ALIAS_TABLE = "aliases:\n" + "".join("  %-10s %s\n" % (a, "--" + f.replace("_", "-")) for f, a in ALIASES.items())


def _setup(variant):
    """Switch to ``variant`` (the package's import selected llvm_ad_rgb and
    registered the plugins; they re-register on a switch)."""
    if variant:
        if variant not in SUPPORTED_VARIANTS:
            raise VariantError("--variant %s: give one of %s (the JIT, RGB, differentiable variants this "
                               "Mitsuba build has)" % (variant, ", ".join(v for v in SUPPORTED_VARIANTS
                                                                         if v in mi.variants())))
        if variant not in mi.variants():
            raise VariantError("--variant %s: this Mitsuba build has no such variant" % variant)
        mi.set_variant(variant)
        if variant.startswith("llvm"):
            check_llvm()


def _config(args):
    """The named preset with the command line's overrides (validated). A
    ConfigError names the option as typed (``--rounds``, ``--max-rounds``)."""
    overrides = {f.name: getattr(args, f.name) for f in dataclasses.fields(Config) if hasattr(args, f.name)}
    if getattr(args, "no_second_route", False):
        overrides["second_route_highlight"] = None
    try:
        cfg = dataclasses.replace(PRESETS[args.preset], **overrides)
    except ConfigError as e:
        if e.field is None or not str(e).startswith(e.field):
            raise
        typed = getattr(args, "typed_options", {}).get(e.field) or "--" + e.field.replace("_", "-")
        raise ConfigError(typed + str(e)[len(e.field):], field=e.field) from None
    return cfg.with_colour_split(False) if getattr(args, "no_colour_split", False) else cfg


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
    for flag in r["flags"]:
        print("  warning: " + flag)


def cmd_build_model(args):
    out = args.out or SHIPPED
    if os.path.exists(out) and not args.force:
        raise InputError("%s exists; pass --force to replace it" % out)
    a = build_model(args.merl, out, k=args.k, exclude=args.exclude, workers=args.workers,
                    fits_from=args.fits_from, gmm=args.gmm)
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


def _or_none(kind):
    """An argparse type: ``kind`` of the text, or None for "none"."""
    def parse(text):
        return None if text.strip().lower() == "none" else kind(text)
    parse.__name__ = kind.__name__ + " or none"
    return parse


#: argparse type and metavar of each Config field's annotation
_KINDS = {"tuple": (_map_size, "HxW"), "int": (int, "N"), "float": (float, "X"),
          "int | None": (_or_none(int), "N|none"), "float | None": (_or_none(float), "X|none")}


def _shown(value) -> str:
    """A Config value as the command line spells it."""
    if value is None:
        return "none"
    if isinstance(value, tuple):
        return "x".join(map(str, value))
    return "%g" % value if isinstance(value, float) else str(value)


class _Setting(argparse.Action):
    """Stores a Config field's value and the option string it was given by (for
    error messages: ``--rounds 0`` is named ``--rounds``)."""

    def __call__(self, parser, namespace, values, option_string=None):
        setattr(namespace, self.dest, values)
        namespace.typed_options = dict(getattr(namespace, "typed_options", {}), **{self.dest: option_string})


def cmd_recover(args):
    if (args.scene is None) == (not args.sphere):
        raise InputError("give --scene SCENE.xml, or --sphere for a photograph of a sphere (no scene file)")
    if not args.sphere and (args.light is not None or args.fov is not None):
        raise InputError("--light and --fov describe the scene --sphere builds; a --scene brings its own")
    config = _config(args)                          # bad settings fail before any work
    scene = args.scene
    if args.sphere:
        scene, circle = photo_scene(args.image, args.mask, light=args.light or "envmap", fov=args.fov,
                                    srgb=args.srgb)
        print("  sphere: centre (%.1f, %.1f) px, radius %.1f px, %s camera, %s light" % (
            circle + ("orthographic" if args.fov is None else "perspective (fov %g)" % args.fov,
                      args.light or "envmap")))
    result = recover_files(scene, args.image, args.out, mask_file=args.mask, force=args.force, config=config,
                           srgb=args.srgb, white_level=args.white_level)   # prints what the scene needs, the passes
    if result.log.get("unseen_texels"):
        print("  %d illumination texels are seen by no pixel: left black (see illumination.png)"
              % result.log["unseen_texels"])
    for flag in result.log.get("flags", []):
        print("  warning: " + flag)
    print("recovered in %.1f s -> %s" % (result.seconds, args.out))


def cmd_batch(args):
    """Returns the exit status: 0 if every row is recovered, else 1."""
    config = _config(args)                          # bad settings fail before any work
    args.interrupted = "the finished rows are kept in %s (a rerun does the rest)" % args.out
    counts = {}
    for name, status, reason in recover_many(args.manifest, args.out, workers=args.workers, config=config,
                                             srgb=args.srgb, white_level=args.white_level, progress=True,
                                             scheduler=args.scheduler):
        counts[status] = counts.get(status, 0) + 1
        if status == FAILED:                        # the rows failing the checks first, together
            tqdm.write("  %s: %s" % (name, reason), file=sys.stderr)
    print("batch: %d recovered, %d complete before, %d failed -> %s" % (
        counts.get("done", 0), counts.get("skipped", 0), counts.get(FAILED, 0),
        os.path.join(args.out, "summary.html")))
    return 1 if counts.get(FAILED) else 0


def cmd_relight(args):
    r = relight(args.material, args.out, envmap=args.envmap, shape=args.shape, scene=args.scene,
                shape_id=args.shape_id, res=args.res, spp=args.spp, force=args.force, samples=args.samples)
    print("relit in %.1f s -> %s, %s" % (r["seconds"], r["exr"], r["png"]))
    if "std_exr" in r:
        print("the posterior's spread over %d samples -> %s, %s" % (args.samples, r["std_exr"], r["std_png"]))


def _config_arguments(p, preset):
    """--preset and one option per Config field, named as the field with dashes
    (:data:`ALIASES` too); a field left out keeps the preset's value."""
    g = p.add_argument_group("inference settings (the fields of mi_dsbrdf.Config)")
    g.add_argument("--preset", default=preset, choices=list(PRESETS),
                   help="the settings the options below change: %s (default %s)" % (", ".join(
                       "%s (map %s)" % (n, _shown(c.map_size)) for n, c in PRESETS.items()), preset))
    docs, c = field_docs(), PRESETS[preset]
    fields = {f.name for f in dataclasses.fields(Config)}

    def option(m):            # ``field`` -> --field, other ``code`` -> code
        return "--" + m.group(1).replace("_", "-") if m.group(1) in fields else m.group(1)
    for f in dataclasses.fields(Config):
        kind, metavar = _KINDS[str(f.type)]
        text = re.sub(r"``([^`]*)``", option, docs.get(f.name, "")).replace("%", "%%")
        names = ["--" + f.name.replace("_", "-")] + ([ALIASES[f.name]] if f.name in ALIASES else [])
        g.add_argument(*names, dest=f.name, type=kind, metavar=metavar, action=_Setting, default=argparse.SUPPRESS,
                       help="%s (%s preset: %s)" % (text, preset, _shown(getattr(c, f.name))))
    g.add_argument("--no-second-route", action="store_true", help="the same as --second-route-highlight none")
    g.add_argument("--no-colour-split", action="store_true",
                   help="leave the image's colour in the material: --w-chromaticity 0 --w-light-colour 0")


def parser() -> argparse.ArgumentParser:
    """The ``mi-dsbrdf`` argument parser (each command's function in ``func``)."""
    ap = argparse.ArgumentParser(prog="mi-dsbrdf", description=__doc__)
    ap.add_argument("--variant", default=None, help="Mitsuba variant (default llvm_ad_rgb)")
    sub = ap.add_subparsers(dest="command", required=True)

    p = sub.add_parser("render", help="render a scene XML to EXR + PNG")
    p.add_argument("scene", help="scene XML path or shipped scene name")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--spp", type=int, default=None, help="samples per pixel, 1 to 16384 (default: the scene's own)")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="override a scene <default> (repeatable)")
    p.add_argument("--force", action="store_true", help="replace earlier renders of the scene in --out")
    p.set_defaults(func=cmd_render)

    p = sub.add_parser("demo", help="recover a shipped material under a generated sky, and report (main job)",
                       epilog=ALIAS_TABLE, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="out/demo")
    p.add_argument("--material", default="gold-metallic-paint", help="library material of the observed sphere")
    p.add_argument("--res", type=int, default=64, help="image size (default 64)")
    _config_arguments(p, "fast")
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
    p.add_argument("--force", action="store_true", help="replace an existing model file")
    p.set_defaults(func=cmd_build_model)

    p = sub.add_parser("recover", help="recover reflectance and illumination from one image",
                       epilog=ALIAS_TABLE, formatter_class=argparse.RawDescriptionHelpFormatter)
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
    p.add_argument("--white-level", default=None, type=float, nargs="+", metavar="LEVEL",
                   help="the camera's white level in the image's linear units, one value or three (R G B): pixels "
                        "with a channel at or above it are left out as clipped (default: plateaus of each "
                        "channel's maximum)")
    p.add_argument("--out", required=True, help="result directory")
    _config_arguments(p, "default")
    p.add_argument("--force", action="store_true", help="replace an earlier result directory")
    p.set_defaults(func=cmd_recover)

    p = sub.add_parser("batch", help="recover many images listed in a manifest, one result folder each",
                       epilog=ALIAS_TABLE, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("manifest", help="CSV (with a header) or JSON list of rows: image, and scene or sphere (true), "
                                    "optional mask, light, fov (with sphere) and name (default the image's stem); "
                                    "paths relative to the manifest's folder")
    p.add_argument("--out", required=True, help="output folder: OUT/<name>/ per row, OUT/summary.csv, summary.html")
    p.add_argument("--workers", type=int, default=None,
                   help="worker processes (default: the number of cores, %d)" % (os.cpu_count() or 1))
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run the rows on the Dask cluster of this scheduler (tcp://HOST:PORT) instead; its "
                        "workers must see the same paths and run one task each (dask worker --nthreads 1)")
    p.add_argument("--srgb", action="store_true", help="the images are 8-bit sRGB (PNG/JPEG): linearise them")
    p.add_argument("--white-level", default=None, type=float, nargs="+", metavar="LEVEL",
                   help="the camera's white level of every image, one value or three (R G B) (see recover)")
    _config_arguments(p, "default")
    p.set_defaults(func=cmd_batch)

    p = sub.add_parser("relight", help="render a recovered material under a new map or in your own scene")
    p.add_argument("material", help="material.json (from recover) or a library material name")
    p.add_argument("--envmap", default=None, help="lat-long HDR/EXR illumination map")
    p.add_argument("--shape", default="sphere", help="with --envmap: sphere, torus or a .ply/.obj mesh")
    p.add_argument("--scene", default=None, help="your scene XML instead: the material goes on --shape-id")
    p.add_argument("--shape-id", default=None, help="with --scene: id of the shape that gets the material")
    p.add_argument("--out", required=True, help="output EXR (a PNG is written beside it)")
    p.add_argument("--res", type=int, default=256, help="with --envmap: image size")
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--samples", type=int, default=0, metavar="N",
                   help="also render N materials drawn from a recovered material's posterior, and write their "
                        "per-pixel standard deviation as <out>_std.exr (and .png)")
    p.add_argument("--force", action="store_true", help="replace an existing output file")
    p.set_defaults(func=cmd_relight)
    return ap


#: the signals that stop a command as Ctrl-C does (SIGINT): a KeyboardInterrupt,
#: which removes what the command was writing
STOP_SIGNALS = (signal.SIGTERM, signal.SIGHUP)


@contextlib.contextmanager
def _stopped_by_signals(received):
    """SIGTERM and SIGHUP raise KeyboardInterrupt while the block runs (their
    numbers appended to ``received``); the handlers are restored after. Outside
    the main thread, where handlers cannot be set, nothing changes."""
    def stop(signum, frame):
        received.append(signum)
        raise KeyboardInterrupt
    previous = {}
    try:
        for sig in STOP_SIGNALS:
            previous[sig] = signal.signal(sig, stop)
    except ValueError:              # not the main thread
        pass
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def main(argv=None):
    """Run the command ``argv`` (default: the process's arguments); returns the exit
    status: 0, 1 for an error (one line on stderr), 128 + the signal's number for
    an interruption (Ctrl-C, SIGTERM, SIGHUP), which writes nothing."""
    args = parser().parse_args(argv)
    received = []
    try:
        with _stopped_by_signals(received):
            _setup(args.variant)
            status = args.func(args)
    except KeyboardInterrupt:
        print("mi-dsbrdf: interrupted; %s" % getattr(args, "interrupted", "nothing written"), file=sys.stderr)
        return 128 + (received[0] if received else signal.SIGINT)
    except (MiDsbrdfError, OSError) as e:
        print("mi-dsbrdf: %s" % e, file=sys.stderr)
        return 1
    return status or 0


if __name__ == "__main__":
    sys.exit(main())
