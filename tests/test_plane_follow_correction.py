"""The static correction of a contact that follows a plane body's boundary
(``follow = true`` with ``modes.static_correction = true``): the dropped
modes' compliance ``c_r`` is taken at the port's present point, along its
present normal, on whichever segment it has slid to (across the corner onto
the next group's), and the contact's linear spring becomes ``k / (1 + k
c_r)`` there each time the port moves (per macro step, as the port and its
normal stand still within one).  The change of stored energy at a change
of stiffness is booked as energy supplied by the reduction, so the ledger
closes as it does without the correction.

The body and the strikes are those of ``tests/test_plane_follow.py`` (the
steel square held on its left and bottom sides, a 1 kg point sliding over
its top-right corner) on a coarser mesh (P2, 4 x 4 squares cut in two: 128
DOFs, so that every mode is affordable as the reference) and a stiffer
spring, 1e8 N/m (the dropped modes then hold 3 % of the contact's
compliance at the first point).
"""
import contextlib
import warnings

import numpy as np
import pytest

import cosim
from cosim.scene.load import SceneError
from cosim.sides.plane import PlaneSubsystem
from documented import Claim, assert_printed, assert_reproduced
from plane_files import spy_kernels, write_msh
from test_plane_follow import BALL, L, MONOLITHIC, POINT, SCENE

S, CMD = "docs/structures.md", "pytest tests/test_plane_follow_correction.py"
K = 1e8
FEW = "count = 12 }"
CORRECTED = "count = 12, static_correction = true }"
ALL = "count = 9999 }"              # every mode of the 128 DOFs
#: the spring of tests/test_plane_follow.py, under which the bare point
#: presses into the corner and the closest point crosses onto the right face
SOFT = 1e6


def _scene(tmp_path, modes=CORRECTED, case=BALL, scheme="gauss_seidel",
           options="macro_step = 1e-6", name="corner", k=K):
    from fem.plane import quad_region
    write_msh(tmp_path / "square.msh", quad_region([(0.0, 0.0), (L, 0.0), (L, L), (0.0, L)],
                                                   4, 4))
    text = SCENE.format(scheme=scheme, scheme_options=options, placement="embedded",
                        t_end=0.0017, **case)
    text = text.replace("count = 12 }", modes).replace("contact_stiffness = 1e6",
                                                       f"contact_stiffness = {k!r}")
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    return path


@contextlib.contextmanager
def _quiet():
    """Flamant's and the mode rule's warnings unsaid (tested below)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yield


def _run(path):
    with _quiet():
        res = cosim.simulate(cosim.load_scene(path), estimate=False)
    assert res.success, res.message
    return res


def _plate(path):
    with _quiet():
        system, _ = cosim.load_scene(path).build()
    return system, system.subsystems[system.names.index("plate")]


# ---------------------------------------------------------------------------
# The compliance anywhere along the loop
# ---------------------------------------------------------------------------
def test_the_compliance_along_the_loop_is_the_full_static_solutions(tmp_path):
    """At points of the loop the port slides along -- inside the top face's
    last segment, at the corner, on the right face's segments (another
    group's) -- along the reference normal and along a turned one, the kept
    modes' static response plus ``c_r`` times the force is the full static
    solution's displacement to 1e-10; the correction solves once per
    segment visited (six DOFs of a P2 segment), whatever the points on it."""
    from fem.modal import _elastic_solver
    _, plate = _plate(_scene(tmp_path))
    loop, corr, st = plate.sliding_loop(0), plate.static_correction, plate.structure
    basis = plate.basis
    el = basis.omega > 0
    phi, w2 = basis.shapes[:, el], basis.omega[el] ** 2
    solve = _elastic_solver(st)
    corner = loop.arc[1]                  # the top face's last segment ends there
    assert corner == pytest.approx(L - 0.075)
    arcs = [0.2 * corner, 0.7 * corner, corner, corner + 0.004, corner + 0.0125,
            corner + 0.031]
    turned = np.array([np.cos(0.5), np.sin(0.5)])
    solves0, visited0 = corr.solves, corr.visited
    for i, arc in enumerate(arcs):
        point = (loop.name, arc)
        pt = st.boundary_point(*point)
        for direction in (None, turned):
            w = pt.normal @ pt.rows if direction is None else direction @ pt.rows
            f = np.zeros(st.n_dof)
            np.add.at(f, pt.dofs, 1e3 * w)
            full = w @ solve(f)[pt.dofs]
            kept = w @ (phi @ ((phi.T @ f) / w2))[pt.dofs]
            assert abs(kept / full - 1) > 1e-4          # the kept modes alone fall short
            restored = kept + 1e3 * corr.compliance(point, direction)
            assert abs(restored / full - 1) < 1e-10, (arc, direction)
            # as a sliding port reads it: its loop segment and position there
            # (at the corner, the top face's segment's end)
            seg = 0 if arc <= corner else int(np.searchsorted(loop.arc, arc, side="right")) - 1
            xi = (arc - loop.arc[seg]) / (loop.arc[seg + 1] - loop.arc[seg])
            n = pt.normal if direction is None else direction
            c_port = corr.row_compliance(*loop.point_row(seg, xi, n))
            assert c_port == pytest.approx(corr.compliance(point, direction), rel=1e-12)
        if i == 1:          # the first point's segment, computed when the scene was built
            assert corr.solves == solves0
    assert corr.visited - visited0 >= 2                 # the right face's segments
    assert corr.solves - solves0 == 6 * (corr.visited - visited0)


# ---------------------------------------------------------------------------
# A run: the spring follows the port
# ---------------------------------------------------------------------------
def test_the_spring_follows_the_port_across_the_corner(tmp_path, monkeypatch):
    """The bare point (the spring of ``tests/test_plane_follow.py``, 1e6
    N/m) presses into the corner and its closest point crosses onto the
    right face: at every move the contact's spring is ``k / (1 + k c_r)``
    with ``c_r`` at the port's new point along its new normal, on the top
    face's segment and on the right face's (measured: the stiffness moves
    between 0.999180 and 0.999323 of ``k``, the dropped share between
    6.8e-4 and 8.2e-4)."""
    seen = []
    original = PlaneSubsystem.follow_stiffness

    def spy(self, port, penetration):
        original(self, port, penetration)
        law = self._follow_corr[port][0]
        seen.append((self.port_coordinates[port], self._dirs[port].copy(),
                     law.contact_stiffness))

    monkeypatch.setattr(PlaneSubsystem, "follow_stiffness", spy)
    path = _scene(tmp_path, case=POINT, k=SOFT)
    res = _run(path)
    assert res.summary["contacts"]["C"]["count"] == 1
    monkeypatch.undo()
    _, plate = _plate(path)               # a fresh body: its correction, its loop
    loop, corr = plate.sliding_loop(0), plate.static_correction
    ks = np.array([k for _, _, k in seen])
    arcs = np.array([a if name == loop.name else 0.0 for (name, a), _, _ in seen])
    right = arcs > loop.arc[1]            # past the corner
    assert right.sum() > 100 and (~right).sum() > 100
    for point, normal, k in seen[::10]:
        assert point[0] == loop.name or point == ("top", POINT["s"])
        c_r = corr.compliance(point, normal)
        assert k == pytest.approx(SOFT / (1 + SOFT * c_r), rel=1e-12)
    for (_, arc), normal, _ in np.array(seen, dtype=object)[right][::10]:
        assert normal == pytest.approx([1.0, 0.0], abs=1e-3)   # the right face's
    assert ks.max() - ks.min() > 1e-4 * SOFT
    assert corr.visited >= 2


def _force_error(res, ref):
    """The largest difference of the contact force over the reference's
    peak, and the peak's relative difference."""
    f, g = np.asarray(res.series["force/C"]), np.asarray(ref.series["force/C"])
    g = np.interp(res.series["t"], ref.series["t"], g)
    return float(np.max(np.abs(f - g)) / g.max()), float(f.max() / g.max() - 1)


def _first_point_only(monkeypatch):
    """The correction kept at the first point (what was there before)."""
    original = PlaneSubsystem.follow_stiffness

    def once(self, port, penetration):
        if not self.__dict__.get("_set_once"):
            self._set_once = True
            original(self, port, penetration)

    monkeypatch.setattr(PlaneSubsystem, "follow_stiffness", once)


def test_the_following_correction_comes_closest_to_every_mode(tmp_path, monkeypatch):
    """Co-simulated (gauss_seidel, macro step 1 us, the contact hosted by
    the plate), the ball rolling over the corner with 12 modes: against the
    run with all 128 modes, the contact force is off by 6.5e-2 of its peak
    without the correction, by 2.6e-2 with the correction kept at the first
    point, and by 6.1e-4 with the correction that follows the port (peaks:
    +2.3e-2, +1.0e-2, +6.6e-5)."""
    ref = _run(_scene(tmp_path, ALL, name="all"))
    few = _force_error(_run(_scene(tmp_path, FEW, name="few")), ref)
    follows = _force_error(_run(_scene(tmp_path, name="follows")), ref)
    _first_point_only(monkeypatch)
    first = _force_error(_run(_scene(tmp_path, name="first")), ref)
    assert few[0] > 3e-2 and abs(few[1]) > 1e-2
    assert first[0] > 1e-2 and abs(first[1]) > 5e-3
    assert follows[0] < 2e-3 and abs(follows[1]) < 2e-4
    assert follows[0] < few[0] / 30 and follows[0] < first[0] / 10
    for printed, value, measured in (
            ("off by 6.5e-2 of its peak without the correction", 6.5e-2, few[0]),
            ("by 2.6e-2 with the correction kept at the first point", 2.6e-2, first[0]),
            ("by 6.1e-4 with the correction that follows the port", 6.1e-4, follows[0])):
        claim = Claim(S, printed, CMD, value, abs=0.05 * 10 ** np.floor(np.log10(value)))
        assert_printed(claim)
        assert_reproduced(claim, measured)


@pytest.mark.slow
def test_against_the_monolithic_run_with_every_mode(tmp_path):
    """The same against the monolithic scheme (DOP853, rtol 1e-8) with every
    mode, for the ball and for the bare point that crosses onto the right
    face: the all-modes co-simulation is within 1.4e-4 of it (the macro
    step's error), the corrected one within 9e-4 (measured 5.3e-4 and
    8.9e-4), the uncorrected one off by 6.5e-2 and 9.3e-2."""
    mono = MONOLITHIC.replace("1e-10", "1e-8").replace("1e-13", "1e-11")
    for case, bound in ((BALL, 1e-3), (POINT, 1.5e-3)):
        ref = _run(_scene(tmp_path, ALL, case, "monolithic", mono, name="mono"))
        assert _force_error(_run(_scene(tmp_path, ALL, case, name="all")), ref)[0] < 2e-4
        assert _force_error(_run(_scene(tmp_path, CORRECTED, case, name="c")), ref)[0] < bound
        assert _force_error(_run(_scene(tmp_path, FEW, case, name="f")), ref)[0] > 5e-2


# ---------------------------------------------------------------------------
# The ledger
# ---------------------------------------------------------------------------
def test_the_ledger_books_the_change_of_stiffness_as_work_of_the_reduction(tmp_path,
                                                                           monkeypatch):
    """The ball's spring softens by about 1 % as it rolls to the corner; the
    energy its stiffness change takes from the spring at fixed penetration,
    ``(k1 - k0) d^2 / 2`` summed, is booked as supplied by the plate
    (measured -3.68e-3 J, of a spring holding up to 0.45 J).  With it the
    energy drifts as much as the uncorrected run does (1.98e-5 J against
    2.05e-5 J at a macro step of 1 us: the co-simulation's own first-order
    drift of a port held still within a step), within 1e-2 of what was
    booked, and less than 0.6 times as much at half the step (measured
    8.3e-6 J); unbooked, the drift is what was booked.  The contact's own
    ledger names it ``reduction`` and keeps it out of its coupling error
    (-6.8e-7 J, against -5.1e-7 J without the correction)."""
    few = _run(_scene(tmp_path, FEW, name="few")).summary
    summaries = [_run(_scene(tmp_path, options=f"macro_step = {h}", name=f"h{i}")).summary
                 for i, h in enumerate((1e-6, 5e-7))]
    runs = [s["energy"] for s in summaries]
    # the contact's own ledger names it, and keeps it out of its coupling error
    c, c_few = summaries[0]["contacts"]["C"], few["contacts"]["C"]
    assert c["reduction"] == pytest.approx(runs[0]["supplied"], rel=1e-12)
    assert "reduction" not in c_few
    assert abs(c["coupling_error"]) < 2.0 * abs(c_few["coupling_error"])
    assert abs(c["coupling_error"]) < 1e-3 * abs(c["reduction"])
    few = few["energy"]
    supplied = runs[0]["supplied"]
    assert -5e-3 < supplied < -2e-3
    assert runs[1]["supplied"] == pytest.approx(supplied, rel=1e-2)
    drift = [e["max_abs_drift"] for e in runs]
    assert drift[0] < 1.5 * few["max_abs_drift"]
    assert drift[0] < 1e-2 * abs(supplied)
    assert drift[1] < 0.6 * drift[0]
    for printed, value, measured in (
            ("the ledger books -3.7e-3 J supplied by the reduction", -3.7e-3, supplied),
            ("drifts by 2.0e-5 J at 1 µs", 2.0e-5, drift[0])):
        claim = Claim(S, printed, CMD, value, abs=0.05 * 10 ** np.floor(np.log10(abs(value))))
        assert_printed(claim)
        assert_reproduced(claim, measured)
    monkeypatch.setattr(PlaneSubsystem, "ledger", lambda self: (float(self.aux[-2]), 0.0))
    unbooked = _run(_scene(tmp_path, name="unbooked")).summary["energy"]
    assert unbooked["max_abs_drift"] == pytest.approx(abs(supplied), rel=2e-2)


@pytest.mark.parametrize("scheme, options", [
    ("jacobi", "macro_step = 1e-6"), ("implicit", "macro_step = 1e-6"),
    ("gauss_seidel", "macro_step = 1e-6\ncontact_step = 2e-7")])
def test_the_other_cosimulation_schemes_book_it_too(tmp_path, scheme, options):
    """Jacobi and the implicit scheme (which read the law at each step), and
    gauss_seidel with a shorter step near contact (steps taken again from a
    saved state, which holds the corrected stiffness with the booked
    energy), take the following correction: the same energy booked within
    1e-2 (measured -3.71e-3, -3.68e-3 and -3.68e-3 J) and a drift no larger
    than 1.5 times theirs without the correction."""
    few = _run(_scene(tmp_path, FEW, scheme=scheme, options=options,
                      name="few")).summary["energy"]
    corr = _run(_scene(tmp_path, scheme=scheme, options=options, name="corr")).summary["energy"]
    assert corr["supplied"] == pytest.approx(-3.68e-3, rel=1e-2)
    assert corr["max_abs_drift"] < 1.5 * few["max_abs_drift"]


def test_a_saved_state_holds_the_stiffness_with_its_booked_energy(tmp_path):
    """A step taken again starts from the saved state: the corrected
    stiffness comes back with the energy booked for it, so the next move
    books its change again (the state vector is otherwise the structure's)."""
    _, plate = _plate(_scene(tmp_path))
    law = plate._follow_corr[0][0]
    k0, n_x = law.contact_stiffness, plate.x.size
    saved = plate.get_state()
    assert saved.x[-2:].tolist() == [k0, 0.0]    # the stiffness and its energy ride along
    plate.slide_port(0, np.array([L + 1e-4, 0.09]), plate.x)     # onto the right face
    plate.follow_stiffness(0, lambda: 1e-4)
    k1, booked = law.contact_stiffness, plate.ledger()[1]
    assert k1 != k0 and booked == pytest.approx(0.5 * (k1 - k0) * 1e-8, rel=1e-12)
    plate.set_state(saved)
    assert law.contact_stiffness == k0 and plate.ledger()[1] == 0.0 and plate.x.size == n_x
    plate.slide_port(0, np.array([L + 2e-4, 0.09]), plate.x)
    plate.follow_stiffness(0, lambda: 1e-4)
    assert plate.ledger()[1] == pytest.approx(0.5 * (law.contact_stiffness - k0) * 1e-8,
                                              rel=1e-12)
    assert plate.follow_supplied(0) == plate.ledger()[1]


def test_compiled_and_numpy_kernels_agree_with_the_following_correction(tmp_path,
                                                                        monkeypatch):
    """The compiled structure step holds its springs' stiffnesses from when
    it is built: the plate builds it again after each change (more than ten
    times here), and it agrees with the numpy reference: contact times to
    1e-9 s, every series within 1e-10 of its largest value (not bit-equal:
    the two sum in other orders)."""
    built = spy_kernels(monkeypatch)
    monkeypatch.setenv("COSIM_KERNEL", "compiled")
    fast = _run(_scene(tmp_path))
    assert len(built) > 10 and all(k is not None for k in built)
    monkeypatch.setenv("COSIM_KERNEL", "numpy")
    ref = _run(_scene(tmp_path))
    np.testing.assert_allclose(np.ravel(fast.summary["contacts"]["C"]["intervals"]),
                               np.ravel(ref.summary["contacts"]["C"]["intervals"]),
                               rtol=0, atol=1e-9)
    for key in ref.series:
        a, b = np.asarray(ref.series[key]), np.asarray(fast.series[key])
        assert np.max(np.abs(a - b)) <= 1e-10 * max(float(np.max(np.abs(a))), 1e-300), key


# ---------------------------------------------------------------------------
# The rules at the first point, and what is refused
# ---------------------------------------------------------------------------
def test_the_rules_still_speak_of_the_first_point(tmp_path):
    """The pre-flight rules are evaluated at the contact's first point, as
    without following: ``cosim info``'s mode rule gives the dropped share
    ``k c_r`` there (along its reference normal: 0.03, which turns the
    verdict to a warning), and both warnings are said, the dropped share's
    and Flamant's for the stiff point contact."""
    from cosim.scene.plane_build import mode_rules
    from fem.plane.reduce import dropped_share_rule
    path = _scene(tmp_path)
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        scene = cosim.load_scene(path)
        system, _ = scene.build()
    said = [str(w.message) for w in said]
    plate = system.subsystems[system.names.index("plate")]
    c_r = plate.static_correction.compliance(("top", BALL["s"]))
    share = K * c_r
    assert 0.02 < share < 0.05
    claim = Claim(S, "the dropped modes hold 0.03 of its compliance", CMD, 0.03, abs=0.005)
    assert_printed(claim)
    assert_reproduced(claim, share)
    assert any("Flamant" in m and str(path) in m for m in said), said
    assert any(f"hold {share:.2g} of the contact's compliance" in m for m in said), said
    (rule,) = mode_rules(system, scene)["plate"]
    assert rule["static_correction"] and rule["dropped_share"] == pytest.approx(share,
                                                                                rel=1e-12)
    assert rule["ratio"] >= 10 and rule["verdict"] == dropped_share_rule(share)[0] == "warn"


def test_what_a_following_correction_refuses(tmp_path):
    """Under the monolithic scheme (it moves the port at every evaluation,
    the correction's stiffness per macro step); and, following or not, the
    correction with kept modes below the contact's frequency."""
    path = _scene(tmp_path, scheme="monolithic", options=MONOLITHIC)
    with pytest.raises(SceneError) as info, _quiet():
        cosim.load_scene(path).build()
    msg = str(info.value)
    assert str(path) in msg and "contacts.C.follow" in msg and "monolithic scheme" in msg
    path = _scene(tmp_path, modes="count = 1, static_correction = true }")
    path.write_text(path.read_text().replace(f"contact_stiffness = {K!r}",
                                             "contact_stiffness = 1e13"))
    with pytest.raises(SceneError) as info, _quiet():
        cosim.load_scene(path).build()
    msg = str(info.value)
    assert "modes.static_correction" in msg and "x the contact frequency" in msg
