"""Figures of ``blackbox design`` (``blackbox.experiment_design``) on the fixtures.

Run ``python benchmarks/design.py`` from the repository root (~1 minute on 2 cores). It prints:

1. **car, complex model** (``fixtures/car_complex``, Table 5.18 truth, 5 % noise, the fixture's
   sensors: joint grids and grids 9, 10, 12, 13, all components, relative to grid 11): the
   predicted widths of the designed plans of 6..12 single-load cases against Chapter 5's
   L1-L30 (``studies/chapter5.md``: the fixture generator's 30 multi-force cases; predicted here at
   the truth with the same sensors and noise model, its realised median 2.6 % there) -- Chapter
   5's measure (geometric mean over the parameters of 2 std / size) and the widest interval;
   1b. the same with candidate *cases*: 300 cases of Chapter 5's generator (2-5 forces each, a
   ``case`` label per candidate case), of which the plan picks;
2. **cube and car, simple model**: designed vs random plans of the same size (50 random plans):
   median-over-parameters and widest relative interval width, all sensors and a sensor budget;
3. **predicted vs realised**: 200 simulated repetitions of a designed plan at the truth, each
   identified in the condensed space, realised median width / predicted width per parameter;
4. **discrimination** (car, complex truth vs the best simple model): the expected excess chi2
   of the simple model of the designed plan and of random plans.

One solver run per fixture (the candidate unit loads and the joint boundary in one batch);
everything else is superposition in the condensed space. Seeded.
"""

from __future__ import annotations

import importlib.util
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from blackbox import experiment_design as D                                      # noqa: E402
from blackbox.commands.common import study_adapter                    # noqa: E402
from blackbox.declared import declared_model, read_truth, truth_joints  # noqa: E402
from blackbox.joints import SimpleJoint, joint_dofs                   # noqa: E402
from blackbox.simulation import NoiseConfig                             # noqa: E402
from blackbox.study import load_study                                 # noqa: E402
from solver_adapters.protocol import LoadMatrix                       # noqa: E402

NOISE = NoiseConfig(relative=0.05, floor=0.02)      # the fixtures' (truth.toml [noise])
N_RANDOM = 50
N_REPS = 200
SETUP = {   # joint grids, away grids, supports, force (N), moment (N*m)
    "cube": ((7, 71, 72), (5, 6, 8), {1}, 5.0, 0.5),
    "car": ((11, 111, 112), (9, 10, 12, 13), {6, 36, 26, 56}, 1000.0, 100.0),
}


def candidates(study, structure: str, reference: bool, moments: bool = True) -> D.Candidates:
    """Loads: every free grid but the joint's, forces (and moments) in each direction; sensors:
    the joint's DOFs and all components of the away grids, relative to the joint's first grid
    when ``reference`` (that grid itself absolutely, as ``blackbox simulate`` does)."""
    jg, away, spc, F, M = SETUP[structure]
    grids = sorted(g for g in study.deck.grids if g not in spc | set(jg))
    comps = range(1, 7) if moments else range(1, 4)
    loads = tuple(D.CandidateLoad(g, c, F if c <= 3 else M) for g in grids for c in comps)
    ref = jg[0] if reference else None
    sens = [D.CandidateSensor(g, c, None, None if ref is None or g == ref else ref) for g, c in joint_dofs(jg)]
    sens += [D.CandidateSensor(g, c, None, ref) for g in away for c in range(1, 7)]
    return D.Candidates(loads, tuple(sens))


def setup(fixture: str, reference: bool, moments: bool = True):
    study = load_study(ROOT / "fixtures" / fixture)
    structure = "cube" if fixture.startswith("cube") else "car"
    dm = declared_model(study)
    cands = candidates(study, structure, reference, moments)
    cm = dm.condense(study_adapter(study, None, cache=False), observed=cands.observed, loads=cands.unit_loads())
    truth_path = study.root / "truth.toml"
    _, k_true = truth_joints(study, read_truth(truth_path), truth_path)
    return study, dm, cands, cm, np.asarray(k_true, float)


def chapter5_cases(structure: str, n_cases: int = 30) -> LoadMatrix:
    """L1..L30 of Chapter 5: the fixture generator with ``N_EXTRA_CASES = 29``
    (``studies/chapter5.py``'s ``extended_load_rows``)."""
    name = "_design_generate_fixtures"
    spec = importlib.util.spec_from_file_location(name, ROOT / "fixtures" / "generate_fixtures.py")
    gf = importlib.util.module_from_spec(spec)
    sys.modules[name] = gf
    spec.loader.exec_module(gf)
    gf.N_EXTRA_CASES = n_cases - 1
    rows = gf.cube_loads()[0] if structure == "cube" else gf.build_car().loads
    cases = list(dict.fromkeys(str(r[0]) for r in rows))
    dofs = list(dict.fromkeys((int(r[1]), int(r[2])) for r in rows))
    V = np.zeros((len(dofs), len(cases)))
    for c, g, k, v in rows:
        V[dofs.index((int(g), int(k))), cases.index(str(c))] = float(v)
    return LoadMatrix.from_dense(dofs, V, cases)


def pct(x: float) -> str:
    return f"{100 * x:.2f} %" if np.isfinite(x) else "inf"


def study_car_complex() -> None:
    print("\n== 1. car, complex model: designed single-load cases vs Chapter 5's L1-L30 ==")
    for moments in (True, False):
        study, dm, cands, cm, kt = setup("car_complex", True, moments)
        space = D.candidate_space(cm, cands, kt, NOISE)
        ch5 = D.candidate_space(cm, cands, kt, NOISE, cases=chapter5_cases("car"))
        p30 = D.predict(ch5, range(30), range(len(cands.sensors)))
        what = "forces and moments" if moments else "forces only"
        print(f"candidates: {len(cands.loads)} loads ({what}), {len(cands.sensors)} sensors")
        for n in (10, 20, 30):
            p = D.predict(ch5, range(n), range(len(cands.sensors)))
            print(f"  Chapter 5 L1-L{n}: geometric mean 2 std/size {pct(p.geometric_mean_2std)}, "
                  f"widest {pct(p.max_relative_width)}")
        for n in ((6, 8, 10, 12) if moments else (8, 12, 16)):
            for crit in ("max_relative_ci_width", "d_optimal"):
                plan = D.optimise(space, n, None, crit)
                p = D.predict(space, plan.loads, plan.sensors)
                print(f"  designed {n:2d} cases ({crit:21s}): geometric mean {pct(p.geometric_mean_2std)}, widest "
                      f"{pct(p.max_relative_width)}; parameters narrower than with L1-L30: "
                      f"{int(np.sum(p.relative_width <= p30.relative_width))}/{kt.size}")
        reached = None
        for n in range(5, 13 if moments else 17):
            plan = D.optimise(space, n, None, "d_optimal", restarts=1)
            p = D.predict(space, plan.loads, plan.sensors)
            if p.geometric_mean_2std <= p30.geometric_mean_2std and p.max_relative_width <= p30.max_relative_width:
                reached = n
                break
        print(f"  -> fewest d_optimal cases at least as narrow as L1-L30 on both measures: "
              f"{reached if reached else '> %d' % n}")


def study_generated_cases(n_generated: int = 300) -> None:
    print(f"\n== 1b. car, complex model: {n_generated} Chapter 5-style multi-force cases as candidates ==")
    study, dm, _, _, kt = setup("car_complex", True)
    sensors = candidates(study, "car", True).sensors
    gen = chapter5_cases("car", n_generated)
    V = gen.values.toarray()
    loads = tuple(D.CandidateLoad(g, c, float(V[i, j]), gen.cases[j])
                  for j in range(gen.n_cases) for i, (g, c) in enumerate(gen.dofs) if V[i, j] != 0.0)
    cands = D.Candidates(loads, sensors)
    cm = dm.condense(study_adapter(study, None, cache=False), observed=cands.observed, loads=cands.unit_loads())
    space = D.candidate_space(cm, cands, kt, NOISE)
    p30 = D.predict(space, range(30), range(len(sensors)))      # L1-L30 are the first 30 candidates
    print(f"  L1-L30: geometric mean {pct(p30.geometric_mean_2std)}, widest {pct(p30.max_relative_width)}")
    for n in (8, 10, 12):
        for crit in ("max_relative_ci_width", "d_optimal"):
            plan = D.optimise(space, n, None, crit, restarts=1)
            p = D.predict(space, plan.loads, plan.sensors)
            print(f"  designed {n:2d} of {n_generated} ({crit:21s}): geometric mean {pct(p.geometric_mean_2std)}, "
                  f"widest {pct(p.max_relative_width)}")


def study_random() -> None:
    print(f"\n== 2. simple model: designed vs {N_RANDOM} random plans of the same size ==")
    for fixture, reference in (("cube", False), ("cube", True), ("car", False), ("car", True)):
        study, dm, cands, cm, kt = setup(fixture, reference)
        space = D.candidate_space(cm, cands, kt, NOISE)
        label = f"{fixture}{' (relative to the joint)' if reference else ''}"
        for n, m in ((4, None), (8, None), (4, 12), (8, 12)):
            plan = D.optimise(space, n, m)
            p = D.predict(space, plan.loads, plan.sensors)
            rnd = [D.predict(space, r.loads, r.sensors) for r in D.random_plans(space, n, m, N_RANDOM, seed=n)]
            rmed = float(np.median([r.median_relative_width for r in rnd]))
            rmax = float(np.median([r.max_relative_width for r in rnd]))
            print(f"  {label:34s} {n} cases, {m or len(cands.sensors):2d} sensors: median width designed "
                  f"{pct(p.median_relative_width)} random {pct(rmed)} (x{rmed / p.median_relative_width:.1f}); "
                  f"widest designed {pct(p.max_relative_width)} random {pct(rmax)} "
                  f"(x{rmax / p.max_relative_width:.1f})")


def study_validation() -> None:
    print(f"\n== 3. predicted vs realised widths, {N_REPS} simulated repetitions at the truth ==")
    for fixture, reference, n, m in (("cube", False, 8, None), ("cube", True, 8, 12), ("car", False, 8, None),
                                     ("car_complex", True, 12, None)):
        study, dm, cands, cm, kt = setup(fixture, reference)
        space = D.candidate_space(cm, cands, kt, NOISE)
        plan = D.optimise(space, n, m)
        p = D.predict(space, plan.loads, plan.sensors)
        t0 = time.perf_counter()
        k0 = dm.k0 if isinstance(dm.joints[0], SimpleJoint) else kt
        est, w = D.simulate_plan(cm, cands, plan, kt, space.sigma, k0, N_REPS, seed=1)
        ratio = np.nanmedian(w, axis=0) / p.relative_width
        print(f"  {fixture:12s} {'ref' if reference else 'abs'} {n} cases {len(plan.sensors)} sensors: "
              f"realised median / predicted per parameter {ratio.min():.3f}..{ratio.max():.3f} (worst |dev| "
              f"{100 * np.max(np.abs(ratio - 1)):.1f} %), failed fits {int(np.isnan(w[:, 0]).sum())}/{N_REPS}, "
              f"{time.perf_counter() - t0:.1f} s")


def study_discrimination() -> None:
    print("\n== 4. discrimination (car: complex truth, simple model fitted to it) ==")
    study, dm, cands, cm, kt = setup("car_complex", True)
    simple = declared_model(study, "simple").condensed_model(cm.c)
    space = D.discrimination_space(D.candidate_space(cm, cands, kt, NOISE), cm, kt, simple)
    total = float(np.sum(space.discrimination[0].r ** 2))
    for n in (1, 3, 6):
        plan = D.optimise(space, n, None, "discrimination")
        lam = -plan.value * total
        if abs(lam) < 1e-6 * total:
            print(f"  {n} case: expected excess chi2 ~0 for every plan ({lam:.1e}): one case cannot discriminate")
            continue
        rnd = [-D.criterion(space, "discrimination", r.loads, r.sensors) * total
               for r in D.random_plans(space, n, None, N_RANDOM, seed=n)]
        print(f"  {n} cases: expected excess chi2 of the simple model designed {lam:.4g}, random median "
              f"{np.median(rnd):.4g} (x{lam / np.median(rnd):.1f})")


if __name__ == "__main__":
    t0 = time.perf_counter()
    study_car_complex()
    study_generated_cases()
    study_random()
    study_validation()
    study_discrimination()
    print(f"\ntotal {time.perf_counter() - t0:.0f} s")
