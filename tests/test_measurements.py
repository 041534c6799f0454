"""``blackbox measurements``: rig readings become measurements.csv (docs/measurements.md).

The worked example ``fixtures/measured/cube_rig`` is the cube (fixtures/cube, J7 springs 1e4
N*m/rad) read by 30 instruments with their own units, zeros, signs and a drifting zero, three
scans per load case after two zero scans, noise of 1 % of each channel's largest displacement
per scan. Reference: the true displacements the generator started from (the cube's response at
1e4 N*m/rad), and the statistics of the scatter.
"""

from __future__ import annotations

import csv
import importlib.util
import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from blackbox.cli import main
from blackbox.commands import identify, measurements
from blackbox.errors import StudyError
from blackbox.fitting.statistics import chi2_band

ROOT = Path(__file__).resolve().parents[1]
RIG = ROOT / "fixtures" / "measured" / "cube_rig"
CUBE = ROOT / "fixtures" / "cube"


def _generator(folder: Path):
    spec = importlib.util.spec_from_file_location(f"gen_{folder.name}", folder / "generate.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def imported():
    return measurements.run(RIG / "readings.csv", RIG / "channels.csv", CUBE)


@pytest.fixture(scope="module")
def truth():
    cases, dofs, values = _generator(RIG).true_rows()
    return {(c, d): v for c, d, v in zip(cases, dofs, values)}


def test_the_example_files_are_what_the_generator_writes(tmp_path):
    _generator(RIG).write(tmp_path)
    for name in ("channels.csv", "readings.csv"):
        assert (tmp_path / name).read_bytes() == (RIG / name).read_bytes(), name


def test_values_are_the_true_displacements_within_their_sigma(imported, truth):
    """Every row's error over its sigma is standard normal: the chi-square of the 300 rows lies
    in the 99 % band of chi2(300) / 300 (each row's value is an independent zero-referenced
    mean; its sigma estimate has 30 dof, slightly heavier tails, well inside the band)."""
    rows = imported.rows
    assert len(rows) == 300 and all(math.isfinite(r[4]) for r in rows)
    z = np.array([(v - truth[(case, (g, c))]) / s for case, g, c, v, s, *_ in rows])
    lo, hi = chi2_band(len(z), 0.99)
    assert lo <= float(z @ z) / len(z) <= hi
    assert np.max(np.abs(z)) < 4.5                 # 300 normal draws: |z| > 4.5 has probability 2e-3


def test_one_channel_by_hand(imported):
    """D7x (volts, gain 5e-6 m/V) recomputed from the readings file alone: the zero before each
    case subtracted, the scatter pooled over all blocks of scans (zero blocks included)."""
    with (RIG / "readings.csv").open() as fh:
        rows = [(r["case"], float(r["D7x"])) for r in csv.DictReader(fh)]
    blocks, last = [], None
    for label, v in rows:
        if last is None or last[0] != label:
            last = (label, [])
            blocks.append(last)
        last[1].append(v)
    ss = sum(float(np.sum((np.array(b) - np.mean(b)) ** 2)) for _, b in blocks)
    nu = sum(len(b) - 1 for _, b in blocks)
    s = math.sqrt(ss / nu)
    assert imported.scatter["D7x"] == pytest.approx((s, nu), rel=1e-12)
    zero = None
    got = {r[0]: r for r in imported.rows if (r[1], r[2]) == (7, 1)}
    for label, b in blocks:
        if label == "zero":
            zero = b
            continue
        value = 5e-6 * (np.mean(b) - np.mean(zero))
        sigma = 5e-6 * s * math.sqrt(1 / len(b) + 1 / len(zero))
        assert got[label][3] == pytest.approx(value, rel=1e-12, abs=1e-18)
        assert got[label][4] == pytest.approx(sigma, rel=1e-12)


def test_scatter_intervals_cover_the_true_noise(imported, truth):
    """Each channel's pooled scatter (30 dof) has a 95 % chi-square interval; over the 30
    channels the number covering the true per-scan noise (the generator's: 1 % of the channel's
    largest true displacement, in reading units) is binomial(30, 0.95): at least 25 of 30 with
    probability 0.998."""
    noise = _generator(RIG).NOISE
    hits = 0
    for c in imported.channels:
        s, nu = imported.scatter[c.name]
        true = noise * max(abs(v) for (_, d), v in truth.items() if d == (c.grid, c.component)) / abs(c.gain)
        lo, hi = (s * math.sqrt(nu / stats.chi2.ppf(q, nu)) for q in (0.975, 0.025))
        hits += lo <= true <= hi
    assert hits >= 25, hits


def test_identify_on_the_imported_measurements(imported, tmp_path):
    """The cube study with the imported file: every spring's interval covers the truth 1e4 and
    the chi-square is in its band (the noise is what the scatter says)."""
    study = tmp_path / "cube"
    shutil.copytree(CUBE, study, ignore=shutil.ignore_patterns(".blackbox_cache"))
    (study / "measurements.csv").write_text(imported.csv_text())
    res = identify.run(study, adapter="reference")
    r = res.result
    assert res.ok and res.noise is None                       # every sigma given by the import
    assert np.all((r.ci_low <= 1e4) & (1e4 <= r.ci_high)), list(zip(r.ci_low, r.ci_high))
    lo, hi = chi2_band(r.n_obs - r.n_params, 0.99)
    assert lo <= r.reduced_chi2 <= hi


def test_cli_writes_the_files_and_never_into_the_study(tmp_path, capsys):
    out = tmp_path / "m"
    assert main(["measurements", str(RIG / "readings.csv"), "--channels", str(RIG / "channels.csv"),
                 "--study", str(CUBE), "--out", str(out)]) == 0
    assert {p.name for p in out.iterdir()} >= {"measurements.csv", "report.md", "channels.json"}
    doc = json.loads((out / "channels.json").read_text())
    assert doc["rows"] == 300 and doc["rows_without_sigma"] == 0
    assert "R72z" in (out / "report.md").read_text()
    assert main(["measurements", str(RIG / "readings.csv"), "--channels", str(RIG / "channels.csv"),
                 "--study", str(CUBE), "--out", str(CUBE / "imported")]) == 2
    assert "outside the study folder" in capsys.readouterr().err
    assert not (CUBE / "imported").exists()


def _edit(tmp_path, channels=None, readings=None) -> tuple[Path, Path]:
    c, r = tmp_path / "channels.csv", tmp_path / "readings.csv"
    c.write_text(channels(RIG.joinpath("channels.csv").read_text()) if channels else RIG.joinpath("channels.csv").read_text())
    r.write_text(readings(RIG.joinpath("readings.csv").read_text()) if readings else RIG.joinpath("readings.csv").read_text())
    return r, c


@pytest.mark.parametrize("channels,readings,where,what", [
    (None, lambda t: t.replace("case,D7x,", "case,LVDT9,", 1), "readings.csv:1 column 'LVDT9'", "not in the channel map"),
    (lambda t: t.replace("D7y,7,2,", "D7y,7,1,"), None, "channels.csv:3 column 'grid'", "as channel 'D7x' on line 2"),
    (lambda t: t.replace("R7x,7,4,+1,1e-06,,urad", "R7x,7,4,+1,1e-06,,mm"), None, "channels.csv:5 column 'units'",
     "cannot read component 4"),
    (lambda t: t.replace("D7z,7,3,+1,", "D7z,7,3,2,"), None, "channels.csv:4 column 'sign'", "must be 1 or -1"),
    (lambda t: t.replace("D7z,7,3,", "D7z,999,3,"), None, "channels.csv:4 column 'grid'", "not in the study's deck"),
    (lambda t: t + "EXTRA,2,1,+1,1e-6,,um\n", None, "channels.csv:32 column 'channel'", "has no column"),
    (None, lambda t: t.replace("\nL3,", "\nL99,", 1), "column 'case'", "neither 'zero'"),
    (None, lambda t: t.replace("zero,", "L1,", 2), "readings.csv:2 column 'case'", "before any 'zero' scan"),
    (None, lambda t: t.replace("\nL2,-", "\nL2,abc-", 1), "column 'D7x'", "expected a number"),
])
def test_located_errors(tmp_path, channels, readings, where, what):
    r, c = _edit(tmp_path, channels, readings)
    with pytest.raises(StudyError) as err:
        measurements.run(r, c, CUBE)
    assert where in str(err.value) and what in str(err.value), str(err.value)


def test_a_channel_read_once_leaves_sigma_blank_and_a_reference_is_written(tmp_path):
    """Scans of one state once each (no repeats) give no scatter: sigma blank, said in a note;
    a channel with a reference grid writes the reference_grid column."""
    text = "channel,grid,component,sign,gain,reference_grid,units\nA,7,1,1,1e-3,5,mm\nB,6,2,-1,1e-3,,mm\n"
    reads = "case,A,B\nzero,0.10,0.20\nL1,0.30,0.10\nzero,0.11,0.21\nL2,0.50,0.00\n"
    (tmp_path / "c.csv").write_text(text)
    (tmp_path / "r.csv").write_text(reads)
    res = measurements.run(tmp_path / "r.csv", tmp_path / "c.csv", CUBE)
    lines = res.csv_text().splitlines()
    assert lines[0] == "case,grid,component,value,sigma,reference_grid"
    case, g, c, v, sig, ref = lines[1].split(",")
    assert (case, g, c, sig, ref) == ("L1", "7", "1", "", "5") and float(v) == pytest.approx(2e-4, rel=1e-12)
    assert any("never scanned twice" in n for n in res.notes)
