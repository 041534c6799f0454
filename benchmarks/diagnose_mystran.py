"""``blackbox diagnose`` through MYSTRAN against the reference solver, on every fixtures/undeclared folder.

    python benchmarks/diagnose_mystran.py [--folders none two_effects ...] [--out table.md]

Each folder is diagnosed twice with the same code, once per adapter (``reference``, ``mystran``),
each run with the command's defaults. A folder agrees when both reach the same conclusion:

* the same verdict and the same effects added, in the same order, at the same places;
* every parameter of the added effects within :data:`PARAM_RTOL` relative of the reference's,
  or within :data:`PARAM_SIGMA` of its own standard error (a parameter the data barely determine
  moves by more than 1e-3 when the flexibilities move by 1e-7, and that move means nothing).

Why those bounds: MYSTRAN prints 7 significant digits (docs/mystran.md), so each displacement the
diagnosis uses carries a relative error up to 5e-7; the split deck's rigid state is recovered by
conditioning on stiff pairs, which multiplies that error by the condition of the pair system
(printed in the run as "nesting ... sigma"), and a fitted stiffness inherits it amplified again by
the fit's own conditioning. Measured on these folders: 4e-4 at most (the table in docs/mystran.md).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
UNDECLARED = ROOT / "fixtures" / "undeclared"

PARAM_RTOL = 2e-3
"""Relative agreement of a parameter of an added effect (see the module docstring)."""
PARAM_SIGMA = 0.05
"""...or agreement within this fraction of the parameter's standard error."""


def folders() -> list[Path]:
    """Every study folder of fixtures/undeclared (those with a study.toml), by name."""
    return sorted(p for p in UNDECLARED.iterdir() if (p / "study.toml").is_file())


def diagnose_doc(folder: Path, adapter: str) -> tuple[dict, float]:
    """``diagnosis.json`` of ``blackbox diagnose folder --adapter adapter`` and its wall time."""
    from blackbox.commands.diagnose import run

    t0 = time.perf_counter()
    result = run(folder, adapter=adapter, plots=False)
    wall = time.perf_counter() - t0
    return json.loads(json.dumps(result.document, default=float)), wall


def added(doc: dict) -> list[tuple[str, tuple]]:
    return [(a["effect"], tuple(a["where"])) for a in doc["added"]]


def compare(ref: dict, mys: dict, sigma: float = PARAM_SIGMA) -> dict:
    """How a MYSTRAN diagnosis compares with the reference one: same verdict, same effects (in
    order, same places), the largest relative parameter difference, the largest difference in
    standard errors, and whether every parameter agrees (module docstring; ``sigma`` replaces
    :data:`PARAM_SIGMA` where a folder's parameters are known to trade off along a valley)."""
    same_effects = added(ref) == added(mys)
    worst_rel, worst_sigma, ok_params, different = 0.0, 0.0, same_effects, False
    if same_effects:
        for a, b in zip(ref["added"], mys["added"]):
            pa = {p["name"]: p for p in a.get("parameters", [])}
            pb = {p["name"]: p for p in b.get("parameters", [])}
            if set(pa) != set(pb):
                ok_params = False
                different = True
                continue
            for name, p in pa.items():
                v, w = float(p["value"]), float(pb[name]["value"])
                diff = abs(w - v)
                rel = diff / abs(v) if v else (0.0 if diff == 0 else math.inf)
                std = p.get("std")
                sig = diff / float(std) if std not in (None, 0) and math.isfinite(float(std)) else math.inf
                worst_rel, worst_sigma = max(worst_rel, rel), max(worst_sigma, sig if rel > PARAM_RTOL else 0.0)
                if not (rel <= PARAM_RTOL or sig <= sigma):
                    ok_params = False
    chi_ref, chi_mys = ref["after"]["reduced_chi2"], mys["after"]["reduced_chi2"]
    return {"same_verdict": ref["verdict"] == mys["verdict"], "same_effects": same_effects,
            "params_ok": ok_params, "max_param_rel": worst_rel, "max_param_sigma": worst_sigma,
            "different_parameters": different,
            "chi2_rel": abs(chi_mys - chi_ref) / abs(chi_ref),
            "agree": ref["verdict"] == mys["verdict"] and same_effects and ok_params}


def _effects_text(doc: dict) -> str:
    return ", ".join(f"{e} @ {','.join(map(str, w))}" for e, w in added(doc)) or "nothing"


def _param_text(r: dict) -> str:
    if r.get("different_parameters"):
        return "different parameters (another variant)"
    text = f"{r['max_param_rel']:.2g}"
    return text + (f" ({r['max_param_sigma']:.2g} std)" if r["max_param_sigma"] else "")


def table(rows: list[dict]) -> str:
    head = ["| folder | reference: verdict, added | MYSTRAN: verdict, added | max param rel. diff "
            "(diff / std beyond 2e-3) | reduced chi2 ref / MYSTRAN | wall s ref / MYSTRAN | agree |",
            "|---|---|---|---|---|---|---|"]
    body = [f"| {r['folder']} | {r['ref_verdict']}: {r['ref_added']} | {r['mys_verdict']}: {r['mys_added']} | "
            f"{_param_text(r)} | {r['chi2_ref']:.5g} / {r['chi2_mys']:.5g} | "
            f"{r['wall_ref']:.1f} / {r['wall_mys']:.1f} | {'yes' if r['agree'] else '**no**'} |" for r in rows]
    return "\n".join(head + body) + "\n"


def run_folder(folder: Path, sigma: float = PARAM_SIGMA) -> dict:
    ref, t_ref = diagnose_doc(folder, "reference")
    mys, t_mys = diagnose_doc(folder, "mystran")
    c = compare(ref, mys, sigma)
    return {"folder": folder.name, "ref_verdict": ref["verdict"], "mys_verdict": mys["verdict"],
            "ref_added": _effects_text(ref), "mys_added": _effects_text(mys),
            "chi2_ref": ref["after"]["reduced_chi2"], "chi2_mys": mys["after"]["reduced_chi2"],
            "wall_ref": t_ref, "wall_mys": t_mys, **c}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--folders", nargs="*", help="folder names (default: every one)")
    ap.add_argument("--out", type=Path, help="write the Markdown table here")
    args = ap.parse_args(argv)
    chosen = [f for f in folders() if not args.folders or f.name in args.folders]
    rows = []
    for f in chosen:
        r = run_folder(f)
        rows.append(r)
        print(f"{f.name}: {'agree' if r['agree'] else 'DIFFER'} (ref {r['ref_verdict']}: {r['ref_added']}; "
              f"MYSTRAN {r['mys_verdict']}: {r['mys_added']}; max param rel {r['max_param_rel']:.2g})",
              flush=True)
    text = table(rows)
    print(text)
    if args.out:
        args.out.write_text(text)
    return 0 if all(r["agree"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
