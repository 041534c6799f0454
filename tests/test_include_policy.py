"""What an INCLUDE may read (issue 22, the INCLUDE bullet): regular files inside the including
deck's folder tree only, unless the user allows a folder (``--include-dir``, or ``include_dirs``
in the user configuration); an included file must be bulk data; ``blackbox import`` copies into
``model.bdf`` nothing of an included file that it did not read as a card.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from blackbox.cli import main
from blackbox.commands import import_deck
from solver_adapters.bdf import read_deck
from solver_adapters.protocol import DeckFormatError

BULK = """GRID,1,,0.,0.,0.
GRID,2,,2.,0.,0.
CBAR,1,7,1,2,0.,1.,0.
MAT1,1,2.1E11,,.3
SPC1,1,123456,1
FORCE,5,2,,1.,0.,0.,-1.
"""
PBAR = "PBAR,7,1,1.E-3,2.E-6,3.E-6,4.E-6\n"
SECRET = "root:x:0:0:root:/root:/bin/bash\nsecret-token-4711\n"


def _deck(folder: Path, include: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    p = folder / "deck.dat"
    p.write_text("SOL 101\nCEND\nSPC = 1\nLOAD = 5\nBEGIN BULK\n" + BULK + f"INCLUDE '{include}'\nENDDATA\n")
    return p


@pytest.fixture(autouse=True)
def _own_config(tmp_path, monkeypatch):
    """No user configuration but the test's own."""
    monkeypatch.setenv("BLACKBOX_CONFIG_DIR", str(tmp_path / "config"))


def test_include_of_a_system_file_is_refused_at_the_include_line(tmp_path, capsys):
    """``INCLUDE '/etc/passwd'``: exit 2, the message names the INCLUDE line, and nothing of
    the file (which is never opened) reaches the output or the study."""
    deck = _deck(tmp_path / "d", "/etc/passwd")
    code = main(["import", str(deck), "--out", str(tmp_path / "study")])
    err = capsys.readouterr().err
    assert code == 2
    assert f"{deck}:12" in err and "card INCLUDE" in err and "outside the deck's folder" in err
    assert "root:" not in err and not (tmp_path / "study").exists()


def test_include_outside_the_folder_names_no_content(tmp_path):
    outside = tmp_path / "elsewhere" / "secret.txt"
    outside.parent.mkdir()
    outside.write_text(SECRET)
    deck = _deck(tmp_path / "d", str(outside))
    with pytest.raises(DeckFormatError) as info:
        import_deck.run(deck)
    assert (info.value.line, info.value.card, info.value.field) == (12, "INCLUDE", 2)
    assert "secret-token" not in str(info.value) and "root:" not in str(info.value)


def test_a_symlink_inside_the_folder_to_a_file_outside_is_refused(tmp_path):
    outside = tmp_path / "elsewhere" / "props.inc"
    outside.parent.mkdir()
    outside.write_text(PBAR)
    deck = _deck(tmp_path / "d", "props.inc")
    os.symlink(outside, tmp_path / "d" / "props.inc")
    with pytest.raises(DeckFormatError, match=r"outside the deck's folder .*symbolic links followed") as info:
        import_deck.run(deck)
    assert (info.value.line, info.value.card) == (12, "INCLUDE")
    with pytest.raises(DeckFormatError, match="outside the deck's folder"):
        read_deck(deck)


def test_an_allowed_folder_is_read(tmp_path, capsys):
    """``--include-dir`` (and ``include_dirs`` in the user configuration) allows a folder: the
    included cards reach the study, written into model.bdf."""
    common = tmp_path / "common"
    common.mkdir()
    (common / "props.inc").write_text(PBAR)
    deck = _deck(tmp_path / "d", str(common / "props.inc"))
    assert main(["import", str(deck), "--out", str(tmp_path / "s1"), "--include-dir", str(common)]) == 0
    assert "PBAR,7,1,1.E-3" in (tmp_path / "s1" / "model.bdf").read_text()
    config = tmp_path / "config"
    config.mkdir()
    (config / "config.toml").write_text(f'include_dirs = ["{common}"]\n')
    os.chmod(config / "config.toml", 0o600)
    assert main(["import", str(deck), "--out", str(tmp_path / "s2")]) == 0
    assert "PBAR,7,1,1.E-3" in (tmp_path / "s2" / "model.bdf").read_text()
    capsys.readouterr()


def test_only_regular_files_are_included(tmp_path):
    """A FIFO would block the reader and a folder is no file: both refused before any read."""
    (tmp_path / "d").mkdir()
    os.mkfifo(tmp_path / "d" / "pipe.inc")
    (tmp_path / "d" / "sub").mkdir()
    for name in ("pipe.inc", "sub"):
        with pytest.raises(DeckFormatError, match="not a regular file") as info:
            import_deck.run(_deck(tmp_path / "d", name))
        assert info.value.card == "INCLUDE"


def test_an_included_file_must_be_bulk_data(tmp_path):
    """A line of an included file that is no card is an error at that line that shows nothing
    of it; executive or case control in an included file is an error at the INCLUDE line."""
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "notes.inc").write_text(PBAR + "the password is hunter2\n")
    with pytest.raises(DeckFormatError, match="not bulk data") as info:
        import_deck.run(_deck(tmp_path / "d", "notes.inc"))
    assert (Path(info.value.file).name, info.value.line) == ("notes.inc", 2)
    assert "hunter2" not in str(info.value) and "password" not in str(info.value)
    (tmp_path / "d" / "job.inc").write_text("SOL 101\nCEND\nBEGIN BULK\n" + PBAR)
    with pytest.raises(DeckFormatError, match="CEND") as info:
        import_deck.run(_deck(tmp_path / "d", "job.inc"))
    assert (info.value.line, info.value.card) == (12, "INCLUDE")


def test_import_copies_only_what_it_read_as_cards_from_an_included_file(tmp_path):
    """Comments (whole lines and after a card) of an included file stay out of model.bdf; the
    input file's own comments stay in."""
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "props.inc").write_text("$ private remark\nPBAR,7,1,1.E-3,2.E-6,3.E-6,4.E-6 $ note\n")
    deck = _deck(tmp_path / "d", "props.inc")
    deck.write_text(deck.read_text().replace("BEGIN BULK\n", "BEGIN BULK\n$ my own remark\n"))
    text = import_deck.run(deck).model_bdf
    assert "PBAR,7,1,1.E-3,2.E-6,3.E-6,4.E-6" in text
    assert "private remark" not in text and "$ note" not in text and "$ my own remark" in text


def test_an_include_written_on_windows_is_found(tmp_path):
    """``INCLUDE 'Props\\PBAR.INC'`` from a deck written on Windows: backslashes as separators
    and the parts in any letter case find ``props/pbar.inc``; the import then reads the
    property, as NASTRAN on Windows would."""
    (tmp_path / "d" / "props").mkdir(parents=True)
    (tmp_path / "d" / "props" / "pbar.inc").write_text(PBAR)
    result = import_deck.run(_deck(tmp_path / "d", "Props\\PBAR.INC"))
    assert "PBAR,7" in result.model_bdf and result.deck.pbars[7].a == 1e-3


def test_a_windows_spelling_leaves_the_folder_only_if_allowed(tmp_path):
    """The same reading of ``..\\elsewhere\\secret.txt`` is still outside the deck's folder,
    refused as any other; and two files of one name in different letter cases are no match."""
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "elsewhere" / "secret.txt").write_text(SECRET)
    with pytest.raises(DeckFormatError, match="outside the deck's folder") as info:
        import_deck.run(_deck(tmp_path / "d", "..\\ELSEWHERE\\secret.txt"))
    assert "secret-token" not in str(info.value)
    (tmp_path / "e").mkdir()
    (tmp_path / "e" / "a.inc").write_text(PBAR)
    (tmp_path / "e" / "A.inc").write_text(PBAR)
    with pytest.raises(DeckFormatError, match="cannot read included file"):
        import_deck.run(_deck(tmp_path / "e", "a.INC"))


@pytest.mark.parametrize("begin", ["BEGIN SUPER 101", "BEGIN SUPER = 2", "BEGIN BULK SUPER=2", "BEGIN AUXMODEL 1"])
def test_a_bulk_data_section_of_its_own_is_refused_at_its_line(tmp_path, begin):
    """A superelement's or an auxiliary model's bulk data (pyyeti's ``outboard.pch``, included in
    an assembly run, starts with ``BEGIN SUPER 101``) is another structure: read as the main
    model's cards it would change it without a word. Both reader paths refuse it at its line;
    a second plain BEGIN BULK is skipped, and a section after ENDDATA is not read."""
    from solver_adapters.bdf import read_deck_text
    from test_reader_paths import both
    text = PBAR + BULK.replace("FORCE,5,2,,1.,0.,0.,-1.\n", "") + f"{begin}\nGRID,3,,1.,1.,0.\n"
    fast, slow = both(text, tmp_path)
    for err in (fast, slow):
        assert isinstance(err, DeckFormatError) and err.line == 7 and "section of its own" in str(err)
    assert read_deck_text(text.replace(begin, "BEGIN BULK")).grids.keys() == {1, 2, 3}
    assert read_deck_text(text.replace(begin, "ENDDATA\n" + begin)).grids.keys() == {1, 2}
