"""A plane body reduced to its modes: the static correction of the dropped
modes per visited boundary segment, the pre-flight mode rule, Flamant's
growth of a point contact's compliance, and the modal basis cached on disk
through cosim's checked writer."""
import numpy as np
import pytest

import fem
from cosim.io.rundir import OutputFolder
from documented import Claim, assert_printed, assert_reproduced
from fem.modal import _elastic_solver
from fem.plane import Plane, rectangle
from fem.plane.cache import cache_key, cached_modes, entry_name
from fem.plane.reduce import FLAMANT, StaticCorrection, flamant_growth, mode_rule

STEEL = dict(thickness=0.01, youngs_modulus=210e9, poisson_ratio=0.3, density=7850.0)


def _strip(fixed="left", nx=24, ny=2, **kw):
    return Plane(rectangle(1.0, 0.1, nx, ny), fixed=fixed, **{**STEEL, **kw}).assemble()


@pytest.mark.parametrize("fixed", ["left", ()])
@pytest.mark.parametrize("point", [("top", 0.73), ("right", 0.02), ("bottom", 0.5)])
def test_the_static_correction_restores_the_full_static_solution(fixed, point):
    """A point force on the boundary: the kept modes' static response plus
    the residual compliance of the dropped ones is the full static solution
    (for a free body, its elastic part under inertia relief) to round-off."""
    st = _strip(fixed)
    basis = fem.modes(st, n_modes=8)
    corr = StaticCorrection(st, basis)
    dofs, w = st.point_operator(point)
    load = st.point_load(point, 1e3)
    full = _elastic_solver(st)(load)
    el = basis.omega > 0
    phi = basis.shapes[:, el]
    kept = phi @ ((phi.T @ load) / basis.omega[el] ** 2)
    u_full = w @ full[dofs]
    assert abs(w @ kept[dofs] / u_full - 1) > 1e-4       # the modes alone fall short
    restored = w @ kept[dofs] + 1e3 * corr.compliance(point)
    assert abs(restored / u_full - 1) < 1e-10
    # the field too: the residual vector completes the modal field
    field = kept + corr.residual(load)
    assert np.max(np.abs(field - full)) < 1e-10 * np.max(np.abs(full))


def test_the_correction_is_computed_per_visited_segment_and_kept():
    st = _strip()
    corr = StaticCorrection(st, fem.modes(st, n_modes=6))
    corr.compliance(("top", 0.51))
    assert corr.visited == 1 and corr.solves == 6        # P2: 3 nodes x 2 components
    corr.compliance(("top", 0.53))                        # the same segment: no solve
    assert corr.visited == 1 and corr.solves == 6
    corr.compliance(("top", 0.57))                        # the next one
    assert corr.visited == 2 and corr.solves == 12


def test_more_modes_leave_less_residual_compliance():
    st = _strip()
    c = [StaticCorrection(st, fem.modes(st, n_modes=m)).compliance(("right", 0.05))
         for m in (4, 8, 16, 32)]
    assert all(a > b > 0 for a, b in zip(c, c[1:]))


def test_a_clamped_point_has_no_compliance():
    st = _strip()
    corr = StaticCorrection(st, fem.modes(st, n_modes=4))
    dofs, _ = st.point_operator(("left", 0.03))
    assert dofs.size == 0 and corr.compliance(("left", 0.03)) == 0.0


def test_the_mode_rule():
    assert mode_rule(1000.0, 100.0)[0] == "ok"
    verdict, why = mode_rule(500.0, 100.0)
    assert verdict == "warn" and "10 x" in why
    verdict, why = mode_rule(50.0, 100.0)
    assert verdict == "refuse" and "turn the correction off" in why


def test_flamant_growth_of_a_point_contacts_compliance():
    """A point force on an elastic half-plane has no finite compliance
    (Flamant): refined at the contact, the static compliance of a boundary
    point grows by 2 ln 2 / (pi E t) at every halving of the mesh."""
    c = []
    for k in (1, 2, 4):
        st = Plane(rectangle(0.2, 0.1, 8 * k, 4 * k), fixed="bottom", element="P1",
                   **STEEL).assemble()
        dofs, w = st.point_operator(("top", 0.1))
        c.append(w @ st.static_displacement(st.point_load(("top", 0.1), 1.0))[dofs])
    growth = np.diff(c) * STEEL["youngs_modulus"] * STEEL["thickness"] / FLAMANT
    # measured: 0.986 and 0.996 (0.999 at the next halving)
    assert np.all(np.abs(growth - 1) < 0.02) and abs(growth[-1] - 1) < 0.006, growth
    claim = Claim("docs/structures.md", "measured within 1.4 % of it on P1",
                  "tests/test_plane_reduce.py", 1.4, abs=0.05)
    assert_printed(claim)
    assert_reproduced(claim, 100 * float(np.max(np.abs(growth - 1))))
    assert FLAMANT == pytest.approx(0.4413, abs=1e-4)
    # the shares: 3e-4 at 1.6e6 N/m on a 10 mm steel plate, 21 % at 1e9
    assert flamant_growth(1.6e6, 210e9, 0.01) == pytest.approx(3.36e-4, rel=1e-3)
    assert flamant_growth(1e9, 210e9, 0.01) == pytest.approx(0.210, rel=1e-3)


# ---------------------------------------------------------------------------
# The disk cache
# ---------------------------------------------------------------------------
def test_the_modal_basis_is_cached_on_disk_and_read_back(tmp_path, monkeypatch):
    st = _strip(nx=40, ny=4)
    with OutputFolder(tmp_path / "cache", lock=False) as folder:
        first, hit = cached_modes(st, folder, n_modes=6)
        assert not hit
        files = [p.name for p in folder.path.iterdir()]
        assert files == [entry_name(cache_key(st, 6, None))]
        from fem.plane import cache
        monkeypatch.setattr(cache, "modes", lambda *a, **k: pytest.fail("solved again"))
        again, hit = cached_modes(_strip(nx=40, ny=4), folder, n_modes=6)
        assert hit
        assert np.array_equal(again.omega, first.omega)
        assert np.array_equal(again.shapes, first.shapes)
        assert (again.kept, again.dropped, again.n_rigid) == (6, st.n_dof - 6, 0)


def test_the_cache_key_follows_the_inputs(tmp_path):
    base = cache_key(_strip(), 6, None)
    assert cache_key(_strip(), 6, None) == base
    for other in (cache_key(_strip(), 8, None), cache_key(_strip(), None, 900.0),
                  cache_key(_strip(density=7800.0), 6, None),
                  cache_key(_strip(fixed=()), 6, None),
                  cache_key(_strip(nx=25), 6, None),
                  cache_key(_strip(model="plane_strain"), 6, None)):
        assert entry_name(other) != entry_name(base)


def test_a_damaged_or_edited_entry_is_computed_again_with_a_warning(tmp_path):
    st = _strip()
    with OutputFolder(tmp_path, lock=False) as folder:
        good, _ = cached_modes(st, folder, n_modes=4)
        name = entry_name(cache_key(st, 4, None))
        path = folder.path_of(name)
        blob = bytearray(path.read_bytes())
        at = blob.rfind(np.float64(good.omega[2]).tobytes())
        blob[at + 3] ^= 0x10                     # one byte of a frequency damaged
        path.write_bytes(bytes(blob))
        with pytest.warns(UserWarning, match="cannot be read"):
            again, hit = cached_modes(st, folder, n_modes=4)
        assert not hit and np.array_equal(again.omega, good.omega)
        with np.load(path) as z:                 # a frequency edited, the file whole
            fields = {k: z[k] for k in z.files}
        fields["omega"] = fields["omega"] * (1 + 1e-9)
        np.savez(path, **fields)
        with pytest.warns(UserWarning, match="checksum"):
            again, hit = cached_modes(st, folder, n_modes=4)
        assert not hit and np.array_equal(again.omega, good.omega)
        path.write_bytes(b"not an npz")
        with pytest.warns(UserWarning, match="cannot be read"):
            _, hit = cached_modes(st, folder, n_modes=4)
        assert not hit
        assert [p.name for p in folder.path.iterdir()] == [name]   # no temporary left
        _, hit = cached_modes(st, folder, n_modes=4)       # written again, whole
        assert hit
