"""The report of ``blackbox design``: the plan, its predicted intervals, the designed-vs-random
curve (kept apart from :class:`blackbox.commands.design.DesignResult`, lmfit-style)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from blackbox.reports.plots import pyplot

__all__ = ["design_plot", "design_report", "PLOT_CAP"]

PLOT_CAP = 10.0
"""Widths above 1000 % are drawn at this cap: such a plan leaves a parameter practically
undetermined, and the log-space interval of a spring grows like exp(z std / k) beyond it."""


def _pct(v: float) -> str:
    return "inf" if not math.isfinite(v) else f"{100.0 * v:.3g} %"


def design_plot(res, out: Path) -> list[str]:
    """``design.png``: predicted relative interval width against the number of load cases, the
    designed plans and the random plans of the same size (median, 10-90 % band)."""
    plt = pyplot()
    if plt is None:
        return []
    c = res.curve
    n = np.array(c.n_cases)
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    cap = lambda a: np.minimum(np.nan_to_num(a, nan=PLOT_CAP, posinf=PLOT_CAP), PLOT_CAP)   # noqa: E731
    for a, designed, rnd, what in ((ax[0], cap(c.designed_max), cap(c.random_max), "widest"),
                                   (ax[1], cap(c.designed_median), cap(c.random_median),
                                    "median over the parameters")):
        a.semilogy(n, designed, "o-", color="C0", label=f"designed ({res.plan.criterion})")
        a.semilogy(n, rnd[:, 1], "s--", color="C1", label=f"random plans (median of {c.n_random})")
        a.fill_between(n, rnd[:, 0], rnd[:, 2], color="C1", alpha=0.2, label="random plans, 10-90 %")
        a.set_xlabel("number of load cases")
        a.set_ylabel(f"(ci_high - ci_low) / size (drawn at most {PLOT_CAP:g})")
        a.set_title(f"predicted interval width, {what}", fontsize=9)
        a.grid(True, which="both", alpha=0.3)
        a.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(Path(out) / "design.png", dpi=110)
    plt.close(fig)
    return ["design.png"]


def design_report(res, plots: list[str]) -> str:
    """``report.md``."""
    p, pr, c = res.plan, res.prediction, res.candidates
    lines = [f"# Test design for {res.study.name}", "",
             "## [[Design]]", "",
             f"* criterion: `{p.criterion}` = {p.value:.6g} (greedy + Fedorov exchange, {p.exchanges} exchange(s))",
             f"* candidates: {len(c.cases)} cases ({len(c.loads)} loads), {len(c.sensors)} sensors; chosen: "
             f"{len(p.loads)} load cases, "
             f"{len(p.sensors)} sensors ({len(p.loads) * len(p.sensors)} readings)",
             f"* prior: {res.prior_source}" + (f"; criterion averaged over the prior and {res.robust_draws} draws "
                                               "of its uncertainty" if res.robust_draws else ""),
             f"* noise of a blank sigma: {res.noise_source}",
             f"* solver: {res.solver.runs} run(s), {res.solver.right_hand_sides} right-hand sides "
             f"({res.solver.cached_batches} batch(es) from the cache); every plan by superposition",
             "",
             "## [[Predicted widths]]", "",
             f"Linearised {100 * res.space.confidence:.0f} % intervals at the prior (log-space for springs); "
             "size = the spring, or sqrt(K_ii K_jj) for an entry of K_C.", "",
             f"* widest: {_pct(pr.max_relative_width)}; median: {_pct(pr.median_relative_width)}; "
             f"geometric mean of 2 std / size: {_pct(pr.geometric_mean_2std)}",
             f"* random plans of the same size (median of {len(res.random)}): widest "
             f"{_pct(res.random_median_width)}"
             + (f", {res.random_median_width / pr.max_relative_width:.3g} x the design's"
                if math.isfinite(res.random_median_width) and pr.max_relative_width > 0 else ""),
             ""]
    if not pr.identifiable.all():
        lines += [f"**The plan does not determine every parameter** (rank {pr.rank} of {len(pr.value)}).", ""]
    lines += ["## [[Load cases]]", "", "| case | grid | component | value |", "|---|---|---|---|"]
    lines += [f"| {cs} | {g} | {k} | {v:g} |" for cs, g, k, v in res.chosen_loads]
    lines += ["", "## [[Sensors]]", "", "| grid | component | relative to grid |", "|---|---|---|"]
    lines += [f"| {c.sensors[j].grid} | {c.sensors[j].component} | "
              f"{'' if c.sensors[j].reference_grid is None else c.sensors[j].reference_grid} |" for j in p.sensors]
    lines += ["", "## [[Parameters]]", "", "| joint | name | prior | std | ci_low | ci_high | width / size |",
              "|---|---|---|---|---|---|---|"]
    for (j, n), v, s, lo, hi, w in zip(pr.names, pr.value, pr.std, pr.ci_low, pr.ci_high, pr.relative_width):
        lines.append(f"| {j} | {n} | {v:.5g} | {s:.4g} | {lo:.5g} | {hi:.5g} | {_pct(w)} |")
    lines += ["", "## [[Width against the number of load cases]]", "",
              "| cases | designed widest | random widest (median) | designed median | random median (median) |",
              "|---|---|---|---|---|"]
    cv = res.curve
    for i, n in enumerate(cv.n_cases):
        lines.append(f"| {n} | {_pct(cv.designed_max[i])} | {_pct(cv.random_max[i, 1])} | "
                     f"{_pct(cv.designed_median[i])} | {_pct(cv.random_median[i, 1])} |")
    if res.notes:
        lines += ["", "## [[Notes]]", ""] + [f"* {n}" for n in res.notes]
    lines.append("")
    if plots:
        lines += [f"![{Path(q).stem}]({q})" for q in plots] + [""]
    else:
        lines += ["No plots: matplotlib is not installed (`pip install 'blackbox-joints[plots]'`).", ""]
    return "\n".join(lines)
