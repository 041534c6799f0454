"""``blackbox simulate STUDY --truth TRUTH.toml``: a copy of the study with simulated measurements.

The truth is joint models with values, the stub "actual joint" of Section 5.4.1, or another
deck; the noise model, force-scale bias, eq. 33 averaging and reference-point measurement are
Section 5.2's (:mod:`blackbox.simulation`). The joint truths go through the study's declared model
(:mod:`blackbox.declared`): rigid pairs and deck springs act in the simulation as in the fit.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from blackbox import simulation as sim
from blackbox.commands.common import as_study, copy_study, study_adapter
from blackbox.condensation import CondensedModel, condense
from blackbox.declared import DeclaredModel, declared_model, read_truth, truth_joints
from blackbox.errors import StudyError
from blackbox.joints import joint_dofs
from blackbox.study import Study, joint_branches
from solver_adapters.protocol import DofLabel, LoadMatrix, SolverAdapter

__all__ = ["SimulateResult", "run", "measured_dofs"]


@dataclass(frozen=True, eq=False)
class SimulateResult:
    """Simulated measurement rows and the record of how they were made (``truth.json``)."""
    study: Study
    rows: list[tuple[str, int, int, float, float, int | None]]   # case, grid, component, value, sigma, ref
    record: dict
    command: str = "simulate"
    notes: list[str] = field(default_factory=list)

    @property
    def n_measurements(self) -> int:
        return len(self.rows)

    def measurements_csv(self) -> str:
        relative = any(r[5] is not None for r in self.rows)
        out = ["case,grid,component,value,sigma" + (",reference_grid" if relative else "")]
        for c, g, comp, v, s_, rg in self.rows:
            tail = ("," + ("" if rg is None else str(rg))) if relative else ""
            out.append(f"{c},{g},{comp},{float(v)!r},{float(s_)!r}{tail}")
        return "\n".join(out) + "\n"

    def write(self, out: Path) -> list[str]:
        """A new study folder: the study's own files (no symbolic link followed out of it), the
        simulated ``measurements.csv`` and ``truth.json``."""
        out = Path(out)
        files = copy_study(self.study, out, skip=("measurements.csv", "truth.json"))
        (out / "measurements.csv").write_text(self.measurements_csv())
        (out / "truth.json").write_text(json.dumps(self.record, indent=2))
        return files + ["measurements.csv", "truth.json"]


def measured_dofs(study: Study, m: sim.MeasureConfig) -> list[DofLabel]:
    """The DOFs a truth's ``[measure]`` table asks for, in order, without repeats."""
    dofs: list[DofLabel] = []
    if m.joint:
        for j in study.config.joints:
            dofs += joint_dofs(j.grids)
    dofs += [tuple(d) for d in m.away]
    dofs += [(g, c) for g in m.away_grids for c in range(1, 7)]
    return list(dict.fromkeys(dofs))


def _joint_truth_response(declared: DeclaredModel, adapter: SolverAdapter, true_loads: LoadMatrix,
                          needed: list[DofLabel], joints, k_true) -> np.ndarray:
    """Responses at ``needed`` of the structure with the truth's joints (the study's rigid pairs
    and deck springs included), from one batched run."""
    boundary = [d for j in joints for d in j.dofs]
    c = condense(adapter, true_loads, boundary, needed)
    truth_model = DeclaredModel(declared.study, tuple(joints), k_true, declared.options, (),
                                declared.deck_stiffness)
    model: CondensedModel = truth_model.condensed_model(c)
    return model.pick(model.response(k_true), needed)


def run(study: Study | str | Path, truth_path: str | Path, *, adapter: str | SolverAdapter | None = None) -> SimulateResult:
    """Simulate the measurements that ``truth_path`` describes on ``study``'s structure."""
    study = as_study(study)
    truth_path = Path(truth_path)
    truth = read_truth(truth_path)
    m = truth.measure
    cases = list(m.cases) or list(study.loads.cases)
    unknown = [c for c in cases if c not in study.loads.cases]
    if unknown:
        raise StudyError(f"measure.cases {unknown} are not load cases of the study", file=str(truth_path))
    if m.reference_grid is not None and m.averaging_points:
        raise StudyError("measure.averaging_points and measure.reference_grid cannot be combined",
                         file=str(truth_path))
    loads = study.loads.select([study.loads.cases.index(c) for c in cases])
    true_loads = LoadMatrix(loads.dofs, loads.values * truth.force_scale, loads.cases)
    dofs = measured_dofs(study, m)
    if not dofs:
        raise StudyError("nothing to measure: set measure.joint = true or list measure.away",
                         file=str(truth_path))
    deck = study.deck
    bad = [d for d in dofs if d[0] not in deck.grids or not 1 <= d[1] <= 6]
    if bad:
        raise StudyError(f"measured DOFs {bad[:5]} are not in the deck", file=str(truth_path))
    branches = {}
    extra: list[DofLabel] = []
    if m.averaging_points:
        for j in study.config.joints:
            for b in joint_branches(deck, j.grids):
                bar = deck.cbars[b.eid]
                other = bar.gb if bar.ga == b.grid else bar.ga
                branches[b.grid] = (b, other)
                extra += [(b.grid, c) for c in range(1, 7)] + [(other, c) for c in range(1, 7)]
    if m.reference_grid is not None:
        extra += [(m.reference_grid, c) for c in range(1, 7)]
    needed = list(dict.fromkeys(dofs + extra))

    if truth.deck:
        truth_deck = (truth_path.parent / truth.deck).resolve()
        tadapter = study_adapter(study, adapter if isinstance(adapter, str) else None, deck=truth_deck)
        U = tadapter.solve(true_loads, needed).values
        k_true, names, runs = np.zeros(0), [], tadapter.stats.runs
    else:
        if not truth.joints:
            raise StudyError("the truth names no [[joints]] and no deck: nothing to simulate", file=str(truth_path))
        ad = study_adapter(study, adapter)
        joints, k_true = truth_joints(study, truth, truth_path)
        U = _joint_truth_response(declared_model(study), ad, true_loads, needed, joints, k_true)
        names = [(j.name, n) for j in joints for n in j.param_names]
        runs = ad.stats.runs
    row = {d: i for i, d in enumerate(needed)}
    rng = np.random.default_rng(truth.seed)
    if m.reference_grid is not None:     # the reference grid itself is measured absolutely
        dofs = [(m.reference_grid, c) for c in range(1, 7)] + [d for d in dofs if d[0] != m.reference_grid]
    rows = sim.simulate_rows(U, row, len(cases), dofs, truth.noise, rng, m.reference_grid)
    dof_rows, ci, true, kinds = rows.dofs, rows.case_index, rows.true, rows.kinds
    values, sigma = rows.values.copy(), rows.sigma.copy()
    refs = [None if r is None else r[0] for r in rows.refs]
    if m.averaging_points:
        s = np.arange(m.averaging_points) * m.averaging_spacing
        xyz = {g.id: np.array(g.xyz, float) for g in deck.grids.values()}
        rot_scale = np.array([np.abs(true[(ci == j) & (kinds == 1)]).max(initial=0.0) for j in range(len(cases))])
        for g, (b, other) in branches.items():
            ua = U[[row[(g, c)] for c in range(1, 7)], :]
            ub = U[[row[(other, c)] for c in range(1, 7)], :]
            samples = sim.member_end_rotation_samples(ua, ub, xyz[g], xyz[other], np.array(b.orientation), s)
            mean, s_mean = sim.averaged_rotation(samples, truth.noise, rng, rot_scale)
            for i, (d, j) in enumerate(zip(dof_rows, ci)):
                if d[0] == g and d[1] >= 4:
                    values[i], sigma[i] = mean[d[1] - 4, j], s_mean[d[1] - 4, j]
    out_rows = [(cases[j], int(g), int(comp), float(v), float(s_), rg)
                for (g, comp), j, v, s_, rg in zip(dof_rows, ci, values, sigma, refs)]
    record = {"truth_file": str(truth_path), "seed": truth.seed, "force_scale": truth.force_scale,
              "noise": truth.noise.model_dump(), "measure": truth.measure.model_dump(),
              "deck": truth.deck, "parameters": [{"joint": j, "name": n, "value": float(v)}
                                                for (j, n), v in zip(names, k_true)],
              "n_measurements": len(out_rows), "cases": cases, "solver_runs": runs}
    return SimulateResult(study, out_rows, record)
