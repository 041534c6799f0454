"""Predicted against realised interval widths of ``blackbox design``, by what the prior is.

``blackbox design`` predicts the intervals a planned test will give at its prior. Without
``--prior`` that is the study's start value, which is a guess: on the car fixture the start is
1e4 N*m/rad for every spring and the truth 1e5 (``fixtures/car/truth.toml``). Run
``python benchmarks/design_prior.py`` from the repository root (~1 minute). For three priors
-- the start value, a pilot result (the car study identified from its own measurements, given
as ``--prior result.json``) and that pilot with ``--robust`` -- it designs 6 single-load cases
with every candidate sensor (the candidates of ``benchmarks/design.py``: forces and moments at
every free grid, the joint's DOFs and grids 9, 10, 12, 13 read absolutely), then runs the planned
test 200 times at the truth (readings of the true joint plus the noise model's noise at the true
readings, each identified from the study's start value in the condensed space: no solver run)
and compares the predicted width of every parameter with the median realised one.
"""

from __future__ import annotations

import importlib.util
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import blackbox                                                        # noqa: E402
from blackbox import experiment_design as D                            # noqa: E402
from blackbox.commands import design                                   # noqa: E402
from blackbox.declared import read_truth, truth_joints                 # noqa: E402
from blackbox.study import load_study                                  # noqa: E402

N_REPS = 200
N_LOADS = 6


def car_candidates(study) -> D.Candidates:
    spec = importlib.util.spec_from_file_location("_bench_design", ROOT / "benchmarks" / "design.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.candidates(study, "car", reference=False)


def measure(study, cands, k_true, label: str, **options) -> dict:
    t0 = time.perf_counter()
    res = design.run(study, cands, n_loads=N_LOADS, **options)
    predicted = res.prediction.relative_width
    sigma_true = D.candidate_space(res.model, cands, k_true, res.noise).sigma
    _, widths = D.simulate_plan(res.model, cands, res.plan, k_true, sigma_true, res.declared.k0, N_REPS, seed=1)
    realised = np.nanmedian(widths, axis=0)
    ratio = predicted / realised
    out = {"label": label, "prior": res.prior_source, "predicted_median": float(np.median(predicted)),
           "realised_median": float(np.median(realised)), "predicted_widest": float(predicted.max()),
           "realised_widest": float(realised.max()), "ratio_median": float(np.median(ratio)),
           "ratio_min": float(ratio.min()), "ratio_max": float(ratio.max()),
           "failed": int(np.isnan(widths[:, 0]).sum()), "wall_s": time.perf_counter() - t0}
    print(f"  {label:18s} predicted width median {100 * out['predicted_median']:6.2f} %, widest "
          f"{100 * out['predicted_widest']:6.2f} %; realised median {100 * out['realised_median']:6.2f} %, widest "
          f"{100 * out['realised_widest']:6.2f} %; predicted / realised per parameter: median "
          f"{out['ratio_median']:.2f}, {out['ratio_min']:.2f}..{out['ratio_max']:.2f} "
          f"(failed fits {out['failed']}/{N_REPS}, {out['wall_s']:.1f} s)", flush=True)
    return out


def main() -> list[dict]:
    study = load_study(ROOT / "fixtures" / "car")
    cands = car_candidates(study)
    truth = study.root / "truth.toml"
    _, k_true = truth_joints(study, read_truth(truth), truth)
    k_true = np.asarray(k_true, float)
    print(f"car fixture: start {study.config.joints[0].initial:g}, truth {k_true[0]:g} N*m/rad; "
          f"{N_LOADS} designed cases, {len(cands.sensors)} sensors, {N_REPS} simulated tests at the truth")
    with tempfile.TemporaryDirectory() as tmp:
        pilot = blackbox.identify(study, profile=False)
        pilot.write(Path(tmp))
        result = Path(tmp) / "result.json"
        return [measure(study, cands, k_true, "start value"),
                measure(study, cands, k_true, "pilot result", prior=result),
                measure(study, cands, k_true, "pilot, --robust", prior=result, robust=True)]


if __name__ == "__main__":
    main()
