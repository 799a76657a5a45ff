"""The command line: the contract the verification suite and users rely on."""
import json
import subprocess
import sys

import numpy as np
import pytest

from conftest import CASES, ROOT
from cosim import cli
from cosim.studies import verify


def test_run_writes_summary_and_series(tmp_path, capsys):
    out = tmp_path / "run"
    assert cli.main(["run", str(CASES / "spring_drop.toml"), "--variant", "kelvin_voigt",
                     "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "contact wall: 1 interval(s)" in text and "summary.json" in text
    s = json.loads((out / "summary.json").read_text())
    for key in ("scene", "scheme", "t_end", "cpu_time_s", "macro_steps", "energy", "contacts",
                "impacts", "final_state"):
        assert key in s
    assert set(s["energy"]) >= {"initial", "final", "max_abs_drift", "dissipated"}
    assert set(s["contacts"]["wall"]) >= {"peak_penetration", "intervals", "count",
                                          "in_touch_time", "impulse"}
    assert s["scene"] == "spring_drop" and s["scheme"] == "gauss_seidel"
    assert set(s["final_state"]["body"]["x"]) == {"q", "dq"}
    series = np.load(out / "series.npz")
    names = set(series.files)
    assert names >= {"t", "gap/wall", "force/wall", "q/body/x", "dq/body/x", "energy/total"}
    n = len(series["t"])
    assert all(len(series[k]) == n for k in names)
    assert not list(out.glob("*.tmp"))          # written atomically, nothing left over


def test_run_scheme_and_set_override(tmp_path):
    out = tmp_path / "r"
    assert cli.main(["run", str(CASES / "spring_drop.toml"), "--scheme", "implicit",
                     "--set", "scheme.macro_step=2e-4", "--set", "t_end=0.015",
                     "--out", str(out)]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["scheme"] == "implicit" and s["t_end"] == pytest.approx(0.015)
    assert s["macro_steps"] == 75


@pytest.mark.parametrize("args,match", [
    (["run", "no/such/scene.toml"], r"no/such/scene\.toml: cannot be read"),
    (["run", str(CASES / "spring_drop.toml"), "--set", "t_end=-1"],
     r"`t_end` must be > 0 s, got -1\.0"),
    (["run", str(CASES / "spring_drop.toml"), "--scheme", "jacobi", "--set",
      'contacts.wall.placement="coupler"'], r"contact `wall`: macro step 0\.0001 s is too large"),
])
def test_errors_are_one_line_and_exit_2(args, match, capsys, tmp_path):
    assert cli.main(args + ["--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "Traceback" not in err
    import re
    assert re.search(match, err), err
    assert not (tmp_path / "x").exists()        # nothing half-written


def test_verify_passes_and_prints_one_line_per_check(capsys):
    assert cli.main(["verify", "--cases", str(CASES)]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[-1] == "all checks passed"
    assert len(lines) - 1 == 12 and all(l.startswith("PASS") for l in lines[:-1])


def test_verify_exits_1_when_a_check_fails(monkeypatch, capsys):
    monkeypatch.setattr(verify, "CHECKS", {"broken": lambda p: [
        verify.Check("always fails", False, "on purpose")]})
    assert cli.main(["verify"]) == 1
    assert "FAIL  always fails: on purpose" in capsys.readouterr().out


def test_console_script_runs(tmp_path):
    """The installed entry point, in a fresh process."""
    proc = subprocess.run([sys.executable, "-m", "cosim.cli", "run",
                           str(CASES / "spring_drop.toml"), "--out", str(tmp_path / "o")],
                          capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "o" / "summary.json").exists()
