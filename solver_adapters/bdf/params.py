"""PARAM and the cards with no effect on a linear static solution."""

from __future__ import annotations

from solver_adapters.bdf.fields import _real


def _param(r, c) -> None:
    """PARAM,AUTOSPC (YES/NO; the last one of the deck wins; without one AUTOSPC is on, NASTRAN's
    SOL 101 default) and PARAM,EPZERO (its singularity ratio) are read; every other PARAM has no
    effect on the reference solver."""
    name = c.text(2)
    if name == "AUTOSPC":
        value = c.text(3)
        if value not in ("YES", "Y", "NO", "N"):
            raise c.error(3, "PARAM,AUTOSPC must be YES or NO")
        r.deck.autospc = value.startswith("Y")
        r.deck.autospc_src = c.src
    elif name == "EPZERO":
        value = _real(c, 3)
        if not 0.0 < value < 1.0:
            raise c.error(3, "PARAM,EPZERO must be in (0, 1)")
        r.deck.epzero = value


NO_EFFECT = frozenset({
    "PARAM",                                                  # solver parameters
    "CONM1", "CONM2", "CMASS1", "CMASS2", "CMASS3", "CMASS4", "PMASS",   # mass
    "EIGR", "EIGRL", "EIGB", "EIGC",                          # eigenvalue extraction
    "FREQ", "FREQ1", "FREQ2", "TSTEP", "NLPARM",              # dynamic / nonlinear controls
})
"""Cards with no effect on a linear static solve: accepted, counted in ``Deck.no_effect``."""

PARSERS = {}
