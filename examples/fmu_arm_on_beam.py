"""A robot from another modelling tool meets a cosim structure: an FMU arm strikes a beam.

Builds the two-link arm of ``examples/fmu/arm2.c`` into a co-simulation FMU
(FMI 2.0, or 3.0 with ``--fmi 3``) with the machine's C compiler, then runs
``examples/fmu/arm_on_beam.toml`` (the FMU against beam_impact's beam) under
the Jacobi, Gauss-Seidel and implicit schemes, and Gauss-Seidel with
macro-step control, and prints C's contact interval and peak force beside
those of the same arm as a cosim multibody tree
(``examples/fmu/arm_on_beam_multibody.toml``).

Needs FMPy (``pip install "cosim[fmi]"``) and a C compiler (gcc or cc).

Usage::

    python examples/fmu_arm_on_beam.py [--fmi 3] [--no-state] [--t-end 0.018]

With ``--no-state`` the FMU cannot get and set its state: the schemes that
roll back (implicit, macro-step control) are refused, and the script says why.
"""
from __future__ import annotations

import argparse
import importlib.util
import tempfile
from pathlib import Path

import numpy as np

from cosim import SceneError, load_scene, simulate

HERE = Path(__file__).resolve().parent
SCENE = HERE / "fmu" / "arm_on_beam.toml"
MULTIBODY = HERE / "fmu" / "arm_on_beam_multibody.toml"

#: (label, scheme, variant)
RUNS = [("jacobi", "jacobi", None), ("gauss_seidel", "gauss_seidel", None),
        ("implicit", "implicit", None), ("gauss_seidel, controlled", "gauss_seidel", "controlled")]


def build_module():
    spec = importlib.util.spec_from_file_location("fmu_build", HERE / "fmu" / "build.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def contact_c(path, scheme, variant, overrides):
    result = simulate(load_scene(path, variant, overrides), scheme=scheme,
                      estimate=False)             # intervals and peaks only
    c = result.summary["contacts"]["C"]
    return c["intervals"], float(np.max(result.series["force/C"]))


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--fmi", type=int, default=2, choices=(2, 3))
    p.add_argument("--no-state", action="store_true", help="build without FMU state get/set")
    p.add_argument("--t-end", type=float, default=0.018, help="end time [s]")
    a = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        fmu = build_module().build_fmu(tmp, a.fmi, not a.no_state)
        print(f"built {fmu.name}")
        common = [f"t_end={a.t_end}"]
        for label, scheme, variant in RUNS:
            try:
                got = contact_c(SCENE, scheme, variant,
                                common + [f"subsystems.arm.path={fmu}"])
            except SceneError as exc:
                print(f"{label:26s} refused: {exc}")
                continue
            ref = contact_c(MULTIBODY, scheme, variant, common)
            for name, (intervals, peak) in (("FMU", got), ("multibody", ref)):
                spans = ", ".join(f"[{t0 * 1e3:.5f}, {t1 * 1e3:.5f}] ms" for t0, t1 in intervals)
                print(f"{label:26s} {name:9s} C {spans}, peak force {peak:.4f} N")


if __name__ == "__main__":
    main()
