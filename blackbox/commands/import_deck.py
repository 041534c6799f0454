"""``blackbox import DECK --out STUDY``: a whole NASTRAN input file becomes a study folder.

* ``model.bdf``: the deck's bulk data as written (comments and formats kept, INCLUDEs inlined),
  without its load cards and with only the constraint sets the case control selects;
* ``loads.csv``: one case per SUBCASE (labelled by its ID; ``1`` for a deck without SUBCASE),
  the subcase's ``LOAD =`` set resolved into nodal forces and moments (:mod:`solver_adapters.loadcards`);
* ``study.toml``: the study to complete: the joints named with ``--joint NAME:G1,G2,...`` (checked
  against the deck), else a commented template listing the candidate joints of the deck.

The executive and case control are read by :mod:`solver_adapters.casecontrol`; what is skipped
(output requests, titles, plot packets ...) is reported once per kind in :attr:`ImportResult.notes`.
docs/import.md describes the rules.
"""

from __future__ import annotations

import json
import re
import time
from collections import Counter
from dataclasses import dataclass, replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from blackbox.commands import enforced
from blackbox.errors import StudyError
from solver_adapters.bdf import deck_from_cards
from solver_adapters.bdf.params import inrel_value
from solver_adapters.bdf.tokens import BEGIN_BULK as _BEGIN_BULK, _INCLUDE, _split, _strip_comment, is_include
from solver_adapters.casecontrol import STATIC_SOLUTIONS as _STATIC_SOLS, CaseControl, bulk_start
from solver_adapters.casecontrol import solution_key as _sol_key
from solver_adapters.deck import Deck
from solver_adapters.loadcards import LOAD_CARDS, OTHER_LOAD_CARDS, read_input_file
from solver_adapters.protocol import DeckFormatError

__all__ = ["ImportResult", "run", "parse_joint", "candidate_joints"]

_SPC_CARDS = ("SPC", "SPC1", "SPCADD")
_MPC_CARDS = ("MPC", "MPCADD")
_SUPORT1 = ("SUPORT1",)
# MYSTRAN's own bulk-data card for debug printout: no effect on the solution, not NASTRAN.
_SOLVER_DEBUG = ("DEBUG",)
_DESIGN_CARDS = ("DESVAR", "DLINK", "DVPREL1", "DVMREL1", "DVPREL2", "DVMREL2", "DVCREL1", "DVCREL2",
                 "DEQATN", "DTABLE")
_DESIGN_SOLS = ("200", "DESOPT")


@dataclass(frozen=True, eq=False)
class ImportResult:
    """The study made from one input file: the three files' text, the parsed model, the notes."""
    source: Path
    model_bdf: str
    loads_csv: str
    study_toml: str
    cases: tuple[str, ...]
    deck: Deck
    notes: tuple[str, ...]
    n_cards: int
    read_seconds: float
    joints: tuple[tuple[str, tuple[int, ...]], ...]
    command: str = "import"

    def write(self, out: Path) -> list[str]:
        """``model.bdf``, ``loads.csv`` and ``study.toml`` into the (existing, empty) folder ``out``."""
        out = Path(out)
        (out / "model.bdf").write_text(self.model_bdf)
        (out / "loads.csv").write_text(self.loads_csv)
        (out / "study.toml").write_text(self.study_toml)
        return ["model.bdf", "loads.csv", "study.toml"]


# --------------------------------------------------------------------------------------------
# joints
# --------------------------------------------------------------------------------------------
def parse_joint(text: str) -> tuple[str, tuple[int, ...]]:
    """``NAME:G1,G2,...`` -> ``(NAME, (G1, G2, ...))``; StudyError naming ``--joint`` otherwise."""
    name, sep, rest = text.partition(":")
    name = name.strip()
    try:
        grids = tuple(int(g) for g in rest.split(",") if g.strip())
    except ValueError:
        grids = ()
    if not sep or not name or len(grids) < 2:
        raise StudyError(f"--joint {text!r}: expected NAME:G1,G2,... (a name, then at least two "
                         f"grid IDs, branch 1 first)")
    if len(set(grids)) != len(grids):
        raise StudyError(f"--joint {text!r}: a grid is named twice")
    if not re.fullmatch(r"[A-Za-z0-9_.-]+", name):
        raise StudyError(f"--joint {text!r}: the name may hold letters, digits, '_', '.', '-'")
    return name, grids


def _model_size(deck: Deck) -> float:
    xyz = np.array([g.xyz for g in deck.grids.values()]) if deck.grids else np.zeros((1, 3))
    return max(float(np.ptp(xyz, axis=0).max()), 1e-300)


def candidate_joints(deck: Deck) -> list[tuple[int, ...]]:
    """Groups of coincident grids tied in translation by one RBE2 (CM containing 123): GN first,
    then the coincident dependent grids in the RBE2's order."""
    size = _model_size(deck)
    out = []
    for r in deck.rbe2s.values():
        if not set("123") <= set(r.cm) or r.gn not in deck.grids:
            continue
        x0 = np.array(deck.grids[r.gn].xyz)
        same = [g for g in r.gm if g in deck.grids
                and float(np.max(np.abs(np.array(deck.grids[g].xyz) - x0))) <= 1e-9 * size]
        if same:
            out.append((r.gn, *same))
    return out


def _check_joints(joints, deck: Deck) -> None:
    from blackbox.study import check_joints
    config = SimpleNamespace(joints=[SimpleNamespace(name=n, grids=list(g), rigid_pairs=[])
                                     for n, g in joints])
    used: dict[int, str] = {}
    for n, g in joints:
        for gid in g:
            if gid in used:
                raise StudyError(f"--joint {n}: grid {gid} already belongs to joint {used[gid]}")
            used[gid] = n
    if len({n for n, _ in joints}) != len(joints):
        raise StudyError("--joint: two joints have the same name")
    check_joints(config, deck, Path("--joint"))


def _relieved(applied: list, deck: Deck, cards, param, notes: list[str]) -> list:
    """The cases' loads balanced by inertia relief on the model's SUPORT DOFs (PARAM,INREL,-1
    at ``param``; :func:`solver_adapters.reference.inertia.relieve`), with a note."""
    from solver_adapters.elementloads import MassReader
    from solver_adapters.reference.inertia import SUPORT_CARDS, relieve
    masses = MassReader(cards).masses(param, deck, "", lead="PARAM,INREL,-1 (inertia relief)")
    balanced, accel, _ = relieve(deck, masses, [v for _, v in applied], param_src=param.src)
    rset = [f"{g}:{c}" for s in deck.spc1s if s.card in SUPORT_CARDS for g in s.grids for c in s.components]
    notes.append(f"inertia relief (PARAM,INREL,-1 at {param.src}): every case's loads balanced by "
                 f"the inertia loads of its rigid-body acceleration on the SUPORT DOFs "
                 f"({', '.join(rset)}; " + "; ".join(
                     f"case {label}: " + ", ".join(f"{a:.4g}" for a in acc)
                     for (label, _), acc in list(zip(applied, accel))[:6])
                 + (" ..." if len(applied) > 6 else "") + "): loads.csv holds the balanced loads, "
                 "model.bdf the SUPORT DOFs (held, as NASTRAN holds them) without the PARAM; the "
                 "displacements are relative to the SUPORT DOFs")
    return [(label, values) for (label, _), values in zip(applied, balanced)]


def _study_toml(name: str, source: Path, cases, joints, deck: Deck) -> str:
    lines = [f"# Made by `blackbox import` from {source.name}: model.bdf (its bulk data), loads.csv",
             f"# ({len(cases)} case(s): {', '.join(cases[:20])}{' ...' if len(cases) > 20 else ''}, "
             f"one per SUBCASE). Complete it, then add measurements.csv (docs/study-format.md).",
             f"name = {json.dumps(name)}", "", "[solver]"]
    if deck.unmodelled:
        kinds = ", ".join(f"{n} x{k}" for n, (k, _) in deck.unmodelled_counts().items())
        lines += [f"# The deck has cards the in-process reference solver does not model ({kinds}):",
                  "# MYSTRAN solves it (an external adapter needs only the grids, joints and loads).",
                  'adapter = "mystran"']
    else:
        lines.append('adapter = "reference"')
    lines += ['deck = "model.bdf"', ""]
    if joints:
        for n, g in joints:
            lines += ["[[joints]]", f"name = {json.dumps(n)}", f"grids = [{', '.join(map(str, g))}]",
                      'model = "simple"', "initial = 1.0e3", ""]
        return "\n".join(lines)
    cands = candidate_joints(deck)
    lines += ["# Flexible joints: uncomment one [[joints]] table per joint to identify (the grids are",
              "# the branch-end grids, branch 1 = the RBE2's GN first; `initial` in your units of",
              "# moment per radian)."]
    if cands:
        lines.append(f"# Candidates found in the deck ({len(cands)}): groups of coincident grids tied "
                     f"by an RBE2 with CM containing 123.")
        for g in cands:
            lines += ["#", "# [[joints]]", f'# name = "J{g[0]}"', f"# grids = [{', '.join(map(str, g))}]",
                      '# model = "simple"', "# initial = 1.0e3"]
    else:
        lines.append("# No candidate found: the deck has no coincident grids tied by an RBE2 with "
                     "CM containing 123 (docs/study-format.md, 'Declaring a flexible joint').")
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------------------------
# model.bdf: the bulk data as written, minus the dropped cards
# --------------------------------------------------------------------------------------------
def _card_image(raw: str) -> str:
    """A fixed-field line cut at column 80 (a card image is 80 columns; NASTRAN reads no further:
    decks put remarks there). Free-field lines (commas) and INCLUDE statements (a path may be
    longer) are left as they are."""
    if len(raw) <= 80 and "\t" not in raw:
        return raw
    if "," in raw.partition("$")[0] or raw.lstrip()[:7].upper() == "INCLUDE":   # no card image
        return raw
    body, dollar, comment = raw.partition("$")
    wide = body.expandtabs(8)
    if len(wide.rstrip()) <= 80:
        return raw
    return wide[:80].rstrip()


def _is_enddata(body: str) -> bool:
    """Whether the reader stops at this comment-free line (its field 1 is ENDDATA)."""
    if "ENDDATA" not in body.upper():
        return False
    try:
        return _split(body, "", 0).first.rstrip("*") == "ENDDATA"
    except DeckFormatError:
        return False


def _one_fate_per_line(shown: str, numbers: list[int], dropped: set[int], kept: set[int]) -> None:
    """A COSMIC free-field line that generates several cards (``=(N)``) is copied or left out
    whole: an error when the import keeps some of its cards and leaves out others (a load set
    and the next constraint set of one replication)."""
    seen: set[int] = set()
    several = {n for n in numbers if n in seen or seen.add(n)}
    both = sorted(dropped & kept & several)
    if both:
        raise DeckFormatError("this free-field line generates cards of which the import keeps some "
                              "(the model, the selected sets) and leaves out others (load cards, "
                              "sets not selected); write those cards on lines of their own",
                              file=shown, line=both[0])


def _model_body(lines: list[str], shown: str, start: int, bulk, kept: dict, dropped: dict,
                out: list[str]) -> bool:
    """Append the bulk data of one file to ``out``; True once ENDDATA is met. The input file
    itself (``start``: its first bulk line) is copied as written, comments too, without the lines
    of the dropped cards; an included file (``start`` None) gives only the lines the reader read
    as its kept cards, each without its comment: import copies nothing of an included file
    that it did not read as a card. INCLUDE lines are replaced by what they include, between
    comment lines naming them (the files' texts as the reader read them, never read again)."""
    own = start is not None
    drop = dropped.get(shown, set())
    keep = kept.get(shown, set())
    numbers = None
    if shown in bulk.expanded:
        # COSMIC free-field input: the card images the reader made of it, each numbered by the
        # line it came from (MYSTRAN and diagnose's edited decks read no replication)
        lines, numbers = bulk.expanded[shown]
    for k in range(start or 0, len(lines)):
        raw, n = lines[k], (numbers[k] if numbers else k + 1)
        if n in drop:
            continue
        head = raw.lstrip()[:1]
        if head and head in "BbIiEe":
            body = _strip_comment(raw)
            s = body.strip()
            if _BEGIN_BULK.fullmatch(s):
                continue
            if is_include(s):
                inc = bulk.included[(shown, n)]
                name = next(g for g in _INCLUDE.fullmatch(s).groups() if g is not None)
                out.append(f"$ ---- INCLUDE '{name}' inlined by blackbox import ----")
                text = bulk.texts[inc].removeprefix("\ufeff").splitlines()
                ended = _model_body(text, inc, None, bulk, kept, dropped, out)
                out.append(f"$ ---- end of '{name}' ----")
                if ended:
                    return True
                continue
            if _is_enddata(body):
                return True
        if own:
            out.append(_card_image(raw).rstrip())
        elif n in keep:
            out.append(_card_image(_strip_comment(raw)).rstrip())
    return False


# --------------------------------------------------------------------------------------------
# the import
# --------------------------------------------------------------------------------------------
def _plural(n: int, word: str) -> str:
    return f"{n} {word}{'' if n == 1 else 's'}"


def _spc_sets_of(cards, names=_SPC_CARDS) -> dict[int, list]:
    sets: dict[int, list] = {}
    for c in cards:
        if c.name in names and c.text(2):
            try:
                sets.setdefault(int(c.text(2)), []).append(c)
            except ValueError:
                raise c.error(2, "SID must be an integer") from None
    return sets


def _spc_members(sid: int, sets: dict[int, list], add: str = "SPCADD") -> set[int]:
    """The SPC/SPC1 set IDs that constraint set ``sid`` stands for (through SPCADD; with
    ``add="MPCADD"`` the MPC sets of an MPC set, through MPCADD)."""
    cards = sets.get(sid, [])
    adds = [c for c in cards if c.name == add]
    if not adds:
        return {sid}
    members = {sid}
    for c in adds:
        for i in range(3, len(c.fields) + 1):
            t = c.text(i)
            if t:
                try:
                    members.add(int(t))
                except ValueError:
                    raise c.error(i, f"{add} set IDs must be integers") from None
    return members


def _one_selection(cc: CaseControl, attr: str, name: str, path: Path, what: str | None = None,
                   one: str = "model") -> int | None:
    """The set the subcases that import a load select with ``name =`` (``attr`` of each
    subcase; ``None``: none selects one). They must all select the same (a study has one
    ``one``), else an error listing each subcase's choice (``what``: the sets' name in it,
    ``name`` by default)."""
    chosen = {getattr(s, attr) for s in cc.subcases if s.static}
    if len(chosen) > 1:
        detail = ", ".join(f"subcase {s.id}: {'none' if getattr(s, attr) is None else getattr(s, attr)}"
                           for s in cc.subcases if s.static)
        raise DeckFormatError(f"the subcases select different {what or name} sets ({detail}); a study has "
                              f"one {one}: give every subcase the same {name} = set (or import the deck "
                              f"once per set)", file=str(path))
    return chosen.pop() if chosen else None


def _one_constraint_set(selected: list, cc: CaseControl, spc: int | None, path: Path,
                        notes: list[str]) -> tuple[list, CaseControl]:
    """The imported subcases of one constraint set (a study has one set of supports): those that
    select ``spc`` (``--spc``), else those of the first imported subcase's set; the others are
    left out with a note naming them and the option that imports them. The case control keeps
    only the subcases that stay (the later selections, MPC and SUPORT1, read those)."""
    by_id = {str(s.id): s for s in cc.subcases}
    chosen_sets = list(dict.fromkeys(by_id[label].spc for label, *_ in selected))
    if spc is None and len(chosen_sets) <= 1:
        return selected, cc
    chosen = chosen_sets[0] if spc is None else spc
    if chosen not in chosen_sets:
        raise DeckFormatError(f"--spc {spc}: no imported subcase selects SPC = {spc} (they select "
                              f"{', '.join('none' if c is None else str(c) for c in chosen_sets)})", file=str(path))
    left = [label for label, *_ in selected if by_id[label].spc != chosen]
    if left:
        others = sorted({by_id[label].spc for label in left}, key=lambda c: (c is None, c or 0))
        notes.append(f"the subcases select different constraint sets and a study has one set of supports: "
                     f"imported the subcases of SPC = {chosen}; left out subcase(s) {', '.join(left)} (SPC = "
                     f"{', '.join('none' if c is None else str(c) for c in others)}): import the deck again with "
                     f"--spc N for another set")
    keep = [row for row in selected if by_id[row[0]].spc == chosen]
    return keep, replace(cc, subcases=tuple(s for s in cc.subcases if str(s.id) not in left))


def _mpc_selection(cc: CaseControl, sets: dict[int, list], path: Path, notes: list[str]) -> list:
    """The MPC/MPCADD cards to drop from model.bdf: every set the subcases do not select (all of
    them when none selects one: NASTRAN then applies none). The subcases that import a load must
    select the same MPC set (a study has one model)."""
    choice = _one_selection(cc, "mpc", "MPC", path)
    if choice is None:
        notes.append(f"no subcase selects an MPC set (no MPC =), so NASTRAN applies none: dropped "
                     f"the MPC/MPCADD cards of set(s) {', '.join(map(str, sorted(sets)))}")
        return [c for cs in sets.values() for c in cs]
    line = next(s.mpc_line for s in cc.subcases if s.static)
    if choice not in sets:
        raise DeckFormatError(f"MPC = {choice} selects a set the bulk data does not have (no MPC or "
                              f"MPCADD with SID {choice})", file=str(path), line=line, card="MPC",
                              value=str(choice))
    keep = _spc_members(choice, sets, "MPCADD")
    dropped = sorted(set(sets) - keep)
    notes.append(f"MPC = {choice} selected: kept MPC set(s) {', '.join(map(str, sorted(keep & set(sets))))}"
                 + (f"; dropped set(s) {', '.join(map(str, dropped))} (not selected)" if dropped else ""))
    return [c for sid in dropped for c in sets[sid]]


def _suport1_selection(cc: CaseControl, sets: dict[int, list], path: Path, notes: list[str]) -> list:
    """The SUPORT1 cards to drop from model.bdf: every set the subcases do not select (all of
    them when none selects one: NASTRAN then applies none). The subcases that import a load must
    select the same set (a study has one model). Bulk SUPORT cards always apply and stay."""
    choice = _one_selection(cc, "suport1", "SUPORT1", path)
    if choice is None:
        if sets:
            notes.append(f"no subcase that imports a load selects a SUPORT1 set (no SUPORT1 =), so "
                         f"NASTRAN applies none: dropped the SUPORT1 cards of set(s) "
                         f"{', '.join(map(str, sorted(sets)))}")
        return [c for cs in sets.values() for c in cs]
    line = next(s.suport1_line for s in cc.subcases if s.static)
    if choice not in sets:
        raise DeckFormatError(f"SUPORT1 = {choice} selects a set the bulk data does not have (no "
                              f"SUPORT1 with SID {choice})", file=str(path), line=line,
                              card="SUPORT1", value=str(choice))
    dropped = sorted(set(sets) - {choice})
    notes.append(f"SUPORT1 = {choice} selected: kept SUPORT1 set {choice}"
                 + (f"; dropped set(s) {', '.join(map(str, dropped))} (not selected)" if dropped else ""))
    return [c for sid in dropped for c in sets[sid]]


def _inertia_relief(cards) -> tuple[int, list]:
    """PARAM,INREL of the deck: its value (0 without one; the last card wins) and its cards.
    -2 (automatic inertia relief, without SUPORT) is refused at the card: NASTRAN then reports
    the displacements with the mass-weighted rigid-body motion removed (M D)^T u = 0, which a
    study whose model holds supports cannot reproduce."""
    params = [c for c in cards if c.name == "PARAM" and c.text(2) == "INREL"]
    if not params:
        return 0, []
    value = inrel_value(params[-1])
    if value == -2:
        raise params[-1].error(3, "PARAM,INREL,-2 (automatic inertia relief) is not imported: "
                                  "NASTRAN then reports the displacements relative to the "
                                  "mass-weighted mean rigid-body motion ((M D)^T u = 0), which a "
                                  "study, whose model holds supports, cannot reproduce. Use "
                                  "PARAM,INREL,-1 with SUPORT entries on a statically determinate "
                                  "set of DOFs (six for a free 3-D structure): the displacements "
                                  "are then relative to them")
    return value, params


_SOL_NAMES = {"3": "normal modes", "103": "normal modes", "SEMODES": "normal modes", "MODES": "normal modes",
              "5": "buckling", "105": "buckling", "SEBUCKL": "buckling", "106": "nonlinear statics",
              "NLSTATIC": "nonlinear statics", "107": "complex modes", "108": "direct frequency response",
              "109": "direct transient response", "110": "modal complex modes",
              "111": "modal frequency response", "112": "modal transient response",
              "129": "nonlinear transient response", "144": "static aeroelasticity",
              "145": "flutter", "146": "aeroelastic response", "153": "steady thermal",
              "159": "transient thermal", "200": "design optimisation", "DESOPT": "design optimisation",
              "400": "nonlinear (SOL 400)", "402": "nonlinear (SOL 402)"}


def _sol_text(sol: str) -> str:
    name = _SOL_NAMES.get(sol.upper())
    return f"SOL {sol}" + (f" ({name})" if name else "")


def _no_static_load(cc: CaseControl | None, path: Path) -> str:
    """The message of a deck with no static load case: what its subcases select instead."""
    if cc is None:
        return "no static load case to import: the deck has no case control and no load cards"
    own = (f"the deck's solution is {_sol_text(cc.sol)}, not linear statics, and " if cc.sol
           and _sol_key(cc.sol) not in _STATIC_SOLS else "")
    what = "; ".join(f"subcase {s.id}: {', '.join(s.others) or 'no selection'}"
                     for s in cc.subcases[:8]) + (" ..." if len(cc.subcases) > 8 else "")
    return (f"no static load case to import: {own}no subcase selects a static load set with "
            f"LOAD = ({what}). A study needs at least one load case: add a subcase with LOAD = n "
            f"naming a FORCE/MOMENT/PLOAD1/GRAV/LOAD set to the deck (or write loads.csv "
            f"yourself) and import again")


def _dmig_selection(cc: CaseControl | None, cards, path: Path, notes: list[str]) -> list:
    """The DMIG cards to drop: NASTRAN adds to the stiffness the matrix that K2GG = NAME selects
    (one for every imported subcase) and no other, while a study adds every DMIG of model.bdf;
    a deck without case control keeps them all."""
    dmigs = [c for c in cards if c.name == "DMIG"]
    if cc is None:
        if dmigs:
            notes.append("no case control: every DMIG matrix of the deck is added to the stiffness (K2GG)")
        return []
    chosen = {s.k2gg for s in cc.subcases if s.static}
    if len(chosen) > 1:
        detail = ", ".join(f"subcase {s.id}: {s.k2gg or 'none'}" for s in cc.subcases if s.static)
        raise DeckFormatError(f"the subcases select different K2GG matrices ({detail}); a study has "
                              f"one stiffness: give every subcase the same K2GG", file=str(path))
    name = chosen.pop() if chosen else None
    names = list(dict.fromkeys(c.text(2) for c in dmigs))
    if name is not None:
        line = next(s.k2gg_line for s in cc.subcases if s.static)
        if name not in names:
            raise DeckFormatError(f"K2GG = {name} selects a matrix the bulk data does not have (no "
                                  f"DMIG named {name})", file=str(path), line=line, card="K2GG",
                                  value=name)
        notes.append(f"K2GG = {name} at {path}:{line}: DMIG {name} kept in model.bdf, added to the "
                     f"stiffness in the g-set (times PARAM,CK2)")
    dropped = [n for n in names if n != name]
    if dropped:
        notes.append(f"dropped DMIG matrix(es) {', '.join(dropped)} from model.bdf: "
                     f"{'not selected by K2GG' if name else 'no K2GG selects them'} (NASTRAN adds none "
                     f"that the case control does not select)")
    return [c for c in dmigs if c.text(2) != name]


def _initial_temperatures(cc: CaseControl | None) -> int | None:
    """The TEMPERATURE(INITIAL) set of the subcases that import a load (one, else an error)."""
    if cc is None:
        return None
    chosen = {s.temp_init for s in cc.subcases if s.static and s.temp_init is not None}
    if len(chosen) > 1:
        s = next(s for s in cc.subcases if s.static and s.temp_init is not None)
        raise DeckFormatError(f"the subcases select different initial temperature sets "
                              f"({', '.join(map(str, sorted(chosen)))}); NASTRAN uses one",
                              file=cc.file, line=s.temp_init_line, card="TEMPERATURE")
    return chosen.pop() if chosen else None


def _temperature_selections(cc: CaseControl, cards, path: Path, notes: list[str]) -> None:
    """TEMPERATURE(MATERIAL) (also from TEMPERATURE = n) selects the temperatures of
    temperature-dependent materials (MATTi): no effect on a deck without MATTi cards, and an
    error with them (the reference solver has no temperature-dependent material)."""
    mat = [s for s in cc.subcases if s.static and s.temp_mat is not None]
    if not mat:
        return
    init = next((s for s in cc.subcases if s.static and s.temp_init is not None), None)
    if init is not None:
        raise DeckFormatError(f"TEMPERATURE(MATERIAL) = {mat[0].temp_mat} (TEMPERATURE = n is LOAD and "
                              f"MATERIAL) and TEMPERATURE(INITIAL) = {init.temp_init} cannot both be "
                              f"given (MSC QRG TEMPERATURE, remark 8): select the thermal load with "
                              f"TEMPERATURE(LOAD)", file=str(path), line=mat[0].temp_mat_line,
                              card="TEMPERATURE")
    matt = next((c for c in cards if c.name.startswith("MATT")), None)
    if matt is not None:
        raise DeckFormatError(f"TEMPERATURE(MATERIAL) = {mat[0].temp_mat} selects temperatures for "
                              f"temperature-dependent materials, and the deck has {matt.name} at "
                              f"{matt.src}: temperature-dependent materials are not modelled",
                              file=str(path), line=mat[0].temp_mat_line, card="TEMPERATURE")
    notes.append(f"TEMPERATURE(MATERIAL) = {', '.join(sorted({str(s.temp_mat) for s in mat}))} "
                 f"(TEMPERATURE = n is LOAD and MATERIAL): no effect, the deck has no "
                 f"temperature-dependent material (MATTi)")


def run(deck_path: str | Path, *, joints: list[str] | tuple[str, ...] = (),
        include_dirs: list | tuple = (), spc: int | None = None) -> ImportResult:
    """Read the NASTRAN input file ``deck_path`` and make the study's files (not written yet).
    INCLUDEs read regular files inside the input file's folder tree only, or inside one of
    ``include_dirs`` (``--include-dir``) or the user's configured ``include_dirs``. ``spc``
    (``--spc``): the constraint set whose subcases are imported when they select different ones
    (default: the first imported subcase's)."""
    from solver_adapters.userconfig import configured_include_dirs
    path = Path(deck_path)
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise DeckFormatError(f"cannot read the deck: {exc.strerror or exc}", file=str(path)) from None
    notes: list[str] = []
    t0 = time.perf_counter()
    raw_lines = text.removeprefix("\ufeff").splitlines()
    images = [_card_image(r) for r in raw_lines] if any(len(r) > 80 or "\t" in r for r in raw_lines) \
        else raw_lines
    cut = sum(a != b for a, b in zip(raw_lines, images))
    source = read_input_file(path, "\n".join(images), (*include_dirs, *configured_include_dirs()))

    cc: CaseControl | None = source.case_control
    cards, files, loads = source.cards, source.files, source.loads
    load_cards = [c for c in cards if c.name in LOAD_CARDS or c.name in OTHER_LOAD_CARDS]
    spc_sets = _spc_sets_of(cards)
    mpc_sets = _spc_sets_of(cards, _MPC_CARDS)

    # the cases: one per subcase that selects a load set
    if cc is None:
        top = sorted(loads.set_ids - {li for c in loads.combinations.values() for _, li in c.terms})
        if len(top) > 1:
            raise DeckFormatError(f"the deck has no case control (no CEND line), so no subcase "
                                  f"selects a load set, and it has {len(top)} load sets "
                                  f"({', '.join(map(str, top[:10]))}); add a case control with one "
                                  f"SUBCASE per load case (SUBCASE n / LOAD = set) and import again",
                                  file=str(path))
        selected = [("1", top[0], None, f"{path}: the only load set")] if top else []
        if top:
            notes.append(f"no case control: load set {top[0]} (the deck's only one) imported as case 1")
        spc_choice = None
    else:
        selected = []
        if not cc.sol or _sol_key(cc.sol) in _STATIC_SOLS:
            # a static subcase with no load set whose constraint set enforces displacements is
            # loaded by them (blackbox.commands.enforced)
            def values_of(sid):
                return enforced.spc_values(c for m in _spc_members(sid, spc_sets) for c in spc_sets.get(m, ()))
            cc = replace(cc, subcases=tuple(
                replace(s, enforced_only=True) if (s.load is None and s.temp_load is None and s.spc is not None
                                                   and s.analysis_static and values_of(s.spc)) else s
                for s in cc.subcases))
        if cc.sol and _sol_key(cc.sol) not in _STATIC_SOLS:
            # a SOL 200 subcase whose ANALYSIS is STATICS is SOL 101's linear static analysis
            # (of the initial design): its TEMPERATURE selections mean what they mean there
            design = _sol_key(cc.sol) in _DESIGN_SOLS
            for s in cc.subcases:
                line = s.temp_load_line or s.temp_mat_line or s.temp_init_line
                if line and not (design and s.analysis_static):
                    raise DeckFormatError(f"the deck's solution is {_sol_text(cc.sol)}, not linear "
                                          f"statics: its TEMPERATURE selections mean what that "
                                          f"solution makes of them, and are imported in a linear "
                                          f"static deck (SOL 101, or a SOL 200 subcase with "
                                          f"ANALYSIS = STATICS) only", file=str(path), line=line,
                                          card="TEMPERATURE")
        for s in cc.subcases:
            if not s.analysis_static:
                notes.append(f"subcase {s.id} is ANALYSIS = {s.analysis}, not a static analysis: not imported")
                continue
            if not s.static:
                notes.append(f"subcase {s.id} selects no load set (no LOAD = or TEMPERATURE(LOAD) =): not imported")
                continue
            if (cc.sol and _sol_key(cc.sol) not in _STATIC_SOLS and s.temp_load is None
                    and s.load not in loads.set_ids):
                # a modal or dynamic solution does not read a LOAD = naming no set: nothing to import
                notes.append(f"subcase {s.id}: LOAD = {s.load} at {path}:{s.load_line} names no load set, "
                             f"which {_sol_text(cc.sol)} does not read: not imported")
                continue
            what = ([f"LOAD = {s.load} at {path}:{s.load_line}"] if s.load is not None else []) + \
                ([f"TEMPERATURE(LOAD) = {s.temp_load} at {path}:{s.temp_load_line}"]
                 if s.temp_load is not None else []) + \
                ([f"SPC = {s.spc} at {path}:{s.spc_line} (its enforced values)"] if s.enforced_only else [])
            where = " and ".join(what) + (f", subcase {s.id}" if cc.explicit else "")
            selected.append((str(s.id), s.load, s.temp_load, where))
        selected, cc = _one_constraint_set(selected, cc, spc, path, notes)
        _temperature_selections(cc, cards, path, notes)
        spc_choice = _one_selection(cc, "spc", "SPC", path, what="constraint", one="set of supports")
    if not selected:
        raise DeckFormatError(_no_static_load(cc, path), file=str(path))

    # the constraint sets kept in model.bdf
    drop_cards = list(load_cards)
    if cc is not None and spc_sets:
        if spc_choice is None:
            drop_cards += [c for cs in spc_sets.values() for c in cs]
            notes.append(f"no subcase selects a constraint set (no SPC =), so NASTRAN applies none: "
                         f"dropped the SPC/SPC1/SPCADD cards of set(s) "
                         f"{', '.join(map(str, sorted(spc_sets)))}")
        else:
            line = next(s.spc_line for s in cc.subcases if s.static)
            if spc_choice not in spc_sets:
                raise DeckFormatError(f"SPC = {spc_choice} selects a constraint set the bulk data "
                                      f"does not have (no SPC, SPC1 or SPCADD with SID {spc_choice})",
                                      file=str(path), line=line, card="SPC", value=str(spc_choice))
            keep = _spc_members(spc_choice, spc_sets)
            dropped = sorted(set(spc_sets) - keep)
            drop_cards += [c for sid in dropped for c in spc_sets[sid]]
            notes.append(f"SPC = {spc_choice} selected: kept constraint set(s) "
                         f"{', '.join(map(str, sorted(keep & set(spc_sets))))}"
                         + (f"; dropped set(s) {', '.join(map(str, dropped))} (not selected)" if dropped else ""))
    if cc is not None and (mpc_sets or any(s.mpc is not None for s in cc.subcases)):
        drop_cards += _mpc_selection(cc, mpc_sets, path, notes)
    suport1_sets = _spc_sets_of(cards, _SUPORT1)
    if cc is not None and (suport1_sets or any(s.suport1 is not None for s in cc.subcases)):
        drop_cards += _suport1_selection(cc, suport1_sets, path, notes)
    inrel, inrel_cards = _inertia_relief(cards)
    if inrel == -1:
        drop_cards += inrel_cards
    debug = [c for c in cards if c.name in _SOLVER_DEBUG]
    drop_cards += debug
    drop_cards += _dmig_selection(cc, cards, path, notes)
    # the design model: SOL 200 analyses the initial design (the reader applies the relations);
    # in a deck of another solution NASTRAN does not read it, so it is not carried over
    design_cards = [c for c in cards if c.name in _DESIGN_CARDS]
    design_dropped = bool(design_cards) and cc is not None and _sol_key(cc.sol) not in _DESIGN_SOLS
    if design_dropped:
        drop_cards += design_cards
    dropped_ids = {id(c) for c in drop_cards}
    kept = [c for c in cards if id(c) not in dropped_ids]
    # enforced values on SPC cards (large-spring method, blackbox.commands.enforced): the reader
    # takes each such card as the constraint alone
    spc_values = enforced.spc_values(kept)
    if spc_values:
        with_values = {id(card) for _, card, _ in spc_values.values()}
        kept = [enforced.without_values(c) if id(c) in with_values else c for c in kept]
    # cards the reference solver does not model (shells, solids) are kept for an external solver:
    # the study's adapter is then MYSTRAN (study.toml, a note); load cards are gone already, and
    # the cards that cannot be handed on (superelements) stay errors
    deck = deck_from_cards(kept, unmodelled="keep")
    if deck.unmodelled:
        kinds = ", ".join(f"{n} x{k}" for n, (k, _) in deck.unmodelled_counts().items())
        notes.append(f"kept {_plural(len(deck.unmodelled), 'card')} the reference solver does not model "
                     f"({kinds}): study.toml names the mystran adapter, which runs them")
    if inrel != -1 and any(s.card in ("SUPORT", "SUPORT1") for s in deck.spc1s):
        notes.append("note: SUPORT DOFs without inertia relief (no PARAM,INREL,-1): a linear static "
                     "solution holds them as it holds an SPC, and so does the study")
    read_seconds = time.perf_counter() - t0

    # loads.csv
    rows: list[str] = ["case,grid,component,value"]
    cases: list[str] = []
    initial = _initial_temperatures(cc)
    if initial is not None and not any(tsid is not None for _, _, tsid, _ in selected):
        notes.append(f"TEMPERATURE(INITIAL) = {initial}: no effect, no imported case has a thermal load")
    applied = []
    spcd: dict[str, dict] = {}
    for label, sid, tsid, where in selected:
        values = loads.resolve(sid, deck, where=where) if sid is not None else {}
        spcd[label] = loads.enforced(sid) if sid is not None else {}
        if tsid is not None:
            for dof, v in loads.resolve_thermal(tsid, deck, where=where, initial=initial).items():
                values[dof] = values.get(dof, 0.0) + v
        moved = any(d != 0.0 for d, _ in spcd[label].values()) or any(
            d != 0.0 and (dof not in spcd[label]) for dof, (d, _, _) in spc_values.items())
        if not any(v != 0.0 for v in values.values()) and not moved:
            what = " and ".join(([f"load set {sid}"] if sid is not None else []) +
                                ([f"temperature set {tsid}"] if tsid is not None else []))
            notes.append(f"case {label}: {what} sums to zero at every DOF: not imported")
            continue
        applied.append((label, values))
    # the handles' MPCs in a set of their own (a study applies every MPC set of model.bdf)
    plan = enforced.plan(deck, kept, {label: spcd[label] for label, _ in applied}, spc_values,
                         max(mpc_sets, default=0) + 1)
    if plan is not None:
        if inrel == -1:
            raise DeckFormatError("enforced displacements (SPCD, SPC with a value) with inertia relief "
                                  "(PARAM,INREL,-1) are not imported", file=str(path))
        for label, values in applied:
            for dof, f in plan.loads[label].items():
                values[dof] = values.get(dof, 0.0) + f
        drop_cards += list(plan.drop)
        notes.append(plan.note)
    if inrel == -1 and applied:
        applied = _relieved(applied, deck, cards, inrel_cards[-1], notes)
    for label, values in applied:
        cases.append(label)
        rows += [f"{label},{g},{comp},{v!r}" for (g, comp), v in sorted(values.items()) if v != 0.0]
    if not cases:
        raise DeckFormatError("every selected load set is zero: nothing to import", file=str(path))

    # joints
    parsed = [parse_joint(j) for j in joints]
    if parsed:
        _check_joints(parsed, deck)

    # the notes: what was read, dropped and skipped, once per kind
    notes.insert(0, f"read {path.name}: {_plural(len(cards), 'bulk card')} in {_plural(len(files), 'file')}; "
                    f"{_plural(len(cases), 'case')} ({', '.join(cases[:12])}{' ...' if len(cases) > 12 else ''})")
    if cc is not None:
        ex = [w if w != "SOL" else f"SOL {cc.sol}" for w in dict.fromkeys(cc.executive)]
        notes.append(f"skipped the executive control ({', '.join(ex)})")
        if cc.sol and _sol_key(cc.sol) not in _STATIC_SOLS:
            taken = ", ".join(f"{label} (" + " and ".join(
                ([f"LOAD = {sid}"] if sid is not None else []) +
                ([f"TEMPERATURE(LOAD) = {tsid}"] if tsid is not None else [])) + ")"
                for label, sid, tsid, _ in selected if label in cases)
            notes.append(f"note: the deck's own solution is {_sol_text(cc.sol)}, not linear statics: "
                         f"imported its structure and, as linear static load cases, the load sets "
                         f"its subcases select: {taken}; the deck's own results are not these")
        titles = [t for t in ("TITLE", "SUBTITLE", "LABEL")
                  if any(getattr(s, t.lower()) for s in cc.subcases)]
        kinds = [(kind, names) for kind, names in cc.skipped.items()]
        if titles:
            kinds.insert(0, ("title lines", tuple(titles)))
        if kinds:
            n = sum(len(names) for _, names in kinds)
            notes.append(f"skipped {_plural(n, 'case-control command')} with no effect on a linear "
                         f"static solution: " + "; ".join(f"{kind} ({', '.join(names)})"
                                                         for kind, names in kinds))
        if cc.autospc is not None and cc.autospc[0] == "NO":
            notes.append(f"AUTOSPC = NO at {path}:{cc.autospc[1]}: written into model.bdf as "
                         f"PARAM,AUTOSPC,NO (a singular DOF is then an error, not constrained)")
    counts = Counter(c.name for c in load_cards)
    if counts:
        notes.append(f"dropped {_plural(len(load_cards), 'load card')} from model.bdf "
                     f"({', '.join(f'{n} x{k}' for n, k in counts.items())}): the selected sets are in loads.csv")
    if cut:
        notes.append(f"ignored the text beyond column 80 of {_plural(cut, 'fixed-field line')} "
                     f"(a card image ends at column 80)")
    if debug:
        notes.append(f"dropped {_plural(len(debug), 'DEBUG card')} (MYSTRAN debug printout, no effect on the solution)")
    if design_cards:
        kinds = ", ".join(f"{n} x{k}" for n, k in Counter(c.name for c in design_cards).items())
        if design_dropped:
            notes.append(f"dropped the design model ({kinds}) from model.bdf: the deck's solution is "
                         f"{_sol_text(cc.sol)}, which does not read it (only SOL 200 does)")
        else:
            what = ("; designed: " + ", ".join(f"{k[0]} {k[1]}" for k in deck.designed)
                    if deck.designed else "; it designs no stiffness (masses, damping only)")
            notes.append(f"read the design model ({kinds}): the study is the deck's analysis at the "
                         f"initial design, the designed values at the DESVAR initial values (XINIT)"
                         f"{what}")
    if deck.no_effect:
        notes.append("accepted with no effect on a linear static solution (kept in model.bdf, never "
                     "a reason for another adapter): " + ", ".join(
                         f"{n} x{k}" for n, (k, _) in sorted(deck.no_effect.items())))
    notes += [f"note: {n}" for n in deck.notes]

    model_lines = [f"$ Bulk data of {path.name}, made by `blackbox import`: load cards removed (the "
                   f"load cases are in loads.csv),", "$ only the constraint sets the case control "
                   "selects kept, INCLUDEs inlined. The rest is as the deck wrote it.", "$"]
    lines = text.removeprefix("\ufeff").splitlines()
    start = 0
    if cc is not None:
        start = bulk_start(lines)[1] + 1
    bulk = source.bulk
    dropped = bulk.lines_of(drop_cards)
    kept_lines = bulk.lines_of([c for c in kept if c.file != str(path)]) if len(files) > 1 else {}
    if cc is not None and cc.autospc is not None and cc.autospc[0] == "NO":
        model_lines += ["$ AUTOSPC = NO of the case control:", "PARAM,AUTOSPC,NO"]
    for shown, (_, numbers) in bulk.expanded.items():
        _one_fate_per_line(shown, numbers, dropped.get(shown, set()),
                           bulk.lines_of([c for c in kept if c.file == shown]).get(shown, set()))
    _model_body(lines, str(path), start, bulk, kept_lines, dropped, model_lines)
    if plan is not None:
        model_lines += plan.lines
    model_lines.append("ENDDATA")

    name = re.sub(r"[^A-Za-z0-9_.-]+", "_", path.stem) or "imported"
    toml = _study_toml(name, path, cases, parsed, deck)
    return ImportResult(path, "\n".join(model_lines) + "\n", "\n".join(rows) + "\n", toml, tuple(cases),
                        deck, tuple(notes), len(cards), read_seconds, tuple(parsed))
