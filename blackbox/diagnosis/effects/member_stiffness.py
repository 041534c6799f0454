"""``member_stiffness``: a member is stiffer or softer than the deck says (a factor on its ``K_e``).

``dK = (alpha - 1) K_e`` on the member's 12 end DOFs in the split deck, ``K_e`` the solver's own
element from the element deck's run. Its score at ``alpha = 1`` needs only rows of the
flexibility at the member's DOFs under the unit loads at ``B`` and ``O`` (reciprocity), which the
split run reports (:meth:`MemberStiffness.batch_columns`: every member scored without a run); its
refit needs the member's own columns, one batched run for every short-listed member of a round.
Candidates: every member, bars and rods (CROD, CTUBE, CONROD: a rod's ``K_e`` is its axial and
torsion stiffness, one factor on both); beyond ``max_member_candidates`` those nearest the
declared fit's residual concentration (each considered member adds its 12 end DOFs to the split
run's rows), and the diagnosis says how many it left out.

Variants: "whole" (``alpha_E``: one factor on ``K_e``) and, when ``K_e`` splits cleanly,
"sections" (``EA_E, EI1_E, EI2_E, GJ_E``: one factor on each of its axial, plane-1 bending,
plane-2 bending and torsion parts; :func:`section_parts`), nested at all four equal to alpha;
"bending" (``EI1_E, EI2_E``, EA and GJ as the deck has them) is where the screen starts a member
whose section may be turned about its axis (:meth:`MemberStiffness.screen_points`), with
"sections" richer (EA and GJ at 1).

*A member that is not there.* A brace left out, a weld never made, a member broken or not
connected: ``alpha`` near 0. Its factors go down to ``ALPHA_MISSING`` (1e-4: the member carries
a ten-thousandth of what the deck says, which no reading tells from nothing, and the augmented
system stays regular where the structure without the member is a mechanism); a factor below
``MISSING_BELOW`` is reported as the member missing or disconnected (:meth:`MemberStiffness.findings`),
a plausible value, not one "beyond" any (the bound 50 above still is). The score at ``alpha = 1``
cannot see such a member when it is stiff beside its surroundings (halving a brace changes
little, removing it everything: s0001 of the unlisted-structure benchmark, score 5 against a chi2
drop of 3,100 at removal), so every candidate's chi2 at removal is evaluated exactly before the
search decides what to refit (:attr:`MemberStiffness.screen_point`), and a refit also starts
there when that drop exceeds the score.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from blackbox.diagnosis.decks import in_member_frames, member_ends
from blackbox.diagnosis.effects.base import CandidateLimit, Effect
from blackbox.diagnosis.effects.registry import register
from solver_adapters.protocol import DofLabel

__all__ = ["MemberStiffness", "section_parts", "stiffness_columns", "SECTIONS", "SPLIT_RTOL", "ALPHA_MISSING",
           "FACTOR_MAX", "MISSING_BELOW", "TURN_MIN", "TURNED_SHARE"]

SECTIONS = ("EA", "EI1", "EI2", "GJ")
# the element's tip DOFs (u_x u_y u_z th_x th_y th_z, element axes) of each part: plane 1 is the
# element x-y plane (y along the orientation vector, I1), plane 2 the x-z plane (I2)
_GROUPS = ((0,), (1, 5), (2, 4), (3,))
ALPHA_MISSING = 1e-4        # the lower bound of a member factor: the member is not there
FACTOR_MAX = 50.0           # the upper bound of a member factor: beyond any plausible value
MISSING_BELOW = 0.02        # a fitted factor below this: reported as missing or disconnected
TURN_MIN = 1.2             # I2/I1 (or I1/I2) at least this: a turned section is looked for
TURNED_SHARE = (0.5, 2.0)   # fitted EI1, EI2 each this share (in log) of the way to I2/I1, I1/I2:
                            # reported as turned (a Timoshenko beam's turn is no exact point of the
                            # factors, and the weak plane's factor is poorly determined)
SPLIT_RTOL = 1e-4           # a coupling between parts above this (diagonal-scaled) in the element
                            # axes: K_e is not a plain beam there (offsets, pins, I12, a wrong
                            # orientation: 1e-2..1); below it, the solver's output rounding (a K_e
                            # from 7-digit flexibilities couples them to ~3e-6)


def _unskew(S: np.ndarray) -> np.ndarray:
    return np.array([S[2, 1], S[0, 2], S[1, 0]])


def section_parts(K_e: np.ndarray, v: np.ndarray) -> np.ndarray | None:
    """``(4, 12, 12)``: ``K_e`` (global axes, DOFs ``a1..a6, b1..b6``) split into its axial,
    plane-1 bending, plane-2 bending and torsion parts, which sum to ``K_e`` exactly; ``None`` when
    it does not split (coupling above ``SPLIT_RTOL``).

    ``K_e = T^T K_bb T`` with ``T = [-Gamma, I]`` the rigid-body map (how
    :func:`blackbox.diagnosis.runs.element_stiffness` builds it), so the member's vector ``r`` is
    read from ``K_e`` itself (``Gamma = -K_bb^-1 K_ba``, its upper right block ``-[r x]``). In the
    element axes (x along ``r``, y along the part of the orientation vector ``v`` normal to x) the
    cantilever stiffness ``K_bb`` of a beam is block diagonal over the four parts (Euler-Bernoulli
    or Timoshenko alike); each part is that block mapped back by ``T``."""
    K_bb, K_ba = K_e[6:, 6:], K_e[6:, :6]
    gamma = -np.linalg.solve(K_bb, K_ba)
    r = _unskew(-gamma[:3, 3:])
    L = float(np.linalg.norm(r))
    v = np.asarray(v, float)
    if L == 0.0 or not np.all(np.isfinite(v)):
        return None
    ex = r / L
    y = v - (v @ ex) * ex
    if np.linalg.norm(y) <= 1e-9 * np.linalg.norm(v):
        return None
    ey = y / np.linalg.norm(y)
    R = np.vstack([ex, ey, np.cross(ex, ey)])
    Rb = np.zeros((6, 6))
    Rb[:3, :3] = Rb[3:, 3:] = R
    K_loc = Rb @ K_bb @ Rb.T
    d = np.sqrt(np.abs(np.diag(K_loc)))
    scaled = K_loc / np.outer(d, d)
    T = np.hstack([-gamma, np.eye(6)])
    parts, covered = [], np.zeros((6, 6), bool)
    for grp in _GROUPS:
        mask = np.zeros((6, 6), bool)
        mask[np.ix_(grp, grp)] = True
        covered |= mask
        Kg = Rb.T @ np.where(mask, K_loc, 0.0) @ Rb
        parts.append(T.T @ Kg @ T)
    if np.max(np.abs(scaled[~covered])) > SPLIT_RTOL:
        return None
    parts = np.array(parts)
    # what the blocks leave out (the rounding-level coupling) shared evenly, so that the parts sum
    # to K_e exactly and "sections" at four equal factors IS "whole" (exact nesting)
    parts += (K_e - parts.sum(axis=0)) / len(parts)
    return 0.5 * (parts + parts.transpose(0, 2, 1))


def orientation(deck, eid: int) -> np.ndarray | None:
    """The orientation vector of CBAR ``eid`` (basic system): ``X1 X2 X3`` or ``G0 - GA``."""
    b = deck.cbars[eid]
    if b.x is not None:
        return np.asarray(b.x, float)
    if b.g0 is not None and b.g0 in deck.grids:
        return np.subtract(deck.grids[b.g0].xyz, deck.grids[b.ga].xyz)
    return None


@register
@dataclass(frozen=True, eq=False)
class MemberStiffness(Effect):
    """``dofs``: the member's 12 end DOFs in the split deck; ``K_e`` its stiffness over them."""
    kind = "member_stiffness"
    summary = ("a member's stiffness differs from the deck's (a factor on its element matrix, or on its "
               "EA, EI1, EI2, GJ parts)")

    dofs: tuple[DofLabel, ...] = ()
    K_e: np.ndarray | None = None
    parts: np.ndarray | None = None         # (4, 12, 12) section parts, None: "whole" only
    start_removed: bool = False             # the refit also starts with the member removed
    start_turned: bool = False              # ("sections") the refit also starts at the turned section
    cap: tuple | None = None                # ("bending") upper bounds at the turned section's factors

    @property
    def eid(self) -> int:
        return int(self.where[0])

    @classmethod
    def selected(cls, ctx) -> list[int]:
        """The members considered: every member, or beyond ``ctx.max_member_candidates`` those
        nearest the declared fit's residual (their midpoints; the limit noted in ``ctx``)."""
        eids = sorted(ctx.K_e)
        if len(eids) <= ctx.max_member_candidates:
            return eids
        xyz = {g.id: np.asarray(g.xyz, float) for g in ctx.deck.grids.values()}
        mid = {e: 0.5 * sum(xyz[g] for g in member_ends(ctx.deck, e)) for e in eids}
        chosen = ctx.nearest_residual(mid, ctx.max_member_candidates)
        ctx.note_limit(CandidateLimit(cls.kind, len(chosen), len(eids),
                                      "the members nearest the declared fit's residual" if ctx.residual_rms is not None
                                      else "the members nearest the measured grids (no declared fit)",
                                      "max_member_candidates"))
        return chosen

    @classmethod
    def split_rows(cls, ctx, split) -> tuple[DofLabel, ...]:
        """The end DOFs of the members considered: their score needs the split run's rows there."""
        return tuple(d for eid in cls.selected(ctx) for d in split.member_dofs[eid])

    @classmethod
    def candidates(cls, ctx, split) -> list["MemberStiffness"]:
        out = []
        for eid in cls.selected(ctx):
            v = orientation(ctx.deck, eid) if eid in ctx.deck.cbars else None
            # the parts from K_e in basic (the element axes are read there), both then in the
            # components of the member's grids (their CD systems), as the split deck has them
            parts = section_parts(ctx.K_e[eid], v) if v is not None else None
            K = in_member_frames(ctx.deck, eid, ctx.K_e[eid])
            if parts is not None:
                parts = in_member_frames(ctx.deck, eid, parts)
            out.append(cls((eid,), (f"alpha_{eid}",), "whole" if parts is not None else "",
                           dofs=split.member_dofs[eid], K_e=K, parts=parts))
        return out

    @property
    def variant_tests(self) -> int:
        return 1 if self.variant in ("whole", "bending") and self.parts is not None else 0

    def _as(self, variant: str, **kw) -> "MemberStiffness":
        """This member as ``variant`` ("sections": EA, EI1, EI2, GJ; "bending": EI1, EI2)."""
        names = {"sections": SECTIONS, "bending": SECTIONS[1:3]}[variant]
        return MemberStiffness(self.where, tuple(f"{s}_{self.eid}" for s in names), variant,
                               dofs=self.dofs, K_e=self.K_e, parts=self.parts, **kw)

    def richer(self, x_effect):
        """"whole" -> "sections", all four factors at the whole factor; "bending" ->
        "sections", EA and GJ at 1."""
        if self.parts is None or self.variant not in ("whole", "bending"):
            return []
        x = np.asarray(x_effect, float)
        start = np.full(4, float(x[0])) if self.variant == "whole" else np.array([1.0, x[0], x[1], 1.0])
        return [(self._as("sections"), start)]

    @property
    def bounds(self):
        hi = np.full(self.n_params, FACTOR_MAX) if self.cap is None else np.asarray(self.cap, float)
        return np.full(self.n_params, ALPHA_MISSING), hi

    def rejection(self, x_effect) -> str | None:
        """Only the upper bound ``FACTOR_MAX`` is beyond any plausible value: a factor at
        ``ALPHA_MISSING`` is the member not being there (module docstring), one at its
        :attr:`cap` the turned section."""
        x = np.asarray(x_effect, float)
        for name, v in zip(self.names, x):
            if abs(v - FACTOR_MAX) <= 1e-9 * FACTOR_MAX:
                return (f"{name} ends at its upper bound {FACTOR_MAX:g}: beyond any plausible value, the effect "
                        "absorbs a misfit it does not describe")
        return None

    def capped(self, x_effect) -> "MemberStiffness | None":
        """A section refitted from its turned point (``start_turned``) whose stiffened plane's
        factor ran on to ``FACTOR_MAX``: the same variant with that factor's bound at the turned
        value (``I1/I2``). A weak turn tells the softened plane well and the stiffened one hardly
        at all (a plane already far stiffer than its surroundings), so that factor runs loose
        from the turned value to the bound."""
        tp = self.turned_point
        if not self.start_turned or self.variant != "bending" or tp is None or self.cap is not None:
            return None
        x = np.asarray(x_effect, float)
        at_max = np.abs(x - FACTOR_MAX) <= 1e-9 * FACTOR_MAX
        if not np.any(at_max & (tp > 1.0)) or np.any(at_max & (tp <= 1.0)):
            return None
        return replace(self, cap=tuple(np.where(at_max, tp, FACTOR_MAX)))

    @property
    def screen_point(self) -> np.ndarray:
        """The member removed: every factor at ``ALPHA_MISSING``."""
        return np.full(self.n_params, ALPHA_MISSING)

    @property
    def bending_ratio(self) -> float | None:
        """``I2 / I1`` as the section parts hold it (the plane-2 bending part's size over the
        plane-1 part's: the two have the same pattern, scaled by E I2 and E I1), ``None``
        without parts."""
        if self.parts is None:
            return None
        n1, n2 = np.linalg.norm(self.parts[1]), np.linalg.norm(self.parts[2])
        return float(n2 / n1) if n1 > 0.0 and n2 > 0.0 else None

    @property
    def turned_point(self) -> np.ndarray | None:
        """``(EI1, EI2)`` factors of the section turned 90 degrees about the member's axis: I1
        and I2 exchanged, ``EI1`` at ``I2/I1`` and ``EI2`` at ``I1/I2`` (the shear terms of a
        Timoshenko beam are scaled with their plane, close enough for a start). ``None`` for a
        section whose two moments differ by less than ``TURN_MIN``: turning it changes too
        little to look for."""
        r = self.bending_ratio
        if r is None or abs(np.log(r)) < np.log(TURN_MIN):
            return None
        return np.array([r, 1.0 / r])

    def screen_points(self):
        """The member removed ("whole" at ``ALPHA_MISSING``) and, for a bar whose section has
        two different bending stiffnesses, the section turned about its axis (the "bending"
        variant, EI1 and EI2 factors with EA and GJ as they are, at :attr:`turned_point`): a
        single factor cannot describe it, since plane 1 gets stiffer where plane 2 gets softer,
        so its score and its "whole" refit miss it."""
        out = [(self, self.screen_point)]
        if self.variant == "whole" and self.turned_point is not None:
            out.append((self._as("bending"), self.turned_point))
        return out

    def started_at_screen(self, which: int = 0) -> "MemberStiffness":
        if which == 1 and self.variant == "whole":
            return self._as("bending", start_turned=True)
        return replace(self, start_removed=True)

    def refit_starts(self, x2, step, lo, hi, first):
        """The nested point, the score step, and, when the screen showed more than the score,
        the member removed (:attr:`start_removed`) or its section turned (:attr:`start_turned`;
        the score step is then that of the "whole" factor, of another size, and not taken)."""
        if self.start_turned:
            xs = x2.copy()
            xs[first:] = np.clip(self.turned_point, lo[first:], hi[first:])
            return [x2, xs]
        starts = super().refit_starts(x2, step, lo, hi, first)
        if self.start_removed:
            xs = x2.copy()
            xs[first:] = ALPHA_MISSING
            starts.append(xs)
        return starts

    def findings(self, fit) -> dict:
        """``missing``: which of the factors ended below ``MISSING_BELOW`` (the member, or that
        part of its stiffness, is not there: missing, broken or not connected); ``turned``: the
        EI1 and EI2 factors each went ``TURNED_SHARE`` of the way (in log) to the exchanged
        moments (the section mounted turned 90 degrees about the member's axis)."""
        e, sl = self.in_fit(fit)
        x = fit.x[sl]
        low = [n for n, v in zip(e.names, x) if v < MISSING_BELOW]
        out = {"missing": low} if low else {}
        if e.cap is not None:
            held = [n for n, v, c in zip(e.names, x, e.cap) if c < FACTOR_MAX and abs(v - c) <= 1e-9 * c]
            if held:
                # the stiffened plane ran loose to FACTOR_MAX: held at the turned value, which
                # the data do not tell from any stiffer one (search.refit_candidate)
                out["held_at_turned_value"] = held
        ei = {"sections": x[1:3], "bending": x[0:2]}.get(e.variant)
        if ei is not None and e.turned_point is not None:
            share = np.log(ei) / np.log(e.turned_point)
            if np.all((share >= TURNED_SHARE[0]) & (share <= TURNED_SHARE[1])):
                out["turned"] = True
        return out

    @property
    def stiffness_dofs(self) -> tuple[DofLabel, ...]:
        return self.dofs

    def stiffness_terms(self):
        if self.variant == "sections":
            return [(q, self.parts[q]) for q in range(4)]
        if self.variant == "bending":
            return [(0, self.parts[1]), (1, self.parts[2])]
        return [(0, self.K_e)]

    def refit_columns(self) -> tuple[DofLabel, ...]:
        return self.dofs

    @classmethod
    def batch_columns(cls, model, st, x, om, effects):
        """``d prediction / d alpha_e`` at ``alpha_e = 1`` for members NOT in ``model``, by
        reciprocity (:func:`stiffness_columns`): no column of the member's own is needed."""
        if any(e.variant != "whole" and e.variant != "" for e in effects):
            return None
        return stiffness_columns(model, st, x, om, [(e.dofs, e.K_e) for e in effects])

    def marker_points(self, xyz, deck):
        ga, gb = member_ends(deck, self.eid)
        return [(xyz[ga] + xyz[gb]) / 2]


def stiffness_columns(model, st, x, om, terms) -> np.ndarray:
    """Unwhitened score columns ``(n_obs, len(terms))`` of stiffness terms NOT in ``model``, one
    per ``(dofs, K)`` (``dK = t K`` over the split deck's ``dofs``, at ``t = 0``), by reciprocity:
    ``u_E`` and ``G_ES``, ``G_OE`` are rows of the split run at the DOFs ``E``, so no unit-load
    column at ``E`` is needed (a member's factor, a permanent load's geometric stiffness)."""
    nS, m = model.nS, model.m
    IDK = np.eye(m) - st.D * model.K0[None, :]
    cond = model.cond
    out = np.zeros((len(om.y), len(terms)))
    # G_OE by reciprocity needs unit-load columns at the observed DOFs; the DOFs only a mix
    # may read (a neighbour of a sensor) have none until an effect that reads them is added
    # (the search loads them then), so until then their rows are not used and stay 0
    loaded = [i for i, d in enumerate(model.o_dofs) if d in cond.base.col_of]
    o_loaded = [model.o_dofs[i] for i in loaded]
    from blackbox.diagnosis.model import MANY_GROUPS, per_case

    groups = st.each()
    many = None
    if len(groups) > MANY_GROUPS:
        dKs, As, _, index = st.stacked
        many = (As, dKs, index)
    for q, (dofs, K) in enumerate(terms):
        E = list(dofs)
        G_ES = cond.G(E, model.S) if nS else np.zeros((len(E), 0))
        Z_E = cond.Z(E)
        G_OE = np.zeros((len(model.o_dofs), len(E)))
        G_OE[loaded] = cond.G(o_loaded, E)
        u0E = cond.u0(E)
        dU = np.zeros_like(st.U_O)
        if many is not None:                     # every case with its own joint stiffness at once
            As, dKs, index = many
            u_E = u0E - G_ES @ per_case(dKs, index, st.u_S) - Z_E @ st.f
            F = K @ u_E
            dz = -per_case(As, index, np.vstack([G_ES.T @ F, IDK @ (Z_E.T @ F)]))
            dU = -model.Gos @ per_case(dKs, index, dz[:nS]) - G_OE @ F - model.Zo @ dz[nS:]
        for cols, dK, Ainv, _ in ([] if many is not None else groups):   # cases with their own
            u_E = u0E[:, cols] - G_ES @ (dK @ st.u_S[:, cols]) - Z_E @ st.f[:, cols]   # joint stiffness
            F = K @ u_E                                               # (|E|, cases)
            rhs = np.vstack([G_ES.T @ F, IDK @ (Z_E.T @ F)])
            dz = -Ainv @ rhs
            du_S, df = dz[:nS], dz[nS:]
            dU[:, cols] = -model.Gos @ (dK @ du_S) - G_OE @ F - model.Zo @ df
        out[:, q] = model.pick(dU, x, om)
    return out * model.multiplier(x, om)[:, None]
