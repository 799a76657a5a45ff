"""Studies: TOML files that fix a scene, its points, the axis of the plot and
a title (``studies/fig8_stiffness.toml`` and ``studies/fig11_chain_mass.toml``
are the paper's figures 8 and 11), and running one into a folder.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from cosim.errors import shown
from cosim.scene.load import SceneError, read_toml_file
from cosim.studies.sweep.driver import MAX_TIMEOUT_S, strike_names, sweep, sweep_folder
from cosim.studies.sweep.grid import _repeated, _text
from cosim.studies.sweep.plot import plot_sweep
from cosim.studies.sweep.table import PLOT

__all__ = ["Study", "load_study", "run_study"]


@dataclass(frozen=True)
class Study:
    """A ready parameter study: a scene, its points, and how to draw them.

    Read from a TOML file by :func:`load_study`::

        title = "..."
        scene = "../cases/three_mass.toml"     # relative to the study file
        variants = ["ms6.4", "ms3.2"]
        contact = "C"                          # optional: the scene's strike
        joint = "robot/arm"                    # optional: the joint that strikes
        [set]                                  # optional grid: key -> values
        "contacts.C.law.contact_stiffness" = [1.6e5, 3.2e5]
        [x]                                    # optional plot axis
        key = "contacts.C.law.contact_stiffness"
        scale = 6.25e-6
        label = "f"

    and optionally ``timeout``, the most wall-clock seconds a point may run
    (see :func:`sweep`).  Without ``contact`` or ``joint``, the scene chooses
    them (:func:`cosim.studies.strike.find_strike`).
    """

    name: str
    title: str
    scene: Path
    variants: tuple = ()
    grid: dict = field(default_factory=dict)
    contact: str | None = None
    joint: str | None = None
    x: str | None = None
    x_scale: float = 1.0
    x_label: str | None = None
    timeout: float | None = None


def load_study(path) -> Study:
    """Read a study file (see :class:`Study`).

    Raises
    ------
    SceneError
        Naming the file and the key, if a value is missing or of the wrong
        kind.
    """
    from cosim.scene.checks import Table as _Table

    path = Path(path)
    top = _Table(read_toml_file(path), (), path)
    title = top.string("title", path.stem)
    scene = top.string("scene")
    variants = top.raw("variants", [])
    if not isinstance(variants, list) or not all(isinstance(v, str) for v in variants):
        top.error("variants", f"must be a list of names, got {variants!r}")
    grid = top.raw("set", {})
    if not isinstance(grid, dict) or not all(isinstance(v, list) and v for v in grid.values()):
        top.error("set", f"must be a table of key = [values], got {grid!r}")
    dup = next((v for i, v in enumerate(variants) if v in variants[:i]), None)
    if dup is not None:
        top.error("variants", f"repeats {shown(dup, 80)!r}: give each variant once")
    for key, values in grid.items():
        dup = _repeated(values)
        if dup is not None:
            raise SceneError(path, f"set.{key}", f"repeats the value {shown(_text(dup), 80)}: "
                                                 f"give each value once (each point runs "
                                                 f"once, into a folder of its own)")
    contact = top.string("contact", None)
    joint = top.string("joint", None)
    timeout = top.number("timeout", None, rule=">0", unit="s")
    if timeout is not None and timeout > MAX_TIMEOUT_S:
        top.error("timeout", f"must be at most {MAX_TIMEOUT_S:.0e} s "
                             f"({MAX_TIMEOUT_S / 86400:.1f} days), got {timeout!r}")
    x = top.table("x", {})
    key = x.string("key", None)
    scale = x.number("scale", 1.0)
    label = x.string("label", None)
    x.finish()
    top.finish()
    return Study(name=path.stem, title=title, scene=path.parent / scene,
                 variants=tuple(variants), grid=dict(grid), contact=contact, joint=joint,
                 x=key, x_scale=scale, x_label=label, timeout=timeout)


def run_study(study: Study, *, out, workers: int = 1, scheduler=None, scheme=None,
              retry_failed: bool = False, progress=None, plot: bool = True):
    """Run a study with :func:`sweep` into ``out`` and draw it there.

    Returns
    -------
    rows : list of dict
    plot : Path or None
        ``out/sweep.png``; None when ``plot`` is false.
    """
    contact, joint = strike_names(study.scene, study.variants, study.contact, study.joint)
    with sweep_folder(out) as folder:       # held from the first point to the figure
        rows = sweep(study.scene, variants=study.variants or None, grid=study.grid,
                     scheme=scheme, workers=workers, scheduler=scheduler, out=folder,
                     retry_failed=retry_failed, contact=contact, joint=joint,
                     progress=progress, timeout=study.timeout)
        png = None
        if plot:
            png = plot_sweep(rows, folder.path_of(PLOT), contact=contact, x=study.x,
                             x_scale=study.x_scale, x_label=study.x_label, title=study.title)
    return rows, png
