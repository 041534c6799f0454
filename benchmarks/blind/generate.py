"""Random studies with one planted effect (or none) for the blind benchmark of ``blackbox diagnose``.

Method-free: this module builds structures (``blackbox.structures``), writes decks, solves them
with the reference solver and simulates measurements (``blackbox simulate``); it never calls the
identification or the diagnosis. What was planted is written beside the study, never into it.

One study (:func:`generate_study`):

* a random frame: a two-plane portal frame (1-3 bays, 1-2 storeys, beams with a midspan node),
  a ladder frame (rails, cross members with a midspan node, some braced bays), a space-frame box
  (up to 3 x 2 x 2 cells, some face diagonals), a tube body (``tube_body``) or a star frame
  (``star_joint_frame``); all members the same steel tube section;
* 1-2 flexible joints of 2-5 branches (2-3 each when there are two) at grids where exactly that
  many members meet (coincident branch grids tied by an RBE2 CM=123, GN = branch 1,
  ``FrameBuilder.flexible_joint``); two joints never share a member (a member between two
  free-rotation ends would spin about its axis in the declared deck); the truth of each is the
  simple model, every spring a random factor of the branch members' bending stiffness 4EI/L;
* 8-20 load cases (``random_loads``); in two studies of three about a fifth of them are hold-out
  cases, in the third none are declared (every case fitted; the diagnosis then checks additions by
  K-fold cross-validation over the load cases);
* sensors: every joint DOF and all six components of 3-8 random grids;
* noise: 1-5 % of each value, floored at 2-10 % of the case's largest value of the same kind;
* the planted effect, written into the truth deck ``truth/truth.bdf`` (deck effects) or applied
  to the simulated values (``sensor_gain``: a factor on one grid's values; ``sensor_offset``: a
  constant added to one channel, grid and component, in every case; ``load_scale`` of one case,
  or of a *test day*: a run of consecutive cases, a third to two thirds of them, whose loads were
  all off by one factor; ``load_scale`` of all cases is the truth's ``force_scale``). A study with
  a test day names the days in a ``group`` column of ``loads.csv`` half of the time (the planted
  day one group, the other cases another); otherwise the diagnosis must find the group from the
  data.

Detection threshold of a planted effect (computed from the noise-free responses, without the
diagnosis): the effect changes the noise-free measured values of the fitted cases by ``d``; the
part of ``d / sigma`` that the declared model cannot absorb is ``r = (I - P) d / sigma``, ``P``
the projector onto the declared joint parameters' sensitivities (log parameters, at the truth);
the noncentrality of the chi2 excess it causes is ``lambda = |r|^2``. A likelihood-ratio test of
the effect's ``p`` parameters at level ``alpha / M`` (``alpha = 0.01``, the diagnosis's default;
``M`` the number of candidate effects the study offers, a Bonferroni correction) rejects with
probability ``P(ncx2(p, lambda) > chi2_isf(alpha / M, p))``; the **threshold** is the
noncentrality ``lambda_1`` at which that probability is 0.5, and an effect of threshold multiple
``m`` is planted at the size whose noncentrality is ``m^2 lambda_1`` (for an effect linear in its
size, ``m`` is the ratio of the size to the threshold size). ``m`` is drawn log-uniformly from
0.5 to 5. A place where 5x would need an unphysical size (a member factor beyond 10, a gain
beyond 1.5, an offset beyond twice the channel's largest value, a coupling that loses positive
definiteness) is redrawn.

Run ``python -m benchmarks.blind.generate OUT --n 5`` to write five studies (``OUT/studies/sNNNN``
for the diagnosis, ``OUT/hidden/sNNNN`` with ``planted.json`` and the truth).
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import sys
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

import numpy as np
import scipy.sparse as sp
from scipy import optimize, stats

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from blackbox.commands import simulate as simulate_cmd                    # noqa: E402
from blackbox.joints import complex_params_from_kc, make_joint             # noqa: E402
from blackbox.simulation import NoiseConfig, noise_sigma                    # noqa: E402
from blackbox.structures import (FrameBuilder, TruthDeck, random_loads, star_joint_frame,  # noqa: E402
                                 tube_body, write_study)
from solver_adapters.bdf import read_deck_text                            # noqa: E402
from solver_adapters.bdf_write import write_deck                          # noqa: E402
from solver_adapters.deck import Deck, Mat1, PBar                         # noqa: E402
from solver_adapters.protocol import LoadMatrix                           # noqa: E402
from solver_adapters.reference import ReferenceAdapter                   # noqa: E402

KINDS = ("joint_coupling", "joint_translation", "undeclared_joint", "support_flexibility",
         "load_scale", "sensor_gain", "sensor_offset", "member_stiffness")
NONE = "none"
KIND_WEIGHTS = {NONE: 2.0, **{k: 1.0 for k in KINDS}}   # none-studies twice as often: false alarms
SHAPES = ("portal", "ladder", "box", "tube", "star")
ALPHA = 0.01                    # the diagnosis's default significance (after Bonferroni)
POWER_AT_THRESHOLD = 0.5        # the threshold: the noncentrality at which the test has this power
MULTIPLE_RANGE = (0.5, 5.0)     # threshold multiples, drawn log-uniformly
# largest physically sensible size per kind (beyond it the place is redrawn)
SIZE_MAX = {"load_scale": 0.5, "sensor_gain": 0.5, "sensor_offset": 2.0, "member_stiffness": math.log(10.0),
            "support_flexibility": 1.0e3, "undeclared_joint": 1.0e3, "joint_translation": 1.0e3,
            "joint_coupling": 0.9}
STEEL = dict(E=206.85e9, G=82.7e9, A=2.99e-4, I1=77.42e-8, I2=16.65e-8, J=35.40e-8)


# --------------------------------------------------------------------------------------------
# structures
# --------------------------------------------------------------------------------------------
def _portal(rng: np.random.Generator) -> FrameBuilder:
    """Two parallel multi-bay portal frames tied by beams at every floor; bases clamped."""
    f = FrameBuilder(**STEEL)
    nb, ns = int(rng.integers(1, 4)), int(rng.integers(1, 3))
    bay, h, depth = rng.uniform(0.8, 1.6), rng.uniform(0.8, 1.4), rng.uniform(0.6, 1.2)
    ids: dict[tuple, int] = {}

    def node(key, xyz):
        if key not in ids:
            ids[key] = f.grid(len(ids) + 1, xyz)
        return ids[key]
    for j in (0, 1):
        for i in range(nb + 1):
            for k in range(ns + 1):
                node(("n", i, k, j), (i * bay, j * depth, k * h))
    for j in (0, 1):
        for i in range(nb + 1):
            f.fix(ids[("n", i, 0, j)])
            for k in range(ns):
                f.bar(ids[("n", i, k, j)], ids[("n", i, k + 1, j)])
        for k in range(1, ns + 1):
            for i in range(nb):
                mid = node(("m", i, k, j), ((i + 0.5) * bay, j * depth, k * h))
                f.bar(ids[("n", i, k, j)], mid)
                f.bar(mid, ids[("n", i + 1, k, j)])
    for k in range(1, ns + 1):
        for i in range(nb + 1):
            f.bar(ids[("n", i, k, 0)], ids[("n", i, k, 1)])
    return f


def _ladder(rng: np.random.Generator) -> FrameBuilder:
    """A ladder (chassis) frame: two rails, cross members with a midspan node, some bays braced;
    clamped at the two front corners, vertically supported at the rear ones."""
    f = FrameBuilder(**STEEL)
    n = int(rng.integers(3, 7))
    length, width = rng.uniform(2.0, 4.0), rng.uniform(0.6, 1.2)
    rail = [[f.grid(1 + 2 * i + s, (length * i / (n - 1), s * width, 0.0)) for s in (0, 1)] for i in range(n)]
    nid = 2 * n + 1
    for i in range(n):
        mid = f.grid(nid, (length * i / (n - 1), 0.5 * width, 0.0))
        nid += 1
        f.bar(rail[i][0], mid)
        f.bar(mid, rail[i][1])
        if i + 1 < n:
            for s in (0, 1):
                f.bar(rail[i][s], rail[i + 1][s])
            if rng.random() < 0.4:
                f.bar(rail[i][0], rail[i + 1][1])
    f.fix(rail[0][0])
    f.fix(rail[0][1])
    f.fix(rail[-1][0], "3")
    f.fix(rail[-1][1], "3")
    return f


def _box(rng: np.random.Generator) -> FrameBuilder:
    """A space-frame box of nx x ny x nz cells (at most 6), some face diagonals; the four bottom
    corners supported (two clamped, two in translation)."""
    f = FrameBuilder(**STEEL)
    while True:
        nx, ny, nz = (int(v) for v in rng.integers(1, [4, 3, 3]))
        if nx * ny * nz <= 6 and nx * ny * nz > 1:
            break
    dx, dy, dz = rng.uniform(0.3, 0.8, 3)

    def gid(i, j, k):
        return 1 + i + (nx + 1) * (j + (ny + 1) * k)
    for k in range(nz + 1):
        for j in range(ny + 1):
            for i in range(nx + 1):
                f.grid(gid(i, j, k), (i * dx, j * dy, k * dz))
    for k in range(nz + 1):
        for j in range(ny + 1):
            for i in range(nx + 1):
                if i < nx:
                    f.bar(gid(i, j, k), gid(i + 1, j, k))
                if j < ny:
                    f.bar(gid(i, j, k), gid(i, j + 1, k))
                if k < nz:
                    f.bar(gid(i, j, k), gid(i, j, k + 1))
                    if i < nx and rng.random() < 0.2:
                        f.bar(gid(i, j, k), gid(i + 1, j, k + 1))
    corners = [gid(0, 0, 0), gid(nx, 0, 0), gid(nx, ny, 0), gid(0, ny, 0)]
    for c, comps in zip(corners, ["123456", "123", "123456", "123"]):
        f.fix(c, comps)
    return f


def _tube(rng: np.random.Generator) -> FrameBuilder:
    """A small car-body-like tube frame (``tube_body``) without its own joint."""
    n_long = int(rng.integers(4, 6))
    n_around = 6 if n_long == 5 else int(rng.choice([6, 8]))
    return tube_body(n_long, n_around, length=rng.uniform(2.0, 4.0), width=rng.uniform(1.0, 1.6),
                     height=rng.uniform(1.0, 1.5), with_joint=False)


def _members_at(f: FrameBuilder) -> dict[int, list[int]]:
    at: dict[int, list[int]] = {}
    for e, a, b, _ in f.bars:
        at.setdefault(a, []).append(e)
        at.setdefault(b, []).append(e)
    return at


def _neighbours(f: FrameBuilder, g: int) -> set[int]:
    return {b if a == g else a for _, a, b, _ in f.bars if g in (a, b)}


def _bending_ref(deck_or_f, eids) -> float:
    """Mean 4EI/L of the members ``eids`` (I the mean of the two planes): the joints' scale."""
    vals = []
    for e in eids:
        _, a, b, _ = deck_or_f.bars[e - 1]
        L = float(np.linalg.norm(np.subtract(deck_or_f.grids[a], deck_or_f.grids[b])))
        vals.append(4.0 * deck_or_f.E * 0.5 * (deck_or_f.I1 + deck_or_f.I2) / L)
    return float(np.mean(vals))


def build_structure(rng: np.random.Generator, shape: str) -> tuple[FrameBuilder, list[dict]]:
    """The frame of ``shape`` with its flexible joints; returns the builder and the joints' truth
    (name, grids, simple-model values)."""
    if shape == "star":
        n = int(rng.integers(2, 6))
        f = star_joint_frame(n, seed=int(rng.integers(2**31)), arm=rng.uniform(0.4, 0.8))
    else:
        f = {"portal": _portal, "ladder": _ladder, "box": _box, "tube": _tube}[shape](rng)
        n_joints = 1 if rng.random() < 0.65 else 2
        # two joints of at most 3 branches each: the diagnosis's complex-model candidates of two
        # 4- or 5-branch joints (45 or 78 parameters each) make one study cost about a minute
        max_branches = 5 if n_joints == 1 else 3
        taken: set[int] = set()
        for _ in range(n_joints):
            at = _members_at(f)
            ok = [g for g, es in at.items() if 2 <= len(es) <= max_branches and g not in f.spcs and g not in taken]
            if not ok:
                break
            degrees = sorted({len(at[g]) for g in ok})
            deg = int(rng.choice(degrees))
            node = int(rng.choice([g for g in ok if len(at[g]) == deg]))
            bars = list(rng.permutation(at[node]))
            f.flexible_joint(f"J{node}", node, [int(b) for b in bars], max(f.grids) + 1)
            # the next joint shares no member with this one
            taken |= {node} | _neighbours(f, node) | {g for _, gs in f.joints[-1:] for g in gs}
            for g in f.joints[-1][1]:
                taken |= _neighbours(f, g)
    joints = []
    for name, grids in f.joints:
        at = _members_at(f)
        eids = [at[g][0] for g in grids]
        k_joint = _bending_ref(f, eids) * 10 ** rng.uniform(-0.7, 0.3)
        model = make_joint(name, grids, "simple")
        values = k_joint * np.exp(0.3 * rng.standard_normal(model.n_params))
        joints.append({"name": name, "grids": [int(g) for g in grids], "k": float(k_joint),
                       "values": [float(v) for v in values]})
    return f, joints


# --------------------------------------------------------------------------------------------
# deck edits of the truth
# --------------------------------------------------------------------------------------------


def coupled_kc(grids, simple_values, rho: np.ndarray, t: float) -> np.ndarray:
    """``K_C = S^1/2 (I + t rho) S^1/2``: the simple model's ``K_C`` (``S``) coupled by the
    symmetric zero-diagonal ``rho`` of spectral norm 1; positive definite for ``t < 1``."""
    K_U = make_joint("J", grids, "simple").unconstrained_matrix(simple_values)
    m = 3 * len(grids) - 3
    S = K_U[:m, :m]
    w, V = np.linalg.eigh(S)
    half = V @ np.diag(np.sqrt(np.maximum(w, 0.0))) @ V.T
    K = half @ (np.eye(m) + t * rho) @ half
    return 0.5 * (K + K.T)


def plant_deck(truth: TruthDeck, kind: str, where, size: float, sign: float, extra: dict) -> None:
    """Edit the effect ``kind`` of ``size`` into the truth deck (deck effects only)."""
    d = truth.deck
    if kind == "support_flexibility":
        g = int(where)
        comps = truth.unclamp(g)
        local = sum(truth.k_diag(e, g) for e in truth.members_at(g))
        for c in sorted(set(comps)):
            truth.spring(local[int(c) - 1] / size, g, int(c))
    elif kind == "undeclared_joint":
        g = int(where)
        ref = np.min([truth.k_diag(e, g)[3:] for e in truth.members_at(g)], axis=0)
        branches = truth.split_grid(g)
        for c in (4, 5, 6):
            for i in range(len(branches)):
                for j in range(i + 1, len(branches)):
                    truth.spring(ref[c - 4] / size, branches[i], c, branches[j], c)
    elif kind == "joint_translation":
        grids = extra["grids"]
        truth.untie_translations(grids)
        ref = np.min([truth.k_diag(truth.members_at(g)[0], g)[:3] for g in grids], axis=0)
        for c in (1, 2, 3):
            for i in range(len(grids)):
                for j in range(i + 1, len(grids)):
                    truth.spring(ref[c - 1] / size, grids[i], c, grids[j], c)
    elif kind == "member_stiffness":
        eid = int(where)
        b = d.cbars[eid]
        p, m = d.pbars[b.pid], d.mat1s[d.pbars[b.pid].mid]
        factor = math.exp(sign * size)
        mid, pid = max(d.mat1s) + 1, max(d.pbars) + 1
        d.mat1s[mid] = Mat1(mid, m.e * factor, m.g * factor, m.nu)
        d.pbars[pid] = PBar(pid, mid, p.a, p.i1, p.i2, p.j)
        d.cbars[eid] = replace(b, pid=pid)
    elif kind != "joint_coupling":              # coupling: the joint's springs, see truth_deck
        raise ValueError(f"{kind} is not a deck effect")


DECK_KINDS = ("joint_coupling", "joint_translation", "undeclared_joint", "support_flexibility", "member_stiffness")


def truth_deck(declared: Deck, joints: list[dict], kind: str, where=None, size: float = 0.0,
               sign: float = 1.0, extra: dict | None = None) -> Deck:
    """The declared deck with the joints' truth springs and, for a deck effect, the effect."""
    t = TruthDeck(declared)
    for j in joints:
        if kind == "joint_coupling" and j["name"] == where and size > 0:
            kc = coupled_kc(j["grids"], j["values"], np.asarray(extra["rho"]), size)
            t.joint(j["name"], j["grids"], "complex", complex_params_from_kc(kc))
        else:
            t.joint(j["name"], j["grids"], "simple", j["values"])
    if kind in DECK_KINDS and kind != "joint_coupling" and size > 0:
        plant_deck(t, kind, where, size, sign, extra or {})
    return t.deck


# --------------------------------------------------------------------------------------------
# noise-free responses, the declared model's sensitivities and the noncentrality
# --------------------------------------------------------------------------------------------
def load_matrix(loads: list[tuple[str, int, int, float]]) -> LoadMatrix:
    cases = list(dict.fromkeys(r[0] for r in loads))
    dofs = list(dict.fromkeys((r[1], r[2]) for r in loads))
    di, ci = {d: i for i, d in enumerate(dofs)}, {c: i for i, c in enumerate(cases)}
    V = sp.lil_matrix((len(dofs), len(cases)))
    for c, g, comp, v in loads:
        V[di[(g, comp)], ci[c]] = v
    return LoadMatrix(tuple(dofs), sp.csc_matrix(V), tuple(cases))


@dataclass
class Response:
    """The noise-free truth without the effect at the measured DOFs (all cases), the fitted
    rows' sigma and the declared model's whitened sensitivity basis ``Q`` (orthonormal)."""
    U0: np.ndarray               # (n_dofs, n_cases)
    dofs: list[tuple[int, int]]
    fit_cases: np.ndarray        # column indices of the fitted cases
    sigma: np.ndarray            # (n_dofs, n_fit) of the fitted rows
    Q: np.ndarray                # (n_dofs * n_fit, r)

    def whitened(self, U: np.ndarray) -> np.ndarray:
        """``(U - U0) / sigma`` on the fitted rows, flattened."""
        return ((U[:, self.fit_cases] - self.U0[:, self.fit_cases]) / self.sigma).ravel()

    def noncentrality(self, r: np.ndarray) -> float:
        return float(r @ r - np.sum((self.Q.T @ r) ** 2))


def declared_response(declared: Deck, joints: list[dict], lm: LoadMatrix, dofs, fit_cases,
                      noise: NoiseConfig) -> Response:
    """One batched solve of the effect-free truth: the case loads and unit moments at every joint
    rotation DOF (their columns give the simple springs' sensitivities exactly:
    ``du/dk = -(G_a - G_b)(u_a - u_b)`` for a spring ``k`` between DOFs ``a`` and ``b``)."""
    deck = truth_deck(declared, joints, NONE)
    rot = [(g, c) for j in joints for g in j["grids"] for c in (4, 5, 6)]
    unit = sp.identity(len(rot), format="csc")
    n_c = len(lm.cases)
    all_dofs = list(dict.fromkeys(list(lm.dofs) + rot))
    V = sp.lil_matrix((len(all_dofs), n_c + len(rot)))
    idx = {d: i for i, d in enumerate(all_dofs)}
    Lc = lm.values.tocoo()
    for i, j, v in zip(Lc.row, Lc.col, Lc.data):
        V[idx[lm.dofs[i]], j] = v
    for q, d in enumerate(rot):
        V[idx[d], n_c + q] = unit[q, q]
    report = list(dict.fromkeys(list(dofs) + rot))
    out = ReferenceAdapter(deck).solve(LoadMatrix(tuple(all_dofs), sp.csc_matrix(V),
                                                  tuple(lm.cases) + tuple(f"u{q}" for q in range(len(rot)))), report)
    rix = {d: i for i, d in enumerate(report)}
    mi = [rix[d] for d in dofs]
    U0 = out.values[mi, :n_c]
    G = out.values[:, n_c:]
    fc = np.asarray(fit_cases)
    kinds = np.array([1 if d[1] >= 4 else 0 for d in dofs])
    for kind in (0, 1):                 # every case must move the measured DOFs of each kind:
        peak = np.abs(U0[kinds == kind]).max(axis=0)  # else its noise floor is rounding noise
        if np.any(peak < 1e-6 * peak.max()):
            raise ValueError("a load case leaves the measured DOFs of one kind at rest")
    true = U0[:, fc]
    ci = np.broadcast_to(np.arange(len(fc))[None, :], true.shape)
    sigma = noise_sigma(true.ravel(), np.broadcast_to(kinds[:, None], true.shape).ravel(), ci.ravel(),
                        noise).reshape(true.shape)
    cols = []
    rq = {d: q for q, d in enumerate(rot)}
    for j in joints:
        g = j["grids"]
        model = make_joint(j["name"], g, "simple")
        for (plane, i_a, i_b), k in zip(model.springs, j["values"]):
            c = "xyz".index(plane) + 4
            a, b = (g[i_a - 1], c), (g[i_b - 1], c)
            du = out.values[rix[a], :n_c] - out.values[rix[b], :n_c]
            dG = G[mi, rq[a]] - G[mi, rq[b]]
            cols.append((-k * np.outer(dG, du)[:, fc] / sigma).ravel())
    J = np.array(cols).T
    Us, s, _ = np.linalg.svd(J, full_matrices=False)
    Q = Us[:, s > 1e-10 * s.max()] if s.size else np.zeros((J.shape[0], 0))
    return Response(U0, list(dofs), fc, sigma, Q)


def threshold_noncentrality(p: int, m_candidates: int, alpha: float = ALPHA,
                            power: float = POWER_AT_THRESHOLD) -> float:
    """The noncentrality at which a ``p``-parameter chi2 test at level ``alpha / m`` has ``power``."""
    crit = stats.chi2.isf(alpha / m_candidates, p)
    return float(optimize.brentq(lambda lam: stats.ncx2.sf(crit, p, lam) - power, 1e-9, 50 * crit + 200))


# --------------------------------------------------------------------------------------------
# one study
# --------------------------------------------------------------------------------------------
def _effect_params(kind: str, n_branches: int, n_support_comps: int) -> int:
    return {"joint_coupling": 3 * (n_branches - 1) * (3 * n_branches - 2) // 2 - 3 * n_branches * (n_branches - 1) // 2,
            "joint_translation": 3, "undeclared_joint": 3, "support_flexibility": n_support_comps,
            "load_scale": 1, "sensor_gain": 1, "sensor_offset": 1, "member_stiffness": 1}[kind]


def candidate_places(deck: Deck, joints: list[dict], measured_grids: list[int], fit_labels: list[str],
                     all_labels: list[str], channels: list[tuple[int, int]] = ()) -> dict[str, list]:
    """Where each kind can be planted (and, counted, the Bonferroni ``M``)."""
    at: dict[int, list[int]] = {}
    for e, b in deck.cbars.items():
        at.setdefault(b.ga, []).append(e)
        at.setdefault(b.gb, []).append(e)
    constrained: dict[int, str] = {}
    for s in deck.spc1s:
        for g in s.grids:
            constrained[g] = "".join(sorted(set(constrained.get(g, "") + s.components)))
    in_rbe2 = {g for r in deck.rbe2s.values() for g in (r.gn, *r.gm)}
    declared = {g for j in joints for g in j["grids"]}
    return {
        "joint_coupling": [j["name"] for j in joints],
        "joint_translation": [j["name"] for j in joints],
        "undeclared_joint": [g for g in sorted(at) if len(at[g]) >= 2 and g not in declared
                             and g not in constrained and g not in in_rbe2],
        "support_flexibility": [g for g in sorted(constrained) if g in at and g not in in_rbe2],
        "load_scale": [tuple(all_labels)] + [(c,) for c in fit_labels] + test_days(all_labels, fit_labels),
        "sensor_gain": list(measured_grids),
        "sensor_offset": list(channels),
        "member_stiffness": sorted(deck.cbars),
    }


def test_days(all_labels: list[str], fit_labels: list[str]) -> list[tuple[str, ...]]:
    """The runs of consecutive cases that can be a planted test day: a third to two thirds of the
    cases, with at least two fitted cases."""
    n = len(all_labels)
    out = []
    for k in range(max(2, math.ceil(n / 3)), max(2, (2 * n) // 3) + 1):
        for i in range(0, n - k + 1):
            day = tuple(all_labels[i:i + k])
            if sum(c in fit_labels for c in day) >= 2:
                out.append(day)
    return out


def found_group_candidates(n_fit: int) -> int:
    """How many load-scale groups the diagnosis finds from the data for ``n_fit`` fitted cases
    (``blackbox.diagnosis.effects.load_scale``): 2 (n - 2)."""
    return max(0, 2 * (n_fit - 2))


def _solve_size(lam: Callable[[float], float], target: float, s_max: float, s0: float) -> tuple[float, float] | None:
    """The size ``s`` with ``lam(s) = target`` (``lam`` ~ s^2 for small s), or None beyond ``s_max``."""
    l0 = lam(s0)
    if not l0 > 0:
        return None
    s = s0 * math.sqrt(target / l0)
    for _ in range(10):
        if s > s_max:
            return None
        val = lam(s)
        if not val > 0:
            return None
        if abs(val / target - 1.0) < 0.01:
            return s, val
        s *= math.sqrt(target / val) if val < 4 * target else 0.5
    return (s, val) if abs(val / target - 1.0) < 0.05 else None


@dataclass
class Study:
    """A generated study: its folder (what the diagnosis sees) and the hidden record."""
    index: int
    folder: Path
    hidden: Path
    planted: dict


def generate_study(index: int, seed: int, out: Path, kind: str | None = None, shape: str | None = None,
                   multiple: float | None = None) -> Study:
    """Write study ``index`` (seeded by ``seed`` and ``index``) into ``out/studies/sNNNN`` and its
    truth and ``planted.json`` into ``out/hidden/sNNNN``. ``kind``/``shape``/``multiple`` force a
    choice (the random draws stay the same, so the rest of the study does not change)."""
    rng = np.random.default_rng([seed, index])
    if kind is None:
        names = list(KIND_WEIGHTS)
        w = np.array([KIND_WEIGHTS[k] for k in names])
        kind = str(rng.choice(names, p=w / w.sum()))
    for attempt in range(30):
        drawn_shape = str(rng.choice(SHAPES))
        res = _try_study(rng, index, kind, shape or drawn_shape, multiple)
        if res is not None:
            break
    else:
        raise RuntimeError(f"study {index}: no place found for {kind} in 30 structures")
    builder, joints, loads, holdout, measured, noise, plan = res
    plan["attempts"] = attempt + 1
    name = f"s{index:04d}"
    folder, hidden = Path(out) / "studies" / name, Path(out) / "hidden" / name
    for p in (folder, hidden):
        if p.exists():
            shutil.rmtree(p)
    hidden.mkdir(parents=True)
    initial = float(np.exp(np.mean([math.log(j["k"]) for j in joints])) * 10 ** rng.uniform(-0.5, 0.5))
    write_study(folder, builder, loads, f"blind-{name}", model="simple", initial=float(f"{initial:.3g}"))
    with (folder / "study.toml").open("a") as fh:
        fh.write(f"[identification]\nholdout_cases = {json.dumps(holdout)}\n")
    if plan.get("group_column"):
        day = set(plan["where"])
        with (folder / "loads.csv").open("w") as fh:
            fh.write("case,grid,component,value,group\n")
            for case, g, c, v in loads:
                fh.write(f"{case},{g},{c},{v!r},{'day2' if case in day else 'day1'}\n")
    declared = read_deck_text((folder / "model.bdf").read_text(), str(folder / "model.bdf"))
    truth = truth_deck(declared, joints, plan["kind"], plan.get("where"), plan.get("size", 0.0),
                       plan.get("sign", 1.0), plan.get("extra"))
    (hidden / "truth").mkdir()
    (hidden / "truth" / "truth.bdf").write_text(write_deck(truth, "large"))
    force_scale = plan["factor"] if plan["kind"] == "load_scale" and plan["group"] == "all" else 1.0
    away = sorted(set(measured) - {j["grids"][0] for j in joints})
    (hidden / "truth" / "truth.toml").write_text("\n".join([
        f"seed = {int(rng.integers(2**31))}", 'deck = "truth.bdf"', f"force_scale = {force_scale!r}", "",
        "[noise]", f"relative = {noise.relative!r}", f"floor = {noise.floor!r}", "",
        "[measure]", "joint = true", f"away_grids = {away}", ""]))
    sim = simulate_cmd.run(folder, hidden / "truth" / "truth.toml", adapter="reference")
    rows = list(sim.rows)
    if plan["kind"] == "sensor_gain":
        rows = [(c, g, comp, v * plan["factor"] if g == plan["where"] else v, s_, r)
                for c, g, comp, v, s_, r in rows]
    elif plan["kind"] == "sensor_offset":
        rows = [(c, g, comp, v + plan["offset"] if (g, comp) == (plan["where"], plan["component"]) else v, s_, r)
                for c, g, comp, v, s_, r in rows]
    elif plan["kind"] == "load_scale" and plan["group"] != "all":
        rows = [(c, g, comp, v * plan["factor"] if c in plan["where"] else v, s_, r)
                for c, g, comp, v, s_, r in rows]
    (folder / "measurements.csv").write_text(replace(sim, rows=rows).measurements_csv())
    (hidden / "truth.json").write_text(json.dumps({**sim.record, "truth_file": "truth/truth.toml"}, indent=2))
    planted = {"study": name, "index": index, "seed": seed, **plan, "joints": joints,
               "holdout_cases": holdout, "measured_grids": measured,
               "noise": {"relative": noise.relative, "floor": noise.floor},
               "n_cases": len(dict.fromkeys(r[0] for r in loads)), "n_members": len(declared.cbars),
               "n_grids": len(declared.grids), "n_measurements": len(rows),
               "note": "blind benchmark: blackbox diagnose never reads this file or truth/"}
    (hidden / "planted.json").write_text(json.dumps(planted, indent=2, default=_json_default))
    return Study(index, folder, hidden, json.loads((hidden / "planted.json").read_text()))


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o))


def _try_study(rng: np.random.Generator, index: int, kind: str, shape: str, forced_multiple: float | None = None):
    """One draw of structure, loads, sensors and noise with the effect placed and sized; None
    when no place of ``kind`` reaches 5x its threshold within the physical sizes."""
    builder, joints = build_structure(rng, shape)
    if not joints:
        return None
    n_cases = int(rng.integers(8, 21))
    loads = random_loads(builder, n_cases, seed=int(rng.integers(2**31)), per_case=int(rng.integers(1, 4)))
    labels = list(dict.fromkeys(r[0] for r in loads))
    n_hold = max(2, round(0.2 * len(labels))) if rng.random() < 2.0 / 3.0 else 0
    holdout = sorted(rng.choice(labels, size=n_hold, replace=False).tolist(), key=labels.index)
    fit_labels = [c for c in labels if c not in holdout]
    joint_grids = {g for j in joints for g in j["grids"]}
    free = [g for g in sorted(builder.grids) if g not in joint_grids and builder.spcs.get(g) != "123456"]
    n_away = min(len(free), int(rng.integers(3, 9)))
    away = sorted(int(g) for g in rng.choice(free, size=n_away, replace=False))
    measured = sorted({j["grids"][0] for j in joints} | set(away))
    dofs = [(g, c) for j in joints for g in j["grids"]
            for c in ((1, 2, 3, 4, 5, 6) if g == j["grids"][0] else (4, 5, 6))]
    dofs = list(dict.fromkeys(dofs + [(g, c) for g in away for c in range(1, 7)]))
    noise = NoiseConfig(relative=float(rng.uniform(0.01, 0.05)), floor=float(rng.uniform(0.02, 0.10)))
    declared = read_deck_text(builder.bdf("blind"), "<blind>")
    lm = load_matrix(loads)
    fit_cases = [labels.index(c) for c in fit_labels]
    try:
        # the declared deck (joint rotations free) must not be a mechanism: a chain of members
        # between two joints could spin about its axis
        ReferenceAdapter(declared).solve(lm, dofs[:1])
        resp = declared_response(declared, joints, lm, dofs, fit_cases, noise)
    except Exception:           # a mechanism, or a case that moves no measured DOF of one kind
        return None
    places = candidate_places(declared, joints, measured, fit_labels, labels, dofs)
    group_column = bool(rng.random() < 0.5)
    # the candidates the diagnosis offers (its Bonferroni M): not the test days (places to plant),
    # but two groups from a group column, or the groups it finds from the data
    n_candidates = (sum(len(v) for k, v in places.items() if k != "load_scale") + 1 + len(fit_labels)
                    + (2 if group_column else found_group_candidates(len(fit_labels))))
    plan: dict = {"kind": kind, "shape": shape, "n_candidates": n_candidates,
                  "n_joints": len(joints), "branches": [len(j["grids"]) for j in joints],
                  "holdout": bool(holdout)}
    if kind == NONE:
        return builder, joints, loads, holdout, measured, noise, plan
    multiple = float(math.exp(rng.uniform(*np.log(MULTIPLE_RANGE))))
    if forced_multiple is not None:
        multiple = float(forced_multiple)
    constrained = {g: c for g, c in builder.spcs.items()}
    pool = places[kind]
    if kind == "load_scale":        # all cases, one case or a test day, a third of the studies each
        which = str(rng.choice(["all", "case", "day"]))
        pool = [w for w in pool if (len(w) == len(labels)) == (which == "all")
                and (len(w) == 1) == (which == "case")]
    order = list(rng.permutation(len(pool)))
    for pi in order[:12]:
        where = pool[pi]
        sign = float(rng.choice([-1.0, 1.0]))
        extra: dict = {}
        if kind in ("joint_coupling", "joint_translation"):
            j = next(j for j in joints if j["name"] == where)
            extra["grids"] = j["grids"]
            n_br = len(j["grids"])
            if kind == "joint_coupling":
                m = 3 * n_br - 3
                R = rng.standard_normal((m, m))
                R = R + R.T
                np.fill_diagonal(R, 0.0)
                extra["rho"] = R / np.linalg.norm(R, 2)
        else:
            n_br = 0
        p = _effect_params(kind, n_br, len(constrained.get(where, "")) if kind == "support_flexibility" else 0)
        lam1 = threshold_noncentrality(p, n_candidates)
        lam = _lambda_fn(kind, where, sign, extra, declared, joints, lm, resp, labels)
        s0 = {"load_scale": 1e-3, "sensor_gain": 1e-3, "member_stiffness": 1e-3, "joint_coupling": 1e-3}.get(kind, 1e-4)
        top = _solve_size(lam, MULTIPLE_RANGE[1] ** 2 * lam1, SIZE_MAX[kind], s0)
        if top is None:
            continue
        one = _solve_size(lam, lam1, SIZE_MAX[kind], s0)
        hit = _solve_size(lam, multiple ** 2 * lam1, SIZE_MAX[kind], s0)
        if one is None or hit is None:
            continue
        size, lam_size = hit
        plan.update({"where": list(where) if isinstance(where, tuple) else where, "sign": sign,
                     **({"where": where[0], "component": where[1]} if kind == "sensor_offset" else {}),
                     "size": size, "threshold_size": one[0], "multiple": math.sqrt(lam_size / lam1),
                     "multiple_drawn": multiple, "noncentrality": lam_size, "threshold_noncentrality": lam1,
                     "params": p, "extra": {k: v for k, v in extra.items()}})
        plan.update(_describe(kind, where, size, sign, labels, resp))
        if kind == "load_scale" and plan["group"] != "all":
            plan["where"] = list(where)
            if plan["group"] == "day":
                plan["group_column"] = group_column
        return builder, joints, loads, holdout, measured, noise, plan
    return None


def _describe(kind: str, where, size: float, sign: float, labels: list[str], resp: "Response") -> dict:
    """The planted size in physical terms."""
    if kind == "sensor_offset":
        return {"offset": sign * size * _channel_scale(resp, where)}
    if kind in ("load_scale", "sensor_gain"):
        out = {"factor": 1.0 + sign * size}
        if kind == "load_scale":
            out["group"] = "all" if len(where) == len(labels) else ("case" if len(where) == 1 else "day")
        return out
    if kind == "member_stiffness":
        return {"factor": math.exp(sign * size)}
    if kind == "joint_coupling":
        return {"coupling": size}
    return {"compliance_ratio": size, "stiffness_factor": 1.0 / size}


def _channel_scale(resp: "Response", channel) -> float:
    """An offset's unit: the channel's largest noise-free |value| over the cases."""
    return float(np.abs(resp.U0[resp.dofs.index(tuple(channel))]).max())


def _lambda_fn(kind, where, sign, extra, declared, joints, lm, resp: Response, labels) -> Callable[[float], float]:
    """``lambda(size)``: the noncentrality of the effect of ``size`` at ``where``."""
    if kind == "sensor_offset":
        base = np.zeros_like(resp.U0)
        base[resp.dofs.index(tuple(where))] = _channel_scale(resp, where)
        r1 = resp.whitened(resp.U0 + base)
        return lambda s: s * s * resp.noncentrality(r1)
    if kind == "sensor_gain":
        rows = np.array([d[0] == where for d in resp.dofs])
        base = np.zeros_like(resp.U0)
        base[rows] = resp.U0[rows]
        r1 = resp.whitened(resp.U0 + base)
        return lambda s: s * s * resp.noncentrality(r1)
    if kind == "load_scale":
        cols = [labels.index(c) for c in where]
        base = np.zeros_like(resp.U0)
        base[:, cols] = resp.U0[:, cols]
        r1 = resp.whitened(resp.U0 + base)
        return lambda s: s * s * resp.noncentrality(r1)
    cache: dict[float, float] = {}

    def lam(s: float) -> float:
        if s not in cache:
            deck = truth_deck(declared, joints, kind, where, s, sign, extra)
            try:
                U = ReferenceAdapter(deck).solve(lm, resp.dofs).values
            except Exception:           # a size that makes the structure a mechanism: no value
                return float("nan")
            cache[s] = resp.noncentrality(resp.whitened(U))
        return cache[s]
    return lam


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--n", type=int, default=5)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--kind", choices=(NONE,) + KINDS)
    args = ap.parse_args(argv)
    for i in range(args.n):
        st = generate_study(i, args.seed, args.out, kind=args.kind)
        p = st.planted
        print(f"{st.folder.name}: {p['shape']}, joints {p['branches']}, {p['kind']}"
              + (f" @ {p['where']} x{p['multiple']:.2f}" if p["kind"] != NONE else ""))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
