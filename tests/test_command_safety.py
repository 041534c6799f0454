"""What a command may do to the user's files, how it reports, and its exit codes.

--out must be new, empty, or an earlier output of the same command (marker file), checked before
any work; outputs appear whole (written beside --out, then moved); copies of a study never follow
links out of it; input errors are located; exit codes are 0 done, 2 bad input, 3 solver failure,
4 finished but not usable.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from blackbox.cli import main
from blackbox.commands.output import MARKER, check_out, write_output
from blackbox.errors import StudyError



# --------------------------------------------------------------------------------------------
# --out
# --------------------------------------------------------------------------------------------
def test_out_must_be_new_empty_or_an_earlier_output_of_the_same_command(tmp_path):
    check_out(tmp_path / "new", "identify")                 # new: fine
    (tmp_path / "empty").mkdir()
    check_out(tmp_path / "empty", "identify")               # empty: fine
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    with pytest.raises(StudyError, match="files this command did not write"):
        check_out(other, "identify")
    earlier = tmp_path / "earlier"
    write_output(earlier, "compare", lambda d: [(d / "a.txt").write_text("x") and "a.txt"])
    with pytest.raises(StudyError, match="the output of 'blackbox compare'"):
        check_out(earlier, "identify")
    check_out(earlier, "compare")                           # the same command may replace it
    (tmp_path / "file").write_text("x")
    with pytest.raises(StudyError, match="not a folder"):
        check_out(tmp_path / "file", "identify")


def test_out_never_the_study_its_parent_or_a_folder_inside_it(cube):
    for out in (cube, cube.parent, cube / "results"):
        with pytest.raises(StudyError, match="outside the study"):
            check_out(out, "identify", protect=(cube,))


@pytest.mark.parametrize("out_name", [".", "parent"])
def test_simulate_into_cwd_or_parent_deletes_nothing(cube, tmp_path, monkeypatch, out_name):
    """``simulate --out .`` used to empty the current folder; now it is refused before any work."""
    monkeypatch.chdir(cube)
    (tmp_path / "keep.txt").write_text("precious")
    out = "." if out_name == "." else str(tmp_path)
    before = sorted(p.name for p in cube.iterdir())
    assert main(["simulate", str(cube), "--truth", str(cube / "truth.toml"), "--out", out]) == 2
    assert sorted(p.name for p in cube.iterdir()) == before
    assert (tmp_path / "keep.txt").read_text() == "precious"


def test_replacing_an_earlier_output_is_all_or_nothing(tmp_path):
    out = tmp_path / "out"
    write_output(out, "identify", lambda d: [(d / "result.json").write_text("old") and "result.json"])

    def broken(d: Path) -> list[str]:
        (d / "result.json").write_text("half")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        write_output(out, "identify", broken)
    assert (out / "result.json").read_text() == "old"        # the earlier output, untouched
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]   # no partial folder left behind
    assert json.loads((out / MARKER).read_text())["command"] == "identify"


def test_out_checked_before_the_computation(cube, tmp_path, monkeypatch):
    """A bad --out fails at once: the identification never starts."""
    from blackbox import identification

    def never(*a, **k):
        raise AssertionError("the estimation ran although --out was unusable")

    monkeypatch.setattr(identification, "identify", never)
    (tmp_path / "busy").mkdir()
    (tmp_path / "busy" / "x").write_text("x")
    assert main(["identify", str(cube), "--out", str(tmp_path / "busy"), "--no-cache"]) == 2


def test_identify_twice_into_the_same_out(cube, tmp_path):
    out = tmp_path / "out"
    assert main(["identify", str(cube), "--out", str(out), "--no-cache"]) == 0
    first = json.loads((out / "result.json").read_text())
    assert main(["identify", str(cube), "--out", str(out), "--no-cache"]) == 0
    assert json.loads((out / "result.json").read_text())["parameters"] == first["parameters"]


def test_simulated_copy_does_not_follow_links_out_of_the_study(cube, tmp_path):
    secret = tmp_path / "secret.txt"
    secret.write_text("outside the study")
    os.symlink(secret, cube / "linked.txt")
    os.symlink(tmp_path, cube / "linked_dir")
    (cube / "notes").mkdir()
    (cube / "notes" / "inside.txt").write_text("inside")
    os.symlink(cube / "notes" / "inside.txt", cube / "inside_link.txt")
    out = tmp_path / "sim"
    assert main(["simulate", str(cube), "--truth", str(cube / "truth.toml"), "--out", str(out)]) == 0
    assert not (out / "linked.txt").exists() and not (out / "linked_dir").exists()
    assert (out / "notes" / "inside.txt").read_text() == "inside"
    assert (out / "inside_link.txt").read_text() == "inside" and not (out / "inside_link.txt").is_symlink()
    assert (out / "measurements.csv").is_file() and (out / "model.bdf").is_file()


# --------------------------------------------------------------------------------------------
# input errors are located
# --------------------------------------------------------------------------------------------
def test_byte_order_mark_accepted_and_bad_byte_located(cube, tmp_path, capsys):
    for name in ("study.toml", "loads.csv", "measurements.csv"):
        p = cube / name
        p.write_bytes(b"\xef\xbb\xbf" + p.read_bytes())
    assert main(["identify", str(cube), "--out", str(tmp_path / "o"), "--no-cache"]) == 0
    p = cube / "loads.csv"
    raw = p.read_bytes()
    p.write_bytes(raw[:200] + b"\xff" + raw[200:])
    capsys.readouterr()
    assert main(["identify", str(cube), "--out", str(tmp_path / "o2"), "--no-cache"]) == 2
    err = capsys.readouterr().err
    assert "loads.csv" in err and "byte 0xff at offset 200" in err


def test_sigma_below_double_precision_is_rejected(cube, tmp_path, capsys):
    p = cube / "measurements.csv"
    lines = p.read_text().splitlines()
    head, row = lines[0], lines[1].split(",")
    row[4] = "1e-300"
    p.write_text("\n".join([head, ",".join(row)] + lines[2:]) + "\n")
    assert main(["identify", str(cube), "--out", str(tmp_path / "o"), "--no-cache"]) == 2
    err = capsys.readouterr().err
    assert "measurements.csv:2 column 'sigma'" in err and "1e-300" in err


def test_every_pair_rigid_is_bad_input(cube, tmp_path, capsys):
    toml = cube / "study.toml"
    toml.write_text(toml.read_text().replace(
        "deck_stiffness = 0.0", "deck_stiffness = 0.0\nrigid_pairs = [[7, 71], [7, 72], [71, 72]]"))
    assert main(["identify", str(cube), "--out", str(tmp_path / "o"), "--no-cache"]) == 2
    assert "every branch pair is declared rigid" in capsys.readouterr().err


def test_debug_is_accepted_after_the_subcommand(cube, tmp_path):
    with pytest.raises(StudyError):
        main(["identify", str(cube / "missing"), "--out", str(tmp_path / "o"), "--debug"])


def test_bench_repeat_zero_is_a_usage_error(tmp_path, capsys):
    with pytest.raises(SystemExit) as info:
        main(["bench", "--out", str(tmp_path / "b"), "--repeat", "0"])
    assert info.value.code == 2 and "must be at least 1" in capsys.readouterr().err


# --------------------------------------------------------------------------------------------
# exit codes 3 and 4
# --------------------------------------------------------------------------------------------
def test_solver_failure_exits_3_with_the_log(cube, tmp_path, capsys):
    """The legacy fixture solver crashing (option from [solver.options]) is a solver failure."""
    toml = cube / "study.toml"
    toml.write_text(toml.read_text().replace('adapter = "reference"', 'adapter = "legacy"\n'
                                             'options = { misbehave = "crash" }'))
    # the project's own fixture program needs no consent (a study's "command" adapter does)
    assert main(["identify", str(cube), "--out", str(tmp_path / "o"), "--no-cache"]) == 3
    err = capsys.readouterr().err
    assert "solver failure" in err and "SolverRunError" in err
    assert not (tmp_path / "o").exists()


def test_a_study_command_needs_consent(cube, tmp_path, capsys):
    """A study.toml naming a program never runs it without the user's consent (exit 2, and the
    message says how to consent); with --trust-command it runs."""
    import sys
    marker = tmp_path / "ran.txt"
    prog = tmp_path / "prog.py"
    prog.write_text(f"import pathlib\npathlib.Path({str(marker)!r}).write_text('ran')\n")
    toml = cube / "study.toml"
    toml.write_text(toml.read_text().replace('adapter = "reference"', 'adapter = "command"\n'
                                             f'command = ["{sys.executable}", "{prog}", "{{deck}}"]'))
    monkey_cfg = tmp_path / "cfg"
    monkey_cfg.mkdir()
    os.environ["BLACKBOX_CONFIG_DIR"] = str(monkey_cfg)
    try:
        assert main(["solve", str(cube), "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err
        assert "--trust-command" in err and "trusted_commands" in err and not marker.exists()
        # consented: the program runs (and, being no solver, fails as a solver would: exit 3)
        assert main(["solve", str(cube), "--out", str(tmp_path / "o"), "--trust-command"]) == 3
        assert marker.read_text() == "ran"
    finally:
        del os.environ["BLACKBOX_CONFIG_DIR"]


def test_unknown_solver_option_is_bad_input(cube, tmp_path, capsys):
    toml = cube / "study.toml"
    toml.write_text(toml.read_text().replace('adapter = "reference"', 'adapter = "reference"\n'
                                             'options = { bogus = 1 }'))
    assert main(["identify", str(cube), "--out", str(tmp_path / "o"), "--no-cache"]) == 2
    assert "bogus" in capsys.readouterr().err


def test_too_few_observations_is_bad_input_before_fitting(cube, tmp_path, capsys):
    p = cube / "measurements.csv"
    lines = p.read_text().splitlines()
    p.write_text("\n".join([lines[0]] + [ln for ln in lines[1:] if ln.startswith("L1,")][:8]) + "\n")
    assert main(["identify", str(cube), "--out", str(tmp_path / "o"), "--no-cache"]) == 2
    assert "too few observations: 8 measured values for 9 parameters" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_not_identifiable_exits_4_with_warnings_on_the_terminal(cube, tmp_path, capsys):
    """One load case (30 rows) determines only 6 combinations of the 9 springs (rank 6: a load
    case excites the joint in one pattern per plane): the command finishes, writes its outputs,
    prints why and exits 4."""
    p = cube / "measurements.csv"
    lines = p.read_text().splitlines()
    p.write_text("\n".join([lines[0]] + [ln for ln in lines[1:] if ln.startswith("L1,")]) + "\n")
    assert main(["identify", str(cube), "--out", str(tmp_path / "o"), "--no-cache"]) == 4
    captured = capsys.readouterr()
    assert "warning: parameter(s)" in captured.out and "not identifiable" in captured.err
    assert json.loads((tmp_path / "o" / "result.json").read_text())["identifiable"] == [False] * 9


def test_joint_grids_in_different_displacement_systems_are_bad_input(cube, tmp_path, capsys):
    """A joint's springs join the same components of its branch grids: grids 7 and 71 giving
    their components in different CD systems is refused, located in study.toml."""
    deck = cube / "model.bdf"
    text = deck.read_text().replace("GRID          71             0.2     0.2     0.2",
                                    "GRID          71             0.2     0.2     0.2       9")
    deck.write_text(text.replace("ENDDATA", "CORD2R,9,,0.,0.,0.,0.,0.,1.,\n,1.,1.,0.\nENDDATA"))
    assert main(["identify", str(cube), "--out", str(tmp_path / "o"), "--no-cache"]) == 2
    err = capsys.readouterr().err
    assert "study.toml" in err and "different displacement systems" in err


def test_out_with_missing_parent_folders_is_made(cube, tmp_path):
    """``--out out/cube`` on a fresh checkout (the README's quick start): the parents are made."""
    out = tmp_path / "new" / "deeper" / "cube"
    assert main(["identify", str(cube), "--out", str(out), "--no-cache"]) == 0
    assert (out / "result.json").is_file()
