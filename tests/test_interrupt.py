"""Nothing lost: a run stopped by Ctrl-C or by an exception still writes its
series and summary up to that point, marked incomplete; files are written
atomically; a directory holding a run is not overwritten unless asked."""
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from conftest import CASES, ROOT
import cosim
from cosim import cli
from cosim.core import series as series_mod
from cosim.errors import OutputExistsError
from cosim.scene.run import RunInterrupted
from cosim.core.schemes import sampled
from cosim.core.schemes.explicit import GaussSeidel

SPRING_DROP = CASES / "spring_drop.toml"


def stop_at(monkeypatch, t_stop, exc):
    """Make the Gauss-Seidel scheme raise ``exc`` at its first step past
    ``t_stop`` (in the macro loop: the sampled path calls no ``advance``)."""
    advance = GaussSeidel.advance
    monkeypatch.setattr(sampled, "ENABLED", False)

    def stopping(self, system, t, h, ratio):
        if t >= t_stop:
            raise exc
        return advance(self, system, t, h, ratio)
    monkeypatch.setattr(GaussSeidel, "advance", stopping)


def read(out):
    summary = json.loads((out / "summary.json").read_text())
    with np.load(out / "series.npz") as npz:
        series = {k: npz[k] for k in npz.files}
    return summary, series


def no_leftovers(out):
    return not [p.name for p in out.iterdir() if p.name.startswith(".")]


def test_sigint_leaves_readable_partial_outputs(tmp_path):
    """A long run in a fresh process, sent SIGINT once it is under way."""
    out = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "cosim.cli", "run",
                             str(CASES / "three_mass.toml"), "--variant", "f100",
                             "--set", "t_end=500", "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    spool = out / ".series.npz.spool"
    deadline = time.monotonic() + 120
    while not spool.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert spool.exists(), "the run never started"
    time.sleep(1.0)                                   # let it step for a while
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr
    summary, series = read(out)
    assert summary["status"] == "interrupted"
    assert summary["message"].startswith("interrupted (Ctrl-C) at t = ")
    t = series["t"]
    assert 0 < t[-1] < 1000 and t[-1] == pytest.approx(summary["t_end"])
    assert len(t) > 10 and np.all(np.diff(t) > 0)
    assert all(len(v) == len(t) for v in series.values())
    assert set(summary["final_state"]["robot"]) == {"x", "y", "body", "arm"}
    assert str(out) in stderr and "interrupted" in stderr       # says where the outputs are
    assert (out / "scene.toml").exists() and no_leftovers(out)


def test_keyboard_interrupt_in_process(tmp_path, monkeypatch):
    stop_at(monkeypatch, 0.005, KeyboardInterrupt())
    out = tmp_path / "run"
    with pytest.raises(RunInterrupted) as exc:
        cosim.simulate(cosim.load_scene(SPRING_DROP), out=out)
    assert isinstance(exc.value, KeyboardInterrupt)            # loops still stop
    res = exc.value.result
    assert res.status == "interrupted" and not res.success
    summary, series = read(out)
    assert summary == res.summary and summary["status"] == "interrupted"
    # the last sample is the last communication point before the stop
    assert series["t"][-1] == pytest.approx(0.005) and summary["t_end"] == pytest.approx(0.005)
    # final state = the last sample, not a state left part-way through a step
    assert summary["final_state"]["body"]["x"]["q"] == series["q/body/x"][-1]
    assert no_leftovers(out)


def test_exception_mid_run_keeps_the_outputs_and_is_re_raised(tmp_path, monkeypatch):
    stop_at(monkeypatch, 0.012, ZeroDivisionError("on purpose"))
    out = tmp_path / "run"
    with pytest.raises(ZeroDivisionError) as exc:
        cosim.simulate(cosim.load_scene(SPRING_DROP), out=out)
    res = exc.value.partial_result
    summary, series = read(out)
    assert summary["status"] == res.status == "error"
    assert summary["message"] == "stopped by ZeroDivisionError at t = 0.012 s: on purpose"
    assert series["t"][-1] == pytest.approx(0.012)
    assert summary["contacts"]["wall"]["count"] == 1         # the contact at 10 ms is kept
    # without an output directory, the partial result is still handed over
    with pytest.raises(ZeroDivisionError) as exc:
        cosim.simulate(cosim.load_scene(SPRING_DROP))
    assert exc.value.partial_result.t[-1] == pytest.approx(0.012)


def test_command_line_on_interrupt_and_error(tmp_path, monkeypatch, capsys):
    stop_at(monkeypatch, 0.005, KeyboardInterrupt())
    out = tmp_path / "a"
    assert cli.main(["run", str(SPRING_DROP), "--out", str(out)]) == 130
    captured = capsys.readouterr()
    assert "status interrupted" in captured.out
    assert f"summary up to t = 0.005 s are in {out}" in captured.err
    assert read(out)[0]["status"] == "interrupted"

    stop_at(monkeypatch, 0.005, ZeroDivisionError("on purpose"))
    out = tmp_path / "b"
    assert cli.main(["run", str(SPRING_DROP), "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "ZeroDivisionError" in err and f"are in {out}" in err and "a bug of cosim" in err
    assert read(out)[0]["status"] == "error"


# -------------------------------------------------------- existing outputs
def test_an_output_directory_holding_a_run_is_refused(tmp_path, capsys):
    out = tmp_path / "run"
    args = ["run", str(SPRING_DROP), "--set", "t_end=0.002", "--out", str(out)]
    assert cli.main(args) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    capsys.readouterr()
    assert cli.main(args) == 2
    err = capsys.readouterr().err
    assert err == (f"error: {out} already holds a run (summary.json, series.npz); choose "
                   f"another --out, or pass --overwrite to replace it\n")
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert cli.main(args[:-2] + ["--set", "t_end=0.001", "--out", str(out), "--overwrite"]) == 0
    assert read(out)[0]["t_end"] == pytest.approx(0.001)


def test_the_default_run_directory_is_never_replaced_unasked(tmp_path, monkeypatch):
    """Run again without --out, a scene gets a new folder (`-2`), the first
    run kept byte for byte; --overwrite without --out replaces the first."""
    monkeypatch.chdir(tmp_path)
    args = ["run", str(SPRING_DROP), "--set", "t_end=0.001"]
    assert cli.main(args) == 0
    first = tmp_path / "runs" / "spring_drop-undamped"
    before = {p.name: p.read_bytes() for p in first.iterdir()}
    assert set(before) >= {"summary.json", "series.npz", "scene.toml"}
    assert cli.main(args) == 0
    assert (tmp_path / "runs" / "spring_drop-undamped-2" / "summary.json").exists()
    assert {p.name: p.read_bytes() for p in first.iterdir()} == before
    assert cli.main(args[:-1] + ["t_end=0.0005", "--overwrite"]) == 0
    assert read(first)[0]["t_end"] == pytest.approx(0.0005)
    assert sorted(p.name for p in (tmp_path / "runs").iterdir()) == [
        "spring_drop-undamped", "spring_drop-undamped-2"]


def test_write_outputs_refuses_unless_overwrite(tmp_path):
    res = cosim.simulate(cosim.load_scene(SPRING_DROP, overrides=["t_end=0.001"]))
    cosim.write_outputs(res, tmp_path)
    with pytest.raises(OutputExistsError, match="already holds a run"):
        cosim.write_outputs(res, tmp_path)
    cosim.write_outputs(res, tmp_path, overwrite=True)
    with pytest.raises(OutputExistsError):
        cosim.simulate(cosim.load_scene(SPRING_DROP), out=tmp_path)


def test_a_failed_write_leaves_the_previous_file_whole(tmp_path, monkeypatch):
    res = cosim.simulate(cosim.load_scene(SPRING_DROP, overrides=["t_end=0.001"]))
    cosim.write_outputs(res, tmp_path)
    before = (tmp_path / "series.npz").read_bytes()
    calls = []
    write_array = np.lib.format.write_array

    def failing(fh, array, *a, **k):
        calls.append(1)
        if len(calls) == 3:
            raise OSError("disk full")
        return write_array(fh, array, *a, **k)
    monkeypatch.setattr(series_mod.np.lib.format, "write_array", failing)
    with pytest.raises(OSError, match="disk full"):
        cosim.write_outputs(res, tmp_path, overwrite=True)
    assert (tmp_path / "series.npz").read_bytes() == before
    assert no_leftovers(tmp_path)


def test_outputs_have_ordinary_permissions(tmp_path):
    res = cosim.simulate(cosim.load_scene(SPRING_DROP, overrides=["t_end=0.001"]))
    cosim.write_outputs(res, tmp_path)
    mask = os.umask(0)
    os.umask(mask)
    for name in ("summary.json", "series.npz"):
        assert (tmp_path / name).stat().st_mode & 0o777 == 0o666 & ~mask


@pytest.mark.parametrize("scene, variant", [(SPRING_DROP, None),
                                            (CASES / "three_mass.toml", "f100")])
def test_a_stop_between_a_full_buffer_and_its_flush_stores_each_row_once(tmp_path, monkeypatch,
                                                                        scene, variant):
    """A signal that lands after the chunk buffer's last row and before its
    flush (the first flush raises, as the signal's KeyboardInterrupt would)
    leaves a run whose finish stores its last row without an error and whose
    series hold each sample once, in order."""
    from cosim.core.recorder import Recorder
    monkeypatch.setattr(series_mod, "CHUNK_BYTES", 4096)       # a full buffer early on
    flush = Recorder._flush
    calls = []

    def interrupted(self):
        calls.append(self._n_buf)
        if len(calls) == 1:
            raise KeyboardInterrupt
        return flush(self)

    monkeypatch.setattr(Recorder, "_flush", interrupted)
    out = tmp_path / "run"
    with pytest.raises(RunInterrupted):
        cosim.simulate(cosim.load_scene(scene, variant), out=out)
    summary, series = read(out)
    assert summary["status"] == "interrupted"
    t = series["t"]
    assert len(t) > calls[0] and np.all(np.diff(t) > 0)
    assert all(len(v) == len(t) for v in series.values())
    assert t[-1] == pytest.approx(summary["t_end"])
