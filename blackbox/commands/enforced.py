"""Enforced displacements of an imported deck (SPC with a value D, SPCD) as loads: the
large-spring method.

A study's solver takes load vectors and returns displacements (``loads.csv`` holds forces and
moments only), and an enforced displacement is not a load. NASTRAN's own way of turning one into
a load is the large-spring method (MSC Dynamic Analysis User's Guide, enforced motion): the DOF
is freed from its constraint, a grounded spring of stiffness K far above the structure's is put
on it, and the force K D is applied. The DOF then moves D (1 - k/K), k the stiffness the
structure offers there; the rest of the structure moves as with the DOF held at D, to the same
relative error. With K = :data:`K_RATIO` times the largest diagonal term of the assembled
stiffness (translations and rotations apart), that error is below 1e-8 (far under the 7 digits
MYSTRAN prints), and a double-precision solve loses about 8 of its 16 digits to it.

* ``SPC SID G C D`` with D not 0 in the selected constraint set: D in every imported case (all
  of them select that set: one set of supports per study), unless a case's SPCD overrides it;
* ``SPCD SID G C D`` in the load set a case selects (through a LOAD combination, scaled): D in
  that case. As NASTRAN requires, the DOF must be held by an SPC or SPC1 of the selected set.

An enforced DOF held in no case by its enforced value (an SPCD of another subcase) is held at
zero by its spring there, as by its constraint.

What changes in the study: the constraint cards (SPC, SPC1) that hold an enforced DOF are
replaced by SPC1 cards of the same set holding the rest of their DOFs; each enforced DOF is tied
by an ``MPC`` (in an MPC set of its own: a study applies every set) to a handle grid of its own
(IDs above the deck's grids; all its components but the DOF's held by its PS), and the handle
by a ``CELAS2`` to ground of stiffness K (element IDs above the deck's); each case gets the force
(moment) K D at the handle. The DOF itself carries no spring, so the grid-point singularity
check (AUTOSPC: per grid, 1e-8 of its largest stiffness) never weighs K against the grid's
other components: a spring on the DOF held a free tip in a measured case. All of it is written
at the end of ``model.bdf`` under a comment saying so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from solver_adapters.bdf.fields import _int, _real, valid_components
from solver_adapters.protocol import DeckFormatError

K_RATIO = 1e8
"""The large spring's stiffness over the largest diagonal stiffness term of its kind."""


@dataclass(frozen=True)
class EnforcedPlan:
    """What the import writes for the deck's enforced displacements: the constraint cards to
    drop, the lines that replace them and add the springs, and the force per case."""
    drop: tuple                                           # SPC/SPC1 cards replaced
    lines: tuple[str, ...]                               # appended to model.bdf
    loads: dict[str, dict[tuple[int, int], float]]       # case -> {(grid, comp): K D}
    stiffness: dict[str, float]                          # "translation"/"rotation" -> K
    note: str


def spc_values(cards) -> dict[tuple[int, int], tuple[float, object, int]]:
    """The nonzero enforced values of the SPC cards among ``cards`` (those of the selected
    constraint set): ``{(grid, component): (D, card, field of D)}``."""
    out: dict[tuple[int, int], tuple[float, object, int]] = {}
    for c in cards:
        if c.name != "SPC":
            continue
        for base in (3, 6):
            if base == 6 and not any(c.text(i) for i in (6, 7, 8)):
                break
            d = _real(c, base + 2, 0.0)
            if d == 0.0:
                continue
            g, comps = _int(c, base), c.text(base + 1)
            if comps in ("", "0") or not valid_components(comps):
                raise c.error(base + 1, "an enforced displacement needs grid components 1-6 (unique digits)")
            for ch in comps:
                out[(g, int(ch))] = (d, c, base + 2)
    return out


def without_values(c):
    """An SPC card as read, its D fields blanked (the constraint the reader takes): the same
    file, line and fields otherwise, so errors still point at the card as written."""
    from solver_adapters.bdf.tokens import _Card, _Field
    texts = [c.text(i) for i in range(1, len(c.fields) + 1)]
    for i in (5, 8):
        if i <= len(texts):
            texts[i - 1] = ""
    return _Card(c.name, c.file, c.line, [_Field(t, c.line, i) for i, t in enumerate(texts, start=1)])


def _stiffness(deck) -> dict[str, float]:
    """K per kind of component: the power of ten at or above K_RATIO times the largest diagonal
    term of the assembled stiffness among translations (rotations), so that model.bdf holds it
    exactly in a few characters (``1.0E15``) and loads.csv's K x D uses the K the solver reads."""
    from solver_adapters.reference.model import assemble
    if deck.unmodelled:
        names = ", ".join(sorted(deck.unmodelled_counts()))
        raise DeckFormatError(f"enforced displacements (SPCD, SPC with a value) in a deck with elements the "
                              f"reference solver does not model ({names}): the springs that enforce them "
                              f"cannot be sized from the model's stiffness; not imported")
    K = assemble(deck).K_gg
    diag = np.abs(K.diagonal()).reshape(-1, 6)
    out = {}
    for kind, cols in (("translation", slice(0, 3)), ("rotation", slice(3, 6))):
        top = float(diag[:, cols].max()) if diag.size else 0.0
        out[kind] = 10.0 ** math.ceil(math.log10(K_RATIO * (top if top > 0.0 else 1.0)))
    return out


def _power(k: float) -> str:
    """``1.0E<n>`` for K = 10^n."""
    return f"1.0E{round(math.log10(k))}"


def _held(deck) -> dict[tuple[int, int], list]:
    """(grid, component) -> the SPC/SPC1 entries of the deck that hold it (not SUPORT)."""
    out: dict[tuple[int, int], list] = {}
    for s in deck.spc1s:
        if s.card != "SPC1":
            continue
        for g in s.grids:
            for ch in s.components:
                if ch != "0":
                    out.setdefault((g, int(ch)), []).append(s)
    return out


def _max_element_id(cards) -> int:
    """The largest ID of an element-like card (connections C..., rigid elements R..., whose
    field 2 is the element ID; coordinate systems aside): the springs are numbered above it."""
    top = 0
    for c in cards:
        n = c.name
        if (n.startswith("C") and not n.startswith("CORD")) or n.startswith("RB") or n in ("RROD", "RSPLINE"):
            t = c.text(2)
            if t.isdigit():
                top = max(top, int(t))
    return top


def plan(deck, kept_cards, per_case: dict[str, dict], from_spc: dict, mpc_sid: int) -> EnforcedPlan | None:
    """The study's springs, replaced constraints and loads for the enforced values: ``from_spc``
    those of the SPC cards (:func:`spc_values`), applied in every case; ``per_case`` a case's
    SPCD values (:meth:`solver_adapters.loadcards.LoadCards.enforced`), which override them.
    ``kept_cards``: the cards the study keeps (the constraint cards among them); ``mpc_sid`` the
    set of the MPCs that tie the DOFs to their handles, one the deck does not use. None when the
    deck enforces nothing."""
    cases = {label: {dof: v for dof, (v, _) in spcd.items()} for label, spcd in per_case.items()}
    where = {dof: (card, f) for dof, (_, card, f) in from_spc.items()}
    for spcd in per_case.values():
        for dof, (_, e) in spcd.items():
            where.setdefault(dof, (e.raw, e.field))
    if not where:
        return None
    held = _held(deck)
    for dof, (card, f) in sorted(where.items()):
        if dof not in held:
            raise card.error(f, f"grid {dof[0]} component {dof[1]}: an enforced displacement needs the DOF "
                                f"held by an SPC or SPC1 of the constraint set the subcases select (NASTRAN "
                                f"requires it); it is not")
    values: dict[str, dict[tuple[int, int], float]] = {}
    for label, spcd in cases.items():
        merged = {dof: d for dof, (d, _, _) in from_spc.items()}
        merged.update(spcd)                          # an SPCD value overrides the SPC's D
        values[label] = merged

    K = _stiffness(deck)
    by_src = {}
    for c in kept_cards:
        if c.name in ("SPC", "SPC1"):
            by_src.setdefault(c.src, c)
    enforced = set(where)
    touched = {s.src for dof in enforced for s in held[dof]}
    drop = [by_src[src] for src in sorted(touched) if src in by_src]
    lines = ["$", "$ ---- blackbox import: enforced displacements by the large-spring method ----",
             "$ the SPC/SPC1 cards at line(s) " + ", ".join(src.rpartition(":")[2] for src in sorted(touched))
             + " of " + ", ".join(sorted({Path(src.rpartition(":")[0]).name for src in touched}))
             + " replaced by the SPC1 cards below, without the enforced DOFs;",
             "$ each enforced DOF tied by an MPC to a handle grid (its one free component the DOF's) held by a",
             f"$ grounded CELAS2 of {_power(K['translation'])} (translations) / {_power(K['rotation'])} "
             f"(rotations), loaded in loads.csv by K x D"]
    rest: dict[tuple[int, str], list[int]] = {}
    for s in deck.spc1s:
        if s.card != "SPC1" or s.src not in touched:
            continue
        for g in s.grids:
            comps = "".join(ch for ch in s.components if (g, int(ch)) not in enforced)
            if comps:
                rest.setdefault((s.sid, comps), []).append(g)
    for (sid, comps), grids in sorted(rest.items()):
        for k in range(0, len(grids), 6):
            lines.append(",".join(["SPC1", str(sid), comps, *map(str, grids[k:k + 6])]))
    # one handle per enforced DOF: a grid whose only free component c carries the spring, tied to
    # the DOF by an MPC (u(G, c) = u(handle, c)); the DOF itself is then dependent, so the
    # singularity check of its grid (AUTOSPC, per grid and 1e-8 of the block's largest) never
    # weighs the spring against the grid's other components. The handle connects to nothing
    # else: its position and directions do not matter (basic, at the origin).
    q = 10 ** len(str(max(deck.grids)))
    eid = 10 ** len(str(_max_element_id(kept_cards)))
    springs, handles = {}, {}
    for dof in sorted(enforced):
        k = K["translation" if dof[1] <= 3 else "rotation"]
        ps = "".join(ch for ch in "123456" if int(ch) != dof[1])
        lines += [f"GRID,{q},0,0.,0.,0.,0,{ps}", f"MPC,{mpc_sid},{dof[0]},{dof[1]},1.,{q},{dof[1]},-1.",
                  f"CELAS2,{eid},{_power(k)},{q},{dof[1]}"]
        springs[dof], handles[dof] = k, (q, dof[1])
        q, eid = q + 1, eid + 1
    lines.append("$ ---- end of the enforced displacements ----")
    loads = {label: {handles[dof]: springs[dof] * d for dof, d in vals.items() if d != 0.0}
             for label, vals in values.items()}
    n_spc = len(from_spc)
    n_spcd = len(enforced) - len(set(from_spc))
    note = (f"enforced displacements on {len(enforced)} DOF(s) ({n_spc} by SPC values, {n_spcd} more by SPCD) "
            f"imported by the large-spring method: each DOF freed from its constraint and tied by an MPC to a "
            f"handle grid held by a grounded CELAS2 of {K['translation']:.3g} (translations) / "
            f"{K['rotation']:.3g} (rotations), {K_RATIO:.0e} x the largest diagonal stiffness or more, loaded "
            f"by K x D in loads.csv (the DOF moves D to within 1e-8); handle grids "
            f"{min(h for h, _ in handles.values())}-{max(h for h, _ in handles.values())}; model.bdf says so "
            f"at its end")
    return EnforcedPlan(tuple(drop), tuple(lines), loads, K, note)
