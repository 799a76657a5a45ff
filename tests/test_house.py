"""The house's sizes and doors: no module of cosim or the model packages
grows past 500 lines, no compiled kernel past 800 (split it by concern instead),
none imports itself again through others, and the console script named in
pyproject.toml is the command line's ``main``."""
from __future__ import annotations

import ast
import importlib
import re
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src"
#: the folders whose modules are held to the limit: every one under src/
HELD = ("cosim", "multibody", "fem", "couplers")
MAX_LINES = 500


def _held_modules():
    for folder in HELD:
        yield from sorted((SRC / folder).rglob("*.py"))


def test_every_python_module_under_src_is_held():
    """No package under src/ escapes the limit below."""
    packages = {p.relative_to(SRC).parts[0] for p in SRC.rglob("*.py")}
    assert packages <= set(HELD), sorted(packages - set(HELD))


@pytest.mark.parametrize("path", list(_held_modules()), ids=lambda p: str(p.relative_to(SRC)))
def test_no_module_over_about_500_lines(path):
    n = len(path.read_text().splitlines())
    assert n <= MAX_LINES, f"{path.relative_to(SRC)} has {n} lines (> {MAX_LINES}): split it by concern"


#: a compiled kernel (``.pyx``) is held to its own limit: past it, split by
#: concept into modules that call one another in C through a ``.pxd``
MAX_KERNEL_LINES = 800


def _held_kernels():
    for folder in HELD:
        yield from sorted((SRC / folder).rglob("*.pyx"))


def test_the_kernels_are_held():
    """The limit below sees the kernels (a moved folder would leave it nothing to hold)."""
    names = {p.name for p in _held_kernels()}
    assert {"_structure_step.pyx", "_multibody_step.pyx"} <= names, sorted(names)


@pytest.mark.parametrize("path", list(_held_kernels()), ids=lambda p: str(p.relative_to(SRC)))
def test_no_kernel_over_800_lines(path):
    n = len(path.read_text().splitlines())
    assert n <= MAX_KERNEL_LINES, (f"{path.relative_to(SRC)} has {n} lines (> {MAX_KERNEL_LINES}):"
                                   " split it by concept, the pieces sharing a .pxd")


def test_the_console_script_is_the_command_lines_main():
    """The console script and ``python -m cosim.cli`` are :func:`cosim.cli.console`,
    :func:`cosim.cli.main` in a process of its own (``tests/test_console.py``)."""
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    module, _, name = scripts["cosim"].partition(":")
    cli = importlib.import_module("cosim.cli")
    assert getattr(importlib.import_module(module), name) is cli.console
    assert importlib.import_module("cosim.cli.__main__").console is cli.console


# ------------------------------------------------------------ import circles
#: the packages whose modules may not import one another in a circle
PACKAGES = ("cosim", "multibody", "fem", "couplers")


def _module_files(src: Path, packages=PACKAGES) -> dict:
    """Module name -> file, for every ``.py`` and ``.pyx`` of ``packages``."""
    out = {}
    for pkg in packages:
        for path in sorted((src / pkg).rglob("*.py")) + sorted((src / pkg).rglob("*.pyx")):
            parts = list(path.relative_to(src).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            out[".".join(parts)] = path
    return out


def _statements(path: Path):
    """``(module, names, level)`` of each import statement of ``path``, at
    module level or inside a function or class alike, but not under ``if
    TYPE_CHECKING:`` (never run).  A ``.pyx`` file's Python imports and
    ``cimport`` lines are read with a pattern (it is not Python's syntax)."""
    text = path.read_text()
    if path.suffix == ".pyx":
        pattern = r"^\s*from\s+([\w.]+)\s+c?import\s+([\w, ]+)|^\s*c?import\s+([\w.]+)"
        for m in re.finditer(pattern, text, re.M):
            if m.group(1):
                yield m.group(1), [n.strip() for n in m.group(2).split(",")], 0
            else:
                yield m.group(3), [], 0
        return
    tree = ast.parse(text)
    unrun = {id(n) for node in ast.walk(tree)
             if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)
             for sub in node.body for n in ast.walk(sub)}
    for node in ast.walk(tree):
        if id(node) in unrun:
            continue
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, [], 0
        elif isinstance(node, ast.ImportFrom):
            yield node.module or "", [a.name for a in node.names], node.level


def _import_graph(mods: dict) -> dict:
    """Module -> the modules of ``mods`` its statements import.

    ``from P import N`` imports ``P.N`` when that is a module, else ``P``;
    ``import P.Q`` imports ``P.Q``; a name that is no module of ours counts
    as its nearest enclosing module.  A package's ``__init__`` is not counted
    as imported by a statement that names one of its submodules (Python runs
    it first, but it is the package's door, not a dependency of the
    importer)."""
    def known(name):
        while name and name not in mods:
            name = name.rpartition(".")[0]
        return name

    graph = {}
    for name, path in mods.items():
        package = name if path.stem == "__init__" else name.rpartition(".")[0]
        deps = set()
        for target, names, level in _statements(path):
            if level:
                base = package.split(".")[:len(package.split(".")) - (level - 1)]
                target = ".".join(base + ([target] if target else []))
            for n in names or [None]:
                sub = f"{target}.{n}" if n else target
                deps.add(sub if sub in mods else known(target))
        graph[name] = deps - {name, ""}
    return graph


def _circles(graph: dict) -> list:
    """The strongly connected components of ``graph`` with more than one
    module (Tarjan's algorithm), each sorted."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while not comp or comp[-1] != v:
                comp.append(stack.pop())
                on.discard(comp[-1])
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_import_circle_in_our_packages():
    """No module of cosim, multibody, fem or couplers imports itself again
    through others.

    What counts: every import statement a module holds, ``import x`` and
    ``from x import y`` (relative ones too), at module level and inside a
    function or method alike: an import deferred into a function that closes
    a circle is still a circle (the two modules still need each other; the
    deferral only hides the order in which they load).  The ``.pyx`` kernels'
    ``import`` and ``cimport`` lines count as well.  What does not count:
    imports under ``if TYPE_CHECKING:`` (never run), and imports by a name
    held as data and resolved at run time (a registry's ``"module:Class"``
    entries, a package's lazy ``__getattr__``, the plug-in groups' registries
    in :mod:`cosim.core.plugins`): they are how a low module names a higher
    one without depending on it."""
    circles = _circles(_import_graph(_module_files(SRC)))
    assert not circles, "import circles: " + "; ".join(" <-> ".join(c) for c in circles)


def test_the_circle_finder_finds_a_deferred_circle(tmp_path):
    """The check above could fail: a circle closed by an import inside a
    function, one through a relative import and a ``.pyx`` kernel, are each
    found; a ``TYPE_CHECKING`` import and a lower module both import are not
    circles."""
    pkg = tmp_path / "cosim"
    (pkg / "core").mkdir(parents=True)
    files = {
        "__init__.py": "",
        "low.py": "X = 1\n",
        "a.py": "from cosim.low import X\nfrom cosim import b\n",
        "b.py": "def f():\n    from cosim.a import g\n",
        "c.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from cosim import d\n",
        "d.py": "import cosim.c\nfrom cosim.low import X\n",
        "core/__init__.py": "",
        "core/e.py": "from . import _k\n",
        "core/_k.pyx": "from cosim.core.e import thing\n",
    }
    for name, text in files.items():
        (pkg / name).write_text(text)
    assert _circles(_import_graph(_module_files(tmp_path, ("cosim",)))) == [
        ["cosim.a", "cosim.b"], ["cosim.core._k", "cosim.core.e"]]


# ------------------------------------------------------- no private probes
def _private_probes(path: Path) -> list:
    """``hasattr``/``getattr``/``setattr`` calls of ``path`` that name a
    private attribute (one underscore) of an object other than ``self`` or
    ``cls``."""
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
                and node.func.id in ("hasattr", "getattr", "setattr") and len(node.args) >= 2
                and isinstance(node.args[1], ast.Constant) and isinstance(node.args[1].value, str)
                and node.args[1].value.startswith("_") and not node.args[1].value.startswith("__")
                and ast.unparse(node.args[0]) not in ("self", "cls")):
            out.append(f"{path.relative_to(SRC)}:{node.lineno} {ast.unparse(node)}")
    return out


def test_the_driver_asks_the_sides_and_schemes_public_questions():
    """Whether a run takes the compiled loop is decided by what the scheme
    class and the sides declare (``compiled_loop``), never by probing or
    reading their private attributes."""
    path = SRC / "cosim" / "core" / "schemes" / "driver.py"
    assert not _private_probes(path)
    reads = [f"{ast.unparse(n)} (line {n.lineno})" for n in ast.walk(ast.parse(path.read_text()))
             if isinstance(n, ast.Attribute) and n.attr.startswith("_")
             and not n.attr.startswith("__") and ast.unparse(n.value) not in ("self", "cls")]
    assert not reads, reads


def test_no_module_probes_a_private_attribute_of_another_module():
    """The one probe left is of the core's own registry by the core's
    plug-in finder (a plain dict may stand where a registry does)."""
    found = [p for path in sorted(SRC.rglob("*.py")) for p in _private_probes(path)]
    assert [f.split(":")[0] for f in found] == ["cosim/core/plugins.py"], found


#: the compiled macro loop's modules: they reach the sides, the system, the
#: scheme and the recorder through public faces (the sides' ``compiled_loop``
#: capability, cosim.core.loop_face), never through their private attributes
LOOP = ("cosim/core/schemes/_driver.pyx", "cosim/core/schemes/_driver_block.pyx",
        "cosim/core/schemes/driven_block.py", "cosim/core/schemes/_follow.pyx",
        "cosim/core/schemes/implicit.py", "cosim/core/schemes/_implicit_step.pyx",
        "cosim/core/schemes/_driver_faces.pyx")


def _private_reads(text: str) -> list[str]:
    """Each ``._name`` (one underscore) read of an object other than ``self``
    in ``text``, with its line.  Allowed: ``self._name`` (an object's own
    state) and a dotted path that starts at ``cosim.`` (a module's name, as
    in ``cosim.core.schemes._follow``: imports, docstrings, import_module),
    which reads no object's attribute."""
    out = []
    for m in re.finditer(r"\._[A-Za-z0-9]\w*", text):
        before = text[:m.start()]
        chain = re.search(r"[\w.]*$", before).group(0)
        lead = before[:len(before) - len(chain)][-1:]
        if chain.startswith("cosim."):
            continue
        if chain == "self" and lead not in (")", "]"):
            continue
        line = text.count("\n", 0, m.start()) + 1
        out.append(f"{line}: {(chain or lead) + m.group(0)}")
    # and a probe by name: hasattr(sub, "_name"), getattr(...), setattr(...)
    probe = r"\b(?:has|get|set)attr\((?!(?:self|cls)\s*,)[^,()]+,\s*[\"']_[A-Za-z0-9]\w*"
    for m in re.finditer(probe, text):
        out.append(f"{text.count(chr(10), 0, m.start()) + 1}: {m.group(0)}")
    return out


def test_the_private_read_finder_finds_them():
    """The finder of the test below tells a side's private attribute (read
    or probed by name) from the loop's own and from a module's name."""
    assert _private_reads("self._x = 1\nimport cosim.core.schemes._follow\n") == []
    assert _private_reads("k = sub._closed_end\n") == ["1: sub._closed_end"]
    assert _private_reads('c = getattr(sub, "_closed_end", None)\nhasattr(self, "_k")\n') == [
        '1: getattr(sub, "_closed_end']
    assert _private_reads("a = self.subs[s]._embedded\n") == ["1: ]._embedded"]
    assert _private_reads("a = f(x)._h\nb = scheme.self._t0\n") == ["1: )._h", "2: scheme.self._t0"]


@pytest.mark.parametrize("name", LOOP)
def test_the_compiled_loop_reads_no_private_attribute_of_another_object(name):
    """The loop's modules read no ``._name`` of an object other than ``self``."""
    found = _private_reads((SRC / name).read_text())
    assert not found, found
