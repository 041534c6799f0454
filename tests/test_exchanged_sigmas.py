"""Two exchanged cases whose sigmas stayed with their labels (``blackbox.diagnosis.exchange``).

The study is ``benchmarks/unlisted_defects.py``'s swapped-cases study of seed 54, index 1 (a
box frame, 8 cases, relative noise: each reading's sigma 5 % of what its gauge read, floored at
2 % of the case's largest). The benchmark exchanges the readings of L5 and L6 and leaves the
sigma column as it was, so each moved reading is judged by the sigma of the other case's
reading. Before: ``case_swap`` found first (reduced chi2 5897 -> 4.96), then L6 set aside as a
bad case to absorb the wrong weights (0.81). The same readings with the sigmas moved along are
the control: one ``case_swap``, nothing else, and no second search."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from benchmarks import unlisted_defects as ud
from benchmarks.blind.generate import NONE, generate_study
from blackbox.commands import diagnose as dc
from blackbox.diagnosis.exchange import with_sigmas_exchanged
from blackbox.identification import Observations


@pytest.fixture(scope="module")
def swapped(tmp_path_factory):
    out = tmp_path_factory.mktemp("swapped")
    st = generate_study(1, 54, out, kind=NONE, shape="box", style="plain")
    where = ud.plant(st.folder, "swapped_cases", np.random.default_rng([54, 1, ud.DEFECTS.index("swapped_cases")]))
    assert sorted(where["cases"]) == ["L5", "L6"]
    return st.folder


def _moved_along(folder, tmp_path):
    """A copy of ``folder`` with the sigmas of L5 and L6 exchanged too (they follow the readings)."""
    import shutil
    dst = tmp_path / "moved"
    shutil.copytree(folder, dst)
    with open(dst / "measurements.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    sig = {(r["case"], r["grid"], r["component"]): r["sigma"] for r in rows}
    for r in rows:
        other = {"L5": "L6", "L6": "L5"}.get(r["case"])
        if other:
            r["sigma"] = sig[(other, r["grid"], r["component"])]
    with open(dst / "measurements.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    return dst


def test_sigmas_are_exchanged_channel_by_channel_between_the_two_cases_only():
    obs = Observations(((1, 1), (1, 2), (1, 1), (1, 2), (1, 1)), np.array([0, 0, 1, 1, 2]),
                       np.zeros(5), np.array([1.0, 2.0, 3.0, 4.0, 5.0]), ("A", "B", "C"))
    ex = with_sigmas_exchanged(obs, "A", "B")
    np.testing.assert_array_equal(ex.sigma, [3.0, 4.0, 1.0, 2.0, 5.0])
    np.testing.assert_array_equal(obs.sigma, [1.0, 2.0, 3.0, 4.0, 5.0])      # the input is left as it is
    # the same set of sigmas: the Gaussian likelihood's sum(log sigma) is unchanged
    assert np.sum(np.log(ex.sigma)) == pytest.approx(np.sum(np.log(obs.sigma)), rel=1e-15)
    assert with_sigmas_exchanged(obs, "A", "C") is None          # C reads one channel, A two
    assert with_sigmas_exchanged(obs, "A", "Z") is None


def test_exchanged_cases_whose_sigmas_stayed_are_one_exchange(swapped):
    r = dc.run(swapped, plots=False)
    d = r.diagnosis
    assert [(a.effect.kind, tuple(a.effect.where)) for a in d.added] == [("case_swap", ("L5", "L6"))]
    assert d.sigmas_exchanged == ("L5", "L6")
    assert d.band[0] <= d.final.reduced_chi2 <= d.band[1]
    a = r.document["added"][0]
    assert a["sigmas_exchanged"] is True and "sigmas stayed with the case labels" in a["pattern_detail"]
    # the first search is kept in brief: the swap and a case set aside, a higher BIC
    ex = r.document["sigma_exchange"]
    assert ex["cases"] == ["L5", "L6"] and ex["kept_exchanged"] and not ex["sigmas_exchanged"]
    assert ex["added"][0].startswith("case_swap") and len(ex["added"]) >= 2 and ex["bic"] > d.final.bic
    from blackbox.reports.diagnose import diagnosis_report
    assert "kept for its lower BIC" in diagnosis_report(r.study, r.document, [])
    # the result's rows carry the sigmas the search used
    moved = {(int(g), int(c), str(r.prepared.fit_obs.case_labels[k])): s for (g, c), k, s in
             zip(r.prepared.fit_obs.dofs, r.prepared.fit_obs.case_index, r.prepared.fit_obs.sigma)}
    with open(swapped / "measurements.csv", newline="") as f:
        listed = {(int(x["grid"]), int(x["component"]), x["case"]): float(x["sigma"]) for x in csv.DictReader(f)}
    g, c = next((g, c) for g, c, k in moved if k == "L5")
    assert moved[(g, c, "L5")] == listed[(g, c, "L6")] and moved[(g, c, "L6")] == listed[(g, c, "L5")]


def test_exchanged_cases_whose_sigmas_moved_along_need_no_second_search(swapped, tmp_path):
    r = dc.run(_moved_along(swapped, tmp_path), plots=False)
    d = r.diagnosis
    assert [(a.effect.kind, tuple(a.effect.where)) for a in d.added] == [("case_swap", ("L5", "L6"))]
    assert d.sigmas_exchanged is None and "sigmas_exchanged" not in r.document["added"][0]
    assert r.document["sigma_exchange"] is None
    assert d.band[0] <= d.final.reduced_chi2 <= d.band[1]


def test_an_exchange_a_later_addition_removed_is_still_tried():
    """Seed 47's portal: ``case_swap @ L4, L10`` added, then both cases set aside and the swap
    removed as no longer needed (the wrong weights left it a misfit); the search on the data with
    their sigmas exchanged ends with the swap alone (measured: BIC -18350 -> -19001, reduced
    chi2 0.931). The pair is taken from the step that added it."""
    from types import SimpleNamespace as NS

    from blackbox.diagnosis.effects.case_swap import CaseSwap
    from blackbox.diagnosis.exchange import swapped_pair
    swap = CaseSwap(("L4", "L10"), ("swap_L4_L10",))
    other = NS(kind="bad_case", where=("L10",))
    steps = (NS(added=NS(effect=swap)), NS(added=NS(effect=other)), NS(added=None))
    diag = NS(final=NS(spec=NS(effects=(other,))), steps=steps)
    assert swapped_pair(diag) is None
    assert swapped_pair(diag, added=True) == ("L4", "L10")
