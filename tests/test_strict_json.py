"""Every JSON file cosim writes is JSON a strict parser reads (no NaN, no
Infinity), and a ledger that is not finite stops a run whatever
`guard.energy_check` says (issue 37, item 5)."""
import json
import math

import numpy as np
import pytest

import cosim
from conftest import CASES
from cosim import cli
from cosim.core.guard import Guard, GuardError, GuardOptions
from cosim.io.strict_json import NOTE_KEY, dumps, finite_json


def _refuse(word):
    raise ValueError(f"not JSON: {word}")


def strict(text: str):
    """``json.loads`` as a strict parser reads: NaN and Infinity refused."""
    return json.loads(text, parse_constant=_refuse)


def strict_files(folder):
    """Every ``*.json`` under ``folder``, each parsed strictly: path -> value."""
    found = {p: strict(p.read_text()) for p in sorted(folder.rglob("*.json"))}
    assert found, f"no JSON written under {folder}"
    return found


def test_the_strict_parser_refuses_what_json_dump_writes_by_default():
    """The check below could fail: Python's own writer emits Infinity."""
    with pytest.raises(ValueError, match="Infinity"):
        strict(json.dumps({"final": math.inf}))


def test_non_finite_values_become_null_and_are_noted():
    value = {"energy": {"final": math.inf, "initial": 0.5}, "xs": [1.0, -math.inf, math.nan],
             "n": 3, "s": "Infinity"}
    clean, where = finite_json(value)
    assert where == {"energy.final": "inf", "xs.1": "-inf", "xs.2": "nan"}
    back = strict(dumps(value))
    assert back["energy"] == {"final": None, "initial": 0.5}
    assert back["xs"] == [1.0, None, None] and back["n"] == 3 and back["s"] == "Infinity"
    assert back[NOTE_KEY] == where
    assert NOTE_KEY not in strict(dumps({"a": 1.0}))       # nothing to note, no key
    assert value["energy"]["final"] == math.inf             # the caller's value untouched


def _spring_system():
    system, _ = cosim.load_scene(CASES / "spring_drop.toml").build()
    return system


@pytest.mark.parametrize("created", [math.inf, -math.inf, math.nan])
def test_a_ledger_not_finite_stops_a_run_with_the_energy_check_off(created):
    """`guard.energy_check = false` turns the energy bound off, not the
    check of non-finite values (docs/troubleshooting.md): an infinite
    ledger passed the infinite bound (inf <= inf)."""
    system = _spring_system()
    z = np.zeros(system.n_rows)
    off = Guard(system, GuardOptions(energy_check=False))
    off.check(0.0, z, z, z, 0.0, 0.0, np.zeros(1))
    off.check(1e-3, z, z, z, 1e300, 0.0, np.zeros(1))       # any finite growth passes
    with pytest.raises(GuardError, match="not finite") as info:
        off.check(2e-3, z, z, z, created, 0.0, np.zeros(1))
    assert info.value.cause == "non-finite"


@pytest.mark.parametrize("check", [True, False])
def test_a_block_with_a_ledger_not_finite_stops_at_that_sample(check):
    """The block check (a side that samples many at once) gives the same verdict."""
    system = _spring_system()
    z = np.zeros(system.n_rows)
    g = Guard(system, GuardOptions(energy_check=check))
    g.check(0.0, z, z, z, 0.0, 0.0, np.zeros(1))
    m = 6
    created = np.zeros(m)
    created[4] = math.inf
    with pytest.raises(GuardError, match="not finite") as info:
        g.check_block(np.arange(1, m + 1) * 1e-4, np.zeros((m, 1)), np.zeros((m, 1)),
                      np.zeros((m, 1)), created, np.zeros(m), np.zeros((m, 1)))
    assert info.value.sample == 4 and info.value.cause == "non-finite"


#: an initial speed whose kinetic energy (m v^2 / 2) overflows float64
_HUGE_SPEED = "subsystems.body.bodies.mass.joint.dq0=-1e160"


def test_a_run_whose_summary_holds_infinity_writes_strict_json(tmp_path, capsys):
    out = tmp_path / "run"
    code = cli.main(["run", str(CASES / "spring_drop.toml"), "--set", _HUGE_SPEED,
                     "--set", "guard.energy_check=false", "--out", str(out)])
    assert code == 1                                        # stopped, not finished
    s = strict_files(out)[out / "summary.json"]
    assert s["status"] == "failed" and "not finite" in s["message"]
    assert s["energy"]["initial"] is None and s[NOTE_KEY]["energy.initial"] == "inf"
    assert "energy: initial inf J" in capsys.readouterr().out      # the terminal says it


def test_a_sweep_point_whose_summary_holds_infinity_writes_strict_json(tmp_path):
    out = tmp_path / "sweep"
    cli.main(["sweep", str(CASES / "spring_drop.toml"), "--set", _HUGE_SPEED,
              "--workers", "1", "--no-plot", "--out", str(out), "--quiet"])
    files = strict_files(out)
    summaries = [v for p, v in files.items() if p.name == "summary.json"]
    assert summaries and all(v["energy"]["initial"] is None for v in summaries)


def test_a_run_whose_energy_overflows_is_stopped_with_the_energy_check_off(tmp_path):
    """The issue's run: a penalty wall of 1e250 N/m exchanged by the coupler
    at an unsafe step, no energy bound. It ended `finished` with six
    `Infinity` values in its summary; the ledger that turned infinite now
    stops it (the last sample kept is finite), and its summary parses."""
    out = tmp_path / "run"
    code = cli.main(["run", str(CASES / "spring_drop.toml"), "--no-estimate",
                     "--set", 'contacts.wall.placement="coupler"',
                     "--set", "scheme.accept_unsafe_step=true",
                     "--set", "guard.energy_check=false",
                     "--set", "contacts.wall.law.contact_stiffness=1e250", "--out", str(out)])
    assert code == 1
    s = strict_files(out)[out / "summary.json"]
    assert s["status"] == "failed"
    assert "the energy ledger is not finite (inf J created)" in s["message"]
    assert math.isfinite(s["energy"]["final"]) and NOTE_KEY not in s
