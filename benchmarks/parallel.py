"""Independent work on a local Dask cluster against the serial run, on this machine.

    python benchmarks/parallel.py [--workers 2] [--replicates 400] [--out docs/parallel.md]

One run each (the cluster's workers warmed up first: their imports are timed separately, with
the cluster's start):

* ``batch identify`` of 8 studies through MYSTRAN (copies of the fixtures with
  ``adapter = "mystran"``, no run cache), the command's default options (profile intervals);
* 400 coverage replicates of the cube simple model (``blackbox.parallel.coverage_study``: the
  set-up of the coverage test in ``tests/test_identification.py``: 31 load cases, the joint's 12
  DOFs measured in L1 + R1..R10, R10 held out, 5 % noise, profile-likelihood intervals);
* ``batch diagnose`` of 4 studies with undeclared effects (``fixtures/undeclared``, reference
  solver): the diagnoses themselves are the tasks (one diagnosis's own runs on the cluster:
  ``benchmarks/diagnose_parallel.py``);
* one MYSTRAN batch of unit loads on a generated car-body-like frame, as one run against
  column chunks run side by side (``CommandAdapter.executor``), each chunk a MYSTRAN process.

For each: the speed-up ``S = T_serial / T_parallel`` on ``p`` workers, the serial fraction
``e = (1/S - 1/p) / (1 - 1/p)`` (Karp-Flatt: Amdahl's serial fraction that explains the measured
speed-up, including every overhead of the parallel run) and Amdahl's projection
``1 / (e + (1 - e) / N)`` for N workers, capped by the number of tasks (and by the longest task).
Every result is checked against the serial one (equal, bit for bit, where the arithmetic is).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

FIXTURES = ROOT / "fixtures"
STUDIES = ("cube", "car", "cube_complex", "car_complex", "cube_joint_only", "car_joint_only", "cube", "car")
DIAGNOSE = ("support_flexibility", "load_scale", "joint_coupling", "none")


def _warm(x):
    import blackbox.commands.identify  # noqa: F401
    import blackbox.commands.diagnose  # noqa: F401
    import blackbox.identification  # noqa: F401
    return os.getpid()


def _cpu() -> float:
    """CPU seconds of this process and its finished children."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def amdahl(t_serial: float, t_parallel: float, p: int, tasks: int, *, work_serial: float, work_parallel: float,
           client: float, longest: float) -> dict:
    """The measured speed-up and two serial fractions, and the projection to N workers.

    ``e`` (Karp-Flatt) explains the measured wall-clock speed-up on ``p`` workers by Amdahl's
    law: every overhead counts, and so does the load others put on the machine. ``f`` comes from
    CPU times, which a shared machine changes much less: ``C`` = the client's CPU during the
    parallel run (packing, pickling, the scheduler, receiving, writing: what does not shrink with
    more workers) against ``W`` = the tasks' CPU in the parallel run. The projection to N
    workers: ``S(N) = W1 / (C + max(W / N, longest task))`` with ``W1`` the tasks' CPU in the
    serial run (so a task that costs more on a worker counts against the cluster); ``S(p)`` is
    the speed-up the run would have had on ``p`` cores of its own."""
    s = t_serial / t_parallel
    e = (1.0 / s - 1.0 / p) / (1.0 - 1.0 / p) if p > 1 else 0.0
    proj = {n: work_serial / (client + max(work_parallel / n, longest)) for n in (2, 4, 8, 16, 64)}
    return {"serial_s": t_serial, "parallel_s": t_parallel, "speedup": s, "serial_fraction": e,
            "tasks": tasks, "work_serial_s": work_serial, "work_parallel_s": work_parallel, "client_s": client,
            "longest_task_s": longest, "cpu_serial_fraction": client / (client + work_parallel),
            "projected": proj}


def mystran_copies(tmp: Path) -> list[Path]:
    out = []
    for i, name in enumerate(STUDIES):
        dst = tmp / f"{i + 1:02d}_{name}"
        shutil.copytree(FIXTURES / name, dst, ignore=shutil.ignore_patterns(".blackbox_cache"))
        toml = (dst / "study.toml").read_text()
        (dst / "study.toml").write_text(toml.replace('adapter = "reference"', 'adapter = "mystran"'))
        out.append(dst)
    return out


def bench_batch(ex, folders, command: str, say) -> dict:
    from blackbox.commands import batch
    from blackbox.parallel import SerialExecutor

    t0 = time.perf_counter()
    ser = batch.run(folders, command=command, executor=SerialExecutor(), cache=False)
    with tempfile.TemporaryDirectory() as out:
        ser.write(Path(out))
    t_ser = time.perf_counter() - t0
    t0, c0 = time.perf_counter(), _cpu()
    par = batch.run(folders, command=command, executor=ex, cache=False)
    with tempfile.TemporaryDirectory() as out:
        par.write(Path(out))
    t_par, c_par = time.perf_counter() - t0, _cpu() - c0
    assert all(o.ok for o in ser.outcomes), [(o.name, o.status, o.message[:200]) for o in ser.outcomes]
    for o in par.outcomes:
        if not o.ok:
            say(f"  parallel run: {o.name}: {o.status}: {o.message[:500]}")
    assert all(o.ok for o in par.outcomes), "a study failed on the cluster (above)"
    same = all(a.parameters == b.parameters and a.reduced_chi2 == b.reduced_chi2 and a.status == b.status
               for a, b in zip(ser.outcomes, par.outcomes))
    # largest difference of a parameter relative to the largest parameter of its joint (a small
    # off-diagonal K_C entry is judged on the joint's scale, as blackbox bench does)
    rel = 0.0
    for a, b in zip(ser.outcomes, par.outcomes):
        scale: dict[str, float] = {}
        for p in a.parameters:
            scale[p["joint"]] = max(scale.get(p["joint"], 0.0), abs(p["value"]))
        for p, q in zip(a.parameters, b.parameters):
            rel = max(rel, abs(p["value"] - q["value"]) / max(scale[p["joint"]], 1e-300))
    same_path = [a.message == b.message for a, b in zip(ser.outcomes, par.outcomes)]
    row = amdahl(t_ser, t_par, ex.workers, len(folders), work_serial=sum(o.cpu_s for o in ser.outcomes),
                 work_parallel=sum(o.cpu_s for o in par.outcomes), client=c_par,
                 longest=max(o.cpu_s for o in par.outcomes))
    row.update(same_as_serial=bool(same), max_rel_difference=rel, same_outcome=same_path,
               task_wall_s=[o.wall_s for o in ser.outcomes], task_cpu_s=[o.cpu_s for o in ser.outcomes])
    say(f"  batch {command}: serial {t_ser:.2f} s, {ex.workers} workers {t_par:.2f} s, S = {row['speedup']:.2f}, "
        f"e = {row['serial_fraction']:.3f}, f = {row['cpu_serial_fraction']:.3f}, same = {same} "
        f"(max rel. difference {rel:.1e})")
    return row


def cube_model():
    """The cube of Sec. 3.7.1 condensed once, as the coverage test's ``cube_setup``."""
    from blackbox.condensation import CondensedModel, condense
    from blackbox.joints import SimpleJoint, joint_dofs
    from blackbox.structures import cube, random_loads
    from solver_adapters.bdf import read_deck_text
    from solver_adapters.protocol import LoadMatrix
    from solver_adapters.reference import ReferenceAdapter

    f = cube()
    name, grids = f.joints[0]
    rows = ([("L1", g, 6, 0.5) for g in (5, 6, 8)]
            + [(f"R{c[1:]}", g, comp, v) for c, g, comp, v in random_loads(f, 30, seed=1)])
    cases = list(dict.fromkeys(r[0] for r in rows))
    dofs = list(dict.fromkeys((r[1], r[2]) for r in rows))
    F = np.zeros((len(dofs), len(cases)))
    for c, g, comp, v in rows:
        F[dofs.index((g, comp)), cases.index(c)] += v
    away = [(g, c) for g in (2, 3, 4, 5, 6, 8) for c in range(1, 7)]
    cond = condense(ReferenceAdapter(read_deck_text(f.bdf())), LoadMatrix.from_dense(dofs, F, cases),
                    joint_dofs(grids), away)
    return CondensedModel(cond, [SimpleJoint(name, grids)]), joint_dofs(grids)


def bench_coverage(ex, n: int, say) -> dict:
    from blackbox.parallel import SerialExecutor, coverage_study

    model, dofs = cube_model()
    args = (model, np.full(9, 1.0e4), dofs, list(range(11)), np.full(9, 1.0e3))
    kw = dict(replicates=n, holdout=["R10"], seed=2024)
    t0 = time.perf_counter()
    a = coverage_study(*args, executor=SerialExecutor(), chunks=4 * ex.workers, **kw)
    t_ser = time.perf_counter() - t0
    t0, c0 = time.perf_counter(), _cpu()
    b = coverage_study(*args, executor=ex, **kw)
    t_par, c_par = time.perf_counter() - t0, _cpu() - c0
    same = all(np.array_equal(x, y) for x, y in [(a.k, b.k), (a.ci_low, b.ci_low), (a.ci_high, b.ci_high)])
    # the chunks can be cut down to one replicate each: the longest task is one replicate's CPU
    row = amdahl(t_ser, t_par, ex.workers, n, work_serial=sum(a.task_cpu_s), work_parallel=sum(b.task_cpu_s),
                 client=c_par, longest=sum(b.task_cpu_s) / n)
    row.update(same_as_serial=bool(same), coverage=[float(v) for v in a.coverage()],
               converged=int(a.converged.sum()), replicates=n)
    say(f"  coverage x{n}: serial {t_ser:.2f} s, {ex.workers} workers {t_par:.2f} s, S = {row['speedup']:.2f}, "
        f"e = {row['serial_fraction']:.3f}, f = {row['cpu_serial_fraction']:.3f}, same = {same}, coverage {np.round(a.coverage(), 3).tolist()}")
    return row


def bench_chunks(ex, tmp: Path, n_long: int, n_around: int, rhs: int, say) -> dict:
    from blackbox.structures import tube_body
    from solver_adapters.protocol import LoadMatrix
    from solver_adapters.registry import make_adapter

    f = tube_body(n_long, n_around, with_joint=False)
    deck = tmp / "tube.bdf"
    deck.write_text(f.bdf("car-body-like tube"))
    rng = np.random.default_rng(0)
    grids = sorted(f.grids)
    dofs = [(int(g), int(rng.integers(1, 7))) for g in rng.choice(grids, rhs, replace=False)]
    loads = LoadMatrix.unit(dofs)
    one = make_adapter("mystran", deck)
    t0 = time.perf_counter()
    a = one.solve(loads, dofs)
    t_ser = time.perf_counter() - t0
    split = make_adapter("mystran", deck)
    split.executor = ex
    t0, c0 = time.perf_counter(), _cpu()
    b = split.solve(loads, dofs)
    t_par, c_par = time.perf_counter() - t0, _cpu() - c0
    same = bool(np.array_equal(a.values, b.values))
    # the solver runs' own wall times stand for the tasks' work (MYSTRAN's CPU is in the workers' children)
    runs = [h["wall_s"] for h in split.stats.history]
    row = amdahl(t_ser, t_par, ex.workers, len(runs), work_serial=one.stats.history[-1]["wall_s"],
                 work_parallel=sum(runs), client=c_par, longest=max(runs))
    # a chunk is a whole solver run: t(k chunks) = F + R s / k with F (start, deck, assembly,
    # factorization) repeated by every chunk; from the one run (k = 1) and the chunks' mean
    t1, tk, k = one.stats.history[-1]["wall_s"], float(np.mean(runs)), len(runs)
    rs = (t1 - tk) * k / (k - 1) if k > 1 else 0.0
    fixed = max(t1 - rs, 0.0)
    row["cpu_serial_fraction"] = (c_par + fixed) / (c_par + t1)
    row["projected"] = {n: t1 / (c_par + fixed + rs / n) for n in (2, 4, 8, 16, 64)}
    row.update(fixed_s=fixed, substitution_s=rs)
    row.update(same_as_serial=same, model=f"tube_body({n_long}, {n_around}), {6 * len(grids)} DOF", rhs=rhs,
               runs=split.stats.runs, chunk_run_s=runs, max_abs_difference=float(np.max(np.abs(a.values - b.values))))
    say(f"  MYSTRAN chunks, {row['model']}, {rhs} rhs: one run {t_ser:.2f} s, {split.stats.runs} chunks "
        f"{t_par:.2f} s, S = {row['speedup']:.2f}, same = {same}")
    return row


def _same(r: dict) -> str:
    if r["same_as_serial"]:
        return "yes, bit for bit"
    d = r.get("max_rel_difference", r.get("max_abs_difference"))
    if d is None:
        return "no"
    path = "" if all(r.get("same_outcome", [True])) else "; a different outcome for some study"
    return f"to {d:.0e} of the joint's largest parameter (BLAS threads, see below){path}"


def markdown(res: dict) -> str:
    m = res["meta"]
    out = ["# Independent work on a Dask cluster: measured speed-ups", "",
           f"Generated by `{m['command']}`; one run each on {m['machine']} ({m['cpus']} cores), "
           f"{m['date']}; load average {m['load_before'][0]:.1f} before and {m['load_after'][0]:.1f} after "
           f"(the machine was shared with other jobs). Parallel = a local Dask cluster of {m['workers']} "
           f"single-threaded worker processes over loopback TCP, started and warmed up in "
           f"{m['cluster_start_s']:.2f} s (not in the times below).", "",
           "S = serial wall time / parallel wall time (wall times on a loaded machine: see below). "
           "e = Karp-Flatt serial fraction, Amdahl's fraction that explains S. f = serial fraction "
           "from CPU times: the client's CPU during the parallel run (packing, pickling, scheduler, "
           "receiving, writing) against the tasks' CPU on the workers. S(N) = W1 / (C + max(W / N, "
           "longest task)): the projection to N workers (machines) from CPU times, W1 the tasks' CPU "
           "in the serial run; S(2) is what the run would have shown on 2 cores of its own.", "",
           "| work | tasks | serial (s) | parallel (s) | S | e | f | S(2) | S(4) | S(8) | S(16) | S(64) | same as serial |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    labels = {"batch_mystran": "batch identify, 8 studies through MYSTRAN",
              "coverage": f"coverage, {res.get('coverage', {}).get('tasks', 0)} replicates (cube simple)",
              "batch_diagnose": "batch diagnose, 4 undeclared-effect studies",
              "mystran_chunks": "one MYSTRAN batch in column chunks"}
    for key, label in labels.items():
        r = res.get(key)
        if not r:
            continue
        extra = f" ({r['model']}, {r['rhs']} rhs)" if key == "mystran_chunks" else ""
        p = r["projected"]
        proj = " | ".join(f"{p[str(n)]:.2f}" for n in (2, 4, 8, 16, 64))
        out.append(f"| {label}{extra} | {r['tasks']} | {r['serial_s']:.2f} | {r['parallel_s']:.2f} | "
                   f"{r['speedup']:.2f} | {r['serial_fraction']:.3f} | {r['cpu_serial_fraction']:.3f} | {proj} | "
                   f"{_same(r)} |")
    return "\n".join(out) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--replicates", type=int, default=400)
    ap.add_argument("--tube", default="40x60", help="generated frame for the chunk benchmark, LONGxAROUND")
    ap.add_argument("--rhs", type=int, default=200)
    ap.add_argument("--skip", default="", help="comma-separated: batch_mystran,coverage,batch_diagnose,mystran_chunks")
    ap.add_argument("--out", type=Path, default=None, help="write the Markdown table here")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    skip = {s.strip() for s in args.skip.split(",") if s.strip()}
    from blackbox.parallel import DaskExecutor

    def say(s):
        print(s, flush=True)

    res: dict = {}
    load0 = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="blackbox-bench-parallel-") as tmp:
        tmp = Path(tmp)
        tempfile.tempdir = str(tmp)          # solver run folders of this benchmark stay here
        t0 = time.perf_counter()
        with DaskExecutor(workers=args.workers) as ex:
            ex.map(_warm, list(range(4 * args.workers)))
            start = time.perf_counter() - t0
            say(f"cluster of {args.workers} workers started and warmed up in {start:.2f} s")
            if "batch_mystran" not in skip:
                res["batch_mystran"] = bench_batch(ex, mystran_copies(tmp), "identify", say)
            if "coverage" not in skip:
                res["coverage"] = bench_coverage(ex, args.replicates, say)
            if "batch_diagnose" not in skip:
                res["batch_diagnose"] = bench_batch(ex, [FIXTURES / "undeclared" / n for n in DIAGNOSE],
                                                    "diagnose", say)
            if "mystran_chunks" not in skip:
                n_long, n_around = (int(v) for v in args.tube.split("x"))
                res["mystran_chunks"] = bench_chunks(ex, tmp, n_long, n_around, args.rhs, say)
        tempfile.tempdir = None
    cmd = "python benchmarks/parallel.py" + (" " + " ".join(argv if argv is not None else sys.argv[1:])
                                             if (argv if argv is not None else sys.argv[1:]) else "")
    res["meta"] = {"machine": platform.platform(), "cpus": os.cpu_count(), "python": platform.python_version(),
                   "date": time.strftime("%Y-%m-%d %H:%M:%S"), "workers": args.workers,
                   "cluster_start_s": start, "command": cmd, "load_before": load0, "load_after": os.getloadavg()}
    res = json.loads(json.dumps(res))          # projection keys as strings, as in the JSON file
    text = markdown(res)
    print(text)
    if args.out:
        args.out.write_text(text)
    if args.json:
        args.json.write_text(json.dumps(res, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
