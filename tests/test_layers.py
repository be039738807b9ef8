"""The package's layers import one way: a module imports only from its own layer
or lower ones, at module level or inside a function alike.

    base (config, errors, backend, lm) < brdf < model, plugins < inference < evaluation < app

The package itself (``mi_dsbrdf/__init__.py``, the public API) sits with app.
"""
import ast
import os

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
#: layer of each part of the package, lowest first
LAYERS = {"base": 0, "brdf": 1, "model": 2, "plugins": 2, "inference": 3, "evaluation": 4, "app": 5}
#: the shared base modules, which any layer may import
BASE = ("config", "errors", "backend", "lm")
#: (importer, imported): the only imports of a higher layer, and why
ALLOWED = {("mi_dsbrdf.backend", "mi_dsbrdf.plugins"):
           "the backend registers the plugins on import and whenever the variant changes"}


def layer(module):
    """The layer of a module of the package, None for one outside it."""
    parts = module.split(".")
    if parts[0] != "mi_dsbrdf":
        return None
    if len(parts) == 1:
        return "app"                        # the package: its public API re-exports app's
    if parts[1] in BASE:
        return "base"
    if parts[1] in LAYERS:
        return parts[1]
    raise AssertionError("%s belongs to no layer: add it to tests/test_layers.py" % module)


def package_modules(root=ROOT) -> dict:
    """{module name: file} of mi_dsbrdf/ and plugins/ (installed as mi_dsbrdf.plugins)."""
    out = {}
    for folder, package in (("mi_dsbrdf", "mi_dsbrdf"), ("plugins", "mi_dsbrdf.plugins")):
        base = os.path.join(root, folder)
        for d, _, files in os.walk(base):
            for f in files:
                if f.endswith(".py"):
                    rel = os.path.relpath(os.path.join(d, f), base)[:-3].split(os.sep)
                    if rel[-1] == "__init__":
                        rel = rel[:-1]
                    out[".".join([package] + rel)] = os.path.join(d, f)
    return out


def imported(module, path, modules) -> list:
    """(line, module) of every import in a file: import statements at any depth
    (in functions too) and ``importlib.import_module``/``__import__`` of a literal."""
    is_package = os.path.basename(path) == "__init__.py"
    here = module if is_package else module.rsplit(".", 1)[0]
    out = []
    for node in ast.walk(ast.parse(open(path).read(), path)):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:                                          # relative: from .x import y
                parts = here.split(".")
                base = ".".join(parts[:len(parts) - node.level + 1] + ([node.module] if node.module else []))
            else:
                base = node.module
            for a in node.names:                                    # a submodule, or a name of base
                out.append((node.lineno, base + "." + a.name if base + "." + a.name in modules else base))
        elif isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant) \
                and isinstance(node.args[0].value, str):
            f = node.func
            name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", None)
            if name in ("import_module", "__import__"):
                out.append((node.lineno, node.args[0].value))
    return sorted(set(out))


def violations(root=ROOT) -> list:
    modules = package_modules(root)
    bad = []
    for module, path in sorted(modules.items()):
        mine = layer(module)
        for line, target in imported(module, path, modules):
            theirs = layer(target)
            if theirs is None or LAYERS[theirs] <= LAYERS[mine]:
                continue
            if any(module == a and (target == b or target.startswith(b + ".")) for a, b in ALLOWED):
                continue
            bad.append("%s:%d (%s) imports %s (%s)" % (os.path.relpath(path, root), line, mine, target, theirs))
    return bad


def test_no_layer_imports_a_higher_one():
    assert violations() == []


def test_a_higher_import_is_found_at_any_depth(tmp_path):
    """The check fails on a lower layer importing a higher one, in a function or
    relative, and passes the same imports the other way."""
    for folder in ("mi_dsbrdf/brdf", "mi_dsbrdf/app", "plugins"):
        os.makedirs(tmp_path / folder)
        (tmp_path / folder / "__init__.py").write_text("")
    (tmp_path / "mi_dsbrdf" / "__init__.py").write_text("")
    (tmp_path / "mi_dsbrdf" / "errors.py").write_text("")
    (tmp_path / "mi_dsbrdf" / "brdf" / "low.py").write_text(
        "from mi_dsbrdf.errors import X\n\ndef f():\n    from mi_dsbrdf.app import high\n")
    (tmp_path / "mi_dsbrdf" / "app" / "high.py").write_text("from mi_dsbrdf.brdf import low\nimport mi_dsbrdf\n")
    (tmp_path / "plugins" / "p.py").write_text("from .q import y\nimport importlib\n"
                                               "importlib.import_module('mi_dsbrdf.app.high')\n")
    (tmp_path / "plugins" / "q.py").write_text("import mi_dsbrdf.errors\n")
    assert violations(str(tmp_path)) == ["mi_dsbrdf/brdf/low.py:4 (brdf) imports mi_dsbrdf.app.high (app)",
                                         "plugins/p.py:3 (plugins) imports mi_dsbrdf.app.high (app)"]
