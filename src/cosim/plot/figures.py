"""The time histories of a run directory: contact penetrations with the
contact intervals shaded, contact forces, joint velocities, structure DOFs
and the energy ledger (:func:`plot_run`), one figure each, drawn on
matplotlib's Agg canvas.
"""
from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from cosim.errors import shown
from cosim.plot.run_data import RunData, load_run

__all__ = ["FORMATS", "plot_run", "wrapped"]

#: Output formats of :func:`plot_run`.
FORMATS = ("png", "svg", "pdf")

_STRUCTURE_TYPES = ("chain", "beam", "cable", "string", "rod")
_MAX_STRUCTURE_LINES = 8
#: most panels of a figure, and most lines of a panel of joints: a run folder
#: may name thousands (the rest are left out, and the title says so)
_MAX_ROWS = 12
_MAX_LINES = 16


def wrapped(fig, text: str, fontsize: float, width: float) -> str:
    """``text`` with each of its lines broken at spaces so that none is wider
    than ``width`` [pixels] on ``fig``'s canvas in the default font at
    ``fontsize`` [pt]; a word wider than ``width`` on its own is broken
    inside.  A title that names a long reason (an incomplete run's message)
    then stays inside the figure instead of running off both its edges."""
    from matplotlib.font_manager import FontProperties

    renderer = fig.canvas.get_renderer()
    font = FontProperties(size=fontsize)

    def fits(s: str) -> bool:
        return renderer.get_text_width_height_descent(s, font, ismath=False)[0] <= width

    lines = []
    for line in text.split("\n"):
        cur = ""
        for word in line.split(" "):
            if fits(f"{cur} {word}" if cur else word):
                cur = f"{cur} {word}" if cur else word
                continue
            if cur:
                lines.append(cur)
            while len(word) > 1 and not fits(word):       # a word wider than a line
                k = len(word) - 1
                while k > 1 and not fits(word[:k]):
                    k -= 1
                lines.append(word[:k])
                word = word[k:]
            cur = word
        lines.append(cur)
    return "\n".join(lines)


# ------------------------------------------------------------------ units
def _table(d, key) -> dict:
    """``d[key]`` when both are tables, else an empty one: the scene as run
    is read as data, and what does not fit is passed over."""
    v = d.get(key) if isinstance(d, dict) else None
    return v if isinstance(v, dict) else {}


def _subsystem_types(run: RunData) -> dict:
    subs = _table(run.scene, "subsystems")
    return {k: v.get("type") for k, v in subs.items() if isinstance(v, dict)}


def _joint_kinds(run: RunData) -> dict:
    """(subsystem, joint) -> "revolute" | "prismatic", from the scene as run."""
    kinds = {}
    for sname, sub in _table(run.scene, "subsystems").items():
        for body in _table(sub, "bodies").values():
            joint = _table(body, "joint")
            if isinstance(joint.get("name"), str):
                kinds[(sname, joint["name"])] = joint.get("type")
    return kinds


def _is_structure(run: RunData, sub: str, names) -> bool:
    types = _subsystem_types(run)
    if types.get(sub) in _STRUCTURE_TYPES:
        return True
    if types.get(sub) in ("multibody", "rigid", "fmu"):
        return False
    # a run without scene.toml, or a structure an installed package declares
    # (plotting imports no plug-in): structures name their DOFs w0, t0, u0, m1, ...
    return all(re.fullmatch(r"[wtum]\d+", n) for n in names)


def _velocity_unit(kind) -> str:
    return {"revolute": "rad/s", "prismatic": "m/s"}.get(kind, "rad/s or m/s")


# ---------------------------------------------------------------- figures
def _label(name) -> str:
    """A name read from the run folder as a figure shows it: control
    characters escaped, its length capped."""
    return shown(name, 60)


def _contact_names(run: RunData) -> list:
    if run.summary is not None:
        return [c for c in run.summary["contacts"] if f"gap/{c}" in run.series]
    return [k[4:] for k in run.series if k.startswith("gap/") and not k.endswith(".t")]


def _contact(run: RunData, contact: str) -> dict:
    """The checked summary record of ``contact`` (empty without one)."""
    return (run.summary or {}).get("contacts", {}).get(contact) or {}


def _most(items: list, most: int = _MAX_ROWS) -> tuple[list, str]:
    """At most ``most`` of ``items``, evenly spread with both ends kept, and
    the note that says so (empty when all are kept)."""
    if len(items) <= most:
        return items, ""
    pick = np.unique(np.linspace(0, len(items) - 1, most).round()).astype(int)
    return [items[i] for i in pick], f" ({len(pick)} of {len(items)} shown)"


def _figure(run: RunData, rows: int, what: str):
    fig = Figure(figsize=(7.5, 1.2 + 1.9 * rows), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(rows, 1, sharex=True, squeeze=False)[:, 0]
    fig.suptitle(wrapped(fig, f"{what}: {run.title()}", 10, 0.95 * fig.bbox.width),
                 fontsize=10, color="firebrick" if run.incomplete else "black")
    t0 = float(run.t[0]) if len(run.t) else 0.0
    for ax in axes:
        ax.grid(True, lw=0.4, alpha=0.5)
        if run.t_end is not None and run.t_end > t0:
            ax.set_xlim(t0, run.t_end)
        if run.incomplete and len(run.t):
            ax.axvline(float(run.t[-1]), color="firebrick", ls=":", lw=1.0)
    axes[-1].set_xlabel("time [s]")
    return fig, axes


def _shade(ax, intervals, label="in contact"):
    for k, (a, b) in enumerate(intervals):
        ax.axvspan(a, b, color="tab:orange", alpha=0.15, lw=0, label=label if k == 0 else None)


def _penetration_figure(run: RunData):
    names, note = _most(_contact_names(run))
    if not names:
        return None
    fig, axes = _figure(run, len(names), "contact penetration" + note)
    for ax, c in zip(axes, names):
        pen = -run.series[f"gap/{c}"]
        ax.plot(run.t, pen, lw=1.0, label="penetration")
        _shade(ax, _contact(run, c).get("intervals", []))
        peak = _contact(run, c).get("peak_penetration")
        finite = pen[np.isfinite(pen)]
        top = max(peak if peak is not None and math.isfinite(peak) else 0.0,
                  float(finite.max(initial=0.0)))
        if top > 0 and finite.size and finite.min() < -3 * top:
            # the flight between contacts would flatten the penetrations to nothing
            ax.set_ylim(-top, 1.15 * top)
            ax.set_ylabel("penetration [m]\n(gaps clipped)")
        else:
            ax.set_ylabel("penetration [m]")
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_title(f"contact {_label(c)}"
                     + (f" (peak {peak:.4g} m)" if peak is not None else ""),
                     fontsize=9, loc="left")
        ax.legend(fontsize=8, loc="best")
    return fig


def _force_figure(run: RunData):
    names, note = _most([c for c in _contact_names(run) if f"force/{c}" in run.series])
    if not names:
        return None
    fig, axes = _figure(run, len(names), "contact force" + note)
    for ax, c in zip(axes, names):
        ax.plot(run.t, run.series[f"force/{c}"], lw=1.0, label="normal")
        if f"force/{c}.t" in run.series:
            ax.plot(run.t, run.series[f"force/{c}.t"], lw=1.0, ls="--", label="tangential")
        _shade(ax, _contact(run, c).get("intervals", []))
        imp = _contact(run, c).get("impulse")
        ax.set_ylabel("force [N]")
        ax.set_title(f"contact {_label(c)}"
                     + (f" (impulse {imp:.4g} N s)" if imp is not None else ""),
                     fontsize=9, loc="left")
        ax.legend(fontsize=8, loc="best")
    return fig


def _dofs(run: RunData, prefix: str) -> dict:
    """subsystem -> [DOF names] of the series ``prefix/SUB/NAME``, in series order."""
    out: dict = {}
    for k in run.series:
        parts = k.split("/", 2)
        if len(parts) == 3 and parts[0] == prefix:
            out.setdefault(parts[1], []).append(parts[2])
    return out


def _joint_velocity_figure(run: RunData):
    kinds = _joint_kinds(run)
    groups = []                                   # (subsystem, unit, [joints])
    for sub, names in _dofs(run, "dq").items():
        if _is_structure(run, sub, names):
            continue
        by_unit: dict = {}
        for j in names:
            by_unit.setdefault(_velocity_unit(kinds.get((sub, j))), []).append(j)
        groups += [(sub, u, js) for u, js in by_unit.items()]
    groups, note = _most(groups)
    if not groups:
        return None
    fig, axes = _figure(run, len(groups), "joint velocities" + note)
    for ax, (sub, unit, joints) in zip(axes, groups):
        joints, some = _most(joints, _MAX_LINES)
        for j in joints:
            ax.plot(run.t, run.series[f"dq/{sub}/{j}"], lw=1.0, label=_label(j))
        ax.set_ylabel(f"velocity [{unit}]")
        ax.set_title(f"subsystem {_label(sub)}{some}", fontsize=9, loc="left")
        ax.legend(fontsize=8, loc="best", ncol=min(4, len(joints)))
    return fig


def _structure_figure(run: RunData):
    groups = []
    for sub, names in _dofs(run, "q").items():
        if not _is_structure(run, sub, names):
            continue
        moving = [n for n in names if not n.startswith("t")]     # t*: rotations [rad]
        if len(moving) > _MAX_STRUCTURE_LINES:                    # evenly spread, ends kept
            pick = np.unique(np.linspace(0, len(moving) - 1, _MAX_STRUCTURE_LINES).round())
            moving = [moving[int(i)] for i in pick]
        if moving:
            groups.append((sub, moving, len(names)))
    groups, note = _most(groups)
    if not groups:
        return None
    fig, axes = _figure(run, len(groups), "structure displacements" + note)
    for ax, (sub, names, total) in zip(axes, groups):
        for n in names:
            ax.plot(run.t, run.series[f"q/{sub}/{n}"], lw=1.0, label=_label(n))
        ax.set_ylabel("displacement [m]")
        ax.set_title(f"subsystem {_label(sub)}" + (f" ({len(names)} of {total} DOFs)"
                                           if len(names) < total else ""), fontsize=9, loc="left")
        ax.legend(fontsize=8, loc="best", ncol=min(4, len(names)))
    return fig


def _energy_figure(run: RunData):
    if "energy/total" not in run.series:
        return None
    fig, axes = _figure(run, 2, "energy ledger")
    ax = axes[0]
    total = run.series["energy/total"]
    diss = run.series.get("energy/dissipated", np.zeros_like(total))
    ax.plot(run.t, total, lw=1.2, label="total (kinetic + potential + stored)")
    ax.plot(run.t, diss, lw=1.0, label="dissipated")
    ax.plot(run.t, total + diss, lw=1.0, ls="--", label="total + dissipated")
    ax.set_ylabel("energy [J]")
    ax.legend(fontsize=8, loc="best")
    if total.size:
        axes[1].plot(run.t, total + diss - total[0], lw=1.0, color="tab:red")
    axes[1].axhline(0.0, color="k", lw=0.5)
    axes[1].set_ylabel("total + dissipated\n- initial [J]")
    ax = axes[1]
    s = run.summary or {}
    notes = []
    e = s.get("energy") or {}
    if e.get("max_abs_drift") is not None:
        notes.append(f"max drift {e['max_abs_drift']:.3g} J")
    if e.get("supplied"):
        notes.append(f"supplied by drives {e['supplied']:.4g} J by the end (not subtracted)")
    contacts, more = _most(list((s.get("contacts") or {}).items()))
    for c, rec in contacts:
        if rec.get("coupling_error") is not None:
            notes.append(f"coupling error {_label(c)}: {rec['coupling_error']:.3g} J")
    if more and notes:
        notes.append(f"coupling errors of {more.strip(' ()')} contacts")
    if notes:
        ax.text(0.99, 0.03, "\n".join(notes), transform=ax.transAxes, ha="right", va="bottom",
                fontsize=8, bbox={"boxstyle": "round", "fc": "white", "alpha": 0.8, "lw": 0.4})
    return fig


_FIGURES = (("penetration", _penetration_figure), ("force", _force_figure),
            ("joint_velocity", _joint_velocity_figure), ("structure", _structure_figure),
            ("energy", _energy_figure))


def plot_run(run_dir, out_dir=None, fmt: str = "png") -> list[Path]:
    """Draw the time histories of a run directory.

    Parameters
    ----------
    run_dir : path-like or RunData
        Written by ``cosim run`` (finished or interrupted), or as
        :func:`load_run` read it.
    out_dir : path-like, optional
        Where to write; ``run_dir`` by default.  The folder is written
        through :class:`~cosim.io.rundir.OutputFolder`: made when missing,
        never through a link (at the folder or at a figure's name), each
        figure whole or not at all, the folder's lock held meanwhile.
    fmt : {"png", "svg", "pdf"}

    Returns
    -------
    list of Path
        The files written, among ``penetration``, ``force``,
        ``joint_velocity``, ``structure`` and ``energy`` (a figure with
        nothing to show is left out).

    Raises
    ------
    ValueError
        If ``fmt`` is not one of :data:`FORMATS`.
    PlotError
        If the run directory has no readable series.
    cosim.errors.OutputError
        If ``out_dir`` is a link, a file or a filesystem root, is in use by
        a run, or cannot be written.
    """
    from matplotlib import rc_context

    from cosim.io.rundir import OutputFolder

    if fmt not in FORMATS:
        raise ValueError(f"`fmt` must be one of {FORMATS}, got {fmt!r}")
    run = run_dir if isinstance(run_dir, RunData) else load_run(run_dir)
    out = Path(out_dir) if out_dir is not None else run.path
    written = []
    # names read from the run folder are text, never TeX: no `$...$` is parsed
    with rc_context({"text.parse_math": False}), OutputFolder(out) as folder:
        for name, make in _FIGURES:
            fig = make(run)
            if fig is None:
                continue
            written.append(folder.write(
                f"{name}.{fmt}", lambda fh, fig=fig: fig.savefig(
                    fh, format=fmt, dpi=110 if fmt == "png" else None), "wb"))
    return written
