"""A batch's manifest (:mod:`mi_dsbrdf.app.batch`): one image per row, as a CSV
file with a header or a JSON list of objects, with the fields

    image    the image file (required)
    mask     an optional mask file
    scene    a scene XML, or
    sphere   true: the image is a photograph of a sphere (the scene is built from
             its outline, :mod:`mi_dsbrdf.app.photo`), with the optional
             ``light`` (envmap, directional, point) and ``fov`` (degrees)
    name     the row's result folder under the output folder (default: the
             image's file name without its extension); names are unique

Paths are relative to the manifest's folder. :func:`check_rows` checks every row
(its files read, its fields parsed) before any work, giving a one-line reason
for each row that fails.
"""
from __future__ import annotations

import csv
import dataclasses
import json
import os

from mi_dsbrdf.app.batch_summary import one_line_reason
from mi_dsbrdf.app.photo import LIGHTS, photo_scene
from mi_dsbrdf.app.recover import load_inputs
from mi_dsbrdf.errors import InputError, MiDsbrdfError

#: the fields a manifest row may have
FIELDS = ("name", "image", "mask", "scene", "sphere", "light", "fov")


@dataclasses.dataclass(frozen=True)
class Row:
    """One image of a batch: absolute paths and the scene's description.

    Attributes
    ----------
    name : the result folder's name under the output folder
    image : the image file; mask : the mask file or None
    scene : the scene XML, or None for a photograph of a sphere (``sphere``)
    light : with ``sphere``: envmap, directional or point; fov : with ``sphere``:
        the horizontal field of view in degrees, or None (orthographic)
    """
    name: str
    image: str
    mask: str | None = None
    scene: str | None = None
    light: str | None = None
    fov: float | None = None

    @property
    def sphere(self) -> bool:
        return self.scene is None


def read_manifest(path) -> list:
    """The rows of the manifest ``path`` (CSV with a header, or a JSON list of
    objects) as dicts of their non-empty fields, paths still as written.
    InputError (one line) if it does not read, has no ``image`` field or unknown
    fields."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise InputError("manifest %s does not exist" % path)
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:          # a spreadsheet's BOM ignored
            text = f.read()
    except (OSError, UnicodeDecodeError) as e:
        raise InputError("manifest %s does not read: %s" % (path, e)) from None
    if path.lower().endswith(".json"):
        try:
            rows = json.loads(text)
        except json.JSONDecodeError as e:
            raise InputError("manifest %s is not valid JSON: %s" % (path, e)) from None
        if not isinstance(rows, list) or not all(isinstance(r, dict) for r in rows):
            raise InputError("manifest %s: give a JSON list of objects, one per image" % path)
        fields = {k for r in rows for k in r}
    else:
        reader = csv.DictReader(text.splitlines(), skipinitialspace=True)
        reader.fieldnames = [f.strip() for f in reader.fieldnames or ()]       # " image , scene " is image, scene
        fields = set(reader.fieldnames)
        rows = [{k: v.strip() if isinstance(v, str) else v for k, v in r.items() if k is not None} for r in reader]
        if any(None in r for r in csv.DictReader(text.splitlines())):
            raise InputError("manifest %s: a row has more values than the header has columns" % path)
    if not rows:
        raise InputError("manifest %s has no rows" % path)
    if "image" not in fields:
        raise InputError("manifest %s has no \"image\" column: give a header with image and scene (or sphere)"
                         % path)
    unknown = sorted(fields - set(FIELDS))
    if unknown:
        raise InputError("manifest %s: unknown column%s %s (known: %s)" % (
            path, "s" if len(unknown) > 1 else "", ", ".join(unknown), ", ".join(FIELDS)))
    return [{k: v for k, v in r.items() if v not in (None, "")} for r in rows]


def _truth(value, what) -> bool:
    if isinstance(value, bool):
        return value
    text = str(value).strip().lower()
    if text in ("true", "yes", "1"):
        return True
    if text in ("false", "no", "0", ""):
        return False
    raise InputError("%s %r: give true or false" % (what, value))


def parse_row(fields: dict, base=".") -> Row:
    """A :class:`Row` of a manifest row's ``fields`` (paths relative to ``base``);
    InputError (one line) for a bad field or a missing file."""
    def path(key):
        value = fields.get(key)
        if value is None:
            return None
        if not isinstance(value, (str, os.PathLike)):
            raise InputError("%s %r: give a file path" % (key, value))
        p = os.path.normpath(os.path.join(base, os.fspath(value)))
        if not os.path.isfile(p):
            raise InputError("%s file %s does not exist" % (key, p))
        return p
    if fields.get("image") is None:
        raise InputError("no image")
    image, mask, scene = path("image"), path("mask"), path("scene")
    sphere = _truth(fields.get("sphere", False), "sphere")
    if (scene is None) == (not sphere):
        raise InputError("give a scene file, or sphere true for a photograph of a sphere (not both)")
    light, fov = fields.get("light"), fields.get("fov")
    if scene is not None and (light is not None or fov is not None):
        raise InputError("light and fov describe the scene sphere builds; a scene file brings its own")
    if light is not None and light not in LIGHTS:
        raise InputError("light %r: give one of %s" % (light, ", ".join(LIGHTS)))
    if fov is not None:
        try:
            fov = float(fov)
        except (TypeError, ValueError):
            raise InputError("fov %r: give degrees, a number in (0, 180)" % (fov,)) from None
        if not 0 < fov < 180:
            raise InputError("fov %g: give degrees in (0, 180)" % fov)
    name = fields.get("name")
    name = os.path.splitext(os.path.basename(image))[0] if name is None else str(name)
    if name in (".", "..") or os.sep in name or (os.altsep and os.altsep in name):
        raise InputError("name %r: give a folder name of its own (not . or .., no path separators)" % name)
    return Row(name=name, image=image, mask=mask, scene=scene, light=light or ("envmap" if sphere else None),
               fov=fov)


def _name_of(fields, i) -> str:
    """A row's name for messages before it is parsed: its name, else its image's
    stem, else its number."""
    if fields.get("name") is not None:
        return str(fields["name"])
    if isinstance(fields.get("image"), str):
        return os.path.splitext(os.path.basename(fields["image"]))[0]
    return "row %d" % (i + 1)


def check_rows(rows, base=".", srgb=False) -> tuple:
    """(the good :class:`Row` s, {name: one-line reason} of the rows that fail the
    checks). ``rows``: dicts (manifest rows, paths relative to ``base``) or Rows.
    Each row's image and mask are read and checked
    (:func:`~mi_dsbrdf.app.recover.load_inputs`), and a sphere's outline fitted
    (:func:`~mi_dsbrdf.app.photo.photo_scene`). InputError if two rows share a
    name."""
    names = [r.name if isinstance(r, Row) else _name_of(r, i) for i, r in enumerate(rows)]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise InputError("manifest rows share the name%s %s: give each row a unique name column"
                         % ("s" if len(dup) > 1 else "", ", ".join(dup)))
    good, bad = [], {}
    for fields, name in zip(rows, names):
        try:
            row = fields if isinstance(fields, Row) else parse_row(fields, base)
            if row.sphere:                          # the outline fits (reads the image and mask)
                photo_scene(row.image, row.mask, light=row.light or "envmap", fov=row.fov, srgb=srgb)
            else:
                load_inputs(row.image, row.mask, srgb)
        except MiDsbrdfError as e:
            bad[name] = one_line_reason(e)
            continue
        good.append(row)
    return good, bad
