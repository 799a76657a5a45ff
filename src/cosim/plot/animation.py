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
from cosim.plot.figures import wrapped
from cosim.plot.run_data import PlotError, RunData, load_run
from cosim.sides.plane import PlaneSubsystem

__all__ = ["animate_run"]

#: pixels per inch of the frames: 512 x 384 pixels (even, as H.264 needs)
_DPI = 80


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
        elif isinstance(sub, PlaneSubsystem):                # a body from a mesh
            structures.append(_plane_outline(run, sub, idx, magnify))
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


def _plane_outline(run: RunData, sub, idx: np.ndarray, magnify: float):
    """A plane body as the animation draws it: its boundary loops (outer
    and holes, split by NaN) through the mesh's vertices, at rest and
    displaced by ``magnify`` times the field ``Phi q`` of the recorded modal
    coordinates of the frames ``idx``."""
    from fem.plane import outline

    st = sub.structure
    Q = np.column_stack([_column(run, f"q/{sub.name}/mode{i + 1}")[idx]
                         for i in range(sub.n_modes)])
    order = np.concatenate([np.append(loop, -1) for loop in outline(st.mesh.cells)])
    gap = order < 0
    nodes = st.nodes() @ np.array([1.0, 1j])
    field = sub.field(Q) @ np.array([1.0, 1j])               # (frames, vertices)
    ref = np.where(gap, np.nan, nodes[order])
    line = np.where(gap, np.nan, nodes[order] + magnify * field[:, order])
    return sub.name, ref, line, False


def animate_run(run_dir, out_dir=None, *, max_frames: int = 200, fps: int = 20,
                magnify: float = 1.0, video: str | None = None, progress=None) -> Path:
    """Animate the robot and the deformed structure of a run directory.

    The geometry is rebuilt from the run's ``scene.toml`` (the scene as run)
    read as data, and posed at the recorded joint coordinates
    (``q/SUB/JOINT``) and structure DOFs (``q/SUB/DOF``), a plane body's
    modal coordinates (``q/SUB/modeK``).  Drawn: each tree's
    links (joint to child joint, joint to port), the structures' deflected
    lines (the field between nodes through the shape functions), a plane
    body's boundary (outer and holes) through its displaced vertices, fixed
    points, rigid surfaces across their contact normals, and contact points,
    red while their force is non-zero.

    The figure is laid out and its still parts (axes, grid, surfaces,
    legend frame) drawn once; each frame then redraws only what moves over
    that background and hands the canvas's pixels to the encoder, so no
    frame is laid out or drawn whole again.

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
        finite and > 0.  The title states it when it is not 1, and always
        when a plane body is drawn.
    video : {"mp4", "gif"}, optional
        The file written: ``"mp4"`` (H.264 through ffmpeg), ``"gif"``
        (Pillow); by default MP4 where matplotlib finds ffmpeg, else GIF.
    progress : callable, optional
        ``progress(done, total)``, called after each frame is drawn (``done``
        from 1 to ``total``, the number of frames).

    Returns
    -------
    Path
        ``animation.mp4`` or ``animation.gif``.

    Raises
    ------
    ValueError
        If ``max_frames``, ``fps``, ``magnify`` or ``video`` is out of its range.
    PlotError
        If the run has no ``scene.toml`` or lacks a series the pose needs, the
        scene's geometry cannot be rebuilt, the encoder asked for is not
        installed, or ffmpeg fails.
    cosim.errors.OutputError
        If ``out_dir`` is a link, a file or a filesystem root, is in use by
        a run, or cannot be written.
    """
    from matplotlib import rc_context

    from cosim.io.rundir import OutputFolder
    from cosim.plot.scene_geometry import scene_geometry
    from cosim.scene.checks import SceneError

    _check_options(max_frames, fps, magnify, video)
    run = run_dir if isinstance(run_dir, RunData) else load_run(run_dir)
    if run.scene is None:
        raise PlotError(f"{run.path / 'scene.toml'}: no such file, or not a readable scene; "
                        f"the animation rebuilds the geometry from the scene `cosim run` "
                        f"writes there, so run the scene again to animate it")
    encode, suffix = _encoder(video)
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
        fig, draw, moving, legend = _figure(run, geo, idx, magnify)
        out = Path(out_dir) if out_dir is not None else run.path
        with OutputFolder(out) as folder:
            return folder.write_by_path(
                f"animation.{suffix}",
                lambda path: encode(path, _Frames(fig, draw, moving, legend, idx), fps,
                                            progress))


def _encoder(video):
    """The encoder ``encode(path, frames, fps, progress)`` of ``video`` (or of the
    default: ffmpeg where found, else Pillow), and its file suffix."""
    from matplotlib import animation

    ffmpeg = animation.writers.is_available("ffmpeg")
    if video == "mp4" or (video is None and ffmpeg):
        if not ffmpeg:
            raise PlotError("an MP4 animation needs ffmpeg, which matplotlib does not find "
                            "(install it, or set matplotlib's `animation.ffmpeg_path`); "
                            "a GIF needs only Pillow")
        return _write_mp4, "mp4"
    from importlib.util import find_spec

    if find_spec("PIL") is None:       # matplotlib depends on it: missing only in a broken install
        raise PlotError("a GIF animation needs Pillow, which is not installed: "
                        "pip install pillow")
    return _write_gif, "gif"


class _Frames:
    """The frames of an animation, drawn on demand as RGBA arrays of the
    canvas.  The figure is laid out once, posed at the first frame; its still
    parts are drawn once into a background, and each frame restores that
    background, draws the ``moving`` artists over it and copies back the
    pixels of the ``legend`` (opaque, drawn once), which lies over them."""

    def __init__(self, fig, draw, moving, legend, idx):
        self.fig, self._draw, self.moving, self.idx = fig, draw, moving, idx
        canvas = fig.canvas
        draw(0, idx[0])
        canvas.draw()                      # lays the figure out, every artist in place
        fig.set_layout_engine("none")      # and keeps that layout for every frame
        for a in moving:
            a.set_animated(True)           # left out of the background
        canvas.draw()
        self._background = canvas.copy_from_bbox(fig.bbox)
        self._legend = (None if legend is None else
                        canvas.copy_from_bbox(legend.get_window_extent().padded(1)))

    def __len__(self) -> int:
        return len(self.idx)

    def __getitem__(self, k: int) -> np.ndarray:
        """Frame ``k``: a view of the canvas's pixels, valid until the next frame."""
        canvas = self.fig.canvas
        canvas.restore_region(self._background)
        self._draw(k, self.idx[k])
        for a in self.moving:
            self.fig.draw_artist(a)
        if self._legend is not None:
            canvas.restore_region(self._legend)
        return np.asarray(canvas.buffer_rgba())

    def colours(self) -> np.ndarray:
        """RGB [0, 255] of the moving artists' lines, markers and text."""
        from matplotlib.colors import to_rgb

        found = []
        for a in self.moving:
            for get in ("get_color", "get_markerfacecolor", "get_markeredgecolor"):
                c = getattr(a, get, None)
                try:
                    found.append(to_rgb(c()))
                except (TypeError, ValueError):   # no such colour ("none", "auto")
                    pass
        return np.round(255 * np.array(found or [(0.0, 0.0, 0.0)])).astype(np.uint8)


def _palette(frames: _Frames):
    """One palette of 256 colours for every frame of a GIF, so that still
    parts keep their colour from frame to frame: drawn from nine frames
    spread over the animation and from swatches of every moving artist's
    colour blended with white (a contact point may be red only between the
    frames sampled)."""
    from PIL import Image

    sample = [frames[k][..., :3].copy()
              for k in np.unique(np.linspace(0, len(frames) - 1, 9).round().astype(int))]
    width = sample[0].shape[1]
    blend = np.linspace(0.0, 1.0, 5)[:, None, None]
    swatch = (blend * frames.colours()[None] + (1 - blend) * 255.0).round().astype(np.uint8)
    swatch = np.resize(swatch.reshape(-1, 3), (8, width, 3))
    return Image.fromarray(np.concatenate(sample + [swatch])).quantize(
        256, Image.Quantize.MEDIANCUT)


def _write_gif(path, frames: _Frames, fps: int, progress) -> None:
    """A looping GIF of ``frames`` through Pillow, each frame mapped to one
    palette (:func:`_palette`) as it is drawn."""
    from PIL import Image

    palette = _palette(frames)
    h, w = frames[0].shape[:2]
    images = []
    for k in range(len(frames)):
        rgb = Image.frombuffer("RGBA", (w, h), frames[k], "raw", "RGBA", 0, 1).convert("RGB")
        images.append(rgb.quantize(palette=palette, dither=Image.Dither.NONE))
        if progress is not None:
            progress(k + 1, len(frames))
    images[0].save(path, format="GIF", save_all=True, append_images=images[1:],
                   duration=round(1000 / fps), loop=0)


def _write_mp4(path, frames: _Frames, fps: int, progress) -> None:
    """An H.264 MP4 of ``frames``: their pixels piped to ffmpeg as raw RGBA
    (the executable and codec as matplotlib's settings name them)."""
    import subprocess
    import tempfile

    from matplotlib import animation, rcParams

    exe = animation.FFMpegWriter.bin_path()
    proc = None
    with tempfile.TemporaryFile() as log:
        try:
            for k in range(len(frames)):
                rgba = frames[k]
                if proc is None:
                    h, w = rgba.shape[:2]
                    proc = subprocess.Popen(
                        [exe, "-y", "-loglevel", "error", "-f", "rawvideo", "-pix_fmt", "rgba",
                         "-s", f"{w}x{h}", "-r", str(fps), "-i", "pipe:0", "-an",
                         "-vcodec", rcParams["animation.codec"], "-pix_fmt", "yuv420p",
                         str(path)], stdin=subprocess.PIPE, stdout=subprocess.DEVNULL,
                        stderr=log)
                proc.stdin.write(rgba.tobytes())
                if progress is not None:
                    progress(k + 1, len(frames))
            proc.stdin.close()
            rc = proc.wait()
        except BrokenPipeError:
            rc = proc.wait()
        except BaseException:
            if proc is not None:
                proc.kill()
                proc.wait()
            raise
        if rc != 0:
            log.seek(0)
            said = log.read().decode(errors="replace").strip()
            raise PlotError(f"{exe} failed (exit {rc}) writing the animation: "
                            f"{shown(said, 400) or 'no message'}")


def _check_options(max_frames, fps, magnify, video=None) -> None:
    if isinstance(max_frames, bool) or not isinstance(max_frames, int) or max_frames < 2:
        raise ValueError(f"`max_frames` must be a whole number >= 2, got {max_frames!r}")
    if isinstance(fps, bool) or not isinstance(fps, int) or not 1 <= fps <= 1000:
        raise ValueError(f"`fps` must be a whole number from 1 to 1000, got {fps!r}")
    if isinstance(magnify, bool) or not isinstance(magnify, (int, float)) or not (
            math.isfinite(magnify) and magnify > 0):
        raise ValueError(f"`magnify` must be a finite number > 0, got {magnify!r}")
    if video not in (None, "mp4", "gif"):
        raise ValueError(f"`video` must be \"mp4\", \"gif\" or None, got {video!r}")


def _figure(run: RunData, geo, idx: np.ndarray, magnify: float):
    """The animation's figure, ``draw(k, i)``, which poses it at frame ``k``
    (sample ``i``), the artists that ``draw`` changes, and the legend (None
    without one), which lies over them."""
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

    fig = Figure(figsize=(6.4, 4.8), dpi=_DPI, layout="constrained")
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
    # the legend's frame is opaque, so its pixels do not depend on what moves
    # under it: they are copied back over each frame instead of drawn again
    legend = (ax.legend(fontsize=8, loc="upper right", framealpha=1.0)
              if robots or structures else None)
    planes = any(isinstance(sub, PlaneSubsystem) for sub in geo.subsystems)
    scale = (f"\nstructure deflection x{magnify:g}" if magnify != 1 else
             "\nstructure deflection x1 (true scale; --magnify to exaggerate)" if planes
             else "")
    if geo.not_drawn:
        scale += (f"\nnot drawn: {shown(', '.join(geo.not_drawn), 80)} (an FMU: its "
                  f"geometry is in its own code, which plotting does not run)")
    # the title is centred on the axes, which sit near the figure's middle:
    # lines within 90 % of the figure's width stay inside it
    ax.set_title(wrapped(fig, run.title() + scale, 9, 0.9 * fig.bbox.width), fontsize=9,
                 color="firebrick" if run.incomplete else "black")
    clock = ax.text(0.02, 0.98, "", transform=ax.transAxes, fontsize=9, va="top")

    def draw(k, i):
        for art, line in artists:
            art.set_data(line[k].real, line[k].imag)
        for la, lines, ja, joints in robot_art:
            la.set_data(lines[k].real, lines[k].imag)
            ja.set_data(joints[k].real, joints[k].imag)
        for ca, pa, touching in contact_art:
            ca.set_data([pa[k].real], [pa[k].imag]) if touching[k] else ca.set_data([], [])
        clock.set_text(f"t = {run.t[i]:.6g} s")

    moving = [a for a, _ in artists] + [a for la, _, ja, _ in robot_art for a in (la, ja)]
    moving += [ca for ca, _, _ in contact_art] + [clock]
    return fig, draw, moving, legend
