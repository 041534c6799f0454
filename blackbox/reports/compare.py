"""``blackbox compare``'s report: Markdown beside the dissertation's Tables 6.1-6.14, and bar
plots like Figures 6.2-6.5."""

from __future__ import annotations

import math
from pathlib import Path
import numpy as np

from blackbox import comparison as cmp
from blackbox.comparison import Stage
from blackbox.joints import SimpleJoint, simple_to_complex_params
from blackbox.reports.plots import pyplot

__all__ = ["comparison_report", "comparison_plots"]


# --------------------------------------------------------------------------------------------
# report and plots
# --------------------------------------------------------------------------------------------
def _e(v, d: int = 4) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "n/a"
    return f"{v:.{d}e}"


def _energy_table(m: cmp.MDSE, assembly: bool, unc: dict | None = None) -> list[str]:
    keys = [k for k in ("complex", "simple", "infinitely_flexible", "truth") if k in m.energies]
    t = m.truth_difference is not None
    out = ["| " + " | ".join(f"E_{k}" for k in keys) + " | R = (E_complex - E_simple)/E_complex |"
           + (" (E_truth - E_simple)/E_truth |" if t else "")
           + (" simple error / infinitely-flexible error |" if assembly else ""),
           "|" + "---|" * (len(keys) + 1 + t + assembly)]
    iv = ""
    if unc:
        lo, hi = unc["relative_difference_interval"]
        iv = f" [{100 * lo:.1f}, {100 * hi:.1f}]"
    row = "| " + " | ".join(_e(m.energies[k]) for k in keys) + f" | {100 * m.relative_difference:.2f} %{iv} |"
    if t:
        row += f" {100 * m.truth_difference:.2f} % |"
    if assembly:
        row += f" {100 * m.error_ratio():.1f} % |"
    return out + [row]


def _unc_note(u: dict | None) -> str:
    if not u:
        return ("No interval for R: a parameter is not identifiable, so the fitted energies are "
                "not bounded by these data.")
    return (f"R's interval: {100 * u['confidence']:g} % of R over {u['draws']} draws of both fits from "
            "their covariances, at this loading. R of *fitted* models contains their estimation "
            "error: a wide interval means the data do not yet separate coupling from noise.")


def _load_table(m: cmp.MDSE) -> list[str]:
    keys = list(m.displacements)
    out = ["| DOF | MDSE load | " + " | ".join(f"u ({k})" for k in keys) + " |", "|---|---|" + "---|" * len(keys)]
    for i, n in enumerate(m.names):
        mark = " **(dominant)**" if i == m.dominant else ""
        out.append(f"| {n} {m.dofs[i]} | {m.load[i]:+.4f}{mark} | "
                   + " | ".join(_e(m.displacements[k][i]) for k in keys) + " |")
    return out


def _params_table(stage: Stage, complex_j, simple_j, truth: dict | None, title: str) -> list[str]:
    f = stage.fits
    out = [title, ""] if title else []
    i_c = i_s = 0
    for cj, sj in zip(complex_j, simple_j):
        kc = f.complex.k[i_c:i_c + cj.n_params]
        lo, hi = f.complex.ci_low[i_c:i_c + cj.n_params], f.complex.ci_high[i_c:i_c + cj.n_params]
        ks = f.simple.k[i_s:i_s + sj.n_params]
        i_c += cj.n_params
        i_s += sj.n_params
        kcs = (simple_to_complex_params(sj, ks) if isinstance(sj, SimpleJoint)
               else cmp.clamped_stiffness(sj, ks)[np.triu_indices(3 * sj.n_branches - 3)])
        tv = truth.get(cj.name, {}) if truth else {}
        pct = f"{100 * f.complex.confidence:g}%"
        out += [f"Joint `{cj.name}`: K_C entries (branch {cj.n_branches} clamped), N*m/rad.", "",
                "| parameter | actual (truth) | complex estimate | " + pct + " interval | simple model (its K_C) |",
                "|---|---|---|---|---|"]
        for n, v, a, b, s in zip(cj.param_names, kc, lo, hi, kcs):
            t = _e(tv[n]) if n in tv else ""
            out.append(f"| {n} | {t} | {_e(v)} | [{_e(a, 3)}, {_e(b, 3)}] | {_e(s)} |")
        ls, hs = f.simple.ci_low[i_s - sj.n_params:i_s], f.simple.ci_high[i_s - sj.n_params:i_s]
        out += ["", "Simple-model springs: " + ", ".join(
            f"{n} = {_e(v, 3)} [{_e(a, 2)}, {_e(b, 2)}]" for n, v, a, b in zip(sj.param_names, ks, ls, hs)), ""]
    return out


def _fit_table(stage: Stage) -> list[str]:
    f = stage.fits
    out = ["| model | parameters | converged | reduced chi2 | BIC | RMS residual | hold-out RMS error | "
           "hold-out chi2 / n |", "|---|---|---|---|---|---|---|---|"]
    for name, r in (("simple", f.simple), ("complex", f.complex)):
        h = (f"{_e(r.holdout.rms_error, 3)} | {r.holdout.chi2 / max(r.holdout.n_obs, 1):.4g}" if r.holdout
             else "no hold-out cases | ")
        out.append(f"| {name} | {r.n_params} | {r.converged} | {r.reduced_chi2:.4g} | {r.bic:.6g} | "
                   f"{_e(r.rms_residual, 3)} | {h} |")
    lr = cmp.likelihood_ratio(f)
    out += ["", f"BIC prefers the **{lr['preferred_by_bic']}** model (delta BIC complex - simple = "
            f"{lr['delta_bic']:.4g}); likelihood ratio chi2_simple - chi2_complex = {lr['statistic']:.4g} "
            f"on {lr['dof']} degrees of freedom, p = {lr['p_value']:.3g} (approximate: springs at 0 "
            f"are on a bound). The complex fit started from the {f.complex_start}."]
    warn = [f"- {m}: {w}" for m, r in (("simple", f.simple), ("complex", f.complex)) for w in r.warnings]
    return out + ([""] + warn if warn else [])


def _stage_sections(stage: Stage, label: str, tables: dict[str, str]) -> list[str]:
    out = []
    for jc, unc in zip(stage.joints, stage.uncertainty):
        iso, asm = jc.isolated, jc.assembly
        out += [f"### Joint `{jc.name}` ({jc.n_branches} branches)", "",
                f"#### MDSE loading, isolated joint ({tables['load']})", "",
                f"Branch {jc.n_branches} clamped; largest eigenvalue of C_complex - C_simple = "
                f"{_e(float(iso.eigenvalues[0]))} rad/(N*m) (next {_e(float(iso.eigenvalues[1]))}). Dominant "
                f"DOF: **{iso.names[iso.dominant]}** ({100 * iso.dominant_share:.1f} % of the squared load).", "",
                *_load_table(iso), "",
                f"#### Strain energy, isolated joint ({tables['energy']})", "",
                *_energy_table(iso, False, unc["isolated"]), "", _unc_note(unc["isolated"]), "",
                f"#### Joint in the structure: MDSE loading, energies and displacements ({tables['assembly']})", "",
                f"Moments at the joint's rotation DOFs; joint `{jc.name}` simple, complex, or infinitely "
                f"flexible (K_J = 0), any other joint at its complex estimate. Dominant DOF: "
                f"**{asm.names[asm.dominant]}** ({100 * asm.dominant_share:.1f} %).", "",
                *_energy_table(asm, True, unc["assembly"]), "", *_load_table(asm), ""]
    if stage.fixed_load is not None:
        out += [f"#### Under the first MDSE loadings ({label})", ""]
        for jc in stage.fixed_load:
            out += [f"Joint `{jc.name}`, isolated:", "", *_energy_table(jc.isolated, False), "",
                    f"Joint `{jc.name}`, in the structure:", "", *_energy_table(jc.assembly, True), ""]
    return out


def comparison_report(result: dict, first: Stage, second: Stage | None, complex_j, simple_j,
                      plots: list[str]) -> str:
    s = result["solver"]
    truth = result.get("truth")
    out = [f"# Comparison of joint models: {result['study']} (Chapter 6)", "",
           f"Both models identified from the same {first.n_measurements} measurements on one "
           f"condensation ({s['runs']} solver run, {s['right_hand_sides']} right-hand sides, adapter "
           f"{s['adapter']}). Energies are E = 1/2 F^T C F (eq. 35); the dissertation's tables list "
           "F^T C F = 2E. Units: N, m, rad.", "",
           "## Identified parameters (Table 6.1 / 6.8)", "",
           *_params_table(first, complex_j, simple_j, truth, ""),
           "## Fit statistics", "", *_fit_table(first), "",
           "## Comparison under the MDSE loading", "",
           *_stage_sections(first, "", {"load": "Table 6.2 / 6.9", "energy": "Table 6.3 / 6.10",
                                        "assembly": "Tables 6.4-6.5 / 6.11-6.12, Figure 6.2 / 6.4"})]
    if "energy_isolated.png" in plots:
        out += ["![isolated joint energies](energy_isolated.png)", "", "![assembly energies](energy_assembly.png)", ""]
    w = result["with_mdse"]
    out += ["## The MDSE loading as an additional load case (the 11-case study)", ""]
    if not w["available"]:
        out += [w["recommendation"] + ".", "", "```", Path(result["study_dir"]).name + " -> mdse_loads.csv:",
                *(f"{c['case']},{g},{cc},{v!r}" for c in result["mdse_load_case"]["cases"] for g, cc, v in c["rows"]),
                "```", ""]
    else:
        ch = w["parameter_changes"]
        scales = ", ".join(f"{c['scale']:g}" for c in result["mdse_load_case"]["cases"])
        out += [f"Case(s) {w['cases']} (the assembly MDSE loading times {scales}: its largest joint rotation "
                f"equals the largest of the study's cases) simulated from the same truth (seed {w['seed']}, "
                f"{w['simulation_solver_runs']} solver run for the simulation; the re-identification used "
                f"{w['identification_solver_runs']} more: the new case is a boundary load, added by "
                f"superposition) into `with_mdse/`.", "",
                *_params_table(second, complex_j, simple_j, truth,
                               "### Parameters with the MDSE case (Table 6.6 / 6.13)"),
                "Parameter changes (dissertation: < 2 % cube, < 3 % car): "
                + "; ".join(f"{m}: max {ch[m]['max_abs_change_percent']:.3g} %, median "
                            f"{ch[m]['median_abs_change_percent']:.3g} % of each value, max "
                            f"{ch[m]['max_change_percent_of_largest_diagonal']:.3g} % of the largest diagonal"
                            for m in ("simple", "complex")), "",
                "### Fit statistics with the MDSE case", "", *_fit_table(second), "",
                *_stage_sections(second, "Table 6.7 / 6.14 with the loading of Table 6.2",
                                 {"load": "recomputed", "energy": "Table 6.7 / 6.14",
                                  "assembly": "Figure 6.3 / 6.5"})]
        if "energy_isolated_mdse.png" in plots:
            out += ["![isolated joint energies, with MDSE](energy_isolated_mdse.png)", "",
                    "![assembly energies, with MDSE](energy_assembly_mdse.png)", ""]
    if not plots:
        out += ["(No plots: install matplotlib, `pip install 'blackbox-joints[plots]'`.)", ""]
    return "\n".join(out) + "\n"


def _energy_bars(plt, comps: list[cmp.JointComparison], unc: list[dict], which: str, path: Path,
                 title: str) -> None:
    keys = ["complex", "simple"] + (["infinitely_flexible"] if which == "assembly" else []) + \
        (["truth"] if "truth" in getattr(comps[0], which).energies else [])
    colors = {"complex": "tab:blue", "simple": "tab:orange", "infinitely_flexible": "0.6", "truth": "k"}
    fig, axes = plt.subplots(1, len(comps), figsize=(3.2 + 1.1 * len(keys), 3.8) if len(comps) == 1
                             else (2.6 * len(comps) + 2, 3.8), squeeze=False)
    for ax, jc, u in zip(axes[0], comps, unc):
        m = getattr(jc, which)
        vals = [m.energies[k] for k in keys]
        lo_hi = (u.get(which) or {}).get("energy_interval", {})
        err = energy_error_bars(vals, [lo_hi.get(k) for k in keys])
        bars = ax.bar(range(len(keys)), vals, color=[colors[k] for k in keys], yerr=err, capsize=4,
                      error_kw={"elinewidth": 1})
        top = max(vals) * 3.0 if max(vals) > 0 else 1.0
        if np.any(np.asarray(vals) + err[1] > top):
            ax.set_ylim(0.0, top)                  # an interval far above the bars is cut, and said
            ax.text(0.02, 0.97, "interval cut at 3x the largest bar", transform=ax.transAxes,
                    fontsize=7, va="top")
        for b, v in zip(bars, vals):
            ax.annotate(f"{v:.3g}", (b.get_x() + b.get_width() / 2, v), ha="center", va="bottom", fontsize=8)
        ax.set_xticks(range(len(keys)), [k.replace("infinitely_flexible", "infinitely\nflexible") for k in keys],
                      fontsize=8)
        sub = f"R = {100 * m.relative_difference:.1f} %"
        if which == "assembly":
            sub += f", simple err / inf.-flex. err = {100 * m.error_ratio():.2g} %"
        ax.set_title(f"{jc.name}: {sub}\nMDSE load mostly {m.names[m.dominant]}", fontsize=9)
        ax.set_ylabel("strain energy 1/2 F^T C F (N*m)\nbars: interval from the fits' covariances", fontsize=8)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def energy_error_bars(values, intervals) -> np.ndarray:
    """Asymmetric error bars ``(2, n)`` from each bar's interval ``[low, high]`` of the energies
    drawn from the fits' covariances (``None``: no bar). The interval, not +-1 std, because the
    energy of a weakly determined joint has a long tail towards the flexible side: a symmetric
    bar of its std reaches far below zero and says nothing about the likely values."""
    err = np.zeros((2, len(values)))
    for i, (v, iv) in enumerate(zip(values, intervals)):
        if iv is None or not np.all(np.isfinite(iv)):
            continue
        err[0, i] = max(v - float(iv[0]), 0.0)
        err[1, i] = max(float(iv[1]) - v, 0.0)
    return err


def comparison_plots(first: Stage, second: Stage | None, out: Path) -> list[str]:
    """Bar plots like Figures 6.2-6.5 (returns the file names; none without matplotlib)."""
    plt = pyplot()
    if plt is None:
        return []
    written = []
    for stage, suffix, tag in ((first, "", ""), (second, "_mdse", " (with the MDSE case)")):
        if stage is None:
            continue
        _energy_bars(plt, stage.joints, stage.uncertainty, "isolated", out / f"energy_isolated{suffix}.png",
                     f"Isolated joint under its MDSE loading (Table {'6.7 / 6.14' if suffix else '6.3 / 6.10'}){tag}")
        _energy_bars(plt, stage.joints, stage.uncertainty, "assembly", out / f"energy_assembly{suffix}.png",
                     "Joint in the structure under its MDSE loading "
                     f"(Figure {'6.3 / 6.5' if suffix else '6.2 / 6.4'}){tag}")
        written += [f"energy_isolated{suffix}.png", f"energy_assembly{suffix}.png"]
    return written
