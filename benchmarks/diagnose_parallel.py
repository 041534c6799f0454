"""``blackbox diagnose`` through MYSTRAN, serially against ``--workers N``, on a generated body.

    python benchmarks/diagnose_parallel.py [--size 130x128] [--workers 2] [--json FILE]

Builds a study in a temporary folder: ``blackbox.structures.tube_body(n_long, n_around)`` (a
car-body-like tube frame, ``6 * n_long * n_around`` DOFs plus the roof joint's branch grids; 130x128
is 99,858 DOFs and 41,408 members, 12x16 is 1,182 DOFs), the roof joint ``JR`` declared as the
simple model, 12 seeded load cases (``blackbox.structures.random_loads``), measurements simulated
by the reference solver from a truth deck with the joint at 1e5 N m/rad and one planted effect the
study does not declare: the front-left suspension point (SPC 123) elastic, a grounded spring per
component of ``PLANTED_FACTOR`` times the members' own stiffness there; 3 % noise (floor 5 %) on
the joint and 20 grids spread over the body; then ``adapter = "mystran"``. Runs
``blackbox.commands.diagnose.run`` on it with the default options (at 130x128 the candidates are
capped: 100 of 16,635 undeclared-joint grids, 300 of 41,408 members), serially and with a local
Dask cluster of ``--workers`` processes (started and warmed up before the clock starts; no run
cache either way), and prints:

* the wall times, the speed-up ``S`` and the Karp-Flatt serial fraction
  ``e = (1/S - 1/p) / (1 - 1/p)``;
* each batched solver run's wall time, serially and on the cluster (a run cut into column
  chunks is one line, its chunks side by side);
* each round's refits: how many, how long, and whether they went to the workers
  (``blackbox.diagnosis.search.refits_pay``);
* CPU times, which a machine shared with other jobs changes much less than wall times: the
  serial run's (``W1``: this process and the solver processes it waited for), the parallel
  run's client (``C``) and workers (``W``, with their solver processes), and the projection
  ``S(p) = W1 / (C + W / p)``: the speed-up the run would have had on ``p`` cores of its own
  (the client's work counted as serial, the workers' as perfectly shared: a bound, since the
  client's element run overlaps the workers' declared run and the chunks are not equal);
* whether the conclusions are the serial ones: the same effects at the same places and
  variants, the same verdict, chi2 to 1e-9 relative and every parameter to 1e-4 of its standard
  deviation (a refit on a worker runs single-threaded BLAS: docs/parallel.md), and whether the
  planted effect was the first one added.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

PLANTED_FACTOR = 3.0
"""The planted support's springs, times the members' own stiffness at the grid per component."""


def build_study(folder: Path, n_long: int, n_around: int) -> tuple[Path, dict]:
    """The study described in the module docstring, in ``folder`` (created), and what was
    planted (for the check after the diagnosis; the diagnosis never reads it)."""
    from dataclasses import replace

    from blackbox.commands.simulate import run as simulate
    from blackbox.joints import make_joint
    from blackbox.structures import TruthDeck, random_loads, tube_body, write_study
    from solver_adapters.bdf import read_deck
    from solver_adapters.bdf_write import write_deck

    f = tube_body(n_long, n_around)
    src = write_study(folder / "source", f, random_loads(f, 12, seed=3), f"tube-{n_long}x{n_around}",
                      initial=1.0e3)
    # the truth: the roof joint at 1e5 N m/rad and the front-left suspension point (SPC 123)
    # elastic, a grounded spring per component of PLANTED_FACTOR x the members' stiffness there
    ed = TruthDeck(read_deck(src / "model.bdf"))
    (jname, jgrids), = f.joints
    ed.joint(jname, jgrids, "simple", make_joint(jname, jgrids, "simple").initial_params(1.0e5))
    support = next(g for g, c in f.spcs.items() if c == "123")
    ed.deck.spc1s = [replace(s, grids=tuple(g for g in s.grids if g != support)) for s in ed.deck.spc1s
                     if set(s.grids) != {support}]
    local = sum(ed.k_diag(e, support) for e in ed.members_at(support))
    for c in (1, 2, 3):
        ed.spring(PLANTED_FACTOR * local[c - 1], support, c)
    (src / "truth.bdf").write_text(write_deck(ed.deck, "large"))
    grids = sorted(f.grids)
    away = grids[:: max(1, len(grids) // 20)][:20]
    (src / "truth.toml").write_text(
        f'seed = 1\ndeck = "truth.bdf"\n\n'
        f"[noise]\nrelative = 0.03\nfloor = 0.05\n\n[measure]\njoint = true\naway_grids = {away}\n")
    study = folder / "study"
    simulate(src, src / "truth.toml", adapter="reference").write(study)
    toml = (study / "study.toml").read_text()
    (study / "study.toml").write_text(toml.replace('adapter = "reference"', 'adapter = "mystran"'))
    return study, {"effect": "support_flexibility", "where": [support]}


def compare(serial: dict, par: dict) -> dict:
    """The parallel document's conclusions against the serial one's (module docstring)."""
    def added(d):
        return [(a["effect"], a["where"], a.get("variant")) for a in d["added"]]

    def params(d):
        out = [(f"{a['effect']}@{a['where']}.{p['name']}", p["value"], p["std"]) for a in d["added"]
               for p in a["parameters"]]
        out += [(f"{j}.{n}", p["value"], p["std"]) for j, rec in d["joint_parameters"]["final"].items()
                for n, p in rec["parameters"].items()]
        return out

    worst = 0.0
    names_equal = [p[0] for p in params(serial)] == [p[0] for p in params(par)]
    if names_equal:
        for (_, v, sd), (_, v0, sd0) in zip(params(par), params(serial)):
            if sd0 and v is not None and v0 is not None:
                worst = max(worst, abs(v - v0) / sd0)
    chi2 = max(abs(par[k]["chi2"] - serial[k]["chi2"]) / abs(serial[k]["chi2"]) for k in ("before", "after"))
    same = (added(par) == added(serial) and par["verdict"] == serial["verdict"] and names_equal
            and worst <= 1e-4 and chi2 <= 1e-9)
    return {"same": bool(same), "max_parameter_difference_in_std": worst, "max_chi2_relative_difference": chi2}


def _cpu() -> float:
    """CPU seconds of this process and the children it waited for (the solver processes, their
    guard processes)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def _workers_cpu(ex) -> float:
    """The workers' :func:`_cpu`, summed."""
    return float(sum(ex.client.run(_cpu).values()))


class _Rounds:
    """Times every round's refits (``search.map_refits``) and notes whether they went to the
    workers (the executor's ``share`` was called)."""

    def __init__(self):
        from blackbox.diagnosis import search

        self.search, self.orig, self.rows = search, search.map_refits, []

        def timed(*args, **kw):
            ex = args[8] if len(args) > 8 else kw.get("executor")
            before = getattr(ex, "shares", 0)
            t0 = time.perf_counter()
            out = self.orig(*args, **kw)
            self.rows.append({"refits": len(args[2]), "wall_s": time.perf_counter() - t0,
                              "on_workers": getattr(ex, "shares", 0) > before})
            return out
        search.map_refits = timed

    def take(self) -> list[dict]:
        rows, self.rows = self.rows, []
        return rows


def _counting(ex):
    """``ex`` with a counter of its ``share`` calls (the rounds whose refits it ran)."""
    share = ex.share

    def counted(value):
        ex.shares += 1
        return share(value)
    ex.shares = 0
    ex.share = counted
    return ex


def main(argv=None) -> int:
    from blackbox.commands import diagnose
    from blackbox.parallel import DaskExecutor

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="130x128", help="n_long x n_around of tube_body (default 130x128)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--json", type=Path, default=None, help="write every number here")
    args = ap.parse_args(argv)
    n_long, n_around = (int(x) for x in args.size.lower().split("x"))
    rounds = _Rounds()
    load0 = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="blackbox-diagnose-bench-") as tmp:
        t0 = time.perf_counter()
        study, planted = build_study(Path(tmp), n_long, n_around)
        t_build = time.perf_counter() - t0
        t0, c0 = time.perf_counter(), _cpu()
        serial = diagnose.run(study, plots=False)
        t_serial, w1 = time.perf_counter() - t0, _cpu() - c0
        r_serial = rounds.take()
        load1 = os.getloadavg()
        t0 = time.perf_counter()
        with DaskExecutor(workers=args.workers) as ex:
            ex.map(abs, list(range(args.workers)))            # workers up before the clock starts
            t_start = time.perf_counter() - t0
            _counting(ex)
            t0, c0, k0 = time.perf_counter(), _cpu(), _workers_cpu(ex)
            par = diagnose.run(study, plots=False, executor=ex)
            t_par, c_par, w_par = time.perf_counter() - t0, _cpu() - c0, _workers_cpu(ex) - k0
        r_par = rounds.take()
    load2 = os.getloadavg()
    check = compare(serial.document, par.document)
    first = serial.document["added"][0] if serial.document["added"] else {}
    found = [first.get("effect"), first.get("where")] == [planted["effect"], planted["where"]]
    p = args.workers
    s = t_serial / t_par
    e = (1 / s - 1 / p) / (1 - 1 / p)
    deck = serial.prepared.deck
    dofs = 6 * len(deck.grids)
    limits = serial.document["settings"]["candidates_limited"]
    rec = {"size": args.size, "dofs": dofs, "members": len(deck.cbars), "workers": p, "build_s": t_build,
           "serial_s": t_serial, "parallel_s": t_par, "cluster_start_s": t_start, "speedup": s,
           "serial_fraction": e, "cpu_serial_s": w1, "cpu_client_s": c_par, "cpu_workers_s": w_par,
           "projected": {n: w1 / (c_par + w_par / n) for n in (2, 4, 8)}, **check,
           "planted": planted, "planted_found_first": found,
           "verdict": serial.document["verdict"], "candidates_limited": limits,
           "runs": [{"purpose": a.purpose, "rhs": a.right_hand_sides, "serial_s": a.wall_s, "parallel_s": b.wall_s}
                    for a, b in zip(serial.diagnosis.runs, par.diagnosis.runs)],
           "rounds_serial": r_serial, "rounds_parallel": r_par,
           "load_average": {"before": load0, "after_serial": load1, "after": load2},
           "machine": f"{platform.platform()} ({os.cpu_count()} cores)",
           "openblas_threads": os.environ.get("OPENBLAS_NUM_THREADS", "default"),
           "date": time.strftime("%Y-%m-%d %H:%M:%S")}
    print(f"tube_body({n_long}, {n_around}): {dofs} DOF, {len(deck.cbars)} members, MYSTRAN; "
          f"study built in {t_build:.1f} s")
    for lim in limits:
        print(f"  {lim['effect']}: {lim['considered']} of {lim['available']} candidates ({lim['chosen_by']})")
    print(f"serial {t_serial:.1f} s, {p} workers {t_par:.1f} s (cluster start {t_start:.1f} s, not included): "
          f"S = {s:.2f}, e = {e:.3f}; conclusions equal: {check['same']} (parameters within "
          f"{check['max_parameter_difference_in_std']:.2g} std, chi2 within "
          f"{check['max_chi2_relative_difference']:.2g}); "
          f"planted {planted['effect']} @ {planted['where']} added first: {found}; verdict {rec['verdict']}")
    print(f"  CPU: serial {w1:.1f} s; parallel client {c_par:.1f} s + workers {w_par:.1f} s; on cores of its "
          f"own S(2) = {rec['projected'][2]:.2f}, S(4) = {rec['projected'][4]:.2f}, S(8) = {rec['projected'][8]:.2f}")
    for r in rec["runs"]:
        print(f"  {r['purpose']:<45s} {r['rhs']:6d} rhs  {r['serial_s']:7.1f} s  ->  {r['parallel_s']:7.1f} s")
    for i, (a, b) in enumerate(zip(r_serial, r_par), 1):
        print(f"  round {i}: {a['refits']} refits {a['wall_s']:6.2f} s  ->  {b['wall_s']:6.2f} s "
              f"({'on the workers' if b['on_workers'] else 'here'})")
    print(f"  load average {load0[0]:.1f} before, {load1[0]:.1f} after the serial run, {load2[0]:.1f} after")
    if args.json:
        args.json.write_text(json.dumps(rec, indent=2))
    return 0 if check["same"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
