"""benchmarks/bench_ratio.py: `cosim bench`'s co-simulation / monolithic CPU
over the shipped and generated scenes.  Its logic on one tiny scene (what it
takes from the bench, the verdict, the table, why a scene is refused), and
that the published table is what the script makes of its JSON; no CPU time
is asserted (a verdict of a timing is the measurement's, not the test's)."""
from __future__ import annotations

import json
import math

import pytest

from documented import ROOT, load_script


@pytest.fixture(scope="module")
def br():
    return load_script(ROOT / "benchmarks" / "bench_ratio.py", "bench_ratio")


@pytest.mark.parametrize("ratio,verdict", [
    (0.04, "yes"), (1.0, "yes"), (math.nextafter(1.0, 2.0), "no"), (5.7, "no"),
    (None, "-"), (math.nan, "-")])
def test_the_verdict_is_the_target_at_most_one(br, ratio, verdict):
    assert br.verdict(ratio) == verdict


def test_every_shipped_scene_and_variant_is_listed(br):
    """Each variant of each scene; the scene alone where it names no default
    variant (it then runs without one)."""
    from cosim.scene.shipped import scene_variants, shipped_scenes
    cases = br.shipped_cases()
    for name, path in shipped_scenes().items():
        variants, default = scene_variants(path)
        got = [v for n, _, v in cases if n == name]
        assert got == ([None] if default is None else []) + list(variants)
    assert all(p == f"cases/{n}.toml" for n, p, _ in cases)


def _case_of_one_scene(br, tmp_path, monkeypatch):
    monkeypatch.chdir(ROOT)     # the scripts run from the project root, its paths relative
    return br.bench_case("spring_drop", "cases/spring_drop.toml", "undamped", spread=1,
                         cache=str(tmp_path / "cache"))


def test_a_case_holds_the_bench_cheapest_rows_and_their_ratio(br, tmp_path, monkeypatch):
    """The chosen rows are the bench's cheapest within 1 % of each kind, the
    ratio their CPUs' quotient, the verdict that of the ratio, and the
    chosen co-simulation is run once more for its loop."""
    from cosim.studies.bench import BenchRow, cheapest_within
    case = _case_of_one_scene(br, tmp_path, monkeypatch)
    rows = [BenchRow(**{k: (math.nan if v is None else v) for k, v in r.items()})
            for r in case["rows"]]
    best = cheapest_within(rows, br.ACCURACY)
    for kind in ("cosim", "monolithic"):
        assert best[kind] is not None
        assert case[kind]["label"] == best[kind].label
        assert case[kind]["cpu_s"] == best[kind].cpu_time_s
    assert case["ratio"] == pytest.approx(case["cosim"]["cpu_s"] / case["monolithic"]["cpu_s"],
                                          rel=1e-12)
    assert case["verdict"] == br.verdict(case["ratio"])
    assert case["cosim"]["step"] > 0 and case["monolithic"]["rtol"] > 0
    loop = case["cosim_loop"]
    assert loop["macro_steps"] > 0 and loop["loop"] in ("compiled", "python", "sampled")
    assert 0.0 <= case["load_before"] and "refused" not in case


def test_the_table_has_one_row_per_case_and_the_verdict_column(br, tmp_path, monkeypatch):
    case = _case_of_one_scene(br, tmp_path, monkeypatch)
    over = {**case, "scene": "over", "ratio": 5.7, "verdict": "no"}
    none = {**case, "scene": "none", "cosim": None, "ratio": None, "verdict": "-"}
    refused = br.bench_case("rod_impact", "cases/rod_impact.toml", None, spread=1,
                            cache=str(tmp_path / "cache"))
    stopped = {"scene": "stopped", "variant": None, "contact": None, "load_before": 1.0,
               "error": "FloatingPointError: the mass matrix is not positive definite"}
    lines = br.table({"cases": [case, over, none, refused, stopped]}).splitlines()
    head = [c.strip() for c in lines[0].strip("|").split("|")]
    assert head[6:8] == ["co-sim / mono", "≤ 1"] and len(lines) == 2 + 5
    cells = [[c.strip() for c in ln.strip("|").split("|")] for ln in lines[2:]]
    assert all(len(c) == len(head) for c in cells)
    assert cells[0][:2] == ["spring_drop", "undamped"]
    assert cells[0][6] == f"{case['ratio']:.2f}" and cells[0][7] == case["verdict"]
    assert cells[1][6:8] == ["5.70", "**no**"]
    assert cells[2][2] == "none within 1 %" and cells[2][6] == "no co-simulation row meets 1 %"
    assert cells[2][7] == "-"
    # a scene the bench refuses says why, in the words of the bench, with no path of this machine
    assert cells[3][2].startswith("bench does not apply: ") and "`joint` must be given" in cells[3][2]
    assert str(ROOT) not in lines[5] and cells[3][7] == "-"
    # a bench that raised says so, and the batch went on
    assert cells[4][2] == "bench stopped: FloatingPointError: the mass matrix is not positive " \
                          "definite" and cells[4][7] == "-"
    t = br.totals({"cases": [case, over, none, refused, stopped]})
    assert (t["refused"], t["errors"], t["no_ratio"], t["ratios"], t["over"]) == (1, 1, 1, 2, 1)


def test_the_published_table_is_its_json(br):
    """benchmarks/results/bench_ratio/README.md is what `--table` makes of
    the bench_ratio.json beside it, and its generated scenes are the
    generator's (same seed, same text)."""
    from cosim.studies import generate
    run = ROOT / "benchmarks" / "results" / "bench_ratio"
    data = json.loads((run / "bench_ratio.json").read_text(encoding="utf-8"))
    assert (run / "README.md").read_text(encoding="utf-8") == br.readme(data)
    written = sorted((run / "scenes").glob("*.toml"))
    assert [p.stem for p in written] == [c["scene"] for c in data["cases"]
                                         if c["origin"] == "generated"]
    texts = dict(generate.scenes(data["n"], data["seed"]))
    assert {p.stem: p.read_text() for p in written} == texts
    assert str(ROOT) not in json.dumps(data)      # no path of the machine that ran it


def test_the_performance_page_says_the_published_ratios():
    """docs/performance.md's numbers of the bench-ratio run, from its JSON:
    the shipped scenes' count and largest ratio, the generated scenes at
    most 1 and the one over, with its ratio."""
    from documented import Claim, assert_printed, assert_reproduced
    data = json.loads((ROOT / "benchmarks" / "results" / "bench_ratio" / "bench_ratio.json")
                      .read_text(encoding="utf-8"))
    page, cmd = "docs/performance.md", "python benchmarks/bench_ratio.py --n 40"
    shipped = [c for c in data["cases"] if c["origin"] == "shipped" and c.get("ratio") is not None]
    generated = [c for c in data["cases"] if c["origin"] == "generated"]
    over = [c for c in generated if c.get("verdict") == "no"]
    top = max(shipped, key=lambda c: c["ratio"])
    for printed, value, measured, tol in [
            ("The 31 ratios of the shipped scenes are all at most 1", 31, len(shipped), 0),
            ("(the largest 0.33, manipulator_wall mu0)", 0.33, top["ratio"], 0.005),
            ("of the generated scenes 39 of 40 are", 39, len(generated) - len(over), 0),
            ("**gen0-018 is 1.18, not met**", 1.18, over[0]["ratio"], 0.005),
            ("(load average 0.6 at its start)", 0.6, data["load_start"], 0.05)]:
        claim = Claim(page, printed, cmd, value, abs=tol)
        assert_printed(claim)
        assert_reproduced(claim, measured)
    assert all(c["verdict"] == "yes" for c in shipped)
    assert (top["scene"], top["variant"]) == ("manipulator_wall", "mu0")
    assert [c["scene"] for c in over] == ["gen0-018"]
