"""Multirate co-simulation: a side takes several sub-steps per macro step,
its coupler forces evaluated anew at each against its partner's motion
(interpolated when the partner has stepped, extrapolated otherwise)."""
import warnings

import pytest

import cosim
from test_hosted_contacts import PAIR, velocities

EXACT = 2 * 5.0 * 2.0 / 5.2      # the light body's exit speed (two-body rebound)


def run(tmp_path, *ov, scheme=None, placement="coupler"):
    path = tmp_path / "pair.toml"
    path.write_text(PAIR.format(placement=placement, host=""))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = cosim.load_scene(path, overrides=["scheme.accept_unsafe_step=true", *ov],
                                 scheme=scheme)
    res = cosim.simulate(scene, estimate=False)
    assert res.success, res.message
    return res


@pytest.mark.parametrize("scheme,sequence", [("gauss_seidel", '["heavy", "light"]'),
                                             ("gauss_seidel", '["light", "heavy"]'),
                                             ("jacobi", '["heavy", "light"]')])
def test_substeps_of_the_light_side_cut_its_error(tmp_path, scheme, sequence):
    """Four sub-steps for the 0.2 kg side against the 5 kg one (H = 20 us,
    omega H = 0.045): the light body's exit-speed error falls at least
    threefold (observed 5.0x and 6.0x under Gauss-Seidel)."""
    seq = f"scheme.sequence={sequence}"
    one = run(tmp_path, seq, scheme=scheme)
    four = run(tmp_path, seq, "scheme.substeps={light = 4}", scheme=scheme)
    e1 = abs(velocities(one)[1] - EXACT)
    e4 = abs(velocities(four)[1] - EXACT)
    assert e4 < e1 / 3, (e1, e4)
    assert four.summary["contacts"]["C"]["count"] == 1
    # the same macro steps: only the light side cut them
    assert four.n_windows == one.n_windows


def test_substeps_of_one_are_the_plain_scheme(tmp_path):
    a = run(tmp_path)
    b = run(tmp_path, "scheme.substeps={light = 1, heavy = 1}")
    # one sub-step takes the plain scheme's code path (base._step_side):
    # the same computation twice, bit for bit
    assert velocities(a) == velocities(b)


def test_substeps_name_a_moving_subsystem(tmp_path):
    with pytest.raises(cosim.SceneError, match=r"`scheme.substeps.wall` names no moving "
                                               r"subsystem"):
        run(tmp_path, "scheme.substeps={wall = 2}")


def test_a_host_takes_no_substeps(tmp_path):
    with pytest.raises(cosim.SceneError, match=r"`light` hosts contacts \['C'\]"):
        run(tmp_path, "scheme.substeps={light = 2}", placement="embedded")


@pytest.mark.parametrize("value", ["{light = 0}", "{light = 1.5}", "3"])
def test_bad_substeps_are_refused(tmp_path, value):
    with pytest.raises(cosim.SceneError, match=r"`scheme.substeps` must be a table of "
                                               r"subsystem name"):
        run(tmp_path, f"scheme.substeps={value}")
