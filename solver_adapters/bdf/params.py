"""PARAM and the cards with no effect on a linear static solution."""

from __future__ import annotations

from solver_adapters.bdf.fields import _int, _real

INREL_IN_STUDY = ("(inertia relief) balances the applied loads by the inertia loads of the "
                  "structure's rigid-body acceleration; a study's loads.csv holds the loads its "
                  "solvers apply, so `blackbox import` writes the balanced loads there and leaves "
                  "this card out of model.bdf (docs/import.md, inertia relief): import the deck, "
                  "or remove the card")
"""Why a study's model refuses PARAM,INREL,-1/-2 (the solvers would hold the SUPORT DOFs with
the loads unbalanced)."""


def inrel_value(c) -> int:
    """PARAM,INREL's value: 0 (none), -1 (inertia relief on the SUPORT DOFs), -2 (automatic)."""
    value = _int(c, 3, minimum=None)
    if value not in (0, -1, -2):
        raise c.error(3, "PARAM,INREL must be 0, -1 or -2")
    return value


def _param(r, c) -> None:
    """PARAM,AUTOSPC (YES/NO; the last one of the deck wins; without one AUTOSPC is on, NASTRAN's
    SOL 101 default) and PARAM,EPZERO (its singularity ratio) are read; PARAM,INREL,-1/-2 is
    refused (:data:`INREL_IN_STUDY`); every other PARAM has no effect on the reference solver."""
    name = c.text(2)
    if name == "AUTOSPC":
        value = c.text(3)
        if value not in ("YES", "Y", "NO", "N"):
            raise c.error(3, "PARAM,AUTOSPC must be YES or NO")
        r.deck.autospc = value.startswith("Y")
        r.deck.autospc_src = c.src
    elif name == "CK2":
        # the scale of the direct stiffness matrices (K2GG, DMIG): MSC QRG PARAM CK2, default 1.0
        r.deck.ck2 = _real(c, 3)
    elif name == "EPZERO":
        value = _real(c, 3)
        if not 0.0 < value < 1.0:
            raise c.error(3, "PARAM,EPZERO must be in (0, 1)")
        r.deck.epzero = value
    elif name == "CDITER" and _int(c, 3, 0, minimum=None) > 0:
        raise c.error(3, "PARAM,CDITER > 0 asks for NASTRAN's constrained displacement iteration "
                         "(linear gaps made of SUPORT scalar points and MPCs, opened and closed by "
                         "iterating): a nonlinear solution, not modelled; remove the PARAM to solve "
                         "the deck as the linear model it writes")
    elif name == "INREL" and inrel_value(c):
        raise c.error(3, f"PARAM,INREL,{inrel_value(c)} {INREL_IN_STUDY}")


NO_EFFECT = frozenset({
    # solver and model parameters (DEBUG: MYSTRAN's printout switches)
    "PARAM", "MDLPRM", "DEBUG", "DOPTPRM",
    # mass: no effect on a linear static solution (GRAV reads the masses it uses from the cards)
    "CONM1", "CONM2", "CMASS1", "CMASS2", "CMASS3", "CMASS4", "PMASS",
    "NSM", "NSM1", "NSMADD", "NSML", "NSML1",
    # heat-transfer materials (conductivity, specific heat): read by thermal solutions only; a
    # structural element's MID names a MAT1 (which a MAT4/MAT5 of the same ID accompanies)
    "MAT4", "MAT5",
    # dampers: a viscous force is proportional to a velocity, zero in a static solution
    "CDAMP1", "CDAMP2", "CDAMP3", "CDAMP4", "CDAMP5", "CVISC", "PDAMP", "PDAMP5", "PDAMPT", "PVISC",
    # eigenvalue extraction, dynamic and nonlinear solution controls
    "EIGR", "EIGRL", "EIGB", "EIGC", "EIGP", "FREQ", "FREQ1", "FREQ2", "FREQ3", "FREQ4", "FREQ5",
    "TSTEP", "TSTEPNL", "NLPARM", "NLPCI", "TABDMP1", "RANDPS", "RANDT1", "TABRND1", "TABRNDG",
    # dynamic excitation (selected by DLOAD, never by a static LOAD) and its tables
    "RLOAD1", "RLOAD2", "TLOAD1", "TLOAD2", "DLOAD", "DELAY", "DPHASE",
    "TABLED1", "TABLED2", "TABLED3", "TABLED4",
    # frequency-dependent and nonlinear bush properties: a linear static solution uses the
    # PBUSH's nominal K (MSC QRG PBUSH remark 1; a note names every PBUSHT, PBUSHT_NOTE)
    "PBUSHT",
    # static condensation sets: the reduction of a linear static solution to them is exact;
    # generalized coordinates of a dynamic reduction (QSET: component modes added to that exact
    # static basis, which leave the static solution as it is); resequencing (SEQGP): the order
    # of the unknowns in the solver's matrices, not the solution
    "ASET", "ASET1", "OMIT", "OMIT1", "QSET", "QSET1", "SEQGP",
    # COSMIC's pressure stiffness elements and their property: differential stiffness only, "no
    # structural stiffness and no structural mass" (NASTRAN-95 User's Manual, CPSEi remark 2)
    "CPSE2", "CPSE3", "CPSE4", "PPSE",
    # output only: plot elements, monitor points, bar output stations (CBARAO: where a CBAR's
    # forces and stresses are printed)
    "PLOTEL", "MONPNT1", "MONPNT3", "CBARAO",
    # design optimisation (SOL 200): responses and constraints (the relations that design the
    # model's properties, their equations DEQATN and constants DTABLE are read by bdf.design)
    "DRESP1", "DRESP2", "DRESP3", "DCONSTR", "DCONADD", "DSCREEN", "DDVAL",
    # static aeroelasticity and flutter: the aerodynamic model adds nothing to a SOL 101 solution
    "AERO", "AEROS", "CAERO1", "CAERO2", "CAERO3", "CAERO4", "CAERO5", "PAERO1", "PAERO2",
    "PAERO3", "PAERO4", "PAERO5", "SPLINE1", "SPLINE2", "SPLINE3", "SPLINE4", "SPLINE5", "SPLINE6",
    "SPLINE7", "SET1", "SET2",
    "AEFACT", "AELIST", "AESTAT", "AESURF", "AESURFS", "AELINK", "AEPARM", "TRIM", "FLFACT",
    "FLUTTER", "MKAERO1", "MKAERO2", "GUST", "DIVERG",
    # direct matrix input for DMAP and the aerodynamic solutions (W2GJ, WKK, FA2J ...): a linear
    # static solution adds none of them (a stiffness added by matrix is DMIG, selected by K2GG)
    "DMI", "DMIJ", "DMIK",
    # dynamics only: extra points (MSC QRG EPOINT: "for use in dynamics problems"), transfer
    # functions (selected by TFL) and transient initial conditions (selected by IC); POINT, an
    # edge point of FEEDGE geometry, holds no degree of freedom
    "EPOINT", "TF", "TIC", "POINT",
    # echo of the input in the printed output (MSC/OptiStruct: from this card until the other)
    "ECHOON", "ECHOOFF",
    # plot elements of other shapes (NX: PLOTEL3..PLOTEL8, PLOTTET, PLOTPEN, PLOTPYR, PLOTHEX:
    # "no stiffness or mass", for display only), output groups and monitors of displacements
    "PLOTEL3", "PLOTEL4", "PLOTEL6", "PLOTEL8", "PLOTTET", "PLOTPEN", "PLOTPYR", "PLOTHEX",
    "GROUP", "MONPNT2", "MONDSP1",
    # transient time steps, dynamic reduction, mode tracking (SOL 200), the strategy parameters
    # of the advanced nonlinear solutions (SOL 401/601/701), heat-transfer tables
    "TSTEP1", "DYNRED", "MODTRAK", "NXSTRAT", "TABLEH1", "TABLEHT",
    # static aeroelasticity and flutter, further cards of the aerodynamic model
    "AECOMP", "AECOMPL", "AEFORCE", "AEPRESS", "AEDW", "CSSCHD", "UXVEC", "GUST2", "TRIM2",
})
"""Cards with no effect on a linear static solve: accepted, counted in ``Deck.no_effect`` (one
line of :meth:`~solver_adapters.deck.Deck.summary`), never handed to an external solver but
PARAM (which MYSTRAN reads: AUTOSPC, ...), and never a reason to choose another adapter."""

PBUSHT_NOTE = ("PBUSHT (frequency-dependent damping and stiffness, nonlinear force-deflection "
               "tables) is not used by a linear static solution: NASTRAN uses the PBUSH's nominal K "
               "there (MSC QRG PBUSH remark 1), and so does the study")
"""The note of every PBUSHT the reader reads (it changes frequency-response and nonlinear
solutions, and a reader of the deck should know the study's bushes have their nominal K)."""

PARSERS = {}
