"""The ``blackbox`` command: one sub-command per capability (docs/commands.md).

Exit codes: 0 done; 2 bad input (study, deck, options, ``--out``); 3 the solver failed; 4 the
command finished but its result is not usable as it stands (not converged, a parameter not
identifiable, or a diagnosis left unexplained) -- the reasons are printed. A message is one
paragraph; ``--debug`` (anywhere on the command line) shows the traceback instead.
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from pathlib import Path

import numpy as np

from blackbox.commands.output import check_out, write_output
from blackbox.errors import BlackboxError, EditedDeckError
from solver_adapters.errors import ConsentError
from solver_adapters.protocol import Deck, DeckFormatError, ModelError, SolverError, UnknownDofError

EXIT_OK, EXIT_BAD_INPUT, EXIT_SOLVER, EXIT_UNUSABLE = 0, 2, 3, 4
"""The documented exit codes (docs/commands.md)."""

_BAD_INPUT_SOLVER_ERRORS = (DeckFormatError, ModelError, UnknownDofError)
"""Solver-side errors that are the user's input, not the solver's failure."""


def _out_for(args, command: str) -> Path:
    """``--out`` checked before any work (the study itself is protected)."""
    protect = (Path(args.study),) if getattr(args, "study", None) is not None and Path(args.study).is_dir() else ()
    return check_out(args.out, command, protect=protect)


def _warn(lines: list[str]) -> None:
    for w in lines:
        print(f"  warning: {w}", flush=True)


# --------------------------------------------------------------------------------------------
# sub-commands
# --------------------------------------------------------------------------------------------
def cmd_solve(args) -> int:
    from blackbox.adapters import make_adapter_for
    from blackbox.study import load_study

    out_dir = _out_for(args, "solve")
    study = load_study(args.study)
    with _executor(args, "solver chunks") as ex:
        adapter = _chunked(study, args, ex)
        adapter = make_adapter_for(study, adapter) if adapter is None or isinstance(adapter, str) else adapter
        # a scalar point (SPOINT) has one DOF, component 1; its other five are held, not reported
        scalar = study.deck.scalar_points() if isinstance(study.deck, Deck) else set()
        report = [d for d in adapter.dofs() if d[1] == 1 or d[0] not in scalar]
        t0 = time.perf_counter()
        out = adapter.solve(study.loads, report)
        wall = time.perf_counter() - t0
    if not np.all(np.isfinite(out.values)):
        raise SolverError(f"adapter {adapter.name!r} returned non-finite displacements")

    def write(folder: Path) -> list[str]:
        with (folder / "displacements.csv").open("w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["case", "grid", "component", "value"])
            w.writerows((case, g, c, repr(float(out.values[i, j])))
                        for j, case in enumerate(out.cases) for i, (g, c) in enumerate(out.dofs))
        return ["displacements.csv"]

    write_output(out_dir, "solve", write)
    print(f"solved {len(out.cases)} case(s) x {len(report)} DOFs with {adapter.name!r} in "
          f"{wall:.3f} s ({adapter.stats.runs} solver run(s)) -> {out_dir / 'displacements.csv'}")
    auto = getattr(adapter, "autospc_dofs", None) if adapter.name == "reference" else None
    if auto:                  # NASTRAN's grid-point singularity processing, as its F06 lists it
        shown = ", ".join(f"{g}:{c}" for g, c in auto[:12]) + (" ..." if len(auto) > 12 else "")
        print(f"  AUTOSPC constrained {len(auto)} component(s) without stiffness (grid:component {shown}); "
              f"their displacements are 0 and a load on them is lost, as in NASTRAN")
    return EXIT_OK


def cmd_simulate(args) -> int:
    from blackbox.commands import simulate

    out = _out_for(args, "simulate")
    res = simulate.run(args.study, args.truth, adapter=args.adapter)
    write_output(out, "simulate", res.write)
    print(f"simulated {res.n_measurements} measurements over {len(res.record['cases'])} case(s) "
          f"({res.record['solver_runs']} solver run(s)) -> {out / 'measurements.csv'}")
    return EXIT_OK


def cmd_identify(args) -> int:
    from blackbox.commands import identify

    out = _out_for(args, "identify")

    def progress(rec) -> bool:
        print(f"  iteration {rec.iteration:2d}  {rec.phase:<11s} chi2 = {rec.objective:.6g}", flush=True)
        return False

    from blackbox.study import load_study
    study = load_study(args.study, need_measurements=True)
    print(f"identify {study.name}: {len(study.measurements)} measurements, joints "
          f"{[j.name for j in study.config.joints]}", flush=True)
    cases = [c.strip() for c in args.cases.split(",") if c.strip()] if args.cases is not None else None
    with _executor(args, "solver chunks, bootstrap refits") as ex:
        res = identify.run(study, adapter=_chunked(study, args, ex), model=args.model, progress=progress,
                           stages=_Throttled(), executor=ex, cases=cases)
    print("  writing the report and plots", flush=True)
    files = write_output(out, "identify", res.write)
    r, cost = res.result, res.solver
    print(f"{'converged' if r.converged else 'NOT converged'} in {r.iterations} iterations "
          f"({r.message}); reduced chi2 = {r.reduced_chi2:.4g}; {cost.runs} solver run(s)"
          + (f" + {cost.cached_batches} batch(es) from the cache" if cost.cached_batches else "")
          + f", {cost.right_hand_sides} right-hand sides, adapter {cost.adapter!r} -> {out}"
          + ("" if any(f.endswith(".png") for f in files) else " (no plots: install matplotlib)"))
    if res.patterns:
        sel = res.selection_json()
        print(f"  fitted the {sel['fitted_cases']} case(s) matching {list(res.patterns)}; "
              f"{sel['excluded_cases']} other case(s) predicted"
              + (f", RMS error {sel['excluded_rms_error']:.4g}" if sel["excluded_rms_error"] is not None else ""))
    if res.fit_sigma is not None:
        fs = res.fit_sigma
        print("  sigma estimated from this fit (" + ", ".join(
            f"{k} {s:.4g}, {100 * fs.confidence:g}% interval [{lo:.4g}, {hi:.4g}]"
            for k, s, lo, hi in zip(fs.kinds, fs.sigma, fs.ci_low, fs.ci_high))
            + "): the chi-square test of the model is off")
    elif res.noise is not None and res.noise.estimated:
        print("  sigma from " + ", ".join(f"{k}: {v} row(s)" for k, v in res.noise.counts().items()))
    for name, value, lo, hi in zip(r.param_names, r.k, r.ci_low, r.ci_high):
        if len(r.param_names) <= 6:
            print(f"  {name} = {value:.5g}  [{lo:.4g}, {hi:.4g}] ({100 * r.confidence:g}%)")
    if res.scaled is not None and len(r.param_names) <= 6:
        sc = res.scaled
        print(f"  the chi-square test fails; with sigma scaled to the residuals (x {sc.covariance_scale ** 0.5:.3g}, "
              "Student t): " + ", ".join(f"{n} [{lo:.4g}, {hi:.4g}]"
                                         for n, lo, hi in zip(sc.param_names, sc.ci_low, sc.ci_high)))
    _warn(list(r.warnings))
    if not res.ok:
        why = [] if r.converged else ["the estimation did not converge"]
        bad = [f"{j}.{n}" for j, n, ok in zip(r.param_joint, r.param_names, r.identifiable) if not ok]
        if bad:
            why.append(f"not identifiable from these data: {', '.join(bad)} (rank {r.rank} of {r.n_params})")
        print(f"blackbox identify: result not usable as it stands: {'; '.join(why)} (exit {EXIT_UNUSABLE})",
              file=sys.stderr)
        return EXIT_UNUSABLE
    return EXIT_OK


def cmd_compare(args) -> int:
    """``blackbox compare STUDY``: simple vs complex joint model (Chapter 6)."""
    from blackbox.commands import compare

    out = _out_for(args, "compare")
    res = compare.run(args.study, adapter=args.adapter, log=lambda s: print(s, flush=True))
    write_output(out, "compare", res.write)
    se = res.document["strain_energy"]
    print(f"isolated joint: E_complex = {se['complex']:.4e}, E_simple = {se['simple']:.4e}, "
          f"R = {100 * se['relative_difference']:.1f} % -> {out / 'comparison.json'}")
    if not res.ok:
        bad = [m for m, d in res.document["models"].items() if not d["converged"]]
        print(f"blackbox compare: the {' and '.join(bad)} fit did not converge (exit {EXIT_UNUSABLE})",
              file=sys.stderr)
        return EXIT_UNUSABLE
    return EXIT_OK


def cmd_diagnose(args) -> int:
    """``blackbox diagnose STUDY``: find what the declared model lacks and add it."""
    from blackbox.commands import diagnose

    out = _out_for(args, "diagnose")
    effects = tuple(e.strip() for e in args.effects.split(",") if e.strip()) if args.effects else None
    with _executor(args, "diagnose runs") as ex:
        caps = {k: v for k, v in (("max_joint_candidates", args.max_joint_candidates),
                                  ("max_member_candidates", args.max_member_candidates)) if v is not None}
        res = diagnose.run(args.study, adapter=args.adapter, alpha=args.alpha, max_steps=args.max_steps,
                           refit_top=args.refit_top, effects=effects, progress=lambda s: print(s, flush=True),
                           executor=ex, **caps)
    write_output(out, "diagnose", res.write)
    d = res.document
    b, a = d["before"], d["after"]
    added = ", ".join(f"{e['effect']} @ {', '.join(map(str, e['where']))[:40]}" for e in d["added"]) or "nothing"
    val = d.get("validation") or {}
    if "k" in val:
        check = f"{val['k']}-fold chi2 {val['cv_chi2_before']:.5g} -> {val['cv_chi2_after']:.5g}"
    elif b["holdout_rms"] is not None and a["holdout_rms"] is not None:
        check = f"hold-out RMS {b['holdout_rms']:.4g} -> {a['holdout_rms']:.4g}"
    else:
        check = "no check against unfitted data (one case)"
    print(f"added {added}; reduced chi2 {b['reduced_chi2']:.4g} -> {a['reduced_chi2']:.4g} "
          f"(99% band {a['band_99'][0]:.3g}..{a['band_99'][1]:.3g}), {check}; verdict {d['verdict']}; "
          f"{d['solver']['runs']} solver runs, {d['wall_s']:.1f} s -> {out}")
    if d["verdict"] == "unexplained":
        print(f"blackbox diagnose: unexplained (exit {EXIT_UNUSABLE}): {d['verdict_detail']}", file=sys.stderr)
        return EXIT_UNUSABLE
    return EXIT_OK


def cmd_design(args) -> int:
    """``blackbox design STUDY --candidates FILE``: which loads and sensors (docs/design.md)."""
    from blackbox.commands import design

    out = _out_for(args, "design")
    print(f"design {args.study}: {args.loads} load case(s), criterion {args.criterion}", flush=True)
    res = design.run(args.study, args.candidates, n_loads=args.loads, n_sensors=args.sensors,
                     criterion=args.criterion, prior=args.prior, robust=args.robust, draws=args.draws,
                     model=args.model, adapter=args.adapter, seed=args.seed)
    write_output(out, "design", res.write)
    p, c = res.prediction, res.solver
    print(f"chose {len(res.plan.loads)} case(s) of {len(res.candidates.cases)} and {len(res.plan.sensors)} "
          f"sensor(s) of {len(res.candidates.sensors)}: widest interval {100 * p.max_relative_width:.3g} % "
          f"(random plans: {100 * res.random_median_width:.3g} %); {c.runs} solver run(s), "
          f"{c.right_hand_sides} right-hand sides -> {out / 'design.json'}")
    _warn(list(res.notes))
    if not p.identifiable.all():
        print(f"blackbox design: the plan does not determine every parameter (exit {EXIT_UNUSABLE})", file=sys.stderr)
        return EXIT_UNUSABLE
    return EXIT_OK


def cmd_measurements(args) -> int:
    """``blackbox measurements READINGS --channels CHANNELS.csv --study STUDY --out DIR``: rig readings
    become measurements.csv (docs/measurements.md)."""
    from blackbox.commands import measurements

    out = check_out(args.out, "measurements", protect=(args.study,) if args.study.is_dir() else ())
    res = measurements.run(args.readings, args.channels, args.study)
    write_output(out, "measurements", res.write)
    doc = res.to_json()
    print(f"{doc['rows']} measurement row(s) from {len(res.channels)} channel(s) over "
          f"{len({r[0] for r in res.rows})} case(s)"
          + (f", {doc['rows_without_sigma']} without sigma" if doc["rows_without_sigma"] else "")
          + f" -> {out / 'measurements.csv'}")
    _warn(list(res.notes))
    return EXIT_OK


def cmd_import(args) -> int:
    """``blackbox import DECK --out STUDY``: a NASTRAN input file becomes a study folder (docs/import.md)."""
    from blackbox.commands import import_deck

    out = check_out(args.out, "import")
    res = import_deck.run(args.deck, joints=args.joint, include_dirs=args.include_dir, spc=args.spc)
    write_output(out, "import", res.write)
    for note in res.notes:
        print(f"  {note}")
    what = (f"joints {[name for name, _ in res.joints]}" if res.joints
            else "no joint declared: complete study.toml (candidate joints are listed there)")
    print(f"imported {res.source.name}: {len(res.cases)} case(s) -> {out} ({what})")
    return EXIT_OK


def cmd_batch(args) -> int:
    """``blackbox batch STUDY...``: identify or diagnose many studies side by side; exit 4 when a
    study is not ok."""
    from blackbox.commands import batch

    out = check_out(args.out, "batch", protect=tuple(Path(s) for s in args.studies if Path(s).is_dir()))
    options = {"model": args.model} if args.model and args.batch_command == "identify" else {}
    with _executor(args, "studies") as ex:
        res = batch.run(args.studies, command=args.batch_command, executor=ex, adapter=args.adapter,
                        options=options, say=lambda s: print(s, flush=True))
    write_output(out, "batch", res.write)
    counts = ", ".join(f"{n} {s}" for s, n in res.counts().items())
    print(f"batch {res.sub_command}: {len(res.outcomes)} studies ({counts}) in {res.wall_s:.1f} s on "
          f"{res.executor} -> {out}")
    bad = [o for o in res.outcomes if not o.ok]
    for o in bad:
        first = o.message.strip().splitlines()[0] if o.message.strip() else ""
        print(f"  {o.name}: {o.status}: {first}", file=sys.stderr)
    if bad:
        print(f"blackbox batch: {len(bad)} of {len(res.outcomes)} studies not ok (exit {EXIT_UNUSABLE}); "
              f"see {out / 'summary.md'}", file=sys.stderr)
        return EXIT_UNUSABLE
    return EXIT_OK


def cmd_population(args) -> int:
    """``blackbox population STUDY...``: many specimens of one joint design pooled into one
    population (docs/population.md); exit 4 when a parameter's population is not determined or a
    specimen's estimate did not converge."""
    from blackbox.commands import population

    out = check_out(args.out, "population", protect=tuple(Path(s) for s in args.studies if Path(s).is_dir()))
    with _executor(args, "specimens") as ex:
        res = population.run(args.studies, executor=ex, adapter=args.adapter, confidence=args.confidence,
                             alpha=args.alpha, say=lambda s: print(s, flush=True))
    print("  writing the report and plots", flush=True)
    files = write_output(out, "population", res.write)
    doc = res.to_json()
    sol, d = doc["solver"], doc["specimens_differ"]
    print(f"population of {len(res.outcomes)} specimens: {sol['runs']} solver run(s)"
          + (f" + {sol['cached_batches']} from the cache" if sol["cached_batches"] else "")
          + f", {res.wall_s:.1f} s on {res.executor}; specimens differ: "
          + (f"p = {d['p_value']:.3g} (chi2 = {d['statistic']:.4g}, {d['df']} df)" if d and d["p_value"] is not None
             else "not tested (no degrees of freedom)") + f" -> {out}"
          + ("" if any(f.endswith(".png") for f in files) else " (no plots: install matplotlib)"))
    for p in doc["parameters"]:
        hi = p["center_ci_high"]
        print(f"  {p['joint']}.{p['name']}: centre {p['center']:.4g} [{p['center_ci_low'] or 0:.4g}, "
              f"{hi if hi is not None else float('inf'):.4g}], spread {100 * (p['spread'] or 0):.3g} %"
              if p["center"] is not None else f"  {p['joint']}.{p['name']}: not determined")
    for o in doc["outliers"]:
        print(f"  outlier: {o['study']} in {o['joint']}.{o['name']} (p = {o['p_value']:.2g}, "
              f"Bonferroni {o['p_adjusted']:.2g})")
    _warn(doc["warnings"])
    if not res.ok:
        why = []
        if res.undetermined:
            why.append(f"these specimens do not determine the centre or bound the spread of "
                       f"{', '.join(res.undetermined)} (see the notes)")
        if res.not_converged:
            why.append(f"the estimate of {', '.join(res.not_converged)} did not converge")
        print(f"blackbox population: result not usable as it stands: {'; '.join(why)} (exit {EXIT_UNUSABLE})",
              file=sys.stderr)
        return EXIT_UNUSABLE
    return EXIT_OK


def cmd_bench(args) -> int:
    from blackbox.commands import bench

    adapters = [a.strip() for a in args.adapters.split(",") if a.strip()]
    cases = [c.strip() for c in args.cases.split(",") if c.strip()] if args.cases else list(bench.CASES)
    out = check_out(args.out, "bench")
    print(f"bench: cases {cases}, adapters {adapters}")
    command = "blackbox bench " + " ".join(sys.argv[2:]) if len(sys.argv) > 2 else "blackbox bench"
    with _executor(args, "bench rows") as ex:
        res = bench.run(args.fixtures, adapters, cases, args.repeat, command=command, executor=ex)
    write_output(out, "bench", res.write)
    print(f"-> {out / 'bench.json'}, {out / 'bench.md'}")
    return EXIT_OK


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
            from blackbox.adapters import make_adapter_for

            study = load_study(args.study)

            def factory(deck):
                return make_adapter_for(study, name, deck=deck, cache=False)

            deck, loads, deck_name, others = study.deck_path, study.loads, study.name, {}
            if study.deck.unmodelled:
                # the reference solver cannot read the study's deck (shells, solids): the checks
                # that compare with it run on the built-in decks instead
                others = cf.conformance_decks(tmp)
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
        print(f"conformance of adapter {name!r} on {deck} ({'+'.join([deck_name, *(n for n in others if n != deck_name)])})")
        if args.no_misbehaviour:
            misbehaviour = None
        else:
            misbehaviour, which = cf.misbehaviour_for(factory, Path(deck), name, args.misbehave_timeout)
            print(f"misbehaviour checks: {which}")

        def progress(check):
            print(cf.check_line(check), flush=True)

        report = cf.run_conformance(factory, deck, loads, misbehaviour=misbehaviour, rtol=args.rtol,
                                    agreement_decks=others, deck_name=deck_name, progress=progress)
    print(report.lines()[-1])
    if args.out is not None:
        js, md = report.write(args.out)
        print(f"-> {js}, {md}")
    return 0 if report.passed else 1


def add_cache_options(s: argparse.ArgumentParser) -> None:
    """``--no-cache`` / ``--cache-dir`` for a sub-command that builds adapters for a study
    (``main`` hands them to ``blackbox.adapters.make_adapter_for`` through ``ADAPTER_CACHE``)."""
    s.add_argument("--no-cache", action="store_true",
                   help="run the solver even for batches already in the study's .blackbox_cache/")
    s.add_argument("--cache-dir", type=Path, default=None,
                   help="keep solver results here instead of STUDY/.blackbox_cache/")


def add_allow_outside(s: argparse.ArgumentParser) -> None:
    """``--allow-outside DIR`` (repeatable): a study's files may lie in DIR although it is outside
    the study folder (``main`` hands it to ``blackbox.study.ALLOW_OUTSIDE``)."""
    s.add_argument("--allow-outside", type=Path, action="append", default=[], metavar="DIR",
                   help="let the study's files (deck, loads...) lie in DIR outside the study folder, for "
                        "this run (or list DIR under allow_outside in your ~/.config/blackbox/config.toml)")


def _cache_choice(args) -> bool | Path:
    if args.no_cache:
        return False
    # a folder the user names may be reached through their own links: use its real path (the
    # cache refuses a linked folder, which is what a study's own .blackbox_cache must not be)
    return args.cache_dir.resolve() if args.cache_dir is not None else True


def _study_command(sub, name: str, help: str, func, *, cache: bool = True) -> argparse.ArgumentParser:
    """A sub-command on a study folder: STUDY, --adapter, --out (and the cache options)."""
    s = sub.add_parser(name, help=help)
    s.add_argument("study", type=Path)
    s.add_argument("--adapter", default=None, help="override [solver] adapter")
    s.add_argument("--out", type=Path, required=True)
    s.add_argument("--trust-command", action="store_true",
                   help="consent, for this run, to start the study's external command (adapter \"command\")")
    add_allow_outside(s)
    if cache:
        add_cache_options(s)
    s.set_defaults(func=func)
    return s


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="blackbox", description=__doc__.splitlines()[0])
    p.add_argument("--debug", action="store_true", help="show tracebacks (accepted anywhere)")
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("import", help="a NASTRAN input file (case control + bulk data) becomes a study folder")
    s.add_argument("deck", type=Path, help="the NASTRAN input file (.bdf, .dat, .nas ...)")
    s.add_argument("--out", type=Path, required=True, help="the study folder to write")
    s.add_argument("--joint", action="append", default=[], metavar="NAME:G1,G2,...",
                   help="declare a flexible joint: its branch-end grids, the RBE2's GN first (repeatable)")
    s.add_argument("--include-dir", action="append", default=[], type=Path, metavar="DIR",
                   help="a folder outside the deck's own folder tree that its INCLUDEs may read "
                        "(repeatable; also include_dirs in the user configuration)")
    s.add_argument("--spc", type=int, metavar="N",
                   help="when the subcases select different constraint sets (SPC = ...): import the subcases of "
                        "set N (default: those of the first subcase's set; a study has one set of supports)")
    s.set_defaults(func=cmd_import)

    s = sub.add_parser("measurements", help="rig readings (channels, repeats, zero scans) become measurements.csv")
    s.add_argument("readings", type=Path, help="CSV case,<channel>,...: one row per scan, 'zero' rows unloaded")
    s.add_argument("--channels", type=Path, required=True,
                   help="channel map CSV channel,grid,component,sign,gain,reference_grid,units[,accuracy]")
    s.add_argument("--study", type=Path, required=True, help="the study the measurements are for")
    s.add_argument("--out", type=Path, required=True, help="folder for measurements.csv and the report")
    s.set_defaults(func=cmd_measurements)

    s = _study_command(sub, "solve", "solve the study's load cases, no joint model added", cmd_solve)
    add_parallel_options(s)

    s = _study_command(sub, "simulate", "a copy of the study with simulated measurements (Sec. 5.2)",
                       cmd_simulate, cache=False)
    s.add_argument("--truth", type=Path, required=True, help="truth TOML: joints, noise, bias, what to measure")

    s = sub.add_parser("bench", help="identification cost by sensitivity method (Table 3.3)")
    s.add_argument("--out", type=Path, required=True)
    s.add_argument("--adapters", default="reference", help="comma-separated, e.g. reference,mystran")
    s.add_argument("--cases", default=None, help="comma-separated subset of cube-simple,cube-complex,car-simple,car-complex")
    s.add_argument("--repeat", type=_positive_int, default=3, help="best of N timings per row")
    s.add_argument("--fixtures", type=Path, default=Path(__file__).resolve().parents[1] / "fixtures")
    add_parallel_options(s)
    s.set_defaults(func=cmd_bench)

    s = _study_command(sub, "identify", "identify the joint parameters from the measurements (Ch. 4-5)",
                       cmd_identify)
    add_parallel_options(s)
    s.add_argument("--model", choices=["simple", "complex"], default=None,
                   help="override every joint's declared model")
    s.add_argument("--cases", default=None, metavar="PATTERN[,PATTERN...]",
                   help="fit only these cases (labels or glob patterns, e.g. 's00[1-4]-*'); the others are "
                        "predicted. Overrides [identification] cases")

    _study_command(sub, "compare", "simple vs complex joint model, MDSE loading (Ch. 6)", cmd_compare)

    s = _study_command(sub, "diagnose", "find what the declared model lacks, add it, report before/after",
                       cmd_diagnose)
    add_parallel_options(s)
    s.add_argument("--alpha", type=float, default=0.01,
                   help="significance level of the whole search (spent over its rounds; default 0.01)")
    s.add_argument("--max-steps", type=int, default=5, help="effects added at most (default 5)")
    s.add_argument("--refit-top", type=int, default=6, help="candidates refitted per round (default 6)")
    s.add_argument("--max-joint-candidates", type=int, default=None, metavar="N",
                   help="undeclared-joint grids (and rigid_end_zone grids) considered at most, those "
                        "nearest the declared fit's residual beyond (default 100; each costs 3 (members - 1) "
                        "right-hand sides of the split run)")
    s.add_argument("--max-member-candidates", type=int, default=None, metavar="N",
                   help="members considered at most for member_stiffness, those nearest the declared "
                        "fit's residual beyond (default: every member when their end grids are at "
                        "most 1000, else 300)")
    s.add_argument("--effects", default=None,
                   help="comma-separated effect kinds to consider (default: every kind; docs/commands.md "
                        "lists them, e.g. joint_coupling, undeclared_joint, member_stiffness, rigid_end_zone)")

    s = sub.add_parser("batch", help="identify (or diagnose) many studies side by side; summary across them")
    s.add_argument("studies", type=Path, nargs="+", metavar="STUDY")
    s.add_argument("--out", type=Path, required=True)
    s.add_argument("--command", dest="batch_command", choices=["identify", "diagnose"], default="identify")
    s.add_argument("--adapter", default=None, help="override every study's [solver] adapter")
    s.add_argument("--model", choices=["simple", "complex"], default=None)
    s.add_argument("--trust-command", action="store_true",
                   help="consent, for this run, to start the studies' external command (adapter \"command\")")
    add_allow_outside(s)
    add_cache_options(s)
    add_parallel_options(s)
    s.set_defaults(func=cmd_batch)

    s = sub.add_parser("population", help="many specimens of one joint design: the population's centre and "
                                          "spread per joint parameter, each specimen shrunk toward it")
    s.add_argument("studies", type=Path, nargs="+", metavar="STUDY", help="one study folder per specimen")
    s.add_argument("--out", type=Path, required=True, help="the output folder")
    s.add_argument("--adapter", default=None, help="override every study's [solver] adapter")
    s.add_argument("--confidence", type=float, default=None,
                   help="of every interval (default: the studies' [identification] confidence)")
    s.add_argument("--alpha", type=float, default=0.01,
                   help="family-wise level of the test for a specimen that does not belong (default 0.01)")
    s.add_argument("--trust-command", action="store_true",
                   help="consent, for this run, to start the studies' external command (adapter \"command\")")
    add_allow_outside(s)
    add_cache_options(s)
    add_parallel_options(s)
    s.set_defaults(func=cmd_population)

    s = _study_command(sub, "design", "choose the load cases and sensors of a test before it is run", cmd_design)
    s.add_argument("--candidates", type=Path, required=True,
                   help="CSV kind,grid,component,value,sigma[,reference_grid[,case]] (docs/design.md)")
    s.add_argument("--loads", type=_positive_int, default=6, help="number of load cases to design (default 6)")
    s.add_argument("--sensors", type=_positive_int, default=None,
                   help="number of sensors (default: every candidate sensor)")
    s.add_argument("--criterion", default="max_relative_ci_width",
                   choices=["max_relative_ci_width", "d_optimal", "a_optimal", "discrimination"])
    s.add_argument("--prior", type=Path, default=None,
                   help="result.json of an earlier identification (or a truth.toml); default: study.toml initial")
    s.add_argument("--robust", action="store_true",
                   help="average the criterion over draws from the prior's uncertainty (needs --prior result.json)")
    s.add_argument("--draws", type=_positive_int, default=10, help="--robust: number of draws (default 10)")
    s.add_argument("--model", choices=["simple", "complex"], default=None, help="override every joint's model")
    s.add_argument("--seed", type=int, default=0, help="seed of the random plans, restarts and draws")

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
    s.add_argument("--trust-command", action="store_true",
                   help="consent, for this run, to start the study's external command (adapter \"command\")")
    s.set_defaults(func=cmd_conformance)
    return p


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {v}")
    return v


class _Throttled:
    """Prints a stage's progress lines at most every ``every_s`` seconds, and the last of each
    stage (``k/k``), so a long stage shows it is alive and a short one stays quiet."""

    def __init__(self, every_s: float = 2.0):
        self.every_s, self.last = every_s, time.perf_counter()

    def __call__(self, message: str) -> None:
        import re
        m = re.search(r"(\d+)/(\d+)", message)
        final = m is not None and m.group(1) == m.group(2)
        now = time.perf_counter()
        if final or m is None or now - self.last >= self.every_s:
            print(f"  {message}", flush=True)
            self.last = now


def add_parallel_options(s: argparse.ArgumentParser) -> None:
    """``--workers N`` / ``--scheduler ADDRESS`` for a sub-command with independent work."""
    g = s.add_mutually_exclusive_group()
    g.add_argument("--workers", type=_positive_int, default=None,
                   help="run the independent work on a local Dask cluster of N worker processes "
                        "(needs: pip install 'blackbox-joints[distributed]')")
    g.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run the independent work on an existing Dask scheduler, e.g. tcp://host:8786")


def _executor(args, label: str):
    """The executor of ``--workers`` / ``--scheduler`` (serial without them, or without dask)."""
    from blackbox.parallel import make_executor, terminal_progress
    return make_executor(getattr(args, "workers", None), getattr(args, "scheduler", None),
                         progress=terminal_progress(label, lambda s: print(s, flush=True)),
                         warn=lambda m: _warn([m]))


def _chunked(study, args, ex):
    """The study's adapter with its large batches split over the executor's workers (external
    solvers), or just its name when the work stays in this process."""
    if ex.workers <= 1:
        return args.adapter
    from blackbox.adapters import make_adapter_for
    from blackbox.parallel import use_executor
    return use_executor(make_adapter_for(study, args.adapter), ex)


def _heartbeat(elapsed_s: float, last_line: str) -> None:
    """One terminal line every few seconds while an external solver runs."""
    tail = f": {last_line.strip()[:100]}" if last_line and last_line.strip() else ""
    print(f"  solver running, {elapsed_s:.0f} s{tail}", flush=True)


def exit_code(exc: BaseException) -> int:
    """The documented exit code of an error that ended a command."""
    if isinstance(exc, SolverError) and not isinstance(exc, _BAD_INPUT_SOLVER_ERRORS + (ValueError,)):
        return EXIT_SOLVER
    if isinstance(exc, EditedDeckError):          # the solver's answer to an edited deck
        return EXIT_SOLVER
    return EXIT_BAD_INPUT


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv                 # accepted anywhere on the command line
    argv = [a for a in argv if a != "--debug"]
    parser = build_parser()
    args = parser.parse_args(argv)
    args.debug = debug
    from solver_adapters.subprocess import install_termination_handlers

    from blackbox.adapters import ADAPTER_CACHE, SOLVER_PROGRESS, TRUST_COMMAND
    from blackbox.study import ALLOW_OUTSIDE

    import threading
    previous = (install_termination_handlers()      # SIGTERM/SIGHUP end a run as Ctrl-C does
                if threading.current_thread() is threading.main_thread() else {})
    trust_token = TRUST_COMMAND.set(bool(getattr(args, "trust_command", False)))
    beat_token = SOLVER_PROGRESS.set(_heartbeat)
    allow_token = ALLOW_OUTSIDE.set(tuple(getattr(args, "allow_outside", None) or ()))
    cache_token = None
    if hasattr(args, "no_cache"):  # a sub-command with --no-cache / --cache-dir (add_cache_options)
        cache_token = ADAPTER_CACHE.set(_cache_choice(args))
    try:
        return int(args.func(args) or 0)
    except (BlackboxError, SolverError, ConsentError, ValueError, OSError) as exc:
        if debug:
            raise
        code = exit_code(exc)
        what = "solver failure" if code == EXIT_SOLVER else "bad input"
        print(f"blackbox {args.command}: {what}: {type(exc).__name__}: {exc}", file=sys.stderr)
        return code
    except KeyboardInterrupt:
        print(f"blackbox {args.command}: interrupted (finished solver batches are kept in the "
              f"cache; run the command again to resume)", file=sys.stderr)
        return 130
    except Exception as exc:                 # a bug, not bad input: still one paragraph
        if debug:
            raise
        print(f"blackbox {args.command}: unexpected {type(exc).__name__}: {exc} "
              f"(this is a bug in blackbox; run again with --debug for the traceback)", file=sys.stderr)
        return 1
    finally:
        import signal
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        TRUST_COMMAND.reset(trust_token)
        SOLVER_PROGRESS.reset(beat_token)
        ALLOW_OUTSIDE.reset(allow_token)
        if cache_token is not None:
            ADAPTER_CACHE.reset(cache_token)


if __name__ == "__main__":
    sys.exit(main())
