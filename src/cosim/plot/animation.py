"""The animation of a run directory: the robot posed at the recorded joint
coordinates over the deflected structures, rebuilt from the run's
``scene.toml``.  Drawn on matplotlib's Agg canvas, without pyplot."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from cosim.plot.run_data import PlotError, RunData, load_run

__all__ = ["animate_run"]


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
