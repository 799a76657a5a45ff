"""Pictures of a run directory: time histories and an animation.

Reads what ``cosim run`` writes (``summary.json``, ``series.npz`` and, for
the animation, ``scene.toml``) and draws, in the manner of the seed paper's
figures (Lipinski, figs. 5-11): contact penetrations with the contact
intervals shaded, contact forces, joint velocities, structure DOFs and the
energy ledger.  A partial run (status not ``finished``, or series that stop
before the scene's end time) is drawn as far as it goes and marked
incomplete in every title.

Needs matplotlib (the ``plot`` extra).  Figures are drawn on matplotlib's
Agg canvas directly, without pyplot, so no global backend is chosen and no
window opens.  Nothing here prints: the paths written are returned.
"""
from __future__ import annotations

import json
import re
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

__all__ = ["FORMATS", "PlotError", "RunData", "load_run", "plot_run", "animate_run"]

#: Output formats of :func:`plot_run`.
FORMATS = ("png", "svg", "pdf")

_STRUCTURE_TYPES = ("chain", "beam", "cable", "string", "rod")
_MAX_STRUCTURE_LINES = 8


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


# ------------------------------------------------------------------ units
def _subsystem_types(run: RunData) -> dict:
    subs = (run.scene or {}).get("subsystems", {})
    return {k: v.get("type") for k, v in subs.items() if isinstance(v, dict)}


def _joint_kinds(run: RunData) -> dict:
    """(subsystem, joint) -> "revolute" | "prismatic", from the scene as run."""
    kinds = {}
    for sname, sub in (run.scene or {}).get("subsystems", {}).items():
        for body in (sub.get("bodies") or {}).values() if isinstance(sub, dict) else ():
            joint = body.get("joint") if isinstance(body, dict) else None
            if isinstance(joint, dict) and "name" in joint:
                kinds[(sname, joint["name"])] = joint.get("type")
    return kinds


def _is_structure(run: RunData, sub: str, names) -> bool:
    types = _subsystem_types(run)
    if sub in types:
        return types[sub] in _STRUCTURE_TYPES
    # a run without scene.toml: structures name their DOFs w0, t0, u0, m1, ...
    return all(re.fullmatch(r"[wtum]\d+", n) for n in names)


def _velocity_unit(kind) -> str:
    return {"revolute": "rad/s", "prismatic": "m/s"}.get(kind, "rad/s or m/s")


# ---------------------------------------------------------------- figures
def _contact_names(run: RunData) -> list:
    if run.summary and isinstance(run.summary.get("contacts"), dict):
        return [c for c in run.summary["contacts"] if f"gap/{c}" in run.series]
    return [k[4:] for k in run.series if k.startswith("gap/") and not k.endswith(".t")]


def _intervals(run: RunData, contact: str) -> list:
    c = ((run.summary or {}).get("contacts") or {}).get(contact) or {}
    return [iv for iv in c.get("intervals", []) if len(iv) == 2]


def _figure(run: RunData, rows: int, what: str):
    fig = Figure(figsize=(7.5, 1.2 + 1.9 * rows), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(rows, 1, sharex=True, squeeze=False)[:, 0]
    fig.suptitle(f"{what}: {run.title()}", fontsize=10,
                 color="firebrick" if run.incomplete else "black")
    for ax in axes:
        ax.grid(True, lw=0.4, alpha=0.5)
        if run.t_end is not None:
            ax.set_xlim(float(run.t[0]) if len(run.t) else 0.0, run.t_end)
        if run.incomplete and len(run.t):
            ax.axvline(float(run.t[-1]), color="firebrick", ls=":", lw=1.0)
    axes[-1].set_xlabel("time [s]")
    return fig, axes


def _shade(ax, intervals, label="in contact"):
    for k, (a, b) in enumerate(intervals):
        ax.axvspan(a, b, color="tab:orange", alpha=0.15, lw=0, label=label if k == 0 else None)


def _penetration_figure(run: RunData):
    names = _contact_names(run)
    if not names:
        return None
    fig, axes = _figure(run, len(names), "contact penetration")
    for ax, c in zip(axes, names):
        pen = -run.series[f"gap/{c}"]
        ax.plot(run.t, pen, lw=1.0, label="penetration")
        _shade(ax, _intervals(run, c))
        peak = (((run.summary or {}).get("contacts") or {}).get(c) or {}).get("peak_penetration")
        top = max(peak or 0.0, float(pen.max(initial=0.0)))
        if top > 0 and pen.size and pen.min() < -3 * top:
            # the flight between contacts would flatten the penetrations to nothing
            ax.set_ylim(-top, 1.15 * top)
            ax.set_ylabel("penetration [m]\n(gaps clipped)")
        else:
            ax.set_ylabel("penetration [m]")
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_title(f"contact {c}" + (f" (peak {peak:.4g} m)" if peak is not None else ""),
                     fontsize=9, loc="left")
        ax.legend(fontsize=8, loc="best")
    return fig


def _force_figure(run: RunData):
    names = [c for c in _contact_names(run) if f"force/{c}" in run.series]
    if not names:
        return None
    fig, axes = _figure(run, len(names), "contact force")
    for ax, c in zip(axes, names):
        ax.plot(run.t, run.series[f"force/{c}"], lw=1.0, label="normal")
        if f"force/{c}.t" in run.series:
            ax.plot(run.t, run.series[f"force/{c}.t"], lw=1.0, ls="--", label="tangential")
        _shade(ax, _intervals(run, c))
        imp = (((run.summary or {}).get("contacts") or {}).get(c) or {}).get("impulse")
        ax.set_ylabel("force [N]")
        ax.set_title(f"contact {c}" + (f" (impulse {imp:.4g} N s)" if imp is not None else ""),
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
    if not groups:
        return None
    fig, axes = _figure(run, len(groups), "joint velocities")
    for ax, (sub, unit, joints) in zip(axes, groups):
        for j in joints:
            ax.plot(run.t, run.series[f"dq/{sub}/{j}"], lw=1.0, label=j)
        ax.set_ylabel(f"velocity [{unit}]")
        ax.set_title(f"subsystem {sub}", fontsize=9, loc="left")
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
    if not groups:
        return None
    fig, axes = _figure(run, len(groups), "structure displacements")
    for ax, (sub, names, total) in zip(axes, groups):
        for n in names:
            ax.plot(run.t, run.series[f"q/{sub}/{n}"], lw=1.0, label=n)
        ax.set_ylabel("displacement [m]")
        ax.set_title(f"subsystem {sub}" + (f" ({len(names)} of {total} DOFs)"
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
    if "max_abs_drift" in e:
        notes.append(f"max drift {e['max_abs_drift']:.3g} J")
    if e.get("supplied"):
        notes.append(f"supplied by drives {e['supplied']:.4g} J by the end (not subtracted)")
    for c, rec in (s.get("contacts") or {}).items():
        if isinstance(rec, dict) and "coupling_error" in rec:
            notes.append(f"coupling error {c}: {rec['coupling_error']:.3g} J")
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
        Where to write; ``run_dir`` by default.
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
    """
    if fmt not in FORMATS:
        raise ValueError(f"`fmt` must be one of {FORMATS}, got {fmt!r}")
    run = run_dir if isinstance(run_dir, RunData) else load_run(run_dir)
    out = Path(out_dir) if out_dir is not None else run.path
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for name, make in _FIGURES:
        fig = make(run)
        if fig is None:
            continue
        path = out / f"{name}.{fmt}"
        fig.savefig(path, dpi=110 if fmt == "png" else None)
        written.append(path)
    return written


# -------------------------------------------------------------- animation
def _frames(n: int, max_frames: int) -> np.ndarray:
    """Indices of at most ``max_frames`` samples, evenly spread, first and last kept."""
    return np.unique(np.linspace(0, n - 1, max(1, min(n, max_frames))).round().astype(int))


def _column(run: RunData, key: str) -> np.ndarray:
    if key not in run.series:
        raise PlotError(f"{run.path / 'series.npz'}: has no `{key}`, which the animation needs")
    return run.series[key]


def _geometry(run: RunData, system, idx: np.ndarray, magnify: float):
    """World geometry of the frames ``idx``, as complex arrays [m]:
    (robots, structures, fixed points, contact points)."""
    robots, structures, fixed, contacts = [], [], [], []
    states = {}
    for s, sub in enumerate(system.subsystems):
        if getattr(sub, "rigid", False):
            fixed.append(sub.outputs(0.0, None)[0] @ np.array([1.0, 1j]))
        elif hasattr(sub, "skeleton"):                      # a multibody tree
            names = sub.model.joint_names
            X = np.column_stack([_column(run, f"q/{sub.name}/{j}")[idx] for j in names]
                                + [_column(run, f"dq/{sub.name}/{j}")[idx] for j in names])
            states[s] = X
            frames = [sub.skeleton(x) for x in X]
            robots.append((sub.name, [f[0] for f in frames], [f[1] for f in frames]))
        elif hasattr(sub, "structure"):
            st = sub.structure
            U = np.column_stack([_column(run, f"q/{sub.name}/{d}")[idx]
                                 for d in st.dof_names])
            direction = complex(*np.asarray(st.direction, float))
            if hasattr(st, "length"):                        # a line: sample between nodes
                s_pts = np.linspace(0.0, float(st.length), max(101, 4 * len(st.nodes())))
                W = np.zeros((s_pts.size, st.n_dof))
                for i, sp in enumerate(s_pts):
                    dofs, w = st.point_operator(sp)
                    W[i, dofs] = w
                ref = np.array([st.reference_position(sp) for sp in s_pts]) @ np.array([1, 1j])
                field = U @ W.T
                dotted = False
            else:                                            # a chain: its masses
                ref = st.nodes() @ np.array([1.0, 1j])
                field = st.nodal_displacement(U)
                dotted = True
            structures.append((sub.name, ref, ref[None, :] + magnify * field * direction, dotted))
    for c, ln in enumerate(system.links):
        name = system.contact_names[c]
        force = run.series.get(f"force/{name}")
        touching = (np.zeros(idx.size, bool) if force is None else force[idx] != 0.0)
        a, b = system.subsystems[ln.sub_a], system.subsystems[ln.sub_b]
        pa = None
        if ln.sub_a in states:
            pa = np.array([a.outputs(0.0, x)[0][ln.port_a] @ np.array([1.0, 1j])
                           for x in states[ln.sub_a]])
        surface = None
        if getattr(b, "rigid", False):
            pb = complex(*b.outputs(0.0, None)[0][ln.port_b])
            n = complex(*np.asarray(ln.contact.normal, float))
            surface = (pb, 1j * n / abs(n))                   # a point and the tangent
        contacts.append((name, pa, touching, surface))
    return robots, structures, fixed, contacts


def animate_run(run_dir, out_dir=None, *, max_frames: int = 200, fps: int = 20,
                magnify: float = 1.0) -> Path:
    """Animate the robot and the deformed structure of a run directory.

    The geometry is rebuilt from the run's ``scene.toml`` (the scene as run)
    and posed at the recorded joint coordinates (``q/SUB/JOINT``) and
    structure DOFs (``q/SUB/DOF``).  Drawn: each tree's links (joint to child
    joint, joint to port), the structures' deflected lines (the field between
    nodes through the shape functions), fixed points, rigid surfaces across
    their contact normals, and contact points, red while their force is
    non-zero.

    Parameters
    ----------
    run_dir : path-like or RunData
    out_dir : path-like, optional
        ``run_dir`` by default.
    max_frames : int
        Most frames; the samples are decimated evenly, the last one kept.
    fps : int
        Frames per second of the animation.
    magnify : float
        Scale of the structures' deflection in the picture (1: true scale).

    Returns
    -------
    Path
        ``animation.gif`` (Pillow) or, without Pillow, ``animation.mp4`` (ffmpeg).

    Raises
    ------
    PlotError
        If the run has no ``scene.toml`` or lacks a series the pose needs, the
        scene cannot be rebuilt, or neither Pillow nor ffmpeg is there.
    """
    from matplotlib import animation

    from cosim.scene.load import SceneError, load_scene

    run = run_dir if isinstance(run_dir, RunData) else load_run(run_dir)
    if run.scene is None:
        raise PlotError(f"{run.path / 'scene.toml'}: no such file; the animation rebuilds the "
                        f"geometry from the scene `cosim run` writes there, so run the scene "
                        f"again to animate it")
    if max_frames < 2:
        raise ValueError(f"`max_frames` must be >= 2, got {max_frames}")
    if animation.writers.is_available("pillow"):
        writer, suffix = animation.PillowWriter(fps=fps), "gif"
    elif animation.writers.is_available("ffmpeg"):
        writer, suffix = animation.FFMpegWriter(fps=fps), "mp4"
    else:
        raise PlotError('an animation needs Pillow (GIF) or ffmpeg (MP4), and neither is '
                        'installed: pip install pillow')
    try:
        system, _ = load_scene(run.path / "scene.toml").build()
    except (SceneError, ValueError, ImportError) as exc:
        raise PlotError(f"{run.path / 'scene.toml'}: cannot rebuild the scene: {exc}") from None
    n = len(run.t)
    if n == 0:
        raise PlotError(f"{run.path / 'series.npz'}: holds no sample")
    idx = _frames(n, max_frames)
    robots, structures, fixed, contacts = _geometry(run, system, idx, magnify)

    pts = [z for _, lines, joints in robots for z in lines + joints]
    pts += [z for _, ref, line, _ in structures for z in (ref, line.ravel())]
    pts += fixed + [pa for _, pa, _, _ in contacts if pa is not None]
    allz = np.concatenate([np.ravel(z) for z in pts]) if pts else np.zeros(1, complex)
    allz = allz[np.isfinite(allz)]
    lo = complex(allz.real.min(), allz.imag.min())
    hi = complex(allz.real.max(), allz.imag.max())
    size = max(hi.real - lo.real, hi.imag - lo.imag, 1e-3)
    centre, half = 0.5 * (lo + hi), 0.62 * size                # a square view, padded

    fig = Figure(figsize=(6.4, 4.8), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    ax.set_xlim(centre.real - half, centre.real + half)
    ax.set_ylim(centre.imag - half, centre.imag + half)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(True, lw=0.4, alpha=0.4)
    for z in fixed:
        ax.plot(z.real, z.imag, "k^", ms=6)
    for _, pa, _, surface in contacts:
        if surface is not None:
            p, tan = surface
            ends = np.array([p - 0.25 * size * tan, p + 0.25 * size * tan])
            ax.plot(ends.real, ends.imag, color="0.3", lw=2.5, solid_capstyle="butt")
    artists = []
    for name, ref, line, dotted in structures:
        ax.plot(ref.real, ref.imag, color="0.6", lw=0.8, ls="--")
        (art,) = ax.plot([], [], color="tab:green", lw=2.0, marker="o" if dotted else None,
                         ms=4, label=name)
        artists.append((art, line))
    robot_art = []
    for name, lines, joints in robots:
        (la,) = ax.plot([], [], color="tab:blue", lw=2.0, solid_capstyle="round", label=name)
        (ja,) = ax.plot([], [], "o", color="tab:blue", mfc="white", ms=5)
        robot_art.append((la, lines, ja, joints))
    contact_art = []
    for name, pa, touching, _ in contacts:
        if pa is not None:
            (ca,) = ax.plot([], [], "o", color="firebrick", ms=7)
            contact_art.append((ca, pa, touching))
    if robots or structures:
        ax.legend(fontsize=8, loc="upper right")
    title = ax.set_title("", fontsize=9, color="firebrick" if run.incomplete else "black")
    scale = f", structure deflection x{magnify:g}" if magnify != 1 else ""

    out = Path(out_dir) if out_dir is not None else run.path
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"animation.{suffix}"
    with writer.saving(fig, str(path), dpi=80):
        for k, i in enumerate(idx):
            for art, line in artists:
                art.set_data(line[k].real, line[k].imag)
            for la, lines, ja, joints in robot_art:
                la.set_data(lines[k].real, lines[k].imag)
                ja.set_data(joints[k].real, joints[k].imag)
            for ca, pa, touching in contact_art:
                ca.set_data([pa[k].real], [pa[k].imag]) if touching[k] else ca.set_data([], [])
            title.set_text(f"{run.title()}\nt = {run.t[i]:.6g} s{scale}")
            writer.grab_frame()
    return path
