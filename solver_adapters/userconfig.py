"""The user's own blackbox configuration folder: the cache's secret key and ``config.toml``.

Both live outside any study folder on purpose: a study is data someone else may hand over, and
nothing in it may decide which programs run or which cached results are trusted.

The folder is ``$BLACKBOX_CONFIG_DIR`` when set (tests point it at a temporary folder), else
``$XDG_CONFIG_HOME/blackbox``, else ``~/.config/blackbox``.

``config.toml`` (optional)::

    # whole command lines (program and arguments as the study gives them), or a program alone,
    # which then runs only with the deck as its argument (see solver_adapters.subprocess)
    trusted_commands = [["/usr/bin/python3", "/opt/solver/solve.py", "{deck}"], "/usr/local/bin/mystran"]
    # folders outside a study that its files (deck, loads, ...) may lie in
    allow_outside = ["/data/shared-decks"]
    include_dirs = ["/home/me/nastran/common"]    # folders a deck's INCLUDE may read

Files here are only used when they are owned by the user and (for the key) not readable by
group or others, (for the configuration) not writable by group or others; otherwise
:class:`InsecureFileError` says what is wrong and how to fix it.
"""

from __future__ import annotations

import errno
import os
import stat
import tomllib
from pathlib import Path
from typing import Any

from solver_adapters.errors import InsecureFileError

CONFIG_ENV = "BLACKBOX_CONFIG_DIR"
CONFIG_FILE = "config.toml"


def config_dir() -> Path:
    """``$BLACKBOX_CONFIG_DIR``, else ``$XDG_CONFIG_HOME/blackbox``, else ``~/.config/blackbox``
    (an ``XDG_CONFIG_HOME`` that is not absolute is ignored, as the XDG specification says)."""
    env = os.environ.get(CONFIG_ENV)
    if env:
        return Path(env).expanduser()
    xdg = os.environ.get("XDG_CONFIG_HOME")
    if xdg and Path(xdg).is_absolute():
        return Path(xdg) / "blackbox"
    return Path.home() / ".config" / "blackbox"


def config_file(folder: str | os.PathLike | None = None) -> Path:
    """The path of ``config.toml`` in ``folder`` (default :func:`config_dir`)."""
    return Path(folder if folder is not None else config_dir()) / CONFIG_FILE


def check_private(path: Path, st: os.stat_result, *, forbid: int, what: str) -> None:
    """Refuse ``path`` (with ``st`` its ``fstat``) unless it is a regular file owned by this user
    with none of the permission bits ``forbid`` set. No check where there are no POSIX owners."""
    if not hasattr(os, "getuid"):
        return
    if not stat.S_ISREG(st.st_mode):
        raise InsecureFileError(f"{what} {path} is not a regular file; remove it "
                                f"(rm -r '{path}') and blackbox will write a new one")
    if st.st_uid != os.getuid():
        raise InsecureFileError(f"{what} {path} is owned by user id {st.st_uid}, not by you "
                                f"(user id {os.getuid()}): another user could have chosen its "
                                f"contents. Remove it (rm '{path}') and blackbox will write a new one")
    if st.st_mode & forbid:
        mode = stat.S_IMODE(st.st_mode)
        fix = "chmod 600" if forbid & 0o044 else "chmod go-w"
        raise InsecureFileError(f"{what} {path} has permissions {mode:04o}: other users can "
                                f"{'read' if st.st_mode & forbid & 0o044 else 'change'} it. "
                                f"Fix with: {fix} '{path}'")


def read_private(path: Path, *, forbid: int, what: str) -> bytes:
    """The bytes of ``path`` after :func:`check_private` on the opened file (no symlink
    followed, so the checked file is the one read). ``FileNotFoundError`` if absent."""
    flags = os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(path, flags)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise InsecureFileError(f"{what} {path} is a symbolic link; replace it by the file "
                                    f"itself or remove it (rm '{path}')") from None
        raise
    try:
        check_private(path, os.fstat(fd), forbid=forbid, what=what)
        with os.fdopen(fd, "rb", closefd=False) as fh:
            return fh.read()
    finally:
        os.close(fd)


def read_config(folder: str | os.PathLike | None = None) -> dict[str, Any]:
    """The user's ``config.toml`` as a dict ({} when there is none). Refused when group or
    others may write it (they could add a trusted command); ``ValueError`` if it is not TOML."""
    path = config_file(folder)
    try:
        data = read_private(path, forbid=0o022, what="blackbox configuration file")
    except FileNotFoundError:
        return {}
    try:
        return tomllib.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise ValueError(f"{path}: not a valid TOML file: {exc}") from None


def configured_include_dirs(folder: str | os.PathLike | None = None) -> tuple[Path, ...]:
    """The folders the user allows a deck's INCLUDE to read besides the deck's own folder tree
    (``include_dirs`` of ``config.toml``; ``~`` expanded). A value that is not a list of strings
    is an error naming the file."""
    value = read_config(folder).get("include_dirs", [])
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise ValueError(f"{config_file(folder)}: include_dirs must be a list of folder names")
    return tuple(Path(v).expanduser() for v in value)


ALLOW_OUTSIDE_KEY = "allow_outside"


def allowed_outside(folder: str | os.PathLike | None = None) -> list[Path]:
    """The folders listed under ``allow_outside`` in the user's ``config.toml`` (absolute,
    symlink-free): a study's files may lie in them although they are outside the study folder.
    ``ValueError`` for an entry that is not an absolute path."""
    cfg = read_config(folder)
    listed = cfg.get(ALLOW_OUTSIDE_KEY, [])
    where = config_file(folder)
    if not isinstance(listed, list) or not all(isinstance(x, str) for x in listed):
        raise ValueError(f"{where}: {ALLOW_OUTSIDE_KEY} must be a list of strings (absolute paths of folders)")
    out = []
    for entry in listed:
        p = Path(entry).expanduser()
        if not p.is_absolute():
            raise ValueError(f"{where}: {ALLOW_OUTSIDE_KEY} entry {entry!r} is not an absolute path; "
                             f"write the full path of the folder")
        out.append(p.resolve())
    return out
