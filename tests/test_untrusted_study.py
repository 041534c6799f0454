"""Safe with what others send: a study folder (and its cache, and an output folder) is data
someone else may have prepared.

* every file a study names resolves inside the study folder, unless the user allows the folder
  (``--allow-outside`` or ``allow_outside`` in their own ``config.toml``); no message shows what
  an outside file holds;
* the run cache opens only regular files of the user, no larger than an entry for the request
  can be, in real folders: a planted named pipe, a link to ``/dev/zero``, a huge file or a
  linked ``.blackbox_cache`` are ignored (with a warning) and the batch is recomputed;
* ``--out`` is replaced only when everything in it is what the command wrote, unchanged.

The attacks that could hang or exhaust memory run ``blackbox`` as a child process with a time
limit and an address-space limit, so that a regression fails the test instead of the test run.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
from pathlib import Path

import pytest

from blackbox.cli import main
from blackbox.commands.output import MARKER, written_files
from blackbox.errors import StudyError
from blackbox.study import load_study, study_file

from conftest import ROOT, copy_fixture

PY = sys.executable
SECRET = "SECRET-LINE-4711 root:x:0:0"
"""The first line of a file outside the study: it must never appear in any message."""


@pytest.fixture(autouse=True)
def config(tmp_path_factory, monkeypatch) -> Path:
    """The user's configuration folder (cache key, config.toml), fresh for each test."""
    folder = tmp_path_factory.mktemp("config")
    monkeypatch.setenv("BLACKBOX_CONFIG_DIR", str(folder))
    return folder


@pytest.fixture
def secret(tmp_path) -> Path:
    """A readable text file outside every study, as /etc/passwd is."""
    p = tmp_path / "private" / "secret.txt"
    p.parent.mkdir()
    p.write_text(SECRET + "\nsecond line\n")
    return p


def _set_deck(study: Path, deck: str) -> None:
    toml = study / "study.toml"
    toml.write_text(toml.read_text().replace('deck = "model.bdf"', f"deck = {json.dumps(deck)}"))


# --------------------------------------------------------------------------------------------
# 1. study files stay inside the study folder
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("how", ["absolute", "dotdot", "linked_deck", "linked_folder"])
def test_a_deck_outside_the_study_is_refused_without_reading_it(how, cube, secret, tmp_path, capsys):
    """``deck = "/etc/passwd"``, ``deck = "../../x"``, a link to it, or a link to its folder:
    exit 2, the key and both paths named, the way to allow it said, nothing of the file shown."""
    if how == "absolute":
        _set_deck(cube, str(secret))
    elif how == "dotdot":
        _set_deck(cube, os.path.relpath(secret, cube))
        assert '"../' in (cube / "study.toml").read_text()
    elif how == "linked_deck":
        (cube / "model.bdf").unlink()
        (cube / "model.bdf").symlink_to(secret)
    else:
        (cube / "decks").symlink_to(secret.parent)
        _set_deck(cube, "decks/secret.txt")
    capsys.readouterr()
    assert main(["solve", str(cube), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "[solver] deck = " in err and "leads outside the study folder" in err
    assert str(secret) in err and f"--allow-outside {secret.parent}" in err and "allow_outside" in err
    assert ("through a symbolic link" in err) == how.startswith("linked")
    assert "SECRET" not in err and "root:x" not in err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("name", ["study.toml", "loads.csv", "measurements.csv", "truth.json"])
def test_a_study_file_linked_outside_is_refused(name, cube, secret, tmp_path, capsys):
    (cube / name).unlink(missing_ok=True)
    (cube / name).symlink_to(secret)
    capsys.readouterr()
    assert main(["identify", str(cube), "--out", str(tmp_path / "o"), "--no-cache"]) == 2
    err = capsys.readouterr().err
    assert f"{name} leads outside the study folder" in err and str(secret) in err
    assert "SECRET" not in err


def test_links_and_decks_inside_the_study_are_fine(cube, tmp_path):
    (cube / "data").mkdir()
    (cube / "loads.csv").rename(cube / "data" / "loads.csv")
    (cube / "loads.csv").symlink_to(Path("data") / "loads.csv")
    (cube / "model.bdf").rename(cube / "data" / "cube.bdf")
    _set_deck(cube, "data/../data/cube.bdf")
    assert main(["solve", str(cube), "--out", str(tmp_path / "o"), "--no-cache"]) == 0


def test_the_user_allows_a_folder_by_flag_or_own_configuration(cube, config, tmp_path):
    shared = tmp_path / "shared-decks"
    shared.mkdir()
    (cube / "model.bdf").rename(shared / "cube.bdf")
    _set_deck(cube, str(shared / "cube.bdf"))
    assert main(["solve", str(cube), "--out", str(tmp_path / "o1"), "--no-cache"]) == 2
    assert main(["solve", str(cube), "--out", str(tmp_path / "o2"), "--no-cache",
                 "--allow-outside", str(tmp_path / "elsewhere")]) == 2
    assert main(["solve", str(cube), "--out", str(tmp_path / "o3"), "--no-cache",
                 "--allow-outside", str(shared)]) == 0
    (config / "config.toml").write_text(f"allow_outside = [{json.dumps(str(shared))}]\n")
    assert main(["solve", str(cube), "--out", str(tmp_path / "o4"), "--no-cache"]) == 0
    study = load_study(cube)                                   # the library reads the same list
    assert study.deck_path == (shared / "cube.bdf").resolve()
    (config / "config.toml").write_text('allow_outside = ["relative/folder"]\n')
    with pytest.raises(ValueError, match="not an absolute path"):
        load_study(cube)


def test_a_truth_deck_named_by_truth_json_is_read_only_where_allowed(cube, secret):
    """compare re-simulates the MDSE case from the truth deck truth.json names; a study's
    truth.json pointing outside it is not followed (the MDSE case is then reported as not
    simulated, with the reason), unless the user allows the folder."""
    from blackbox.commands.compare import _truth_deck_refused
    from blackbox.study import ALLOW_OUTSIDE

    study = load_study(cube)
    rec = {"truth_file": str(cube / "truth.toml"), "deck": str(secret)}
    why = _truth_deck_refused(study, rec)
    assert why and "leads outside the study folder" in why and "SECRET" not in why
    assert _truth_deck_refused(study, {**rec, "deck": "model.bdf"}) is None
    token = ALLOW_OUTSIDE.set((secret.parent,))
    try:
        assert _truth_deck_refused(study, rec) is None
    finally:
        ALLOW_OUTSIDE.reset(token)


def test_a_study_file_that_is_no_regular_file_is_refused_unread(cube, tmp_path):
    """A named pipe as the deck would block the reader forever: refused from its type alone.
    (Run as a child with a time limit, so a regression fails instead of hanging.)"""
    os.mkfifo(cube / "pipe.bdf")
    _set_deck(cube, "pipe.bdf")
    r = _blackbox(["solve", str(cube), "--out", str(tmp_path / "o"), "--no-cache"])
    assert r.returncode == 2 and "is a named pipe, not a regular file" in r.stderr
    (cube / "data_dir").mkdir()
    with pytest.raises(StudyError, match="data_dir is a folder, not a regular file"):
        study_file(cube, "data_dir")


def test_error_messages_quote_no_line_of_a_file(cube, tmp_path, capsys):
    """A table whose first line is not the header: the message says which column differs,
    without quoting the line (the file might be anything)."""
    text = (cube / "loads.csv").read_text().splitlines()
    (cube / "loads.csv").write_text("\n".join([SECRET] + text[1:]) + "\n")
    capsys.readouterr()
    assert main(["solve", str(cube), "--out", str(tmp_path / "o"), "--no-cache"]) == 2
    err = capsys.readouterr().err
    assert "loads.csv:1" in err and "column 1 of line 1 is not 'case'" in err and "SECRET" not in err


# --------------------------------------------------------------------------------------------
# 2. planted cache entries
# --------------------------------------------------------------------------------------------
LIMIT_S = 120
"""Time limit of a child ``blackbox`` run: ~2 s normally; only a hang reaches it."""
MEMORY = 3 << 30
"""Address-space limit of a child ``blackbox`` run: the cube needs well under 1 GiB."""


def _limits() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY, MEMORY))


def _blackbox(args: list[str]) -> subprocess.CompletedProcess:
    """``blackbox ARGS`` as a child process, limited in time and memory."""
    return subprocess.run([PY, "-m", "blackbox.cli", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=LIMIT_S, preexec_fn=_limits)


def _entry_of_solve(study: Path) -> Path:
    """Where ``blackbox solve STUDY`` keeps its one batch (the name follows from the study)."""
    from blackbox.adapters import make_adapter_for
    from solver_adapters.cache import entry_path

    s = load_study(study)
    a = make_adapter_for(s, cache=True)
    return entry_path(a.cache_dir, a.key(s.loads, a.dofs()))


@pytest.mark.parametrize("plant", ["fifo", "dev_zero", "huge", "other_user"])
def test_a_planted_entry_is_never_read_and_the_batch_is_recomputed(plant, cube, tmp_path):
    """A named pipe (opening it would wait for a writer forever), a link to /dev/zero (reading
    it never ends), a sparse 8 GiB file (beyond the size cap, and beyond the child's memory) or
    an entry of another user: not read, warned about, recomputed, and replaced by a real entry."""
    if plant == "other_user" and os.getuid() != 0:
        pytest.skip("giving a file to another user needs root")
    entry = _entry_of_solve(cube)
    entry.parent.mkdir(parents=True)
    if plant == "fifo":
        os.mkfifo(entry)
    elif plant == "dev_zero":
        entry.symlink_to("/dev/zero")
    elif plant == "huge":
        with open(entry, "wb") as fh:
            fh.truncate(8 << 30)
    else:
        entry.write_bytes(b"x")
        os.chown(entry, 12345, 12345)
    r = _blackbox(["solve", str(cube), "--out", str(tmp_path / "o")])
    assert r.returncode == 0, r.stderr
    assert "1 solver run(s)" in r.stdout and f"ignored {entry}" in r.stderr
    why = {"fifo": "a named pipe, not an entry", "dev_zero": "a symbolic link, not an entry",
           "huge": "more than the", "other_user": "owned by user id 12345"}[plant]
    assert why in r.stderr
    assert entry.is_file() and not entry.is_symlink() and entry.stat().st_size < 1 << 20
    again = _blackbox(["solve", str(cube), "--out", str(tmp_path / "o")])
    assert again.returncode == 0 and "(0 solver run(s))" in again.stdout   # the new entry is used


@pytest.mark.parametrize("where", ["cache", "shard"])
def test_a_linked_cache_folder_is_not_written_through(where, cube, tmp_path):
    """``.blackbox_cache`` (or its two-letter sub-folder) is a link to a folder outside the study:
    nothing is read from or written there; the solve runs, warning that the cache is off."""
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    entry = _entry_of_solve(cube)
    if where == "cache":
        (cube / ".blackbox_cache").symlink_to(elsewhere)
    else:
        entry.parent.parent.mkdir()
        entry.parent.symlink_to(elsewhere)
    r = _blackbox(["solve", str(cube), "--out", str(tmp_path / "o")])
    assert r.returncode == 0, r.stderr
    assert "is a symbolic link" in r.stderr and "the cache is off for this run" in r.stderr
    assert list(elsewhere.iterdir()) == []


def test_the_size_cap_follows_from_the_request():
    from solver_adapters.cache import HEADER_FIXED_BYTES, MAC_PREFIX, MAGIC, entry_size_cap

    report, cases = [(1, 1), (2, 3)], ["a", "b", "c"]
    values = 8 * 2 * 3
    assert entry_size_cap(report, cases) == (len(MAGIC) + HEADER_FIXED_BYTES + len('[[1, 1], [2, 3]]')
                                             + len('["a", "b", "c"]') + 1 + len(MAC_PREFIX) + 65 + values)


# --------------------------------------------------------------------------------------------
# 3. --out deletes nothing of the user's
# --------------------------------------------------------------------------------------------
def test_the_marker_lists_every_file_with_size_and_digest(cube, tmp_path):
    out = tmp_path / "o"
    assert main(["identify", str(cube), "--out", str(out), "--no-cache"]) == 0
    marker = json.loads((out / MARKER).read_text())
    assert marker["command"] == "identify" and marker["format"] == 2
    on_disk = {p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file() and p.name != MARKER}
    assert set(marker["files"]) == on_disk and marker["files"] == written_files(out)
    assert marker["files"]["result.json"]["size"] == (out / "result.json").stat().st_size


@pytest.mark.parametrize("marker", ["legacy", "genuine"])
def test_a_copied_marker_makes_no_folder_replaceable(marker, cube, tmp_path, capsys):
    """The attack: a folder with the user's file and a marker copied from elsewhere (the old
    24-byte one, or a complete one from a real output) is not replaced."""
    real = tmp_path / "real"
    assert main(["solve", str(cube), "--out", str(real), "--no-cache"]) == 0
    victim = tmp_path / "victim"
    victim.mkdir()
    (victim / "thesis.docx").write_bytes(b"years of work")
    if marker == "legacy":
        (victim / MARKER).write_text('{"command": "solve"}\n')
        assert (victim / MARKER).stat().st_size == 21
    else:
        (victim / MARKER).write_bytes((real / MARKER).read_bytes())
    capsys.readouterr()
    assert main(["solve", str(cube), "--out", str(victim), "--no-cache"]) == 2
    err = capsys.readouterr().err
    if marker == "legacy":
        assert "does not list the files the command wrote" in err
    else:
        assert "thesis.docx (not written by the command)" in err
    assert (victim / "thesis.docx").read_bytes() == b"years of work"


def test_a_file_added_or_changed_in_an_earlier_output_is_never_deleted(cube, tmp_path, capsys):
    out = tmp_path / "o"
    assert main(["solve", str(cube), "--out", str(out), "--no-cache"]) == 0
    (out / "notes.txt").write_text("mine")
    (out / "sub").mkdir()
    (out / "sub" / "plot.png").write_bytes(b"mine too")
    capsys.readouterr()
    assert main(["solve", str(cube), "--out", str(out), "--no-cache"]) == 2
    err = capsys.readouterr().err
    assert "notes.txt (not written by the command)" in err and "sub/plot.png" in err
    assert (out / "notes.txt").read_text() == "mine" and (out / "sub" / "plot.png").read_bytes() == b"mine too"
    (out / "notes.txt").unlink()
    (out / "sub" / "plot.png").unlink()
    (out / "sub").rmdir()
    with (out / "displacements.csv").open("a") as fh:          # the user edited a result
        fh.write("# checked by hand\n")
    assert main(["solve", str(cube), "--out", str(out), "--no-cache"]) == 2
    assert "displacements.csv (changed since the command wrote it)" in capsys.readouterr().err
    assert (out / "displacements.csv").read_text().endswith("# checked by hand\n")
    (out / "displacements.csv").unlink()                        # a file the user removed: nothing to keep
    (out / "link").symlink_to(cube)
    assert main(["solve", str(cube), "--out", str(out), "--no-cache"]) == 2
    assert "link (a symbolic link)" in capsys.readouterr().err
    (out / "link").unlink()
    assert main(["solve", str(cube), "--out", str(out), "--no-cache"]) == 0   # intact: replaced
    assert (out / "displacements.csv").is_file()


def test_a_forged_marker_cannot_point_outside_the_folder(cube, tmp_path):
    """A marker that lists a file beside the output (with its true size and digest) makes the
    folder replaceable, but the replacement deletes only what is inside it."""
    victim = tmp_path / "victim.txt"
    victim.write_text("beside the output")
    forged = tmp_path / "o"
    forged.mkdir()
    listing = written_files(tmp_path)["victim.txt"]
    (forged / MARKER).write_text(json.dumps({"command": "solve", "format": 2,
                                             "files": {"../victim.txt": listing}}))
    assert main(["solve", str(cube), "--out", str(forged), "--no-cache"]) == 0
    assert victim.read_text() == "beside the output"


def test_reruns_keep_the_study_cache_of_a_simulated_study(cube, tmp_path):
    """simulate, identify the simulated study (its cache appears in it), simulate again into the
    same folder: allowed, and the cache is kept (moved into the new output)."""
    sim = tmp_path / "sim"
    args = ["simulate", str(cube), "--truth", str(cube / "truth.toml"), "--out", str(sim)]
    assert main(args) == 0
    assert main(["identify", str(sim), "--out", str(tmp_path / "id")]) == 0
    entries = sorted(p.name for p in (sim / ".blackbox_cache").rglob("*.bbc"))
    assert entries
    assert main(args) == 0
    assert sorted(p.name for p in (sim / ".blackbox_cache").rglob("*.bbc")) == entries
