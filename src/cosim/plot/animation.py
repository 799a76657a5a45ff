"""The animation of a run directory: the robot posed at the recorded joint
coordinates over the deflected structures, rebuilt from the run's
``scene.toml`` as data (:mod:`cosim.plot.scene_geometry`: no side that runs
code, such as an FMU, is built).  Drawn on matplotlib's Agg canvas, without
pyplot."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from cosim.errors import shown
from cosim.plot.run_data import PlotError, RunData, load_run

__all__ = ["animate_run"]


def _frames(n: int, max_frames: int) -> np.ndarray:
    """Indices of at most ``max_frames`` samples, evenly spread, first and last kept."""
    return np.unique(np.linspace(0, n - 1, max(1, min(n, max_frames))).round().astype(int))


def _column(run: RunData, key: str) -> np.ndarray:
    if key not in run.series:
        raise PlotError(f"{run.path / 'series.npz'}: has no `{shown(key, 120)}`, which the "
                        f"animation needs")
    return run.series[key]


def _geometry(run: RunData, geo, idx: np.ndarray, magnify: float):
    """World geometry of the frames ``idx``, as complex arrays [m]:
    (robots, structures, fixed points, contact points), of the sides of
    ``geo`` (a :class:`~cosim.plot.scene_geometry.SceneGeometry`) that are
    built."""
    robots, structures, fixed, contacts = [], [], [], []
    states = {}
    for s, sub in enumerate(geo.subsystems):
        if sub is None:                                      # a side not built (an FMU)
            continue
        if sub.rigid:
            fixed.append(sub.outputs(0.0, None)[0] @ np.array([1.0, 1j]))
        elif "skeleton" in sub.capabilities:                      # a multibody tree
            names = sub.model.joint_names
            X = np.column_stack([_column(run, f"q/{sub.name}/{j}")[idx] for j in names]
                                + [_column(run, f"dq/{sub.name}/{j}")[idx] for j in names])
            states[s] = X
            frames = [sub.skeleton(x) for x in X]
            robots.append((sub.name, [f[0] for f in frames], [f[1] for f in frames]))
        elif "modes" in sub.capabilities:
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
    for ln in geo.links:
        name = ln.name
        force = run.series.get(f"force/{name}")
        touching = (np.zeros(idx.size, bool) if force is None else force[idx] != 0.0)
        a, b = geo.subsystems[ln.sub_a], geo.subsystems[ln.sub_b]
        pa = None
        if ln.sub_a in states:
            pa = np.array([a.outputs(0.0, x)[0][ln.port_a] @ np.array([1.0, 1j])
                           for x in states[ln.sub_a]])
        surface = None
        if b is not None and b.rigid:
            pb = complex(*b.outputs(0.0, None)[0][ln.port_b])
            n = complex(*np.asarray(ln.normal, float))
            surface = (pb, 1j * n / abs(n))                   # a point and the tangent
        contacts.append((name, pa, touching, surface))
    return robots, structures, fixed, contacts


def animate_run(run_dir, out_dir=None, *, max_frames: int = 200, fps: int = 20,
                magnify: float = 1.0) -> Path:
    """Animate the robot and the deformed structure of a run directory.

    The geometry is rebuilt from the run's ``scene.toml`` (the scene as run)
    read as data, and posed at the recorded joint coordinates
    (``q/SUB/JOINT``) and structure DOFs (``q/SUB/DOF``).  Drawn: each tree's
    links (joint to child joint, joint to port), the structures' deflected
    lines (the field between nodes through the shape functions), fixed
    points, rigid surfaces across their contact normals, and contact points,
    red while their force is non-zero.

    No side whose geometry is computed by code the scene names (an FMU) is
    built, so animating a run folder runs none of its code: such a side is
    left out of the picture, and its title says so.

    Parameters
    ----------
    run_dir : path-like or RunData
    out_dir : path-like, optional
        ``run_dir`` by default; written through
        :class:`~cosim.io.rundir.OutputFolder` (never through a link, the
        animation whole or not at all, the folder's lock held meanwhile).
    max_frames : int
        Most frames (at least 2); the samples are decimated evenly, the last
        one kept.
    fps : int
        Frames per second of the animation (at least 1).
    magnify : float
        Scale of the structures' deflection in the picture (1: true scale);
        finite and > 0.

    Returns
    -------
    Path
        ``animation.gif`` (Pillow) or, without Pillow, ``animation.mp4`` (ffmpeg).

    Raises
    ------
    ValueError
        If ``max_frames``, ``fps`` or ``magnify`` is out of its range.
    PlotError
        If the run has no ``scene.toml`` or lacks a series the pose needs, the
        scene's geometry cannot be rebuilt, or neither Pillow nor ffmpeg is there.
    cosim.errors.OutputError
        If ``out_dir`` is a link, a file or a filesystem root, is in use by
        a run, or cannot be written.
    """
    from matplotlib import animation, rc_context

    from cosim.io.rundir import OutputFolder
    from cosim.plot.scene_geometry import scene_geometry
    from cosim.scene.checks import SceneError

    _check_options(max_frames, fps, magnify)
    run = run_dir if isinstance(run_dir, RunData) else load_run(run_dir)
    if run.scene is None:
        raise PlotError(f"{run.path / 'scene.toml'}: no such file, or not a readable scene; "
                        f"the animation rebuilds the geometry from the scene `cosim run` "
                        f"writes there, so run the scene again to animate it")
    if animation.writers.is_available("pillow"):
        writer, suffix = animation.PillowWriter(fps=fps), "gif"
    elif animation.writers.is_available("ffmpeg"):
        writer, suffix = animation.FFMpegWriter(fps=fps), "mp4"
    else:
        raise PlotError('an animation needs Pillow (GIF) or ffmpeg (MP4), and neither is '
                        'installed: pip install pillow')
    try:
        geo = scene_geometry(run.scene, run.path / "scene.toml")
    except (SceneError, ValueError, TypeError, ImportError) as exc:
        raise PlotError(f"{run.path / 'scene.toml'}: cannot rebuild the scene's geometry: "
                        f"{shown(str(exc), 400)}") from None
    n = len(run.t)
    if n == 0:
        raise PlotError(f"{run.path / 'series.npz'}: holds no sample")
    idx = _frames(n, max_frames)
    with rc_context({"text.parse_math": False}):   # names from the run are text, not TeX
        fig, draw = _figure(run, geo, idx, magnify)
        out = Path(out_dir) if out_dir is not None else run.path

        def save(path):
            with writer.saving(fig, str(path), dpi=80):
                for k, i in enumerate(idx):
                    draw(k, i)
                    writer.grab_frame()

        with OutputFolder(out) as folder:
            return folder.write_by_path(f"animation.{suffix}", save)


def _check_options(max_frames, fps, magnify) -> None:
    if isinstance(max_frames, bool) or not isinstance(max_frames, int) or max_frames < 2:
        raise ValueError(f"`max_frames` must be a whole number >= 2, got {max_frames!r}")
    if isinstance(fps, bool) or not isinstance(fps, int) or not 1 <= fps <= 1000:
        raise ValueError(f"`fps` must be a whole number from 1 to 1000, got {fps!r}")
    if isinstance(magnify, bool) or not isinstance(magnify, (int, float)) or not (
            math.isfinite(magnify) and magnify > 0):
        raise ValueError(f"`magnify` must be a finite number > 0, got {magnify!r}")


def _figure(run: RunData, geo, idx: np.ndarray, magnify: float):
    """The animation's figure, and ``draw(k, i)``, which poses it at frame
    ``k`` (sample ``i``)."""
    robots, structures, fixed, contacts = _geometry(run, geo, idx, magnify)

    pts = [z for _, lines, joints in robots for z in lines + joints]
    pts += [z for _, ref, line, _ in structures for z in (ref, line.ravel())]
    pts += fixed + [pa for _, pa, _, _ in contacts if pa is not None]
    allz = np.concatenate([np.ravel(z) for z in pts]) if pts else np.zeros(1, complex)
    allz = allz[np.isfinite(allz)]
    if allz.size == 0:                                       # nothing finite to frame
        allz = np.zeros(1, complex)
    lo = complex(allz.real.min(), allz.imag.min())
    hi = complex(allz.real.max(), allz.imag.max())
    size = max(hi.real - lo.real, hi.imag - lo.imag, 1e-3)
    centre, half = 0.5 * (lo + hi), 0.62 * size                # a square view, padded
    if not (math.isfinite(abs(centre)) and math.isfinite(half)):
        raise PlotError(f"{run.path / 'series.npz'}: the positions recorded are too large "
                        f"to draw (about {size:.3g} m across)")

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
                         ms=4, label=shown(name, 40))
        artists.append((art, line))
    robot_art = []
    for name, lines, joints in robots:
        (la,) = ax.plot([], [], color="tab:blue", lw=2.0, solid_capstyle="round",
                        label=shown(name, 40))
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
    if geo.not_drawn:
        scale += (f"\nnot drawn: {shown(', '.join(geo.not_drawn), 80)} (an FMU: its "
                  f"geometry is in its own code, which plotting does not run)")

    def draw(k, i):
        for art, line in artists:
            art.set_data(line[k].real, line[k].imag)
        for la, lines, ja, joints in robot_art:
            la.set_data(lines[k].real, lines[k].imag)
            ja.set_data(joints[k].real, joints[k].imag)
        for ca, pa, touching in contact_art:
            ca.set_data([pa[k].real], [pa[k].imag]) if touching[k] else ca.set_data([], [])
        title.set_text(f"{run.title()}\nt = {run.t[i]:.6g} s{scale}")

    return fig, draw
