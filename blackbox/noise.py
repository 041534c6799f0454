"""Measurement noise when nobody declares it (docs/study-format.md, "Sigma").

A row of ``measurements.csv`` may leave its ``sigma`` blank. Its standard deviation then comes,
in the order an experimentalist trusts them (GUM, JCGM 100:2008, Sec. 4-5):

1. **repeated readings** of the same case and channel (type A): several rows with the same
   ``case``, ``grid``, ``component`` (and ``reference_grid``) are readings of one step; the row
   becomes their mean. Each channel's scatter is pooled over its repeated steps,

       s^2 = sum_steps sum_readings (x - mean_step)^2 / nu,     nu = sum_steps (n_step - 1),

   and the mean of ``n`` readings has ``s / sqrt(n)``. A channel is one instrument, so one
   scatter per channel, whatever the step (the readings of a hold scatter by the instrument's
   noise, not by the structure's response). Cycles repeated at the same amplitude are *not*
   repeats: the specimen changes between them (cracking, slip, degradation), so their
   difference is response, not noise;
2. **a declared instrument accuracy** (type B): ``[measurements] translation_accuracy`` /
   ``rotation_accuracy`` in study.toml, the +- bound of a reading's error as a calibration
   certificate or data sheet states it, taken as a rectangular distribution: ``u_B = a / sqrt(3)``
   (GUM 4.3.7). With repeats as well, the two combine: ``u = sqrt(s^2 / n + u_B^2)`` with the
   Welch-Satterthwaite degrees of freedom ``nu_eff = u^4 / ((s^2/n)^2 / nu)`` (GUM G.4.1);
3. **the fit** (last resort): one sigma per kind of quantity (translations, rotations) from the
   residuals of the fit itself (``blackbox.identification.fit_sigma``). The chi-square test of the
   model is then lost (it would be ``n - p`` by construction); ``identify`` says so and uses
   Student's t; ``diagnose`` and ``compare`` refuse (they judge a model against the noise, which
   must not come from that model).

Each estimate carries its own interval: ``nu s^2 / sigma^2 ~ chi2(nu)`` for a pooled or fitted
standard deviation (exact for Gaussian readings), none for a declared accuracy (it is a
statement, not an estimate).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from blackbox.distributions import chi2_ppf

__all__ = ["SIGMA_SOURCES", "ChannelNoise", "NoiseModel", "Readings", "sigma_interval", "reduce_readings",
           "RECTANGULAR", "pooled_scatter"]

RECTANGULAR = math.sqrt(3.0)
"""A +-a bound read as a rectangular distribution has the standard deviation a / sqrt(3)."""

SIGMA_SOURCES = ("given", "repeats", "accuracy", "repeats+accuracy", "fit")


def pooled_scatter(blocks: Sequence[np.ndarray]) -> tuple[float, int]:
    """``(s, nu)``: the pooled standard deviation of readings that should be equal within each
    block (repeated scans of one state), ``s^2 = sum_b sum (x - mean_b)^2 / nu``,
    ``nu = sum_b (n_b - 1)``; ``(nan, 0)`` without a block of two readings."""
    ss, nu = 0.0, 0
    for b in blocks:
        b = np.asarray(b, float)
        if b.size >= 2:
            ss += float(np.sum((b - b.mean()) ** 2))
            nu += b.size - 1
    return (math.sqrt(ss / nu) if nu else math.nan), nu


def sigma_interval(s: float, dof: float, confidence: float) -> tuple[float, float]:
    """Two-sided interval of a standard deviation estimated as ``s`` with ``dof`` degrees of
    freedom (``dof s^2 / sigma^2 ~ chi2(dof)``); ``(s, s)`` for ``dof = inf`` (a declared value)."""
    if not math.isfinite(dof):
        return (s, s)
    if dof <= 0:
        return (math.nan, math.nan)
    a = 1.0 - confidence
    return (s * math.sqrt(dof / chi2_ppf(1.0 - a / 2.0, dof)),
            s * math.sqrt(dof / chi2_ppf(a / 2.0, dof)))


@dataclass(frozen=True)
class ChannelNoise:
    """The noise of one channel (grid, component, reference grid or 0): the standard deviation of
    one reading, where it came from, its degrees of freedom (``inf``: declared) and interval."""
    grid: int
    component: int
    reference: int
    source: str
    sigma: float
    dof: float
    ci_low: float
    ci_high: float
    readings: int                      # rows read for the channel
    repeated_steps: int                # (case) steps with two or more readings

    def to_json(self) -> dict:
        def num(v):
            return float(v) if math.isfinite(v) else None
        return {"grid": self.grid, "component": self.component, "reference_grid": self.reference or None,
                "source": self.source, "sigma": num(self.sigma), "dof": num(self.dof),
                "ci_low": num(self.ci_low), "ci_high": num(self.ci_high), "readings": self.readings,
                "repeated_steps": self.repeated_steps}


@dataclass(frozen=True, eq=False)
class NoiseModel:
    """How each row's sigma came about: ``source[i]`` one of :data:`SIGMA_SOURCES`, ``dof[i]``
    (``inf`` for a given or declared sigma, ``nan`` for a row whose sigma the fit estimates),
    ``readings[i]`` averaged into row ``i``; the channels' estimates; the declared accuracies."""
    source: tuple[str, ...]
    dof: np.ndarray
    readings: np.ndarray
    channels: tuple[ChannelNoise, ...] = ()
    accuracy: dict[str, float] = field(default_factory=dict)
    confidence: float = 0.95

    @property
    def fit_rows(self) -> np.ndarray:
        """Rows whose sigma only the fit can give."""
        return np.array([s == "fit" for s in self.source], dtype=bool)

    @property
    def estimated(self) -> bool:
        """Whether any row's sigma was not given in measurements.csv."""
        return any(s != "given" for s in self.source)

    def effective_dof(self, rows: np.ndarray | None = None) -> float:
        """The fewest degrees of freedom of a sigma among ``rows`` (default all; rows the fit
        estimates excluded): the Student t quantile of the parameter intervals (``inf``: normal)."""
        d = self.dof if rows is None else self.dof[rows]
        d = d[np.isfinite(d) | np.isinf(d)]
        return float(np.min(d)) if d.size else math.inf

    def counts(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for s in self.source:
            out[s] = out.get(s, 0) + 1
        return out

    def subset(self, idx: np.ndarray) -> "NoiseModel":
        return NoiseModel(tuple(self.source[i] for i in idx), self.dof[idx], self.readings[idx], self.channels,
                          dict(self.accuracy), self.confidence)

    def to_json(self) -> dict:
        return {"rows_by_source": self.counts(), "accuracy": dict(self.accuracy),
                "channels": [c.to_json() for c in self.channels], "confidence": self.confidence}


@dataclass(frozen=True, eq=False)
class Readings:
    """The rows of measurements.csv before any reduction: one per reading; ``sigma`` nan where
    blank; ``keys[i]`` = (case, grid, component, reference grid or 0)."""
    keys: tuple[tuple[str, int, int, int], ...]
    values: np.ndarray
    sigma: np.ndarray
    lines: tuple[int, ...]


def reduce_readings(r: Readings, translation_accuracy: float | None = None,
                    rotation_accuracy: float | None = None, confidence: float = 0.95):
    """Average repeated readings and give each row its sigma (module docstring).

    Returns ``(order, values, sigma, noise)``: ``order[i]`` the index of row ``i``'s first
    reading in ``r`` (rows keep the order of their first reading), the mean values, sigma
    (``nan`` where only the fit can give it) and the :class:`NoiseModel`. The caller has checked
    that repeated readings leave sigma blank."""
    groups: dict[tuple, list[int]] = {}
    for i, key in enumerate(r.keys):
        groups.setdefault(key, []).append(i)
    order = np.array([idx[0] for idx in groups.values()], dtype=int)
    values = np.array([float(np.mean(r.values[idx])) for idx in groups.values()])
    n = np.array([len(idx) for idx in groups.values()], dtype=int)
    given = np.array([math.isfinite(r.sigma[idx[0]]) for idx in groups.values()])
    sigma = np.where(given, r.sigma[order], np.nan)

    # type A: the pooled scatter of each channel over its repeated steps
    ss: dict[tuple, float] = {}
    nu: dict[tuple, int] = {}
    reads: dict[tuple, int] = {}
    steps: dict[tuple, int] = {}
    for key, idx in groups.items():
        ch = key[1:]
        reads[ch] = reads.get(ch, 0) + len(idx)
        if len(idx) >= 2:
            x = r.values[idx]
            ss[ch] = ss.get(ch, 0.0) + float(np.sum((x - x.mean()) ** 2))
            nu[ch] = nu.get(ch, 0) + len(idx) - 1
            steps[ch] = steps.get(ch, 0) + 1
    pooled = {ch: math.sqrt(ss[ch] / nu[ch]) for ch in nu}

    acc = {"translation": translation_accuracy, "rotation": rotation_accuracy}
    u_b = {k: (v / RECTANGULAR if v is not None else None) for k, v in acc.items()}
    source, dof = [], np.full(len(order), math.inf)
    for j, key in enumerate(groups):
        ch = key[1:]
        if given[j]:
            source.append("given")
            continue
        kind = "rotation" if key[2] >= 4 else "translation"
        ub = u_b[kind]
        if ch in pooled and pooled[ch] > 0.0:
            ua2 = pooled[ch] ** 2 / n[j]
            if ub is not None:
                u2 = ua2 + ub * ub
                sigma[j] = math.sqrt(u2)
                dof[j] = u2 * u2 / (ua2 * ua2 / nu[ch])           # Welch-Satterthwaite
                source.append("repeats+accuracy")
            else:
                sigma[j] = math.sqrt(ua2)
                dof[j] = nu[ch]
                source.append("repeats")
        elif ub is not None:
            sigma[j] = ub
            source.append("accuracy")
        else:
            dof[j] = math.nan
            source.append("fit")

    channels = []
    for ch in dict.fromkeys(k[1:] for k in groups):
        kind = "rotation" if ch[1] >= 4 else "translation"
        blank = [j for j, key in enumerate(groups) if key[1:] == ch and not given[j]]
        if not blank:
            continue
        ub = u_b[kind]
        if ch in pooled and pooled[ch] > 0.0:
            s, d = pooled[ch], float(nu[ch])
            lo, hi = sigma_interval(s, d, confidence)
            src = "repeats+accuracy" if ub is not None else "repeats"
        elif ub is not None:
            s, d, lo, hi, src = ub, math.inf, ub, ub, "accuracy"
        else:
            s, d, lo, hi, src = math.nan, math.nan, math.nan, math.nan, "fit"
        channels.append(ChannelNoise(ch[0], ch[1], ch[2], src, s, d, lo, hi, reads[ch], steps.get(ch, 0)))
    noise = NoiseModel(tuple(source), dof, n, tuple(channels),
                       {k: v for k, v in acc.items() if v is not None}, confidence)
    return order, values, sigma, noise


def kinds(components: Sequence[int]) -> list[str]:
    """``"translation"`` or ``"rotation"`` per component."""
    return ["rotation" if int(c) >= 4 else "translation" for c in components]
