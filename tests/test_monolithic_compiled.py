"""The monolithic reference's compiled right-hand side (``cosim.core._stacked``)
against the Python one it reproduces (``COSIM_KERNEL=numpy`` runs the latter).

Two levels:

* the right-hand side and the event values at random states and at the
  states a run visits (followers in touch, contacts closed, joint effects),
  block by block within a bound that says where round-off can enter;
* whole runs both ways: the same contact counts (under few-ulp nudges of the
  initial state too), and series within a bound.  Two runs of one adaptive
  solver whose right-hand sides differ by round-off differ by the solver's
  own sensitivity to round-off, not by the tolerance: where its step choices
  do not branch the series agree to ``SERIES_RTOL`` times the solver's rtol
  of their largest value; where they branch (beam_impact: its high modes)
  the bound is the spread of the Python run's own copies moved by one ulp.
"""
from __future__ import annotations

import os
import warnings

import numpy as np
import pytest

import cosim
from conftest import CASES
from cosim.core.schemes.monolithic import _compiled_rhs, _python_rhs
from cosim.studies.roundoff import spread

pytest.importorskip("cosim.core._stacked")

EPS = np.finfo(float).eps
#: a series' difference between the runs, in units of the solver's rtol of
#: its largest value (three_mass f100, 9 impacts of C: 30 measured)
SERIES_RTOL = 100.0
#: the quantities compared (``energy/dissipated`` of a conservative scene is
#: round-off itself, ``peak/*`` a running maximum sampled at events)
SERIES = ("gap/", "force/", "q/", "dq/", "energy/total")

#: scenes (variant, overrides) the right-hand sides are compared on
SCENES = {
    "three_mass f100": ("three_mass", "f100", ()),
    "beam_impact": ("beam_impact", None, ()),
    "manipulator_wall mu0.03": ("manipulator_wall", "mu0.03", ()),
    "spring_drop kelvin_voigt": ("spring_drop", "kelvin_voigt", ()),
    "spring_drop hunt_crossley": ("spring_drop", None, (
        'contacts.wall.law={type="hunt_crossley", contact_stiffness=1e9, exponent=1.5, '
        'hysteresis_damping=0.3}',)),
}


def _scene(name, variant, overrides=(), kernel="compiled"):
    os.environ["COSIM_KERNEL"] = kernel
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return cosim.load_scene(CASES / f"{name}.toml", variant, list(overrides), "monolithic")


@pytest.fixture(autouse=True)
def _kernel_env():
    before = os.environ.get("COSIM_KERNEL")
    yield
    if before is None:
        os.environ.pop("COSIM_KERNEL", None)
    else:
        os.environ["COSIM_KERNEL"] = before


def _blocks(system):
    """(name, slice) of each part of the stacked derivative."""
    off = system.stacked()
    n_x, nc = int(off[-1]), system.n_contacts
    out = [(sub.name, slice(off[s], off[s + 1])) for s, sub in enumerate(system.subsystems)]
    return out + [("force", slice(n_x, n_x + nc)), ("dissipated", slice(n_x + nc, n_x + 2 * nc)),
                  ("work", slice(n_x + 2 * nc, n_x + 3 * nc)),
                  ("ledger", slice(n_x + 3 * nc, n_x + 3 * nc + 2))]


class Comparison:
    """Both right-hand sides of one system, and the bound of their difference."""

    def __init__(self, system, active):
        self.system, self.active = system, active
        self.contact_state, self.python = _python_rhs(system, active)
        self.compiled = _compiled_rhs(system, active)
        assert self.compiled is not None
        self.laws = [ln.contact.law for ln in system.links]

    def check(self, t, y):
        """Assert the compiled derivative and event values at ``(t, y)``
        within bounds; return the worst ratio of difference to bound."""
        got, ref = self.compiled.rhs(t, y), self.python(t, y)
        _, d, dd, f = self.contact_state(y)
        # Penetrations are differences of port positions of order 1 m summed
        # in another order: they may differ by a few ulps of the positions,
        # not of d.  A force moves by what the law makes of such a move
        # (k delta_d + c delta_dd for Kelvin-Voigt; taken here on the law
        # itself, twice over), a power by that times |dd|.
        outs = self.system.outputs([y[a:b] for a, b in zip(self.system.stacked()[:-1],
                                                           self.system.stacked()[1:])])
        scale_x = max(float(np.max(np.abs(o[0]))) for o in outs if o[0].size)
        scale_v = max(float(np.max(np.abs(o[1]))) for o in outs if o[1].size)
        delta_d, delta_dd = 16 * EPS * scale_x, 16 * EPS * scale_v
        df = np.array([2 * max(abs(float(law.force_active(d[c] + i * delta_d, dd[c] + j * delta_dd))
                                   - float(law.force_active(d[c], dd[c])))
                               for i in (-1, 1) for j in (-1, 1))
                       for c, law in enumerate(self.laws)])
        worst = 0.0
        for name, sl in _blocks(self.system):
            a, b = got[sl], ref[sl]
            # sums and products of the same operands in another order: a few
            # ulps of the block's largest term
            bound = 1e-13 * np.max(np.abs(b), initial=0.0) + np.zeros(b.shape)
            sub = next((s for s in self.system.subsystems if s.name == name), None)
            if sub is not None and hasattr(sub, "n_dof") and sub.n_dof:
                # accelerations: two backward-stable solves of M (Cholesky, LU)
                # each within a small multiple of eps cond(M) of the exact one
                n = sub.n_dof
                x = y[sl]
                M = sub._compiled().evaluate(x)[0]
                acc = slice(n, 2 * n)
                bound[acc] = 4 * EPS * np.linalg.cond(M) * np.max(np.abs(b[acc]))
            if sub is not None and sl.stop > sl.start:
                # and what the contact forces' own bounds move them by
                x, zero = y[sl], np.zeros(self.system.n_rows)
                s_i = self.system.subsystems.index(sub)
                base = sub.derivatives(t, x, self.system.port_forces(s_i, zero))
                for c in range(self.system.n_contacts):
                    e = zero.copy()
                    e[c] = df[c]
                    bound += np.abs(sub.derivatives(t, x, self.system.port_forces(s_i, e)) - base)
            if name == "force":
                bound = bound + df
            elif name in ("dissipated", "work"):
                bound = bound + df * np.abs(dd[:self.system.n_contacts]) + np.abs(f) * delta_dd
            diff = np.abs(a - b)
            assert np.all(diff <= bound), (name, diff, bound)
            with np.errstate(divide="ignore", invalid="ignore"):
                r = np.where(bound > 0, diff / np.where(bound > 0, bound, 1.0), 0.0)
            worst = max(worst, float(np.max(r, initial=0.0)))
        # the event values: each law's switch and the penetration rate
        ev = self.compiled.events(y)
        nc = self.system.n_contacts
        sw = np.array([float(ln.contact.law.switch(d[c], dd[c]))
                       for c, ln in enumerate(self.system.links)])
        dsw = np.array([2 * max(abs(float(law.switch(d[c] + i * delta_d, dd[c] + j * delta_dd))
                                    - sw[c]) for i in (-1, 1) for j in (-1, 1))
                        for c, law in enumerate(self.laws)])
        assert np.all(np.abs(ev[:nc] - sw) <= dsw + 1e-13 * np.abs(sw))
        assert np.all(np.abs(ev[nc:] - dd) <= delta_dd + 1e-13 * np.abs(dd))
        return worst


@pytest.mark.parametrize("key", list(SCENES))
def test_compiled_rhs_matches_python_at_random_states(key):
    name, variant, over = SCENES[key]
    system, _ = _scene(name, variant, over).build("monolithic")
    nc = system.n_contacts
    active = np.zeros(nc, dtype=bool)
    cmp = Comparison(system, active)
    y0 = np.concatenate([s.x for s in system.subsystems] + [np.zeros(3 * nc + 2)])
    rng = np.random.default_rng(7)
    pressed = np.zeros(nc, dtype=bool)
    for _ in range(200):
        # moves from small to as large as the state itself, so that every
        # contact is found open and pressed
        size = 10.0 ** rng.uniform(-3, 0.3)
        y = y0 + rng.normal(size=y0.size) * size * (np.abs(y0) + 1e-3)
        active[:] = rng.random(nc) < 0.7
        cmp.check(float(rng.uniform(0, 0.2)), y)
        pressed |= cmp.contact_state(y)[3][:nc] > 0
    rigid = np.array([ln.contact.law.rigid for ln in system.links])
    assert np.all(pressed | rigid), f"contacts never pressed: {pressed}"


class _Probe:
    """Stands in for the compiled right-hand side in a run: checks it against
    the Python one at every ``every``-th state the solver visits."""

    def __init__(self, system, active, every):
        self.cmp = Comparison(system, active)
        self.every, self.n, self.checked, self.worst = every, 0, 0, 0.0
        self.closed = np.zeros(system.n_contacts, dtype=bool)

    def rhs(self, t, y):
        self.n += 1
        if self.n % self.every == 0:
            self.worst = max(self.worst, self.cmp.check(t, y))
            self.checked += 1
            self.closed |= self.cmp.active
        return self.cmp.compiled.rhs(t, y)

    def events(self, y):
        return self.cmp.compiled.events(y)


@pytest.mark.parametrize("name,variant,over,every", [
    ("three_mass", "f100", (), 7),
    # C strikes the beam at about 0.103 s: the struck point follows C
    ("beam_impact", None, ("t_end=0.105", "subsystems.beam.modes.cutoff_hz=3000"), 11),
])
def test_compiled_rhs_matches_python_along_a_run(monkeypatch, name, variant, over, every):
    import cosim.core.schemes.monolithic as mono
    probes = []

    def probe(system, active):
        probes.append(_Probe(system, active, every))
        return probes[-1]

    monkeypatch.setattr(mono, "_compiled_rhs", probe)
    res = cosim.simulate(_scene(name, variant, over), estimate=False)
    assert res.success, res.message
    p, = probes
    assert p.checked > 100
    assert p.closed.all(), f"contacts never closed at a checked state: {p.closed}"
    assert p.worst <= 1.0


def _runs(name, variant, over, kernel, copies=1):
    scene = _scene(name, variant, over, kernel)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return [cosim.simulate(s, scheme="monolithic", estimate=False)
                for s in spread(scene, copies)]


def _counts(res):
    return {c: v["count"] for c, v in res.summary["contacts"].items()}


def _differences(a, b):
    """Per series: the largest difference at the output times both share,
    and the series' largest magnitude."""
    _, ia, ib = np.intersect1d(a.series["t"], b.series["t"], return_indices=True)
    assert ia.size >= 1000          # the regular output times, events aside
    out = {}
    for key in b.series:
        if key.startswith(SERIES):
            va, vb = np.asarray(a.series[key]), np.asarray(b.series[key])
            out[key] = (float(np.max(np.abs(va[ia] - vb[ib]))), float(np.max(np.abs(vb))))
    return out


@pytest.mark.parametrize("name,variant,over", [
    ("three_mass", "f1", ()),
    ("three_mass", "f100", ()),
    ("spring_drop", "undamped", ()),
    ("spring_drop", "kelvin_voigt", ()),
    ("manipulator_wall", "mu0.03", ()),
])
def test_monolithic_runs_agree_both_ways(name, variant, over):
    compiled, = _runs(name, variant, over, "compiled")
    python, = _runs(name, variant, over, "numpy")
    assert compiled.success and python.success
    assert _counts(compiled) == _counts(python)
    # the count is no accident of the last bit
    for copy in _runs(name, variant, over, "compiled", copies=3)[1:]:
        assert _counts(copy) == _counts(python)
    rtol = _monolithic_rtol(name, variant, over)
    for key, (diff, scale) in _differences(compiled, python).items():
        assert diff <= SERIES_RTOL * rtol * scale, (key, diff / (rtol * scale))
    for c, ref in python.summary["contacts"].items():
        got = compiled.summary["contacts"][c]
        for q in ("peak_penetration", "impulse"):
            assert got[q] == pytest.approx(ref[q], rel=SERIES_RTOL * rtol, abs=1e-300), (c, q)


def _monolithic_rtol(name, variant, over) -> float:
    """The rtol the scene's monolithic run uses."""
    system, sch = _scene(name, variant, over).build("monolithic")
    return float(sch.rtol)


def test_beam_impact_monolithic_agrees_within_its_round_off_spread():
    # The beam's high modes make the solver's step choices branch under
    # round-off: the Python run differs from its own copies moved by one ulp
    # by about 1e3 rtol, and those copies agree with the compiled run's to
    # some 10 rtol.  So the bound is that spread, not the tolerance.
    over = ("t_end=0.105", "subsystems.beam.modes.cutoff_hz=3000")
    compiled, *compiled_copies = _runs("beam_impact", None, over, "compiled", copies=3)
    python, *copies = _runs("beam_impact", None, over, "numpy", copies=3)
    assert _counts(compiled) == _counts(python) == {"A": 2, "B": 1, "C": 1}
    for copy in compiled_copies:
        assert _counts(copy) == _counts(python)
    spreads = [_differences(c, python) for c in copies]
    rtol = _monolithic_rtol("beam_impact", None, over)
    for key, (diff, scale) in _differences(compiled, python).items():
        allowed = max(3 * max(s[key][0] for s in spreads), SERIES_RTOL * rtol * scale)
        assert diff <= allowed, (key, diff, allowed)


def test_numpy_kernel_runs_the_python_rhs(monkeypatch):
    import cosim.core.schemes.monolithic as mono
    seen = []
    real = mono._compiled_rhs
    monkeypatch.setattr(mono, "_compiled_rhs", lambda s, a: seen.append(real(s, a)) or seen[-1])
    _runs("spring_drop", None, (), "numpy")
    _runs("spring_drop", None, (), "compiled")
    assert seen[0] is None and seen[1] is not None


def test_a_law_the_kernels_do_not_know_runs_the_python_rhs():
    from couplers.laws import LinearLaw
    from cosim.core.links import ContactLink
    from cosim.core.system import CoupledSystem
    system, _ = _scene("spring_drop", None).build("monolithic")
    assert _compiled_rhs(system, np.zeros(1, dtype=bool)) is not None

    class OwnLaw(LinearLaw):            # a user's own law: the kernels do not know it
        pass

    ln = system.links[0]
    own = CoupledSystem(system.subsystems, [ContactLink(
        type(ln.contact)(ln.contact.name, OwnLaw(1e6), ln.contact.normal), ln.sub_a, ln.port_a,
        ln.sub_b, ln.port_b, "coupler", False, None, None)])
    assert _compiled_rhs(own, np.zeros(1, dtype=bool)) is None
