"""Scale benchmark of the reference solver: one factorization + many right-hand sides.

Builds car-body-like frames (``blackbox.structures.tube_body``) of about 1e4, 1e5 and 1e6 DOFs
(and the fixture car if ``fixtures/car/model.bdf`` exists), then for each factorization backend
reads the deck, assembles, factorizes and solves ``--rhs`` unit loads at random free DOFs in one
batch. Each (size, backend) runs in its own subprocess so that the peak memory of one run does
not pollute the next; a thread samples the RSS of the run (psutil, every 20 ms) and the peak of
each phase is recorded, with ``ru_maxrss`` as a cross-check. The full solutions of the two
backends are compared (relative 2-norm difference per load case, the largest reported) and each
solution's residual ``||K u - f|| / ||f||`` is checked.

    python benchmarks/scale.py                                  # car, 1e4, 1e5, 1e6; both backends
    python benchmarks/scale.py --sizes 1e5 --backends pardiso
    python benchmarks/scale.py --sizes 250x200,417x200 --backends superlu --timeout 900
    python benchmarks/scale.py --out /tmp/scale.json --markdown

Sizes: ``car`` (the fixture), ``latticeN`` (a solid N^3-grid 3D lattice, for contrast), a preset (``1e4`` = 42 rings x 40 around, ``1e5`` = 167 x 100,
``1e6`` = 834 x 200) or ``NLxNA`` (n_long x n_around); DOFs = 6 * n_long * n_around (+ the joint's
branch grids). Deck text generation is timed but is not the solver's cost; parsing is reported
separately from assembly. A run that exceeds ``--timeout`` seconds or ``--mem-limit-gb`` is
stopped and reported as such, with the phases it completed.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

PRESETS = {"1e4": (42, 40), "1e5": (167, 100), "1e6": (834, 200)}
CAR = ROOT / "fixtures" / "car" / "model.bdf"
PHASES = ("generate", "parse", "assemble", "factor", "solve", "protocol_solve")


# --------------------------------------------------------------------------------------------
# worker: one (size, backend) in this process
# --------------------------------------------------------------------------------------------
class _Sampler(threading.Thread):
    """Samples this process's RSS; keeps the peak per phase; enforces the memory limit."""

    def __init__(self, limit_bytes: int, on_limit):
        super().__init__(daemon=True)
        import psutil
        self.proc = psutil.Process()
        self.limit, self.on_limit = limit_bytes, on_limit
        self.phase = "start"
        self.peaks: dict[str, int] = {}
        self.stop = threading.Event()

    def sample(self) -> int:
        rss = self.proc.memory_info().rss
        if rss > self.peaks.get(self.phase, 0):
            self.peaks[self.phase] = rss
        return rss

    def run(self) -> None:
        while not self.stop.wait(0.02):
            if self.sample() > self.limit:
                self.on_limit(self.phase)

    def enter(self, phase: str) -> None:
        self.sample()
        self.phase = phase
        self.sample()


def worker(spec: dict) -> None:
    from solver_adapters.bdf import read_deck_text
    from solver_adapters.protocol import LoadMatrix
    from solver_adapters.reference import ReferenceAdapter

    out = Path(spec["result"])
    res: dict = {"case": spec["case"], "backend": spec["backend"], "status": "running",
                 "times": {}, "peak_rss": {}, "loadavg_start": os.getloadavg()[0]}

    def save() -> None:
        res["peak_rss"] = {k: v for k, v in sampler.peaks.items()}
        res["ru_maxrss"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
        tmp = out.with_suffix(".tmp")
        tmp.write_text(json.dumps(res, indent=1))
        tmp.replace(out)

    def over_limit(phase: str) -> None:
        res["status"] = f"memory limit ({spec['mem_limit_gb']} GB) exceeded in {phase}"
        save()
        os._exit(3)

    sampler = _Sampler(int(spec["mem_limit_gb"] * 2**30), over_limit)
    sampler.start()

    def phase(name: str):
        sampler.enter(name)
        res["phase"] = name
        save()
        return time.perf_counter()

    def done(name: str, t0: float) -> None:
        res["times"][name] = time.perf_counter() - t0
        sampler.sample()
        save()

    # deck text (not the solver's cost)
    t0 = phase("generate")
    if spec["case"] == "car":
        text = Path(spec["car"]).read_text()
        name, base = str(spec["car"]), Path(spec["car"]).parent
    elif "lattice" in spec:
        text = lattice(spec["lattice"]).bdf(spec["case"])
        name, base = f"{spec['case']}.bdf", None
    else:
        from blackbox.structures import tube_body
        nl, na = spec["n_long"], spec["n_around"]
        text = tube_body(nl, na).bdf(f"tube_body({nl}, {na})")
        name, base = f"tube_{nl}x{na}.bdf", None
    res["deck_mb"] = len(text) / 1e6
    done("generate", t0)

    t0 = phase("parse")
    deck = read_deck_text(text, name=name, base_dir=base)
    del text
    done("parse", t0)
    res.update(grids=len(deck.grids), bars=len(deck.cbars))

    t0 = phase("assemble")
    adapter = ReferenceAdapter(deck, backend=spec["backend"])
    m = adapter.model
    done("assemble", t0)
    res["assembly"] = dict(adapter.timings)
    n_f = m.K_ff.shape[0]
    res.update(dofs=m.T.shape[0], free_dofs=n_f, nnz_K=int(m.K_ff.nnz))

    if spec["backend"] in ("pardiso", "auto"):
        # one-off per process: import pypardiso and load MKL (~0.3-0.8 s), not the factorization
        from solver_adapters.reference.model import pardiso_available
        t0 = time.perf_counter()
        pardiso_available()
        res["backend_load_s"] = time.perf_counter() - t0

    t0 = phase("factor")
    fact = adapter.factorization()
    done("factor", t0)
    res["backend_used"] = fact.backend
    if fact.backend == "pardiso":
        pd = fact._pd
        res.update(nnz_factor=pd.nnz_factor, pardiso_mtype=pd.mtype,
                   pardiso_peak_mem=pd.peak_memory_bytes, analyse_s=pd.analyse_s,
                   numeric_s=pd.numeric_s)
    else:
        res["nnz_factor"] = int(fact._lu.L.nnz + fact._lu.U.nnz)

    rng = np.random.default_rng(spec["seed"])
    nrhs = min(spec["rhs"], n_f)
    cols = rng.choice(n_f, size=nrhs, replace=False)
    F = np.zeros((n_f, nrhs))
    F[cols, np.arange(nrhs)] = 1.0
    t0 = phase("solve")
    U = fact.solve(F)
    done("solve", t0)
    R = m.K_ff @ U - F
    res["residual"] = float(np.max(np.linalg.norm(R, axis=0) / np.linalg.norm(F, axis=0)))
    del R
    if spec.get("solution"):
        np.save(spec["solution"], U)
    del U

    if spec.get("protocol"):
        labels = [m.f_labels[i] for i in cols]
        t0 = phase("protocol_solve")
        adapter.solve(LoadMatrix.unit(labels), labels)
        done("protocol_solve", t0)

    sampler.stop.set()
    res["status"] = "ok"
    res["loadavg_end"] = os.getloadavg()[0]
    res.pop("phase", None)
    save()


# --------------------------------------------------------------------------------------------
# driver
# --------------------------------------------------------------------------------------------
def lattice(n: int):
    """A solid 3D lattice of n^3 grids (bars along x, y, z; 0.5 m pitch), the bottom layer
    clamped: the contrast to the shell-like body (much more fill; the issue's 48k-DOF case is
    n = 20)."""
    from blackbox.structures import FrameBuilder
    f = FrameBuilder()

    def gid(i, j, k):
        return 1 + i + n * (j + n * k)
    for k in range(n):
        for j in range(n):
            for i in range(n):
                f.grid(gid(i, j, k), (0.5 * i, 0.5 * j, 0.5 * k))
    for k in range(n):
        for j in range(n):
            for i in range(n):
                if i + 1 < n:
                    f.bar(gid(i, j, k), gid(i + 1, j, k), v=(0.0, 0.0, 1.0))
                if j + 1 < n:
                    f.bar(gid(i, j, k), gid(i, j + 1, k), v=(0.0, 0.0, 1.0))
                if k + 1 < n:
                    f.bar(gid(i, j, k), gid(i, j, k + 1), v=(1.0, 0.0, 0.0))
    for j in range(n):
        for i in range(n):
            f.fix(gid(i, j, 0))
    return f


def parse_size(s: str) -> dict:
    s = s.strip()
    if s == "car":
        return {"case": "car"}
    if s.startswith("lattice"):
        return {"case": s, "lattice": int(s[len("lattice"):])}
    nl, na = PRESETS[s] if s in PRESETS else map(int, s.lower().split("x"))
    return {"case": f"{nl}x{na}", "n_long": nl, "n_around": na}


def run_one(spec: dict, timeout: float, threads: int | None = None) -> dict:
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", json.dumps(spec)]
    env = dict(os.environ)
    if threads:
        for var in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OMP_NUM_THREADS"):
            env[var] = str(threads)
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(cmd, timeout=timeout, capture_output=True, text=True, env=env)
        status = None if proc.returncode in (0, 3) else f"failed (exit {proc.returncode}): {proc.stderr[-800:]}"
    except subprocess.TimeoutExpired:
        status = "timeout"
    try:
        res = json.loads(Path(spec["result"]).read_text())
    except (OSError, ValueError):
        res = {"case": spec["case"], "backend": spec["backend"], "times": {}, "peak_rss": {}}
    if status == "timeout":
        res["status"] = f"timeout after {timeout:.0f} s in {res.get('phase', '?')}"
    elif status:
        res["status"] = status
    res["wall_s"] = time.perf_counter() - t0
    return res


def agreement(a: str, b: str) -> float:
    """Largest relative 2-norm difference between the columns of two saved solutions."""
    A, B = np.load(a, mmap_mode="r"), np.load(b, mmap_mode="r")
    d2 = np.zeros(A.shape[1])
    r2 = np.zeros(A.shape[1])
    for s in range(0, A.shape[0], 200_000):
        x, y = np.asarray(A[s:s + 200_000]), np.asarray(B[s:s + 200_000])
        d2 += ((x - y) ** 2).sum(axis=0)
        r2 += (y ** 2).sum(axis=0)
    return float(np.sqrt(d2 / r2).max())


def machine() -> dict:
    import psutil
    import scipy
    info = {"cpus": os.cpu_count(), "ram_gb": psutil.virtual_memory().total / 2**30,
            "available_gb": psutil.virtual_memory().available / 2**30,
            "python": platform.python_version(), "numpy": np.__version__, "scipy": scipy.__version__,
            "platform": platform.platform()}
    try:
        with open("/proc/cpuinfo") as fh:
            info["cpu"] = next(line.split(":", 1)[1].strip() for line in fh if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    try:
        from importlib.metadata import version
        info["pypardiso"] = version("pypardiso")
        info["mkl"] = version("mkl")
    except Exception:           # noqa: BLE001 - optional
        pass
    return info


def peak_gb(r: dict) -> float:
    """Peak sampled RSS of a run in GiB. (``ru_maxrss`` is kept in the JSON but not used: on
    Linux a child inherits its parent's high-water mark across fork/exec.)"""
    return max(list(r.get("peak_rss", {}).values()) + [0]) / 2**30


def fmt_row(r: dict, agree: str) -> str:
    t = r.get("times", {})
    peak = peak_gb(r)

    def f(key, digits=2):
        return f"{t[key]:.{digits}f}" if key in t else "-"
    asm = r.get("assembly", {})
    status = r.get("status", "?")
    return (f"| {r['case']} | {r.get('dofs', '-'):,} | {r.get('nnz_K', 0):,} | {r.get('backend_used', r['backend'])} "
            f"| {f('parse')} | {f('assemble')} ({asm.get('elements_s', 0):.1f} el / "
            f"{asm.get('constraint_map_s', 0):.2f} T / {asm.get('reduce_s', 0):.1f} TtKT) "
            f"| {f('factor')} | {f('solve')} | {peak:.2f} | {r.get('nnz_factor', 0) / 1e6:.1f} "
            f"| {r.get('residual', float('nan')):.1e} | {agree} | {status} |").replace("| 0 |", "| - |")


HEADER = ("| case | DOFs | nnz K_ff | backend | parse s | assembly s (elements / constraint map / T^T K T) "
          "| factor s | 100-RHS solve s | peak RSS GB | factor nnz (M) | max residual | agreement | status |\n"
          "|---|---:|---:|---|---:|---|---:|---:|---:|---:|---:|---:|---|")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default="car,1e4,1e5,1e6",
                    help="comma list: car, 1e4, 1e5, 1e6 or NLxNA (default: %(default)s)")
    ap.add_argument("--backends", default="superlu,pardiso", help="comma list (default: %(default)s)")
    ap.add_argument("--rhs", type=int, default=100, help="right-hand sides in the batch (default 100)")
    ap.add_argument("--timeout", type=float, default=900.0, help="seconds per run (default 900)")
    ap.add_argument("--mem-limit-gb", type=float, default=20.0, help="RSS limit per run (default 20)")
    ap.add_argument("--blas-threads", type=int,
                    help="set OPENBLAS/MKL/OMP_NUM_THREADS for the runs (default: libraries' own)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--car", default=str(CAR), help="fixture deck for size 'car'")
    ap.add_argument("--protocol", action="store_true",
                    help="also time the same batch through ReferenceAdapter.solve (the protocol path)")
    ap.add_argument("--no-agreement", action="store_true", help="do not save and compare solutions")
    ap.add_argument("--out", help="write all results as JSON here")
    ap.add_argument("--markdown", action="store_true", help="print the table at the end")
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        worker(json.loads(args.worker))
        return 0

    sizes = [parse_size(s) for s in args.sizes.split(",") if s.strip()]
    if any(s["case"] == "car" for s in sizes) and not Path(args.car).exists():
        print(f"note: {args.car} does not exist; skipping the car")
        sizes = [s for s in sizes if s["case"] != "car"]
    backends = [b.strip() for b in args.backends.split(",") if b.strip()]
    info = machine()
    print(f"machine: {info.get('cpu', '?')}, {info['cpus']} CPUs, {info['ram_gb']:.1f} GiB RAM "
          f"({info['available_gb']:.1f} available); numpy {info['numpy']}, scipy {info['scipy']}, "
          f"pypardiso {info.get('pypardiso', '-')}, mkl {info.get('mkl', '-')}", flush=True)
    results, rows = [], []
    with tempfile.TemporaryDirectory(prefix="scale-") as tmp:
        for size in sizes:
            sols = {}
            size_results = []
            for be in backends:
                sol = None if args.no_agreement else os.path.join(tmp, f"{size['case']}_{be}.npy")
                spec = dict(size, backend=be, rhs=args.rhs, seed=args.seed, car=args.car,
                            mem_limit_gb=args.mem_limit_gb, protocol=args.protocol, solution=sol,
                            result=os.path.join(tmp, f"{size['case']}_{be}.json"))
                r = run_one(spec, args.timeout, args.blas_threads)
                results.append(r)
                size_results.append(r)
                t = r.get("times", {})
                print(f"{size['case']:>9} {be:8s} dofs={r.get('dofs', '-')} "
                      + " ".join(f"{k}={t[k]:.2f}s" for k in PHASES if k in t)
                      + f" peak={peak_gb(r):.2f}GB"
                      + f" residual={r.get('residual', float('nan')):.1e} [{r.get('status')}]", flush=True)
                if r.get("status") == "ok" and sol and os.path.exists(sol):
                    sols[be] = sol
            agree = "-"
            if len(sols) >= 2:
                names = list(sols)
                agree = f"{agreement(sols[names[0]], sols[names[1]]):.1e}"
                print(f"{size['case']:>9} agreement {names[0]} vs {names[1]}: {agree}", flush=True)
            for s in sols.values():
                os.remove(s)
            for r in size_results:
                r["agreement"] = agree
                rows.append(fmt_row(r, agree))
    if args.out:
        Path(args.out).write_text(json.dumps({"machine": info, "args": vars(args), "results": results},
                                             indent=1))
    if args.markdown:
        print("\n" + HEADER + "\n" + "\n".join(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
