"""The sweep's table: one record per point (the grid's values, the status,
the flattened ``summary.json`` and the impact regime), written as CSV in grid
order so that it reads back exactly, whatever order the points ran in.
"""
from __future__ import annotations

import csv
import json
from pathlib import Path

from cosim.io.rundir import atomic_write
from cosim.studies.sweep.grid import Point
from cosim.studies.metrics import impact_regime

__all__ = ["TABLE", "PLOT", "TIMING_COLUMNS", "flatten", "columns", "write_table", "table_writer",
           "read_table"]

#: the table and the plot in a sweep's output directory
TABLE, PLOT = "sweep.csv", "sweep.png"

#: columns that measure the machine, not the model: they differ between two
#: runs of the same point
TIMING_COLUMNS = ("cpu_time_s",)

#: the columns every row starts with, after the grid's keys
_LEAD = ("variant", "point", "status", "message")


def flatten(tree: dict, prefix: str = "") -> dict:
    """Nested dicts to one level, keys joined with dots
    (``contacts.C.count``); lists stay values."""
    out = {}
    for k, v in tree.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(flatten(v, key + "."))
        else:
            out[key] = v
    return out


def _record(point: Point, spec: dict, summary: dict | None, series, contact, joint) -> dict:
    """One row: the grid's values (``set.KEY``, apart from the summary's own
    keys such as ``t_end``, the time a run reached), variant, point, status, message, then the
    flattened summary and the impact regime (when the scene has ``contact``
    and the series ``dq/joint``)."""
    row = {f"set.{k}": v for k, v in point.params}
    row.update(variant=spec["variant"], point=point.name, status=spec["status"],
               message=spec["message"])
    if summary is None:
        return row
    summary = json.loads(json.dumps(summary))       # the same values read back from disk
    flat = flatten(summary)
    flat.pop("status", None)
    flat.pop("message", None)
    row.update(flat)
    if (contact in summary.get("contacts", {}) and series is not None
            and f"dq/{joint}" in series and "t" in series):
        row.update({f"impact.{k}": v
                    for k, v in impact_regime(summary, series, contact, joint).items()})
    return row


def _cell(v) -> str:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, (list, tuple, dict)):
        return json.dumps(v, separators=(",", ":"))
    return str(v)


def columns(rows: list[dict]) -> list[str]:
    """The table's columns: the grid's keys (``set.KEY``), ``variant``, ``point``,
    ``status``, ``message``, then every other key in order of first
    appearance (rows in grid order), so the same rows give the same columns
    whatever order they were computed in."""
    grid = _grid_keys(rows)
    cols = grid + list(_LEAD)
    for r in rows:
        cols.extend(k for k in r if k not in cols)
    return cols


def _grid_keys(rows: list[dict]) -> list[str]:
    """The grid's keys: what every record holds before ``variant``."""
    if not rows:
        return []
    first = list(rows[0])
    return first[:first.index("variant")]


def table_writer(rows: list[dict]):
    """``writer(fh)`` that writes the records as CSV into the text file
    ``fh`` (see :func:`write_table`), for a caller that holds the folder."""
    cols = columns(rows)

    def write(fh):
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(cols)
        for r in rows:
            w.writerow([_cell(r.get(c)) for c in cols])
    return write


def write_table(rows: list[dict], path) -> Path:
    """Write the records as CSV, one row per point in grid order.  Floats are
    written to round trip, lists as JSON, missing values empty.  The file is
    written whole through the checked writer
    (:func:`cosim.io.rundir.atomic_write`): a link planted at ``path`` is
    replaced, never followed."""
    return atomic_write(Path(path), table_writer(rows), "w")


def read_table(path) -> list[dict]:
    """Read a sweep's CSV back: numbers as numbers, JSON lists as lists, empty
    cells (a missing value, or an empty message) as None, everything else as
    text."""
    def value(s: str):
        if s == "":
            return None
        if s[0] in "[{":
            try:
                return json.loads(s)
            except ValueError:
                return s
        for kind in (int, float):
            try:
                return kind(s)
            except ValueError:
                pass
        return {"true": True, "false": False}.get(s, s)

    with open(path, newline="") as fh:
        return [{k: value(v) for k, v in r.items()} for r in csv.DictReader(fh)]
