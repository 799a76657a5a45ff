"""Reading a run directory for drawing: :func:`load_run` gives a
:class:`RunData` from what ``cosim run`` wrote (``summary.json``,
``series.npz``, ``scene.toml``), finished or not, and says what is missing.
Needs no matplotlib."""
from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["PlotError", "RunData", "load_run"]


class PlotError(RuntimeError):
    """A run directory that cannot be drawn (what is missing is named)."""


@dataclass(frozen=True)
class RunData:
    """What a run directory holds.

    Attributes
    ----------
    path : Path
    summary : dict or None
        ``summary.json``; None if the run never wrote it.
    series : dict[str, ndarray]
        ``series.npz``, every array cut to the shortest length.
    scene : dict or None
        ``scene.toml`` (the scene as run), None for runs written before it.
    t_end : float or None
        The scene's end time [s] (None when unknown).
    incomplete : str
        Why the run is incomplete, empty if it is not.
    """

    path: Path
    summary: dict | None
    series: dict
    scene: dict | None
    t_end: float | None
    incomplete: str

    @property
    def t(self) -> np.ndarray:
        return self.series["t"]

    def title(self) -> str:
        s = self.summary or {}
        head = f"{s.get('scene') or (self.scene or {}).get('name') or self.path.name}"
        if s.get("scheme"):
            head += f", scheme {s['scheme']}"
        return head + (f"\nINCOMPLETE run: {self.incomplete}" if self.incomplete else "")


def load_run(run_dir) -> RunData:
    """Read a run directory, finished or not.

    Raises
    ------
    PlotError
        If there is no readable ``series.npz``.
    """
    from cosim.io.tomlread import read_toml

    path = Path(run_dir)
    fseries = path / "series.npz"
    if not fseries.is_file():
        raise PlotError(f"{fseries}: no such file; `cosim plot` needs a run directory "
                        f"written by `cosim run`")
    try:
        with np.load(fseries) as npz:
            series = {k: np.asarray(npz[k]) for k in npz.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise PlotError(f"{fseries}: cannot be read: {exc}") from None
    if "t" not in series:
        raise PlotError(f"{fseries}: has no time array `t`")
    n = min(len(v) for v in series.values())
    series = {k: v[:n] for k, v in series.items()}
    summary = None
    fsum = path / "summary.json"
    if fsum.is_file():
        try:
            summary = json.loads(fsum.read_text())
        except (OSError, ValueError):
            summary = None
    scene = None
    fscene = path / "scene.toml"
    if fscene.is_file():
        try:
            scene = read_toml(fscene)           # within the limits of a scene file
        except (OSError, ValueError):           # TOMLDecodeError, TomlLimitError
            scene = None
    t_end = None
    if scene is not None and isinstance(scene.get("t_end"), (int, float)):
        t_end = float(scene["t_end"])
    why = []
    if summary is None:
        why.append("no readable summary.json")
    elif summary.get("status") != "finished":
        why.append(f"status {summary.get('status')!r}"
                   + (f" ({summary['message']})" if summary.get("message") else ""))
    t_last = float(series["t"][-1]) if n else 0.0
    if t_end is not None and t_last < t_end * (1 - 1e-9):
        why.append(f"series reach t = {t_last:.6g} s of {t_end:.6g} s")
    return RunData(path, summary, series, scene, t_end, "; ".join(why))
