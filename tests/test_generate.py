"""Generated scenes (cosim.studies.generate): reproducible from their seed,
covering every structure, law, placement, scheme, robot size and joint kind,
and each one loads, passes the pre-flight check, runs to its end, strikes
early and closes its energy ledger."""
import json
import math
import time
import tomllib
import warnings

import pytest

from cosim.scene.load import load_scene
from cosim.scene.run import simulate
from cosim.studies import generate
from cosim.studies.metrics import impact_metrics
from cosim.studies.roundoff import perturbed
from cosim.studies.strike import find_strike

#: the scenes every CI run checks (the issue's "at least 40")
N = 40
SEED = 0
#: [s] the latest first touch the generator allows: its longest approach (4 ms),
#: twice over for the tip's curved path, gravity and the structure's give
LATEST_TOUCH = 8e-3
#: ulps the copy's initial state is moved by: the strike may not hang on round-off
NUDGE = 4


def _quiet_run(scene):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return simulate(scene)


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    folder = tmp_path_factory.mktemp("generated")
    return generate.write_scenes(folder, N, SEED)


@pytest.fixture(scope="module")
def runs(written):
    """Each scene, its run and the run of its copy nudged by NUDGE ulps;
    the CPU time of all of them (printed with ``-s``)."""
    out = {}
    t0 = time.process_time()
    for path in written:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            scene = load_scene(path)
        out[path.stem] = (scene, _quiet_run(scene), _quiet_run(perturbed(scene, NUDGE)))
    print(f"\n{N} generated scenes and their nudged copies: "
          f"{time.process_time() - t0:.1f} s of CPU")
    return out


def test_the_same_seed_gives_the_same_scenes():
    first = generate.scenes(5, seed=7)
    assert first == generate.scenes(5, seed=7)
    assert generate.scenes(3, seed=7) == first[:3]       # each deck deals from its own stream
    assert [t for _, t in generate.scenes(5, seed=8)] != [t for _, t in first]


def test_written_files_hold_the_generated_text(written):
    texts = dict(generate.scenes(N, SEED))
    assert [p.stem for p in written] == list(texts)
    for p in written:
        assert p.read_text() == texts[p.stem]


def test_forty_scenes_cover_every_category(written):
    seen = {k: set() for k in ("structure", "law", "placement", "scheme", "links", "joint")}
    for p in written:
        data = tomllib.loads(p.read_text())
        seen["structure"].add(data["subsystems"]["target"]["type"])
        contact = data["contacts"]["strike"]
        seen["law"].add(contact["law"]["type"])
        seen["placement"].add(contact["placement"])
        seen["scheme"].add(data["scheme"]["name"])
        bodies = data["subsystems"]["robot"]["bodies"]
        seen["links"].add(len(bodies))
        seen["joint"] |= {b["joint"]["type"] for b in bodies.values()}
    assert seen == {"structure": set(generate.STRUCTURES), "law": set(generate.LAWS),
                    "placement": set(generate.PLACEMENTS), "scheme": set(generate.SCHEMES),
                    "links": set(generate.LINKS), "joint": set(generate.JOINT_KINDS)}


def test_every_category_is_dealt_evenly():
    """Any n scenes hold each category of a deck at least n // (deck size)
    times: the decks are dealt whole."""
    cats = generate.categories(N, SEED)
    for key, deck in generate.DECKS.items():
        counts = [sum(c[key] == v for c in cats) for v in deck]
        assert min(counts) >= N // len(deck), (key, counts)


def test_every_scene_runs_to_its_end_and_strikes_early(runs):
    """Every scene loads, passes the pre-flight check (an exchanged contact
    under jacobi or gauss_seidel is judged there), runs to t_end without the
    guard stopping it, and its tip strikes the structure within
    LATEST_TOUCH; so does its copy moved by NUDGE ulps."""
    for name, (scene, res, nudged) in runs.items():
        for r in (res, nudged):
            assert r.success and r.status == "finished", (name, r.status, r.message)
            c = r.summary["contacts"]["strike"]
            assert c["count"] >= 1, name
            assert c["intervals"][0][0] < LATEST_TOUCH, (name, c["intervals"][0])


def test_the_strike_is_the_contact_a_study_reads(runs):
    """find_strike names the one contact and the joint of the tip's link, and
    the tip leaves before the end: the exit velocity a study compares is read
    on every scene of seed 0 (a robot that comes back to the structure just
    before t_end leaves it unread: 3 of the 320 scenes of seeds 0 to 7)."""
    for name, (scene, res, _) in runs.items():
        contact, joint = find_strike(scene)
        n_links = len(scene.data["subsystems"]["robot"]["bodies"])
        assert (contact, joint) == ("strike", f"robot/q{n_links}")
        m = impact_metrics(res, contact, joint)
        assert math.isfinite(m["exit_velocity"]), (name, m)


def _robot_kinetic_energy(scene) -> float:
    """The robot's kinetic energy at the start [J]: what the strike brings."""
    system, _ = scene.build()
    robot = next(s for s in system.subsystems if s.name == "robot")
    n = robot.n_dof
    return robot.model.kinetic_energy(robot.x[:n], robot.x[n:2 * n])


def test_the_energy_ledger_closes(runs):
    """initial + supplied - dissipated + the contact's coupling error =
    final: what the contact's forces did to the sides is what their energy
    shows.  Closed-form structures step it exactly; what is left is the
    robot's (and a structure's) RK4 at omega h <= 0.3 while the contact is
    closed, against the kinetic energy the robot brings to the strike
    (observed at most 2.5e-5 of it on seed 0)."""
    worst = 0.0
    for name, (scene, res, _) in runs.items():
        e, c = res.summary["energy"], res.summary["contacts"]["strike"]
        residual = e["final"] - (e["initial"] + e["supplied"] - e["dissipated"]
                                 + c["coupling_error"])
        scale = _robot_kinetic_energy(scene)
        worst = max(worst, abs(residual) / scale)
        assert abs(residual) <= 1e-4 * scale, (name, residual, scale)
    print(f"\nworst ledger residual: {worst:.2g} of the robot's kinetic energy")


def test_bad_counts_are_refused():
    with pytest.raises(ValueError, match="`n` must be >= 0"):
        generate.scenes(-1)
    assert generate.scenes(0) == []


def test_an_exchanged_step_is_checked_where_it_lands():
    """The energy one contact gains is not monotonic in the step (a contact
    takes a whole number of steps): on a contact of omega = 3094 rad/s at
    0.01061 kg, extrapolated at order 2 (a generated scene's), 1.8e-4 s is
    safe and 1.66e-4 s is not.  The generator checks the step it writes."""
    from cosim.core import preflight
    from cosim.studies.generate import _safe_below
    m, omega = 0.01061, 3094.0
    k = m * omega ** 2
    assert preflight.is_safe(m, k, 0.0, 1.8e-4, 2, 0.01)
    assert not preflight.is_safe(m, k, 0.0, 1.66e-4, 2, 0.01)
    h = _safe_below({"type": "linear", "contact_stiffness": k}, m, 2, 1.66e-4)
    assert h < 1.66e-4 and preflight.is_safe(m, k, 0.0, h, 2, 0.01)


def _validation_script():
    from documented import ROOT, load_script
    return ROOT, load_script(ROOT / "benchmarks" / "generated_validation.py",
                             "generated_validation")


@pytest.mark.parametrize("est,act,agrees", [
    (0.01, 0.004, True), (0.01, 0.0034, True), (0.01, 0.0033, False),   # within 3x of actual
    (1e-3, 2.9e-3, True), (1e-3, 3.1e-3, False), (None, 0.01, None), (0.01, None, None),
    (9e-4, 1e-6, True), (1.1e-3, 1e-6, False),      # actual below X/100: estimate below X/10?
])
def test_the_validation_judges_pairs_as_its_page_says(est, act, agrees):
    _, gv = _validation_script()
    assert gv.judge(est, act) is agrees


def test_the_published_validation_tables_are_its_json():
    """benchmarks/results/generated_validation/README.md is what `--table`
    makes of the validation.json beside it, and its scenes are the
    generator's (same seed, same text)."""
    root, gv = _validation_script()
    run = root / "benchmarks" / "results" / "generated_validation"
    data = json.loads((run / "validation.json").read_text())
    assert (run / "README.md").read_text() == gv.readme(data)
    written = sorted((run / "scenes").glob("*.toml"))
    assert [p.stem for p in written] == [c["scene"] for c in data["cases"]]
    texts = dict(generate.scenes(data["n"], data["seed"]))
    assert {p.stem: p.read_text() for p in written} == texts
