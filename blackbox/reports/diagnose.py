"""``blackbox diagnose``'s report: ``report.md`` (before and after, the effects added, every
round's candidates and residual structure, joint parameters, solver runs) and four plots
(residual maps before and after, the first round's candidate ranking, the steps)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from blackbox.diagnosis.search import Diagnosis, hypotheses_by_kind
from blackbox.reports.plots import pyplot
from blackbox.study import Study
from solver_adapters.protocol import Deck

__all__ = ["diagnosis_report", "diagnosis_plots"]


def _g(v, digits: int = 4) -> str:
    return "n/a" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f"{v:.{digits}g}"


def _separation_lines(e: dict, x: dict) -> list[str]:
    """What would separate the added effect ``e`` from its alternative ``x`` (the two fitted
    models' structural responses; a data defect by a second sensor)."""
    where = f"{x['effect']} at {', '.join(map(str, x['where']))}"
    sep = x.get("separate_by") or {}
    lines = []
    s, ld = sep.get("sensors", []), sep.get("loads", [])
    if s:
        b = s[0]
        lines.append(f"- To separate it from {where}: a sensor at grid {b['grid']} component {b['component']} "
                     f"({'already measured' if b['measured'] else 'not measured yet'}) differs between the two "
                     f"fits by {_g(b['separation_sigma'], 3)} sigma (RMS over the load cases)"
                     + (f"; a load of {_g(ld[0]['value'], 3)} at grid {ld[0]['grid']} component "
                        f"{ld[0]['component']} would separate them by {_g(ld[0]['separation_sigma'], 3)} sigma "
                        "with the sensors in place" if ld else "") + ".")
    if e.get("of") == "data" or x.get("of") == "data":
        grids = sorted({int(w) for w in (e["where"] + x["where"]) if not isinstance(w, str)})
        if grids:
            lines.append(f"- One of the two is a defect of the data: a second, independent sensor at grid(s) "
                         f"{', '.join(map(str, grids))} (or re-zeroed, re-read channels) would tell it from the structure.")
    return lines + ([""] if lines else [])


def diagnosis_report(study: Study, doc: dict, files: list[str]) -> str:
    """``report.md`` from the ``diagnosis.json`` document; ``files``: the plots written beside it."""
    b, a = doc["before"], doc["after"]
    out = [f"# Diagnosis of {study.name}", "",
           "Declared model fitted, standardized residuals tested against the declared noise, candidate "
           "effects scored against the residual (score test), every one that could win refitted "
           "(likelihood ratio, BIC); an effect is added when its LR p-value x 2^round x the kinds of "
           f"effect x its kind's hypotheses is below {doc['settings']['alpha']:g} (alpha spending), BIC "
           "improves and it passes the check against data it was not fitted to (hold-out cases: "
           "delta BIC + hold-out chi2 change < 0 and no worse hold-out prediction than chance allows; "
           "without them: the K-fold chi2 over the load cases decreases); an accepted effect is first "
           "refined through its richer variants (per-axis, per-branch springs; a member's EA, EI1, "
           "EI2, GJ), each kept only on the same conditions; after each addition an earlier effect that "
           "no longer passes those tests is removed.", "",
           "## Before and after", "",
           "| | reduced chi2 | 99% band | RMS residual | hold-out RMS | BIC | parameters |",
           "|---|---|---|---|---|---|---|"]
    for name, s in (("declared", b), ("final", a)):
        out.append(f"| {name} | {_g(s['reduced_chi2'])} | [{_g(s['band_99'][0])}, {_g(s['band_99'][1])}] | "
                   f"{_g(s['rms_residual'])} | {_g(s['holdout_rms'])} | {_g(s['bic'], 7)} | {s['n_params']} |")
    val = doc.get("validation", {})
    out += ["", f"Hold-out cases: {', '.join(doc['holdout']['cases']) or 'none'}. "
                f"Check against data not fitted: {val.get('description', 'hold-out cases')}"
            + (f"; K-fold chi2 {_g(val['cv_chi2_before'])} -> {_g(val['cv_chi2_after'])}" if "k" in val else "")
            + ".", f"Stopped: {doc['stop_reason']}.", ""]
    ex = doc.get("sigma_exchange")
    if ex:
        a, b = ex["cases"]
        other = (f"the search with the declared sigmas (as measurements.csv labels them) added "
                 f"{', '.join(ex['added']) or 'nothing'} and ended at reduced chi2 {_g(ex['reduced_chi2'])}, "
                 f"BIC {_g(ex['bic'], 7)} ({ex['verdict']})")
        if not ex["sigmas_exchanged"]:
            out += [f"Cases {a} and {b}: their readings are exchanged, and their sigmas read as each other's fit "
                    f"better; this is the search on the data with the two cases' sigmas exchanged channel by "
                    f"channel, kept for its lower BIC: {other}.", ""]
        else:
            out += [f"Cases {a} and {b}: their readings are exchanged; the search was run again with their sigmas "
                    f"exchanged too, and ended at reduced chi2 {_g(ex['reduced_chi2'])}, BIC {_g(ex['bic'], 7)} "
                    f"({', '.join(ex['added']) or 'nothing added'}): not kept, its BIC is not lower by 2 ln 2.", ""]
    verdict = doc.get("verdict")
    if verdict is not None:
        out += ["## Verdict", "", f"**{verdict}**: {doc.get('verdict_detail', '')}.", ""]
        nl = doc.get("noise_level")
        if nl is not None:
            out += ["Is it noise larger than declared? The final residuals were tested against noise "
                    f"{_g(nl['factor'], 3)} times the declared sigma (evenly over grids, cases, components and "
                    "quarters of the declared sigmas; no gross reading; the hold-out cases predicted at that "
                    f"noise): {nl['sentence']}.", ""]
        if verdict == "unexplained":
            out += ["The model still lacks something that no candidate effect describes, or the data cannot "
                    "say which. Where the remaining misfit sits (share of the chi-square excess, "
                    "sum of z^2 - 1 over a group's rows clipped at 0):", ""]
        if doc.get("hotspots"):
            for title, key, col in (("grid", "hotspots", "grid"), ("case", "hotspot_cases", "case"),
                                    ("component", "hotspot_components", "component")):
                rows = doc.get(key, [])[:10]
                if rows:
                    out += [f"| {title} | share | rows | excess |", "|---|---|---|---|"]
                    out += [f"| {h[col]} | {_g(h['share'], 3)} | {h['n']} | {_g(h['excess'])} |" for h in rows]
                    out.append("")
    hc = doc.get("holdout_check")
    if hc is not None:
        out += ["## Hold-out cases against the final model", "",
                f"The {hc['n']} hold-out readings, never fitted, against the final model's predictions (their "
                f"noise and the fitted parameters' error): chi2 {_g(hc['chi2'])}; each case against its "
                f"Bonferroni level, each reading against |z| {_g(hc['z_limit'], 3)}, the rest against its "
                f"level (alpha {_g(hc['alpha'])} split among the three). "
                + ("They are predicted." if hc["predicted"] and not hc["findings"] else
                   "They are predicted once the defects of the data below are set aside." if hc["predicted"]
                   else "They are **not** predicted."), ""]
        out += [f"- {f}" for f in hc["findings"]]
        out += [f"- (no finding) {n}" for n in hc.get("notes", [])]
        out += ["", "| case | readings | chi2 |", "|---|---|---|"]
        out += [f"| {c} | {v['n']} | {_g(v['chi2'])} |" for c, v in hc["per_case"].items()]
        out.append("")
    if doc.get("removed"):
        out += ["## Effects removed again", "",
                "Added in an earlier round, then made unnecessary by a later addition (judged again as "
                "if added last, they no longer pass):", ""]
        out += [f"- {r['effect']} at {', '.join(map(str, r['where']))} (added in round {r['step']}): "
                f"{r['decision']}" for r in doc["removed"]]
        out.append("")
    out += ["## Effects added", ""]
    if not doc["added"]:
        out.append("None: the residuals are explained by the declared model and noise." if verdict != "unexplained"
                   else "None: no candidate effect is significant at its round's level, improves BIC and "
                        "passes the check against data it was not fitted to.")
    for i, e in enumerate(doc["added"], 1):
        extra = "".join(f", {k} {e[k]}" for k in ("component", "group", "variant", "member") if k in e)
        what = " -- the data, not the structure" if e.get("of") == "data" else ""
        out += [f"### {i}. {e['effect']} at {', '.join(map(str, e['where']))}{extra}{what}", "",
                f"delta BIC {_g(e['delta_bic'])}, LR p-value {_g(e['lr_p_value'], 3)}", ""]
        if e.get("pattern_detail"):                 # what readings set aside or exchanged look like
            out += [f"What the readings show: {e['pattern_detail']}.", ""]
        if e.get("alternatives"):
            out += ["The data hardly tell this effect from (evidence, delta BIC + hold-out chi2, within "
                    f"{_g(10.0)} of it): " + "; ".join(
                        f"{x['effect']} at {', '.join(map(str, x['where']))}"
                        f"{''.join(f', {k} {x[k]}' for k in ('variant', 'member') if k in x)} (+{_g(x['evidence_gap'])})"
                        for x in e["alternatives"]) + ".", ""]
            for x in e["alternatives"]:
                out += _separation_lines(e, x)
        out += [
                "| parameter | value | std |", "|---|---|---|"]
        out += [f"| {p['name']} | {_g(p['value'])} | {_g(p['std'], 3)} |" for p in e["parameters"]]
        out.append("")
        if e.get("variants_tried"):
            out += ["Richer variants tried:", "", "| variant | from | reduced chi2 | delta BIC | hold-out delta chi2 | "
                    "K-fold delta chi2 | decision |", "|---|---|---|---|---|---|---|"]
            out += [f"| {t['variant']} | {t['from_variant']} | {_g(t['reduced_chi2'])} | {_g(t['delta_bic'])} | "
                    f"{_g(t['holdout_delta_chi2'])} | {_g(t.get('kfold_delta_chi2'))} | {t['decision']} |"
                    for t in e["variants_tried"]]
            out.append("")
    out += ["## Steps", "", "| step | added | reduced chi2 before -> after | hold-out RMS before -> after | "
            "BIC before -> after | runs |", "|---|---|---|---|---|---|"]
    for s in doc["steps"]:
        ad = "none" if s["added"] is None else f"{s['added']['effect']} @ {', '.join(map(str, s['added']['where']))}"
        out.append(f"| {s['step']} | {ad} | {_g(s['before']['reduced_chi2'])} -> {_g(s['after']['reduced_chi2'])} | "
                   f"{_g(s['before']['holdout_rms'])} -> {_g(s['after']['holdout_rms'])} | "
                   f"{_g(s['before']['bic'], 7)} -> {_g(s['after']['bic'], 7)} | {s['solver_runs']} |")
    for s in doc["steps"]:
        out += ["", f"### Round {s['step']}: candidates (best 15 of {s['n_candidates']} by score p-value)", "",
                "| effect | where | score | df | log10 p | delta BIC | decision |", "|---|---|---|---|---|---|---|"]
        for c in s["candidates"][:15]:
            out.append(f"| {c['effect']} | {', '.join(map(str, c['where']))[:40]} | {_g(c['score'])} | {c['df']} | "
                       f"{_g(c['log10_p_value'])} | {_g(c['delta_bic'])} ({'refit' if c.get('refit') else 'score'}) | "
                       f"{c.get('decision', '')} |")
        rs = s["residual_structure_before"]
        out += ["", "Where the residual concentrated before this round (chi2/n per group; the noise gives 1):", "",
                "| grid | n | chi2/n | p |", "|---|---|---|---|"]
        out += [f"| {w['grid']} | {w['n']} | {_g(w['chi2_per_n'])} | {_g(w['p_value'], 3)} |"
                for w in rs["worst_grids"][:6]]
        out += ["", "| component | " + " | ".join(rs["per_component"]) + " |",
                "|---|" + "---|" * len(rs["per_component"]),
                "| chi2/n | " + " | ".join(_g(v["chi2_per_n"]) for v in rs["per_component"].values()) + " |"]
        cases = sorted(rs["per_case"].items(), key=lambda kv: -kv[1]["chi2_per_n"])[:6]
        out += ["", "Cases with the largest chi2/n: " + ", ".join(f"{k} {_g(v['chi2_per_n'])}" for k, v in cases)]
    out += ["", "## Joint parameters", "", "| joint | parameter | declared fit | final |", "|---|---|---|---|"]
    dj, fj = doc["joint_parameters"]["declared"], doc["joint_parameters"]["final"]
    for name, jd in dj.items():
        final = fj.get(name, {}).get("parameters", {})
        for pn, pv in jd["parameters"].items():
            out.append(f"| {name} | {pn} | {_g(pv['value'])} | {_g(final.get(pn, {}).get('value'))} |")
        if fj.get(name, {}).get("model") != jd["model"]:
            out.append(f"| {name} | (now {fj[name]['model']} model: see diagnosis.json) | | |")
    sv = doc["solver"]
    out += ["", "## Solver", "", f"{sv['runs']} runs, {sv['right_hand_sides']} right-hand sides, "
            f"{_g(sv['wall_s'], 3)} s in the solver (adapter {sv['adapter']}); whole command "
            f"{_g(doc.get('wall_s'), 3)} s.", "", "| purpose | deck | right-hand sides | wall s |", "|---|---|---|---|"]
    out += [f"| {r['purpose']} | {r['deck']} | {r['right_hand_sides']} | {_g(r['wall_s'], 3)} |" for r in sv["by_run"]]
    ic = doc.get("identify_check")
    if ic:
        out += ["", f"The split deck reproduces the declared model to {_g(ic['nesting_error_sigma'], 2)} sigma "
                f"(rigid state of {sv['split_pairs']} cut pairs, condition {_g(sv['split_condition'], 2)})."]
    if doc["warnings"]:
        out += ["", "## Warnings", ""] + [f"- {w}" for w in doc["warnings"]]
    if doc.get("notes"):
        out += ["", "## Notes", ""] + [f"- {n}" for n in doc["notes"]]
    pics = [f for f in files if f.endswith(".png")]
    if pics:
        out += ["", "## Plots", ""] + [f"![{p[:-4]}]({p})" for p in pics]
    else:
        out += ["", "(no plots: install matplotlib)"]
    return "\n".join(out) + "\n"


# --------------------------------------------------------------------------------------------
# plots
# --------------------------------------------------------------------------------------------
def diagnosis_plots(diag: Diagnosis, deck: Deck, out_dir: Path) -> list[str]:
    """The residual maps before and after, the first round's candidate ranking and the
    before/after statistics per step, as PNG files in ``out_dir`` (none without matplotlib)."""
    plt = pyplot()
    if plt is None:
        return []
    from matplotlib import colors
    written = []
    xyz = {g.id: np.array(g.xyz) for g in deck.grids.values()}
    segs = [(xyz[b.ga], xyz[b.gb]) for b in deck.cbars.values()]
    steps = diag.steps
    dofs = steps[0].structure_before if steps else None
    rms_before = {int(k): v["rms"] for k, v in (dofs["per_grid"].items() if dofs else [])}
    last = steps[-1].structure_after if steps else None
    rms_after = {int(k): v["rms"] for k, v in (last["per_grid"].items() if last else [])}
    vmax = max([1.0] + list(rms_before.values()) + list(rms_after.values()))
    norm = colors.LogNorm(vmin=0.5, vmax=max(vmax, 2.0))
    marks = [(s.added.effect.kind, s.added.effect.marker_points(xyz, deck)) for s in steps if s.added is not None]
    for name, rms, title in (("residual_map_before.png", rms_before, "declared model"),
                             ("residual_map_after.png", rms_after, "after the added effects")):
        fig = plt.figure(figsize=(8, 6.5))
        ax = fig.add_subplot(projection="3d")
        if segs:
            # one collection for every member (one line each cost minutes at 1e5 DOFs)
            from mpl_toolkits.mplot3d.art3d import Line3DCollection
            ax.add_collection3d(Line3DCollection(segs, colors="0.6", linewidths=0.8))
            ends = np.array(segs).reshape(-1, 3)
            ax.auto_scale_xyz(ends[:, 0], ends[:, 1], ends[:, 2])
        gs = [g for g in rms if g in xyz]
        if gs:
            P = np.array([xyz[g] for g in gs])
            sc = ax.scatter(P[:, 0], P[:, 1], P[:, 2], c=[max(rms[g], 0.5) for g in gs], cmap="inferno_r",
                            norm=norm, s=40, depthshade=False, edgecolors="k", linewidths=0.3)
            fig.colorbar(sc, ax=ax, shrink=0.6, label="RMS standardized residual per grid (noise = 1)")
            for g in sorted(gs, key=lambda g: -rms[g])[:5]:
                if rms[g] > 1.5:
                    ax.text(*xyz[g], f" {g}", fontsize=7)
        for kind, pts in marks:
            for p in pts:
                ax.scatter(*p, marker="*", s=220, color="tab:blue", depthshade=False)
                ax.text(*p, f"  {kind}", fontsize=7, color="tab:blue")
        span = np.ptp(np.array(list(xyz.values())), axis=0)
        ax.set_box_aspect(np.maximum(span, 0.05 * span.max()))
        ax.set_title(f"Residual map: {title}")
        fig.tight_layout()
        fig.savefig(out_dir / name, dpi=110)
        plt.close(fig)
        written.append(name)
    if steps:
        sc = [c for c in steps[0].scores if c.df > 0][:25]
        fig, ax = plt.subplots(figsize=(8, max(3.5, 0.28 * len(sc) + 1.5)))
        kinds = sorted({c.effect.kind for c in sc})
        cmap = plt.get_cmap("tab10")
        y = np.arange(len(sc))[::-1]
        # -log10 p as it is (a strong effect has thousands: capping it would draw every bar to
        # the cap), on a log axis wide enough for the longest bar and its label
        val = [max(-c.log10_p, 1e-3) if math.isfinite(c.log10_p) else 1e6 for c in sc]
        ax.barh(y, val, color=[cmap(kinds.index(c.effect.kind)) for c in sc])
        ax.set_yticks(y, [f"{c.effect.kind} @ {', '.join(map(str, c.effect.where))[:24]}" for c in sc], fontsize=7)
        n_hyp = sum(hypotheses_by_kind([c.effect for c in steps[0].scores]).values())
        thr = -math.log10(diag.alpha / (2.0 * max(n_hyp, 1)))
        ax.axvline(thr, color="k", ls="--", lw=1, label=f"round-1 level ({n_hyp} hypotheses, alpha / 2)")
        for yi, v, c in zip(y, val, sc):
            if c.refit is not None:
                ax.text(v, yi, f" dBIC {c.delta_bic:.3g}", va="center", fontsize=6, clip_on=True)
        ax.set_xscale("log")
        ax.set_xlim(min(0.5, 0.5 * min(val), 0.5 * thr), 30.0 * max(max(val), thr))
        ax.set_xlabel("-log10 p (score test)")
        ax.set_title("Candidate ranking, round 1")
        ax.legend(fontsize=7, loc="lower right")
        fig.tight_layout()
        fig.savefig(out_dir / "candidates.png", dpi=110)
        plt.close(fig)
        written.append("candidates.png")
        fits = [steps[0].before] + [s.after for s in steps if s.added is not None]
        labels = ["declared"] + [s.added.effect.kind for s in steps if s.added is not None]
        fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.5))
        a1.semilogy(range(len(fits)), [f.reduced_chi2 for f in fits], "o-")
        lo, hi = diag.band
        a1.axhspan(lo, hi, color="0.85", label="99% band")
        a1.set_xticks(range(len(fits)), labels, rotation=20, fontsize=7)
        a1.set_ylabel("reduced chi2")
        a1.legend(fontsize=7)
        if all(f.holdout_rms is not None for f in fits):
            a2.semilogy(range(len(fits)), [f.holdout_rms for f in fits], "o-", color="tab:orange")
        a2.set_xticks(range(len(fits)), labels, rotation=20, fontsize=7)
        a2.set_ylabel("hold-out RMS prediction error")
        fig.tight_layout()
        fig.savefig(out_dir / "steps.png", dpi=110)
        plt.close(fig)
        written.append("steps.png")
    return written
