"""Two exchanged load cases whose declared sigmas stayed with their labels.

``case_swap`` explains two cases whose readings were exchanged (:mod:`.effects.case_swap`). When
``measurements.csv`` gives each reading a sigma from what the gauge read (a relative accuracy,
as most transducer data sheets state it) and the exchange happened after the sigmas were written
(the readings copied into each other's files, the sigma column computed per label from the
planned response), each moved reading is judged by the other reading's sigma. With relative
noise those differ reading by reading, so even the exact exchange leaves a misfit above the
noise band and the search goes on adding effects that describe nothing but the wrong weights.

The exchange of the two cases' sigmas channel by channel is a second reading of the same data:
it only permutes the sigmas between the two rows of each channel, so the Gaussian likelihood's
``sum(log sigma)`` is the same and the chi2 of the two readings compare directly (one discrete
choice more, charged ``2 ln 2``). When a diagnosis added a ``case_swap`` (kept to the end, or
removed by a later addition) and the fit that added it fits the readings better with the sigmas
exchanged, the search is run again on the data with those sigmas exchanged; that diagnosis is
kept when it has the same exchange and a lower BIC (:func:`better`), and says so
(``Diagnosis.sigmas_exchanged``)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from blackbox.identification import Observations

__all__ = ["EXCHANGE_PENALTY", "swapped_pair", "with_sigmas_exchanged", "exchange_pays", "better", "brief"]

EXCHANGE_PENALTY = 2.0 * math.log(2.0)
"""What the choice of the sigmas' reading costs in BIC units: one binary choice."""


def swapped_pair(diag, *, added: bool = False) -> tuple[str, str] | None:
    """The two case labels of the final model's ``case_swap`` (``None``: none); ``added``: or,
    without one there, of the last ``case_swap`` the search added and a later addition removed
    (both cases then set aside, say, because the wrong weights left the exchange a misfit)."""
    for e in diag.final.spec.effects:
        if e.kind == "case_swap":
            a, b = e.where
            return str(a), str(b)
    if added:
        for s in reversed(diag.steps):
            if s.added is not None and s.added.effect.kind == "case_swap":
                a, b = s.added.effect.where
                return str(a), str(b)
    return None


def with_sigmas_exchanged(obs: Observations, a: str, b: str) -> Observations | None:
    """``obs`` with the sigmas of cases ``a`` and ``b`` exchanged at each channel the two read
    (``None`` when they read different channels or either is not a fitted case)."""
    labels = list(obs.case_labels)
    if a not in labels or b not in labels:
        return None
    ia, ib = labels.index(a), labels.index(b)
    rows: dict[int, dict] = {ia: {}, ib: {}}
    refs = obs.ref_dofs or (None,) * len(obs.dofs)
    for i, (d, ci, r) in enumerate(zip(obs.dofs, np.asarray(obs.case_index).tolist(), refs)):
        if ci in rows:
            rows[ci][(tuple(d), r)] = i
    if not rows[ia] or set(rows[ia]) != set(rows[ib]):
        return None
    sigma = np.array(obs.sigma, float)
    for ch, i in rows[ia].items():
        j = rows[ib][ch]
        sigma[i], sigma[j] = obs.sigma[j], obs.sigma[i]
    return dataclasses.replace(obs, sigma=sigma)


def exchange_pays(diag, obs: Observations, exchanged: Observations) -> bool:
    """Whether the fit that added the ``case_swap`` (:func:`swapped_pair` with ``added``) fits
    ``obs``'s readings better (by more than :data:`EXCHANGE_PENALTY`) with the sigmas of
    ``exchanged`` than with their own. That
    fit, not the final one: an effect added after it (one exchanged case set aside, say) may
    have absorbed the misfit the wrong weights left, and there the two readings of the sigmas
    no longer differ where they should."""
    pair = swapped_pair(diag, added=True)
    fits = [s.added.refit for s in diag.steps if s.added is not None and s.added.refit is not None
            and s.added.effect.kind == "case_swap" and tuple(map(str, s.added.effect.where)) == pair]
    if not fits:
        return False
    f = np.asarray(fits[-1].predicted, float)
    y = np.asarray(obs.values, float)
    if f.shape != y.shape:
        return False
    own = float(np.sum(((y - f) / np.asarray(obs.sigma, float)) ** 2))
    other = float(np.sum(((y - f) / np.asarray(exchanged.sigma, float)) ** 2))
    return other + EXCHANGE_PENALTY < own


def better(diag, again, pair: tuple[str, str]) -> bool:
    """Whether ``again`` (the search on the data with ``pair``'s sigmas exchanged) is the better
    diagnosis: it explains the same exchange and its final BIC, charged
    :data:`EXCHANGE_PENALTY`, is lower (both BICs are on the same readings with the same set of
    sigmas, so their sum(log sigma) terms are equal and they compare)."""
    return (swapped_pair(again) in (pair, pair[::-1])
            and again.final.bic + EXCHANGE_PENALTY < diag.final.bic)


def brief(diag, pair: tuple[str, str], exchanged: bool, kept: bool) -> dict:
    """``diagnosis.json``'s ``sigma_exchange``: the search that is not the document's, in brief --
    the cases, whether its sigmas were ``exchanged``, whether the document is the search with them
    exchanged (``kept``), what it added, its reduced chi2 and BIC."""
    return {"cases": list(pair), "sigmas_exchanged": exchanged, "kept_exchanged": kept,
            "added": [a.effect.label() for a in diag.added],
            "reduced_chi2": float(diag.final.reduced_chi2), "bic": float(diag.final.bic),
            "verdict": diag.verdict}
