"""Former home of the diagnosis method, now :mod:`blackbox.diagnosis` (a subpackage: runs, decks,
split run, effect families, augmented model, refit, scoring, the loop). Re-exports its names
for old imports; ``EFFECTS`` is :func:`blackbox.diagnosis.kinds`."""

from blackbox.diagnosis import (AugmentedModel, CandidateScore, Diagnosis, Effect, Fit, ModelSpec, ObsMap,
                                Pair, RunRecord, SplitBase, Step, chi2_band, default_holdout, diagnose,
                                element_stiffness, fit_model, kinds, residual_structure, score_candidates)

EFFECTS = kinds()

__all__ = ["EFFECTS", "RunRecord", "element_stiffness", "Pair", "SplitBase", "Effect", "ModelSpec", "ObsMap",
           "AugmentedModel", "Fit", "fit_model", "CandidateScore", "score_candidates", "residual_structure",
           "Step", "Diagnosis", "diagnose", "chi2_band", "default_holdout"]
