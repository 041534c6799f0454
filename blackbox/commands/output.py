"""Where a command's files go: checked before any work, written whole or not at all.

A command never deletes or overwrites what it did not create. ``--out`` must be a folder that
does not exist, an empty folder, or an intact earlier output of the same command. Every output
folder holds the marker file :data:`MARKER`, written last, that names the command and lists every
file it wrote with its size and sha256: the marker binds the folder to its contents. A folder is
replaced only when its marker names this command and everything in it is a listed file, unchanged
(missing ones do not matter); a file added, changed or swapped for a link since is the user's,
and the folder is refused with those files listed. A marker copied into another folder therefore
makes nothing replaceable: the folder's other files are not on its list. The one exception is
the solver cache ``.blackbox_cache/`` that blackbox itself adds when the output is a study later
run (``simulate``, ``import``): it is moved into the new output, never deleted.

:func:`check_out` says so before the computation starts; :func:`write_output` writes the result
into a temporary folder beside ``--out``, checks the old folder again and moves the new one into
place, so an interrupted run leaves either the old output or the new one, never a mix. Of the old
output only the listed files are deleted.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import stat
import tempfile
import time
import warnings
from pathlib import Path
from typing import Callable, Protocol

from blackbox.errors import StudyError

__all__ = ["MARKER", "CommandResult", "check_out", "write_output", "written_files"]

MARKER = ".blackbox-output"
"""Marker file in every command's output folder: JSON ``{"command": name, "format": 2, "files":
{relative path: {"size": bytes, "sha256": hex}}}`` (see the module docstring)."""

MARKER_FORMAT = 2
MARKER_MAX_BYTES = 16 * 1024 * 1024
"""A larger marker is not ours (it lists file names and digests: ~120 bytes a file)."""

CACHE_FOLDER = ".blackbox_cache"
"""The solver cache blackbox adds to a study; carried from an old output into its replacement."""

_FLAGS = os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)


class CommandResult(Protocol):
    """What every command's ``run`` returns: a typed result that can write its files."""
    command: str

    def write(self, out: Path) -> list[str]:
        """Write every output file into the (existing, empty) folder ``out``; return their names."""


# --------------------------------------------------------------------------------------------
# what a folder holds
# --------------------------------------------------------------------------------------------
def _digest(path: Path, limit: int | None = None) -> tuple[int, str] | None:
    """``(size, sha256)`` of a regular file opened without following a link or blocking; None
    for anything else (or a file over ``limit`` bytes)."""
    try:
        fd = os.open(path, _FLAGS)
    except OSError:
        return None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode) or (limit is not None and st.st_size > limit):
            return None
        h, size = hashlib.sha256(), 0
        while block := os.read(fd, 1 << 20):
            h.update(block)
            size += len(block)
        return size, h.hexdigest()
    finally:
        os.close(fd)


def written_files(folder: str | Path) -> dict[str, dict]:
    """Every regular file under ``folder`` (the marker left out), ``{relative POSIX path:
    {"size": bytes, "sha256": hex}}``: what the marker lists. Links are not followed."""
    folder = Path(folder)
    out: dict[str, dict] = {}
    for here, dirs, names in os.walk(folder, followlinks=False):
        rel = Path(here).relative_to(folder)
        dirs.sort()
        for n in sorted(names):
            if rel == Path(".") and n == MARKER:
                continue
            got = _digest(Path(here) / n)
            if got is not None:
                out[(rel / n).as_posix()] = {"size": got[0], "sha256": got[1]}
    return out


def _read_marker(folder: Path) -> dict | None:
    """The marker of ``folder`` as a dict (None: absent, a link, not a regular file, too large,
    or not a marker)."""
    path = folder / MARKER
    got = _digest(path, MARKER_MAX_BYTES)
    if got is None:
        return None
    try:
        data = json.loads(path.read_bytes())     # the file just checked (a swap only makes it unreadable)
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) and isinstance(data.get("command"), str) else None


def _foreign(folder: Path, listed: dict) -> list[str]:
    """What in ``folder`` the command did not write: ``["name (why)", ...]`` for every file not
    listed, changed since, a link or not a regular file. The marker and a top-level real
    :data:`CACHE_FOLDER` are not counted."""
    found: list[str] = []
    for here, dirs, names in os.walk(folder, followlinks=False):
        rel = Path(here).relative_to(folder)
        keep = []
        for d in sorted(dirs):
            p = Path(here) / d
            if p.is_symlink():
                found.append(f"{(rel / d).as_posix()} (a symbolic link)")
            elif not (rel == Path(".") and d == CACHE_FOLDER):
                keep.append(d)
        dirs[:] = keep
        for n in sorted(names):
            name = (rel / n).as_posix()
            if name == MARKER:
                continue
            p = Path(here) / n
            if p.is_symlink():
                found.append(f"{name} (a symbolic link)")
                continue
            entry = listed.get(name)
            if not isinstance(entry, dict):
                found.append(f"{name} (not written by the command)")
                continue
            got = _digest(p)
            if got is None:
                found.append(f"{name} (not a regular file)")
            elif got != (entry.get("size"), entry.get("sha256")):
                found.append(f"{name} (changed since the command wrote it)")
    return found


def _replaceable(out: Path, command: str) -> None:
    """Raise :class:`StudyError` unless the non-empty folder ``out`` is an intact earlier output
    of ``command`` (module docstring)."""
    marker = _read_marker(out)
    found = marker.get("command") if marker else None
    if found != command:
        what = f"the output of 'blackbox {found}'" if found else "files this command did not write"
        raise StudyError(f"--out is not empty: it holds {what}. Give a new or empty folder "
                         f"(an earlier output of 'blackbox {command}' may be replaced)", file=str(out))
    listed = marker.get("files")
    if marker.get("format") != MARKER_FORMAT or not isinstance(listed, dict):
        raise StudyError(f"--out holds an output of 'blackbox {command}' whose marker {MARKER} does not "
                         f"list the files the command wrote (an older blackbox, or a copied marker), so "
                         f"blackbox cannot tell whether any file there is yours and will not replace it. "
                         f"Give a new or empty folder, or move that folder away yourself", file=str(out))
    foreign = _foreign(out, listed)
    if foreign:
        shown = ", ".join(foreign[:10]) + (f" and {len(foreign) - 10} more" if len(foreign) > 10 else "")
        raise StudyError(f"--out holds an earlier output of 'blackbox {command}' with files the command did "
                         f"not write: {shown}. They are never deleted: move them elsewhere, or give a new "
                         f"or empty folder", file=str(out))


# --------------------------------------------------------------------------------------------
# the two steps
# --------------------------------------------------------------------------------------------
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
            _replaceable(out, command)
    parent = out.parent                      # missing parents are created (nothing is replaced)
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise StudyError(f"{parent} is a file, not a folder, so --out cannot be made there", file=str(out))
    if not os.access(parent, os.W_OK | os.X_OK):
        raise StudyError(f"cannot write in {parent}, the parent folder of --out (permission denied)", file=str(out))
    return out


def _remove_listed(folder: Path, listed: dict) -> None:
    """Delete the files under ``folder`` that ``listed`` names, unchanged, then its empty
    sub-folders. Only what is found inside ``folder`` is considered (a listed name leading
    elsewhere is never touched); anything else stays."""
    for here, dirs, names in os.walk(folder, topdown=False, followlinks=False):
        rel = Path(here).relative_to(folder)
        for n in names:
            p = Path(here) / n
            entry = listed.get((rel / n).as_posix())
            if (rel == Path(".") and n == MARKER) or (
                    isinstance(entry, dict) and not p.is_symlink()
                    and _digest(p) == (entry.get("size"), entry.get("sha256"))):
                p.unlink()
        for d in dirs:
            try:
                os.rmdir(Path(here) / d)        # only when empty (a link to a folder is not one)
            except OSError:
                pass


def write_output(out: str | Path, command: str, write: Callable[[Path], list[str]]) -> list[str]:
    """Run ``write(tmp)`` into a fresh folder beside ``out``, then move it into place.

    An earlier output of the same command at ``out`` is replaced only after the new one is
    complete, and only when it is still intact (:func:`check_out` again: a file the user added
    meanwhile refuses it, and the new output is then kept beside ``out``, its path in the error).
    Returns the file names ``write`` reported."""
    out = check_out(out, command)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.partial-", dir=out.parent))
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o777 & ~umask)            # mkdtemp makes 0700; an output folder is an ordinary one
    try:
        files = write(tmp)
        listing = written_files(tmp)
        (tmp / MARKER).write_text(json.dumps({"command": command, "format": MARKER_FORMAT,
                                              "files": listing}, indent=1) + "\n")
        if out.exists():
            try:
                os.rmdir(out)                # empty: nothing to keep
            except OSError:
                pass
        if out.exists():
            try:
                check_out(out, command)
            except StudyError as exc:        # changed while the command ran: keep both
                kept = out.with_name(f"{out.name}.new-{time.strftime('%Y%m%d-%H%M%S')}")
                os.rename(tmp, kept)
                raise StudyError(f"{exc.args[0]} (it changed while the command ran; the new output is in "
                                 f"{kept})") from None
            previous = _read_marker(out)["files"]
            cache = out / CACHE_FOLDER
            if cache.is_dir() and not cache.is_symlink() and not (tmp / CACHE_FOLDER).exists():
                os.rename(cache, tmp / CACHE_FOLDER)
            old = Path(tempfile.mkdtemp(prefix=f".{out.name}.old-", dir=out.parent))
            os.rename(out, old / "previous")
            os.rename(tmp, out)
            _remove_listed(old / "previous", previous)
            try:
                os.rmdir(old / "previous")
                os.rmdir(old)
            except OSError:                  # something appeared in the last moment: kept
                kept = out.with_name(f"{out.name}.kept-{time.strftime('%Y%m%d-%H%M%S')}")
                os.rename(old / "previous", kept)
                shutil.rmtree(old, ignore_errors=True)
                warnings.warn(f"files that appeared in {out} while it was replaced were kept in {kept}",
                              RuntimeWarning, stacklevel=2)
        else:
            os.rename(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return files
