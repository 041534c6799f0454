"""Solver-run cache: :class:`CachedAdapter` answers a repeated ``solve`` from disk, without a run.

A long study (identification, diagnosis, a benchmark) makes many batches; an interrupted one is
resumed by running the same command again: every batch that finished before the interruption is
read back, the others are computed. ``blackbox`` commands use ``STUDY/.blackbox_cache/`` (see
``blackbox.adapters.make_adapter_for``; ``--no-cache`` bypasses it, ``--cache-dir`` moves it).

The key
-------
sha256 over everything that decides the answer:

* the deck: the bytes of the main file and of every file it INCLUDEs (recursively), in reading
  order. Contents, not paths: a study folder copied elsewhere keeps its cache. The deck is
  fingerprinted when the adapter is wrapped and again at every solve; if it changed in between,
  the inner adapter may hold the old model, so that solve bypasses the cache (``bypassed``);
* the extra springs (``with_springs``), in order, with ``repr`` of each stiffness;
* the load matrix: DOF labels, case labels, and the CSC arrays of its values (duplicates summed,
  explicit zeros dropped, indices sorted: equal matrices give equal bytes);
* the report labels, in order;
* the adapter: class, ``name``, ``version`` and the options that change results (``command``,
  ``backend``, ``misbehave``, the dialect's name and scalar settings);
* the solver program itself, when the adapter has an ``identity()`` method (computed once per
  adapter): for an external code (:meth:`solver_adapters.subprocess.CommandAdapter.identity`)
  the sha256 of its executable and of an interpreter's script, and its version when the adapter
  or dialect can tell. A rebuilt or replaced solver misses the cache.

An adapter that is neither deck-file based nor one of ours can define ``cache_token()``
(a string that changes whenever its answers may change); it replaces the deck fingerprint.

Entries
-------
``CACHE_DIR/<key[:2]>/<key>.bbc``: a magic line, one JSON header line (key, shape, dtype, report
labels, cases, sha256 and length of the value bytes, adapter, time), one line
``hmac-sha256 <hex>`` and the raw float64 values.
An entry is written to a temporary file in the same directory, flushed, ``fsync``-ed and renamed
over the final name with ``os.replace`` (atomic on POSIX), so a reader sees either the whole old
entry, the whole new one or none, and two processes writing the same key leave one valid entry.
On read the header must match the request and the sha256 of the values must match the header;
anything else (a truncated file, a flipped byte) counts as ``corrupt``, is ignored and is
rewritten by the recomputed result. A failed run raises before anything is written: failures are
never cached. The cache never makes a solve fail: an unwritable directory is counted
(``store_errors``) and warned about once.

What is opened
--------------
The cache folder travels with the study, so whoever sent the study chose what is in it, and entry
names can be computed from the study alone. So the cache folder and its two-letter sub-folders
are opened as real directories only (never through a symbolic link; every later step works
relative to the opened directory), and an entry is opened without following a link and without
blocking (a named pipe would otherwise wait for a writer forever), then checked on the open file
before a byte is read: a regular file, owned by this user, and no larger than
:func:`entry_size_cap` for the request. Anything else is :class:`~solver_adapters.errors.UnsafeEntry`:
never read, counted (``corrupt`` and ``unsafe``), warned about, recomputed and replaced by the
new entry (the rename replaces the name, it does not write through it). A cache folder that is
a symbolic link or not a directory (:class:`~solver_adapters.errors.UnsafeCacheFolder`) turns
the cache off for the run, with a warning: nothing is read from or written through it.

Authentication
--------------
A checksum only catches accidents: whoever can write the cache folder (it travels with the
study) can plant an entry with a matching sha256 and change results silently. So every entry
carries an HMAC-SHA256, over the magic line, the header line and the values, keyed with a
per-user secret kept outside any study: ``cache.key`` in the user's configuration folder
(:func:`solver_adapters.userconfig.config_dir`: ``$BLACKBOX_CONFIG_DIR``, else
``$XDG_CONFIG_HOME/blackbox``, else ``~/.config/blackbox``), 32 random bytes in hex, created
with mode 0600 on first use (atomically: written to a private temporary file, then linked to
its name, so concurrent first uses agree on one key). A key file that another user owns or that
group or others may read is refused (:class:`~solver_adapters.userconfig.InsecureFileError`,
saying how to fix it). An entry whose MAC does not verify - planted, altered, or written by
another user - is never used: it counts as ``corrupt`` and ``unauthenticated``, a
``RuntimeWarning`` names it, and the result is recomputed and stored under this user's key. A
cache folder shared between users therefore works as a private cache for each.
"""

from __future__ import annotations

import hashlib
import hmac
import json
import os
import re
import secrets
import stat
import threading
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from solver_adapters.errors import CorruptEntry, UnauthenticEntry, UnsafeCacheFolder, UnsafeEntry
from solver_adapters.protocol import (Displacements, DofLabel, LoadMatrix, ScalarSpring, SolverAdapter,
                                      SolverStats)
from solver_adapters.userconfig import InsecureFileError, config_dir, read_private

MAGIC = b"BLACKBOX-SOLVER-CACHE 2\n"
SUFFIX = ".bbc"
CACHE_DIRNAME = ".blackbox_cache"
STALE_TMP_S = 3600.0
"""A temporary file older than this was left by a writer that died; it is removed on the next write."""

_INCLUDE = re.compile(r"^\s*INCLUDE\s*(?:'([^']*)'|\"([^\"]*)\"|([^\s'\"$]+))", re.IGNORECASE)
_RESULT_OPTIONS = ("version", "command", "backend", "misbehave")
_COUNT_LOCK = threading.Lock()   # counters are shared by a CachedAdapter and its with_springs copies
KEY_FILE = "cache.key"
MAC_PREFIX = b"hmac-sha256 "
HEADER_FIXED_BYTES = 64 * 1024
"""Room in an entry's header line for everything but the report labels and the case names (key,
shape, dtype, sizes, sha256, time, adapter name, run count: a few hundred bytes in practice)."""
_DIR_FLAGS = os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
_READ_FLAGS = os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
_NOFOLLOW_OK = hasattr(os, "O_NOFOLLOW") and os.open in os.supports_dir_fd


@dataclass
class CacheStats:
    """What the cache did. ``hits`` made no solver run; ``misses`` ran the inner adapter."""

    hits: int = 0
    misses: int = 0
    stores: int = 0
    corrupt: int = 0
    store_errors: int = 0
    bypassed: int = 0
    not_stored: int = 0
    unauthenticated: int = 0
    unsafe: int = 0

    def snapshot(self) -> dict[str, int]:
        return dict(vars(self))


# --------------------------------------------------------------------------------------------
# the user's secret (authenticates entries)
# --------------------------------------------------------------------------------------------
def cache_key_path(folder: str | os.PathLike | None = None) -> Path:
    """Where the secret lives: ``cache.key`` in ``folder`` (default: the user's configuration
    folder, :func:`solver_adapters.userconfig.config_dir`)."""
    return Path(folder if folder is not None else config_dir()) / KEY_FILE


def _create_key(path: Path) -> None:
    """Write a new random key at ``path`` unless one exists: into a private (0600) temporary
    file first, then linked to the final name, which fails if another process got there first
    (its key is then used)."""
    path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
    tmp = path.with_name(f".{KEY_FILE}.{os.getpid()}.{secrets.token_hex(4)}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0), 0o600)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(secrets.token_hex(32).encode() + b"\n")
            fh.flush()
            os.fsync(fh.fileno())
        try:
            os.link(tmp, path)
        except FileExistsError:
            pass
        except OSError:  # a file system without hard links: exclusive create of the name itself
            try:
                fd2 = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0), 0o600)
            except FileExistsError:
                return
            with os.fdopen(fd2, "wb") as fh:
                fh.write(tmp.read_bytes())
    finally:
        try:
            os.unlink(tmp)
        except OSError:
            pass


def load_cache_key(folder: str | os.PathLike | None = None) -> bytes:
    """This user's secret for authenticating cache entries, created on first use (see the module
    docstring). :class:`~solver_adapters.userconfig.InsecureFileError` for a key file others
    could read or that another user owns; ``ValueError`` for one that is not a key."""
    path = cache_key_path(folder)
    for attempt in range(50):
        try:
            data = read_private(path, forbid=0o077, what="blackbox cache key")
        except FileNotFoundError:
            _create_key(path)
            continue
        text = data.decode("ascii", errors="replace").strip()
        if not text and attempt < 49:  # the no-hard-link fallback is still writing it
            time.sleep(0.01)
            continue
        try:
            key = bytes.fromhex(text)
        except ValueError:
            key = b""
        if len(key) < 32:
            raise ValueError(f"{path} is not a blackbox cache key (64 hex digits); remove it "
                             f"(rm '{path}') and a new one is made on the next run")
        return key
    raise OSError(f"cannot create the blackbox cache key {path}")


def _mac(secret: bytes, header_line: bytes, raw: bytes) -> bytes:
    m = hmac.new(secret, MAGIC, hashlib.sha256)
    m.update(header_line)
    m.update(b"\n")
    m.update(raw)
    return m.hexdigest().encode()


# --------------------------------------------------------------------------------------------
# the key
# --------------------------------------------------------------------------------------------
def deck_files(path: str | os.PathLike) -> list[Path]:
    """The deck and every file it INCLUDEs (recursively, relative to the including file), in
    reading order. Unreadable includes are left out: the adapter could not have read them either."""
    out: list[Path] = []

    def walk(p: Path) -> None:
        if p in out:
            return
        out.append(p)
        try:
            text = _read_regular(p).decode("latin-1")
        except OSError:
            return
        for line in text.splitlines():
            m = _INCLUDE.match(line)
            if m:
                name = next(g for g in m.groups() if g is not None).strip()
                walk((p.parent / name).resolve())

    walk(Path(path).resolve())
    return out


def _read_regular(path: Path) -> bytes:
    """The bytes of ``path`` if it is a regular file (links followed: a deck may be one), opened
    without blocking; ``OSError`` for anything else (a named pipe, a device, a folder)."""
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise OSError(f"{path} is not a regular file")
        with os.fdopen(fd, "rb", closefd=False) as fh:
            return fh.read()
    finally:
        os.close(fd)


def _files_digest(files: Sequence[Path]) -> str:
    h = hashlib.sha256()
    for f in files:
        try:
            data = _read_regular(f)
        except OSError:
            data = b"<unreadable>"
        h.update(hashlib.sha256(data).digest())
    return h.hexdigest()


def deck_fingerprint(adapter: Any) -> str:
    """What identifies the model an adapter solves: its ``cache_token()``, else the bytes of its
    deck files (``deck_path`` + INCLUDEs, plus any file listed in its parsed deck), else the parsed
    deck itself. ``TypeError`` when none is available."""
    token = getattr(adapter, "cache_token", None)
    if callable(token):
        return "token:" + str(token())
    path = getattr(adapter, "deck_path", None)
    parsed = getattr(adapter, "deck", None)
    if parsed is None:
        parsed = getattr(getattr(adapter, "_base", None), "model", None)
    if path is not None:
        files = deck_files(path)
        for name in getattr(parsed, "files", None) or []:   # what the reader itself followed
            p = Path(name).resolve()
            if p.is_file() and p not in files:
                files.append(p)
        return "files:" + _files_digest(files)
    if parsed is not None:
        return "deck:" + hashlib.sha256(repr(parsed).encode()).hexdigest()
    raise TypeError(f"CachedAdapter cannot identify the model of {type(adapter).__name__}: give it a "
                    f"deck_path attribute or a cache_token() method")


def _scalar_settings(obj: Any) -> dict[str, Any]:
    return {k: v for k, v in sorted(vars(obj).items())
            if not k.startswith("_") and isinstance(v, (str, int, float, bool, type(None)))}


def adapter_identity(adapter: Any) -> dict[str, Any]:
    """Class, name and the options that change an adapter's answers (see the module docstring)."""
    ident: dict[str, Any] = {"class": f"{type(adapter).__module__}.{type(adapter).__qualname__}",
                             "name": getattr(adapter, "name", None)}
    for attr in _RESULT_OPTIONS:
        value = getattr(adapter, attr, None)
        if value is not None:
            ident[attr] = list(value) if isinstance(value, (list, tuple)) else str(value)
    dialect = getattr(adapter, "dialect", None)
    if dialect is not None:
        ident["dialect"] = {"name": getattr(dialect, "name", type(dialect).__name__),
                            "class": f"{type(dialect).__module__}.{type(dialect).__qualname__}",
                            **(_scalar_settings(dialect) if hasattr(dialect, "__dict__") else {})}
    solver = getattr(adapter, "identity", None)
    if callable(solver):
        ident["solver"] = solver()
    return ident


def _springs_of(adapter: Any, tracked: tuple[ScalarSpring, ...]) -> tuple[ScalarSpring, ...]:
    """The adapter's own full list of extra springs when it exposes one, else those added
    through :meth:`CachedAdapter.with_springs`."""
    for attr in ("extra_springs", "springs"):
        value = getattr(adapter, attr, None)
        if isinstance(value, (tuple, list)) and all(isinstance(s, ScalarSpring) for s in value):
            return tuple(value)
    return tracked


def solve_key(identity: dict[str, Any], deck: str, springs: Sequence[ScalarSpring], loads: LoadMatrix,
              report: Sequence[DofLabel]) -> str:
    """The cache key of one ``solve`` (hex sha256); every part is length-prefixed."""
    h = hashlib.sha256()

    def part(tag: str, data: bytes) -> None:
        h.update(f"{tag}:{len(data)}:".encode())
        h.update(data)

    part("format", MAGIC)
    part("adapter", json.dumps(identity, sort_keys=True, default=str).encode())
    part("deck", deck.encode())
    part("springs", json.dumps([[list(s.a), list(s.b) if s.b is not None else None, repr(float(s.k))]
                                for s in springs]).encode())
    part("load_dofs", json.dumps([list(d) for d in loads.dofs]).encode())
    part("cases", json.dumps(list(loads.cases)).encode())
    v = loads.values.tocsc(copy=True)
    v.sum_duplicates()
    v.eliminate_zeros()
    v.sort_indices()
    part("shape", json.dumps(list(v.shape)).encode())
    part("indptr", np.asarray(v.indptr, dtype="<i8").tobytes())
    part("indices", np.asarray(v.indices, dtype="<i8").tobytes())
    part("data", np.asarray(v.data, dtype="<f8").tobytes())
    part("report", json.dumps([[int(g), int(c)] for g, c in report]).encode())
    return h.hexdigest()


# --------------------------------------------------------------------------------------------
# entries
# --------------------------------------------------------------------------------------------
def entry_path(cache_dir: str | os.PathLike, key: str) -> Path:
    return Path(cache_dir) / key[:2] / f"{key}{SUFFIX}"


def entry_size_cap(report: Sequence[DofLabel], cases: Sequence[str]) -> int:
    """The largest size an entry for ``report`` x ``cases`` can have: the magic line, a header
    line of at most :data:`HEADER_FIXED_BYTES` plus the JSON of the report labels and of the
    case names (as the writer spells them), the MAC line and 8 bytes per value. A file larger
    than this is not one of our entries and is not read."""
    labels = json.dumps([[int(g), int(c)] for g, c in report])
    names = json.dumps(list(cases))
    return (len(MAGIC) + HEADER_FIXED_BYTES + len(labels) + len(names) + 1
            + len(MAC_PREFIX) + 64 + 1 + 8 * len(report) * len(cases))


def _open_dir(name: str | os.PathLike, dir_fd: int | None = None, *, create: bool = False) -> int:
    """A descriptor of the directory ``name`` (relative to ``dir_fd`` when given), opened without
    following a symbolic link; made (mode 0777 & ~umask) first when ``create``. Raises
    :class:`UnsafeCacheFolder` for a link or anything but a directory, ``OSError`` otherwise."""
    if create:
        try:
            os.mkdir(name, dir_fd=dir_fd) if dir_fd is not None else Path(name).mkdir(parents=True)
        except FileExistsError:
            pass
    try:
        return os.open(name, _DIR_FLAGS, dir_fd=dir_fd)
    except OSError as exc:
        try:
            st = os.stat(name, dir_fd=dir_fd, follow_symlinks=False)
        except OSError:
            raise exc from None
        shown = name if dir_fd is None else f"{name} (in the cache folder)"
        if stat.S_ISLNK(st.st_mode):
            raise UnsafeCacheFolder(f"cache folder {shown} is a symbolic link; the cache reads and writes "
                                    f"only a real folder (remove the link, or give the real folder with "
                                    f"--cache-dir)") from None
        if not stat.S_ISDIR(st.st_mode):
            raise UnsafeCacheFolder(f"cache folder {shown} is not a folder") from None
        raise


class _EntryDir:
    """The folder of one entry, opened as a real directory: ``cache_dir`` (when given) and the
    entry's sub-folder, each without following links. A context manager; ``fd`` is the entry's
    folder. Without ``cache_dir``, only the entry's own folder is checked."""

    def __init__(self, path: Path, cache_dir: Path | None = None, *, create: bool = False):
        self.path, self.cache_dir, self.create = Path(path), cache_dir, create
        self.fd: int | None = None

    def __enter__(self) -> "_EntryDir":
        if not _NOFOLLOW_OK:                     # no O_NOFOLLOW / dir_fd: plain paths (Windows)
            if self.create:
                self.path.parent.mkdir(parents=True, exist_ok=True)
            return self
        if self.cache_dir is not None and self.path.parent.parent == self.cache_dir:
            top = _open_dir(self.cache_dir, create=self.create)
            try:
                self.fd = _open_dir(self.path.parent.name, top, create=self.create)
            finally:
                os.close(top)
        else:
            self.fd = _open_dir(self.path.parent, create=self.create)
        return self

    def __exit__(self, *exc) -> None:
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None

    def at(self) -> dict:
        """``dir_fd`` keyword for calls relative to the folder (none without descriptors)."""
        return {"dir_fd": self.fd} if self.fd is not None else {}

    def name(self, leaf: str) -> str | Path:
        return leaf if self.fd is not None else self.path.parent / leaf


def _read_capped(path: Path, folder: _EntryDir, cap: int) -> bytes:
    """The bytes of the entry ``path`` after checking the opened file: a regular file, owned by
    this user, at most ``cap`` bytes. ``FileNotFoundError`` if absent, :class:`UnsafeEntry`
    for anything else (never read)."""
    try:
        fd = os.open(folder.name(path.name), _READ_FLAGS, **folder.at())
    except FileNotFoundError:
        raise
    except OSError as exc:
        try:
            link = stat.S_ISLNK(os.stat(folder.name(path.name), follow_symlinks=False, **folder.at()).st_mode)
        except OSError:
            link = False
        if link:
            raise UnsafeEntry("a symbolic link, not an entry (not followed)") from None
        raise
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            kind = ("a named pipe" if stat.S_ISFIFO(st.st_mode) else "a device" if stat.S_ISCHR(st.st_mode)
                    or stat.S_ISBLK(st.st_mode) else "a folder" if stat.S_ISDIR(st.st_mode) else "a socket"
                    if stat.S_ISSOCK(st.st_mode) else "not a regular file")
            raise UnsafeEntry(f"{kind}, not an entry (not read)")
        if hasattr(os, "getuid") and st.st_uid != os.getuid():
            raise UnsafeEntry(f"owned by user id {st.st_uid}, not by you (not read)")
        if st.st_size > cap:
            raise UnsafeEntry(f"{st.st_size} bytes, more than the {cap} an entry for this request can have "
                              f"(not read)")
        chunks, left = [], cap + 1
        while left > 0:
            chunk = os.read(fd, min(left, 1 << 20))
            if not chunk:
                break
            chunks.append(chunk)
            left -= len(chunk)
        if left <= 0:
            raise UnsafeEntry(f"grew beyond {cap} bytes while being read (not used)")
        return b"".join(chunks)
    finally:
        os.close(fd)


def write_entry(path: Path, key: str, result: Displacements, extra: dict[str, Any] | None = None, *,
                secret: bytes | None = None, cache_dir: str | os.PathLike | None = None) -> None:
    """Write ``result`` as the entry ``path`` atomically (temp file, fsync, ``os.replace``),
    authenticated with ``secret`` (default: this user's key, :func:`load_cache_key`).

    The entry's folder (and ``cache_dir`` when ``path`` is its entry) is opened as a real
    directory and every step works inside it: a linked folder raises :class:`UnsafeCacheFolder`
    and nothing is written through it; whatever is at the entry's name (a planted pipe or link)
    is replaced, not written through."""
    secret = load_cache_key() if secret is None else secret
    values = np.ascontiguousarray(result.values, dtype="<f8")
    raw = values.tobytes()
    header = {"key": key, "shape": list(values.shape), "dtype": "<f8", "nbytes": len(raw),
              "sha256": hashlib.sha256(raw).hexdigest(),
              "dofs": [[int(g), int(c)] for g, c in result.dofs], "cases": list(result.cases),
              "created": time.time(), **(extra or {})}
    path = Path(path)
    with _EntryDir(path, Path(cache_dir) if cache_dir is not None else None, create=True) as folder:
        _remove_stale_tmp(folder)
        tmp = f".tmp-{os.getpid()}-{secrets.token_hex(6)}.part"
        fd = os.open(folder.name(tmp), os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0)
                     | getattr(os, "O_CLOEXEC", 0), 0o600, **folder.at())
        try:
            with os.fdopen(fd, "wb") as fh:
                line = json.dumps(header).encode()
                fh.write(MAGIC)
                fh.write(line + b"\n")
                fh.write(MAC_PREFIX + _mac(secret, line, raw) + b"\n")
                fh.write(raw)
                fh.flush()
                os.fsync(fh.fileno())
            if folder.fd is not None:
                os.replace(tmp, path.name, src_dir_fd=folder.fd, dst_dir_fd=folder.fd)
            else:
                os.replace(folder.name(tmp), path)
        except BaseException:
            try:
                os.unlink(folder.name(tmp), **folder.at())
            except OSError:
                pass
            raise
        if folder.fd is not None:  # make the rename itself durable (best effort)
            try:
                os.fsync(folder.fd)
            except OSError:
                pass


def read_entry(path: Path, key: str, report: Sequence[DofLabel], cases: Sequence[str], *,
               secret: bytes | None = None, cache_dir: str | os.PathLike | None = None) -> Displacements:
    """The stored result for ``key``; :class:`CorruptEntry` unless the file is a complete entry
    with matching checksum, :class:`UnauthenticEntry` unless its HMAC verifies with ``secret``
    (default: this user's key), :class:`CorruptEntry` unless it is for exactly this key, report
    and cases; ``FileNotFoundError`` if absent. Before anything is read, the entry's folder (and
    ``cache_dir``) must be real directories (:class:`UnsafeCacheFolder`) and the entry a regular
    file of this user no larger than :func:`entry_size_cap` (:class:`UnsafeEntry`)."""
    secret = load_cache_key() if secret is None else secret
    path = Path(path)
    with _EntryDir(path, Path(cache_dir) if cache_dir is not None else None) as folder:
        data = _read_capped(path, folder, entry_size_cap(report, cases))
    if not data.startswith(MAGIC):
        raise CorruptEntry("bad magic")
    end = data.find(b"\n", len(MAGIC))
    if end < 0:
        raise CorruptEntry("no header line")
    line = data[len(MAGIC):end]
    try:
        header = json.loads(line.decode())
    except (UnicodeDecodeError, ValueError) as exc:
        raise CorruptEntry(f"unreadable header: {exc}") from None
    mac_end = data.find(b"\n", end + 1)
    mac = data[end + 1:mac_end] if mac_end >= 0 else b""
    if not mac.startswith(MAC_PREFIX):
        raise CorruptEntry("no authentication line")
    raw = data[mac_end + 1:]
    if not isinstance(header, dict) or hashlib.sha256(raw).hexdigest() != header.get("sha256"):
        raise CorruptEntry("checksum mismatch")
    if not hmac.compare_digest(mac[len(MAC_PREFIX):], _mac(secret, line, raw)):
        raise UnauthenticEntry("authentication failed: the entry was not written with this user's "
                               "cache key (planted, altered or someone else's)")
    report = [(int(g), int(c)) for g, c in report]
    shape = [len(report), len(cases)]
    try:
        ok = (header["key"] == key and header["shape"] == shape and header["dtype"] == "<f8"
              and header["nbytes"] == len(raw) == 8 * shape[0] * shape[1]
              and [tuple(d) for d in header["dofs"]] == report and header["cases"] == list(cases))
    except (KeyError, TypeError):
        ok = False
    if not ok:
        raise CorruptEntry("header does not match the request")
    values = np.frombuffer(raw, dtype="<f8").reshape(shape).astype(float)
    return Displacements(tuple(report), values, tuple(cases))


def _remove_stale_tmp(folder: _EntryDir) -> None:
    """Remove temporary files (``.tmp-*.part``) older than :data:`STALE_TMP_S` from the entry's
    folder: left by a writer that died. Links are removed, never followed."""
    now = time.time()
    try:
        names = os.listdir(folder.fd) if folder.fd is not None else os.listdir(folder.path.parent)
    except OSError:
        return
    for n in names:
        if not (n.startswith(".tmp-") and n.endswith(".part")):
            continue
        try:
            if now - os.stat(folder.name(n), follow_symlinks=False, **folder.at()).st_mtime > STALE_TMP_S:
                os.unlink(folder.name(n), **folder.at())
        except OSError:
            pass


# --------------------------------------------------------------------------------------------
# the adapter
# --------------------------------------------------------------------------------------------
class CachedAdapter:
    """A :class:`SolverAdapter` that delegates to ``inner`` and keeps every successful ``solve``
    in ``cache_dir`` (see the module docstring for the key and the entry format).

    ``stats`` is the inner adapter's: a cache hit makes no run and changes none of its counters.
    The cache's own counters are in ``cache_stats`` (:class:`CacheStats`), shared with every
    adapter derived through :meth:`with_springs`. Other attributes are read from ``inner``;
    ``progress`` is also set on ``inner`` (the CLI's heartbeat for external solvers).

    ``secret`` authenticates the entries (default: this user's key, :func:`load_cache_key`,
    read once here). A key file others could read raises
    :class:`~solver_adapters.userconfig.InsecureFileError`; when the key cannot be made at all
    (no writable configuration folder) the cache is off, with a warning, and every solve
    goes to ``inner`` (counted as ``bypassed``).
    """

    def __init__(self, inner: SolverAdapter, cache_dir: str | os.PathLike, *,
                 springs: Sequence[ScalarSpring] = (), cache_stats: CacheStats | None = None,
                 secret: bytes | None = None, _shared: dict | None = None):
        self.inner = inner
        self.cache_dir = Path(cache_dir)
        self._shared = _shared if _shared is not None else {"unsafe_folder": None}
        self.name = inner.name
        self.cache_stats = cache_stats if cache_stats is not None else CacheStats()
        self._springs = tuple(springs)
        self._identity = adapter_identity(inner)
        self._deck0 = deck_fingerprint(inner)
        self._warned = False
        if secret is None:
            try:
                secret = load_cache_key()
            except InsecureFileError:
                raise
            except OSError as exc:
                warnings.warn(f"solver cache: cannot create the cache key {cache_key_path()}: {exc}; "
                              f"the cache is off for this run", RuntimeWarning, stacklevel=2)
        self._secret = secret

    # ---- protocol --------------------------------------------------------------------------
    @property
    def stats(self) -> SolverStats:
        return self.inner.stats

    def dofs(self) -> tuple[DofLabel, ...]:
        return self.inner.dofs()

    def grid_xyz(self) -> dict[int, tuple[float, float, float]]:
        return self.inner.grid_xyz()

    def with_springs(self, springs: Sequence[ScalarSpring]) -> "CachedAdapter":
        return CachedAdapter(self.inner.with_springs(springs), self.cache_dir,
                             springs=self._springs + tuple(springs), cache_stats=self.cache_stats,
                             secret=self._secret if self._secret is not None else b"", _shared=self._shared)

    @property
    def progress(self) -> Any:
        return getattr(self.inner, "progress", None)

    @progress.setter
    def progress(self, callback: Any) -> None:
        self.inner.progress = callback

    def solve(self, loads: LoadMatrix, report: Sequence[DofLabel]) -> Displacements:
        report = tuple((int(g), int(c)) for g, c in report)
        deck = deck_fingerprint(self.inner)
        if deck != self._deck0 or not self._secret:
            self._count("bypassed")
            return self.inner.solve(loads, report)
        key = self.key(loads, report, deck)
        path = entry_path(self.cache_dir, key)
        if self._unsafe_folder is not None:             # a linked cache folder: never used
            self._count("bypassed")
            return self.inner.solve(loads, report)
        try:
            hit = read_entry(path, key, report, loads.cases, secret=self._secret, cache_dir=self.cache_dir)
        except FileNotFoundError:
            hit = None
        except UnsafeCacheFolder as exc:
            self._folder_unsafe(exc)
            self._count("bypassed")
            return self.inner.solve(loads, report)
        except (UnauthenticEntry, UnsafeEntry) as exc:
            self._count("corrupt")
            self._count("unauthenticated" if isinstance(exc, UnauthenticEntry) else "unsafe")
            warnings.warn(f"solver cache: ignored {path}: {exc}; recomputing", RuntimeWarning, stacklevel=2)
            hit = None
        except (CorruptEntry, OSError):
            self._count("corrupt")
            hit = None
        if hit is not None:
            self._count("hits")
            return hit
        self._count("misses")
        out = self.inner.solve(loads, report)          # a failure propagates: nothing is stored
        self._store(path, key, out, loads, report)
        return out

    def _folder_unsafe(self, exc: UnsafeCacheFolder) -> None:
        """Turn the cache off for this adapter (and its ``with_springs`` copies), warning once."""
        with _COUNT_LOCK:
            first = self._shared["unsafe_folder"] is None
            self._shared["unsafe_folder"] = str(exc)
        if first:
            self._count("unsafe")
            warnings.warn(f"solver cache: {exc}; the cache is off for this run (nothing read or written "
                          f"there)", RuntimeWarning, stacklevel=3)

    @property
    def _unsafe_folder(self) -> str | None:
        return self._shared["unsafe_folder"]

    # ---- helpers -----------------------------------------------------------------------------
    def key(self, loads: LoadMatrix, report: Sequence[DofLabel], deck: str | None = None) -> str:
        """The cache key of ``solve(loads, report)`` on this adapter."""
        return solve_key(self._identity, deck or deck_fingerprint(self.inner),
                         _springs_of(self.inner, self._springs), loads, report)

    def _store(self, path: Path, key: str, out: Displacements, loads: LoadMatrix,
               report: tuple[DofLabel, ...]) -> None:
        values = np.asarray(out.values)
        good = (values.shape == (len(report), loads.n_cases) and np.all(np.isfinite(values))
                and tuple(tuple(d) for d in out.dofs) == report and tuple(out.cases) == loads.cases)
        if not good:
            self._count("not_stored")
            return
        try:
            write_entry(path, key, Displacements(report, values, loads.cases),
                        {"adapter": self.name, "inner_runs": self.inner.stats.runs}, secret=self._secret,
                        cache_dir=self.cache_dir)
        except UnsafeCacheFolder as exc:
            self._folder_unsafe(exc)
            return
        except OSError as exc:
            self._count("store_errors")
            if not self._warned:
                self._warned = True
                warnings.warn(f"solver cache: cannot write {path}: {exc}; continuing without storing",
                              RuntimeWarning, stacklevel=3)
            return
        self._count("stores")

    def _count(self, what: str) -> None:
        with _COUNT_LOCK:
            setattr(self.cache_stats, what, getattr(self.cache_stats, what) + 1)

    def __getattr__(self, attr: str) -> Any:
        if attr.startswith("_") or attr in ("inner", "cache_dir", "cache_stats", "name", "progress"):
            raise AttributeError(attr)
        return getattr(self.inner, attr)

    def __repr__(self) -> str:
        return f"CachedAdapter({self.inner!r}, cache_dir={str(self.cache_dir)!r})"
