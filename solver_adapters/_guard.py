"""Guard process between blackbox and an external solver: no solver process outlives blackbox.

    python -I -S _guard.py PARENT_PID STATUS_FD -- COMMAND...

:func:`solver_adapters.subprocess.run_solver` starts this script (by path, standard library only,
so it starts in ~15 ms) and it starts COMMAND. On Linux it

* makes itself a *child subreaper* (``prctl(PR_SET_CHILD_SUBREAPER)``): a descendant of the
  solver whose parent exits - a daemon that double-forks, a child started in a session of its
  own - is re-parented to the guard instead of to init, so the guard can always find and kill
  every process the solver started;
* asks for SIGTERM when its parent dies (``prctl(PR_SET_PDEATHSIG)``), whatever killed the
  parent, SIGKILL included, and gives the solver SIGKILL on its own death the same way
  (``PR_SET_PDEATHSIG`` set in the forked child before ``exec``).

On SIGTERM, SIGHUP or SIGINT, and when the solver has exited, the guard SIGKILLs every process
left below it (generation by generation: orphans of a killed process come to the guard) and
exits. Its exit status is the solver's (a solver killed by signal N makes the guard die of
signal N), so the caller sees the solver's status.

``PR_SET_PDEATHSIG`` fires when the parent *thread* that started the guard exits, not only the
parent process; ``run_solver`` blocks that thread until the guard has exited, so this only
matters for a caller that would start the guard from a thread that ends before the run.

STATUS_FD receives one line: ``started PID`` once COMMAND is executing, or ``error ERRNO TEXT``
when it could not be executed (the guard then exits with 127).
"""

import os
import signal
import sys
import time

PR_SET_PDEATHSIG = 1
PR_SET_CHILD_SUBREAPER = 36


class _Stop(Exception):
    pass


def _prctl():
    """``prctl`` from the C library, or None where there is none (not Linux)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        import ctypes
        libc = ctypes.CDLL(None, use_errno=True)
        fn = libc.prctl
        fn.argtypes = [ctypes.c_int, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong]
        fn.restype = ctypes.c_int
        return fn
    except (OSError, AttributeError, ImportError):
        return None


def _children():
    """PIDs whose parent is this process (a scan of /proc; the PID of a child cannot be reused
    before this process has reaped it, so every PID found is really ours)."""
    me, found = os.getpid(), []
    try:
        names = os.listdir("/proc")
    except OSError:
        return found
    for name in names:
        if not name.isdigit():
            continue
        try:
            with open(f"/proc/{name}/stat", "rb") as fh:
                data = fh.read()
        except OSError:
            continue
        rest = data[data.rfind(b")") + 2:].split()  # after "pid (comm) ": state ppid ...
        if len(rest) > 1 and int(rest[1]) == me:
            found.append(int(name))
    return found


def _reap():
    """Reap every child that has exited, without waiting."""
    while True:
        try:
            pid, _ = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            return
        if pid == 0:
            return


def _kill_all(rounds=400):
    """SIGKILL every process below the guard until none is left (each round also takes the
    orphans that the previous round's kills handed to the guard). Without /proc and the
    subreaper (not Linux): the guard's process group, the guard included."""
    if not sys.platform.startswith("linux"):
        os.killpg(0, signal.SIGKILL)
        return
    for _ in range(rounds):
        _reap()
        kids = _children()
        if not kids:
            return
        for pid in kids:
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:
                pass
        try:
            os.waitpid(-1, 0)  # at least one of them has died: wait for it, the rest next round
        except ChildProcessError:
            return


def _spawn(argv, prctl, status_fd):
    """fork + exec ``argv`` (PATH search as ``execvp``); report to ``status_fd``."""
    err_r, err_w = os.pipe()
    os.set_inheritable(err_w, False)
    pid = os.fork()
    if pid == 0:  # the child: default signal handling, death signal, then exec
        try:
            os.close(err_r)
            for sig in (signal.SIGTERM, signal.SIGHUP, signal.SIGINT, signal.SIGPIPE, signal.SIGXFSZ):
                signal.signal(sig, signal.SIG_DFL)
            if prctl is not None:
                prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
            os.execvp(argv[0], argv)
        except OSError as exc:
            os.write(err_w, f"{exc.errno} {exc.strerror}".encode())
        finally:
            os._exit(127)
    os.close(err_w)
    msg = b""
    while True:  # EOF when exec succeeded (close-on-exec) or the child exited
        chunk = os.read(err_r, 4096)
        if not chunk:
            break
        msg += chunk
    os.close(err_r)
    if msg:
        os.waitpid(pid, 0)
        os.write(status_fd, b"error " + msg + b"\n")
        return None
    os.write(status_fd, f"started {pid}\n".encode())
    return pid


def main(args):
    parent, status_fd = int(args[0]), int(args[1])
    os.set_inheritable(status_fd, False)  # the solver does not get the status pipe
    argv = args[3:]
    prctl = _prctl()
    if prctl is not None:
        prctl(PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0)
        prctl(PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)

    def stop(signum, frame):
        raise _Stop()

    for sig in (signal.SIGTERM, signal.SIGHUP, signal.SIGINT):
        signal.signal(sig, stop)
    status = 0
    try:
        if os.getppid() != parent:  # the parent died before the death signal was armed
            raise _Stop()
        pid = _spawn(argv, prctl, status_fd)
        os.close(status_fd)
        if pid is None:
            return 127
        while True:
            if prctl is None:  # no death signal: watch the parent
                done, status = os.waitpid(pid, os.WNOHANG)
                if done:
                    break
                if os.getppid() != parent:
                    raise _Stop()
                time.sleep(0.1)
                continue
            done, st = os.waitpid(-1, 0)  # adopted orphans are reaped here too
            if done == pid:
                status = st
                break
    except _Stop:
        for sig in (signal.SIGTERM, signal.SIGHUP, signal.SIGINT):
            signal.signal(sig, signal.SIG_IGN)
        _kill_all()
        return 128 + signal.SIGTERM
    for sig in (signal.SIGTERM, signal.SIGHUP, signal.SIGINT):
        signal.signal(sig, signal.SIG_IGN)
    if sys.platform.startswith("linux"):  # elsewhere run_solver kills the process group
        _kill_all()
    if os.WIFSIGNALED(status):
        sig = os.WTERMSIG(status)
        signal.signal(sig, signal.SIG_DFL)
        os.kill(os.getpid(), sig)
        return 128 + sig
    return os.waitstatus_to_exitcode(status)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
