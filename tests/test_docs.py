"""The documentation builds without a warning, and what it shows runs.

The Sphinx build is run as CI's command runs it (warnings as errors, offline),
into a temporary folder, so a broken reference, a missing page or a docstring
that does not parse fails here.  The README's Python example and the design
page's worked examples are run as they stand; the tables that mirror the code
(the layers, the registries) are compared with it; and the version is one.
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SRC = ROOT / "src"
DOCS = ROOT / "docs"


def _env() -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(SRC), env.get("PYTHONPATH")]))
    return env


def _python_blocks(path: Path) -> list[str]:
    """The ```python fenced blocks of a Markdown file, in order."""
    return re.findall(r"^```python\n(.*?)^```", path.read_text(encoding="utf-8"),
                      flags=re.M | re.S)


def _run(code: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], cwd=cwd, env=_env(),
                          capture_output=True, text=True, timeout=600)


def test_the_docs_build_without_a_warning(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-E", "-q", "-b", "html",
         "-d", str(tmp_path / "doctrees"), str(DOCS), str(tmp_path / "html")],
        cwd=ROOT, env=_env(), capture_output=True, text=True, timeout=1200)
    assert proc.returncode == 0, f"sphinx exit {proc.returncode}:\n{proc.stderr[-6000:]}"
    assert proc.stderr.strip() == "", proc.stderr[-6000:]
    html = tmp_path / "html"
    for page in ("index", "getting-started", "scenes", "api", "design", "examples", "changelog"):
        assert (html / f"{page}.html").is_file(), page
    # the scene reference holds the loader's own table, generated at build time
    from cosim.scene.keys import reference_markdown

    section = re.search(r"^## (\[[^\]\n]+\])", reference_markdown(), flags=re.M)
    assert section, "reference_markdown() has no `## [section]` heading"
    assert section.group(1) in (html / "scenes.html").read_text(encoding="utf-8")
    assert "0.8.0" in (html / "changelog.html").read_text(encoding="utf-8")


def test_a_broken_reference_to_a_public_name_fails_the_build():
    """The build is nitpicky: of the references that do not resolve, only those
    to the standard library, to private names and to the internal modules
    below the public API are let through; the build above then fails on any
    other (a misspelt public name, a method that was renamed)."""
    import json

    # read in a child process: conf.py puts the source tree first on sys.path,
    # which must not change what this process imports (an installed cosim's
    # compiled kernels against the source tree's numpy reference)
    code = ("import json, runpy; c = runpy.run_path('docs/conf.py'); "
            "print(json.dumps([c['nitpicky'], c['nitpick_ignore_regex']]))")
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=_env(),
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    nitpicky, ignore = json.loads(proc.stdout.strip().splitlines()[-1])
    assert nitpicky is True
    conf = {"nitpick_ignore_regex": ignore}

    def ignored(role, target):
        return any(re.fullmatch(r, role) and re.fullmatch(t, target)
                   for r, t in conf["nitpick_ignore_regex"])

    for role, target in [("py:func", "cosim.simulate"), ("py:meth", "cosim.Scene.build"),
                         ("py:class", "fem.Beam"), ("py:meth", "couplers.HertzLaw.stiffness"),
                         ("py:meth", "multibody.TreeModel.mass_matrix"),
                         ("py:func", "cosim.no_such_function"), ("py:class", "simulate")]:
        assert not ignored(role, target), target
    for role, target in [("py:class", "abc.ABC"), ("py:class", "fem.newmark._AlphaFamily"),
                         ("py:func", "cosim.core.hermite.substep_peaks"),
                         ("py:mod", "cosim.core.guard")]:
        assert ignored(role, target), target


def test_the_readme_python_example_runs(tmp_path):
    blocks = _python_blocks(ROOT / "README.md")
    assert len(blocks) == 1, f"the README shows one Python example, found {len(blocks)}"
    assert len(blocks[0].strip().splitlines()) == 3, blocks[0]
    proc = _run(blocks[0], ROOT)
    assert proc.returncode == 0, proc.stderr[-4000:]
    intervals = proc.stdout.split("]]")[0] + "]]"
    assert re.match(r"\[\[0\.01\d*, 0\.012\d*\]\]", intervals), proc.stdout


@pytest.mark.parametrize("page", ["getting-started.md", "commands.md"])
def test_the_guides_python_examples_run(page):
    blocks = _python_blocks(DOCS / page)
    assert blocks, page
    for code in blocks:
        proc = _run(code, ROOT)
        assert proc.returncode == 0, f"{page}:\n{code}\n{proc.stderr[-4000:]}"


@pytest.mark.parametrize("index", range(3), ids=["law", "structure", "scheme"])
def test_the_design_pages_worked_examples_run(index):
    blocks = _python_blocks(DOCS / "design.md")
    assert len(blocks) == 3, f"design.md shows a law, a structure and a scheme, found {len(blocks)}"
    proc = _run(blocks[index], ROOT)       # each asserts its own physics
    assert proc.returncode == 0, proc.stderr[-4000:]


def test_the_design_pages_scheme_is_refused_at_the_step_the_page_names():
    """The page says the pre-flight check refuses its new scheme at 2e-5 s and names
    6.33e-06 s as the largest safe step."""
    code = _python_blocks(DOCS / "design.md")[2]
    assert '"scheme.macro_step = 5e-6"' in code
    proc = _run(code.replace('"scheme.macro_step = 5e-6"', '"scheme.macro_step = 2e-5"'), ROOT)
    assert proc.returncode != 0
    assert "UnsafeStepError" in proc.stderr and "held_jacobi" in proc.stderr, proc.stderr[-2000:]
    assert "largest safe macro step is 6.33e-06 s" in proc.stderr, proc.stderr[-2000:]
    assert "2e-5" in (DOCS / "design.md").read_text(encoding="utf-8")


def test_the_design_page_draws_the_layers_the_test_enforces():
    sys.path.insert(0, str(ROOT / "tests"))
    try:
        from test_layers import LAYERS
    finally:
        sys.path.remove(str(ROOT / "tests"))
    text = (DOCS / "design.md").read_text(encoding="utf-8")
    drawn = {}
    for layer, holds in re.findall(r"^\| (\d) \| (.*?) \|", text, flags=re.M):
        for name in re.findall(r"`([\w.]+)`", holds):
            drawn[name] = int(layer)
    assert drawn == LAYERS, f"design.md draws {drawn}, tests/test_layers.py enforces {LAYERS}"


def _table(text: str, title: str) -> list[str]:
    start = text.index(title)
    rows = re.findall(r"^\| `(\w+)` \|", text[start:].split("\n\n", 2)[1], flags=re.M)
    return rows


def test_the_api_page_lists_every_registered_name():
    import couplers
    import fem
    from cosim import COUPLING_SCHEMES, INTEGRATORS

    text = (DOCS / "api.md").read_text(encoding="utf-8")
    for title, registry in (("`cosim.COUPLING_SCHEMES`", COUPLING_SCHEMES),
                            ("`couplers.CONTACT_LAWS`", couplers.CONTACT_LAWS),
                            ("`cosim.INTEGRATORS`", INTEGRATORS),
                            ("`fem.STRUCTURAL_INTEGRATORS`", fem.STRUCTURAL_INTEGRATORS)):
        assert _table(text, title) == list(registry), title


def test_the_readme_is_short_and_links_to_pages_that_exist():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 150
    assert not re.search(r"\bissues? \d+|#\d+\b", text, flags=re.I), "an issue number"
    links = re.findall(r"\]\(((?:docs/|CHANGELOG)[^)#]*)\)", text)
    assert len(links) >= 10, links
    for link in links:
        assert (ROOT / link).is_file(), link
    # every guide page is linked from the front page
    for page in DOCS.glob("*.md"):
        if page.stem not in ("index", "changelog"):
            assert f"(docs/{page.name})" in text, page.name


def test_no_page_speaks_of_issue_numbers():
    for path in [ROOT / "CHANGELOG.md", *DOCS.glob("*.md")]:
        text = path.read_text(encoding="utf-8")
        found = re.search(r".{0,40}\bissues? \d+.{0,40}", text, flags=re.I)
        assert found is None, f"{path.name}: {found.group(0)!r}"


def test_ci_runs_the_readme_test_command():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    command = 'python -m pip install ".[test,docs]" && python -m pytest'
    assert command in readme
    assert (ROOT / ".ci" / "run").read_text(encoding="utf-8").strip().endswith(command)
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))[
        "project"]["optional-dependencies"]
    names = {re.split(r"[<>=\[ ]", r)[0] for r in extras["docs"]}
    assert names == {"sphinx", "furo", "myst-parser", "numpydoc"}, names


def test_one_version():
    import cosim

    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    assert "version" not in pyproject["project"]
    assert "version" in pyproject["project"]["dynamic"]
    assert pyproject["tool"]["setuptools"]["dynamic"]["version"] == {"attr": "cosim.__version__"}
    # setuptools reads the attribute without importing cosim: a plain assignment
    assert re.search(r'^__version__ = "[^"]+"$', (SRC / "cosim" / "__init__.py").read_text(
        encoding="utf-8"), flags=re.M)
    proc = subprocess.run([sys.executable, "-m", "cosim.cli", "--version"], cwd=ROOT,
                          env=_env(), capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == f"cosim {cosim.__version__}"
    assert f"## {cosim.__version__}" in (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
    # an installed distribution is compared only when it is the copy under test
    from importlib import metadata

    try:
        dist = metadata.distribution("cosim")
    except metadata.PackageNotFoundError:
        return
    installed = Path(dist.locate_file("cosim/__init__.py")).resolve()
    if installed == Path(cosim.__file__).resolve():
        assert dist.version == cosim.__version__


def test_the_suite_runs_on_every_core_as_the_readme_says():
    """README: the test command runs the suite on every core, through
    pytest-xdist in the test extra and `-n auto` in the project's pytest
    options (so the command itself stays `python -m pytest`)."""
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    test = {re.split(r"[<>=\[ ]", r)[0] for r in pyproject["project"]["optional-dependencies"]["test"]}
    assert "pytest-xdist" in test
    assert "-n auto" in pyproject["tool"]["pytest"]["ini_options"]["addopts"]
    readme = " ".join((ROOT / "README.md").read_text(encoding="utf-8").split())
    assert "The suite then runs on every core (pytest-xdist, `-n auto` in `pyproject.toml`" in readme
