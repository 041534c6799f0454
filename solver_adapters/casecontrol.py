"""The executive and case control of a NASTRAN input file: what ``blackbox import`` needs of them.

A NASTRAN input file is executive control (``SOL 101``, ``ID``, ``TIME`` ...) up to ``CEND``, case
control up to ``BEGIN BULK``, then bulk data. This module reads the two sections before the bulk
data:

* ``SUBCASE n`` starts a subcase; commands above the first SUBCASE are the defaults every subcase
  inherits (a deck without SUBCASE has one case, numbered 1);
* ``LOAD = n``, ``SPC = n``, ``MPC = n`` and ``SUPORT1 = n`` select the load set, the constraint
  set, the multipoint-constraint set and the SUPORT1 set (reference DOFs) of a subcase;
* ``TEMPERATURE(LOAD) = n`` selects its thermal load, ``TEMPERATURE(MATERIAL) = n`` the
  temperatures of temperature-dependent materials, ``TEMPERATURE(INITIAL) = n`` the initial
  temperatures; ``TEMPERATURE = n`` and ``TEMPERATURE(BOTH) = n`` are LOAD and MATERIAL (MSC QRG,
  TEMPERATURE);
* ``TITLE``, ``SUBTITLE``, ``LABEL`` are kept as text;
* output requests (``DISP``, ``STRESS``, ``FORCE`` ...), output controls (``ECHO``, ``SET``,
  ``LINE`` ...), selections of other solutions (``METHOD``, ``FREQ``, ``TSTEPNL``, ``TRIM``
  ...), the design model's (``DESOBJ``, ``DESSUB`` ..., by their first four letters: ``DESOPJ``
  is DESOBJ), case-control ``PARAM`` and the plot/XY-plot packets after ``OUTPUT(PLOT)`` are
  recognised and listed in :attr:`CaseControl.skipped` by kind, so that a caller can say once what
  it skipped; a subcase's selections of other solutions are kept in :attr:`Subcase.others`
  (to say what a deck without a static load selects instead);
* ``ANALYSIS = ...`` (SOL 200, 400) is kept in :attr:`Subcase.analysis`: a subcase of another
  analysis than statics has no static load (:attr:`Subcase.static`);
* ``K2GG = NAME`` (the DMIG matrix added to the stiffness) is kept in :attr:`Subcase.k2gg`;
* ``AUTOSPC = YES/NO`` is kept in :attr:`CaseControl.autospc`;
* commands that change the static solution and that an import cannot carry over
  (``DEFORM``, ``P2G``, ``LOADSET``, ``SYMCOM`` ...) are errors naming the
  line; an unknown command is an error naming the line and the known commands closest to it;
* ``SUBCOM`` (a combination of subcases) is skipped with its ``SUBSEQ``: the subcases it
  combines are imported themselves.

Commands are recognised by their first four letters, as NASTRAN does (``DISP`` = ``DISPLACEMENT``,
``SUBTI`` = ``SUBTITLE``). A line ending with a comma continues on the next line (``SET``
lists). ``$`` starts a comment.
"""

from __future__ import annotations

import difflib
import re
from dataclasses import dataclass, field

from solver_adapters.protocol import DeckFormatError

__all__ = ["Subcase", "CaseControl", "read_case_control", "bulk_start", "STATIC_SOLUTIONS", "solution_key"]

_BEGIN_BULK = re.compile(r"BEGIN\s+BULK\b.*", re.IGNORECASE)
_COMMAND = re.compile(r"\s*([A-Za-z][A-Za-z0-9]*)\s*(\([^)]*\))?\s*(=)?\s*(.*?)\s*$", re.DOTALL)

# first four letters -> (canonical name, kind)
_TITLES = {"TITL": "TITLE", "SUBT": "SUBTITLE", "LABE": "LABEL"}
_OUTPUT_REQUESTS = {
    "DISP": "DISPLACEMENT", "VECT": "VECTOR", "PRES": "PRESSURE", "STRE": "STRESS",
    "ELST": "ELSTRESS", "STRA": "STRAIN", "ELSU": "ELSUM", "FORC": "FORCE", "ELFO": "ELFORCE",
    "SPCF": "SPCFORCE", "MPCF": "MPCFORCE", "OLOA": "OLOAD", "GPFO": "GPFORCE", "ESE": "ESE",
    "EKE": "EKE", "EDE": "EDE", "GPST": "GPSTRESS", "GPKE": "GPKE", "ACCE": "ACCELERATION",
    "VELO": "VELOCITY", "ELDA": "ELDATA", "GROU": "GROUNDCHECK", "WEIG": "WEIGHTCHECK",
    "THER": "THERMAL", "FLUX": "FLUX", "SDIS": "SDISPLACEMENT", "SVEC": "SVECTOR",
    "NOUT": "NOUTPUT", "BOUT": "BOUTPUT", "MPRE": "MPRES", "STRF": "STRFIELD", "GPSD": "GPSDCON",
    "ELSD": "ELSDCON", "NLST": "NLSTRESS", "MEFF": "MEFFMASS", "OTIM": "OTIME", "OFRE": "OFREQUENCY",
    "OMOD": "OMODES", "PLOT": "PLOTID", "AERO": "AEROF", "APRE": "APRESSURE",
}
_OUTPUT_CONTROLS = {
    "ECHO": "ECHO", "LINE": "LINE", "MAXL": "MAXLINES", "SET": "SET", "PAGE": "PAGE",
    "SKIP": "SKIP", "POST": "POST", "OUTR": "OUTRCV", "MODS": "MODSEL", "SORT": "SORT",
    "ECHOON": "ECHOON", "ECHOOFF": "ECHOOFF", "MAXM": "MAXMIN", "GPRS": "GPRSORT",
    "MONI": "MONITOR",
}
_NOT_STATIC = {  # selections of other solutions: no effect on the static solution of LOAD/SPC
    "METH": "METHOD", "SDAM": "SDAMPING", "FREQ": "FREQUENCY", "TSTE": "TSTEP", "DLOA": "DLOAD",
    "NLPA": "NLPARM", "RESV": "RESVEC", "CMET": "CMETHOD", "RAND": "RANDOM", "IC": "IC",
    "MODE": "MODES", "ANAL": "ANALYSIS", "STAT": "STATSUB", "RIGI": "RIGID", "MASS": "MASS",
    "RMET": "RMETHOD", "FMET": "FMETHOD", "SMET": "SMETHOD", "TSTEPNL": "TSTEPNL",
    "NONL": "NONLINEAR", "B2GG": "B2GG", "B2PP": "B2PP", "TFL": "TFL", "RGYR": "RGYRO",
    # p-set direct matrices: used only in dynamic response (OptiStruct's K2PP reference; Autodesk
    # Nastran's: complex eigenvalue solutions only), never in a linear static solution
    "K2PP": "K2PP", "M2PP": "M2PP",
    "TRIM": "TRIM", "FLUT": "FLUTTER", "GUST": "GUST", "DIVE": "DIVERG",
    "GENG": "GENGAF", "AESYMXY": "AESYMXY", "AESYMXZ": "AESYMXZ", "AEUX": "AEUXREF",
    "CSSC": "CSSCHD", "MODT": "MODTRAK", "MPFA": "MPFACTOR",
    "AECO": "AECONFIG", "BC": "BC",
    # COSMIC NASTRAN: the differential-stiffness coefficient set (rigid formats 4 and 13 only)
    "DSCO": "DSCOEFFICIENT",
}
_DESIGN = {  # design optimisation (SOL 200): read by their first four letters, as NASTRAN does
    "DESO": "DESOBJ", "DESS": "DESSUB", "DESG": "DESGLB", "DSAP": "DSAPRT", "DRSP": "DRSPAN",
    "DESV": "DESVAR", "DESM": "DESMOD",
}
STATIC_SOLUTIONS = ("1", "101", "SESTATIC", "SESTATICS", "STATICS")
"""SOL values of a linear static solution, as :func:`solution_key` gives them."""


def solution_key(sol: str) -> str:
    """The solution a SOL statement names, upper-cased: COSMIC NASTRAN's ``SOL n,m`` (rigid
    format n, its subset m) names rigid format n (1: static analysis, as MSC's SOL 1)."""
    return sol.upper().split(",")[0].strip()

STATIC_ANALYSES = ("STATICS", "STATIC", "NLSTATICS", "NLSTATIC", "NLSTAT")
"""ANALYSIS values of a static subcase (MSC QRG ANALYSIS: STATICS in SOL 200; NLSTATIC in
SOL 400); a subcase of any other (MODES, BUCK, DFREQ, SAERO, FLUTTER ...) is not imported."""
_UNSUPPORTED = {  # change the static solution; an imported study cannot carry them
    "DEFO": "DEFORM (enforced element deformation)",
    "P2G": "P2G (direct load input)",
    "K42G": "K42GG (direct matrix input)",
    "M2GG": "M2GG (direct mass input: changes gravity loads)",
    "LOADSET": "LOADSET (static load sets from LSEQ cards, not read by blackbox import)",
    "SYMC": "SYMCOM",
    "SYMS": "SYMSEQ", "REPC": "REPCASE", "BCON": "BCONTACT", "AXIS": "AXISYMMETRIC",
    "CLOA": "CLOAD", "INCL": "INCLUDE (in the case control)", "ADAP": "ADAPT",
}
_PLOT_PACKETS = {"PLOT", "XYPLOT", "XYOUT", "XYPUNCH", "POST", "CARDS"}
_OTHER = ("SUBCASE", "SUBCOM", "SUBSEQ", "LOAD", "SPC", "MPC", "SUPORT1", "K2GG", "OUTPUT", "PARAM", "BEGIN", "AUTOSPC",
          "SEALL", "SUPER", "TEMPERATURE")
# TEMPERATURE(option): the kinds of temperature set each option selects (MSC QRG TEMPERATURE:
# blank and BOTH are LOAD and MATERIAL)
_TEMP_OPTIONS = {"": ("LOAD", "MAT"), "BOTH": ("LOAD", "MAT"), "LOAD": ("LOAD",), "MATE": ("MAT",),
                 "MATERIAL": ("MAT",), "INIT": ("INIT",), "INITIAL": ("INIT",)}


def _lookup(table: dict[str, str], word: str) -> str | None:
    """The command of ``table`` that ``word`` names (its first four letters, or the whole name
    for a name that shares them with another: TSTEP, TSTEPNL)."""
    for key in (word, word[:4]):
        name = table.get(key)
        if name is not None and _is(word, name.split()[0]):
            return name
    return None


def known_commands() -> list[str]:
    """Every case-control command this module reads (for "did you mean")."""
    names = {n.split()[0] for t in (_TITLES, _OUTPUT_REQUESTS, _OUTPUT_CONTROLS, _NOT_STATIC,
                                    _DESIGN, _UNSUPPORTED) for n in t.values()}
    return sorted(names | set(_OTHER))


@dataclass(frozen=True)
class Subcase:
    """One subcase: its ID, the selected load and constraint sets (``None``: not selected) with
    the lines that selected them (0: inherited or none), and its title lines."""
    id: int
    load: int | None
    spc: int | None
    line: int = 0
    load_line: int = 0
    spc_line: int = 0
    title: str = ""
    subtitle: str = ""
    label: str = ""
    others: tuple[str, ...] = ()
    mpc: int | None = None          # the MPC set selected (MPC = n), and the line that did
    mpc_line: int = 0
    temp_load: int | None = None    # TEMPERATURE(LOAD) (or BOTH) = n: the thermal load's set
    temp_load_line: int = 0
    temp_mat: int | None = None     # TEMPERATURE(MATERIAL) (or BOTH) = n
    temp_mat_line: int = 0
    temp_init: int | None = None    # TEMPERATURE(INITIAL) = n
    temp_init_line: int = 0
    suport1: int | None = None      # SUPORT1 = n: the SUPORT1 set of reference DOFs
    suport1_line: int = 0
    analysis: str = ""              # ANALYSIS = ... (SOL 200, SOL 400): the subcase's own analysis
    k2gg: str | None = None         # K2GG = NAME: the DMIG matrix added to the stiffness
    k2gg_line: int = 0
    enforced_only: bool = False     # no load set, but its constraint set enforces displacements
                                    # (SPC values: blackbox import sets this from the bulk data)

    @property
    def static(self) -> bool:
        """The subcase has a static load (a LOAD set, a thermal load, or displacements its
        constraint set enforces) and its ANALYSIS, if it names one, is a static analysis
        (STATICS; SOL 400's NLSTATIC, whose load steps are imported as linear static cases like
        SOL 106's)."""
        return (self.load is not None or self.temp_load is not None or self.enforced_only) and self.analysis_static

    @property
    def analysis_static(self) -> bool:
        """No ANALYSIS command, or one naming a static analysis."""
        return self.analysis in ("", *STATIC_ANALYSES)


@dataclass(frozen=True)
class CaseControl:
    """The executive and case control of an input file.

    ``subcases``: in the deck's order (one subcase numbered 1 when the deck has no SUBCASE);
    ``explicit``: the deck has SUBCASE commands; ``sol``: the SOL statement's value ("" if none);
    ``executive``: the executive statements' keywords in order; ``skipped``: kind -> command names
    (each once, in order of appearance); ``bulk_line``: the 1-based line of BEGIN BULK."""
    file: str
    subcases: tuple[Subcase, ...]
    explicit: bool
    sol: str
    executive: tuple[str, ...]
    skipped: dict[str, tuple[str, ...]] = field(default_factory=dict)
    bulk_line: int = 0
    autospc: tuple[str, int] | None = None


def _is(word: str, name: str) -> bool:
    """``word`` names the command ``name``: an abbreviation of at least four letters (or the
    whole name), or the name with a plural ``S`` (``SPCFORCES``; ``ES`` after an S: COSMIC
    NASTRAN's ``STRESSES``)."""
    return name.startswith(word) or word == name + "S" or (name.endswith("S") and word == name + "ES")


def _uncomment(raw: str) -> str:
    return raw.partition("$")[0].rstrip()


def bulk_start(lines: list[str]) -> tuple[int | None, int | None]:
    """``(CEND index, BEGIN BULK index)`` (0-based) of an input file's lines; ``None`` where absent."""
    cend = begin = None
    for i, raw in enumerate(lines):
        s = _uncomment(raw).strip()
        if cend is None and s.upper() == "CEND":
            cend = i
        elif cend is not None and _BEGIN_BULK.fullmatch(s):
            begin = i
            break
    return cend, begin


def _card_columns(raw: str) -> str:
    """A line cut at column 72 when what follows there is only marks (no letter or digit: a
    frame drawn around the commands, ``|``): NASTRAN reads columns 1-72 of a case-control card
    (NASTRAN-95 User's Manual 2.3.4, rule 6), and marks can carry no value. Other text beyond
    column 72 is kept (the line is read as written, and a value there is not silently lost)."""
    if len(raw) > 72 and raw[72:].strip() and not any(ch.isalnum() for ch in raw[72:]):
        return raw[:72]
    return raw


def _statements(lines: list[str], start: int, stop: int):
    """``(line number, text)`` of the commands in ``lines[start:stop]``, comma continuations joined."""
    pending, first = "", 0
    for i in range(start, stop):
        text = _uncomment(_card_columns(lines[i]))
        if not text.strip() and not pending:
            continue
        if not pending:
            first = i + 1
        pending += text.strip()
        if pending.endswith(","):
            continue
        yield first, pending
        pending = ""
    if pending:
        yield first, pending


def _integer(file: str, line: int, name: str, value: str) -> int:
    if not re.fullmatch(r"[+-]?\d+", value):
        raise DeckFormatError(f"{name} must select a set by its integer ID", file=file, line=line,
                              card=name, value=value)
    return int(value)


def read_case_control(text: str, file: str) -> CaseControl | None:
    """The executive and case control of the input file ``text`` (named ``file`` in errors);
    ``None`` for a file of bulk data only (no ``CEND`` line)."""
    lines = text.removeprefix("\ufeff").splitlines()
    cend, begin = bulk_start(lines)
    if cend is None:
        return None
    if begin is None:
        raise DeckFormatError("the deck has a CEND line (executive/case control) but no BEGIN BULK",
                              file=file, line=cend + 1)
    executive: list[str] = []
    sol = ""
    for line, stmt in _statements(lines, 0, cend):
        word = stmt.split(None, 1)[0].upper().rstrip(",")
        executive.append(word)
        if word == "SOL":
            sol = stmt.split(None, 1)[1].strip().upper() if len(stmt.split(None, 1)) > 1 else ""

    skipped: dict[str, dict[str, None]] = {}

    def skip(kind: str, name: str) -> None:
        skipped.setdefault(kind, {})[name] = None

    defaults: dict[str, tuple[object, int]] = {}
    subcases: list[tuple[int, int, dict[str, tuple[object, int]]]] = []
    current = defaults
    plot_packet = in_subcom = False
    autospc: tuple[str, int] | None = None
    # the first command the import cannot take (a superelement selection, a command that changes
    # the static solution, an unknown one): raised once the whole case control is read, unless
    # the deck has no static load case at all, which is then what the message says first
    refused: list[DeckFormatError] = []
    for line, stmt in _statements(lines, cend + 1, begin):
        if plot_packet:
            skip("plot commands", stmt.split(None, 1)[0].upper())
            continue
        m = _COMMAND.match(stmt)
        if m is None:
            raise DeckFormatError("cannot read this case-control command", file=file, line=line,
                                  value=stmt)
        # "LOAD = 1" and "LOAD 1" read alike: the "=" (group 3) is optional
        word, options, value = m.group(1).upper(), (m.group(2) or ""), m.group(4)
        key = word[:4]
        if word == "SUBCOM":
            # a linear combination of the subcases above: its own commands (SUBSEQ, output
            # requests) are read and dropped; the subcases it combines are imported themselves
            current = {}
            in_subcom = True
            skip("subcase combinations", f"SUBCOM {value.strip()}")
        elif word == "SUBSEQ":
            if not in_subcom:
                raise DeckFormatError("SUBSEQ outside a SUBCOM", file=file, line=line, card=word,
                                      value=stmt)
        elif word == "SUBCASE":
            in_subcom = False
            sid = _integer(file, line, "SUBCASE", value.strip())
            if sid < 1:
                raise DeckFormatError("SUBCASE ID must be >= 1", file=file, line=line,
                                      card="SUBCASE", value=value)
            if any(sid == s[0] for s in subcases):
                first = next(s[1] for s in subcases if s[0] == sid)
                raise DeckFormatError(f"SUBCASE {sid} appears twice (first at line {first})",
                                      file=file, line=line, card="SUBCASE", value=value)
            current = {}
            subcases.append((sid, line, current))
        elif word == "LOAD":
            current["LOAD"] = (_integer(file, line, "LOAD", value.strip()), line)
        elif word == "SPC":
            current["SPC"] = (_integer(file, line, "SPC", value.strip()), line)
        elif word == "MPC":
            current["MPC"] = (_integer(file, line, "MPC", value.strip()), line)
        elif len(word) >= 4 and _is(word, "SUPORT1"):
            current["SUPORT1"] = (_integer(file, line, "SUPORT1", value.strip()), line)
        elif word == "K2GG":
            name = value.strip().upper()
            if not re.fullmatch(r"[A-Z][A-Z0-9]{0,7}", name):
                raise DeckFormatError("K2GG is read as one DMIG matrix name (K2GG = NAME); scale "
                                      "factors and sums of matrices are not read (PARAM,CK2 scales "
                                      "the matrix)", file=file, line=line, card=word, value=stmt)
            current["K2GG"] = (name, line)
        elif key == "TEMP" and _is(word, "TEMPERATURE"):
            option = options.strip("() ").upper()
            kinds = _TEMP_OPTIONS.get(option)
            if kinds is None:
                raise DeckFormatError("TEMPERATURE's option must be LOAD, MATERIAL, INITIAL or BOTH",
                                      file=file, line=line, card=word, value=stmt)
            for kind in kinds:
                current[f"TEMP_{kind}"] = (_integer(file, line, "TEMPERATURE", value.strip()), line)
        elif key in _TITLES and _is(word, _TITLES[key]):
            current[_TITLES[key]] = (value, line)
        elif word == "OUTPUT":
            packet = options.strip("() ").upper()
            if packet in _PLOT_PACKETS:
                plot_packet = True
                skip("plot commands", f"OUTPUT({packet})")
            else:
                skip("output controls", f"OUTPUT{options.upper()}")
        elif key in ("SEAL", "SUPE", "SEKR", "SEMG", "SEEX", "SELG", "SELR", "SEDR", "SEFI"):
            if value.strip().upper() not in ("ALL", "0", ""):
                refused.append(DeckFormatError("superelement selections other than ALL are not supported "
                                               "(the import reads the residual structure only)", file=file,
                                               line=line, card=word, value=stmt))
                continue
            skip("superelement controls", f"{word} = {value.strip().upper()}")
        elif word == "PARAM":
            skip("case-control parameters", re.split(r"[,\s]+", value.strip(", "))[0].upper() or "PARAM")
        elif word == "BEGIN":
            raise DeckFormatError("only BEGIN BULK is supported (superelement bulk sections are not)",
                                  file=file, line=line, value=stmt)
        elif word == "AUTOSPC":
            # NASTRAN's automatic constraint of singular DOFs: YES is the SOL 101 default the
            # study reader applies; NO is carried into model.bdf as PARAM,AUTOSPC,NO
            flag = value.strip().upper() or "YES"
            if flag not in ("YES", "NO"):
                raise DeckFormatError("AUTOSPC must be YES or NO", file=file, line=line,
                                      card=word, value=stmt)
            autospc = (flag, line)
        elif key in _DESIGN:
            # the design model's selections (objective, constraints, responses, design
            # variables) do not change the static solution of the initial design; NASTRAN
            # reads them by their first four letters (DESOPJ is DESOBJ)
            name = _DESIGN[key]
            skip("design optimisation", name if _is(word, name) else f"{name} (written {word})")
            current.setdefault("OTHERS", ({}, line))[0][name] = value.strip()
        elif _lookup(_UNSUPPORTED, word) is not None:
            refused.append(DeckFormatError(f"the case-control command {_lookup(_UNSUPPORTED, word)} changes "
                                           f"the static solution and cannot be imported; remove it from the "
                                           f"deck (or model its effect with supported cards) and import again",
                                           file=file, line=line, card=word, value=stmt))
        else:
            for kind, table in (("output requests", _OUTPUT_REQUESTS),
                                ("output controls", _OUTPUT_CONTROLS),
                                ("selections of other solutions", _NOT_STATIC)):
                name = _lookup(table, word)
                if name is not None:
                    skip(kind, name)
                    if table is _NOT_STATIC:
                        current.setdefault("OTHERS", ({}, line))[0][name] = value.strip()
                    break
            else:
                close = difflib.get_close_matches(word, known_commands(), n=3, cutoff=0.6)
                hint = f"; did you mean {' or '.join(close)}?" if close else ""
                refused.append(DeckFormatError("unknown case-control command (not read by blackbox import; "
                                               "docs/import.md lists the commands it skips as having no "
                                               f"effect on a linear static solution){hint}",
                                               file=file, line=line, card=word, value=stmt))

    def make(sid: int, line: int, own: dict) -> Subcase:
        merged = {**defaults, **own}
        others = {**defaults.get("OTHERS", ({}, 0))[0], **own.get("OTHERS", ({}, 0))[0]}
        load, load_line = merged.get("LOAD", (None, 0))
        spc, spc_line = merged.get("SPC", (None, 0))
        mpc, mpc_line = merged.get("MPC", (None, 0))
        temps = [v for k in ("TEMP_LOAD", "TEMP_MAT", "TEMP_INIT") for v in merged.get(k, (None, 0))]
        suport1, suport1_line = merged.get("SUPORT1", (None, 0))
        analysis = re.sub(r"\s+", "", others.get("ANALYSIS", "")).upper()
        k2gg, k2gg_line = merged.get("K2GG", (None, 0))
        return Subcase(sid, load, spc, line, load_line, spc_line,
                       str(merged.get("TITLE", ("", 0))[0]), str(merged.get("SUBTITLE", ("", 0))[0]),
                       str(merged.get("LABEL", ("", 0))[0]),
                       tuple(f"{k} = {v}" if v else k for k, v in others.items()), mpc, mpc_line, *temps,
                       suport1, suport1_line, analysis, k2gg, k2gg_line)

    if subcases:
        cases = tuple(make(sid, line, own) for sid, line, own in subcases)
    else:
        cases = (make(1, 0, {}),)
    if refused:
        first = refused[0]
        static_sol = not sol or solution_key(sol) in STATIC_SOLUTIONS
        if not static_sol and not any(c.load is not None or c.temp_load is not None for c in cases):
            # nothing of this deck could be a study: that comes first, the command besides
            raise DeckFormatError(f"no static load case to import: the deck's solution is SOL {sol}, not "
                                  f"linear statics, and no subcase selects a load set (LOAD =); besides, "
                                  f"{first}", file=file, line=first.line)
        raise first
    return CaseControl(file, cases, bool(subcases), sol, tuple(executive),
                       {k: tuple(v) for k, v in skipped.items()}, begin + 1, autospc)
