"""Resuming a sweep: what a point's run directory must hold for the point to
count as done (the same scene file by content, variant, overrides and scheme,
and a complete run), so that a sweep run again skips it.
"""
from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from cosim.io.tomlread import read_bytes
from cosim.studies.sweep.grid import Point

__all__ = ["DONE"]

#: a point whose run ended in one of these is done: a sweep run again skips it
DONE = ("finished", "failed", "refused")


def _file_hash(path: Path) -> str:
    return hashlib.sha256(read_bytes(path)).hexdigest()


def _spec(point: Point, scene_path: Path, scheme, scene_hash: str) -> dict:
    return {"scene": scene_path.name, "scene_sha256": scene_hash, "variant": point.variant,
            "set": [[k, v] for k, v in point.params], "scheme": scheme}


def _load_done(run_dir: Path, spec: dict, retry_failed: bool):
    """The record of a point done before, or None when it must run: its
    ``point.json`` names the same scene file (by content), variant, overrides
    and scheme, ended in a status of :data:`DONE`, and, if it ran, its
    ``summary.json`` is complete with the same status."""
    try:
        done = json.loads((run_dir / "point.json").read_text())
    except (OSError, ValueError):
        return None
    if any(done.get(k) != v for k, v in spec.items()):
        return None
    status = done.get("status")
    if status not in DONE or (retry_failed and status != "finished"):
        return None
    if status == "refused":
        return done, None, None
    try:
        summary = json.loads((run_dir / "summary.json").read_text())
        with np.load(run_dir / "series.npz") as z:
            series = {k: z[k] for k in z.files}
    except (OSError, ValueError):
        return None
    if summary.get("status") != status:
        return None
    return done, summary, series
