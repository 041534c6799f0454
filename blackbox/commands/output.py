"""Where a command's files go: checked before any work, written whole or not at all.

A command never deletes or overwrites what it did not create. ``--out`` must be a folder that
does not exist, an empty folder, or an earlier output of the same command (it holds the marker
file :data:`MARKER` naming that command). :func:`check_out` says so before the computation starts;
:func:`write_output` writes the result into a temporary folder beside ``--out`` and moves it into
place, so an interrupted run leaves either the old output or the new one, never a mix.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Callable, Protocol

from blackbox.errors import StudyError

__all__ = ["MARKER", "CommandResult", "check_out", "write_output"]

MARKER = ".blackbox-output"
"""Marker file in every command's output folder: JSON ``{"command": name}``."""


class CommandResult(Protocol):
    """What every command's ``run`` returns: a typed result that can write its files."""
    command: str

    def write(self, out: Path) -> list[str]:
        """Write every output file into the (existing, empty) folder ``out``; return their names."""


def _marker_command(folder: Path) -> str | None:
    try:
        return json.loads((folder / MARKER).read_text()).get("command")
    except (OSError, ValueError, AttributeError):
        return None


def check_out(out: str | Path, command: str, *, protect: tuple[Path, ...] = ()) -> Path:
    """``out`` as an absolute path, after checking that ``command`` may write there.

    ``protect``: folders the output must neither be, nor lie inside, nor contain (the study)."""
    out = Path(out).absolute()
    real = out.resolve()
    for p in protect:
        p = Path(p).resolve()
        if real == p or p.is_relative_to(real) or real.is_relative_to(p):
            raise StudyError(f"--out must be outside the study folder {p} and must not contain it",
                             file=str(out))
    if out.is_symlink():
        raise StudyError("--out is a symbolic link; give a real folder", file=str(out))
    if out.exists():
        if not out.is_dir():
            raise StudyError("--out exists and is not a folder", file=str(out))
        if any(out.iterdir()):
            found = _marker_command(out)
            if found != command:
                what = f"the output of 'blackbox {found}'" if found else "files this command did not write"
                raise StudyError(f"--out is not empty: it holds {what}. Give a new or empty folder "
                                 f"(an earlier output of 'blackbox {command}' may be replaced)", file=str(out))
    parent = out.parent                      # missing parents are created (nothing is replaced)
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise StudyError(f"{parent} is a file, not a folder, so --out cannot be made there", file=str(out))
    if not os.access(parent, os.W_OK | os.X_OK):
        raise StudyError(f"cannot write in {parent}, the parent folder of --out (permission denied)", file=str(out))
    return out


def write_output(out: str | Path, command: str, write: Callable[[Path], list[str]]) -> list[str]:
    """Run ``write(tmp)`` into a fresh folder beside ``out``, then move it into place.

    An earlier output of the same command at ``out`` is replaced only after the new one is
    complete. Returns the file names ``write`` reported."""
    out = check_out(out, command)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.partial-", dir=out.parent))
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o777 & ~umask)            # mkdtemp makes 0700; an output folder is an ordinary one
    try:
        files = write(tmp)
        (tmp / MARKER).write_text(json.dumps({"command": command}) + "\n")
        if out.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{out.name}.old-", dir=out.parent))
            os.rename(out, old / "previous")
            os.rename(tmp, out)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.rename(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return files
