"""Make any external solver command fail on purpose: ``python _misbehave.py MODE -- COMMAND...``.

A program of its own (imports nothing of this project). The conformance suite puts it in front
of a :class:`~solver_adapters.subprocess.CommandAdapter`'s command line to see that the adapter
turns every way a run can go wrong into a typed error, whatever its code and dialect
(``solver_adapters.conformance.command_misbehaviour``). Modes:

``crash``     half a line of output, a segmentation-fault message on stderr, exit code 139; the
              solver is not run
``hang``      starts a sleeping child in a session of its own and sleeps forever (the adapter's
              timeout must kill both)
``silent``    exit code 0 and nothing written at all
``truncate``  runs the solver, then passes on only the first half of its standard output and
              cuts every file the run wrote in the working directory to half its size; exit
              code 0 (the solver's own when it failed)
"""

from __future__ import annotations

import os
import sys

# run as a script from inside the package folder: its modules (subprocess.py, ...) must not
# shadow the standard library's
if sys.path and os.path.abspath(sys.path[0] or ".") == os.path.dirname(os.path.abspath(__file__)):
    del sys.path[0]

import subprocess
import time
from pathlib import Path

MODES = ("crash", "hang", "silent", "truncate")


def _files(folder: Path) -> dict[Path, int]:
    out = {}
    for p in folder.rglob("*"):
        try:
            if p.is_file() and not p.is_symlink():
                out[p] = p.stat().st_mtime_ns
        except OSError:
            pass
    return out


def main(argv: list[str]) -> int:
    if argv[:1] == ["--sleep-child"]:
        while True:
            time.sleep(60)
    if len(argv) < 2 or argv[0] not in MODES or argv[1] != "--":
        print(f"usage: _misbehave.py {{{','.join(MODES)}}} -- COMMAND...", file=sys.stderr)
        return 2
    mode, command = argv[0], argv[2:]
    if mode == "crash":
        sys.stdout.write(" SOLVER START\n PARTIAL OUT")
        sys.stdout.flush()
        print("Segmentation fault (core dumped)", file=sys.stderr)
        return 139
    if mode == "hang":
        subprocess.Popen([sys.executable, os.path.abspath(__file__), "--sleep-child"],
                         start_new_session=True, stdin=subprocess.DEVNULL)
        print("WAITING FOR CHILD PROCESS", flush=True)
        while True:
            time.sleep(60)
    if mode == "silent":
        return 0
    before = _files(Path.cwd())
    run = subprocess.run(command, stdout=subprocess.PIPE, stdin=subprocess.DEVNULL)
    sys.stdout.buffer.write(run.stdout[:len(run.stdout) // 2])
    sys.stdout.flush()
    own = set()                       # this program's own stdout and stderr files are not the run's
    for fd in (1, 2):
        try:
            st = os.fstat(fd)
            own.add((st.st_dev, st.st_ino))
        except OSError:
            pass
    for p, stamp in _files(Path.cwd()).items():
        st = p.stat()
        if before.get(p) != stamp and (st.st_dev, st.st_ino) not in own:
            with open(p, "r+b") as fh:
                fh.truncate(st.st_size // 2)
    return run.returncode


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
