"""The house's layers: no import runs against them.

A module may import from its own layer or from a lower one, never from a
higher one (docs/design.md draws the layers).  Every ``import`` and
``from ... import`` statement of every module is read, including those
inside functions (the lazy imports that keep start-up short), so a lazy
arrow against the layers fails here as much as one at the top of a file.
Each module is then imported, so the table below cannot hold a name that no
longer exists.
"""
from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"

#: layer of each package or module prefix, lowest first; the longest prefix wins
LAYERS = {
    "multibody": 0, "fem": 0, "couplers": 0,
    "cosim.errors": 1,
    # the release string, assigned in the package's __init__ before it imports anything
    "cosim.__version__": 1,
    "cosim.io": 2,
    "cosim.core": 3,
    "cosim.sides": 4,
    "cosim.scene": 5,
    "cosim.studies": 6,
    "cosim.cli": 7, "cosim.plot": 7, "cosim": 7,
}
MODEL_PACKAGES = ("multibody", "fem", "couplers")


def _modules():
    for path in sorted(SRC.rglob("*.py")):
        parts = path.relative_to(SRC).with_suffix("").parts
        if parts[0] not in ("cosim", *MODEL_PACKAGES):
            continue
        is_package = parts[-1] == "__init__"
        name = ".".join(parts[:-1] if is_package else parts)
        yield name, path, is_package


MODULES = list(_modules())


def _layer(module: str) -> int | None:
    best = None
    for prefix, layer in LAYERS.items():
        if module == prefix or module.startswith(prefix + "."):
            if best is None or len(prefix) > len(best[0]):
                best = (prefix, layer)
    return None if best is None else best[1]


def _imports(name: str, path: Path, is_package: bool):
    """(line, imported module) for each import of our packages in a file,
    relative imports resolved."""
    package = name if is_package else name.rpartition(".")[0]
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - node.level + 1]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module
            for alias in node.names:
                # ``from cosim.core import preflight`` imports cosim.core.preflight
                yield node.lineno, f"{module}.{alias.name}"


def _owner(imported: str) -> str | None:
    root = imported.split(".")[0]
    return root if root in ("cosim", *MODEL_PACKAGES) else None


@pytest.mark.parametrize("name,path,is_package", MODULES, ids=[m[0] for m in MODULES])
def test_no_import_runs_against_the_layers(name, path, is_package):
    own = _layer(name)
    assert own is not None, f"{name} has no layer in LAYERS"
    against = []
    for line, imported in _imports(name, path, is_package):
        if _owner(imported) is None:
            continue
        layer = _layer(imported)
        if name.split(".")[0] in MODEL_PACKAGES and imported.split(".")[0] != name.split(".")[0]:
            against.append(f"line {line}: {imported} (a model package imports only itself)")
        elif layer is not None and layer > own:
            against.append(f"line {line}: {imported} (layer {layer} above {own})")
    assert not against, f"{path.relative_to(SRC)} imports against the layers:\n" + "\n".join(against)


@pytest.mark.parametrize("name", [m[0] for m in MODULES])
def test_every_module_imports(name):
    importlib.import_module(name)


def test_the_check_sees_lazy_arrows(tmp_path):
    """An import inside a function counts, and a relative one is resolved:
    the check would fail a core module that imports the scene loader lazily."""
    path = tmp_path / "guard.py"
    path.write_text("def f():\n    from ..scene.load import load_scene\n")
    imports = list(_imports("cosim.core.guard", path, False))
    assert imports == [(2, "cosim.scene.load.load_scene")]
    assert _layer(imports[0][1]) > _layer("cosim.core.guard")
