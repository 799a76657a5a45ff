"""How a plane body's first impact converges with the modes kept, with and
without the static correction: the scan behind ``tests/test_plane_truncation.py``
and ``tests/test_plane_truncation_rule.py``.

The clamped strip 1 m x 0.1 m (P2 on ``--mesh`` squares cut in two, plane
stress, steel) struck on its top face at ``--s`` by 0.2 kg at 1 m/s through a
linear spring ``--k``; each run is the monolithic reference at rtol 1e-11, so
only the modes differ.  For each cutoff (a multiple of the contact frequency
``sqrt(k / m) / 2 pi``) it prints the top kept frequency, the number of modes,
``c_r k`` (the dropped modes' share of the contact's compliance at the point)
and the relative errors of the first contact's duration and peak force
against the run with every mode of the mesh, without and with the static
correction; then the largest errors over windows of cutoffs (the error
swings with where the cutoff falls among the modes).

Run from the project root::

    python benchmarks/plane_truncation.py [--k 1e8] [--mesh 20x2] [--s 0.5]
                                          [--ratios 6:31:1]
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
MASS = 0.2

SCENE = """\
name = "strip_strike"
t_end = {t_end!r}

[scheme]
name = "monolithic"
rtol = 1e-11
atol = 1e-14

[subsystems.strip]
type = "plane"
mesh = "strip.msh"
thickness = 0.01
youngs_modulus = 210e9
poisson_ratio = 0.3
density = 7850.0
supports = {{ fixed = "left" }}
points = {{ hit = {{ boundary = "top", s = {s!r} }} }}
{modes}

[subsystems.striker]
type = "multibody"

[subsystems.striker.bodies.ball]
mass = {mass!r}
inertia = 1e-5
points = {{ tip = [0.0, 0.0] }}
joint = {{ name = "y", type = "prismatic", parent = "ground", axis = [0.0, 1.0], offset = [{s!r}, 0.05], dq0 = -1.0 }}

[contacts.hit]
a = "striker.tip"
b = "strip.hit"
normal = [0.0, 1.0]
law = {{ type = "linear", contact_stiffness = {k!r} }}
"""


def first_contact(folder: Path, k: float, s: float, modes: str = ""):
    """(duration [s], peak force [N]) of the first contact, the top kept
    frequency [Hz], the number of modes and ``c_r k``."""
    import cosim
    # the contact lasts about pi sqrt(m / k) against a rigid strip
    t_end = 3.0 * np.pi * np.sqrt(MASS / k)
    path = folder / "strip.toml"
    path.write_text(SCENE.format(t_end=float(t_end), s=s, modes=modes, mass=MASS, k=k))
    scene = cosim.load_scene(path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")      # the mode rule's and Flamant's warnings
        system, _ = scene.build()
        c = cosim.simulate(scene, estimate=False).summary["contacts"]["hit"]
    k_run = system.links[0].contact.law.contact_stiffness
    on, off = c["intervals"][0]
    sub = system.subsystems[0]
    return (np.array([off - on, k_run * c["peak_penetration"]]),
            float(sub.natural_frequencies_hz[-1]), int(sub.n_modes), k / k_run - 1.0)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--k", type=float, default=1e8, help="contact stiffness [N/m]")
    ap.add_argument("--mesh", default="20x2", help="squares along x across")
    ap.add_argument("--s", type=float, default=0.5, help="arc length of the point [m]")
    ap.add_argument("--ratios", default="6:31:1", help="cutoffs: start:stop:step multiples")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT / "tests"))
    from plane_files import write_msh
    from fem.plane import rectangle

    nx, ny = (int(v) for v in args.mesh.split("x"))
    f_c = float(np.sqrt(args.k / MASS) / (2 * np.pi))
    a, b, c = (float(v) for v in args.ratios.split(":"))
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        write_msh(folder / "strip.msh", rectangle(1.0, 0.1, nx, ny), "strip")
        ref, top, n_all, _ = first_contact(folder, args.k, args.s)
        print(f"strip {nx} x {ny}, point s = {args.s} m, k = {args.k:g} N/m: contact "
              f"{f_c:.6g} Hz; every mode: {n_all} to {top:.4g} Hz, duration {ref[0]:.6e} s, "
              f"peak {ref[1]:.6f} N")
        print(f"{'cutoff':>7}{'top':>8}{'modes':>6}{'c_r k':>10}  {'without: duration':>17}"
              f"{'peak':>10}  {'with: duration':>14}{'peak':>10}")
        rows = []
        for r in np.arange(a, b, c):
            errs = []
            for corr in ("false", "true"):
                got, top, n, crk = first_contact(
                    folder, args.k, args.s,
                    f"modes = {{ cutoff_hz = {float(r * f_c)!r}, static_correction = {corr} }}")
                errs.append(got / ref - 1)
            rows.append((r, *errs[1]))
            print(f"{r:>6.1f}x{top / f_c:>7.2f}x{n:>6}{crk:>10.3g}  {errs[0][0]:>+17.2e}"
                  f"{errs[0][1]:>+10.2e}  {errs[1][0]:>+14.2e}{errs[1][1]:>+10.2e}", flush=True)
    rows = np.array(rows)
    print("largest errors with the correction over windows of cutoffs:")
    for lo in range(int(a), int(b), 5):
        m = (rows[:, 0] >= lo) & (rows[:, 0] < lo + 5)
        if m.any():
            print(f"  {lo:>3} to {lo + 4:>3} x: duration {np.abs(rows[m, 1]).max():.2e}, "
                  f"peak {np.abs(rows[m, 2]).max():.2e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
