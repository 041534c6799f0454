"""``blackbox identify``'s report: an lmfit-style Markdown fit report and three plots."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from blackbox.reports.plots import MAX_COLUMNS, pyplot

__all__ = ["fit_report", "identification_plots", "residual_plot"]


def _g(v: float, digits: int = 5) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "n/a"
    return f"{v:.{digits}g}"


def fit_report(result, *, title: str = "Identification", solver: dict | None = None,
               truth: dict[str, float] | None = None, min_correl: float = 0.1) -> str:
    """Markdown report of an :class:`~blackbox.identification.IdentificationResult`."""
    r = result
    out = [f"# {title}", "", "## [[Fit Statistics]]", "",
           "| statistic | value |", "|---|---|",
           f"| converged | {r.converged} ({r.message}) |",
           f"| iterations | {r.iterations} (fixed point {r.n_fixed_point}, Newton {r.n_newton}) |",
           f"| data points | {r.n_obs} |", f"| variables | {r.n_params} |",
           f"| chi-square | {_g(r.chi2)} |", f"| reduced chi-square | {_g(r.reduced_chi2)} |",
           f"| RMS residual | {_g(r.rms_residual)} |",
           f"| Akaike info crit | {_g(r.aic)} |", f"| Bayesian info crit | {_g(r.bic)} |"]
    if r.holdout is not None:
        out += [f"| hold-out cases | {', '.join(r.holdout.cases)} |",
                f"| hold-out RMS prediction error | {_g(r.holdout.rms_error)} |",
                f"| hold-out chi-square / n | {_g(r.holdout.chi2 / max(r.holdout.n_obs, 1))} |"]
    if solver:
        out += [f"| solver runs | {solver.get('runs')} ({solver.get('right_hand_sides')} right-hand sides, "
                f"{_g(solver.get('wall_s', float('nan')), 3)} s, adapter {solver.get('adapter')}) |"]
    pct = f"{100 * r.confidence:g}"
    out += ["", "## [[Variables]]", "",
            f"| joint | parameter | value | std | {pct}% low | {pct}% high | +- % |"
            + (" truth | in interval |" if truth else ""),
            "|---|---|---|---|---|---|---|" + ("---|---|" if truth else "")]
    for i in range(r.n_params):
        name = r.param_names[i]
        rel = 100 * r.std[i] / abs(r.k[i]) if r.identifiable[i] and r.k[i] != 0 else float("nan")
        row = (f"| {r.param_joint[i]} | {name} | {_g(r.k[i])} | {_g(r.std[i], 3)} | "
               f"{_g(r.ci_low[i])} | {_g(r.ci_high[i])} | {_g(rel, 3)} |")
        if truth:
            t = truth.get(f"{r.param_joint[i]}.{name}")
            inside = t is not None and r.ci_low[i] <= t <= r.ci_high[i]
            row += f" {_g(t) if t is not None else ''} | {'yes' if inside else 'NO'} |"
        out.append(row)
    if not np.all(r.identifiable):
        out += ["", "Uncertainties could not be estimated for: "
                + ", ".join(n for n, ok in zip(r.param_names, r.identifiable) if not ok)
                + " (not identifiable from these data)."]
    out += ["", f"Intervals: {r.ci_method}; covariance scale {_g(r.covariance_scale, 3)}."]
    if r.profile_ci is not None or r.bootstrap_ci is not None:
        out += ["", "| parameter | linearised | profile likelihood | bootstrap |", "|---|---|---|---|"]
        for i in range(r.n_params):
            pc = r.profile_ci[i] if r.profile_ci is not None else (float("nan"),) * 2
            bc = r.bootstrap_ci[i] if r.bootstrap_ci is not None else (float("nan"),) * 2
            lc = r.linear_ci[i]
            out.append(f"| {r.param_names[i]} | [{_g(lc[0])}, {_g(lc[1])}] | "
                       f"[{_g(pc[0])}, {_g(pc[1])}] | [{_g(bc[0])}, {_g(bc[1])}] |")
    out += ["", "## [[Correlations]] (unreported correlations are < "
            f"{min_correl})", ""]
    pairs = []
    C = r.correlation
    for i in range(r.n_params):
        for j in range(i + 1, r.n_params):
            if np.isfinite(C[i, j]) and abs(C[i, j]) >= min_correl:
                pairs.append((abs(C[i, j]), r.param_names[i], r.param_names[j], C[i, j]))
    for _, a, b, c in sorted(pairs, reverse=True)[:30]:
        out.append(f"- C({a}, {b}) = {c:+.3f}")
    if not pairs:
        out.append("- none")
    if r.warnings:
        out += ["", "## Warnings", ""] + [f"- {w}" for w in r.warnings]
    return "\n".join(out) + "\n"


def identification_plots(result, obs, out_dir: Path, *, truth: dict[str, float] | None = None) -> list[str]:
    """Convergence (Figs. 5.3-5.5), estimates with intervals (Table 5.2 as a figure) and
    standardized residuals per case and DOF. Returns the file names written."""
    plt = pyplot()
    if plt is None:
        return []
    r = result
    written = []
    hist = r.history
    its = [h.iteration for h in hist]
    K = np.array([h.k for h in hist])
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4))
    for i in range(r.n_params):
        a1.plot(its, K[:, i] / (r.k[i] if r.k[i] != 0 else 1.0), marker="o", ms=3, lw=1,
                label=r.param_names[i] if r.n_params <= 12 else None)
    a1.set_xlabel("iteration")
    a1.set_ylabel("parameter / final estimate")
    a1.set_yscale("symlog", linthresh=1e-2)
    a1.set_title("parameters per iteration")
    if r.n_params <= 12:
        a1.legend(fontsize=7, ncol=2)
    fp = [h.iteration for h in hist if h.phase == "fixed-point"]
    if fp:
        a1.axvspan(min(fp) - 0.5, max(fp) + 0.5, color="0.9", label="fixed point")
        a2.axvspan(min(fp) - 0.5, max(fp) + 0.5, color="0.9")
    a2.semilogy(its, [h.objective for h in hist], marker="o")
    a2.set_xlabel("iteration")
    a2.set_ylabel("chi-square")
    a2.set_title("objective (shaded: fixed-point phase)")
    fig.tight_layout()
    fig.savefig(out_dir / "convergence.png", dpi=110)
    plt.close(fig)
    written.append("convergence.png")

    fig, ax = plt.subplots(figsize=(max(6, 0.45 * r.n_params + 2), 4))
    x = np.arange(r.n_params)
    ok = r.identifiable
    lo = np.where(ok, r.k - r.ci_low, 0)
    hi = np.where(ok, r.ci_high - r.k, 0)
    ax.errorbar(x[ok], r.k[ok], yerr=[lo[ok], hi[ok]], fmt="o", capsize=3, label=f"estimate, {100 * r.confidence:g}% interval")
    if np.any(~ok):
        ax.plot(x[~ok], r.k[~ok], "x", color="red", label="not identifiable")
    if truth:
        tv = [truth.get(f"{j}.{n}", np.nan) for j, n in zip(r.param_joint, r.param_names)]
        ax.plot(x, tv, "_", ms=18, color="k", label="truth")
    ax.set_xticks(x, r.param_names, rotation=60, fontsize=8)
    if np.all(r.k > 0):
        ax.set_yscale("log")
    else:
        ax.set_yscale("symlog", linthresh=max(1.0, float(np.min(np.abs(r.k[r.k != 0]), initial=1.0))))
    ax.set_ylabel("stiffness (N*m/rad)")
    ax.legend(fontsize=8)
    ax.set_title("estimates with confidence intervals")
    fig.tight_layout()
    fig.savefig(out_dir / "estimates.png", dpi=110)
    plt.close(fig)
    written.append("estimates.png")

    written.append(residual_plot(plt, r.residuals, obs, out_dir / "residuals.png"))
    return written


def residual_plot(plt, z: np.ndarray, obs, path: Path) -> str:
    """Standardized residuals per load case and measured DOF: a map when it fits on a page
    (:data:`MAX_COLUMNS` cases and rows at most), else RMS per case and the DOFs with the largest
    RMS. Linear in the number of rows."""
    labels = np.array([f"{g}:{c}" for g, c in obs.dofs])
    dof_names, dof_idx = np.unique(labels, return_inverse=True)
    order = {n: i for i, n in enumerate(dict.fromkeys(labels.tolist()))}      # first appearance
    perm = np.array([order[n] for n in dof_names])
    dof_idx = perm[dof_idx]
    dof_names = list(order)
    ci = np.asarray(obs.case_index)
    uc, case_idx = np.unique(ci, return_inverse=True)
    names = [obs.case_labels[c] if c < len(obs.case_labels) else str(c) for c in uc]
    z = np.asarray(z, float)
    if len(uc) <= MAX_COLUMNS and len(dof_names) <= 2 * MAX_COLUMNS:
        grid = np.full((len(dof_names), len(uc)), np.nan)
        grid[dof_idx, case_idx] = z
        fig, ax = plt.subplots(figsize=(max(6, 0.35 * len(uc) + 3), max(4, 0.18 * len(dof_names) + 1.5)))
        lim = max(3.0, float(np.nanmax(np.abs(grid))) if np.isfinite(grid).any() else 3.0)
        im = ax.imshow(grid, aspect="auto", cmap="RdBu_r", vmin=-lim, vmax=lim, interpolation="nearest")
        ax.set_yticks(range(len(dof_names)), dof_names, fontsize=6)
        ax.set_xticks(range(len(uc)), names, rotation=90, fontsize=7)
        ax.set_xlabel("load case")
        ax.set_ylabel("grid:component")
        fig.colorbar(im, ax=ax, label="standardized residual (measured - predicted) / sigma")
        ax.set_title("standardized residuals")
    else:
        n_case = np.bincount(case_idx, minlength=len(uc))
        rms_case = np.sqrt(np.bincount(case_idx, z * z, minlength=len(uc)) / np.maximum(n_case, 1))
        n_dof = np.bincount(dof_idx, minlength=len(dof_names))
        rms_dof = np.sqrt(np.bincount(dof_idx, z * z, minlength=len(dof_names)) / np.maximum(n_dof, 1))
        top = np.argsort(rms_dof)[::-1][:30]
        fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 4.5))
        a1.plot(np.arange(len(uc)), rms_case, lw=0.8)
        a1.axhline(1.0, color="k", ls="--", lw=0.8)
        a1.set_xlabel(f"load case (1..{len(uc)}, in file order)")
        a1.set_ylabel("RMS standardized residual")
        a1.set_title(f"per case ({len(uc)} cases; 1 = within the declared noise)")
        a2.bar(range(len(top)), rms_dof[top])
        a2.axhline(1.0, color="k", ls="--", lw=0.8)
        a2.set_xticks(range(len(top)), [dof_names[i] for i in top], rotation=90, fontsize=7)
        a2.set_ylabel("RMS standardized residual")
        a2.set_title(f"the {len(top)} DOFs with the largest RMS (of {len(dof_names)})")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path.name
