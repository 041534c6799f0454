"""Random studies with planted effects (or none) for the blind benchmark of ``blackbox diagnose``.

Method-free: this module builds structures (:mod:`benchmarks.blind.frames`), writes decks, solves
them with the reference solver and simulates measurements (the noise model of
``blackbox.simulation``); it never calls the identification or the diagnosis. What was planted
is written beside the study (``hidden/``), never into it.

One study (:func:`generate_study`):

* a frame of one of the families of :mod:`benchmarks.blind.frames` (ladder, truss, storey, tube,
  imported, portal, box, star, hall, bus; ``jacket`` is held out of all tuning: :func:`study_family`
  draws it too, and ``run.py`` runs its studies only with ``--include-held-out``);
* written in one of three styles: ``plain`` (the project's own writing, two studies of three),
  ``user`` (a user's bulk data: CORD2R/CORD1R chains, grids in CP and CD systems, GRDSET,
  PBARL, CBAR vectors and offsets in the grids' systems, CONM2, SPC1 sets combined by an
  SPCADD) or ``import`` (a whole user's input file whose case control selects the SPCADD, with
  a further SPC1 set it does not select and the load cases as FORCE/MOMENT cards, made into the
  study by ``blackbox import``); a few percent of the studies name ``adapter = "mystran"``;
* 1-3 flexible joints (1: 2-6 branches, 2: up to 4 each, 3: up to 3 each) at grids where that
  many bars meet (coincident branch grids tied by an RBE2 CM=123, in the grid's CD); two joints
  never share or touch a member; the truth of each is the simple model, every spring a random
  factor of the branch members' bending stiffness 4EI/L;
* 8-20 load cases on free grids, components in the grids' CD systems (random forces and moments,
  or on a frame that has them a test rig's cases, the bus's, or a design analysis's, the
  jacket's); in two studies of three a
  fifth of them are hold-out cases, in the third none (the diagnosis then checks additions by
  K-fold cross-validation over the load cases);
* sensors: every joint DOF and all six components of 4-10 random grids;
* noise: 1-5 % of each value, floored at 2-10 % of the case's largest value of the same kind;
* none, one or (in about 15 % of the effect studies) two planted effects of different kinds at
  different places (:data:`ALL_KINDS`; on a frame with one joint, not two at joints).
  Structural effects are edited into the truth deck ``truth/truth.bdf``; the others act on the
  readings:

  - ``sensor_gain``: a factor on one grid's values; ``sensor_offset``: a constant added to one
    channel (grid, component) in every case; ``load_scale``: all cases (the truth's
    ``force_scale``), one case, or a test day (a run of consecutive cases whose loads were all
    off by one factor; named by a ``group`` column of ``loads.csv`` half of the time);
  - ``outlier``: one reading (a fitted case c, grid g, component k) off by ``b``;
  - ``sign_flip``: one channel (g, k) negated in every case (``y = -u + noise``);
  - ``channel_swap``: the values of the channels (g1, k) and (g2, k), g1 < g2, exchanged in
    every case;
  - ``misplaced_sensor``: the channels of grid g (one, or all six) really read at a grid h joined
    to g by one member: ``u(h, k) + noise`` in every case;
  - ``joint_gap``: a declared joint whose springs are softer on one side: in each load case each
    spring m has stiffness ``k_m`` when its relative rotation (branch i minus branch j about its
    axis) is >= 0 and ``r k_m`` when it is < 0, one ``r`` in [0.05, 20] per joint; the truth is
    solved per case by iterating the signs until they settle (:func:`gap_response`; a case
    whose signs cycle is reported and the draw repeated).

  The readings' defects act on what the gauge saw (its noise is that of the value read, as a
  rig's own sigma would be); gains, offsets, load scales and the outlier on the noisy values.
  Misplaced and swapped channels, sign flips and outliers are placed on the fitted data.

Placement: in half of the studies of the kinds that have such places, the effect goes where
something else could mimic it: an undeclared joint one grid away from a declared joint, a
member factor on a member framing into a joint or a support, a flexible support where one bar
ends (a factor on that bar could stand in) (``planted.json``: ``placement``).

Detection threshold of a planted effect (computed from the noise-free responses, without the
diagnosis): the effect changes the noise-free measured values of the fitted cases by ``d``; the
part of ``d / sigma`` that the declared model cannot absorb is ``r = (I - P) d / sigma``, ``P``
the projector onto the declared joint parameters' sensitivities (log parameters, at the truth);
the noncentrality of the chi2 excess it causes is ``lambda = |r|^2``. A likelihood-ratio test of
the effect's ``p`` parameters at the level the diagnosis spends on one hypothesis of its kind in
its first round, ``alpha / (2 K M_k)`` (``alpha = 0.01``, the diagnosis's default; ``K`` the
kinds the study offers candidates of, ``M_k`` the candidates of the effect's kind, data defects
included: each fitted reading an outlier, each channel a sign flip, each pair of channels of one
component a swap, each grid-neighbour pair a misplaced sensor in seven ways; see
``blackbox.diagnosis.search.multipliers``)
rejects with probability ``P(ncx2(p, lambda) > chi2_isf(alpha / M, p))`` (a test day with no
group column, which the diagnosis must find from the data: ``P(ncx2(1, lambda) > t)`` with ``t``
the critical value of the found groups' bound, ``blackbox.diagnosis.effects.load_scale``, at the
same level; the found groups count as one hypothesis in ``M``); the **threshold** is
the noncentrality ``lambda_1`` at which that probability is 0.5, and an effect of threshold
multiple ``m`` has noncentrality ``m^2 lambda_1``. Continuous effects are planted at the size
whose noncentrality is that of a multiple drawn log-uniformly within a size bin (the bins
0.5-1, 1-2, 2-5 and 5-20x drawn equally often); a place where that multiple would need an
unphysical size (a member factor beyond 10, a gain beyond 1.5, an offset beyond twice the
channel's largest value, a coupling that loses positive definiteness, a gap ratio beyond
20) is redrawn. A discrete defect (sign flip, swap, misplaced sensor) has the size its place
gives it, its multiple computed the same way with ``p = 1`` (the one parameter that mixes the
declared reading with the defective one); the place is chosen among those whose multiple falls in
the drawn bin (the nearest bin that has one when none does; beyond 20x when every place is).

Run ``python -m benchmarks.blind.generate OUT --n 5`` to write five studies (``OUT/studies/sNNNN``
for the diagnosis, ``OUT/hidden/sNNNN`` with ``planted.json`` and the truth).
"""

from __future__ import annotations

import argparse
import itertools
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

from benchmarks.blind import frames as fr                                 # noqa: E402
from blackbox.diagnosis.effects.load_scale import found_group_log_sf       # noqa: E402
from blackbox.joints import complex_params_from_kc, joint_dofs, make_joint  # noqa: E402
from blackbox.simulation import NoiseConfig, noise_sigma, simulate_rows     # noqa: E402
from blackbox.structures import TruthDeck                                 # noqa: E402
from solver_adapters.bdf import read_deck_text                            # noqa: E402
from solver_adapters.bdf_write import write_deck                          # noqa: E402
from solver_adapters.deck import Deck, Mat1                               # noqa: E402
from solver_adapters.protocol import LoadMatrix                           # noqa: E402
from solver_adapters.reference import ReferenceAdapter                   # noqa: E402

KINDS = ("joint_coupling", "joint_translation", "undeclared_joint", "support_flexibility",
         "load_scale", "sensor_gain", "sensor_offset", "member_stiffness")
DATA_KINDS = ("outlier", "sign_flip", "channel_swap", "misplaced_sensor", "joint_gap")
ALL_KINDS = KINDS + DATA_KINDS
DISCRETE = ("sign_flip", "channel_swap", "misplaced_sensor")
NONE = "none"
KIND_WEIGHTS = {NONE: 2.0, **{k: 1.0 for k in ALL_KINDS}}   # none-studies twice as often: false alarms
TWO_EFFECTS = 0.15              # share of the effect studies with two effects
STYLES = {"plain": 2 / 3, "user": 1 / 6, "import": 1 / 6}
MYSTRAN_SHARE = 0.03            # studies whose study.toml names adapter = "mystran"
ALPHA = 0.01                    # the diagnosis's default significance (after Bonferroni)
POWER_AT_THRESHOLD = 0.5        # the threshold: the noncentrality at which the test has this power
BINS = ((0.5, 1.0), (1.0, 2.0), (2.0, 5.0), (5.0, 20.0))
BIN_NAMES = ("0.5-1x", "1-2x", "2-5x", "5-20x")
OVER = ">20x"                   # the bin of a discrete defect no place of which is within 20x
# largest physically sensible size per kind (beyond it the place is redrawn)
SIZE_MAX = {"load_scale": 0.5, "sensor_gain": 0.5, "sensor_offset": 2.0, "member_stiffness": math.log(10.0),
            "support_flexibility": 1.0e3, "undeclared_joint": 1.0e3, "joint_translation": 1.0e3,
            "joint_coupling": 0.9, "outlier": 1.0e3, "joint_gap": math.log(20.0)}
DECK_KINDS = ("joint_coupling", "joint_translation", "undeclared_joint", "support_flexibility", "member_stiffness")
JOINT_KINDS = ("joint_coupling", "joint_translation", "joint_gap")
MAX_BRANCHES = {1: 6, 2: 4, 3: 3}   # per joint, by the number of joints of the study
ONE_JOINT = ("star",)               # families whose frame comes with its one joint


def size_bin(multiple: float | None) -> str | None:
    if multiple is None:
        return None
    for (lo, hi), name in zip(BINS, BIN_NAMES):
        if lo <= multiple < hi:
            return name
    return BIN_NAMES[0] if multiple < BINS[0][0] else (BIN_NAMES[-1] if multiple < BINS[-1][1] * 1.01 else OVER)


# --------------------------------------------------------------------------------------------
# the study's draws that do not depend on its structure
# --------------------------------------------------------------------------------------------
FIRST_FAMILIES = 9
"""The families of the first benchmarks (the first nine of ``FAMILIES``), drawn from one stream."""


def study_family(seed: int, index: int) -> str:
    """The family of study ``index`` (its own random stream: the same whichever families a run
    includes). Every family is drawn equally often; a family added after the first nine takes
    its share from a stream of its own (the latest first), so that adding one leaves the other
    studies of a seed with their family."""
    names = list(fr.FAMILIES)
    for k in range(len(names) - 1, FIRST_FAMILIES - 1, -1):
        if np.random.default_rng([seed, index, 3, k]).random() < 1.0 / (k + 1):
            return names[k]
    return str(np.random.default_rng([seed, index, 1]).choice(names[:FIRST_FAMILIES]))


def study_style(seed: int, index: int) -> tuple[str, str]:
    """``(style, adapter)`` of study ``index`` (its own random stream)."""
    rng = np.random.default_rng([seed, index, 2])
    style = str(rng.choice(list(STYLES), p=list(STYLES.values())))
    return style, ("mystran" if rng.random() < MYSTRAN_SHARE else "reference")


def draw_kinds(rng: np.random.Generator) -> tuple[str, ...]:
    """``()`` (no effect), one kind, or two different kinds."""
    names = list(KIND_WEIGHTS)
    w = np.array([KIND_WEIGHTS[k] for k in names])
    first = str(rng.choice(names, p=w / w.sum()))
    if first == NONE:
        return ()
    if rng.random() < TWO_EFFECTS:
        second = str(rng.choice([k for k in ALL_KINDS if k != first]))
        return (first, second)
    return (first,)


def draw_multiple(rng: np.random.Generator) -> float:
    """A threshold multiple: a size bin drawn equally, log-uniform within it."""
    lo, hi = BINS[int(rng.integers(len(BINS)))]
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


# --------------------------------------------------------------------------------------------
# joints, offsets, loads
# --------------------------------------------------------------------------------------------
def place_joints(f: fr.Frame, rng: np.random.Generator) -> None:
    """1-3 flexible joints at grids where 2-6 bars meet (:data:`MAX_BRANCHES`); no two share or
    touch a member; the degree is drawn first (among those available), then the grid."""
    if f.joints:
        return
    n_joints = int(rng.choice([1, 2, 3], p=[0.5, 0.3, 0.2]))
    taken: set[int] = set()
    for _ in range(n_joints):
        at = f.members_at()
        ok = [g for g, es in at.items() if 2 <= len(es) <= MAX_BRANCHES[n_joints]
              and g not in f.spcs and g not in taken]
        if not ok:
            break
        degrees = sorted({len(at[g]) for g in ok})
        deg = int(rng.choice(degrees))
        node = int(rng.choice([g for g in ok if len(at[g]) == deg]))
        bars = [int(b) for b in rng.permutation(at[node])]
        grids = f.flexible_joint(f"J{node}", node, bars)
        for g in grids:
            taken |= {g} | f.neighbours(g)
            for h in f.neighbours(g):
                taken |= f.neighbours(h)


def add_offsets(f: fr.Frame, rng: np.random.Generator) -> None:
    """CBAR offsets as a user models eccentric connections: the members of one or two groups
    get, at each end where a member of another group ends, an offset of 2-10 cm along their
    orientation vector (a purlin on a rafter, a cross member on the rails)."""
    groups = [g for g, es in f.groups.items() if any(e in f.bars for e in es)]
    if len(groups) < 2:
        return
    chosen = [str(g) for g in rng.choice(groups, size=min(2, len(groups)), replace=False)]
    owner = {e: g for g, es in f.groups.items() for e in es}
    ends: dict[int, set[str]] = {}
    for e, (a, b, *_) in f.bars.items():
        for g in (a, b):
            ends.setdefault(g, set()).add(owner.get(e, ""))
    for grp in chosen:
        delta = float(np.round(rng.uniform(0.02, 0.1), 3))
        for e in f.groups[grp]:
            if e not in f.bars:
                continue
            bar = f.bars[e]
            v = np.asarray(bar[3], float)
            d = np.subtract(f.grids[bar[1]], f.grids[bar[0]])
            n = v - d * (v @ d) / (d @ d)
            n = tuple(float(x) for x in delta * n / np.linalg.norm(n))
            for k, g in ((4, bar[0]), (5, bar[1])):
                if ends.get(g, set()) - {grp}:
                    bar[k] = n


def random_loads(f: fr.Frame, n_cases: int, rng: np.random.Generator, per_case: int,
                 labels: list[str]) -> list[tuple[str, int, int, float]]:
    """Load cases on unsupported grids away from the joints: forces and moments mixed, in the
    grids' CD components (a frame with a test rig's cases, :attr:`~frames.Frame.rig_case`: those,
    :func:`rig_loads`)."""
    if f.rig_case is not None:
        return rig_loads(f, n_cases, rng, labels)
    joint_grids = {g for _, gs in f.joints for g in gs}
    free = [g for g in sorted(f.grids) if g not in f.spcs and g not in joint_grids]
    rows = []
    for c in range(n_cases):
        for g in rng.choice(free, size=min(per_case, len(free)), replace=False):
            comp = int(rng.integers(1, 7))
            mag = f.force if comp <= 3 else f.moment
            rows.append((labels[c], int(g), comp, float(np.round(mag * rng.uniform(-1, 1), 3))))
    return rows


def rig_loads(f: fr.Frame, n_cases: int, rng: np.random.Generator,
              labels: list[str]) -> list[tuple[str, int, int, float]]:
    """The frame's test-rig cases (``f.rig_case``: forces in basic on grids that are neither
    supported nor a joint's), each force written in its grid's CD components."""
    avoid = set(f.spcs) | {g for _, gs in f.joints for g in gs}
    rows = []
    for c in range(n_cases):
        for g, vec in sorted(f.rig_case(rng, avoid).items()):
            cd = f.cd.get(g, 0)
            local = np.asarray(f.coords[cd].coord.axes) @ vec if cd else np.asarray(vec, float)
            for k, v in enumerate(np.round(local, 3)):
                if v != 0.0:
                    rows.append((labels[c], int(g), k + 1, float(v)))
    return rows


def joint_truths(deck: Deck, f: fr.Frame, rng: np.random.Generator) -> list[dict]:
    """Each joint's truth: the simple model, springs a random factor (log-normal, 0.3) of a
    joint scale ``k`` = 10^U(-0.7, 0.3) x the mean 4EI/L of its branch members."""
    out = []
    at: dict[int, list[int]] = {}
    for e, b in deck.cbars.items():
        at.setdefault(b.ga, []).append(e)
        at.setdefault(b.gb, []).append(e)
    for name, grids in f.joints:
        vals = []
        for g in grids:
            b = deck.cbars[at[g][0]]
            p, m = deck.pbars[b.pid], deck.mat1s[deck.pbars[b.pid].mid]
            L = float(np.linalg.norm(np.subtract(deck.grids[b.ga].xyz, deck.grids[b.gb].xyz)))
            vals.append(4.0 * m.e * 0.5 * (p.i1 + p.i2) / L)
        k = float(np.mean(vals)) * 10 ** rng.uniform(-0.7, 0.3)
        model = make_joint(name, grids, "simple")
        values = k * np.exp(0.3 * rng.standard_normal(model.n_params))
        out.append({"name": name, "grids": [int(g) for g in grids], "k": k, "values": [float(v) for v in values]})
    return out


# --------------------------------------------------------------------------------------------
# the truth deck
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
    """Edit the deck effect ``kind`` of ``size`` into the truth deck (joint coupling: the
    joint's springs, see :func:`truth_deck`)."""
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
        mid, pid = max(d.mat1s) + 1, max([*d.pbars, *d.prods]) + 1
        d.mat1s[mid] = Mat1(mid, m.e * factor, m.g * factor, m.nu)
        d.pbars[pid] = replace(p, pid=pid, mid=mid, src="")       # shear factors and I12 kept
        d.cbars[eid] = replace(b, pid=pid)
    elif kind != "joint_coupling":
        raise ValueError(f"{kind} is not a deck effect")


def truth_deck(declared: Deck, joints: list[dict], effects: list[dict]) -> Deck:
    """The declared deck with the joints' truth springs and the deck effects of ``effects``
    (dicts with ``kind``, ``where``, ``size``, ``sign``, ``extra``)."""
    t = TruthDeck(declared)
    coupled = {e["where"]: e for e in effects if e["kind"] == "joint_coupling" and e["size"] > 0}
    for j in joints:
        if j["name"] in coupled:
            e = coupled[j["name"]]
            kc = coupled_kc(j["grids"], j["values"], np.asarray(e["extra"]["rho"]), e["size"])
            t.joint(j["name"], j["grids"], "complex", complex_params_from_kc(kc))
        else:
            t.joint(j["name"], j["grids"], "simple", j["values"])
    for e in effects:
        if e["kind"] in DECK_KINDS and e["kind"] != "joint_coupling" and e["size"] > 0:
            plant_deck(t, e["kind"], e["where"], e["size"], e.get("sign", 1.0), e.get("extra") or {})
    return t.deck


# --------------------------------------------------------------------------------------------
# solves: the linear truth and the joint with a gap
# --------------------------------------------------------------------------------------------
def load_matrix(loads: list[tuple[str, int, int, float]], scale: float = 1.0) -> LoadMatrix:
    cases = list(dict.fromkeys(r[0] for r in loads))
    dofs = list(dict.fromkeys((r[1], r[2]) for r in loads))
    di, ci = {d: i for i, d in enumerate(dofs)}, {c: i for i, c in enumerate(cases)}
    V = sp.lil_matrix((len(dofs), len(cases)))
    for c, g, comp, v in loads:
        V[di[(g, comp)], ci[c]] += v * scale
    return LoadMatrix(tuple(dofs), sp.csc_matrix(V), tuple(cases))


def gap_springs(joint: dict) -> list[tuple[tuple[int, int], tuple[int, int], float]]:
    """The joint's simple-model springs ``((grid_i, c), (grid_j, c), k)``, branch i < j."""
    g = joint["grids"]
    model = make_joint(joint["name"], g, "simple")
    return [((g[ia - 1], "xyz".index(p) + 4), (g[ib - 1], "xyz".index(p) + 4), k)
            for (p, ia, ib), k in zip(model.springs, joint["values"])]


class GapNotConverged(RuntimeError):
    """The signs of a joint with a gap cycle in a load case: no settled state was found."""


def gap_solve(U: np.ndarray, G: np.ndarray, Ub: np.ndarray, Gbb: np.ndarray, springs, bindex, ratio: float,
              max_iter: int = 60) -> tuple[np.ndarray, list[int]]:
    """The responses with the joint's springs ``k_m`` where the relative rotation is >= 0 and
    ``ratio k_m`` where it is < 0, from the linear responses (springs ``k_m``) ``U`` (rows: the
    reported DOFs) and ``Ub`` (rows: the joint's rotation DOFs ``bindex``), and the flexibility
    columns of unit moments at those DOFs (``G``, ``Gbb``): per case, the springs' stiffness
    change ``dK`` gives ``u_b = (I + Gbb dK)^-1 u_b,lin`` and ``u = u_lin - G dK u_b``; the signs
    are iterated from the linear state until they repeat. Returns the responses and the number of
    iterations per case; raises :class:`GapNotConverged` when a case's signs cycle."""
    nb = Gbb.shape[0]
    E = np.zeros((len(springs), nb))
    ks = np.array([k for _, _, k in springs])
    for m, (a, b, _) in enumerate(springs):
        E[m, bindex[a]] += 1.0
        E[m, bindex[b]] -= 1.0
    out = U.copy()
    iters = []
    for c in range(U.shape[1]):
        ub = Ub[:, c]
        neg = (E @ ub) < 0
        seen = {neg.tobytes()}
        for it in range(1, max_iter + 1):
            dk = np.where(neg, (ratio - 1.0) * ks, 0.0)
            dK = E.T @ (dk[:, None] * E)
            ub_new = np.linalg.solve(np.eye(nb) + Gbb @ dK, Ub[:, c])
            new_neg = (E @ ub_new) < 0
            if np.array_equal(new_neg, neg):
                out[:, c] = U[:, c] - G @ (dK @ ub_new)
                iters.append(it)
                break
            if new_neg.tobytes() in seen:
                raise GapNotConverged(f"load case {c + 1}: the springs' signs cycle after {it} iterations")
            seen.add(new_neg.tobytes())
            neg = new_neg
        else:
            raise GapNotConverged(f"load case {c + 1}: no settled signs in {max_iter} iterations")
    return out, iters


def truth_response(deck: Deck, lm: LoadMatrix, report: list[tuple[int, int]], gap: dict | None = None,
                   ratio: float = 1.0) -> tuple[np.ndarray, list[int]]:
    """Noise-free responses at ``report`` (rows) for every case of ``lm`` from one batched run of
    the truth deck; with ``gap`` (a joint's truth) the joint's springs depend on the sign
    (:func:`gap_solve`, the linear truth's flexibility at its rotation DOFs from the same run)."""
    if gap is None:
        return ReferenceAdapter(deck).solve(lm, report).values, []
    rot = [(g, c) for g in gap["grids"] for c in (4, 5, 6)]
    unit = LoadMatrix(tuple(rot), sp.identity(len(rot), format="csc"), tuple(f"u{q}" for q in range(len(rot))))
    rows = list(dict.fromkeys(list(report) + rot))
    out = ReferenceAdapter(deck).solve(lm.hstack(unit), rows).values
    n = lm.n_cases
    ri = {d: i for i, d in enumerate(rows)}
    rep, bi = [ri[d] for d in report], [ri[d] for d in rot]
    U, G = out[rep, :n], out[rep, n:]
    Ub, Gbb = out[bi, :n], out[bi, n:]
    return gap_solve(U, G, Ub, Gbb, gap_springs(gap), {d: i for i, d in enumerate(rot)}, ratio)


# --------------------------------------------------------------------------------------------
# noise-free responses, the declared model's sensitivities and the noncentrality
# --------------------------------------------------------------------------------------------
@dataclass
class Response:
    """The noise-free truth without effects: at the measured DOFs (``U0``, all cases), at further
    DOFs (``extra``: neighbours of measured grids, for misplaced sensors), the fitted rows' sigma,
    the declared model's whitened sensitivity basis ``Q`` (orthonormal), and for each joint the
    flexibility columns of unit moments at its rotation DOFs (for a gap)."""
    U0: np.ndarray               # (n_dofs, n_cases)
    dofs: list[tuple[int, int]]
    fit_cases: np.ndarray        # column indices of the fitted cases
    sigma: np.ndarray            # (n_dofs, n_fit) of the fitted rows
    Q: np.ndarray                # (n_dofs * n_fit, r)
    extra: dict                  # DOF -> (n_cases,) noise-free response
    rot: dict                    # joint name -> (rot DOFs, U_rot (nb, n_cases), G (n_dofs, nb), Gbb (nb, nb))
    frames: Callable | None = None   # grid ids -> (n, 3, 3) displacement directions (Deck.displacement_frames)

    def whitened(self, U: np.ndarray) -> np.ndarray:
        """``(U - U0) / sigma`` on the fitted rows, flattened."""
        return ((U[:, self.fit_cases] - self.U0[:, self.fit_cases]) / self.sigma).ravel()

    def noncentrality(self, r: np.ndarray) -> float:
        return float(r @ r - np.sum((self.Q.T @ r) ** 2))

    def value(self, dof) -> np.ndarray:
        """The noise-free response at a measured or extra DOF, every case."""
        dof = tuple(dof)
        return self.U0[self.dofs.index(dof)] if dof in self.dofs else self.extra[dof]


def declared_response(declared: Deck, joints: list[dict], lm: LoadMatrix, dofs, fit_cases,
                      noise: NoiseConfig, extra: list[tuple[int, int]] = ()) -> Response:
    """One batched solve of the effect-free truth: the case loads and unit moments at every joint
    rotation DOF (their columns give the simple springs' sensitivities exactly:
    ``du/dk = -(G_a - G_b)(u_a - u_b)`` for a spring ``k`` between DOFs ``a`` and ``b``)."""
    deck = truth_deck(declared, joints, [])
    rot = [(g, c) for j in joints for g in j["grids"] for c in (4, 5, 6)]
    unit = LoadMatrix(tuple(rot), sp.identity(len(rot), format="csc"), tuple(f"u{q}" for q in range(len(rot))))
    n_c = lm.n_cases
    report = list(dict.fromkeys(list(dofs) + rot + list(extra)))
    out = ReferenceAdapter(deck).solve(lm.hstack(unit), report)
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
    rots = {}
    for j in joints:
        g = j["grids"]
        jr = [(x, c) for x in g for c in (4, 5, 6)]
        qi = [rq[d] for d in jr]
        rots[j["name"]] = (jr, out.values[[rix[d] for d in jr], :n_c], G[mi][:, qi], G[[rix[d] for d in jr]][:, qi])
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
    ext = {d: out.values[rix[d], :n_c] for d in extra}
    return Response(U0, list(dofs), fc, sigma, Q, ext, rots, declared.displacement_frames)


def threshold_noncentrality(p: int, m_candidates: int, alpha: float = ALPHA,
                            power: float = POWER_AT_THRESHOLD, found_among: int = 0) -> float:
    """The noncentrality at which a ``p``-parameter chi2 test at level ``alpha / m`` has ``power``;
    ``found_among``: a load-scale group the diagnosis must find from the data among that many
    fitted cases, whose test is the bound of :func:`found_group_log_sf` (a higher critical value
    than a group named in advance)."""
    crit = stats.chi2.isf(alpha / m_candidates, p)
    if found_among:
        level = math.log(alpha / m_candidates)
        crit = optimize.brentq(lambda t: found_group_log_sf(t, found_among) - level, 1e-6, 1e4)
    return float(optimize.brentq(lambda lam: stats.ncx2.sf(crit, p, lam) - power, 1e-9, 50 * crit + 200))


# --------------------------------------------------------------------------------------------
# places and their counts
# --------------------------------------------------------------------------------------------
def _effect_params(kind: str, n_branches: int, n_support_comps: int) -> int:
    if kind == "joint_coupling":
        return 3 * (n_branches - 1) * (3 * n_branches - 2) // 2 - 3 * n_branches * (n_branches - 1) // 2
    if kind == "joint_translation":
        return 3
    if kind == "undeclared_joint":
        return 3
    if kind == "support_flexibility":
        return n_support_comps
    return 1


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
    """How many hypotheses the load-scale groups the diagnosis finds from the data make for
    ``n_fit`` fitted cases (``blackbox.diagnosis.effects.load_scale``): one, tested with a bound
    that accounts for the choice among them, when there are at least three fitted cases."""
    return 1 if n_fit >= 3 else 0


def neighbours_of(deck: Deck, g: int) -> list[int]:
    """Grids joined to ``g`` by one member (bar or rod)."""
    out = {b.gb if b.ga == g else b.ga for b in deck.cbars.values() if g in (b.ga, b.gb)}
    out |= {r.gb if r.ga == g else r.ga for r in deck.rods.values() if g in (r.ga, r.gb)}
    return sorted(out)


def candidate_places(deck: Deck, joints: list[dict], away: list[int], measured_grids: list[int],
                     fit_labels: list[str], all_labels: list[str], channels: list[tuple[int, int]]) -> dict[str, list]:
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
    clamped = {g for g, c in constrained.items() if c == "123456"}
    by_comp: dict[int, list[int]] = {}
    for g, k in channels:
        if g in away:
            by_comp.setdefault(k, []).append(g)
    misplaced = []
    for g in away:
        comps = [k for gg, k in channels if gg == g]
        for h in neighbours_of(deck, g):
            if h in clamped or h in declared:
                continue
            # a channel whose direction only meets components held at h would read nothing:
            # that is a dead channel, not a misplacement the data could show
            live = [k for k in comps
                    if any(str(c) not in constrained.get(h, "")
                           for (_, c), _ in misplaced_weights(g, h, k, deck.displacement_frames))]
            if live == comps:
                misplaced.append((g, h, tuple(comps)))
            misplaced += [(g, h, (k,)) for k in live]
    return {
        "joint_coupling": [j["name"] for j in joints],
        "joint_translation": [j["name"] for j in joints],
        "joint_gap": [j["name"] for j in joints],
        "undeclared_joint": [g for g in sorted(at) if len(at[g]) >= 2 and g not in declared
                             and g not in constrained and g not in in_rbe2],
        "support_flexibility": [g for g in sorted(constrained) if g in at and g not in in_rbe2],
        "load_scale": [tuple(all_labels)] + [(c,) for c in fit_labels] + test_days(all_labels, fit_labels),
        "sensor_gain": list(measured_grids),
        "sensor_offset": list(channels),
        "member_stiffness": sorted(deck.cbars),
        "outlier": [(c, g, k) for c in fit_labels for g, k in channels],
        "sign_flip": [(g, k) for g, k in channels if g in away],
        "channel_swap": [(a, b, k) for k, gs in sorted(by_comp.items())
                         for a, b in itertools.combinations(sorted(gs), 2)],
        "misplaced_sensor": misplaced,
    }


def near_places(kind: str, deck: Deck, joints: list[dict]) -> set:
    """Places of ``kind`` where something else could mimic the effect: an undeclared joint one
    grid away from a declared joint; a member factor on a member framing into a joint or a
    support; a flexible support where one bar ends (a factor on that bar could stand in)."""
    declared = {g for j in joints for g in j["grids"]}
    supported = {g for s in deck.spc1s for g in s.grids}
    if kind == "undeclared_joint":
        return {h for g in declared for h in neighbours_of(deck, g)} - declared
    if kind == "member_stiffness":
        return {e for e, b in deck.cbars.items() if {b.ga, b.gb} & (declared | supported)}
    if kind == "support_flexibility":
        ends = [g for b in deck.cbars.values() for g in (b.ga, b.gb)]
        return {g for g in supported if ends.count(g) == 1}
    return set()


def _solve_size(lam: Callable[[float], float], target: float, s_max: float, s0: float) -> tuple[float, float] | None:
    """The size ``s`` with ``lam(s) = target`` (``lam`` ~ s^2 for small s), or None beyond ``s_max``."""
    l0 = lam(s0)
    if not l0 > 0:
        return None
    s = s0 * math.sqrt(target / l0)
    val = l0
    for _ in range(12):
        if s > s_max:
            return None
        val = lam(s)
        if not val > 0:
            return None
        if abs(val / target - 1.0) < 0.01:
            return s, val
        s *= math.sqrt(target / val) if val < 4 * target else 0.5
    return (s, val) if abs(val / target - 1.0) < 0.05 else None


def _channel_scale(resp: Response, channel) -> float:
    """An offset's unit: the channel's largest noise-free |value| over the cases."""
    return float(np.abs(resp.U0[resp.dofs.index(tuple(channel))]).max())


def read_map(effects: list[dict], frames: Callable | None = None) -> dict:
    """What each defective channel really read: ``{(g, k): [(source DOF, weight), ...]}`` of the
    sign flips, swaps and misplaced sensors among ``effects``. A misplaced sensor still measures
    along its own physical direction: channel ``k`` of ``g`` read at ``h`` sees ``h``'s motion
    along ``g``'s direction ``k``, a combination of ``h``'s three components of that kind when
    the two grids have different displacement systems (``frames``: grid ids -> their
    directions, ``Deck.displacement_frames``; without it, the same system is assumed)."""
    out = {}
    for e in effects:
        if e["kind"] == "sign_flip":
            out[(e["where"][0], e["component"])] = [((e["where"][0], e["component"]), -1.0)]
        elif e["kind"] == "channel_swap":
            a, b = e["where"]
            k = e["component"]
            out[(a, k)], out[(b, k)] = [((b, k), 1.0)], [((a, k), 1.0)]
        elif e["kind"] == "misplaced_sensor":
            g, h = e["where"][0], e["read_at"]
            for k in e["components"]:
                out[(g, k)] = misplaced_weights(g, h, k, frames)
    return out


def misplaced_weights(g: int, h: int, k: int, frames: Callable | None) -> list:
    """``[((h, c), w), ...]``: ``h``'s motion along ``g``'s direction ``k``."""
    if frames is None:
        return [((h, k), 1.0)]
    Rg, Rh = frames([g, h])
    o = 3 if k >= 4 else 0
    row = (Rg @ Rh.T)[k - 1 - o]            # g's direction k in h's components
    return [((h, o + j + 1), float(w)) for j, w in enumerate(row) if abs(w) > 1e-12]


def _read_values(resp: Response, mapping: dict) -> np.ndarray:
    U = resp.U0.copy()
    for dof, srcs in mapping.items():
        U[resp.dofs.index(dof)] = sum(w * resp.value(src) for src, w in srcs)
    return U


def lambda_fn(kind, where, extra, declared, joints, lm, resp: Response, labels) -> Callable[[float], float]:
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
    if kind == "outlier":                       # size in units of the reading's sigma
        c, g, k = where
        fi = list(resp.fit_cases).index(labels.index(c))
        r1 = np.zeros(resp.sigma.shape)
        r1[resp.dofs.index((g, k)), fi] = 1.0
        r1 = r1.ravel()
        return lambda s: s * s * resp.noncentrality(r1)
    if kind == "joint_gap":
        jr, Ub, G, Gbb = resp.rot[where]
        j = next(j for j in joints if j["name"] == where)
        springs, bindex = gap_springs(j), {d: i for i, d in enumerate(jr)}
        sign = extra["sign"]

        def lam_gap(s: float) -> float:
            try:
                U, _ = gap_solve(resp.U0, G, Ub, Gbb, springs, bindex, math.exp(sign * s))
            except GapNotConverged:
                return float("nan")
            return resp.noncentrality(resp.whitened(U))
        return lam_gap
    cache: dict[float, float] = {}

    def lam(s: float) -> float:
        if s not in cache:
            deck = truth_deck(declared, joints, [{"kind": kind, "where": where, "size": s,
                                                  "sign": extra.get("sign", 1.0), "extra": extra}])
            try:
                U = ReferenceAdapter(deck).solve(lm, resp.dofs).values
            except Exception:           # a size that makes the structure a mechanism: no value
                return float("nan")
            cache[s] = resp.noncentrality(resp.whitened(U))
        return cache[s]
    return lam


def discrete_lambda(kind: str, place, resp: Response) -> float:
    """The noncentrality of a sign flip, swap or misplaced sensor at ``place``."""
    if kind == "sign_flip":
        e = {"kind": kind, "where": [place[0]], "component": place[1]}
    elif kind == "channel_swap":
        e = {"kind": kind, "where": [place[0], place[1]], "component": place[2]}
    else:
        e = {"kind": kind, "where": [place[0]], "read_at": place[1], "components": list(place[2])}
    return resp.noncentrality(resp.whitened(_read_values(resp, read_map([e], resp.frames))))


# --------------------------------------------------------------------------------------------
# one study
# --------------------------------------------------------------------------------------------
@dataclass
class Study:
    """A generated study: its folder (what the diagnosis sees) and the hidden record."""
    index: int
    folder: Path
    hidden: Path
    planted: dict


@dataclass
class Draw:
    """Everything one successful draw decided."""
    frame: fr.Frame
    declared: Deck
    model_text: str
    input_text: str | None
    joints: list[dict]
    loads: list
    labels: list[str]
    holdout: list[str]
    away: list[int]
    measured: list[int]
    noise: NoiseConfig
    effects: list[dict]
    info: dict


def generate_study(index: int, seed: int, out: Path, kind: str | tuple[str, ...] | None = None,
                   shape: str | None = None, multiple: float | None = None, style: str | None = None,
                   adapter: str | None = None) -> Study:
    """Write study ``index`` (seeded by ``seed`` and ``index``) into ``out/studies/sNNNN`` and its
    truth and ``planted.json`` into ``out/hidden/sNNNN``. ``kind`` (one kind, ``"none"``, or a
    tuple of two), ``shape`` (the family), ``multiple``, ``style`` and ``adapter`` force a choice;
    the other draws stay as they are."""
    rng = np.random.default_rng([seed, index])
    family = shape or study_family(seed, index)
    st, ad = study_style(seed, index)
    style, adapter = style or st, adapter or ad
    kinds = draw_kinds(rng)
    if family in ONE_JOINT and len(kinds) == 2 and all(k in JOINT_KINDS for k in kinds):
        # two effects at two joints need two joints: the second goes elsewhere
        kinds = (kinds[0], str(rng.choice([k for k in ALL_KINDS if k not in JOINT_KINDS])))
    if kind is not None:
        kinds = () if kind == NONE else ((kind,) if isinstance(kind, str) else tuple(kind))
    failures: list[str] = []
    for attempt in range(40):
        try:
            res = _try_study(rng, index, kinds, family, style, multiple)
        except GapNotConverged as exc:
            failures.append(f"joint_gap: {exc}")
            res = None
        if res is not None:
            break
    else:
        raise RuntimeError(f"study {index}: no place found for {kinds} in 40 {family} structures")
    res.info.update({"attempts": attempt + 1, "gap_not_converged": failures})
    return write_study_files(index, seed, out, res, family, style, adapter, rng)


def _try_study(rng: np.random.Generator, index: int, kinds: tuple[str, ...], family: str, style: str,
               forced_multiple: float | None) -> Draw | None:
    """One draw of structure, loads, sensors and noise with the effects placed and sized; None
    when a place of some kind cannot be found."""
    f = fr.FAMILIES[family](rng)
    if style != "plain":
        fr.assign_user_systems(f, rng)
        add_offsets(f, rng)
    place_joints(f, rng)
    if not f.joints:
        return None
    n_cases = int(rng.integers(8, 21))
    labels = [str(c + 1) for c in range(n_cases)] if style == "import" else [f"L{c + 1}" for c in range(n_cases)]
    loads = random_loads(f, n_cases, rng, int(rng.integers(1, 4)), labels)
    title = f"blind study {index}"
    ustyle = fr.user_style(f, rng) if style != "plain" else None
    if style == "plain":
        model_text = fr.plain_text(f, title)
    else:
        model_text = fr.user_text(f, ustyle, title)
    input_text = None
    if style == "import":
        free = [g for g in sorted(f.grids) if g not in f.spcs and all(g not in gs for _, gs in f.joints)]
        input_text = fr.user_text(f, ustyle, title, loads=loads, decoy_spc=int(rng.choice(free)))
    declared = read_deck_text(model_text, "<blind>")
    joints = joint_truths(declared, f, rng)
    n_hold = max(2, round(0.2 * len(labels))) if rng.random() < 2.0 / 3.0 else 0
    holdout = sorted(rng.choice(labels, size=n_hold, replace=False).tolist(), key=labels.index)
    fit_labels = [c for c in labels if c not in holdout]
    joint_grids = {g for j in joints for g in j["grids"]}
    free = [g for g in sorted(declared.grids) if g not in joint_grids and f.spcs.get(g) != "123456"]
    n_away = min(len(free), int(rng.integers(4, 11)))
    away = sorted(int(g) for g in rng.choice(free, size=n_away, replace=False))
    measured = sorted({j["grids"][0] for j in joints} | set(away))
    dofs = list(dict.fromkeys([d for j in joints for d in joint_dofs(j["grids"])]
                              + [(g, c) for g in away for c in range(1, 7)]))
    noise = NoiseConfig(relative=float(rng.uniform(0.01, 0.05)), floor=float(rng.uniform(0.02, 0.10)))
    lm = load_matrix(loads)
    fit_cases = [labels.index(c) for c in fit_labels]
    extra = sorted({(h, c) for g in away for h in neighbours_of(declared, g) for c in range(1, 7)} - set(dofs))
    try:
        # the declared deck (joint rotations free) must not be a mechanism: a chain of members
        # between two joints could spin about its axis
        ReferenceAdapter(declared).solve(lm, dofs[:1])
        resp = declared_response(declared, joints, lm, dofs, fit_cases, noise, extra)
    except Exception:           # a mechanism, or a case that moves no measured DOF of one kind
        return None
    places = candidate_places(declared, joints, away, measured, fit_labels, labels, dofs)
    group_column = bool(rng.random() < 0.5)
    # the candidates the diagnosis offers (its Bonferroni M_k per kind): not the test days (places
    # to plant), but two groups from a group column, or the groups it finds from the data
    m_k = {k: len(v) for k, v in places.items() if k != "load_scale" and v}
    m_k["load_scale"] = 1 + len(fit_labels) + (2 if group_column else found_group_candidates(len(fit_labels)))
    # every channel read in two fitted cases or more may be set aside, and every fitted case when
    # three or more are (blackbox.diagnosis.effects.bad_channel, bad_case): kinds the diagnosis
    # offers, though nothing is planted as them
    m_k["bad_channel"] = len(dofs) if len(fit_labels) >= 2 else 0
    m_k["bad_case"] = len(fit_labels) if len(fit_labels) >= 3 else 0
    # every pair of fitted cases read at the same channels may have been exchanged (case_swap):
    # every case here is read at the same channels
    m_k["case_swap"] = len(fit_labels) * (len(fit_labels) - 1) // 2
    # every force and every moment of a fitted case may have gone in turned (load_tilt)
    m_k["load_tilt"] = len({(c, g, 1 if k <= 3 else 4) for c, g, k, v in loads if c in fit_labels and v != 0.0})
    # and every fitted case of two or more such vectors may have had all of them turned (case_tilt)
    per_case = {}
    for c, g, k, v in loads:
        if c in fit_labels and v != 0.0:
            per_case.setdefault(c, set()).add((g, 1 if k <= 3 else 4))
    m_k["case_tilt"] = sum(1 for vs in per_case.values() if len(vs) >= 2)
    # and every grid a fitted case loads may have been the wrong one, its neighbour the right
    # one (misplaced_load; a neighbour held in all six components is none)
    m_k["misplaced_load"] = sum(1 for c, g in {(c, g) for c, g, _, v in loads if c in fit_labels and v != 0.0}
                                for h in neighbours_of(declared, g) if f.spcs.get(h) != "123456")
    # and the load at every grid a fitted case loads may be off by one factor in every case
    # (load_cell; a component a support holds carries no load of it; a grid whose every case
    # loads nothing else is a load scale of those cases instead)
    grids_of: dict = {}
    for c, g, k, v in loads:
        if v != 0.0:
            grids_of.setdefault(c, set()).add(g)
    m_k["load_cell"] = len({g for c, g, k, v in loads if c in fit_labels and v != 0.0
                            and str(k) not in (f.spcs.get(g) or "")
                            and not all(gs == {g} for gs in grids_of.values() if g in gs)})
    m_k = {k: v for k, v in m_k.items() if v}
    # the diagnosis's first-round multiplier of one hypothesis of a kind (search.multipliers): 2 K M_k
    mult = {k: 2 * len(m_k) * m for k, m in m_k.items()}
    n_candidates = sum(m_k.values())
    info = {"n_candidates": n_candidates, "candidates_per_kind": m_k, "group_column": group_column}
    effects: list[dict] = []
    for kind in kinds:
        e = plan_effect(rng, kind, places, declared, joints, lm, resp, labels, mult[kind],
                        forced_multiple, effects, group_column, len(fit_labels))
        if e is None:
            return None
        effects.append(e)
    return Draw(f, declared, model_text, input_text, joints, loads, labels, holdout, away, measured, noise,
                effects, info)


def _overlaps(e: dict, others: list[dict]) -> bool:
    """Two effects at one place: the same joint, grid, element, or a channel of the same grid."""
    def grids(x):
        w = x["where"]
        w = w if isinstance(w, list) else [w]
        out = {str(v) for v in w}
        if x["kind"] == "misplaced_sensor":
            out.add(str(x["read_at"]))
        if x["kind"] == "load_scale":
            out = {"case " + str(v) for v in w}
        if x["kind"] == "outlier":
            out = {str(x["where"][0]), "case " + str(x["case"])}
        if x["kind"] == "member_stiffness":
            out = {"element " + str(v) for v in w}
        return out
    mine = grids(e)
    return any(mine & grids(o) for o in others)


def plan_effect(rng, kind, places, declared, joints, lm, resp, labels, multiplier, forced_multiple,
                others, group_column, n_fit: int = 0) -> dict | None:
    """Place and size one effect of ``kind`` (module docstring); None when no place works.
    ``n_fit``: the fitted cases, among which a test day with no group column is found."""
    multiple = float(forced_multiple) if forced_multiple is not None else draw_multiple(rng)
    pool = list(places[kind])
    placement = "anywhere"
    near = near_places(kind, declared, joints)
    if near and rng.random() < 0.5:
        pool = [p for p in pool if p in near]
        placement = {"undeclared_joint": "near_joint", "member_stiffness": "joint_or_support_member",
                     "support_flexibility": "one_bar_support"}[kind]
    if kind == "load_scale":        # all cases, one case or a test day, a third of the studies each
        which = str(rng.choice(["all", "case", "day"]))
        pool = [w for w in pool if (len(w) == len(labels)) == (which == "all")
                and (len(w) == 1) == (which == "case")]
    if not pool:
        return None
    if kind in DISCRETE:
        return _plan_discrete(rng, kind, pool, resp, multiplier, multiple, forced_multiple, others)
    order = list(rng.permutation(len(pool)))
    for pi in order[:12]:
        where = pool[pi]
        sign = float(rng.choice([-1.0, 1.0]))
        extra: dict = {"sign": sign}
        n_br = 0
        if kind in JOINT_KINDS:
            j = next(j for j in joints if j["name"] == where)
            extra["grids"] = j["grids"]
            n_br = len(j["grids"])
            if kind == "joint_coupling":
                m = 3 * n_br - 3
                R = rng.standard_normal((m, m))
                R = R + R.T
                np.fill_diagonal(R, 0.0)
                extra["rho"] = R / np.linalg.norm(R, 2)
        constrained = {g: s.components for s in declared.spc1s for g in s.grids}
        p = _effect_params(kind, n_br, len(set("".join(s.components for s in declared.spc1s if where in s.grids)))
                           if kind == "support_flexibility" else 0)
        if kind == "support_flexibility" and where not in constrained:
            continue
        e = {"kind": kind, "where": list(where) if isinstance(where, tuple) else where}
        if kind == "outlier":
            e.update({"where": [where[1]], "case": where[0], "component": where[2]})
        if kind == "sensor_offset":
            e.update({"where": where[0], "component": where[1]})
        if _overlaps(e, others):
            continue
        found = kind == "load_scale" and which == "day" and not group_column and found_group_candidates(n_fit)
        lam1 = threshold_noncentrality(p, multiplier, found_among=n_fit if found else 0)
        lam = lambda_fn(kind, where, extra, declared, joints, lm, resp, labels)
        s0 = {"load_scale": 1e-3, "sensor_gain": 1e-3, "member_stiffness": 1e-3, "joint_coupling": 1e-3,
              "outlier": 1.0, "joint_gap": 1e-2}.get(kind, 1e-4)
        one = _solve_size(lam, lam1, SIZE_MAX[kind], s0)
        if one is None:
            continue
        hit = _solve_size(lam, multiple ** 2 * lam1, SIZE_MAX[kind], s0)
        if hit is None:
            continue
        size, lam_size = hit
        m = math.sqrt(lam_size / lam1)
        e.update({"sign": sign, "size": size, "threshold_size": one[0], "multiple": m, "bin": size_bin(m),
                  "multiple_drawn": multiple, "noncentrality": lam_size, "threshold_noncentrality": lam1, "bonferroni": multiplier,
                  "params": p, "placement": placement, "extra": {k: v for k, v in extra.items()}})
        e.update(_describe(kind, where, size, sign, labels, resp))
        if kind == "load_scale" and e["group"] == "day":
            e["group_column"] = group_column
        return e
    return None


def _plan_discrete(rng, kind, pool, resp, multiplier, multiple, forced, others) -> dict | None:
    """A sign flip, swap or misplaced sensor at a place whose multiple is in the drawn bin."""
    lam1 = threshold_noncentrality(1, multiplier)
    if len(pool) > 400:
        pool = [pool[i] for i in rng.choice(len(pool), 400, replace=False)]
    mults = {}
    for place in pool:                  # below half its threshold a defect is not planted
        lam = discrete_lambda(kind, place, resp)
        if lam >= (BINS[0][0] ** 2) * lam1:
            mults[place] = math.sqrt(lam / lam1)
    if not mults:
        return None
    target = size_bin(multiple)
    order = [target] + sorted((b for b in BIN_NAMES if b != target),
                              key=lambda b: abs(BIN_NAMES.index(b) - BIN_NAMES.index(target)))
    for b in order + [OVER]:
        cands = [p for p, m in mults.items() if size_bin(m) == b]
        rng.shuffle(cands)
        for place in cands:
            if kind == "sign_flip":
                e = {"kind": kind, "where": [place[0]], "component": place[1]}
            elif kind == "channel_swap":
                e = {"kind": kind, "where": [place[0], place[1]], "component": place[2]}
            else:
                e = {"kind": kind, "where": [place[0]], "read_at": place[1], "components": list(place[2])}
            if _overlaps(e, others):
                continue
            m = mults[place]
            e.update({"size": 1.0, "multiple": m, "bin": size_bin(m), "multiple_drawn": multiple,
                      "noncentrality": m * m * lam1, "threshold_noncentrality": lam1, "bonferroni": multiplier, "params": 1,
                      "placement": "neighbour" if kind == "misplaced_sensor" else "anywhere",
                      "bin_drawn": target})
            return e
    return None


def _describe(kind: str, where, size: float, sign: float, labels: list[str], resp: Response) -> dict:
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
    if kind == "joint_gap":
        return {"ratio": math.exp(sign * size)}
    if kind == "outlier":
        c, g, k = where
        fi = list(resp.fit_cases).index(labels.index(c))
        s = float(resp.sigma[resp.dofs.index((g, k)), fi])
        return {"offset": sign * size * s, "sigma_units": sign * size}
    return {"compliance_ratio": size, "stiffness_factor": 1.0 / size}


# --------------------------------------------------------------------------------------------
# writing the study
# --------------------------------------------------------------------------------------------
def _toml_list(v) -> str:
    return json.dumps(v)


@dataclass
class Simulated:
    """The simulated measurements of a study: ``rows`` (``blackbox.simulation.SimulatedRows`` of
    the readings: what each gauge saw, its sigma, its noise), ``values`` (with the effects on
    the noisy values applied), the noise-free truth ``U`` at ``report`` and the readings ``read``
    (noise-free, after sign flips, swaps and misplaced sensors)."""
    cases: list[str]
    dofs: list[tuple[int, int]]
    rows: object
    values: np.ndarray
    U: np.ndarray
    report: list[tuple[int, int]]
    read: np.ndarray
    force_scale: float
    gap_iterations: list[int]


def simulate_study(truth: Deck, loads, joints: list[dict], away: list[int], effects: list[dict],
                   noise: NoiseConfig, noise_seed: int) -> Simulated:
    """Measurements of the joints' DOFs and all components of ``away`` from the truth deck (the
    joint with a gap solved per case), the readings' defects applied to what the gauges saw,
    noise as ``blackbox simulate`` draws it (same order, seed ``noise_seed``), then gains,
    offsets, load scales of cases and the outlier on the noisy values."""
    scale = next((e["factor"] for e in effects if e["kind"] == "load_scale" and e["group"] == "all"), 1.0)
    gap = next((e for e in effects if e["kind"] == "joint_gap"), None)
    gap_joint = next(j for j in joints if j["name"] == gap["where"]) if gap else None
    dofs = list(dict.fromkeys([dd for j in joints for dd in joint_dofs(j["grids"])]
                              + [(g, c) for g in away for c in range(1, 7)]))
    mapping = read_map(effects, truth.displacement_frames)
    report = list(dict.fromkeys(dofs + [src for srcs in mapping.values() for src, _ in srcs]))
    cases = list(dict.fromkeys(r[0] for r in loads))
    U, iters = truth_response(truth, load_matrix(loads, scale), report, gap_joint, gap["ratio"] if gap else 1.0)
    row = {dd: i for i, dd in enumerate(report)}
    read = U[[row[dd] for dd in dofs]]
    for k, dd in enumerate(dofs):
        if dd in mapping:
            read[k] = sum(w * U[row[src]] for src, w in mapping[dd])
    rows = simulate_rows(read, {dd: i for i, dd in enumerate(dofs)}, len(cases), dofs, noise,
                         np.random.default_rng(noise_seed))
    values = rows.values.copy()
    for e in effects:               # effects on the noisy values
        for i, ((g, comp), ci) in enumerate(zip(rows.dofs, rows.case_index)):
            case = cases[ci]
            if e["kind"] == "sensor_gain" and g == e["where"]:
                values[i] *= e["factor"]
            elif e["kind"] == "sensor_offset" and (g, comp) == (e["where"], e["component"]):
                values[i] += e["offset"]
            elif e["kind"] == "load_scale" and e["group"] != "all" and case in e["where"]:
                values[i] *= e["factor"]
            elif e["kind"] == "outlier" and (case, g, comp) == (e["case"], e["where"][0], e["component"]):
                values[i] += e["offset"]
    return Simulated(cases, dofs, rows, values, U, report, read, scale, iters)


def write_study_files(index: int, seed: int, out: Path, d: Draw, family: str, style: str, adapter: str,
                      rng: np.random.Generator) -> Study:
    """The study folder (model.bdf, loads.csv, study.toml, measurements.csv) and the hidden
    record (truth deck and settings, planted.json, the input file of an imported study)."""
    name = f"s{index:04d}"
    folder, hidden = Path(out) / "studies" / name, Path(out) / "hidden" / name
    for p in (folder, hidden):
        if p.exists():
            shutil.rmtree(p)
    folder.mkdir(parents=True)
    (hidden / "truth").mkdir(parents=True)
    effects = d.effects
    loads = d.loads
    if style == "import":
        from blackbox.commands.import_deck import run as import_deck
        src = hidden / f"{name}.dat"
        src.write_text(d.input_text)
        imp = import_deck(src)
        (folder / "model.bdf").write_text(imp.model_bdf)
        (folder / "loads.csv").write_text(imp.loads_csv)
        loads = [(r[0], int(r[1]), int(r[2]), float(r[3]))
                 for r in (line.split(",") for line in imp.loads_csv.splitlines()[1:] if line.strip())]
    else:
        (folder / "model.bdf").write_text(d.model_text)
    day = next((e for e in effects if e["kind"] == "load_scale" and e.get("group") == "day"
                and e.get("group_column")), None)
    if day is not None or style != "import":
        with (folder / "loads.csv").open("w") as fh:
            fh.write("case,grid,component,value" + (",group" if day else "") + "\n")
            for case, g, c, v in loads:
                tail = f",{'day2' if case in day['where'] else 'day1'}" if day else ""
                fh.write(f"{case},{g},{c},{v!r}{tail}\n")
    initial = float(np.exp(np.mean([math.log(j["k"]) for j in d.joints])) * 10 ** rng.uniform(-0.5, 0.5))
    lines = [f'name = "blind-{name}"', "", "[solver]", f'adapter = "{adapter}"', 'deck = "model.bdf"', ""]
    for j in d.joints:
        lines += ["[[joints]]", f'name = "{j["name"]}"', f"grids = {j['grids']}", 'model = "simple"',
                  f"initial = {float(f'{initial:.3g}')!r}", ""]
    lines += ["[identification]", f"holdout_cases = {_toml_list(d.holdout)}", ""]
    (folder / "study.toml").write_text("\n".join(lines))

    declared = read_deck_text((folder / "model.bdf").read_text(), str(folder / "model.bdf"))
    truth = truth_deck(declared, d.joints, effects)
    (hidden / "truth" / "truth.bdf").write_text(write_deck(truth, "large"))
    noise_seed = int(rng.integers(2**31))
    sim = simulate_study(truth, loads, d.joints, d.away, effects, d.noise, noise_seed)
    scale, iters, rows, values, cases = sim.force_scale, sim.gap_iterations, sim.rows, sim.values, sim.cases
    out_rows = ["case,grid,component,value,sigma"]
    out_rows += [f"{cases[ci]},{g},{comp},{float(v)!r},{float(s)!r}"
                 for (g, comp), ci, v, s in zip(rows.dofs, rows.case_index, values, rows.sigma)]
    (folder / "measurements.csv").write_text("\n".join(out_rows) + "\n")
    (hidden / "truth" / "truth.toml").write_text("\n".join([
        f"seed = {noise_seed}", 'deck = "truth.bdf"', f"force_scale = {scale!r}", "",
        "[noise]", f"relative = {d.noise.relative!r}", f"floor = {d.noise.floor!r}", "",
        "[measure]", "joint = true", f"away_grids = {d.away}", ""]))
    kinds = [e["kind"] for e in effects]
    mults = [e["multiple"] for e in effects]
    planted = {"study": name, "index": index, "seed": seed, "family": family, "shape": family,
               "style": style, "adapter": adapter,
               "kind": NONE if not kinds else "+".join(kinds), "kinds": kinds, "n_effects": len(kinds),
               "effects": effects,
               **({"where": effects[0]["where"]} if len(effects) == 1 else {}),
               "multiple": min(mults) if mults else None, "bin": size_bin(min(mults)) if mults else None,
               "n_joints": len(d.joints), "branches": [len(j["grids"]) for j in d.joints], "joints": d.joints,
               "holdout": bool(d.holdout), "holdout_cases": d.holdout, "measured_grids": d.measured,
               "away_grids": d.away, "noise": {"relative": d.noise.relative, "floor": d.noise.floor},
               "n_cases": len(cases), "n_members": len(declared.cbars) + len(declared.rods),
               "n_bars": len(declared.cbars), "n_rods": len(declared.rods), "n_grids": len(declared.grids),
               "n_measurements": len(rows.values), "gap_iterations": iters, **d.info,
               "note": "blind benchmark: blackbox diagnose never reads this file or truth/"}
    (hidden / "planted.json").write_text(json.dumps(planted, indent=1, default=_json_default))
    (hidden / "truth.json").write_text(json.dumps({"truth_file": "truth/truth.toml", "seed": noise_seed,
                                                   "force_scale": scale, "cases": cases,
                                                   "n_measurements": len(rows.values)}, indent=1))
    return Study(index, folder, hidden, json.loads((hidden / "planted.json").read_text()))


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--n", type=int, default=5)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--kind", choices=(NONE,) + ALL_KINDS)
    ap.add_argument("--family", choices=tuple(fr.FAMILIES))
    ap.add_argument("--style", choices=tuple(STYLES))
    args = ap.parse_args(argv)
    import time
    for i in range(args.n):
        t0 = time.perf_counter()
        st = generate_study(i, args.seed, args.out, kind=args.kind, shape=args.family, style=args.style)
        p = st.planted
        eff = ", ".join(f"{e['kind']} @ {e['where']} x{e['multiple']:.2f}" for e in p["effects"]) or "none"
        print(f"{st.folder.name}: {p['family']} ({p['style']}, {p['adapter']}), {p['n_members']} members, "
              f"joints {p['branches']}, {eff} ({time.perf_counter() - t0:.1f} s)", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
