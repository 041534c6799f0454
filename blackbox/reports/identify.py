"""``blackbox identify``'s report: an lmfit-style Markdown fit report and three plots."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from blackbox.reports import raster
from blackbox.reports.plots import MAX_COLUMNS

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
    standardized residuals per case and DOF, drawn with :mod:`blackbox.reports.raster` (a few
    milliseconds each: identify's fixed cost stays small). Returns the file names written."""
    if not raster.available():
        return []
    r = result
    written = []
    hist = r.history
    its = np.array([h.iteration for h in hist], float)
    K = np.array([h.k for h in hist]).reshape(len(hist), r.n_params)
    ratio = K / np.where(r.k != 0, r.k, 1.0)
    fig = raster.Figure(1210, 440)
    a1, a2 = fig.panels(2)
    positive = bool(np.all(ratio[np.isfinite(ratio)] > 0))
    a1.limits(its, ratio, ylog=positive)
    a2.limits(its, [h.objective for h in hist], ylog=True)
    fp = [h.iteration for h in hist if h.phase == "fixed-point"]
    if fp:
        for ax in (a1, a2):
            ax.vspan(min(fp) - 0.5, max(fp) + 0.5)
    for i in range(r.n_params):
        color = raster.PALETTE[i % len(raster.PALETTE)]
        label = r.param_names[i] if r.n_params <= 12 else None
        a1.line(its, ratio[:, i], color=color, label=label)
        a1.points(its, ratio[:, i], color=color, size=2)
    a1.title, a1.xlabel, a1.ylabel = "parameters per iteration", "iteration", "parameter / final estimate"
    obj = [h.objective for h in hist]
    a2.line(its, obj)
    a2.points(its, obj)
    a2.title, a2.xlabel, a2.ylabel = "objective (shaded: fixed-point phase)", "iteration", "chi-square"
    for ax in (a1, a2):
        ax.xticks(list(its), [str(int(i)) for i in its]) if len(its) <= 20 else None
    written.append(fig.save(out_dir / "convergence.png"))

    x = np.arange(r.n_params, dtype=float)
    ok = np.asarray(r.identifiable, bool)
    fig = raster.Figure(int(max(660, 50 * r.n_params + 220)), 480)
    (ax,) = fig.panels(1, bottom=110)
    positive = bool(np.all(r.k > 0))
    vals = [r.k, np.where(ok, r.ci_low, np.nan), np.where(ok, r.ci_high, np.nan)]
    tv = None
    if truth:
        tv = np.array([truth.get(f"{j}.{n}", np.nan) for j, n in zip(r.param_joint, r.param_names)], float)
        vals.append(tv)
    ax.limits(np.r_[x, -0.6, r.n_params - 0.4], np.concatenate(vals), ylog=positive, pad=0.08)
    ax.errorbars(x[ok], np.asarray(r.ci_low)[ok], np.asarray(r.ci_high)[ok])
    ax.points(x[ok], r.k[ok], label=f"estimate, {100 * r.confidence:g}% interval")
    if np.any(~ok):
        ax.points(x[~ok], r.k[~ok], color="#d62728", marker="x", size=5, label="not identifiable")
    if tv is not None:
        ax.points(x, tv, color="#000000", marker="_", size=5, label="truth")
    ax.xticks(list(x), list(r.param_names), vertical=True)
    ax.title, ax.ylabel = "estimates with confidence intervals", "stiffness (N*m/rad)"
    written.append(fig.save(out_dir / "estimates.png"))

    written.append(residual_plot(r.residuals, obs, out_dir / "residuals.png"))
    return written


def residual_plot(z: np.ndarray, obs, path: Path) -> str:
    """Standardized residuals per load case and measured DOF: a map when it fits on a page
    (:data:`MAX_COLUMNS` cases and rows at most), else RMS per case and the DOFs with the largest
    RMS. Linear in the number of rows. Drawn with :mod:`blackbox.reports.raster`."""
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
        lim = max(3.0, float(np.nanmax(np.abs(grid))) if np.isfinite(grid).any() else 3.0)
        fig = raster.Figure(int(max(660, 30 * len(uc) + 330)), int(max(440, 13 * len(dof_names) + 190)))
        ax = fig.add_axes(100, 34, fig.width - 190, fig.height - 110)
        ax.xlim, ax.ylim = (-0.5, len(uc) - 0.5), (len(dof_names) - 0.5, -0.5)
        ax.image(raster.diverging(grid, lim))
        ax.xticks(list(range(len(uc))), names, vertical=True)
        ax.yticks(list(range(len(dof_names))), dof_names)
        ax.title, ax.xlabel, ax.ylabel = "standardized residuals", "load case", "grid:component"
        # the colour bar: -lim .. lim
        bar = fig.add_axes(fig.width - 150, 34, fig.width - 130, fig.height - 110)
        bar.xlim, bar.ylim = (0.0, 1.0), (-lim, lim)
        bar.image(raster.diverging(np.linspace(lim, -lim, 200)[:, None], lim))
        bar.xticks([], [])
        bar.ylabel = ""
        bar.title = "(measured - predicted) / sigma"
        ticks = [-lim, -3.0, 0.0, 3.0, lim] if lim > 3.6 else [-3.0, 0.0, 3.0]
        bar.yticks(ticks, [f"{v:.3g}" for v in ticks])
    else:
        n_case = np.bincount(case_idx, minlength=len(uc))
        rms_case = np.sqrt(np.bincount(case_idx, z * z, minlength=len(uc)) / np.maximum(n_case, 1))
        n_dof = np.bincount(dof_idx, minlength=len(dof_names))
        rms_dof = np.sqrt(np.bincount(dof_idx, z * z, minlength=len(dof_names)) / np.maximum(n_dof, 1))
        top = np.argsort(rms_dof)[::-1][:30]
        fig = raster.Figure(1320, 500)
        a1, a2 = fig.panels(2, bottom=110)
        xc = np.arange(len(uc), dtype=float)
        a1.limits(xc, np.r_[rms_case, 0.0, 1.0])
        a1.hline(1.0)
        a1.line(xc, rms_case, width=1)
        a1.title = f"per case ({len(uc)} cases; 1 = within the declared noise)"
        a1.xlabel, a1.ylabel = f"load case (1..{len(uc)}, in file order)", "RMS standardized residual"
        xt = np.arange(len(top), dtype=float)
        a2.limits(np.r_[xt, -0.6, len(top) - 0.4], np.r_[rms_dof[top], 0.0, 1.0], pad=0.03)
        a2.bars(xt, rms_dof[top])
        a2.hline(1.0)
        a2.xticks(list(xt), [dof_names[i] for i in top], vertical=True)
        a2.title = f"the {len(top)} DOFs with the largest RMS (of {len(dof_names)})"
        a2.ylabel = "RMS standardized residual"
    return fig.save(path)