"""Measured rows located in the condensed model's load cases (Sec. 4.2, 5.2).

An :class:`Observations` row is one measured DOF in one load case with its declared standard
deviation (absolute, the measurement's units), optionally relative to a reference DOF (Sec. 5.2:
the value is ``u(dof) - u(ref_dof)``). Every check happens when the rows are built, so the
estimator never sees a malformed row.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from blackbox.errors import IdentificationError
from solver_adapters.protocol import DofLabel

__all__ = ["Observations"]


@dataclass(frozen=True, eq=False)
class Observations:
    """Measured rows mapped to the condensed model: row ``i`` is DOF ``dofs[i]`` in case
    ``case_labels[case_index[i]]`` (a column of ``Condensed.cases``), measured ``values[i]`` with
    standard deviation ``sigma[i]`` (absolute, the measurement's units)."""
    dofs: tuple[DofLabel, ...]
    case_index: np.ndarray
    values: np.ndarray
    sigma: np.ndarray
    case_labels: tuple[str, ...] = ()
    ref_dofs: tuple[DofLabel | None, ...] = ()
    """Per row, ``None`` or the DOF the row is measured relative to (Section 5.2 reference point):
    the row's value is then ``u(dof) - u(ref_dof)``. Empty: every row is absolute."""

    def __post_init__(self) -> None:
        try:
            dofs = tuple((int(g), int(c)) for g, c in self.dofs)
        except (TypeError, ValueError):
            raise IdentificationError("Observations.dofs must be (grid, component) pairs") from None
        ci = np.asarray(self.case_index)
        vals = np.asarray(self.values, dtype=float)
        sig = np.asarray(self.sigma, dtype=float)
        n = len(dofs)
        if ci.shape != (n,) or vals.shape != (n,) or sig.shape != (n,):
            raise IdentificationError(
                f"Observations need one case_index, value and sigma per DOF row ({n} rows), got "
                f"shapes {ci.shape}, {vals.shape}, {sig.shape}")
        if n and (not np.issubdtype(ci.dtype, np.integer) or ci.min() < 0):
            raise IdentificationError(f"case_index must be non-negative integers, got {ci[:5].tolist()}...")
        labels = tuple(str(c) for c in self.case_labels)
        if labels and n and ci.max() >= len(labels):
            raise IdentificationError(f"case_index {int(ci.max())} is out of range for {len(labels)} cases")
        bad = np.flatnonzero(~np.isfinite(vals))
        if bad.size:
            i = int(bad[0])
            raise IdentificationError(
                f"{bad.size} measured value(s) are not finite, first DOF {dofs[i]} in case "
                f"{self._label(labels, int(ci[i]))!r}: {vals[i]!r}")
        bad = np.flatnonzero(~(np.isfinite(sig) & (sig > 0)))
        if bad.size:
            i = int(bad[0])
            raise IdentificationError(
                f"{bad.size} sigma(s) are not finite and positive, first DOF {dofs[i]} in case "
                f"{self._label(labels, int(ci[i]))!r}: {sig[i]!r}")
        refs = tuple(None if r is None else (int(r[0]), int(r[1])) for r in self.ref_dofs)
        if refs and len(refs) != n:
            raise IdentificationError(f"ref_dofs needs one entry (None or a DOF) per row ({n}), got {len(refs)}")
        if not any(r is not None for r in refs):
            refs = ()
        seen: set = set()
        for i, (d, c) in enumerate(zip(dofs, ci.tolist())):
            key = (d, c, refs[i] if refs else None)
            if key in seen:
                raise IdentificationError(f"DOF {d} is measured twice in case {self._label(labels, c)!r}")
            if refs and refs[i] == d:
                raise IdentificationError(f"DOF {d} is measured relative to itself in case "
                                          f"{self._label(labels, c)!r}")
            seen.add(key)
        object.__setattr__(self, "ref_dofs", refs)
        ci = ci.astype(int)
        for name, arr in (("case_index", ci), ("values", vals), ("sigma", sig)):
            arr = arr.copy()
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "dofs", dofs)
        object.__setattr__(self, "case_labels", labels)

    @staticmethod
    def _label(labels: tuple[str, ...], c: int) -> str:
        return labels[c] if c < len(labels) else f"#{c}"

    def __len__(self) -> int:
        return len(self.dofs)

    @property
    def cases(self) -> tuple[int, ...]:
        """The case indices that have at least one row, ascending."""
        return tuple(int(c) for c in np.unique(self.case_index))

    @classmethod
    def from_measurements(cls, measurements, condensed_cases: Sequence[str],
                          provisional_sigma: bool = False) -> "Observations":
        """From :class:`blackbox.study.Measurements` (rows ``cases, dofs, values, sigma``); every
        case label must be one of ``condensed_cases`` (``Condensed.cases``).

        A row without sigma (blank, and neither repeated readings nor a declared accuracy give
        one, :mod:`blackbox.noise`) is an error, unless ``provisional_sigma``: it then gets a
        placeholder per kind (translations, rotations: 1e-3 of the kind's RMS value) that
        :func:`blackbox.identification.fit_sigma.identify_with_fit_sigma` replaces by the fit's
        estimate."""
        labels = tuple(str(c) for c in condensed_cases)
        index = {c: j for j, c in enumerate(labels)}
        unknown = sorted({str(c) for c in measurements.cases} - set(index))
        if unknown:
            raise IdentificationError(
                f"measured case(s) {unknown} are not among the condensed load cases {list(labels)}")
        sigma = np.array(measurements.sigma, dtype=float)
        missing = np.isnan(sigma)
        if missing.any():
            if not provisional_sigma:
                raise IdentificationError(
                    f"{int(missing.sum())} measurement row(s) have no sigma (blank in measurements.csv, no "
                    f"repeated readings, no declared accuracy), and this command judges the model against "
                    f"the noise, which must not come from the model's own fit: give sigma in "
                    f"measurements.csv, declare [measurements] translation_accuracy / rotation_accuracy in "
                    f"study.toml, or import rig readings with repeats (blackbox measurements)")
            values = np.asarray(measurements.values, float)
            rot = np.array([int(c) >= 4 for _, c in measurements.dofs])
            for kind in (rot, ~rot):
                m = missing & kind
                if m.any():
                    scale = float(np.sqrt(np.mean(values[kind] ** 2)))
                    sigma[m] = 1e-3 * scale if scale > 0 else 1.0
        return cls(tuple(measurements.dofs), np.array([index[str(c)] for c in measurements.cases], dtype=int),
                   np.asarray(measurements.values, float), sigma, labels,
                   tuple(getattr(measurements, "refs", ()) or ()))

    def subset(self, mask: np.ndarray) -> "Observations":
        idx = np.flatnonzero(mask)
        return Observations(tuple(self.dofs[i] for i in idx), self.case_index[idx], self.values[idx],
                            self.sigma[idx], self.case_labels,
                            tuple(self.ref_dofs[i] for i in idx) if self.ref_dofs else ())

    def with_values(self, values: np.ndarray) -> "Observations":
        """The same rows with other measured values (bootstrap, simulation)."""
        return Observations(self.dofs, self.case_index, values, self.sigma, self.case_labels, self.ref_dofs)

    def with_sigma(self, sigma: np.ndarray) -> "Observations":
        """The same rows with other standard deviations (a sigma estimated from the fit)."""
        return Observations(self.dofs, self.case_index, self.values, sigma, self.case_labels, self.ref_dofs)

    def split(self, holdout_cases: Sequence[str | int]) -> tuple["Observations", "Observations"]:
        """``(fit, holdout)``: the rows of ``holdout_cases`` (labels or case indices) go to ``holdout``."""
        idx = set()
        for c in holdout_cases:
            if isinstance(c, str):
                if c not in self.case_labels:
                    raise IdentificationError(
                        f"holdout case {c!r} is not a load case {list(self.case_labels)}")
                idx.add(self.case_labels.index(c))
            else:
                idx.add(int(c))
        empty = sorted(self._label(self.case_labels, c) for c in idx if c not in set(self.case_index.tolist()))
        if empty:
            raise IdentificationError(f"holdout case(s) {empty} have no observations")
        mask = np.isin(self.case_index, sorted(idx))
        return self.subset(~mask), self.subset(mask)
