"""OpenSees (openseespy) as an external code: ``adapter = "opensees"``.

The first non-NASTRAN code shipped: the parsed model is written as a deck of OpenSees commands
(Tcl syntax, one per line) and run by :mod:`solver_adapters._opensees_run`, a program of its own
started as a subprocess by the generic :class:`~solver_adapters.subprocess.CommandAdapter`
(timeout, process tree, run folders, consent and counters are its job). Install::

    pip install --ignore-requires-python --no-deps openseespy openseespylinux

(openseespy 3.8 declares ``Requires-Python >= 3.12`` but runs on 3.11; ``--no-deps`` keeps pip
from choosing dependency versions for another Python.)

What is written, card by card (``docs/plugin.md`` has the table):

* GRID: ``node`` at its basic position. Loads, results, SPCs and springs are in the grid's CD
  system: loads and results are rotated here; OpenSees's ``fix`` acts on basic components, so a
  support in a rotated CD system is expressible only when it holds all three translations or
  rotations (or none).
* CBAR/CBEAM: ``elasticBeamColumn`` (``ElasticTimoshenkoBeam`` with PBAR K1/K2) with a ``Linear``
  ``geomTransf`` whose ``vecxz`` is local z = x cross v, so local y is NASTRAN's plane 1 (I1 = Iz,
  I2 = Iy); offsets WA/WB as ``-jntOffset`` (basic components, as OpenSees takes them); pin
  flags 5 and 6 as ``-releasey``/``-releasez``, 1 and 4 (no axial force, no torque: the element
  carries none) as A = 0, J = 0. Flags 2 and 3 (shear releases) are not expressible.
* CROD/CONROD: ``elasticBeamColumn`` with Iy = Iz = 0 (axial EA/L and torsion GJ/L only).
* RBE2: ``rigidLink beam`` for CM = 123456, ``equalDOF`` between coincident grids or for
  rotations only; CM with some translations of a grid away from GN is not expressible (OpenSees
  ties such components only as equal, not as a rigid arm).
* CELAS1/CELAS2 and the method's extra springs: ``zeroLength`` with an ``Elastic`` material;
  grounded on a fixed node of its own; between two different components through an auxiliary
  node tied by ``equalDOF_Mixed``. CBUSH: ``zeroLength`` with six materials along its axes
  (coincident GA and GB, or grounded).
* Not expressible, refused: RBE3 (no weighted-average constraint in OpenSees), PBAR I12 (no
  product of inertia), CBUSH between grids apart (no spring point with rigid arms), and the
  cases above. OpenSees has no AUTOSPC: a component without stiffness is a mechanism
  (:class:`UnstableStructureError`), where NASTRAN and the reference solver constrain it.

Everything refused is refused before anything runs, every feature at once with its card and
location (:class:`UnsupportedFeatureError`, a bad-input error: exit 2). A singular stiffness,
which OpenSees often solves silently into 1e8-sized displacements, is caught by the runner's
equilibrium check and raised as :class:`UnstableStructureError` (see ``_opensees_run``).
"""

from __future__ import annotations

import importlib.util
import os
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from solver_adapters.protocol import (DofLabel, LoadMatrix, PluginLoadError, ScalarSpring, SolverRunError,
                                      UnstableStructureError, UnsupportedFeatureError)
from solver_adapters.subprocess import BaseDeck, CommandAdapter, RunRecord

RUNNER = Path(__file__).resolve().with_name("_opensees_run.py")
INSTALL = "pip install --ignore-requires-python --no-deps openseespy openseespylinux"
RESULTS = "displacements.out"

_SINGULAR = re.compile(r"\*\*\* SINGULAR STIFFNESS(?: AT NODE (\d+) COMPONENT (\d))?")
_TOL = 1e-12      # geometry: coincident grids, a frame equal to the basic axes, parallel directions


def _num(x: float) -> str:
    """A real exactly as it round-trips (``repr``); integers stay integers for tags."""
    return repr(float(x))


def _unit(v) -> np.ndarray:
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def _perpendicular(x: np.ndarray) -> np.ndarray:
    """A unit vector perpendicular to ``x`` (the basic axis least aligned with it, projected)."""
    e = np.eye(3)[int(np.argmin(np.abs(x)))]
    return _unit(e - (e @ x) * x)


@dataclass
class _Deck:
    """An OpenSees deck being written: the command lines and the tags handed out so far."""

    lines: list[str] = field(default_factory=list)
    next_node: int = 1
    next_elem: int = 1
    next_mat: int = 1
    next_transf: int = 1

    def add(self, *words) -> None:
        self.lines.append(" ".join(str(w) for w in words))

    def node(self, xyz, fixed: str = "") -> int:
        tag = self.next_node
        self.next_node += 1
        self.add("node", tag, *map(_num, xyz))
        if fixed:
            self.add("fix", tag, *[1 if str(c) in fixed else 0 for c in range(1, 7)])
        return tag

    def material(self, k: float) -> int:
        tag = self.next_mat
        self.next_mat += 1
        self.add("uniaxialMaterial", "Elastic", tag, _num(k))
        return tag

    def element(self, *words) -> int:
        tag = self.next_elem
        self.next_elem += 1
        self.add("element", words[0], tag, *words[1:])
        return tag

    def transf(self, vecxz, offsets=None) -> int:
        tag = self.next_transf
        self.next_transf += 1
        extra = ["-jntOffset", *map(_num, offsets)] if offsets is not None else []
        self.add("geomTransf", "Linear", tag, *map(_num, vecxz), *extra)
        return tag


class Translation:
    """The model (a parsed :class:`~solver_adapters.deck.Deck`) as OpenSees commands, or the list
    of what OpenSees cannot express (:attr:`refused`: ``(card, where, why)``).

    ``frames[g]``: rows are grid ``g``'s component directions in basic (identity for CD 0)."""

    def __init__(self, model):
        self.model = model
        self.grids = sorted(model.grids)
        self.xyz = {g: np.array(model.grids[g].xyz, float) for g in self.grids}
        self.frames = dict(zip(self.grids, model.displacement_frames(self.grids))) if self.grids else {}
        self.refused: list[tuple[str, str, str]] = []
        self.deck = _Deck(next_node=max(self.grids, default=0) + 1)
        self._model_lines()

    # ---- helpers ------------------------------------------------------------------------------
    def refuse(self, card: str, where: str, why: str) -> None:
        self.refused.append((card, where, why))

    def rotated(self, g: int) -> bool:
        return not np.allclose(self.frames[g], np.eye(3), rtol=0.0, atol=_TOL)

    def coincident(self, a: int, b: int) -> bool:
        scale = max(1.0, float(np.max(np.abs(self.xyz[a]))), float(np.max(np.abs(self.xyz[b]))))
        return bool(np.linalg.norm(self.xyz[a] - self.xyz[b]) <= _TOL * scale)

    def direction(self, g: int, c: int) -> np.ndarray:
        """Component ``c`` of grid ``g`` as a basic direction (of a translation or a rotation)."""
        return self.frames[g][(c - 1) % 3]

    # ---- the model ----------------------------------------------------------------------------
    def _model_lines(self) -> None:
        m, d = self.model, self.deck
        d.add("model", "basic", "-ndm", 3, "-ndf", 6)
        for g in self.grids:
            if m.grids[g].scalar:
                self.refuse(f"SPOINT {g}", m.grids[g].src, "a scalar point (one DOF, no position): "
                                                         "an OpenSees node is a point in space")
        for dm in getattr(m, "dmigs", {}).values():
            self.refuse(dm.label, dm.src, "a direct stiffness matrix (K2GG, or a GENEL's): the "
                                          "OpenSees deck has no general matrix element")
        for g in self.grids:
            d.add("node", g, *map(_num, self.xyz[g]))
        self._supports()
        for b in sorted(m.cbars.values(), key=lambda b: b.eid):
            self._bar(b)
        for r in sorted(m.rods.values(), key=lambda r: r.eid):
            self._rod(r)
        for r in sorted(m.rbe2s.values(), key=lambda r: r.eid):
            self._rbe2(r)
        for r in sorted(m.rbe3s.values(), key=lambda r: r.eid):
            self.refuse(f"{r.card} {r.eid}", r.src, "OpenSees has no weighted-average (interpolation) constraint")
        for c in getattr(m, "mpcs", ()):
            self.refuse(f"MPC {c.sid}", c.src, "the OpenSees deck ties rigid links only, not a general "
                                               "linear equation")
        for s in sorted(m.springs.values(), key=lambda s: s.eid):
            self.spring((s.g1, s.c1), (s.g2, s.c2) if s.g2 else None, m.spring_stiffness(s),
                        f"{s.card} {s.eid}", s.src)
        for b in sorted(m.bushes.values(), key=lambda b: b.eid):
            self._bush(b)
        for e in sorted(getattr(m, "gaps", {}).values(), key=lambda e: e.eid):
            self.refuse(f"CGAP {e.eid}", e.src, "the OpenSees deck has no gap element (the reference "
                                                "adapter models its linear stiffness)")

    def _supports(self) -> None:
        fixed: dict[int, set[str]] = {}
        source: dict[int, tuple[str, str]] = {}
        for g in self.grids:
            if self.model.grids[g].ps:
                fixed.setdefault(g, set()).update(self.model.grids[g].ps)
                source.setdefault(g, (f"GRID {g} PS", self.model.grids[g].src))
        for s in self.model.spc1s:
            for g in s.grids:
                fixed.setdefault(g, set()).update(s.components)
                source.setdefault(g, (f"SPC1 {s.sid}", s.src))
        for g, comps in sorted(fixed.items()):
            if g not in self.model.grids:
                continue          # the reader's validation names it
            if self.rotated(g):
                for part in ("123", "456"):
                    held = set(part) & comps
                    if held and held != set(part):
                        card, src = source[g]
                        self.refuse(card, src, f"components {''.join(sorted(held))} of GRID {g} are in its "
                                               f"rotated CD system {self.model.grids[g].cd}; OpenSees supports "
                                               f"only basic components (all three or none can be held)")
            self.deck.add("fix", g, *[1 if str(c) in comps else 0 for c in range(1, 7)])

    def _bar(self, b) -> None:
        m, d = self.model, self.deck
        card = f"{b.card} {b.eid}"
        p = m.pbars[b.pid]
        mat = m.mat1s[p.mid]
        xa = self.xyz[b.ga] + (np.array(b.wa) if b.wa is not None else 0.0)
        xb = self.xyz[b.gb] + (np.array(b.wb) if b.wb is not None else 0.0)
        v = np.array(b.x, float) if b.g0 is None else self.xyz[b.g0] - self.xyz[b.ga]
        ex = _unit(xb - xa)
        vecxz = np.cross(ex, v)                    # NASTRAN's local z: OpenSees's y is then NASTRAN's y
        if p.i12:
            self.refuse(f"{p.card} {p.pid}", p.src, f"product of inertia I12 = {p.i12:g} (used by {card}): "
                                                    f"OpenSees's elastic beams have none")
        if getattr(p, "taper", None) is not None:
            self.refuse(f"{p.card} {p.pid}", p.src, f"a tapered section (used by {card}): OpenSees's elastic "
                                                    f"beams are prismatic")
        if getattr(p, "n1", 0.0) or getattr(p, "n2", 0.0):
            self.refuse(f"{p.card} {p.pid}", p.src, f"neutral axis offset N1/N2 = {p.n1:g}/{p.n2:g} (used by "
                                                    f"{card}): OpenSees's elastic beams have their axis on the "
                                                    f"shear centre")
        pins = set(b.pa) | set(b.pb)
        shear = p.k1 is not None or p.k2 is not None
        if pins & set("23"):
            self.refuse(card, b.src, f"pin flag(s) {''.join(sorted(pins & set('23')))} (a shear release): "
                                     f"OpenSees's elastic beams release only moments")
        if shear and pins:
            self.refuse(card, b.src, "pin flags on a beam with shear flexibility (PBAR K1/K2): OpenSees's "
                                     "Timoshenko beam has no releases")
        offsets = None
        if b.wa is not None or b.wb is not None:
            offsets = [*(b.wa or (0.0, 0.0, 0.0)), *(b.wb or (0.0, 0.0, 0.0))]
        d.add(f"# {card} ({b.src})" if b.src else f"# {card}")
        t = d.transf(vecxz, offsets)
        a, j = p.a * ("1" not in pins), p.j * ("4" not in pins)
        if shear:
            big = 1e100 * p.a              # K blank: no shear flexibility (phi = 1e-100, exactly 0 in 1 + phi)
            avy = p.k1 * p.a if p.k1 is not None else big
            avz = p.k2 * p.a if p.k2 is not None else big
            d.element("ElasticTimoshenkoBeam", b.ga, b.gb, _num(mat.e), _num(mat.g), _num(p.a), _num(p.j),
                      _num(p.i2), _num(p.i1), _num(avy), _num(avz), t)
            return
        release = []
        for flag, option in (("5", "-releasey"), ("6", "-releasez")):
            code = (flag in b.pa) + 2 * (flag in b.pb)
            if code:
                release += [option, code]
        d.element("elasticBeamColumn", b.ga, b.gb, _num(a), _num(mat.e), _num(mat.g), _num(j),
                  _num(p.i2), _num(p.i1), t, *release)

    def _rod(self, r) -> None:
        mid, a, j = self.model.rod_section(r)
        mat = self.model.mat1s[mid]
        ex = _unit(self.xyz[r.gb] - self.xyz[r.ga])
        self.deck.add(f"# {r.card} {r.eid} ({r.src})" if r.src else f"# {r.card} {r.eid}")
        t = self.deck.transf(_perpendicular(ex))
        self.deck.element("elasticBeamColumn", r.ga, r.gb, _num(a), _num(mat.e), _num(mat.g), _num(j),
                          0.0, 0.0, t)

    def _rbe2(self, r) -> None:
        card = f"{r.card} {r.eid}"
        cm = "".join(sorted(set(r.cm)))
        for gm in r.gm:
            if cm == "123456":
                self.deck.add("rigidLink", "beam", r.gn, gm)
                continue
            if self.rotated(gm) and any(set(part) & set(cm) not in (set(), set(part)) for part in ("123", "456")):
                self.refuse(card, r.src, f"components {cm} of dependent GRID {gm} are in its rotated CD system "
                                         f"{self.model.grids[gm].cd}; OpenSees ties basic components only")
                continue
            if set(cm) & set("123") and not self.coincident(r.gn, gm):
                self.refuse(card, r.src, f"CM = {cm} ties translations of GRID {gm}, away from GN {r.gn}, "
                                         f"without all rotations: OpenSees ties such components only as "
                                         f"equal (equalDOF), not through a rigid arm (only rigidLink beam, CM = 123456)")
                continue
            self.deck.add("equalDOF", r.gn, gm, *cm)

    def spring(self, a: DofLabel, b: DofLabel | None, k: float, card: str, src: str = "") -> None:
        """A scalar spring of stiffness ``k`` between components ``a`` and ``b`` (None: ground)."""
        d = self.deck
        ga, ca = a
        ea = self.direction(ga, ca)
        rot = ca > 3
        if b is not None and (b[1] > 3) != rot:
            self.refuse(card, src, f"a spring between a translation {a} and a rotation {b}: no OpenSees "
                                   f"element couples a force to a rotation this way")
            return
        if b is None:                                 # to ground: a fixed node of its own
            other = d.node(self.xyz[ga], "123456")
            self._zero_length(ga, other, ea, rot, k)
            return
        gb, cb = b
        eb = self.direction(gb, cb)
        if np.allclose(ea, eb, rtol=0.0, atol=1e-9):  # along one direction: a zeroLength between them
            self._zero_length(ga, gb, ea, rot, k)
            return
        ia, ib = self._axis(ea), self._axis(eb)
        if ia is None or ib is None:
            self.refuse(card, src, f"a spring between components {a} and {b} whose directions (in their CD "
                                   f"systems) are neither equal nor both along basic axes")
            return
        # different basic components: an auxiliary node at GA whose component ia follows
        # component ib of GB (equalDOF_Mixed), every other component held, and the spring on it
        dof_a, dof_b = ia + 3 * rot, ib + 3 * rot
        aux = d.node(self.xyz[ga], "".join(str(c) for c in range(1, 7) if c != dof_a))
        d.add("equalDOF_Mixed", gb, aux, 1, dof_b, dof_a)
        mat = d.material(k)
        d.element("zeroLength", ga, aux, "-mat", mat, "-dir", dof_a)

    @staticmethod
    def _axis(e: np.ndarray) -> int | None:
        """1, 2 or 3 when ``e`` is that positive basic axis, else None."""
        i = int(np.argmax(np.abs(e)))
        return i + 1 if abs(e[i] - 1.0) <= 1e-9 else None

    def _zero_length(self, a: int, b: int, direction: np.ndarray, rot: bool, k: float) -> None:
        x = _unit(direction)
        y = _perpendicular(x)
        mat = self.deck.material(k)
        self.deck.element("zeroLength", a, b, "-mat", mat, "-dir", 4 if rot else 1,
                          "-orient", *map(_num, x), *map(_num, y))

    def _bush(self, b) -> None:
        card = f"CBUSH {b.eid}"
        if getattr(b, "offset", None) is not None and any(b.offset):
            self.refuse(card, b.src, "spring point offset from GA (OCID, S1-S3): OpenSees's zeroLength "
                                     "has no spring point reached by rigid arms")
            return
        if b.gb and not self.coincident(b.ga, b.gb):
            self.refuse(card, b.src, f"GA {b.ga} and GB {b.gb} apart: OpenSees's zeroLength has no spring "
                                     f"point reached by rigid arms")
            return
        if b.cid is None:
            self.refuse(card, b.src, "coincident GA and GB need CID for the element axes")
            return
        axes = np.eye(3) if b.cid == 0 else self.model.coords[b.cid].frames_at(self.xyz[b.ga][None, :])[0]
        k = self.model.pbushes[b.pid].k
        mats, dirs = [], []
        for i, ki in enumerate(k, 1):
            if ki:
                mats.append(self.deck.material(ki))
                dirs.append(i)
        if not mats:
            return
        other = b.gb or self.deck.node(self.xyz[b.ga], "123456")
        self.deck.element("zeroLength", b.ga, other, "-mat", *mats, "-dir", *dirs,
                          "-orient", *map(_num, axes[0]), *map(_num, axes[1]))

    # ---- a run --------------------------------------------------------------------------------
    def with_springs(self, springs: Sequence[ScalarSpring]) -> _Deck:
        """The model's deck with the method's extra ``springs`` added (a copy);
        :class:`UnsupportedFeatureError` naming the springs OpenSees cannot express."""
        base = self.deck
        d = _Deck(list(base.lines), base.next_node, base.next_elem, base.next_mat, base.next_transf)
        saved, self.deck, self.refused = (self.deck, self.refused), d, []
        try:
            for s in springs:
                where = f"{s.b[0]}:{s.b[1]}" if s.b is not None else "ground"
                self.spring(s.a, s.b, s.k, f"spring {s.a[0]}:{s.a[1]}-{where}")
            if self.refused:
                raise UnsupportedFeatureError("OpenSees", self.refused)
        finally:
            self.deck, self.refused = saved
        return d

    def run_deck(self, loads: LoadMatrix, report: Sequence[DofLabel], springs: Sequence[ScalarSpring]) -> str:
        """The whole deck for one run: the model, ``springs``, one case per column of ``loads``
        (rotated from the grids' CD systems to basic) and the output nodes."""
        d = self.with_springs(springs)
        coo = loads.values.tocoo()
        per_case: list[dict[int, np.ndarray]] = [{} for _ in range(loads.n_cases)]
        for i, j, v in zip(coo.row, coo.col, coo.data):
            g, c = loads.dofs[i]
            vec = per_case[j].setdefault(g, np.zeros(6))
            vec[3 * (c > 3):3 * (c > 3) + 3] += v * self.direction(g, c)
        for j, name in enumerate(loads.cases):
            d.add("case", _safe(name))
            for g in sorted(per_case[j]):
                if np.any(per_case[j][g]):
                    d.add("load", g, *map(_num, per_case[j][g]))
        grids = sorted({g for g, _ in report})
        for k in range(0, len(grids), 16):
            d.add("output", *grids[k:k + 16])
        return "\n".join(d.lines) + "\n"


def _safe(name: str) -> str:
    text = "".join(ch if ch.isascii() and ch.isprintable() and not ch.isspace() else "_" for ch in str(name))
    return text or "_"


def unsupported_features(model) -> list[tuple[str, str, str]]:
    """What OpenSees cannot express in ``model``: ``(card, where, why)``, in the deck's order."""
    return Translation(model).refused


class OpenSeesDialect:
    """The parsed model in, ``displacements.out`` (written by the runner) out."""

    name = "opensees"

    def __init__(self):
        self._cache: tuple[int, Translation] | None = None

    def command(self, deck_path: Path) -> list[str]:
        """The runner under this Python (installed code: no consent needed); another Python is
        given as the command ``[python, RUNNER, "{deck}"]`` (:class:`OpenSeesAdapter`'s ``python``)."""
        return [sys.executable, str(RUNNER), "{deck}"]

    def translation(self, model) -> Translation:
        if self._cache is None or self._cache[0] != id(model):
            self._cache = (id(model), Translation(model))
        return self._cache[1]

    # ---- refused before anything runs (CommandAdapter calls these) ----------------------------
    def check_model(self, model) -> None:
        refused = self.translation(model).refused
        if refused:
            raise UnsupportedFeatureError("OpenSees", refused, hint="The reference solver and MYSTRAN model "
                                                                    "these cards (adapter = \"reference\" or \"mystran\")")

    def check_springs(self, model, springs: Sequence[ScalarSpring]) -> None:
        self.translation(model).with_springs(springs)     # raises UnsupportedFeatureError

    # ---- one run ------------------------------------------------------------------------------
    def write_deck(self, workdir: Path, base: BaseDeck, loads: LoadMatrix, report: Sequence[DofLabel],
                   springs: Sequence[ScalarSpring]) -> Path:
        self.check_model(base.model)
        text = self.translation(base.model).run_deck(loads, report, springs)
        deck = Path(workdir) / "run.tcl"
        deck.write_text(f"# blackbox run of {base.path.name}: OpenSees commands, run by "
                        f"solver_adapters/_opensees_run.py\n" + text)
        return deck

    def read_results(self, workdir: Path, deck_path: Path, loads: LoadMatrix, report: Sequence[DofLabel],
                     record: RunRecord) -> np.ndarray:
        text = record.stdout_path.read_text(errors="replace")

        def fail(message: str) -> SolverRunError:
            return SolverRunError(f"OpenSees: {message}", returncode=record.returncode, log_tail=record.log_tail())

        if m := _SINGULAR.search(text):
            dofs = [(int(m[1]), int(m[2]))] if m[1] else []
            raise UnstableStructureError(
                "OpenSees: the stiffness is singular (a mechanism, a missing support, or a component "
                "without stiffness, which NASTRAN's AUTOSPC would constrain and OpenSees does not)"
                f"\n--- solver log tail ---\n{record.log_tail()}", dofs)
        if record.returncode == 5:
            raise fail(f"openseespy is not installed for {record.command[0]}; install it into that "
                       f"Python with: {INSTALL}")
        if record.returncode != 0:
            raise fail("the run failed")
        if "NORMAL END" not in text:
            raise fail("no NORMAL END line: the run did not finish")
        path = Path(workdir) / RESULTS
        try:
            rows = path.read_text().splitlines()
        except OSError as exc:
            raise fail(f"no results file {RESULTS}: {exc}") from None
        head = rows[0].split() if rows else []
        grids = sorted({g for g, _ in report})
        if head[:2] != ["OPENSEES", "DISPLACEMENTS"] or rows[-1:] != ["END"] or \
                head[2:] != [str(loads.n_cases), str(len(grids))]:
            raise fail(f"{RESULTS} is not a complete results file for {loads.n_cases} case(s) and "
                       f"{len(grids)} node(s) (header {rows[:1]}, last line {rows[-1:]})")
        blocks: dict[int, dict[int, np.ndarray]] = {}
        table = None
        for n, row in enumerate(rows[1:-1], 2):
            words = row.split()
            if words[:1] == ["case"] and len(words) == 2:
                table = blocks.setdefault(int(words[1]), {})
                continue
            try:
                values = np.array([float(w) for w in words[1:]])
                if table is None or len(values) != 6 or not np.all(np.isfinite(values)):
                    raise ValueError
                table[int(words[0])] = values
            except ValueError:
                raise fail(f"{RESULTS} line {n} cannot be read: {row[:100]!r}") from None
        if sorted(blocks) != list(range(1, loads.n_cases + 1)):
            raise fail(f"{RESULTS} has case blocks {sorted(blocks)[:10]}, expected 1-{loads.n_cases}")
        if self._cache is None:
            raise fail("results read before a deck was written")
        tr = self._cache[1]
        out = np.empty((len(report), loads.n_cases))
        for j in range(loads.n_cases):
            table = blocks[j + 1]
            missing = [g for g in grids if g not in table]
            if missing:
                raise fail(f"case {j + 1} lacks node(s) {missing[:10]}")
            for i, (g, c) in enumerate(report):
                u = table[g][3 * (c > 3):3 * (c > 3) + 3]
                out[i, j] = float(tr.direction(g, c) @ u)
        return out


class OpenSeesAdapter(CommandAdapter):
    """OpenSees through :class:`OpenSeesDialect`: ``OpenSeesAdapter("model.bdf").solve(loads, report)``.

    ``python``: the interpreter that runs the runner, e.g. a virtual environment's
    ``bin/python`` that has openseespy (default: this one, which then must have it). Another
    interpreter is a program like any other: it runs only with the user's consent
    (``trusted`` / ``--trust-command``, or listed in the user's ``trusted_commands``), and as
    named, so a virtual environment's interpreter runs inside its environment. Other keyword
    arguments go to :class:`CommandAdapter` (``keep_failed``, ``workdir_root``, ...). Raises
    :class:`UnsupportedFeatureError` at construction for a deck OpenSees cannot express.
    """

    rtol = 1e-9
    """OpenSees solves in double precision and the runner writes ``repr`` digits; its results
    agree with the reference solver to ~1e-13 on the fixtures (tests/test_opensees.py)."""

    def __init__(self, deck_path: str | os.PathLike, timeout_s: float = 600.0, *,
                 python: str | os.PathLike | None = None, **kw):
        if python is None and importlib.util.find_spec("openseespy") is None:
            raise PluginLoadError(f"adapter 'opensees' needs openseespy in this Python ({sys.executable}); "
                                  f"install it with: {INSTALL}")
        if python is not None:
            kw["command"] = [str(python), str(RUNNER), "{deck}"]
        kw.setdefault("name", "opensees")
        kw.setdefault("dialect", OpenSeesDialect())
        super().__init__(deck_path, timeout_s=timeout_s, **kw)
