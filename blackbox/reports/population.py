"""``blackbox population``: the report (``report.md``) and its plots.

* ``specimens.png``: one panel per parameter: every specimen's own interval (its data alone, grey)
  and its interval shrunk toward the population (blue, the dot its estimate), over the
  population's centre (line), the centre's interval (dark band) and the range where 95 % of the
  specimens of the population lie (``centre x exp(+-1.96 tau)``, light band); a specimen named as
  an outlier is red, one whose data say nothing about the parameter is a hollow marker.
* ``spread.png``: the spread (coefficient of variation) of every parameter with its interval.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from blackbox.reports.plots import pyplot

__all__ = ["population_markdown", "population_plots"]


def _g(v, spec: str = ".4g") -> str:
    if v is None:
        return "-"
    v = float(v)
    if math.isinf(v):
        return "inf" if v > 0 else "-inf"
    return format(v, spec) if math.isfinite(v) else "-"


def _pct(v) -> str:
    if v is None:
        return "-"
    v = float(v)
    if math.isinf(v):
        return "unbounded"
    return f"{100.0 * v:.3g} %" if math.isfinite(v) else "-"


def population_markdown(result, doc: dict, plots: list[str]) -> str:
    """The report: what was pooled, the population per parameter, the test of whether the
    specimens differ, named outliers, each specimen's estimates, what is not determined, method."""
    f = result.fit
    S = len(result.outcomes)
    sol = doc["solver"]
    lines = [f"# Population of {S} specimens", "",
             f"- specimens: {', '.join(result.names)}",
             f"- solver: {sol['runs']} run(s) for {S} specimens"
             + (f" (+ {sol['cached_batches']} from the cache)" if sol["cached_batches"] else "")
             + f", {sol['right_hand_sides']} right-hand sides, adapter {sol['adapter']}; every further "
               "evaluation in the specimens' condensed models",
             f"- wall time: {result.wall_s:.2f} s (specimens {result.specimen_wall_s:.2f} s on {result.executor}; "
             f"population fit {result.population_wall_s:.2f} s)",
             f"- intervals at {100 * f.confidence:g} %", ""]
    lines += ["## Population", "",
              "centre = median of the specimens' stiffness; spread = between-specimen coefficient of "
              "variation (log-normal population).", "",
              "| joint | parameter | centre | centre interval | spread | spread interval | specimens | "
              "specimens share one value (p) |", "|---|---|---|---|---|---|---|---|"]
    for p in doc["parameters"]:
        lo, hi = p["center_ci_low"], p["center_ci_high"]
        lines.append(f"| {p['joint']} | {p['name']} | {_g(p['center'])} | [{_g(lo)}, {_g(hi if hi is not None else math.inf)}] | "
                     f"{_pct(p['spread'])} | [{_pct(p['spread_ci_low'])}, "
                     f"{_pct(p['spread_ci_high']) if p['spread_ci_high'] is not None else 'unbounded'}] | "
                     f"{p['n_specimens']} of {S} | {_g(p['specimens_share_value']['p_value'], '.2g')} |")
    d = doc["specimens_differ"]
    lines += ["", "## Do the specimens differ?", ""]
    if d is not None and d["p_value"] is not None:
        verdict = ("yes: they differ by more than their measurement noise explains" if d["p_value"] < 0.01 else
                   "not shown: their differences are within what their measurement noise explains"
                   if d["p_value"] >= 0.05 else "weak evidence that they differ (0.01 <= p < 0.05)")
        lines += [f"Likelihood ratio of one common set of joint parameters for every specimen against each "
                  f"specimen's own: chi2 = {_g(d['statistic'])} for {d['df']} degrees of freedom, "
                  f"**p = {_g(d['p_value'], '.3g')}**: {verdict}.",
                  "Per parameter, the last column of the table above tests the same for that parameter alone "
                  "(the specimens' other parameters free)."]
    else:
        lines.append("Not tested (no degrees of freedom).")
    lines += ["", "## Specimens that do not belong", ""]
    if doc["outliers"]:
        for o in doc["outliers"]:
            oth = o["others"]
            lines.append(f"- **{o['study']}**, {o['joint']}.{o['name']}: statistic {_g(o['statistic'], '.3g')}, "
                         f"p = {_g(o['p_value'], '.2g')} (Bonferroni over {f.n_outlier_tests} tests: "
                         f"{_g(o['p_adjusted'], '.2g')}); the other specimens' centre {_g(oth['center'])} "
                         f"[{_g(oth['center_ci_low'])}, {_g(oth['center_ci_high'])}], spread {_pct(oth['spread'])}")
        lines += ["", f"Test: {doc['outlier_test']['method']}, family-wise level {f.alpha:g}. The population "
                      "above includes these specimens; rerun without them to see the population they distort."]
    else:
        tested = doc["outlier_test"]["tests"]
        lines.append(f"None at the family-wise level {f.alpha:g} ({tested} leave-one-out tests: "
                     f"{doc['outlier_test']['method']})." if tested else
                     "Not tested: the leave-one-out test needs at least 3 specimens whose data determine a parameter.")
    lines += ["", "## Specimens", "",
              "Each specimen's estimate shrunk toward the population, with its interval; `(alone ...)` is the "
              "interval from its own data. A specimen whose data do not determine a parameter gets the "
              "population's prediction for a new specimen, marked *population only*.", ""]
    names = [f"{j}.{n}" for j, n in zip(f.param_joint, f.param_names)]
    lines += ["| specimen | reduced chi2 | " + " | ".join(names) + " |", "|---|---|" + "---|" * len(names)]
    for s in doc["specimens"]:
        cells = []
        for p in s["parameters"]:
            a = p["alone"]
            cell = f"{_g(p['value'])} [{_g(p['ci_low'], '.3g')}, {_g(p['ci_high'], '.3g')}]"
            if p["identifiable"]:
                cell += f" (alone {_g(a['ci_low'], '.3g')}..{_g(a['ci_high'] if a['ci_high'] is not None else math.inf, '.3g')})"
            else:
                cell += " *population only*"
            cells.append(cell)
        lines.append(f"| {s['study']} | {_g(s['reduced_chi2'])} | " + " | ".join(cells) + " |")
    if doc["warnings"]:
        lines += ["", "## Warnings", "", *(f"- {w}" for w in doc["warnings"])]
    lines += ["", "## Method", "",
              "- Every specimen: one batched solver run (the condensation), then its maximum-likelihood "
              "estimate and, per parameter, its likelihood of log k: the exact profile likelihood from its "
              "condensed model, or its quadratic approximation where the exact chi2 was checked to rise as "
              "the quadratic does (within 5 % at 1.5 and 3 standard deviations).",
              "- Population per parameter: log k of each specimen ~ N(log centre, tau^2); each specimen's "
              "likelihood is integrated against it (the marginal likelihood). Spread: Paule-Mandel estimate "
              "and Q-profile interval of the deviance D(tau) ~ chi2(S - 1) (exact for Gaussian "
              "likelihoods). Centre: maximum marginal likelihood at the estimated spread, Hartung-Knapp "
              "interval with Student's t of (S - 1) n_eff / S degrees of freedom (n_eff: Kish's effective "
              "number of specimens).",
              "- Specimens: posterior median and equal-tailed interval under the population, averaged over "
              "the centre and the spread with flat priors.", "- docs/population.md gives the references and the "
              "measured coverage of the intervals."]
    if plots:
        lines += ["", *(f"![{Path(p).stem}]({p})" for p in plots)]
    else:
        lines += ["", "No plots: matplotlib is not installed (`pip install 'blackbox-joints[plots]'`)."]
    return "\n".join(lines) + "\n"


def population_plots(result, out: Path, max_panels: int = 24) -> list[str]:
    """``specimens.png`` and ``spread.png`` (module docstring); [] without matplotlib."""
    plt = pyplot()
    if plt is None:
        return []
    f = result.fit
    p = min(len(f.param_names), max_panels)
    names = result.names
    S = len(names)
    outlier = {(o.specimen, o.parameter) for o in f.outliers}
    ncol = min(3, p)
    nrow = math.ceil(p / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.6 * ncol, 3.0 * nrow), squeeze=False)
    x = np.arange(S)
    for j, ax in zip(range(p), axes.flat):
        P = f.parameters[j]
        if np.isfinite(P.mu):
            c = P.centre
            lo, hi = P.centre_ci
            if np.isfinite(P.tau):
                ax.axhspan(math.exp(P.mu - 1.96 * P.tau), math.exp(P.mu + 1.96 * P.tau), color="C0", alpha=0.10,
                           label="95 % of the specimens")
            if np.isfinite(lo) and np.isfinite(hi) and hi > 0:
                ax.axhspan(max(lo, 1e-300), hi, color="C0", alpha=0.25, label="centre interval")
            ax.axhline(c, color="C0", lw=1.2, label="centre")
        for s, o in enumerate(result.outcomes):
            L = o.fit.likelihoods[j]
            if L.informative:
                a, b = o.fit.interval(j)
                top = b if np.isfinite(b) else None
                bot = a if a > 0 else None
                ymin = bot if bot is not None else (ax.get_ylim()[0] if ax.has_data() else o.fit.k[j] / 10)
                ymax = top if top is not None else o.fit.k[j] * 10
                ax.plot([s - 0.15, s - 0.15], [ymin, ymax], color="0.55", lw=2.0, solid_capstyle="butt")
                ax.plot(s - 0.15, o.fit.k[j], "o", color="0.55", ms=3)
            v = f.shrunk[j, s]
            if np.all(np.isfinite(v)):
                col = "C3" if (s, j) in outlier else "C0"
                ax.errorbar(s + 0.15, math.exp(v[0]), yerr=[[math.exp(v[0]) - math.exp(v[1])],
                                                            [math.exp(v[2]) - math.exp(v[0])]],
                            fmt="o" if L.informative else "o", mfc=col if L.informative else "white", color=col,
                            capsize=2, ms=4)
        ax.set_yscale("log")
        ax.set_title(f"{f.param_joint[j]}.{f.param_names[j]}", fontsize=9)
        ax.set_xticks(x)
        ax.set_xticklabels(names, rotation=60, ha="right", fontsize=6 if S > 12 else 7)
        if j == 0:
            ax.legend(fontsize=6, loc="best")
    for ax in list(axes.flat)[p:]:
        ax.set_visible(False)
    fig.suptitle("grey: each specimen alone; blue: shrunk toward the population (red: outlier)", fontsize=9)
    fig.tight_layout()
    fig.savefig(Path(out) / "specimens.png", dpi=90)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(max(5.0, 0.5 * len(f.param_names) + 2.0), 3.2))
    for j, P in enumerate(f.parameters):
        cv, (a, b) = P.spread, P.spread_ci
        if not np.isfinite(cv):
            continue
        top = b if np.isfinite(b) else 10.0 * max(cv, a, 0.01)
        ax.errorbar(j, 100 * cv, yerr=[[100 * (cv - a)], [100 * (top - cv)]], fmt="o", color="C0", capsize=3,
                    uplims=not np.isfinite(b))
    ax.set_xticks(range(len(f.param_names)))
    ax.set_xticklabels([f"{jn}.{n}" for jn, n in zip(f.param_joint, f.param_names)], rotation=60, ha="right",
                       fontsize=7)
    ax.set_ylabel("spread: coefficient of variation (%)")
    ax.set_title(f"between-specimen spread with {100 * f.confidence:g} % intervals", fontsize=9)
    fig.tight_layout()
    fig.savefig(Path(out) / "spread.png", dpi=90)
    plt.close(fig)
    return ["specimens.png", "spread.png"]
