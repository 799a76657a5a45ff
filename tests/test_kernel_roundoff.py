"""Where round-off makes the compiled kernels' discrete outcomes differ from
the numpy reference's (docs/schemes.md, "Where round-off decides").

The compiled steps evaluate the reference's formulas with other roundings,
so the two differ as a run differs from a copy of itself whose initial state
is moved by a few ulps (:func:`cosim.studies.roundoff.spread`).  Two runs of
three_mass ``ms0.01`` (chain masses 0.01 kg, C's spring 1.6e7 N/m) hold it:

- Gauss-Seidel with C hosted, at 10 x the hard-case reference step, stable:
  the kernels and the moved copies close C as many times, and the onsets
  differ between the kernels by no more than twice the largest difference
  between the compiled run and its moved copies (the spread of five copies
  estimates what a few-ulp nudge does; twice it, as five copies sample it).
- Jacobi with C exchanged at 5 x the reference step, forced past the
  pre-flight check: the guard stops every run for energy growth, but the
  number of C's closings before the stop is decided by round-off: the moved
  copies of each kernel spread over it, over the same counts, within the
  range the page prints.
"""
import re
import warnings

import numpy as np

import cosim
from conftest import CASES
from cosim.studies.roundoff import spread
from cosim.studies.verify import HardCase, reference_step
from documented import ROOT, flat

THREE_MASS = CASES / "three_mass.toml"
PAGE = "docs/schemes.md"


def _runs(monkeypatch, case, t_end, copies, reference=1, extra=()):
    """The numpy reference on the scene and ``reference - 1`` moved copies,
    and the compiled kernel on the scene and ``copies - 1`` moved copies."""
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for kernel, n in (("numpy", reference), ("compiled", copies)):
            monkeypatch.setenv("COSIM_KERNEL", kernel)
            scene = cosim.load_scene(THREE_MASS, case.variant,
                                     overrides=case.overrides(t_end) + list(extra),
                                     scheme=case.scheme)
            out[kernel] = [cosim.simulate(s) for s in spread(scene, n)]
    return out["numpy"], out["compiled"]


def _onsets(res, contact="C"):
    return np.array([iv[0] for iv in res.summary["contacts"][contact]["intervals"]])


def _case(scheme, placement, factor, forced=False):
    ref = reference_step(CASES, "ms0.01", scheme, placement)
    return HardCase("ms0.01", scheme, placement, ref * factor, factor, forced)


def test_a_stable_run_closes_c_as_often_in_both_kernels_and_nudged_copies(monkeypatch):
    (ref,), copies = _runs(monkeypatch, _case("gauss_seidel", "embedded", 10.0), 0.106, 5)
    assert ref.status == "finished" and all(c.status == "finished" for c in copies)
    counts = [r.summary["contacts"]["C"]["count"] for r in [ref, *copies]]
    assert counts[0] >= 3 and len(set(counts)) == 1, counts
    nudge = max(np.abs(_onsets(c) - _onsets(copies[0])).max() for c in copies[1:])
    kernels = np.abs(_onsets(ref) - _onsets(copies[0])).max()
    assert nudge > 0, "the copies must move the onsets, else the bound is none"
    assert kernels <= 2 * nudge, (kernels, nudge)


def test_a_forced_unstable_run_differs_in_its_count_as_nudged_copies_do(monkeypatch):
    text = flat((ROOT / PAGE).read_text())
    said = re.search(r"nine copies moved by up to 6 ulps close C (\d+) to (\d+) times before "
                     r"the stop under either kernel, and stop up to ([0-9.]+) ms apart", text)
    assert said, f"{PAGE} no longer says the copies' spread"
    lo, hi, apart = int(said[1]), int(said[2]), float(said[3]) * 1e-3
    # 0.13's steps: landed on, the onsets make this run's count robust (13 in
    # every copy at 10x, bounded at 5x), and the page's case is the one before
    refs, copies = _runs(monkeypatch, _case("jacobi", "coupler", 5.0, forced=True), None, 9, 9,
                         extra=["scheme.land_onsets=false"])
    # the verdict is not round-off's: every run is stopped by the guard, for energy growth
    assert all(r.status == "failed" and "the energy grew by" in r.message
               for r in refs + copies), [r.message for r in refs + copies]
    # the count before the stop is: each kernel's copies spread over it, over
    # the same counts (the two ranges overlap), within the range the page prints
    counts = {k: [r.summary["contacts"]["C"]["count"] for r in rr]
              for k, rr in (("numpy", refs), ("compiled", copies))}
    for kernel, seen in counts.items():
        assert min(seen) < max(seen), (kernel, seen)
        assert lo <= min(seen) and max(seen) <= hi, (kernel, seen, (lo, hi))
    assert max(map(min, counts.values())) <= min(map(max, counts.values())), counts
    stops = [r.summary["t_end"] for r in refs + copies]
    assert abs((max(stops) - min(stops)) - apart) <= 0.05e-3, (stops, apart)   # half a unit
