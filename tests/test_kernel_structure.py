"""The compiled structure step (``cosim.sides._structure_step``) against the numpy reference.

Every shipped scene and variant runs both ways in ``tests/test_kernel.py``
(both sides' kernels, and there every structure is checked to have stepped
compiled).  Here: one step of a chain whose spring touches and releases inside
it, value by value; the compiled rank-one update; rollback; the CLI both ways.  The
extension must have been built: no test here skips without it.
"""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

import fem
from conftest import CASES, ROOT
from cosim.sides.fem import StructureSubsystem
from cosim.core.subsystem import StepInput
from couplers import LinearLaw, PointContact

RTOL = 1e-10

#: the modules the compiled structure step is built of (split by concept, each
#: extending or calling the one before in C through its .pxd)
STRUCTURE_MODULES = ("_rank_one", "_structure_modes", "_structure_contacts", "_structure_step")


def test_the_extension_is_built():
    """CI must fail, not fall back, when the kernel did not build: every module
    it is made of, the step's classes built on one another, and the names a
    host reads from ``_structure_step`` the pieces' own."""
    import importlib
    mods = {name: importlib.import_module(f"cosim.sides.{name}") for name in STRUCTURE_MODULES}
    k = mods["_structure_step"]
    assert [c.__name__ for c in k.StructureStep.__mro__[:3]] == [
        "StructureStep", "ContactPhases", "ModalResponse"]
    assert k.StructureStep.__mro__[1] is mods["_structure_contacts"].ContactPhases
    assert k.StructureStep.__mro__[2] is mods["_structure_modes"].ModalResponse
    assert k.StalledStep is mods["_structure_contacts"].StalledStep
    assert k.rank_one_eigh is mods["_rank_one"].rank_one_eigh
    assert k.STEP_API == 3 and k.MAX_SEGMENTS == 10000


def test_compiled_rank_one_update_matches_the_reference():
    """Eigenpairs of diag(d) + z z^T: sorted and unsorted d, a zero entry of
    z (deflation), scales over six decades, two equal entries of d that z
    couples (rotated apart); declined where the reference declines."""
    from cosim.sides._structure_step import rank_one_eigh as compiled
    from fem.rank_one import rank_one_eigh as reference
    rng = np.random.default_rng(7)
    solved = 0
    for trial in range(200):
        m = int(rng.integers(1, 40))
        d = rng.uniform(0.0, 1e6, m)
        if trial % 3:
            d = np.sort(d)
        z = rng.normal(size=m) * 10.0 ** rng.uniform(-3, 3)
        if trial % 5 == 0:
            z[rng.integers(0, m)] = 0.0
        a, b = reference(d, z), compiled(d, z)
        assert (a is None) == (b is None), trial
        if a is not None:
            solved += 1
            np.testing.assert_allclose(b[0], a[0], rtol=0, atol=1e-13 * np.abs(a[0]).max())
            np.testing.assert_allclose(b[1], a[1], rtol=0, atol=1e-12)
    assert solved > 150
    # equal entries that z couples: rotated apart by both, alike
    d = np.array([1.0, 2.0, 2.0, 5.0])
    (la, Va), (lb, Vb) = reference(d, np.ones(4)), compiled(d, np.ones(4))
    np.testing.assert_allclose(lb, la, rtol=0, atol=1e-13 * 8)
    np.testing.assert_allclose(Vb, Va, rtol=0, atol=1e-12)


# ------------------------------------------------------------------ one step
def _chain_with_spring():
    """Two 0.1 kg masses on 1e5 N/m springs, the top one rising at 1 m/s
    towards a fixed point 0.1 mm above it, with a 1e6 N/m linear spring:
    it touches after 0.1 ms and leaves about 1 ms later."""
    s = fem.Chain((0.1, 0.1), (1e5, 1e5), spacing=0.05).assemble()
    sub = StructureSubsystem("chain", s, fem.modes(s), {"top": 0}, v0=np.ones(2))
    contact = PointContact("c", LinearLaw(1e6), (0.0, 1.0))
    sub.embed_contact(contact, 0, -1.0, (0.0, 1e-4))
    return sub


def _one_step(monkeypatch, kernel):
    monkeypatch.setenv("COSIM_KERNEL", kernel)
    sub = _chain_with_spring()
    coeffs = np.zeros((2, 1, 2))
    coeffs[:, 0, 1] = (-20.0, 35.0)          # a port force, linear over the step [N]
    h = 3e-3
    sub.step(0.0, h, StepInput(0.0, h, coeffs))
    return sub


def test_one_step_with_a_touch_and_a_release_matches_the_reference(monkeypatch):
    ref = _one_step(monkeypatch, "numpy")
    com = _one_step(monkeypatch, "compiled")
    assert ref.kernel == "numpy" and com.kernel == "compiled"
    # the step holds a touch and a release of the spring
    assert [(j, on) for _, j, on in ref.switch_log] == [(0, True), (0, False)]
    assert [(j, on) for _, j, on in com.switch_log] == [(0, True), (0, False)]
    t_ref = [t for t, _, _ in ref.switch_log]
    t_com = [t for t, _, _ in com.switch_log]
    assert 0 < t_ref[0] < t_ref[1] < 3e-3
    np.testing.assert_allclose(t_com, t_ref, rtol=0, atol=1e-15)
    for a, b in [(ref.x, com.x), (ref.aux, com.aux), (ref.port_moments, com.port_moments)]:
        assert np.abs(a).max() > 0
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-12 * np.abs(a).max())
    # the impulse is the spring's, and the first moment lies inside the contact
    impulse, _, moment, work = ref.embedded_quadratures()[0]
    assert impulse > 0 and t_ref[0] < moment / impulse < t_ref[1]
    # the located peak (issue 19): the kernel raises the host's `peak` as the
    # reference does, to the penetration where the rate falls through zero
    assert ref.peak[0] > 0
    np.testing.assert_allclose(com.peak, ref.peak, rtol=1e-12, atol=0)


def _probed_peaks(sub, h):
    """The spring's largest penetration seen on the switch search's probes of
    one step from a fresh chain (``n = max(ceil(2 L omega_max), 2)`` instants
    per segment, as the reference places them), without locating it."""
    from cosim.sides import fem as structure
    seen = []
    original = structure.StructureSubsystem._segment_peaks

    def spy(self, tc, seg, active, taus, D, V):
        seen.append(float(np.max(D[:, 0])))
        return original(self, tc, seg, active, taus, D, V)

    structure.StructureSubsystem._segment_peaks = spy
    try:
        sub.step(0.0, h)
    finally:
        structure.StructureSubsystem._segment_peaks = original
    return max(seen)


def test_the_kernel_locates_the_peak_between_probes(monkeypatch):
    """The peak lies between the probes of the switch search, where the
    rate falls through zero: both kernels find it there, above every probed
    value, and agree to round-off."""
    monkeypatch.setenv("COSIM_KERNEL", "numpy")
    probed = _probed_peaks(_chain_with_spring(), 3e-3)
    ref = _chain_with_spring()
    ref.step(0.0, 3e-3)
    monkeypatch.setenv("COSIM_KERNEL", "compiled")
    com = _chain_with_spring()
    com.step(0.0, 3e-3)
    assert com.kernel == "compiled"
    assert ref.peak[0] > probed * (1 + 1e-9)
    np.testing.assert_allclose(com.peak, ref.peak, rtol=1e-12, atol=0)


def test_a_long_step_probes_without_a_cap(monkeypatch):
    """A step of 0.6 s over the chain: 2 L omega_max asks for about 1900
    probes, and the spring's contacts last 0.39 ms, shorter than the 1.2 ms
    between 512 probes, the count the kernel used to stop at.  Every touch
    and release, the state and the peak agree with the reference."""
    h = 0.6
    out = {}
    for kernel in ("numpy", "compiled"):
        monkeypatch.setenv("COSIM_KERNEL", kernel)
        sub = _chain_with_spring()
        sub.step(0.0, h)
        assert sub.kernel == kernel
        out[kernel] = sub
    ref, com = out["numpy"], out["compiled"]
    times = np.array([t for t, _, _ in ref.switch_log])
    assert [on for _, _, on in ref.switch_log] == [True, False] * (len(times) // 2)
    shortest = float(np.min(times[1::2] - times[0::2]))
    assert len(times) > 100 and shortest < h / 512, (len(times), shortest)
    assert [(j, on) for _, j, on in com.switch_log] == [(j, on) for _, j, on in ref.switch_log]
    np.testing.assert_allclose([t for t, _, _ in com.switch_log], times, rtol=0, atol=1e-12)
    np.testing.assert_allclose(com.x, ref.x, rtol=0, atol=1e-9 * np.abs(ref.x).max())
    np.testing.assert_allclose(com.aux, ref.aux, rtol=0, atol=1e-9 * np.abs(ref.aux).max())
    np.testing.assert_allclose(com.peak, ref.peak, rtol=1e-10, atol=0)


def test_the_kernel_raises_the_peak_array_the_host_holds_now(monkeypatch):
    """The recorder resets ``peak`` in place (take_peaks), set_state writes
    it in place, and a host may rebind it: the kernel raises whichever array
    the host holds at the step, never one it kept."""
    monkeypatch.setenv("COSIM_KERNEL", "compiled")
    sub = _chain_with_spring()
    saved = sub.get_state()
    sub.step(0.0, 3e-3)
    first = float(sub.peak[0])
    assert first > 0
    assert sub.take_peaks()[0] == first and sub.peak[0] == 0.0
    sub.set_state(saved)                     # the saved peak: 0
    assert sub.peak[0] == 0.0
    old = sub.peak
    sub.peak = np.zeros(1)                   # rebound
    sub.step(0.0, 3e-3)
    assert sub.peak[0] == first and old[0] == 0.0
    # rolled back, a step that ends before the touch (at 0.1 ms) raises nothing
    sub.set_state(saved)
    sub.step(0.0, 5e-5)
    assert sub.switch_log == [] and sub.peak[0] == 0.0


def test_a_rolled_back_step_is_taken_again_the_same_way(monkeypatch):
    """get_state / set_state carry the kernel's view of the closed springs."""
    monkeypatch.setenv("COSIM_KERNEL", "compiled")
    sub = _chain_with_spring()
    saved = sub.get_state()
    sub.step(0.0, 3e-3)
    first = (sub.x.copy(), sub.aux.copy(), list(sub.switch_log))
    sub.set_state(saved)
    sub.step(0.0, 1e-3)
    sub.set_state(saved)
    sub.step(0.0, 3e-3)
    np.testing.assert_array_equal(sub.x, first[0])
    np.testing.assert_array_equal(sub.aux, first[1])
    assert sub.switch_log == first[2]


def test_the_reference_is_chosen_by_cosim_kernel_numpy(monkeypatch):
    monkeypatch.setenv("COSIM_KERNEL", "numpy")
    sub = _chain_with_spring()
    sub.step(0.0, 1e-3)
    assert sub.kernel == "numpy"


# --------------------------------------------------------- as a user runs it
def test_cli_runs_a_structure_scene_the_same_with_either_kernel(tmp_path):
    """`COSIM_KERNEL=numpy cosim run ...` and the default give the same run."""
    runs = {}
    for kernel in ("numpy", "compiled"):
        out = tmp_path / kernel
        env = {**os.environ, "COSIM_KERNEL": kernel}
        proc = subprocess.run([sys.executable, "-m", "cosim.cli", "run",
                               str(CASES / "rod_impact.toml"), "--out", str(out), "--quiet"],
                              capture_output=True, text=True, env=env, cwd=ROOT)
        assert proc.returncode == 0, proc.stderr
        assert "not built" not in proc.stderr
        assert (out / "summary.json").is_file() and (out / "series.npz").is_file()
        runs[kernel] = (json.loads((out / "summary.json").read_text()),
                        dict(np.load(out / "series.npz")))
    (s_ref, x_ref), (s_com, x_com) = runs["numpy"], runs["compiled"]
    assert s_com["contacts"]["wall"]["count"] == s_ref["contacts"]["wall"]["count"] >= 1
    for key, a in x_ref.items():
        scale = max(float(np.abs(a).max(initial=0.0)), 1e-300)
        assert float(np.abs(x_com[key] - a).max(initial=0.0)) <= RTOL * scale, key


def _beam_with_moving_probe(monkeypatch, kernel):
    """A pinned beam pushed up at a probe that moves along it each step, into
    a spring hosted at another point: the kernel must see the moved row."""
    monkeypatch.setenv("COSIM_KERNEL", kernel)
    sec = fem.rectangular_section(0.04, 0.01)
    s = fem.Beam(1.0, 210e9, sec.second_moment, 7850.0, sec.area, 16, "pinned",
                 "pinned").assemble()
    sub = StructureSubsystem("beam", s, fem.modes(s), {"hit": 0.45, "probe": 0.3})
    sub.embed_contact(PointContact("c", LinearLaw(1e6), (0.0, 1.0)), 0, -1.0, (0.45, 2e-6))
    h = 2e-4
    out = []
    for k in range(12):
        sub.move_port(1, 0.3 + 0.02 * k)
        coeffs = np.zeros((1, 2, 2))
        coeffs[0, 1, 1] = 400.0                  # [N] up, at the probe
        sub.step(k * h, h, StepInput(k * h, h, coeffs))
        out.append(np.concatenate([sub.x, sub.aux, sub.port_moments.view(float).ravel()]))
    return sub, np.array(out)


def test_a_moved_port_is_seen_by_the_kernel(monkeypatch):
    ref, a = _beam_with_moving_probe(monkeypatch, "numpy")
    com, b = _beam_with_moving_probe(monkeypatch, "compiled")
    assert com.kernel == "compiled"
    assert ref.embedded_quadratures()[0, 0] > 0           # the spring closed
    np.testing.assert_allclose(b, a, rtol=0, atol=1e-10 * np.abs(a).max())


@pytest.mark.parametrize("kernel", ["numpy", "compiled"])
def test_a_touch_on_the_step_boundary_is_logged_at_the_step_start(monkeypatch, kernel):
    """Open at the end of a step, closed at the start of the next (the
    partner's motion is extrapolated anew each step): a touch at the start
    when the contact is closing; none when it is opening (the jump of the
    new extrapolation just after a release)."""
    monkeypatch.setenv("COSIM_KERNEL", kernel)
    logs = []
    for rate in (+0.5, -0.5):                    # the partner's velocity [m/s]
        sub = _chain_with_spring()               # top rising at 1 m/s, partner 0.1 mm up
        sub.step(0.0, 5e-5)                      # still open: 0.05 mm apart
        assert sub.switch_log == []
        gap = 1e-4 - (sub.outputs(sub.t, sub.x)[0][0, 1])
        e = sub._embedded[0]
        # the partner now 1 um below the top, moving at `rate` relative to it
        v_top = sub.outputs(sub.t, sub.x)[1][0, 1]
        e.set_motion(sub.t, 1e-4, np.array([complex(0.0, 1e-4 - gap - 1e-6),
                                            complex(0.0, 1e-4 * (v_top - rate))]))
        sub.step(sub.t, 1e-4)
        logs.append(sub.switch_log)
    closing, opening = logs
    assert closing[0][1:] == (0, True) and closing[0][0] == pytest.approx(5e-5, abs=1e-15)
    assert all(not (on and t == pytest.approx(5e-5, abs=1e-15)) for t, _, on in opening)


def test_a_kernel_built_from_older_sources_is_not_used(monkeypatch, caplog):
    """A source tree updated without rebuilding holds a kernel whose step
    takes other arguments: the reference steps instead, and says so once."""
    import logging

    import cosim.sides._structure_step as k
    from cosim.sides import fem as structure
    monkeypatch.setenv("COSIM_KERNEL", "compiled")
    monkeypatch.delattr(k, "STEP_API")           # as built before the interface was named
    monkeypatch.setattr(structure, "_stale_said", False)
    with caplog.at_level(logging.WARNING, logger="cosim.sides.fem"):
        subs = [_chain_with_spring() for _ in range(2)]
        for sub in subs:
            sub.step(0.0, 3e-3)
    assert [sub.kernel for sub in subs] == ["numpy", "numpy"]
    said = [r.getMessage() for r in caplog.records if "older sources" in r.getMessage()]
    assert said == ["the compiled kernel `cosim.sides._structure_step` was built from older sources "
                    f"(interface 1, these sources need {structure.STEP_API}): using the numpy "
                    "reference, which is "
                    "slower; rebuild it with `pip install .`"]
    assert subs[0].peak[0] > 0 and [on for _, _, on in subs[0].switch_log] == [True, False]


def test_a_stalled_compiled_step_is_redone_by_the_reference(monkeypatch, caplog):
    """Known defect: at contact steps of 100 us, three_mass f100's compiled
    chain step finds one switch again and again at t = 0.1112 s.  The kernel
    stops after MAX_SEGMENTS segments, the host restores the step and the
    numpy reference takes it, logged once at debug level (an internal matter,
    not printed); the run then matches the reference."""
    import logging

    import cosim
    from conftest import CASES
    over = ["scheme.contact_step=1e-4", "scheme.land_onsets=false"]   # where it stalled
    runs = {}
    for kernel in ("numpy", "compiled"):
        monkeypatch.setenv("COSIM_KERNEL", kernel)
        with caplog.at_level(logging.DEBUG, logger="cosim.sides.fem"):
            runs[kernel] = cosim.simulate(cosim.load_scene(CASES / "three_mass.toml", "f100",
                                                           overrides=over), estimate=False)
    stalled = [r for r in caplog.records if "segments in the step" in r.getMessage()]
    assert len(stalled) == 1 and "numpy reference" in stalled[0].getMessage()
    assert stalled[0].levelno == logging.DEBUG
    ref, com = runs["numpy"], runs["compiled"]
    assert com.success and ref.success
    for name, c in ref.summary["contacts"].items():
        assert com.summary["contacts"][name]["count"] == c["count"], name
    for key in ("q/chain/m1", "dq/robot/arm", "gap/C"):
        a, b = np.asarray(ref.series[key]), np.asarray(com.series[key])
        assert np.max(np.abs(a - b)) <= 1e-8 * np.max(np.abs(a)), key
