"""The compiled steps against the numpy reference.

Each side's step runs in compiled code (``cosim.sides._multibody_step`` and
``cosim.sides._structure_step``); the numpy modules stay the reference.  Here both run every shipped scene and variant: the
contact interval counts and impacts agree exactly, every series to 1e-10 of its
largest magnitude (gaps and forces: of the scene's largest gap or force, since a
gap is the difference of two positions and a contact may barely touch).  The compiled kernel must be built: this file fails (never
skips) where it is not, so CI cannot pass on the reference alone.
"""
import tomllib

import numpy as np
import pytest

import cosim
from cosim.core.schemes import sampled
from cosim.sides.multibody import MultibodySubsystem
from cosim.sides.fem import StructureSubsystem
from conftest import CASES

SERIES_RTOL = 1e-10

#: shorter runs of the long scenes, each still past its first contacts [s]
T_END = {"ground_multicontact": 0.05, "ground_multicontact_strike": 0.03, "brachiation": 0.3,
         "manipulator_wall": 0.45}


def _cases():
    for path in sorted(CASES.glob("*.toml")):
        variants = tomllib.loads(path.read_text()).get("variants", {})
        for v in [None, *sorted(variants)]:
            yield pytest.param(path, v, id=f"{path.stem}-{v or 'default'}")


def _run(monkeypatch, kernel, path, variant, structure_kernels=None):
    """One run with ``COSIM_KERNEL=kernel``; the structures' compiled steps
    that were built are appended to ``structure_kernels``."""
    monkeypatch.setenv("COSIM_KERNEL", kernel)
    # the steps as the macro loop takes them: the sampled path, which an
    # adaptive side takes across output points, is held to the loop in
    # tests/test_sampled.py
    monkeypatch.setattr(sampled, "ENABLED", False)
    over = [f"t_end={T_END[path.stem]}"] if path.stem in T_END else []
    scene = cosim.load_scene(path, variant, overrides=over)
    if structure_kernels is None:
        return cosim.simulate(scene, estimate=False)
    original = StructureSubsystem._build_kernel

    def spy(self):
        k = original(self)
        structure_kernels.append(k)
        return k

    monkeypatch.setattr(StructureSubsystem, "_build_kernel", spy)
    try:
        return cosim.simulate(scene, estimate=False)
    finally:
        monkeypatch.setattr(StructureSubsystem, "_build_kernel", original)


def test_compiled_kernel_is_built():
    from cosim.sides import _multibody_step  # noqa: F401  (ImportError fails CI)
    from cosim.sides.kernel import compiled_module
    assert compiled_module("_multibody_step") is not None


def test_kernel_switch(monkeypatch):
    from cosim.sides.kernel import kernel_choice
    monkeypatch.setenv("COSIM_KERNEL", "numpy")
    assert kernel_choice() == "numpy"
    monkeypatch.setenv("COSIM_KERNEL", "fortran")
    with pytest.raises(ValueError, match="`COSIM_KERNEL` must be one of"):
        kernel_choice()


def _series_errors(ref, other):
    """Largest difference of each series, over the series' largest magnitude
    (gaps and forces: over the scene's largest gap or force, since a gap is
    the difference of two positions and a contact may barely touch)."""
    peak = {key: float(np.max(np.abs(ref.series[key]), initial=0.0)) for key in ref.series}
    errors = {}
    for key in ref.series:
        a, b = np.asarray(ref.series[key]), np.asarray(other.series[key])
        family = key.split("/")[0] + "/"
        scale = (max(peak[k] for k in peak if k.startswith(family))
                 if family in ("gap/", "force/") else peak[key])
        errors[key] = float(np.max(np.abs(a - b), initial=0.0)) / max(scale, 1e-300)
    return errors


def _cholesky_accelerations(M, F, J, u):
    from scipy.linalg import cho_factor, cho_solve
    return cho_solve(cho_factor(M), (J.conj().T @ u).real - F)


def _counts(res):
    return {name: c["count"] for name, c in res.summary["contacts"].items()}


def _run_cholesky(monkeypatch, path, variant):
    """The reference with another round-off in the operation the kernel
    changes most: the accelerations by Cholesky instead of LU."""
    monkeypatch.setattr(MultibodySubsystem, "_accelerations",
                        staticmethod(_cholesky_accelerations))
    return _run(monkeypatch, "numpy", path, variant)


@pytest.mark.parametrize("path,variant", list(_cases()))
def test_compiled_matches_reference(monkeypatch, path, variant):
    ref = _run(monkeypatch, "numpy", path, variant)
    built = []
    fast = _run(monkeypatch, "compiled", path, variant, built)
    # every structure steps compiled; each shipped one hosts one spring at
    # most, whose modes come from the compiled rank-one update, never numpy
    assert all(k is not None and k.n_host_bases == 0 for k in built), path.stem
    assert fast.status == ref.status and fast.message == ref.message
    assert fast.n_windows == ref.n_windows and fast.n_rejected == ref.n_rejected
    assert fast.n_iterations == ref.n_iterations
    counts = _counts(ref)
    if _counts(fast) != counts:
        # a train of grazing touches (three_mass ms0.01) is decided by
        # round-off: the reference itself, with another round-off, counts
        # otherwise.  There the compiled count must lie within that spread.
        other = _counts(_run_cholesky(monkeypatch, path, variant))
        for name, n in counts.items():
            spread = abs(other[name] - n)
            assert abs(_counts(fast)[name] - n) <= spread, (
                f"contact {name}: {_counts(fast)[name]} intervals compiled, {n} in the "
                f"reference, whose own round-off spread is {spread}")
        return
    for name, c in ref.summary["contacts"].items():
        np.testing.assert_allclose(np.ravel(fast.summary["contacts"][name]["intervals"]),
                                   np.ravel(c["intervals"]), rtol=0, atol=1e-9, err_msg=name)
    assert len(fast.summary["impacts"]) == len(ref.summary["impacts"])
    # communication points aimed at a predicted touch-down carry its round-off
    np.testing.assert_allclose(fast.t, ref.t, rtol=1e-12, atol=1e-15)
    assert set(fast.series) == set(ref.series)
    errors = _series_errors(ref, fast)
    loose = {k: e for k, e in errors.items() if e > SERIES_RTOL}
    if loose:
        # Some scenes amplify round-off: the reference itself, with another
        # round-off in its one changed operation (Cholesky instead of LU for
        # the accelerations), moves as far.  There the bound is ten times
        # that spread, measured here, never a fixed wider tolerance.
        spread = _series_errors(ref, _run_cholesky(monkeypatch, path, variant))
        for key, err in loose.items():
            assert spread[key] > SERIES_RTOL / 10, (
                f"{key}: compiled differs from the reference by {err:.2e}, though the "
                f"reference moves only {spread[key]:.2e} under another round-off")
            assert err <= 10 * spread[key], (
                f"{key}: compiled differs from the reference by {err:.2e}, over ten times "
                f"the reference's own round-off spread {spread[key]:.2e}")


def test_kernel_takes_the_steps_it_covers(monkeypatch):
    """Penalty and rigid contacts, joint drives (brachiation's PD drive)
    step in the kernel; with ``COSIM_KERNEL=numpy`` the reference steps."""
    from cosim.scene.build import build_system
    monkeypatch.setenv("COSIM_KERNEL", "compiled")
    for stem, expected in (("three_mass", "compiled"), ("spring_drop", "compiled"),
                           ("manipulator_wall", "compiled"), ("brachiation", "compiled")):
        system, _ = build_system(cosim.load_scene(CASES / f"{stem}.toml"))
        kinds = {s.kernel for s in system.subsystems if isinstance(s, MultibodySubsystem)}
        assert kinds == {expected}, stem
    monkeypatch.setenv("COSIM_KERNEL", "numpy")
    system, _ = build_system(cosim.load_scene(CASES / "three_mass.toml"))
    assert {s.kernel for s in system.subsystems if isinstance(s, MultibodySubsystem)} == {"numpy"}


def _random_tree_step(seed, effects=None):
    """A random 4-joint tree (mixed joints, gravity, two ports, a hosted
    Hunt-Crossley and a Kelvin-Voigt contact against moving partners)."""
    from couplers import PointContact
    from couplers.laws import HuntCrossleyLaw, KelvinVoigtLaw
    from multibody import Body, Joint, TreeModel
    from cosim.core.ode import RK4
    from cosim.core.subsystem import StepInput

    rng = np.random.default_rng(seed)
    bodies = [Body(f"b{i}", mass=rng.uniform(0.5, 2), inertia=rng.uniform(0.01, 0.1),
                   com=tuple(rng.uniform(-0.2, 0.2, 2))) for i in range(4)]
    joints = [Joint("j0", "prismatic", -1, axis=(1.0, 0.3)),
              Joint("j1", "revolute", 0, offset=(0.1, 0.0), angle=0.2),
              Joint("j2", "revolute", 1, offset=(0.3, 0.05)),
              Joint("j3", "prismatic", 1, offset=(0.0, 0.2), axis=(0.0, 1.0), angle=-0.4)]
    model = TreeModel(bodies, joints)
    ports = {"p": (2, (0.25, -0.1)), "r": (3, (0.1, 0.1))}
    sub = MultibodySubsystem("tree", model, rng.normal(size=4), rng.normal(size=4), ports,
                             gravity=(0.0, -9.81), integrator=RK4(max_step=1e-4, free_step=1e-3),
                             effects=effects)
    hc = HuntCrossleyLaw(contact_stiffness=2e5, exponent=1.5, hysteresis_damping=0.3)
    kv = KelvinVoigtLaw(contact_stiffness=1e5, contact_damping=40.0)
    x, _ = sub.outputs(0.0, sub.x)
    for port, law, name in ((0, hc, "c1"), (1, kv, "c2")):
        contact = PointContact(name=name, law=law, normal=(0.0, 1.0))
        # partners placed just below the ports, so both strike within the step
        e = sub.embed_contact(contact, port, +1.0, (x[port, 0], x[port, 1] - 2e-3))
        e.set_motion(0.0, 0.02, np.array([complex(x[port, 0], x[port, 1] - 2e-3),
                                          complex(0.0, 0.02), complex(0.0, -0.004)]))
    u = StepInput(0.0, 0.02, rng.normal(size=(3, 2, 2)))
    return sub, u


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_kernel_step_against_reference_on_a_random_tree(monkeypatch, seed):
    """One macro step with switches inside: state, quadratures, moments and
    the located switches agree with the reference to round-off."""
    out = {}
    for kernel in ("numpy", "compiled"):
        monkeypatch.setenv("COSIM_KERNEL", kernel)
        sub, u = _random_tree_step(seed)
        sub.step(0.0, 0.02, u)
        assert sub.kernel == kernel
        out[kernel] = (sub.x.copy(), sub.aux.copy(), sub.port_moments.copy(),
                       list(sub.switch_log))
    (x0, a0, m0, s0), (x1, a1, m1, s1) = out["numpy"], out["compiled"]
    assert s0, "the random tree's contacts must switch within the step"
    assert [(j, on) for _, j, on in s0] == [(j, on) for _, j, on in s1]
    np.testing.assert_allclose([t for t, _, _ in s1], [t for t, _, _ in s0], rtol=0, atol=1e-13)
    np.testing.assert_allclose(x1, x0, rtol=1e-11, atol=1e-12)
    np.testing.assert_allclose(a1, a0, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(m1, m0, rtol=1e-11, atol=1e-13)


def _effects(kind):
    from multibody import JointEffects
    from multibody.effects import (ConstantTorque, JointDamper, JointSpring, MinimumJerk,
                                   PDTracking, Sinusoid, Table, TorqueTable)
    base = [JointSpring(1, 30.0, 0.2), JointDamper(2, 0.4), JointSpring(3, 50.0, -0.01)]
    drives = {
        "constant": [ConstantTorque(1, 2.5)],
        "table": [TorqueTable(2, Table((0.0, 0.004, 0.011, 0.03), (0.0, 3.0, -1.0, 2.0)))],
        "pd_table": [PDTracking(1, 80.0, 3.0, Table((0.0, 0.01, 0.02), (0.0, 0.5, 0.2)))],
        "pd_minimum_jerk": [PDTracking(2, 100.0, 5.0, MinimumJerk(0.0, 1.3, 0.002, 0.015),
                                       max_torque=4.0)],
        "pd_sinusoid": [PDTracking(1, 60.0, 2.0, Sinusoid(0.3, 40.0, 0.1, -0.2))],
    }[kind]
    return JointEffects(4, base + drives)


@pytest.mark.parametrize("kind", ["constant", "table", "pd_table", "pd_minimum_jerk",
                                  "pd_sinusoid"])
def test_kernel_joint_effects_against_reference(monkeypatch, kind):
    """Springs, dampers and every kind of drive and reference: state, the
    dampers' and drives' ledger and the energy agree with the reference."""
    out = {}
    for kernel in ("numpy", "compiled"):
        monkeypatch.setenv("COSIM_KERNEL", kernel)
        sub, u = _random_tree_step(4, _effects(kind))
        sub.step(0.0, 0.02, u)
        assert sub.kernel == kernel
        out[kernel] = (sub.x.copy(), sub.aux.copy(), sub.energy(), sub.ledger())
    (x0, a0, e0, l0), (x1, a1, e1, l1) = out["numpy"], out["compiled"]
    np.testing.assert_allclose(x1, x0, rtol=1e-11, atol=1e-12)
    np.testing.assert_allclose(a1, a0, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(e1, e0, rtol=1e-12)
    np.testing.assert_allclose(l1, l0, rtol=1e-10, atol=1e-14)
    assert l0[1] != 0.0 and l0[0] > 0.0       # the drive supplied, the damper dissipated


def test_a_bad_kernel_choice_is_refused_before_the_run(tmp_path, monkeypatch):
    import subprocess
    import sys
    monkeypatch.setenv("COSIM_KERNEL", "fortran")
    p = subprocess.run([sys.executable, "-m", "cosim.cli", "run", str(CASES / "spring_drop.toml"),
                        "--out", str(tmp_path / "run")], capture_output=True, text=True)
    assert p.returncode == 2
    assert "`COSIM_KERNEL` must be one of ['compiled', 'numpy'], got 'fortran'" in p.stderr
    assert "Traceback" not in p.stderr and not (tmp_path / "run").exists()
