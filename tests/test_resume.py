"""An identification interrupted after its batched solver run (Ctrl-C, a crash) makes no new
solver run when it is run again: the finished batch comes from the cache."""

import json


import blackbox.identification as identification
from blackbox.cli import main

from conftest import copy_fixture


def test_interrupted_identify_resumes_without_solver_run(tmp_path, monkeypatch, capsys):
    study = tmp_path / "cube"
    copy_fixture("cube", study, "*.png")

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt          # after the condensation's batch, before the estimate

    monkeypatch.setattr(identification, "identify", interrupted)
    assert main(["identify", str(study), "--out", str(tmp_path / "out")]) == 130
    assert not (tmp_path / "out" / "result.json").exists()
    monkeypatch.undo()
    capsys.readouterr()
    assert main(["identify", str(study), "--out", str(tmp_path / "out")]) == 0
    assert "0 solver run(s) + 1 batch(es) from the cache" in capsys.readouterr().out
    solver = json.loads((tmp_path / "out" / "result.json").read_text())["solver"]
    assert solver["runs"] == 0 and solver["cached_batches"] == 1
    # and without the cache the same identification costs exactly one batched run
    assert main(["identify", str(study), "--out", str(tmp_path / "o2"), "--no-cache"]) == 0
    assert json.loads((tmp_path / "o2" / "result.json").read_text())["solver"]["runs"] == 1
