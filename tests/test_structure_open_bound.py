"""A structure's segments with every hosted contact open, stepped without
probes where a bound proves the contacts stay open.

The closed-form step probes a segment ``2 omega_max L`` times for a touch
(half a radian of the fastest mode apart: 252 probes of 28 modes per 1 ms
step of beam_impact's beam).  Where every contact is open, a bound of the
exact solution (:func:`fem.undamped_envelope`: the port's particular
polynomial plus the harmonics' amplitudes) decides first, in O(m), whether
any probe could find one closed; where none could, the segment ends as the
probes would have ended it.  Here: the envelope bounds the response and is
reached; the decision is sound on random segments of a beam and tight on a
single mode (both kernels); beam_impact gives the same run with and without
it, under both kernels and round-off copies.
"""
import functools
import warnings

import numpy as np
import pytest

import cosim
import fem
from conftest import CASES
from cosim.sides.fem import StructureSubsystem
from cosim.studies.roundoff import spread
from couplers import LinearLaw, PointContact
from fem.response import undamped_envelope, undamped_response

#: each series within this of its largest value (the same computation; bound,
#: not asserted bit-equal)
SERIES_RTOL = 1e-10


def _random_segment(rng, m):
    lam = np.sort(10.0 ** rng.uniform(2.0, 10.0, m))
    z0 = rng.normal(size=m) * 1e-4
    dz0 = rng.normal(size=m) * 1e-2
    a = rng.normal(size=(4, m)) * 10.0 ** rng.uniform(-2.0, 2.0, (4, 1))
    rows = rng.normal(size=(m, 3))
    return lam, z0, dz0, a, rows


def test_the_envelope_bounds_the_response_and_is_reached():
    """|z(tau) @ rows - Q(tau)| <= E on 20001 instants of [0, L], over ten
    random sets of modes (frequencies over eight decades) under cubic loads;
    E reached to 1e-6 by one undriven mode over a period; None with a rigid
    mode."""
    rng = np.random.default_rng(3)
    for _ in range(10):
        lam, z0, dz0, a, rows = _random_segment(rng, 12)
        L = 10.0 ** rng.uniform(-5.0, -2.0)
        Q, E, size = undamped_envelope(lam, z0, dz0, a, rows, L)
        tau = np.linspace(0.0, L, 20001)
        W, _ = undamped_response(lam, z0, dz0, a, tau, rows=rows)
        poly = (tau[:, None] ** np.arange(4)) @ Q
        assert np.all(np.abs(W - poly) <= E + 1e-12 * size)
        assert np.all(E <= size)
    lam = np.array([4e6])                   # omega 2000 rad/s: a period of 3.14 ms
    Q, E, _ = undamped_envelope(lam, [3e-4], [-0.8], np.zeros((1, 1)), np.ones((1, 1)), 3.2e-3)
    tau = np.linspace(0.0, 3.2e-3, 200001)
    W, _ = undamped_response(lam, [3e-4], [-0.8], np.zeros((1, 1)), tau, rows=np.ones((1, 1)))
    np.testing.assert_array_equal(Q, 0.0)
    assert np.abs(W).max() <= E[0] <= (1.0 + 1e-6) * np.abs(W).max()
    assert np.hypot(3e-4, 0.8 / 2000) == pytest.approx(E[0], rel=1e-15)
    assert undamped_envelope(np.array([0.0, 1e6]), np.zeros(2), np.zeros(2), np.zeros((1, 2)),
                             np.ones((2, 1)), 1e-3) is None


@functools.lru_cache(maxsize=1)
def _beam():
    """beam_impact's beam (32 elements) and its 28 modes below 20 kHz."""
    sec = fem.rectangular_section(0.04, 0.01)
    s = fem.Beam(1.0, 210e9, sec.second_moment, 7850.0, sec.area, 32, "pinned",
                 "pinned").assemble()
    return s, fem.modes(s, cutoff_hz=20000.0)


def _struck_beam(rng):
    """beam_impact's beam hosting C's spring at 0.45 m, its state a random
    vibration of about 0.1 mm."""
    sub = StructureSubsystem("beam", *_beam(), {"c": 0.45}, gravity=(0.0, -9.81))
    m = sub.n_modes
    sub.x[:m] = rng.normal(size=m) * 1e-4 / np.arange(1, m + 1) ** 2
    sub.x[m:] = rng.normal(size=m) * 1e-4 / np.arange(1, m + 1) * sub.omega
    contact = PointContact("C", LinearLaw(1.6e6), (0.0, 1.0))
    e = sub.embed_contact(contact, 0, -1.0, (0.45, 0.0))
    return sub, e


def test_a_segment_said_to_stay_open_has_no_penetration():
    """Random beam states, the partner descending at up to 2 m/s from 0 to
    3 mm above the beam's rest line, the port loaded by the weight and a
    random constant force, or (one trial in three) a random cubic one:
    wherever the reference's ``_stays_open`` spares a 1 ms segment its
    probes, the exact penetration sampled 10001 times stays negative.  Both
    answers occur.  (Under a cubic load the slow modes' particular
    polynomial and harmonic nearly cancel over 1 ms, so their envelope is
    loose and such segments are mostly probed, as before the bound.)"""
    rng = np.random.default_rng(11)
    said = {True: 0, False: 0}
    for trial in range(60):
        sub, e = _struck_beam(rng)
        m = sub.n_modes
        t, h = 0.0, 1e-3
        y0 = float(rng.uniform(0.0, 3e-3))
        e.set_motion(t, h, np.array([0.45 + 1j * y0, -1j * h * rng.uniform(0.0, 2.0)]))
        coeffs = rng.normal(size=(4, 1, 2)) * 5.0
        if trial % 3:
            coeffs[1:] = 0.0
        Gin = sub._modal_force(coeffs)
        Gin[0] += sub._g_modal
        active = (False,)
        lam, Psi, _ = sub._active_basis(active)
        seg = sub._segment(lam, Psi, sub.x[:m], sub.x[m:],
                           sub._segment_load(t, h, t, Gin, active))
        d0, _ = sub._gaps(t, [0.0], *sub._port_states(seg, [0.0]))
        if d0[0, 0] > 0:
            continue                        # closed at the start: not this bound's case
        ok = sub._stays_open(t, h, seg)
        said[ok] += 1
        if ok:
            # 0.013 rad of the fastest mode apart
            taus = np.linspace(0.0, h, 10001)
            d, _ = sub._gaps(t, taus, *sub._port_states(seg, taus))
            assert d.max() < 0.0, trial
    assert said[True] >= 15 and said[False] >= 15, said


def _one_mode(kernel, monkeypatch, reach):
    """One mass (omega 1000 rad/s) rising from rest position at 1 m/s
    (amplitude 1 mm at a quarter period) under a fixed point ``reach``
    times its amplitude above: one step of half a period."""
    monkeypatch.setenv("COSIM_KERNEL", kernel)
    s = fem.Chain((0.1,), (1e5,), spacing=0.05).assemble()
    sub = StructureSubsystem("mass", s, fem.modes(s), {"top": 0}, v0=np.ones(1))
    contact = PointContact("c", LinearLaw(1e6), (0.0, 1.0))
    sub.embed_contact(contact, 0, -1.0, (0.0, 1e-3 * reach))
    sub.step(0.0, np.pi / 1000.0, None)
    spared = sub._kernel.n_unprobed if sub._kernel else sub.n_unprobed
    return spared, sub.switch_log


@pytest.mark.parametrize("kernel", ["compiled", "numpy"])
def test_the_bound_is_tight_on_one_mode(kernel, monkeypatch):
    """A point 1e-6 of the amplitude out of reach is spared the probes; one
    1e-6 within reach is probed (the probes, seven half radians apart, then
    miss so small a touch, as they did before the bound); one at 0.9 of it is
    probed and its touch and release found."""
    assert _one_mode(kernel, monkeypatch, 1.0 + 1e-6) == (1, [])
    assert _one_mode(kernel, monkeypatch, 1.0 - 1e-6) == (0, [])
    spared, log = _one_mode(kernel, monkeypatch, 0.9)
    assert spared == 0 and [on for _, _, on in log] == [True, False]


def _beam_impact(kernel, monkeypatch, bound, overrides=(), copies=1):
    """Results of beam_impact (and its round-off copies) with the bound on
    or off, and the segments the beam spared its probes."""
    monkeypatch.setenv("COSIM_KERNEL", kernel)
    monkeypatch.setattr(StructureSubsystem, "bound_open", bound)
    built = []
    init = StructureSubsystem.__init__

    def spy(self, *args, **kw):
        init(self, *args, **kw)
        built.append(self)

    monkeypatch.setattr(StructureSubsystem, "__init__", spy)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = cosim.load_scene(CASES / "beam_impact.toml", overrides=list(overrides))
        out = []
        for s in spread(scene, copies):
            built.clear()
            res = cosim.simulate(s, estimate=False)     # the probes of this run counted
            (beam,) = built
            out.append((res, beam._kernel.n_unprobed if beam._kernel else beam.n_unprobed))
    monkeypatch.setattr(StructureSubsystem, "__init__", init)
    return out


def _same_run(a, b):
    assert a.summary["macro_steps"] == b.summary["macro_steps"]
    for name, c in a.summary["contacts"].items():
        assert b.summary["contacts"][name]["count"] == c["count"], name
    for key, x in a.series.items():
        x, y = np.asarray(x), np.asarray(b.series[key])
        scale = float(np.max(np.abs(x), initial=0.0))
        assert np.max(np.abs(x - y), initial=0.0) <= SERIES_RTOL * scale, key


@pytest.mark.parametrize("kernel,overrides", [("compiled", ("t_end=1",)),
                                              ("compiled", ()), ("numpy", ())])
def test_beam_impact_is_the_same_run_without_the_probes(kernel, monkeypatch, overrides):
    """beam_impact (0.13 s, and 1 s with the compiled kernel) with the bound
    and without it, for the scene and its +-1 ulp copies: same macro steps
    and contact counts, every series within 1e-10 of its largest value; over
    a third of the steps (the free flight's 1 ms steps) spared their probes,
    the same ones by both kernels."""
    on = _beam_impact(kernel, monkeypatch, True, overrides, copies=3)
    off = _beam_impact(kernel, monkeypatch, False, overrides, copies=3)
    for (a, spared), (b, none) in zip(on, off):
        _same_run(a, b)
        assert none == 0
        assert spared > a.summary["macro_steps"] / 3
    if kernel == "numpy":
        compiled = _beam_impact("compiled", monkeypatch, True, overrides)
        assert compiled[0][1] == on[0][1]
