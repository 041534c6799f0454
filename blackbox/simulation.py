"""Simulation of measurements (Section 5.2).

The exact response comes from a *truth*: joint models with known parameters added to the
condensed structure (the same black-box condensation as the identification), or a different
deck solved as it is (for effects the study does not declare). It is then contaminated:

* Gaussian noise whose standard deviation is a fraction of each measured quantity's magnitude
  (the dissertation: 5 % of the actual rotation), with a floor so that a quantity that happens to
  be ~0 (a symmetric case) still gets a realistic error, and/or an absolute part;
* systematic bias by scaling the applied forces of the truth (Section 5.3.1): the study keeps
  the nominal loads, the "structure" felt scaled ones;
* branch rotations measured as the average of several points near the branch end (eq. 33):
  each point's rotation follows the member's cubic (Hermite) deflection, each has its own noise,
  the mean is reported with the sigma of the mean;
* measurement relative to a reference point (Section 5.2): each quantity is reported relative
  to the reference grid's same component (``reference_grid`` column of measurements.csv) with an
  error proportional to the *relative* motion, and the reference grid itself absolutely.

Everything here is solver-free: the caller supplies the exact values.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from solver_adapters.protocol import DofLabel


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class TruthJoint(_Strict):
    """A joint of the truth: ``value`` (every parameter), explicit ``values``, or for the complex
    model a ``stub_length`` (the "actual joint" of Section 5.4.1, from the deck's branch members)."""
    name: str
    model: str = "simple"
    value: float | None = None
    values: dict[str, float] | None = None
    stub_length: float | None = Field(None, gt=0)


class NoiseConfig(_Strict):
    relative: float = Field(0.05, ge=0)     # sigma = relative * |true value|
    absolute: float = Field(0.0, ge=0)      # added in quadrature
    floor: float = Field(0.02, ge=0)        # sigma >= relative * floor * max|same kind in the case|


class MeasureConfig(_Strict):
    joint: bool = True                      # all joint boundary DOFs
    away: list[tuple[int, int]] = []        # extra (grid, component) away from the joint
    away_grids: list[int] = []              # all six components of these grids
    cases: list[str] = []                   # default: every load case
    averaging_points: int = Field(0, ge=0)  # eq. 33: points per branch (0 = the branch end itself)
    averaging_spacing: float = Field(0.01, gt=0)
    reference_grid: int | None = None       # Section 5.2 reference point


class TruthConfig(_Strict):
    seed: int = 0
    deck: str | None = None                 # a different deck as the truth (solved as it is)
    joints: list[TruthJoint] = []
    noise: NoiseConfig = NoiseConfig()
    force_scale: float = Field(1.0, gt=0)   # Section 5.3.1 systematic bias
    measure: MeasureConfig = MeasureConfig()


def measured_rows(case_labels: Sequence[str], dofs: Sequence[DofLabel]) -> tuple[list[str], list[DofLabel]]:
    """Every (case, DOF) pair, case-major, as rows of measurements.csv."""
    return [c for c in case_labels for _ in dofs], [d for _ in case_labels for d in dofs]


def noise_sigma(true: np.ndarray, kinds: np.ndarray, case_idx: np.ndarray, cfg: NoiseConfig) -> np.ndarray:
    """Per-row sigma: ``relative*|u|`` floored by ``relative*floor*max|u|`` over the rows of the
    same kind (translation/rotation) and case, with ``absolute`` added in quadrature."""
    mag = np.abs(true)
    _, group = np.unique(np.stack([np.asarray(case_idx), np.asarray(kinds)]), axis=1, return_inverse=True)
    group = group.ravel()
    peak = np.zeros(group.max() + 1 if group.size else 0)
    np.maximum.at(peak, group, mag)                 # largest |u| of each (case, kind): linear time
    ref = peak[group]
    rel = cfg.relative * np.maximum(mag, cfg.floor * ref)
    sigma = np.sqrt(rel**2 + cfg.absolute**2)
    if np.any(sigma <= 0):
        raise ValueError("noise model gives sigma = 0 for some measurement: set noise.absolute > 0 "
                         "or noise.floor > 0")
    return sigma


@dataclass(frozen=True)
class SimulatedRows:
    """Measured rows, case-major: ``case_index`` (column of the response), ``dofs``, ``values``,
    ``sigma``, ``true`` values, ``kinds`` (0 translation, 1 rotation) and ``refs`` (the reference
    DOF of a row measured relative to a reference point, else None)."""
    case_index: np.ndarray
    dofs: tuple[DofLabel, ...]
    values: np.ndarray
    sigma: np.ndarray
    true: np.ndarray
    kinds: np.ndarray
    refs: tuple[DofLabel | None, ...]


def simulate_rows(U: np.ndarray, row: dict[DofLabel, int], n_cases: int, dofs: Sequence[DofLabel],
                  cfg: NoiseConfig, rng: np.random.Generator, reference_grid: int | None = None,
                  scale: float = 1.0) -> SimulatedRows:
    """Every (case, DOF) of ``dofs`` measured from the exact response ``U`` (rows ``row[dof]``,
    one column per case), contaminated as Section 5.2 says: proportional noise with its floor,
    and, with ``reference_grid``, every row but the reference grid's own measured relative to it
    (the caller lists the reference grid's DOFs in ``dofs`` to have them measured absolutely).
    ``scale`` multiplies the exact response (forces scaled in the truth). The random draws come
    in a fixed order, so a seed reproduces the same values."""
    case_rows, dof_rows = measured_rows(list(range(n_cases)), dofs)
    ci = np.array(case_rows, dtype=int)
    true = np.array([U[row[d], j] for d, j in zip(dof_rows, ci)]) * scale
    kinds = np.array([1 if d[1] >= 4 else 0 for d in dof_rows])
    sigma = noise_sigma(true, kinds, ci, cfg)
    values = contaminate(true, sigma, rng)
    refs: list[DofLabel | None] = [None] * len(dof_rows)
    if reference_grid is not None:
        rel = np.array([d[0] != reference_grid for d in dof_rows])
        ref = np.array([U[row[(reference_grid, d[1])], j] for d, j in zip(dof_rows, ci)]) * scale
        out = relative_to_reference(true[rel], ref[rel], kinds[rel], ci[rel], cfg, rng)
        values[rel], sigma[rel] = out.values, out.sigma
        refs = [(reference_grid, d[1]) if r else None for d, r in zip(dof_rows, rel)]
    return SimulatedRows(ci, tuple(dof_rows), values, sigma, true, kinds, tuple(refs))


@dataclass(frozen=True)
class Simulated:
    values: np.ndarray
    sigma: np.ndarray
    true: np.ndarray


def contaminate(true: np.ndarray, sigma: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    return true + sigma * rng.standard_normal(true.shape)


def relative_to_reference(true: np.ndarray, ref_true: np.ndarray, kinds: np.ndarray,
                          case_idx: np.ndarray, cfg: NoiseConfig, rng: np.random.Generator) -> Simulated:
    """Section 5.2: a quantity measured *relative to a reference point*: the value is
    ``u_i - u_ref`` and its error is proportional to the relative motion only (floored), so the
    rigid-body part that dominates the rotations no longer drowns the relative rotations that
    carry the joint's information. Rows are independent; the reference point's own absolute
    measurement is a separate row."""
    rel_true = true - ref_true
    sigma = noise_sigma(rel_true, kinds, case_idx, cfg)
    return Simulated(contaminate(rel_true, sigma, rng), sigma, rel_true)


def member_end_rotation_samples(u_a: np.ndarray, u_b: np.ndarray, xa: np.ndarray, xb: np.ndarray,
                                v: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Rotations (global, 3) at distances ``s`` from end a along a frame member (eq. 33 points).

    ``u_a``, ``u_b``: the 6 global DOFs of each end, shape ``(6, L)``. Bending rotations follow
    the Hermite cubic of each plane, torsion is linear. Returns ``(len(s), 3, L)``.
    """
    d = xb - xa
    Lm = float(np.linalg.norm(d))
    ex = d / Lm
    ez = np.cross(ex, v)
    ez /= np.linalg.norm(ez)
    ey = np.cross(ez, ex)
    R = np.vstack([ex, ey, ez])                     # global -> local
    ta, tb = R @ u_a[:3], R @ u_b[:3]
    ra, rb = R @ u_a[3:], R @ u_b[3:]
    out = np.empty((len(s), 3, u_a.shape[1]))
    for i, si in enumerate(np.asarray(s, float)):
        xi = si / Lm
        # derivatives of the Hermite shape functions N1..N4 with respect to x
        dN1 = (-6 * xi + 6 * xi**2) / Lm
        dN2 = 1 - 4 * xi + 3 * xi**2
        dN3 = (6 * xi - 6 * xi**2) / Lm
        dN4 = -2 * xi + 3 * xi**2
        theta_z = dN1 * ta[1] + dN2 * ra[2] + dN3 * tb[1] + dN4 * rb[2]          # plane 1: v'
        theta_y = -(dN1 * ta[2] + dN2 * (-ra[1]) + dN3 * tb[2] + dN4 * (-rb[1]))  # plane 2: -w'
        theta_x = (1 - xi) * ra[0] + xi * rb[0]
        out[i] = R.T @ np.vstack([theta_x, theta_y, theta_z])
    return out


def averaged_rotation(samples: np.ndarray, cfg: NoiseConfig, rng: np.random.Generator,
                      kinds_scale: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 33: mean of the noisy rotations of several points; returns ``(value, sigma_of_mean)``.

    ``samples``: ``(p, 3, L)`` true rotations; ``kinds_scale``: ``(L,)`` the largest rotation of
    each case (the noise floor's reference)."""
    mag = np.abs(samples)
    s = cfg.relative * np.maximum(mag, cfg.floor * kinds_scale[None, None, :])
    s = np.sqrt(s**2 + cfg.absolute**2)
    noisy = samples + s * rng.standard_normal(samples.shape)
    p = samples.shape[0]
    return noisy.mean(axis=0), np.sqrt((s**2).sum(axis=0)) / p
