"""The outcome of a run, and writing it to disk atomically."""
from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["SimulationResult", "write_outputs", "resolved_scene_text"]


@dataclass(frozen=True)
class SimulationResult:
    """What :func:`cosim.simulate` returns.

    Attributes
    ----------
    t : (n,) array
        Sample times [s].
    series : dict[str, array]
        Time series named as in ``series.npz`` (``gap/C``, ``force/C``,
        ``q/SUB/JOINT``, ``dq/SUB/JOINT``, ``energy/total``, ...).
    summary : dict
        The ``summary.json`` contract.
    contact_events : tuple of dict
        Contact intervals in time order: ``contact``, ``t_on``, ``t_off``.
    n_windows, n_iterations, n_rejected : int
        Macro steps, coupling iterations, rejected macro steps.
    status : {"finished", "failed"}
    message : str
    success : bool
    """

    t: np.ndarray
    series: dict
    summary: dict
    contact_events: tuple
    n_windows: int
    n_iterations: int
    n_rejected: int
    status: str
    message: str
    success: bool

    def to_csv(self, path) -> None:
        """Write the series as CSV, ``time`` first."""
        names = [k for k in self.series if k != "t"]
        data = np.column_stack([self.t] + [self.series[k] for k in names])
        _atomic_write(Path(path), lambda fh: np.savetxt(
            fh, data, delimiter=",", header=",".join(["time"] + names), comments=""), "w")


def _atomic_write(path: Path, writer, mode: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, mode) as fh:
            writer(fh)
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise


def write_outputs(result: SimulationResult, out_dir, scene=None) -> tuple[Path, Path]:
    """Write ``summary.json`` and ``series.npz`` into ``out_dir`` atomically.

    Parameters
    ----------
    result : SimulationResult
    out_dir : path-like
    scene : Scene, optional
        The scene that ran; its merged table (variant, overrides and scheme
        applied) is written as ``scene.toml`` too, a scene file of its own
        that ``cosim plot --animate`` rebuilds the geometry from (and that
        ``cosim run`` runs again).

    Returns
    -------
    summary, series : Path
    """
    out = Path(out_dir)
    summary = out / "summary.json"
    series = out / "series.npz"
    if scene is not None:
        text = resolved_scene_text(scene)
        _atomic_write(out / "scene.toml", lambda fh: fh.write(text), "w")
    _atomic_write(series, lambda fh: np.savez(fh, **result.series), "wb")
    _atomic_write(summary, lambda fh: json.dump(result.summary, fh, indent=2), "w")
    return summary, series


def resolved_scene_text(scene) -> str:
    """``scene.toml`` of a run: the scene's merged table as TOML, its origin in a comment."""
    from .tomlwrite import dumps

    data = {"name": scene.name, **scene.data}
    head = (f"# The scene as run: {Path(scene.path).name}"
            + (f", variant {scene.variant!r}" if scene.variant else "")
            + ", overrides and scheme applied (written by `cosim run`).\n")
    return head + dumps(data)
