"""The ``blackbox`` command (CONTRACT.md section 2).

Every sub-command exits non-zero with a one-paragraph message on bad input; ``--debug`` shows
the traceback instead.
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from pathlib import Path

import numpy as np

from blackbox.errors import IdentificationError, StudyError
from solver_adapters.protocol import SolverError


def _write_csv(path: Path, header: list[str], rows) -> None:
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows(rows)


# --------------------------------------------------------------------------------------------
# sub-commands
# --------------------------------------------------------------------------------------------
def cmd_solve(args) -> int:
    from blackbox.study import load_study
    from blackbox.workflows import make_adapter_for

    study = load_study(args.study)
    adapter = make_adapter_for(study, args.adapter)
    report = adapter.dofs()
    t0 = time.perf_counter()
    out = adapter.solve(study.loads, report)
    wall = time.perf_counter() - t0
    if not np.all(np.isfinite(out.values)):
        raise SolverError(f"adapter {adapter.name!r} returned non-finite displacements")
    args.out.mkdir(parents=True, exist_ok=True)
    rows = ((case, g, c, repr(float(out.values[i, j])))
            for j, case in enumerate(out.cases) for i, (g, c) in enumerate(out.dofs))
    _write_csv(args.out / "displacements.csv", ["case", "grid", "component", "value"], rows)
    print(f"solved {len(out.cases)} case(s) x {len(report)} DOFs with {adapter.name!r} in "
          f"{wall:.3f} s ({adapter.stats.runs} solver run(s)) -> {args.out / 'displacements.csv'}")
    return 0


def cmd_simulate(args) -> int:
    from blackbox.workflows import simulate_study

    rec = simulate_study(args.study, args.truth, args.out, args.adapter)
    print(f"simulated {rec['n_measurements']} measurements over {len(rec['cases'])} case(s) "
          f"({rec['solver_runs']} solver run(s)) -> {args.out / 'measurements.csv'}")
    return 0


def cmd_identify(args) -> int:
    import json

    from blackbox.report import fit_report, identification_plots
    from blackbox.study import load_study
    from blackbox.workflows import identify_study, make_adapter_for, truth_of

    study = load_study(args.study, need_measurements=True)
    adapter = make_adapter_for(study, args.adapter)

    def progress(rec) -> bool:
        print(f"  iteration {rec.iteration:2d}  {rec.phase:<11s} chi2 = {rec.objective:.6g}", flush=True)
        return False

    print(f"identify {study.name}: {len(study.measurements)} measurements, joints "
          f"{[j.name for j in study.config.joints]}, adapter {adapter.name!r}")
    run = identify_study(study, adapter, model=args.model, progress=progress)
    r = run.result
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "result.json").write_text(json.dumps(r.to_json_dict(run.solver), indent=2))
    truth = truth_of(study)
    (args.out / "report.md").write_text(
        fit_report(r, title=f"Identification of {study.name}", solver=run.solver, truth=truth)
        + "\n![convergence](convergence.png)\n\n![estimates](estimates.png)\n\n![residuals](residuals.png)\n")
    plots = identification_plots(r, run.fit_obs, args.out, truth=truth)
    print(f"{'converged' if r.converged else 'NOT converged'} in {r.iterations} iterations "
          f"({r.message}); reduced chi2 = {r.reduced_chi2:.4g}; {run.solver['runs']} solver run(s)"
          + (f" + {run.solver['cached_batches']} batch(es) from the cache"
             if run.solver.get("cached_batches") else "")
          + f", {run.solver['right_hand_sides']} right-hand sides -> {args.out}"
          + ("" if plots else " (no plots: install matplotlib)"))
    return 0 if r.converged else 3


def cmd_compare(args) -> int:
    """``blackbox compare STUDY``: simple vs complex joint model (Chapter 6), ``blackbox.compare_run``."""
    from blackbox.compare_run import compare_study

    res = compare_study(args.study, args.out, args.adapter, log=lambda s: print(s, flush=True))
    se = res["strain_energy"]
    print(f"isolated joint: E_complex = {se['complex']:.4e}, E_simple = {se['simple']:.4e}, "
          f"R = {100 * se['relative_difference']:.1f} % -> {args.out / 'comparison.json'}")
    ok = all(m["converged"] for m in res["models"].values())
    return 0 if ok else 3


def cmd_diagnose(args) -> int:
    """``blackbox diagnose STUDY``: find what the declared model lacks (``blackbox.diagnose_run``)."""
    from blackbox.diagnose_run import run_diagnose

    effects = tuple(e.strip() for e in args.effects.split(",") if e.strip()) if args.effects else None
    opts = {"effects": effects} if effects else {}
    run = run_diagnose(args.study, args.out, adapter_name=args.adapter, alpha=args.alpha,
                       max_steps=args.max_steps, refit_top=args.refit_top,
                       progress=lambda s: print(s, flush=True), **opts)
    d = run.document
    b, a = d["before"], d["after"]
    added = ", ".join(f"{e['effect']} @ {', '.join(map(str, e['where']))[:40]}" for e in d["added"]) or "nothing"
    print(f"added {added}; reduced chi2 {b['reduced_chi2']:.4g} -> {a['reduced_chi2']:.4g} "
          f"(99% band {a['band_99'][0]:.3g}..{a['band_99'][1]:.3g}), hold-out RMS "
          f"{b['holdout_rms'] if b['holdout_rms'] is not None else float('nan'):.4g} -> "
          f"{a['holdout_rms'] if a['holdout_rms'] is not None else float('nan'):.4g}; "
          f"{d['solver']['runs']} solver runs, {d['wall_s']:.1f} s -> {args.out}")
    return 0


def cmd_bench(args) -> int:
    from blackbox.bench import CASES, main_bench

    adapters = [a.strip() for a in args.adapters.split(",") if a.strip()]
    cases = [c.strip() for c in args.cases.split(",") if c.strip()] if args.cases else list(CASES)
    unknown = [c for c in cases if c not in CASES]
    if unknown:
        raise ValueError(f"unknown bench case(s) {unknown}; known: {', '.join(CASES)}")
    print(f"bench: cases {cases}, adapters {adapters}")
    command = "blackbox bench " + " ".join(sys.argv[2:]) if len(sys.argv) > 2 else "blackbox bench"
    main_bench(args.out, args.fixtures, adapters, cases, args.repeat, command)
    print(f"-> {args.out / 'bench.json'}, {args.out / 'bench.md'}")
    return 0


def cmd_conformance(args) -> int:
    """``blackbox conformance ADAPTER``: the shared adapter checks of ``solver_adapters.conformance``."""
    import tempfile

    from solver_adapters import conformance as cf
    from solver_adapters.registry import adapter_factory, make_adapter

    name = args.adapter
    adapter_factory(name)  # an unknown or uninstalled adapter is bad input (exit 2), not a failed check
    opts = {"timeout_s": args.timeout}
    with tempfile.TemporaryDirectory(prefix="blackbox-conformance-") as tmp:
        if args.study is not None:
            from blackbox.study import load_study
            from blackbox.workflows import make_adapter_for

            study = load_study(args.study)

            def factory(deck):
                return make_adapter_for(study, name, deck=deck, cache=False)

            deck, loads, deck_name, others = study.deck_path, study.loads, study.name, {}
        else:
            if name == "command":
                raise ValueError("adapter 'command' needs a study for its command line and dialect: "
                                 "blackbox conformance command --study STUDY")

            def factory(deck):
                return make_adapter(name, deck, **opts)

            if args.deck is not None:
                if not args.deck.is_file():
                    raise ValueError(f"--deck {args.deck}: no such file")
                deck, loads, deck_name, others = args.deck, None, args.deck.stem, {}
            else:
                others = cf.conformance_decks(tmp)
                deck_name = "cube" if "cube" in others else "generated"
                deck, loads = others[deck_name]
        misbehaviour = None if args.no_misbehaviour else cf.builtin_misbehaviour(name, args.misbehave_timeout)
        print(f"conformance of adapter {name!r} on {deck} ({'+'.join([deck_name, *(n for n in others if n != deck_name)])})")

        def progress(check):
            print(f"{'PASS' if check.passed else 'FAIL'}  {check.name:<34} {check.wall_s:7.2f} s  {check.detail}",
                  flush=True)

        report = cf.run_conformance(factory, deck, loads, misbehaviour=misbehaviour, rtol=args.rtol,
                                    agreement_decks=others, deck_name=deck_name, progress=progress)
    print(report.lines()[-1])
    if args.out is not None:
        js, md = report.write(args.out)
        print(f"-> {js}, {md}")
    return 0 if report.passed else 1


def add_cache_options(s: argparse.ArgumentParser) -> None:
    """``--no-cache`` / ``--cache-dir`` for a sub-command that builds adapters for a study
    (``main`` hands them to ``blackbox.workflows.make_adapter_for`` through ``ADAPTER_CACHE``)."""
    s.add_argument("--no-cache", action="store_true",
                   help="run the solver even for batches already in the study's .blackbox_cache/")
    s.add_argument("--cache-dir", type=Path, default=None,
                   help="keep solver results here instead of STUDY/.blackbox_cache/")


def _cache_choice(args) -> bool | Path:
    if args.no_cache:
        return False
    return args.cache_dir if args.cache_dir is not None else True


def _study_command(sub, name: str, help: str, func, *, cache: bool = True) -> argparse.ArgumentParser:
    """A sub-command on a study folder: STUDY, --adapter, --out (and the cache options)."""
    s = sub.add_parser(name, help=help)
    s.add_argument("study", type=Path)
    s.add_argument("--adapter", default=None, help="override [solver] adapter")
    s.add_argument("--out", type=Path, required=True)
    if cache:
        add_cache_options(s)
    s.set_defaults(func=func)
    return s


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="blackbox", description=__doc__.splitlines()[0])
    p.add_argument("--debug", action="store_true", help="show tracebacks")
    sub = p.add_subparsers(dest="command", required=True)

    _study_command(sub, "solve", "solve the study's load cases, no joint model added", cmd_solve)

    s = _study_command(sub, "simulate", "a copy of the study with simulated measurements (Sec. 5.2)",
                       cmd_simulate, cache=False)
    s.add_argument("--truth", type=Path, required=True, help="truth TOML: joints, noise, bias, what to measure")

    s = sub.add_parser("bench", help="identification cost by sensitivity method (Table 3.3)")
    s.add_argument("--out", type=Path, required=True)
    s.add_argument("--adapters", default="reference", help="comma-separated, e.g. reference,mystran")
    s.add_argument("--cases", default=None, help="comma-separated subset of cube-simple,cube-complex,car-simple,car-complex")
    s.add_argument("--repeat", type=int, default=3, help="best of N timings per row")
    s.add_argument("--fixtures", type=Path, default=Path(__file__).resolve().parents[1] / "fixtures")
    s.set_defaults(func=cmd_bench)

    s = _study_command(sub, "identify", "identify the joint parameters from the measurements (Ch. 4-5)",
                       cmd_identify)
    s.add_argument("--model", choices=["simple", "complex"], default=None,
                   help="override every joint's declared model")

    _study_command(sub, "compare", "simple vs complex joint model, MDSE loading (Ch. 6)", cmd_compare)

    s = _study_command(sub, "diagnose", "find what the declared model lacks, add it, report before/after",
                       cmd_diagnose)
    s.add_argument("--alpha", type=float, default=0.01,
                   help="significance level after the Bonferroni correction (default 0.01)")
    s.add_argument("--max-steps", type=int, default=5, help="effects added at most (default 5)")
    s.add_argument("--refit-top", type=int, default=6, help="candidates refitted per round (default 6)")
    s.add_argument("--effects", default=None,
                   help="comma-separated effect kinds to consider (default: all of joint_coupling, "
                        "joint_translation, undeclared_joint, support_flexibility, load_scale, "
                        "sensor_gain, member_stiffness)")

    s = sub.add_parser("conformance", help="run the shared adapter checks; exit 0 only if all pass")
    s.add_argument("adapter", help="adapter name: reference, mystran, legacy, command (needs --study), "
                                   "or one registered under the entry-point group blackbox.adapters")
    s.add_argument("--deck", type=Path, default=None,
                   help="run on this deck with seeded loads (default: the cube fixture, and the car and a "
                        "generated deck for the reference agreement)")
    s.add_argument("--study", type=Path, default=None,
                   help="run on this study's deck and loads with its [solver] settings")
    s.add_argument("--out", type=Path, default=None, help="write conformance.json and conformance.md here")
    s.add_argument("--rtol", type=float, default=None,
                   help="precision to hold the adapter to (default: its rtol attribute, else 1e-6)")
    s.add_argument("--timeout", type=float, default=None, help="per-run timeout for external codes (s)")
    s.add_argument("--misbehave-timeout", type=float, default=2.0,
                   help="timeout of the 'hang' misbehaviour check (s)")
    s.add_argument("--no-misbehaviour", action="store_true", help="skip the misbehaviour checks")
    s.set_defaults(func=cmd_conformance)
    return p


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    cache_token = None
    if hasattr(args, "no_cache"):  # a sub-command with --no-cache / --cache-dir (add_cache_options)
        from blackbox.workflows import ADAPTER_CACHE
        cache_token = ADAPTER_CACHE.set(_cache_choice(args))
    try:
        return int(args.func(args) or 0)
    except (StudyError, SolverError, IdentificationError, ValueError, OSError) as exc:
        if args.debug:
            raise
        kind = type(exc).__name__
        print(f"blackbox {args.command}: {kind}: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"blackbox {args.command}: interrupted (finished solver batches are kept in the "
              f"cache; run the command again to resume)", file=sys.stderr)
        return 130
    except Exception as exc:                 # a bug, not bad input: still one paragraph
        if args.debug:
            raise
        print(f"blackbox {args.command}: unexpected {type(exc).__name__}: {exc} "
              f"(this is a bug in blackbox; run again with --debug for the traceback)", file=sys.stderr)
        return 1
    finally:
        if cache_token is not None:
            ADAPTER_CACHE.reset(cache_token)


if __name__ == "__main__":
    sys.exit(main())
