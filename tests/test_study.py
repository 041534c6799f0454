"""Study folders reject bad input before any work, naming file, line and column."""

from __future__ import annotations

from pathlib import Path

import pytest

from blackbox.errors import StudyError
from blackbox.study import load_study

from conftest import copy_fixture
GOOD_MEAS = "case,grid,component,value,sigma\nL1,7,4,1.0e-5,1.0e-6\nL1,7,5,2.0e-5,1.0e-6\n"


@pytest.fixture
def study(tmp_path) -> Path:
    root = tmp_path / "cube"
    copy_fixture("cube", root, "*.png", "measurements*")
    (root / "measurements.csv").write_text(GOOD_MEAS)
    return root


def test_good_study_loads(study):
    s = load_study(study)
    assert len(s.measurements) == 2 and s.loads.n_cases >= 1


@pytest.mark.parametrize("text,where,what", [
    ("case,grid,component,value,sigma\nL1,7,4,1e-5,nan\n", "measurements.csv:2 column 'sigma'", "finite"),
    ("case,grid,component,value,sigma\nL1,7,4,1e-5,-1e-6\n", "measurements.csv:2 column 'sigma'", "positive"),
    ("case,grid,component,value,sigma\nL1,7,4,1e-5,0\n", "measurements.csv:2 column 'sigma'", "positive"),
    ("case,grid,component,value,sigma\nL1,7,4,NaN,1e-6\n", "measurements.csv:2 column 'value'", "finite"),
    ("case,grid,component,value,sigma\nL1,7,4,1e-5,1e-6\nL1,999,4,1e-5,1e-6\n",
     "measurements.csv:3 column 'grid'", "grid 999 is not in the deck"),
    ("case,grid,component,value,sigma\nL1,7,7,1e-5,1e-6\n", "measurements.csv:2 column 'component'", "1..6"),
    ("case,grid,component,value,sigma\nL1,7,x,1e-5,1e-6\n", "measurements.csv:2 column 'component'", "integer"),
    ("case,grid,component,value,sigma\nNOLOAD,7,4,1e-5,1e-6\n", "measurements.csv:2 column 'case'", "no loads"),
    ("case,grid,component,value,sigma\nL1,7,4,1e-5,1e-6\nL1,7,4,2e-5,1e-6\n", "measurements.csv:3",
     "duplicate measurement"),
    ("case,grid,component,value,reference_grid\nL1,7,4,1e-5,8\n", "measurements.csv:1", "header"),
    ("case,grid,component,value,sigma\nL1,7,4,1e-5\n", "measurements.csv:2", "expected 5 columns"),
])
def test_bad_measurements(study, text, where, what):
    (study / "measurements.csv").write_text(text)
    with pytest.raises(StudyError) as err:
        load_study(study)
    assert where in str(err.value) and what in str(err.value)


@pytest.mark.parametrize("text,where,what", [
    ("case,grid,component,value\nL1,5,6,0.5\nL1,5,6,0.5\n", "loads.csv:3", "duplicate row"),
    ("case,grid,component,value\nL1,55,6,0.5\n", "loads.csv:2 column 'grid'", "not in the deck"),
    ("case,grid,component,value\nL1,5,6,inf\n", "loads.csv:2 column 'value'", "finite"),
    ("case,grid,component,value\n,5,6,0.5\n", "loads.csv:2 column 'case'", "empty case"),
    ("case,grid,component,value\n", "loads.csv", "no load rows"),
])
def test_bad_loads(study, text, where, what):
    (study / "loads.csv").write_text(text)
    (study / "measurements.csv").unlink()
    with pytest.raises(StudyError) as err:
        load_study(study)
    assert where in str(err.value) and what in str(err.value)


@pytest.mark.parametrize("old,new,what", [
    ("grids = [7, 71, 72]", "grids = [7, 71, 5]", "not coincident"),
    ("grids = [7, 71, 72]", "grids = [71, 7, 72]", "not tied"),
    ("grids = [7, 71, 72]", "grids = [7, 71, 71]", "distinct"),
    ("grids = [7, 71, 72]", "grids = [7, 71, 99]", "not in the deck"),
    ('model = "simple"', 'model = "fancy"', "model"),
    ("initial = 1.0e3", "initial = -1.0", "initial"),
    ("confidence = 0.95", "confidence = 1.5", "confidence"),
    ('name = "cube"', 'name = "cube"\ntypo_key = 1', "typo_key"),
])
def test_bad_study_toml(study, old, new, what):
    toml = study / "study.toml"
    text = toml.read_text()
    assert old in text
    toml.write_text(text.replace(old, new))
    with pytest.raises(StudyError) as err:
        load_study(study)
    assert "study.toml" in str(err.value) and what in str(err.value)


@pytest.mark.parametrize("entries,what", [
    ("grid = 99\ncomponent = 3\nvalue = -1.0", "preloads[0]: grid 99 is not in the deck"),
    ("grid = 5\ncomponent = 3\nvalue = -1.0\n\n[[preloads]]\ngrid = 5\ncomponent = 3\nvalue = 2.0",
     "preloads[1]: grid 5 component 3 is given twice"),
    ("grid = 5\ncomponent = 7\nvalue = -1.0", "component"),
    ("grid = 5\ncomponent = 3\nvalue = -1.0\nforce = 2", "force"),
])
def test_bad_preloads(study, entries, what):
    """``[[preloads]]`` entries: a grid of the deck, a component 1-6, each grid and component once,
    no unknown key; the error names the table's entry."""
    toml = study / "study.toml"
    toml.write_text(toml.read_text() + "\n[[preloads]]\n" + entries + "\n")
    with pytest.raises(StudyError) as err:
        load_study(study)
    assert "study.toml" in str(err.value) and what in str(err.value)


def test_preloads_and_sequential_are_read(study):
    toml = study / "study.toml"
    toml.write_text(toml.read_text() + "\n[measurements]\nsequential = true\n\n[[preloads]]\ngrid = 5\n"
                    "component = 3\nvalue = -2.0e4\n")
    from blackbox.study import preload_matrix

    s = load_study(study)
    assert s.config.measurements.sequential is True
    P = preload_matrix(s.config)
    assert list(P.dofs) == [(5, 3)]
    assert P.values.toarray().tolist() == [[-2.0e4]] and list(P.cases) == ["preload"]


def test_joint_not_tied_by_rbe2(study):
    deck = study / "model.bdf"
    lines = [ln for ln in deck.read_text().splitlines() if not ln.startswith("RBE2")]
    deck.write_text("\n".join(lines) + "\n")
    with pytest.raises(StudyError, match="not tied"):
        load_study(study)


def test_holdout_case_without_measurements(study):
    toml = study / "study.toml"
    toml.write_text(toml.read_text().replace("holdout_cases = []", 'holdout_cases = ["L9"]'))
    with pytest.raises(StudyError, match="holdout_cases"):
        load_study(study)
