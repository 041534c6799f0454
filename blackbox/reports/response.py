"""What a structural engineer looks at on measured data, for ``identify``'s report: where sigma
came from, which cases were fitted and how the model predicts the others, the load-displacement
curve measured and fitted, and the residual against the amplitude of the response.

A linear model predicts a displacement proportional to the load. Measured data that curve away
from it (stiffness falling with amplitude), loop (loading and unloading on different paths) or
drift (residual displacement at zero load) show in these two plots before any statistic."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from blackbox.fitting.statistics import chi2_band
from blackbox.reports import raster
from blackbox.reports.plots import pyplot

__all__ = ["measured_data_report", "measured_data_plots", "amplitude_table", "single_load", "amplitude_before_after",
           "before_after_plots"]

AMPLITUDE_BINS = 6                  # rows of the residual-by-amplitude table


def _g(v, digits: int = 4) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "n/a"
    if isinstance(v, float) and math.isinf(v):
        return "inf" if v > 0 else "-inf"
    return f"{v:.{digits}g}"


def _row_cases(obs) -> np.ndarray:
    return np.array([obs.case_labels[i] for i in obs.case_index])


def single_load(loads, cases) -> tuple[tuple[int, int], np.ndarray] | None:
    """``(dof, value per case)`` when every case of ``cases`` loads the same one DOF (a single
    actuator, as a cyclic test); else None."""
    if len(loads.dofs) != 1:
        return None
    index = {c: j for j, c in enumerate(loads.cases)}
    dense = loads.values.toarray()[0]
    return loads.dofs[0], np.array([dense[index[c]] for c in cases])


def amplitude_table(measured: np.ndarray, residual: np.ndarray, fitted: np.ndarray,
                    bins: int = AMPLITUDE_BINS) -> list[tuple[float, float, int, float, int, float]]:
    """Rows ``(low, high, n_fitted, rms_fitted, n_other, rms_other)`` over bins of equal count
    of ``|measured|``: the residual's RMS by amplitude, fitted rows and the others apart."""
    amp = np.abs(measured)
    edges = np.unique(np.quantile(amp, np.linspace(0.0, 1.0, bins + 1)))
    out = []
    for a, b in zip(edges[:-1], edges[1:]):
        m = (amp >= a) & ((amp <= b) if b == edges[-1] else (amp < b))

        def rms(sel):
            return float(np.sqrt(np.mean(residual[sel] ** 2))) if sel.any() else math.nan

        out.append((float(a), float(b), int((m & fitted).sum()), rms(m & fitted),
                    int((m & ~fitted).sum()), rms(m & ~fitted)))
    return out


def measured_data_report(res) -> str:
    """Markdown sections of an :class:`~blackbox.commands.identify.IdentifyResult` on measured
    data: sigma, the case selection, the residual by amplitude, the joints held for the
    condensation."""
    r, obs, pred = res.result, res.all_obs, res.prediction
    out = ["", "## [[Measurement errors]]", ""]
    noise = res.noise
    if noise is None or not noise.estimated:
        out.append("Every sigma was given in measurements.csv.")
    else:
        counts = noise.counts()
        out.append("Rows by the source of their sigma: " + ", ".join(f"{k} {v}" for k, v in counts.items()) + ".")
        if noise.accuracy:
            out.append("Declared accuracy (+- bound, rectangular: sigma = bound / sqrt 3): " + ", ".join(
                f"{k} {_g(v)}" for k, v in noise.accuracy.items()) + ".")
        shown = [c for c in noise.channels if c.source != "fit"]
        if shown:
            pct = f"{100 * noise.confidence:g}%"
            out += ["", f"| grid | component | source | sigma of one reading | dof | {pct} interval | readings | "
                        "repeated steps |", "|---|---|---|---|---|---|---|---|"]
            for c in shown[:40]:
                out.append(f"| {c.grid} | {c.component} | {c.source} | {_g(c.sigma)} | "
                           f"{'declared' if math.isinf(c.dof) else _g(c.dof)} | "
                           f"[{_g(c.ci_low)}, {_g(c.ci_high)}] | {c.readings} | {c.repeated_steps} |")
    fs = res.fit_sigma
    if fs is not None:
        pct = f"{100 * fs.confidence:g}%"
        out += ["", "**sigma estimated from this fit** (no sigma, repeats or declared accuracy for "
                    f"{sum(fs.rows)} row(s)): the reduced chi-square is 1 by construction, so the chi-square test "
                    "of the model is off; the intervals use Student's t.", "",
                f"| kind | sigma | dof | {pct} interval | rows |", "|---|---|---|---|---|"]
        for k, s, d, lo, hi, n in zip(fs.kinds, fs.sigma, fs.dof, fs.ci_low, fs.ci_high, fs.rows):
            out.append(f"| {k} | {_g(s)} | {_g(d)} | [{_g(lo)}, {_g(hi)}] | {n} |")
    elif r.n_obs > r.n_params:
        lo, hi = chi2_band(r.n_obs - r.n_params, 0.99)
        within = lo <= r.reduced_chi2 <= hi
        out += ["", f"Chi-square test: reduced chi-square {_g(r.reduced_chi2)}, 99% band {_g(lo, 3)}..{_g(hi, 3)}: "
                + ("the model fits the fitted rows within the measurement errors." if within else
                   "the model does **not** fit the fitted rows within the measurement errors (a model error, "
                   "or sigma too small): the intervals above assume sigma is right.")]
        sc = res.scaled
        if sc is not None:
            pct = f"{100 * sc.confidence:g}%"
            out += ["", f"Intervals with sigma scaled to the residuals (x {_g(math.sqrt(sc.covariance_scale), 3)}, "
                        f"Student t; what the data give if the misfit is taken as noise): {sc.ci_method}", "",
                    f"| joint | parameter | value | {pct} low | {pct} high |", "|---|---|---|---|---|"]
            for j, n, k, a, b in zip(sc.param_joint, sc.param_names, sc.k, sc.ci_low, sc.ci_high):
                out.append(f"| {j} | {n} | {_g(k, 5)} | {_g(a, 5)} | {_g(b, 5)} |")
    if res.patterns or res.excluded:
        lab = _row_cases(obs)
        fitted = np.isin(lab, res.selected)
        out += ["", "## [[Case selection]]", "",
                f"Fitted: the cases matching {list(res.patterns)} ({len(res.selected)} cases, {int(fitted.sum())} "
                f"rows); the other {len(res.excluded)} cases are predicted with the estimate, never fitted."]
        if pred is not None and (~fitted).any():
            rf = float(np.sqrt(np.mean((obs.values[fitted] - pred[fitted]) ** 2)))
            ro = float(np.sqrt(np.mean((obs.values[~fitted] - pred[~fitted]) ** 2)))
            out.append(f"RMS residual (measured - predicted): fitted {_g(rf)}, predicted cases {_g(ro)}.")
    if pred is not None:
        lab = _row_cases(obs)
        fitted = np.isin(lab, res.selected) if res.patterns else np.ones(len(obs), dtype=bool)
        resid = obs.values - pred
        out += ["", "## [[Residual by amplitude]]", "",
                "Rows binned by the measured value's magnitude (equal counts); measured - predicted, "
                "measurement units.", "",
                "| amplitude from | to | fitted rows | RMS | other rows | RMS |", "|---|---|---|---|---|---|"]
        for a, b, nf, rf, no, ro in amplitude_table(obs.values, resid, fitted):
            out.append(f"| {_g(a)} | {_g(b)} | {nf} | {_g(rf)} | {no} | {_g(ro)} |")
    added = res.model.c.added_springs
    if added:
        out += ["", "## [[Joints held for the condensation]]", "",
                "With its joints released the structure is a mechanism (a joint is its only support), so the "
                f"solver ran with {len(added)} reference spring(s) across the joints, accounted for exactly "
                "(K_deck = K_ref, docs/study-format.md \"A joint that is the only support\"):", ""]
        out += [f"- {s.a[0]}:{s.a[1]} - {s.b[0]}:{s.b[1] if s.b else ''} k = {_g(s.k)}" if s.b is not None
                else f"- {s.a[0]}:{s.a[1]} - ground k = {_g(s.k)}" for s in added]
    held = [(j.name, j.constrained_springs) for j in res.declared.joints if getattr(j, "constrained_springs", ())]
    if held:
        out += ["", "Springs between two rotations the supports fix (no parameters, they cannot act): "
                + "; ".join(f"{n}: {', '.join(f'k{p}{i}{k}' for p, i, k in cs)}" for n, cs in held) + "."]
    return "\n".join(out) + "\n"


def measured_data_plots(res, out_dir: Path) -> list[str]:
    """``load_displacement.png`` (measured and fitted, when every case loads one DOF) and
    ``residual_amplitude.png`` (the residual signed with the measured value, so that a response
    larger than the model's is above 0 on either side of the cycle), drawn with
    :mod:`blackbox.reports.raster`. Returns the file names written."""
    if not raster.available() or res.prediction is None:
        return []
    obs, pred = res.all_obs, res.prediction
    lab = _row_cases(obs)
    fitted = np.isin(lab, res.selected) if res.patterns else np.ones(len(obs), dtype=bool)
    held = np.isin(lab, list(res.declared.holdout))
    written = []
    sl = single_load(res.study.loads, lab)
    C0, C1, C2, C3 = raster.PALETTE[:4]
    if sl is not None:
        (g, c), load = sl
        channels = list(dict.fromkeys(obs.dofs))[:4]
        fig = raster.Figure(650 * len(channels), 500)
        for ax, ch in zip(fig.panels(len(channels)), channels):
            m = np.array([d == ch for d in obs.dofs])
            order = np.argsort(obs.case_index[m], kind="stable")
            x, y, p = obs.values[m][order], load[m][order], pred[m][order]
            f = fitted[m][order]
            lim = np.array([y.min(), y.max()])
            slope = np.polyfit(y, p, 1) if np.ptp(y) > 0 else np.array([0.0, 0.0])
            ax.limits(np.r_[x, np.polyval(slope, lim), 0.0], np.r_[y, 0.0])
            ax.hline(0.0)
            ax.vline(0.0)
            ax.line(x, y, color="#999999", width=1, label="measured (in case order)")
            ax.points(x[f], y[f], color=C0, size=3, label="measured, fitted cases")
            ax.line(np.polyval(slope, lim), lim, color=C3, width=2, label="identified model")
            ax.xlabel = f"measured displacement at grid {ch[0]}, component {ch[1]}"
            ax.ylabel = f"load at grid {g}, component {c}"
            ax.title = "load - displacement: measured and identified"
        written.append(fig.save(out_dir / "load_displacement.png"))
    rot = np.array([cc >= 4 for _, cc in obs.dofs])
    kinds = [(k, m) for k, m in (("translation", ~rot), ("rotation", rot)) if m.any()]
    # the residual in the direction of the measured value: > 0 where the structure moved more
    # than the model says, whichever way it moved (a softening shows as one rising band)
    resid = (obs.values - pred) * np.where(obs.values < 0, -1.0, 1.0)
    fig = raster.Figure(700 * len(kinds), 450)
    for ax, (kind, m) in zip(fig.panels(len(kinds)), kinds):
        s = obs.sigma[m]
        band = 2 * float(np.median(s)) if s.size else 0.0
        ax.limits(np.abs(obs.values[m]), np.r_[resid[m], -band, band])
        if band > 0:
            ax.hspan(-band, band, label="+-2 sigma (median)")
        ax.hline(0.0)
        for sel, color, size, label in ((m & ~fitted & ~held, C1, 2, "predicted (not fitted)"),
                                        (m & held, C2, 3, "hold-out"),
                                        (m & fitted & ~held, C0, 3, "fitted")):
            if sel.any():
                ax.points(np.abs(obs.values[sel]), resid[sel], color=color, size=size,
                          label=f"{label} ({int(sel.sum())})")
        ax.xlabel = f"|measured {kind}|"
        ax.ylabel = "(measured - predicted) x sign(measured)"
        ax.title = f"residual against amplitude ({kind}s)"
    written.append(fig.save(out_dir / "residual_amplitude.png"))
    return written


def amplitude_before_after(values: np.ndarray, sigma: np.ndarray, z_before: np.ndarray, z_after: np.ndarray,
                           bins: int = AMPLITUDE_BINS) -> str:
    """A Markdown section for ``diagnose``: the residual's RMS (measurement units) and chi2/n
    by bins of equal count of ``|measured value|``, before (declared model) and after (the
    effects added). ``z_*`` are the whitened residuals of the same rows."""
    amp = np.abs(values)
    edges = np.unique(np.quantile(amp, np.linspace(0.0, 1.0, bins + 1)))
    out = ["", "## Residual by amplitude", "",
           "Rows binned by the measured value's magnitude (equal counts): where the misfit grows with the "
           "amplitude of the response, the model lacks something amplitude-dependent (stiffness falling with "
           "deformation, slip, a geometric effect of the load).", "",
           "| amplitude from | to | rows | RMS before | chi2/n before | RMS after | chi2/n after |",
           "|---|---|---|---|---|---|---|"]
    for a, b in zip(edges[:-1], edges[1:]):
        m = (amp >= a) & ((amp <= b) if b == edges[-1] else (amp < b))
        if not m.any():
            continue
        rb = float(np.sqrt(np.mean((z_before[m] * sigma[m]) ** 2)))
        ra = float(np.sqrt(np.mean((z_after[m] * sigma[m]) ** 2)))
        out.append(f"| {_g(a)} | {_g(b)} | {int(m.sum())} | {_g(rb)} | {_g(float(np.mean(z_before[m] ** 2)))} | "
                   f"{_g(ra)} | {_g(float(np.mean(z_after[m] ** 2)))} |")
    return "\n".join(out) + "\n"


def before_after_plots(loads, obs, before: np.ndarray, after: np.ndarray, out_dir: Path,
                       labels: tuple[str, str] = ("declared model", "after the added effects")) -> list[str]:
    """``diagnose``'s response plots of the rows ``obs`` (:class:`~blackbox.identification.Observations`)
    predicted ``before`` and ``after`` (measurement units): ``load_displacement.png`` when every
    case loads one DOF (the measured path in case order, each model's prediction of every case:
    a linear model is one straight line, a model whose stiffness depends on the case is not) and
    ``residual_amplitude.png`` (measured - predicted, signed with the measured value, against its
    magnitude, before and after side by side). Returns the file names written (none without
    matplotlib)."""
    plt = pyplot()
    if plt is None or not len(obs.values):
        return []
    written = []
    lab = _row_cases(obs)
    sl = single_load(loads, lab)
    if sl is not None:
        (g, c), load = sl
        channels = list(dict.fromkeys(obs.dofs))[:4]
        fig, axes = plt.subplots(1, len(channels), figsize=(6.5 * len(channels), 5), squeeze=False)
        for ax, ch in zip(axes[0], channels):
            m = np.array([d == ch for d in obs.dofs])
            order = np.argsort(obs.case_index[m], kind="stable")
            y = load[m][order]
            ax.plot(obs.values[m][order], y, "-", color="0.55", lw=0.8, label="measured (in case order)")
            for pred, style, name in ((before, dict(color="C3", lw=1.2), labels[0]),
                                      (after, dict(color="C0", lw=0.9, alpha=0.85), labels[1])):
                ax.plot(pred[m][order], y, "-", label=f"{name} (in case order)", **style)
            ax.axhline(0.0, color="k", lw=0.5)
            ax.axvline(0.0, color="k", lw=0.5)
            ax.set_xlabel(f"displacement at grid {ch[0]}, component {ch[1]}")
            ax.set_ylabel(f"load at grid {g}, component {c}")
            ax.legend(fontsize=8)
            ax.set_title("load - displacement: measured and fitted")
        fig.tight_layout()
        fig.savefig(out_dir / "load_displacement.png", dpi=110)
        plt.close(fig)
        written.append("load_displacement.png")
    rot = np.array([cc >= 4 for _, cc in obs.dofs])
    kinds = [(k, m) for k, m in (("translation", ~rot), ("rotation", rot)) if m.any()]
    fig, axes = plt.subplots(1, len(kinds), figsize=(7 * len(kinds), 4.5), squeeze=False)
    sign = np.where(obs.values < 0, -1.0, 1.0)      # > 0: the structure moved more than the model says
    for ax, (kind, m) in zip(axes[0], kinds):
        for pred, style, name in ((before, dict(color="C3", ms=3, alpha=0.6), labels[0]),
                                  (after, dict(color="C0", ms=3, alpha=0.6), labels[1])):
            ax.plot(np.abs(obs.values[m]), ((obs.values - pred) * sign)[m], "o", label=name, **style)
        s = float(np.median(obs.sigma[m]))
        ax.axhspan(-2 * s, 2 * s, color="0.85", label="+-2 sigma (median)")
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_xlabel(f"|measured {kind}|")
        ax.set_ylabel("(measured - predicted) x sign(measured)")
        ax.legend(fontsize=8)
        ax.set_title(f"residual against amplitude ({kind}s)")
    fig.tight_layout()
    fig.savefig(out_dir / "residual_amplitude.png", dpi=110)
    plt.close(fig)
    written.append("residual_amplitude.png")
    return written
