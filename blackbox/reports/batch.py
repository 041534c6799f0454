"""``blackbox batch``: the summary across studies (``summary.csv``, ``summary.md``, ``summary.png``)."""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path
from typing import Sequence

from blackbox.reports.plots import pyplot

__all__ = ["parameter_columns", "summary_csv", "summary_markdown", "summary_plot"]


def parameter_columns(outcomes: Sequence) -> list[str]:
    """``<joint>.<name>`` of every parameter reported by any study, in first-seen order."""
    cols: dict[str, None] = {}
    for o in outcomes:
        for p in o.parameters:
            cols.setdefault(f"{p['joint']}.{p['name']}", None)
    return list(cols)


def _fmt(v) -> str:
    if v is None:
        return ""
    v = float(v)
    return repr(v) if math.isfinite(v) else ""


def summary_csv(outcomes: Sequence) -> str:
    """One row per study: ``study, status, reduced_chi2``, the parameter values, then ``error``
    (the first line of a failed study's message; empty when it is ok)."""
    cols = parameter_columns(outcomes)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["study", "status", "reduced_chi2", *cols, "error"])
    for o in outcomes:
        vals = {f"{p['joint']}.{p['name']}": p["value"] for p in o.parameters}
        err = "" if o.status == "ok" else (o.message.splitlines()[0] if o.message else o.status)
        w.writerow([o.name, o.status, _fmt(o.reduced_chi2), *(_fmt(vals.get(c)) for c in cols), err])
    return buf.getvalue()


def _g(v, spec: str = ".4g") -> str:
    if v is None:
        return "-"
    v = float(v)
    return format(v, spec) if math.isfinite(v) else "-"


def summary_markdown(result, plots: list[str]) -> str:
    """The batch's report: how it ran, a table of the studies, the failures' messages."""
    outs = result.outcomes
    counts = ", ".join(f"{n} {s}" for s, n in result.counts().items())
    lines = [f"# Batch: `blackbox {result.sub_command}` on {len(outs)} studies", "",
             f"- executor: {result.executor}",
             f"- wall time: {result.wall_s:.2f} s (sum of the studies' own times "
             f"{sum(o.wall_s for o in outs):.2f} s)",
             f"- status: {counts}", ""]
    cols = parameter_columns(outs)
    lines += ["| study | status | reduced chi2 | " + " | ".join(cols) + " | wall s | worker |",
              "|---|---|---|" + "---|" * len(cols) + "---|---|"]
    for o in outs:
        vals = {f"{p['joint']}.{p['name']}": p for p in o.parameters}
        cells = []
        for c in cols:
            p = vals.get(c)
            if p is None:
                cells.append("-")
            elif p.get("ci_low") is not None and p.get("ci_high") is not None:
                cells.append(f"{_g(p['value'])} [{_g(p['ci_low'], '.3g')}, {_g(p['ci_high'], '.3g')}]")
            else:
                cells.append(_g(p["value"]))
        lines.append(f"| [{o.name}]({o.name}/) | {o.status} | {_g(o.reduced_chi2)} | " + " | ".join(cells)
                     + f" | {o.wall_s:.2f} | {o.worker or '-'} |")
    bad = [o for o in outs if o.status != "ok"]
    if bad:
        lines += ["", "## Studies that are not ok", ""]
        for o in bad:
            first = o.message.strip().splitlines()[0] if o.message.strip() else o.status
            lines.append(f"- **{o.name}** ({o.status}): {first}")
    if plots:
        lines += ["", *(f"![{Path(p).stem}]({p})" for p in plots)]
        if len(cols) > PLOT_PANELS:
            lines += ["", f"The plot shows the first {PLOT_PANELS} of the {len(cols)} parameters; the "
                          f"table above has all of them."]
    else:
        lines += ["", "No plot: matplotlib is not installed (`pip install 'blackbox-joints[plots]'`) "
                      "or no study reported parameters."]
    return "\n".join(lines) + "\n"


PLOT_PANELS = 48
"""Parameters drawn at most in ``summary.png`` (a complex joint of 4 branches has 27); beyond, the
plot and ``summary.md`` say how many are left out (all are in the table and ``summary.csv``)."""


def summary_plot(outcomes: Sequence, path: Path, max_panels: int = PLOT_PANELS) -> bool:
    """Each parameter across the studies (value with its interval, log scale when all values are
    positive) and the reduced chi-square, one panel each; False when nothing to draw or no
    matplotlib. Every parameter up to ``max_panels``; beyond, the title says how many are left out."""
    plt = pyplot()
    every = parameter_columns(outcomes)
    cols = every[:max_panels]
    if plt is None or not cols:
        return False
    names = [o.name for o in outcomes]
    n = len(cols) + 1
    ncol = min(3 if n <= 12 else 4, n)
    nrow = math.ceil(n / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.2 * ncol, 2.8 * nrow), squeeze=False)
    x = list(range(len(outcomes)))
    for ax, c in zip(axes.flat, cols):
        xs, ys, lo, hi = [], [], [], []
        for i, o in enumerate(outcomes):
            p = next((p for p in o.parameters if f"{p['joint']}.{p['name']}" == c), None)
            if p is None or p.get("value") is None or not math.isfinite(float(p["value"])):
                continue
            v = float(p["value"])
            xs.append(i)
            ys.append(v)
            a = p.get("ci_low")
            b = p.get("ci_high")
            lo.append(v - float(a) if a is not None and math.isfinite(float(a)) else 0.0)
            hi.append(float(b) - v if b is not None and math.isfinite(float(b)) else 0.0)
        if ys:
            ax.errorbar(xs, ys, yerr=[lo, hi], fmt="o", capsize=3)
            if all(v > 0 for v in ys) and all(v - d > 0 for v, d in zip(ys, lo)):
                ax.set_yscale("log")
        ax.set_title(c, fontsize=9)
        ax.set_xticks(x)
        ax.set_xticklabels(names, rotation=45, ha="right", fontsize=7)
    ax = axes.flat[len(cols)]
    chi = [(i, float(o.reduced_chi2)) for i, o in enumerate(outcomes)
           if o.reduced_chi2 is not None and math.isfinite(float(o.reduced_chi2))]
    if chi:
        ax.plot([i for i, _ in chi], [v for _, v in chi], "s", color="C3")
    ax.axhline(1.0, color="grey", lw=0.8, ls="--")
    ax.set_title("reduced chi2", fontsize=9)
    ax.set_xticks(x)
    ax.set_xticklabels(names, rotation=45, ha="right", fontsize=7)
    for ax in list(axes.flat)[n:]:
        ax.set_visible(False)
    if len(every) > len(cols):
        fig.suptitle(f"the first {len(cols)} of {len(every)} parameters; all of them are in summary.csv "
                     f"and summary.md", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return True
