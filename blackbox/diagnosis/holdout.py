"""The hold-out cases, read once more at the end: are they predicted, and if not, where not?

The search never fits a hold-out case, so it cannot find a defect confined to one: a transducer
clipped past its range in the one case that loads it hardest, a hold-out case loaded the other
way. Its checks only compare the hold-out chi2 of two fits. What the final model predicts for
the hold-out readings is fixed once the fit rows are fitted, so they can be tested against that
prediction directly, with three tests at ``alpha / 3`` each (``alpha`` the search's level; on
data the model describes, the chance that any of them fires is below ``alpha``):

* **each case**: its chi2 against ``chi2(n_c)`` at ``alpha / (3 C)`` (``C`` hold-out cases).
  A case beyond it has up to :data:`OUTLIERS_PER_CASE` of its readings set aside as outliers
  (largest ``|z|`` first, each beyond the reading level below); when that brings the rest of
  the case within its level those readings are the finding, else the whole case is. A case is
  then tried as what a rig gets wrong in one case (:func:`_as_case`): its prediction times one
  factor, on the load (``-1``: loaded the other way) or on the readings, noise and all
  (``1000``: another unit); another case's prediction (two files mixed up, one saved twice);
  its prediction plus one rigid motion of the specimen; one of its loads turned off its declared
  direction, or put in at a neighbouring grid (the final model with that effect, its one or two
  parameters fitted to the case's readings alone). Otherwise it is not predicted.
* **each reading** of a case that passes: ``|z| > z*``, two-sided at ``alpha / (3 n)`` (``n``
  hold-out readings): an outlier.
* **the rest** (the readings of no finding): its chi2 against ``chi2(n_rest)`` at ``alpha / 3``.
  Beyond it, the hold-out cases are not predicted by the final model, though no single case or
  reading is to blame.

``z`` and the chi2 take the prediction's own uncertainty into account: a hold-out reading's
residual is the reading's noise plus the error of the fitted parameters carried to it, with
covariance ``I + A A^T`` (whitened; ``A = J_h W S^-1``, the hold-out Jacobian in the fit's
singular basis: ``(J^T J)^+`` restricted to the free parameters that the fit rows determine).
A parameter at a bound (a spring at 0, a rigid joint) is held there. Readings an effect of the
final model sets aside in every case (a bad channel's) are left out.

That linear error is blind where the fit rows leave parameters loose (a spring at a bound, or
so undetermined that its error is not linear over its range): a hold-out case that loads such a
parameter can be far off the prediction while a model the fit rows cannot tell from the fitted
one predicts it. So a case beyond its level is first fitted together with the fit rows
(:func:`~blackbox.diagnosis.fit.fit_model` from the final fit): when the fit rows' chi2 rises by
no more than ``chi2(p)`` at ``alpha`` (``p`` the model's parameters other than offsets that set
readings aside: Scheffe's simultaneous region) and the case is then within its level, it is
*predicted with loose parameters*, which the report names, and no finding.

An outlier or a case read as one of those descriptions is a defect of the data and the
diagnosis says so; a case or a rest that is not predicted leaves the verdict "unexplained", since
the model does not describe data it was not fitted to (:func:`blackbox.diagnosis.search.verdict`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import linalg, stats

from blackbox.diagnosis.fit import Fit, fit_model, prediction_basis
from blackbox.diagnosis.effects.base import SetAsideEffect, takes_readings
from blackbox.diagnosis.effects.rigid_motion import rigid_weights
from blackbox.diagnosis.model import AugmentedModel, ObsMap
from blackbox.diagnosis.validation import inside_bounds
from blackbox.errors import IdentificationError

__all__ = ["HoldoutReading", "HoldoutCase", "HoldoutCheck", "check_holdout", "read_holdout", "prediction_basis",
           "free_parameters", "OUTLIERS_PER_CASE", "TESTS"]

OUTLIERS_PER_CASE = 2       # readings of one case set aside as outliers before the case is the finding
TESTS = 3                   # the tests alpha is split among (module docstring)


@dataclass(frozen=True)
class HoldoutReading:
    """One hold-out reading beyond its level: ``z`` its standardized residual (the prediction's
    uncertainty included)."""
    grid: int
    component: int
    case: str
    measured: float
    predicted: float
    z: float

    def to_json(self) -> dict:
        return {"grid": self.grid, "component": self.component, "case": self.case, "measured": self.measured,
                "predicted": self.predicted, "z": self.z}


@dataclass(frozen=True)
class HoldoutCase:
    """A hold-out case beyond its level (``chi2`` over ``n`` readings, ``limit`` its level) and
    what it reads as, when one of the descriptions of :func:`_as_case` fits it (``reads_as``:
    ``"load_scale"``, ``"readings_scale"``, ``"other_case"``, ``"rigid_motion"``,
    ``"load_tilt"``, ``"misplaced_load"``; ``None``: not predicted). ``scale``/``scale_std``:
    the factor; ``other``: the case whose prediction it reads as; ``motion``: the rigid
    translation (length) and rotation (rad); ``load``: the turned or misplaced load (its grid,
    the angle or the grid it went in at, the fitted parameters); ``fitted_chi2``: the case's
    chi2 so described."""
    case: str
    n: int
    chi2: float
    limit: float
    reads_as: str | None = None
    fitted_chi2: float | None = None
    scale: float | None = None
    scale_std: float | None = None
    other: str | None = None
    other_response: bool = False            # the other case's response, its own readings set aside
    motion: tuple[float, ...] | None = None
    load: dict | None = None

    @property
    def explained(self) -> bool:
        return self.reads_as is not None

    def sentence(self) -> str:
        if self.reads_as is None:
            return (f"hold-out case {self.case} is not predicted (chi2 {self.chi2:.4g} over {self.n} readings, "
                    f"beyond {self.limit:.4g}); no factor on its load or readings, no other case's prediction, "
                    "no rigid motion of the specimen and no load of it turned or at a neighbouring grid fits it")
        if self.reads_as in ("load_tilt", "misplaced_load"):
            how = self.load["finding"]
        elif self.reads_as == "other_case":
            how = (f"the model's response to case {self.other}'s load, whose own readings the diagnosis set aside "
                   f"(the readings of cases {self.case} and {self.other} exchanged)" if self.other_response else
                   f"case {self.other}'s readings (the files of two cases mixed up, or one saved twice)")
        elif self.reads_as == "rigid_motion":
            t, w = self.motion[:3], self.motion[3:]
            how = ("its prediction plus one rigid motion of the whole specimen (a support base or the "
                   f"reference frame moved: translation {', '.join(f'{v:.3g}' for v in t)}, rotation "
                   f"{', '.join(f'{v:.3g}' for v in w)} rad)")
        elif abs(self.scale + 1.0) <= max(3.0 * (self.scale_std or 0.0), 0.05):
            how = f"loaded the other way (its prediction times {self.scale:.4g} +- {self.scale_std:.2g})"
        elif self.reads_as == "readings_scale":
            how = (f"its prediction read {self.scale:.4g} +- {self.scale_std:.2g} times, noise and all "
                   "(another unit or gain)")
        else:
            how = f"loaded {self.scale:.4g} +- {self.scale_std:.2g} times as declared"
        return (f"hold-out case {self.case} reads as {how}: chi2 {self.chi2:.4g} -> {self.fitted_chi2:.4g} over "
                f"{self.n} readings")

    def to_json(self) -> dict:
        return {"case": self.case, "n": self.n, "chi2": self.chi2, "limit": self.limit, "reads_as": self.reads_as,
                "fitted_chi2": self.fitted_chi2, "scale": self.scale, "scale_std": self.scale_std,
                "other": self.other, "other_response": self.other_response,
                "motion": None if self.motion is None else list(self.motion), "load": self.load,
                "of": "data" if self.explained else "unknown", "finding": self.sentence()}


@dataclass(frozen=True)
class HoldoutCheck:
    """The result of :func:`check_holdout` (module docstring)."""
    n: int
    chi2: float                         # all hold-out rows checked, prediction uncertainty included
    n_rest: int
    chi2_rest: float                    # the rows of no finding
    limit_rest: float                   # the rest's chi2 level
    z_limit: float                      # a reading's level
    readings: tuple[HoldoutReading, ...] = ()
    cases: tuple[HoldoutCase, ...] = ()
    alpha: float = 0.01
    set_aside: int = 0                  # rows an effect of the model sets aside, not checked
    per_case: dict = field(default_factory=dict)    # case -> (chi2, n)
    loose: tuple = ()                   # (case, fit rows' chi2 rise, its limit, case chi2 then, its level)

    @property
    def predicted(self) -> bool:
        """Whether the final model predicts the hold-out cases, once the defects of the data
        found in them are set aside."""
        return self.chi2_rest <= self.limit_rest and all(c.explained for c in self.cases)

    @property
    def findings(self) -> int:
        """Defects of the data found in the hold-out cases."""
        return len(self.readings) + sum(c.explained for c in self.cases)

    def notes(self) -> list[str]:
        """What is said of the hold-out cases and is no finding."""
        return [f"hold-out case {c} is predicted only with parameters the fitted cases leave loose (fitted with "
                f"them: fitted chi2 {d:+.4g}, within {dl:.4g}; the case's chi2 {q:.4g}, within {ql:.4g})"
                for c, d, dl, q, ql in self.loose]

    def sentences(self) -> list[str]:
        out = [f"hold-out reading at grid {r.grid}, component {r.component}, case {r.case} is an outlier "
               f"({r.measured:.4g} against {r.predicted:.4g} predicted, z {r.z:+.3g})" for r in self.readings]
        out += [c.sentence() for c in self.cases]
        if self.chi2_rest > self.limit_rest:
            out.append(f"the other hold-out readings are not predicted (chi2 {self.chi2_rest:.4g} over "
                       f"{self.n_rest}, beyond {self.limit_rest:.4g})")
        return out

    def to_json(self) -> dict:
        return {"n": self.n, "chi2": self.chi2, "n_rest": self.n_rest, "chi2_rest": self.chi2_rest,
                "limit_rest": self.limit_rest, "z_limit": self.z_limit, "predicted": self.predicted,
                "alpha": self.alpha, "set_aside_by_effects": self.set_aside,
                "outliers": [r.to_json() for r in self.readings], "cases": [c.to_json() for c in self.cases],
                "per_case": {k: {"chi2": v[0], "n": v[1]} for k, v in self.per_case.items()},
                "loose": [{"case": c, "fitted_chi2_rise": d, "rise_limit": dl, "chi2": q, "limit": ql}
                          for c, d, dl, q, ql in self.loose],
                "findings": self.sentences(), "notes": self.notes()}


def free_parameters(model: AugmentedModel, fit: Fit) -> np.ndarray:
    """The parameters of ``fit`` strictly inside their bounds (a spring at 0 or at its rigid
    limit is held there)."""
    _, lo, hi = fit.spec.transforms()
    return inside_bounds(fit.x, lo, np.minimum(hi, model.rigid_limits()))


def _chi2(r: np.ndarray, A: np.ndarray) -> float:
    """``r^T (I + A A^T)^-1 r`` by Woodbury."""
    if A.shape[1] == 0:
        return float(r @ r)
    b = A.T @ r
    return float(r @ r - b @ np.linalg.solve(np.eye(A.shape[1]) + A.T @ A, b))


def fit_load(model: AugmentedModel, x: np.ndarray, effects, rows: ObsMap,
             iterations: int = 30) -> tuple[np.ndarray, np.ndarray] | None:
    """``(parameters, predictions)``: the parameters of the load effects ``effects`` (the last of
    ``x``, just added to ``model`` in that order) fitted by Gauss-Newton within their bounds to
    the rows ``rows`` alone, every other parameter held; started at the nested point and, for
    shares, at the whole defect too (the better kept). ``None`` when the model cannot be
    evaluated."""
    k = sum(e.n_params for e in effects)
    lo = np.concatenate([e.bounds[0] for e in effects])
    hi = np.concatenate([e.bounds[1] for e in effects])
    nominal = np.concatenate([e.nominal for e in effects])
    share = all(np.all(e.nominal == 0.0) and e.one_sided.all() for e in effects)
    starts = [np.asarray(nominal, float)] + ([np.ones(k)] if share else [])
    best = None
    for start in starts:
        xk = np.clip(start, lo, hi)
        for _ in range(iterations):
            x2 = np.concatenate([x[:-k], xk])
            try:
                st = model.state(x2)
                f = model.predict(x2, rows, st)
                J = model.jacobian(x2, rows, st)[:, -k:] / rows.sigma[:, None]
            except (np.linalg.LinAlgError, IdentificationError):
                return None
            r = (rows.y - f) / rows.sigma
            step = np.linalg.lstsq(J, r, rcond=1e-10)[0]
            new = np.clip(xk + step, lo, hi)
            done = np.max(np.abs(new - xk)) < 1e-10 * max(1.0, float(np.max(np.abs(xk))))
            xk = new
            if done:
                break
        x2 = np.concatenate([x[:-k], xk])
        f = model.predict(x2, rows)
        q = float(np.sum(((rows.y - f) / rows.sigma) ** 2))
        if best is None or q < best[0]:
            best = (q, xk, f)
    return None if best is None else (best[1], best[2])


def check_holdout(model: AugmentedModel, fit: Fit, hold: ObsMap, alpha: float,
                  geometry: tuple | None = None, fitted: ObsMap | None = None,
                  noise_factor: float = 1.0, loads=None) -> HoldoutCheck:
    """The tests of the module docstring on ``fit``'s predictions of the rows ``hold``
    (``model``: the final model, ``fit`` its fit). ``geometry``: ``(grid -> (xyz, frame),
    centre)`` of the measured grids (as :class:`~blackbox.diagnosis.effects.rigid_motion.RigidMotion`
    holds them), to try a case as a rigid motion of the specimen; ``None``: not tried.
    ``fitted``: the fitted rows, whose declared sigma a case read as another's takes.
    ``noise_factor``: the readings' noise taken as that many times the declared sigma, every
    reading's, fitted or not (the parameters' error then grows by the same factor, so the
    prediction basis, in units of the noise, is the declared one). ``loads``: ``(effects_of,
    augment)``: ``effects_of(label)`` the load effects of that hold-out case (a load turned or
    misplaced there), which a case beyond its level is tried as, and ``augment(effects)`` the
    final model with them added and its parameters at their nested point (``None`` when it
    cannot be built); ``None``: not tried."""
    st = model.state(fit.x)
    f = model.predict(fit.x, hold, st)
    if model.p:
        Jh = model.jacobian(fit.x, hold, st) / hold.sigma[:, None]
        A = prediction_basis(fit.J, Jh, free_parameters(model, fit))
    else:
        A = np.zeros((len(hold.y), 0))
    if noise_factor != 1.0:
        hold = replace(hold, sigma=hold.sigma * noise_factor)
        fitted = None if fitted is None else replace(fitted, sigma=fitted.sigma * noise_factor)
    use = np.ones(len(hold.y), bool)
    for e in fit.spec.effects:
        aside = e.set_aside_rows(hold)
        if aside is not None:
            use &= ~aside

    sig: dict = {}

    # a case whose readings an effect sets aside (bad_case) is predicted with and without its
    # offsets: with them its prediction is its readings as read (a hold-out case saved from it
    # twice), without them the model's response to its load (a hold-out case it was swapped with)
    x_resp = fit.x.copy()
    for e, sl in zip(fit.spec.effects, fit.spec.effect_slices()):
        if isinstance(e, SetAsideEffect):
            x_resp[sl] = e.nominal
    st_resp = st if np.array_equal(x_resp, fit.x) else model.state(x_resp)

    def other_cases(rows: np.ndarray) -> list:
        if not sig:
            # each reading's declared sigma by (grid, component, case), fitted and hold-out rows:
            # a case that is another's readings carries that case's noise (built when a case
            # beyond its level is first tried, not on every diagnosis)
            for o in ((fitted,) if fitted is not None else ()) + (hold,):
                sig.update(zip(zip(o.grid.tolist(), o.comp.tolist(), o.case.tolist()), o.sigma.tolist()))
        out = []
        for k, lab in enumerate(hold.labels):
            om = replace(hold.subset(rows), case=np.full(len(rows), k))
            s_k = np.array([sig.get((g, c, k), s) for g, c, s in
                            zip(hold.grid[rows].tolist(), hold.comp[rows].tolist(), hold.sigma[rows].tolist())])
            fo = model.predict(fit.x, om, st)
            out.append((lab, fo, s_k, False))
            if st_resp is not st:
                fr = model.predict(x_resp, om, st_resp)
                if not np.array_equal(fr, fo):
                    out.append((lab, fr, s_k, True))
        return out

    rigid = None
    if geometry is not None:
        grid_map, centre = geometry

        def rigid(rows: np.ndarray) -> np.ndarray:
            W = np.zeros((len(rows), 6))
            known = np.isin(hold.grid[rows], list(grid_map))
            W[known] = rigid_weights(hold.grid[rows][known], hold.comp[rows][known], grid_map,
                                     np.asarray(centre, float), 1.0)
            return W
    loose = None
    if fitted is not None and model.p:
        p_model = len(fit.x) - sum(len(e.names) for e in fit.spec.effects if takes_readings(e))
        rise_limit = float(stats.chi2.isf(alpha, max(p_model, 1)))

        def loose(rows: np.ndarray) -> tuple[float, float, float] | None:
            both = ObsMap(*(np.concatenate([getattr(fitted, k), getattr(hold, k)[rows]]) for k in
                            ("row", "ref", "case", "grid", "y", "sigma", "comp")), hold.labels)
            try:
                g = fit_model(model, both, None, fit.x)
            except (np.linalg.LinAlgError, IdentificationError):
                return None
            r = g.residuals
            nf = len(fitted.y)
            # the final fit's chi2 in the noise the rows now carry
            return float(r[:nf] @ r[:nf]) - fit.chi2 / noise_factor ** 2, rise_limit, float(r[nf:] @ r[nf:])
    moved = None
    if loads is not None:
        def moved(rows: np.ndarray, label: str) -> list:
            """``[(kind, predictions at rows, parameters, the finding's fields)]`` of the case's
            loads turned or misplaced, each fitted to the case's readings; with more than one
            load, also all of them turned (each its own angles), and the loads put in at
            neighbours together: grid by grid, each time the grid and neighbour that fit best
            with those chosen before (:func:`_misplaced_together`)."""
            effects_of, augment = loads
            sub = hold.subset(rows)
            out = []
            mine = effects_of(label)
            for e in mine:
                built = augment([e])
                if built is None:
                    continue
                got = fit_load(*built, [e], sub)
                if got is None:
                    continue
                xk, fk = got
                if e.rejection(xk) is not None:
                    continue
                out.append((e.kind, fk, e.n_params, holdout_load([e], xk)))
            together = _misplaced_together([e for e in mine if e.kind == "misplaced_load"], augment, sub)
            for kind, group in (("load_tilt", [e for e in mine if e.kind == "load_tilt"]),
                                ("misplaced_load", together)):
                got = _fitted_together(group, augment, sub) if len(group) >= 2 else None
                if got is not None:
                    xk, fk = got
                    out.append((kind, fk, len(xk), holdout_load(group, xk)))
            return out
    return read_holdout(hold, f, A, use, alpha, other_cases, rigid, loose, moved)


def _fitted_together(group: list, augment, sub) -> tuple[np.ndarray, np.ndarray] | None:
    """``(parameters, predictions at sub)`` of the load effects ``group`` fitted together to the
    case's rows ``sub``; ``None`` when the model cannot be built, the fit fails, or a member's
    fitted parameters are no effect of its kind (its :meth:`~Effect.rejection`: a share of a
    misplacement mostly where declared, or beyond)."""
    built = augment(group)
    got = None if built is None else fit_load(*built, group, sub)
    if got is None:
        return None
    parts = np.split(got[0], np.cumsum([e.n_params for e in group])[:-1])
    return None if any(e.rejection(p) is not None for e, p in zip(group, parts)) else got


def _misplaced_together(cands: list, augment, sub) -> list:
    """The loads of a hold-out case put in at neighbours together, chosen grid by grid: each step
    adds the grid's misplacement (one of ``cands``, one per grid at most) that, fitted with
    those chosen before and every share one a misplacement has, leaves the lowest chi2 at the
    case's rows ``sub``, while that chi2 falls. One grid at a time because a single load's fit
    is confounded by the others when several moved (its best neighbour alone is then often the
    wrong one)."""
    chosen: list = []
    best_q = math.inf
    while True:
        step = None
        for e in cands:
            if any(c.grid == e.grid for c in chosen):
                continue
            got = _fitted_together(chosen + [e], augment, sub)
            if got is None:
                continue
            q = float(np.sum(((sub.y - got[1]) / sub.sigma) ** 2))
            if q < best_q and (step is None or q < step[0]):
                step = (q, e)
        if step is None:
            return chosen
        best_q = step[0]
        chosen.append(step[1])


def holdout_load(effects, xk: np.ndarray) -> dict:
    """What a hold-out case read as the load effects ``effects`` (one kind) at parameters ``xk``
    says: ``{"effect", "loads": [each one's place and size], "finding": a sentence}``."""
    parts = np.split(np.asarray(xk, float), np.cumsum([e.n_params for e in effects])[:-1])
    loads, said = [], []
    for e, p in zip(effects, parts):
        d = {"grid": e.grid, "parameters": {n: float(v) for n, v in zip(e.names, p)}, **e.details_json()}
        if e.kind == "load_tilt":
            deg, d0, d1 = e.turned(p)
            d.update(angle_deg=deg, declared_direction=[float(a) for a in d0], turned_direction=[float(a) for a in d1])
            said.append(f"its {d['vector']} at grid {e.grid} turned {deg:.3g} degrees")
        else:
            said.append(f"its load at grid {e.grid} put in at grid {e.moved_to} ({float(p[0]):.3g} of it)")
        loads.append(d)
    why = "a load mounted askew" if effects[0].kind == "load_tilt" else "an actuator on the neighbouring node"
    return {"effect": effects[0].kind, "loads": loads, "finding": f"{'; '.join(said)} ({why})"}


def read_holdout(hold: ObsMap, f: np.ndarray, A: np.ndarray, use: np.ndarray, alpha: float,
                 other_cases=None, rigid=None, loose=None, moved=None) -> HoldoutCheck:
    """The tests of the module docstring: the readings ``hold`` (rows ``use``) against the
    predictions ``f``, whose whitened covariance is ``A A^T`` (:func:`prediction_basis`);
    ``other_cases``, ``rigid``: what a case beyond its level is tried as (:func:`_as_case`);
    ``loose(rows)``: the case refitted with the fit rows, ``(their chi2 rise, its limit, the
    case's chi2)`` or ``None`` (module docstring); ``moved(rows, label)``: the case's loads turned
    or misplaced, fitted (:func:`check_holdout`)."""
    r_all = (hold.y - f) / hold.sigma
    n = int(use.sum())
    labels = hold.labels
    case_ids = list(dict.fromkeys(hold.case[use].tolist()))
    a_case = alpha / TESTS / max(len(case_ids), 1)
    a_read = alpha / TESTS / max(n, 1)
    z_lim = float(stats.norm.isf(a_read / 2.0))
    z = r_all / np.sqrt(1.0 + np.sum(A ** 2, axis=1))
    rest = use.copy()
    readings: list[HoldoutReading] = []
    cases: list[HoldoutCase] = []
    per_case = {}
    loosely: list[tuple] = []
    for c in case_ids:
        rows = np.flatnonzero(use & (hold.case == c))
        q = _chi2(r_all[rows], A[rows])
        per_case[labels[c]] = (q, len(rows))
        limit = float(stats.chi2.isf(a_case, len(rows)))
        if q > limit and loose is not None:
            lf = loose(rows)
            if lf is not None and lf[0] <= lf[1] and lf[2] <= limit:
                loosely.append((labels[c], *lf, limit))
                rest[rows] = False
                continue
        beyond = rows[np.abs(z[rows]) > z_lim]
        beyond = beyond[np.argsort(-np.abs(z[beyond]))]
        out = beyond                                        # a case within its level: its readings beyond theirs
        if q > limit:
            out = None
            if 0 < len(beyond) <= OUTLIERS_PER_CASE:
                kept = np.setdiff1d(rows, beyond)
                if len(kept) and _chi2(r_all[kept], A[kept]) <= float(stats.chi2.isf(a_case, len(kept))):
                    out = beyond
            if out is None:
                rest[rows] = False
                cases.append(_as_case(labels[c], rows, hold, f, A, q, limit, a_case, other_cases, rigid,
                                      None if moved is None else (lambda rr, lab=labels[c]: moved(rr, lab))))
                continue
        for i in out:
            rest[i] = False
            readings.append(HoldoutReading(int(hold.grid[i]), int(hold.comp[i]), labels[c], float(hold.y[i]),
                                           float(f[i]), float(z[i])))
    n_rest = int(rest.sum())
    chi2_rest = _chi2(r_all[rest], A[rest]) if n_rest else 0.0
    limit_rest = float(stats.chi2.isf(alpha / TESTS, n_rest)) if n_rest else 0.0
    return HoldoutCheck(n, _chi2(r_all[use], A[use]), n_rest, chi2_rest, limit_rest, z_lim, tuple(readings),
                        tuple(cases), alpha, int(len(use) - n), per_case, tuple(loosely))


def _as_case(label: str, rows: np.ndarray, hold: ObsMap, f: np.ndarray, A: np.ndarray, q: float, limit: float,
             a_case: float, other_cases=None, rigid=None, moved=None) -> HoldoutCase:
    """A case beyond its level, tried against what a rig gets wrong in one case, each within
    the case's level at ``a_case`` for its own degrees of freedom, the one with the least
    ``chi2 + k ln n`` (``k`` its parameters) kept:

    * its prediction times one factor ``s`` (least squares in the whitened readings), on the
      *load* (``s`` times as declared: the noise as declared, the prediction's error times ``s``)
      or on the *readings* (``s`` times what was measured, noise and all: another unit, a gain
      of the whole acquisition); ``s``'s standard error from both errors;
    * another case's prediction at the same channels (``other_cases(rows)``: ``(label,
      predictions, that case's declared sigma there, whether the predictions leave out the
      offsets that set that case's readings aside)``; no parameter): the files of two cases
      mixed up, or one saved twice;
    * its prediction plus one rigid motion of the specimen (``rigid(rows)``: the readings per
      unit translation and rotation, :func:`blackbox.diagnosis.effects.rigid_motion.rigid_weights`;
      up to six parameters);
    * one of its loads turned off its declared direction or put in at a neighbouring grid
      (``moved(rows)``: ``[(kind, predictions, parameters, fields)]``, each fitted to the case's
      readings; two parameters or one).

    The prediction's error enters the factor, the rigid motion and the loads; another case's
    prediction is compared with the noise alone."""
    n = len(rows)
    y = hold.y[rows] / hold.sigma[rows]
    p = f[rows] / hold.sigma[rows]
    pp = float(p @ p)
    tries = []                      # (chi2 + k ln n, chi2, reads_as, its fields of HoldoutCase)
    lnn = float(np.log(max(n, 2)))

    def level(k: int) -> float:
        return float(stats.chi2.isf(a_case, n - k)) if n > k else -1.0

    s = float(p @ y) / pp if pp > 0.0 else 0.0
    if s != 0.0:
        ap = A[rows].T @ p
        for qs, how, std in ((_chi2(y - s * p, s * A[rows]), "load_scale", float(np.sqrt(pp + s * s * (ap @ ap)) / pp)),
                             (_chi2(y / s - p, A[rows]), "readings_scale", float(abs(s) * np.sqrt(pp + ap @ ap) / pp))):
            if qs <= level(1):
                tries.append((qs + lnn, qs, how, {"scale": s, "scale_std": std}))
    if other_cases is not None:
        for other, fo, so, response in other_cases(rows):
            if other == label:
                continue
            qo = float(np.sum(((hold.y[rows] - fo) / so) ** 2))
            if qo <= level(0):
                tries.append((qo, qo, "other_case", {"other": other, "other_response": response}))
    if rigid is not None:
        W = rigid(rows) / hold.sigma[rows, None]
        seen = np.linalg.norm(W, axis=0) > 0
        if seen.any():
            # generalised least squares with the residual's covariance I + A A^T
            L = np.linalg.cholesky(np.eye(n) + A[rows] @ A[rows].T)
            Wl = linalg.solve_triangular(L, W[:, seen], lower=True)
            rl = linalg.solve_triangular(L, y - p, lower=True)
            theta, *_ = np.linalg.lstsq(Wl, rl, rcond=1e-8)
            rank = int(np.linalg.matrix_rank(Wl))
            qr = float(np.sum((rl - Wl @ theta) ** 2))
            if qr <= level(rank):
                motion = np.zeros(6)
                motion[seen] = theta
                tries.append((qr + rank * lnn, qr, "rigid_motion", {"motion": tuple(float(v) for v in motion)}))
    if moved is not None:
        for kind, fk, k, fields in moved(rows):
            qm = _chi2(y - fk / hold.sigma[rows], A[rows])
            if qm <= level(k):
                tries.append((qm + k * lnn, qm, kind, {"load": fields}))
    if not tries:
        return HoldoutCase(label, n, q, limit)
    _, qf, how, extra = min(tries, key=lambda t: t[0])
    return HoldoutCase(label, n, q, limit, how, qf, **extra)
