"""Diagnosis of a declared model: find what it lacks, add it, report before and after.

The layout follows the method:

* :mod:`~blackbox.diagnosis.runs` -- batched solver runs and each member's black-box ``K_e``;
* :mod:`~blackbox.diagnosis.decks` -- the edited decks (element deck, split deck);
* :mod:`~blackbox.diagnosis.split` -- the split run conditioned on its rigid state (= the declared model);
* :mod:`~blackbox.diagnosis.effects` -- the effect families, one module each, registered by name;
* :mod:`~blackbox.diagnosis.model` -- a specification (joints + effects) and its augmented model;
* :mod:`~blackbox.diagnosis.fit` -- the refit and its statistics;
* :mod:`~blackbox.diagnosis.scoring` -- score tests of candidates at the current optimum;
* :mod:`~blackbox.diagnosis.search` -- the loop (:func:`diagnose`), :class:`Step`, :class:`Diagnosis`;
* :mod:`~blackbox.diagnosis.document` -- ``diagnosis.json``.

The command (reading the study, picking adapters, running the three decks) is
:mod:`blackbox.commands.diagnose`; its report :mod:`blackbox.reports.diagnose`.

**Cost.** Runs: one condensation of the study's deck (the declared fit), one element run, one
split run, plus one split run per round in which a member is short-listed. Right-hand sides:
``6`` (element run: every member loaded at once, :func:`~blackbox.diagnosis.runs.element_flexibility`)
and ``n_B + n_O + pairs + L`` (split run; its rows: the boundary, the measured DOFs, both sides of
every pair and the ends of the members considered). The candidate caps (undeclared-joint grids,
members; :class:`~blackbox.diagnosis.effects.base.CandidateLimit`) bound the split run on a large
model. The loop itself needs no solver: the car fixture (115 members, 459 cut pairs, 234
candidates) diagnoses in a few seconds.
"""

from blackbox.diagnosis.decks import SplitDeck, SplitEditor, constrained_grids, element_deck, members_at, split_deck
from blackbox.diagnosis.effects import (CandidateContext, Connection, Effect, JointCoupling, JointTranslation,
                                        LoadScale, MemberStiffness, SensorGain, SensorOffset, SupportFlexibility,
                                        UndeclaredJoint, families, get, kinds, register)
from blackbox.diagnosis.fit import Fit, chi2_band, fit_model
from blackbox.diagnosis.model import AugmentedModel, ModelSpec, ObsMap, State
from blackbox.diagnosis.residuals import residual_structure
from blackbox.diagnosis.runs import RunRecord, element_flexibility, element_stiffness
from blackbox.diagnosis.scoring import CandidateScore, score_candidates, score_test
from blackbox.diagnosis.search import Diagnosis, Step, diagnose
from blackbox.diagnosis.split import Pair, SplitBase

__all__ = ["SplitDeck", "SplitEditor", "constrained_grids", "element_deck", "members_at", "split_deck",
           "CandidateContext", "Connection", "Effect", "JointCoupling", "JointTranslation", "LoadScale",
           "MemberStiffness", "SensorGain", "SensorOffset", "SupportFlexibility", "UndeclaredJoint", "families", "get", "kinds",
           "register", "Fit", "chi2_band", "fit_model", "AugmentedModel", "ModelSpec", "ObsMap", "State",
           "residual_structure", "RunRecord", "element_flexibility", "element_stiffness",
           "CandidateScore", "score_candidates", "score_test", "Diagnosis", "Step", "diagnose", "Pair",
           "SplitBase"]
