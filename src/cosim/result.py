"""The outcome of a run, and writing it to disk atomically."""
from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["SimulationResult", "write_outputs"]


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


def write_outputs(result: SimulationResult, out_dir) -> tuple[Path, Path]:
    """Write ``summary.json`` and ``series.npz`` into ``out_dir`` atomically."""
    out = Path(out_dir)
    summary = out / "summary.json"
    series = out / "series.npz"
    _atomic_write(series, lambda fh: np.savez(fh, **result.series), "wb")
    _atomic_write(summary, lambda fh: json.dump(result.summary, fh, indent=2), "w")
    return summary, series
