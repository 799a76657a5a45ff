"""Ctrl-C or SIGTERM while the error estimate's companions run, after the
run finished: the run is kept as it finished, and both the terminal and
``summary.json``'s ``accuracy`` say that the estimate was skipped, and why
(docs/commands.md, docs/troubleshooting.md)."""
import json
import subprocess
import sys
import textwrap

import pytest

from conftest import CASES

SPRING_DROP = CASES / "spring_drop.toml"

#: a `cosim` process that sends itself SIG at the first sample a companion
#: records: the signal comes within the companion's run, as a user's would
STOPPED_IN_A_COMPANION = textwrap.dedent("""
    import os, signal, sys
    from cosim import cli
    from cosim.core import recorder
    from cosim.studies import estimate
    SIG = getattr(signal, sys.argv.pop(1))
    simulate, record = estimate._simulate, recorder.Recorder.record
    armed = []
    def companion(scene):
        armed.append(True)
        return simulate(scene)
    def first_sample(self, *a, **k):
        if armed:
            armed.clear()
            os.kill(os.getpid(), SIG)
        return record(self, *a, **k)
    estimate._simulate = companion
    recorder.Recorder.record = first_sample
    sys.exit(cli.main(sys.argv[1:]))
    """)


@pytest.mark.parametrize("sig,name,code", [("SIGINT", "Ctrl-C", 130),
                                           ("SIGTERM", "SIGTERM", 143)])
@pytest.mark.parametrize("asked", [(), ("--accuracy", "1%")])
def test_a_signal_during_the_companions_says_the_estimate_was_skipped(tmp_path, sig, name,
                                                                      code, asked):
    out = tmp_path / "run"
    proc = subprocess.run([sys.executable, "-c", STOPPED_IN_A_COMPANION, sig, "run",
                           str(SPRING_DROP), "--set", "t_end=0.012", *asked, "--out", str(out)],
                          capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert proc.returncode == code, proc.stderr
    assert "Traceback" not in proc.stderr
    said = (f"the estimate was skipped: {name} stopped its companion run; the run finished "
            f"and is kept, without an error estimate")
    assert "status finished" in proc.stdout
    assert f"  accuracy: {said}\n" in proc.stdout
    s = json.loads((out / "summary.json").read_text())
    assert s["status"] == "finished"
    acc = s["accuracy"]
    assert acc["skipped"] == said and acc["why"] == [said] and not acc["reliable"]
    assert acc["companion"]["status"] == "interrupted" and acc["contacts"] == {}
    if asked:
        assert acc["request"]["outcome"] == "unchecked"
        assert acc["request"]["unchecked"] == said
        assert f"unchecked: {said}" in proc.stdout
    assert sorted(p.name for p in out.iterdir()) == ["scene.toml", "series.npz", "summary.json"]
