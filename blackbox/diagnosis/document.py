"""``diagnosis.json``: a :class:`~blackbox.diagnosis.search.Diagnosis` as a JSON document.

Keys: ``study``, ``before`` / ``after`` (fit statistics with the 99 % band), ``candidates`` (the
first round's, best first), ``added`` (each effect of the final model with its parameters there,
in the order added), ``removed`` (effects a later addition made unnecessary), ``steps`` (every round:
statistics, the 25 best candidates, joint parameters and residual structure before and after),
``stop_reason``, ``sigma_exchange`` (two exchanged cases searched again with their sigmas
exchanged: the search the document is not, in brief, :func:`blackbox.diagnosis.exchange.brief`;
``null`` when not run), ``joint_parameters``, ``holdout``, ``holdout_check`` (the hold-out cases read
against the final model: outliers, cases of another size, whether the rest is predicted;
:mod:`blackbox.diagnosis.holdout`), ``noise_level`` (above the noise band: whether the misfit looks
like noise larger than declared, :mod:`blackbox.diagnosis.noise_level`; ``null`` within it),
``validation`` (hold-out cases or K-fold over
the load cases, :mod:`blackbox.diagnosis.validation`), ``settings``, ``identify_check``, ``solver``,
``warnings``, ``method_wall_s`` (and ``wall_s``, the whole command, and ``notes``, what the
diagnosis leaves aside on a deck with shells or solids, added by the command);
``verdict`` (``adequate`` / ``explained`` / ``unexplained``, :func:`blackbox.diagnosis.search.verdict`)
with ``verdict_detail`` (one sentence), ``hotspots`` (``[{"grid", "share", "n", "excess"}]``: each
grid's share of the final fit's chi-square excess, largest first, top 10), ``hotspot_cases`` and
``hotspot_components`` (the same per case and per component).
"""

from __future__ import annotations

import math

from blackbox.diagnosis.fit import Fit, chi2_band
from blackbox.diagnosis.scoring import CandidateScore
from blackbox.diagnosis.search import AMBIGUOUS, Diagnosis, near_tie

__all__ = ["diagnosis_document", "final_additions", "verdict_detail", "misfit_location", "alternatives", "AMBIGUOUS"]


def _num(v):
    if v is None:
        return None
    v = float(v)
    return v if math.isfinite(v) else None


def _stats(fit: Fit, band) -> dict:
    lo, hi = chi2_band(fit.n_obs - fit.n_params)
    return {"reduced_chi2": _num(fit.reduced_chi2), "rms_residual": _num(fit.rms_residual),
            "holdout_rms": _num(fit.holdout_rms), "bic": _num(fit.bic), "chi2": _num(fit.chi2),
            "n_obs": fit.n_obs, "n_params": fit.n_params, "holdout_chi2": _num(fit.holdout_chi2),
            "holdout_n_obs": fit.holdout_n, "band_99": [_num(lo), _num(hi)],
            "in_band": bool(lo <= fit.reduced_chi2 <= hi)}


def _candidate(c: CandidateScore) -> dict:
    out = {"effect": c.effect.kind, "where": c.effect.where_json(), **c.effect.details_json(),
           "delta_bic": _num(c.delta_bic),
           "p_value": _num(c.p_value), "log10_p_value": _num(c.log10_p), "score": _num(c.score),
           "df": c.df, "p_value_bonferroni": _num(c.p_adjusted), "delta_bic_method": c.delta_bic_method}
    if c.screen_drop is not None:
        out["screen_chi2_drop"] = _num(c.screen_drop)
    if c.refit is not None:
        out.update({"refit": True, "lr": _num(c.lr), "lr_p_value": _num(c.lr_p_value),
                    "lr_p_value_bonferroni": _num(c.lr_p_adjusted), "reduced_chi2": _num(c.refit.reduced_chi2),
                    "holdout_delta_chi2": _num(c.holdout_delta_chi2),
                    "kfold_delta_chi2": _num(c.kfold_delta_chi2), "decision": c.reason})
    out["variants_tried"] = [_trial(t) for t in c.variants]
    return out


def _trial(t) -> dict:
    """One richer variant refitted against the one it extends (:class:`search.VariantTrial`)."""
    return {"variant": t.effect.variant, "from_variant": t.from_variant, "parameters": list(t.effect.names),
            "reduced_chi2": None if t.refit is None else _num(t.refit.reduced_chi2),
            "lr": _num(t.lr), "lr_p_value": _num(t.lr_p_value), "lr_p_value_adjusted": _num(t.lr_p_adjusted),
            "delta_bic": _num(t.delta_bic), "holdout_delta_chi2": _num(t.holdout_delta_chi2),
            "kfold_delta_chi2": _num(t.kfold_delta_chi2),
            "accepted": bool(t.accepted), "decision": t.reason}


def _joint_params(fit: Fit) -> dict:
    out = {}
    for j, sl in zip(fit.spec.joints, fit.spec.joint_slices()):
        out[j.name] = {"model": j.model_name,
                       "parameters": {n: {"value": _num(v), "std": _num(s)}
                                      for n, v, s in zip(j.param_names, fit.x[sl], fit.std[sl])}}
    return out




def alternatives(step) -> list[dict]:
    """The accepted candidates of ``step`` whose evidence is within :data:`AMBIGUOUS` of the one
    added: explanations the data hardly tell apart from it (a support spring and the member
    that ends there), best first."""
    a = step.added
    out = []
    for c in step.scores:
        if c is a or not c.accepted or c.refit is None or c.effect.key == a.effect.key:
            continue
        if near_tie(c, a):
            gap = c.evidence - a.evidence
            alt = {"effect": c.effect.kind, "where": c.effect.where_json(), **c.effect.details_json(),
                   "evidence_gap": _num(gap), "of": "data" if c.effect.of_data else "structure"}
            sep = step.separations.get(c.effect.key)
            if sep is not None:
                alt["separate_by"] = sep
            out.append(alt)
    return sorted(out, key=lambda d: d["evidence_gap"])


def final_additions(added_keys: list, final_keys) -> list[int]:
    """The rounds whose added effect (``added_keys[i]``, ``None``: nothing added) is in the
    final model, each effect once: one removed as unnecessary and added again in a later round
    is one effect of the final model, listed at the round that added it last."""
    last = {k: i for i, k in enumerate(added_keys) if k is not None}
    return [i for i, k in enumerate(added_keys) if k is not None and k in final_keys and last[k] == i]


def diagnosis_document(study_name: str, diag: Diagnosis, runs: dict, holdout: list[str],
                       declared_holdout: bool, ident, limits=()) -> dict:
    """The document (module docstring). ``limits``: the
    :class:`~blackbox.diagnosis.effects.base.CandidateLimit` of every family that considered
    fewer candidates than the study offers (``settings.candidates_limited``, and a warning each)."""
    first = diag.steps[0].scores if diag.steps else ()
    added = []
    final = {e.key: e for e in diag.final.spec.effects}
    for i in final_additions([None if s.added is None else s.added.effect.key for s in diag.steps], final):
        s = diag.steps[i]
        e = final[s.added.effect.key]
        found = e.findings(diag.final)
        if e.kind == "case_swap" and diag.sigmas_exchanged is not None \
                and set(map(str, e.where)) == set(diag.sigmas_exchanged):
            found = {**found, "sigmas_exchanged": True,
                     "pattern_detail": found.get("pattern_detail", "") + "; their declared sigmas stayed with "
                     "the case labels, so each reading is judged by the sigma of the row it came from (the "
                     "search ran again with the two cases' sigmas exchanged, which fits better)"}
        added.append({"effect": e.kind, "where": e.where_json(), **e.details_json(), **found,
                      "of": "data" if e.of_data else "structure",
                      "parameters": e.parameters(diag.final), "step": i + 1,
                      "delta_bic": _num(s.added.delta_bic), "lr_p_value": _num(s.added.lr_p_value),
                      "variants_tried": [_trial(t) for t in s.added.variants],
                      "alternatives": alternatives(s)})
    removed = [{"effect": e.kind, "where": e.where_json(), **e.details_json(), "step": i + 1,
                "delta_bic": _num(j.delta_bic), "holdout_delta_chi2": _num(j.holdout_delta_chi2),
                "kfold_delta_chi2": _num(j.kfold_delta_chi2), "decision": j.decision}
               for i, s in enumerate(diag.steps) for e, j in s.removed]
    steps = []
    for i, s in enumerate(diag.steps):
        steps.append({
            "step": i + 1,
            "before": _stats(s.before, diag.band),
            "after": _stats(s.after, diag.band),
            "added": None if s.added is None else {"effect": s.added.effect.kind, "where": s.added.effect.where_json(),
                                                   **s.added.effect.details_json(),
                                                   "parameters": s.added.effect.parameters(s.after)},
            "candidates": [_candidate(c) for c in s.scores[:25]],
            "n_candidates": len(s.scores),
            "joint_parameters_before": _joint_params(s.before),
            "joint_parameters_after": _joint_params(s.after),
            "residual_structure_before": _trim(s.structure_before),
            "residual_structure_after": _trim(s.structure_after),
            "solver_runs": s.runs,
            "lr_level": _num(s.level),
            "lr_levels": {k: _num(v) for k, v in s.levels.items()},
            "hypotheses": s.hypotheses,
            "hypotheses_by_kind": dict(s.by_kind),
            "removed": [{"effect": e.kind, "where": e.where_json(), **e.details_json(), "decision": j.decision}
                        for e, j in s.removed],
        })
    return {
        "study": study_name,
        "before": _stats(diag.declared, diag.band),
        "candidates": [_candidate(c) for c in first],
        "added": added,
        "removed": removed,
        "after": _stats(diag.final, diag.band),
        "steps": steps,
        "stop_reason": diag.stop_reason,
        "sigma_exchange": diag.other_search,
        "joint_parameters": {"declared": _joint_params(diag.declared), "final": _joint_params(diag.final)},
        "holdout": {"cases": list(holdout), "declared_in_study": declared_holdout},
        "holdout_check": None if diag.holdout_check is None else diag.holdout_check.to_json(),
        "noise_level": None if diag.noise_level is None else diag.noise_level.to_json(),
        "validation": {"method": diag.validation.kind, "description": diag.validation.describe(),
                       **({} if diag.kfold is None else
                          {"k": diag.kfold["k"], "folds": diag.kfold["folds"],
                           "cv_chi2_before": _num(diag.kfold["cv_chi2_before"]),
                           "cv_chi2_after": _num(diag.kfold["cv_chi2_after"])})},
        "settings": {"alpha": diag.alpha,
                     "multiplicity": "alpha spending over rounds (round r spends alpha / 2^r), shared "
                                     "equally among the kinds of effect in the round and, within a kind, "
                                     "Bonferroni over its candidates and their variant upgrades; the "
                                     "*_bonferroni p-values are p x 2^r x K_r x M_kind, compared with alpha",
                     "elimination": "after each addition every earlier effect is judged again as if added "
                                    "last; one that no longer passes is removed (removed)",
                     "variants": "each accepted candidate refined through its family's richer variants "
                                 "(the same tests as a candidate, against the variant it extends)",
                     "band": "99% band of chi2(n - p) / (n - p)", "candidates_by_effect": diag.n_candidates,
                     "candidates_limited": [lim.to_json() for lim in limits]},
        "identify_check": None if ident is None else {
            "reduced_chi2": _num(ident.reduced_chi2), "converged": bool(ident.converged),
            "nesting_error_sigma": _num(diag.nesting_error)},
        "solver": runs,
        "warnings": [lim.sentence() for lim in limits] + list(diag.warnings),
        "method_wall_s": diag.wall_s,
        "verdict": diag.verdict,
        "verdict_detail": verdict_detail(diag),
        "hotspots": [_hot(h) for h in diag.hotspots.get("grids", [])],
        "hotspot_cases": [_hot(h) for h in diag.hotspots.get("cases", [])],
        "hotspot_components": [_hot(h) for h in diag.hotspots.get("components", [])],
    }


def _hot(h: dict) -> dict:
    return {k: (_num(v) if isinstance(v, float) else v) for k, v in h.items()}


def misfit_location(hot: dict, top: int = 3) -> str:
    """``grids 41 (35 %), 42 (20 %); cases L3 (...); components 2 (...)``: where the excess sits."""
    parts = []
    for kind, key, name in (("grids", "grid", "grids"), ("cases", "case", "cases"),
                            ("components", "component", "components")):
        rows = hot.get(kind, [])[:top]
        if rows:
            parts.append(f"{name} " + ", ".join(f"{h[key]} ({100 * h['share']:.0f} %)" for h in rows))
    return "; ".join(parts) or "nowhere in particular"


def verdict_detail(diag: Diagnosis) -> str:
    """One sentence for the verdict."""
    lo, hi = diag.band
    r = diag.final.reduced_chi2
    n = len(diag.added)
    hc = diag.holdout_check
    if hc is not None and not hc.predicted and r <= hi:
        return (f"the fitted cases are within the noise (reduced chi2 {r:.4g}, 99 % band {lo:.4g}..{hi:.4g}) "
                f"but the hold-out cases are not predicted: " + "; ".join(hc.sentences()))
    held = ("" if hc is None or not hc.findings else
            "; the hold-out cases hold defects of the data, not of the structure: " + "; ".join(hc.sentences()))
    if diag.verdict == "adequate":
        return f"the declared model fits within the noise (reduced chi2 {r:.4g}, 99 % band {lo:.4g}..{hi:.4g}); nothing added"
    if diag.verdict == "explained" and not diag.added:
        return (f"the declared model fits within the noise (reduced chi2 {r:.4g}, 99 % band {lo:.4g}..{hi:.4g}); "
                f"nothing added{held}")
    if diag.verdict == "explained":
        data = sum(1 for c in diag.added if c.effect.of_data)
        which = ("" if not data else " (all of them defects of the test data, not of the structure)" if data == n
                 else f" ({data} of them defects of the test data, not of the structure)")
        return (f"{n} effect(s) added{which}; the reduced chi2 is back within the noise band ({r:.4g}, 99 % band "
                f"{lo:.4g}..{hi:.4g}){held}")
    what = f"after {n} added effect(s)" if n else "and no candidate effect is supported"
    noise = ("" if diag.noise_level is None or not diag.noise_level.noise_like else
             f"; {diag.noise_level.sentence()}")
    return (f"the reduced chi2 stays at {r:.4g}, above the 99 % band {lo:.4g}..{hi:.4g}, {what}; "
            f"the misfit sits at {misfit_location(diag.hotspots)}{noise}")


def _trim(st: dict) -> dict:
    return {"per_case": st["per_case"], "per_component": st["per_component"],
            "worst_grids": st["worst_grids"], "grid_map": st["grid_map"]}
