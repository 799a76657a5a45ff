"""The numbers the README gives for ground_multicontact_strike (CASES.md section 4).

Run from the project root: ``python benchmarks/strike_findings.py``.  For each
of the variants kA1e6, kA4e6 and kA16e6 it runs the scene as shipped and
prints C's and A's separation speeds (the gap's rate at the end of C's
contact and of A's second contact, by a central difference on the series, as
``tests/test_paper_findings.py`` takes them), C's peak penetration over A's,
and the spread of C's speed over the three variants.
"""
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "src"))
import cosim  # noqa: E402

SCENE = ROOT / "cases" / "ground_multicontact_strike.toml"


def exit_rate(res, contact, k):
    t, g = res.series["t"], res.series[f"gap/{contact}"]
    t_off = res.summary["contacts"][contact]["intervals"][k][1]
    i = min(np.searchsorted(t, t_off) + 1, len(t) - 2)
    return (g[i + 1] - g[i - 1]) / (t[i + 1] - t[i - 1])


def main():
    v_c = []
    print("variant  kA [N/m]  C exit [m/s]  A exit [m/s]  C peak / A peak")
    for v in ("kA1e6", "kA4e6", "kA16e6"):
        scene = cosim.load_scene(SCENE, v)
        res = cosim.simulate(scene, estimate=False)
        c = res.summary["contacts"]
        k_a = next(x["law"].contact_stiffness for x in scene.contacts if x["name"] == "A")
        v_c.append(exit_rate(res, "C", 0))
        print(f"{v:8s} {k_a:9.3g}  {v_c[-1]:12.3f}  {exit_rate(res, 'A', 1):12.3f}  "
              f"{c['C']['peak_penetration'] / c['A']['peak_penetration']:15.1f}")
    print(f"C's exit speed: spread {(max(v_c) - min(v_c)) / np.mean(v_c) * 100:.1f} % of its mean")


if __name__ == "__main__":
    main()
