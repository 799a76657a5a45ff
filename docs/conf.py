"""Sphinx configuration of cosim's documentation.

Build it offline, warnings as errors (``tests/test_docs.py`` does the same)::

    python -m sphinx -W -b html docs docs/_build/html

The guide pages are MyST Markdown; the API reference is generated from the
numpydoc docstrings.  The scene file's table of keys is written at build time
from the loader's own table (``cosim.scene.keys.reference_markdown``), so the
reference cannot drift from what the loader checks.
"""
from __future__ import annotations

import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
sys.path.insert(0, str(DOCS.parent / "src"))       # the source tree, not an installed copy

import cosim  # noqa: E402
from cosim.scene.keys import reference_markdown  # noqa: E402

project = "cosim"
author = "the cosim authors"
copyright = "the cosim authors"
release = cosim.__version__
version = ".".join(release.split(".")[:2])

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "numpydoc",
]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build", "_generated", "Thumbs.db", ".DS_Store"]

# -- the scene file's keys, generated -------------------------------------------------
GENERATED = DOCS / "_generated"
GENERATED.mkdir(exist_ok=True)
_keys = GENERATED / "scene_keys.md"
_text = reference_markdown()
if not _keys.exists() or _keys.read_text(encoding="utf-8") != _text:
    _keys.write_text(_text, encoding="utf-8")      # rewritten only when it changed

# -- MyST ----------------------------------------------------------------------------
myst_enable_extensions = ["dollarmath", "colon_fence"]
myst_heading_anchors = 3
suppress_warnings = []

# -- API reference -------------------------------------------------------------------
autosummary_generate = True
templates_path = ["_templates"]      # a class page documents its members, so they can be referred to
autodoc_typehints = "none"              # numpydoc's sections carry the types
autodoc_member_order = "bysource"
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_validation_checks: set = set()

# Every cross-reference must resolve (-W fails the build on one that does not), except:
# the standard library (the build is offline, without intersphinx), private names, and
# the internal modules below the public API (cosim.core, io, scene, sides, studies and
# couplers.restitution), which the API pages leave out on purpose (see the design page).
nitpicky = True
nitpick_ignore_regex = [
    ("py:class", r"abc\.ABC"),
    (r"py:.*", r"(.*\.)?_\w+"),
    (r"py:.*", r"(cosim\.(core|io|scene|sides|studies)|couplers\.restitution)(\..*)?"),
]

# -- HTML ----------------------------------------------------------------------------
html_theme = "furo"
html_title = f"cosim {release}"


# -- citations -----------------------------------------------------------------------
# A module's numpydoc "References" list its works once, in the module docstring, and its
# classes cite them as ``[1]_``.  Shown alone (a class page, a summary line), such a
# citation has no target; it is rendered as the plain text ``[1]`` instead.
import re  # noqa: E402

_CITATION = re.compile(r"\[(\d+)\]_")


def _plain_citations(app, what, name, obj, options, lines):
    text = "\n".join(lines)
    defined = set(re.findall(r"^\s*\.\. \[(\d+)\]", text, flags=re.M))
    for i, line in enumerate(lines):
        lines[i] = _CITATION.sub(
            lambda m: m.group(0) if m.group(1) in defined else f"[{m.group(1)}]", line)


def setup(app):
    # after numpydoc (priority 500), which turns a References section into ``.. [1]`` targets
    app.connect("autodoc-process-docstring", _plain_citations, priority=600)
