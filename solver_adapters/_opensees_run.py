"""Run one OpenSees deck written by ``solver_adapters.opensees``: ``python _opensees_run.py DECK``.

A program of its own (started as a subprocess by the ``opensees`` adapter, imports nothing of
this project): it reads the deck, builds the model in openseespy, runs one linear static
analysis per load case and writes ``displacements.out`` beside the deck.

The deck is OpenSees commands in Tcl syntax, one per line (``#`` starts a comment line), in three
parts: the model (``model``, ``node``, ``fix``, ``geomTransf``, ``uniaxialMaterial``, ``element``,
``equalDOF``, ``equalDOF_Mixed``, ``rigidLink``), then the load cases (``case NAME`` followed by
its ``load NODE F1 F2 F3 M1 M2 M3`` lines), and ``output NODE ...`` (the nodes to report). Only
those commands are accepted: a deck cannot make this program do anything else.

Load cases: each case has its own load pattern with a ``Path`` time series that is 1 at the
case's time step and 0 at every other, all defined before the first analysis; the model is never
changed between cases (no pattern removed or added, which would re-number and re-factor), and
``reset()`` returns it to the undeformed state before each case, so a case's answer never carries
forces (of springs, of elements) over from the case before. ``algorithm Linear -factorOnce``
factors the stiffness once for all cases.

Failures OpenSees itself does not report. A singular stiffness (a mechanism, a missing support)
makes UMFPACK fail only when a pivot is exactly zero; a pivot that is zero up to rounding gives
displacements of 1e8 and more and ``analyze`` returns 0. So every case is checked for
equilibrium: the element forces minus the applied loads at every node, with the forces of the
ties (``equalDOF``, ``rigidLink``) carried to their retained nodes and the supports' reactions
left out, must vanish. For a solve of condition number kappa the residual is about
``1e-16 kappa`` of the load; a mechanism's is of the order of the load itself. Above
``RESIDUAL_TOL`` (kappa ~ 1e10, where the reference solver's pivot test also stops) the run ends
with a ``*** SINGULAR STIFFNESS`` line naming the node and component and exit code 3.

Exit codes: 0 done; 2 the deck cannot be read; 3 singular stiffness; 4 OpenSees failed
otherwise; 5 openseespy is not installed.
"""

from __future__ import annotations

import os
import sys

# run as a script from inside the package folder: its modules (subprocess.py, ...) must not
# shadow the standard library's
if sys.path and os.path.abspath(sys.path[0] or ".") == os.path.dirname(os.path.abspath(__file__)):
    del sys.path[0]

import math
import time
from pathlib import Path

RESIDUAL_TOL = 1e-6
"""Largest equilibrium residual accepted, relative to the case's largest load (moments divided
by the model's size); see the module docstring."""

MODEL_COMMANDS = {"model", "node", "fix", "geomTransf", "uniaxialMaterial", "element", "equalDOF",
                  "equalDOF_Mixed", "rigidLink"}


def _value(word: str):
    try:
        return int(word)
    except ValueError:
        pass
    try:
        return float(word)
    except ValueError:
        return word


def read_deck(path: Path):
    """``(model commands, cases [(name, [(node, six loads)])], output nodes)``; ``ValueError``
    with the line number for anything else."""
    model, cases, output = [], [], []
    for n, raw in enumerate(path.read_text().splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        words = line.split()
        cmd, args = words[0], [_value(w) for w in words[1:]]
        if cmd == "case":
            cases.append((" ".join(words[1:]), []))
        elif cmd == "load":
            if not cases or len(args) != 7 or not isinstance(args[0], int):
                raise ValueError(f"line {n}: 'load NODE six values' inside a case expected: {line!r}")
            cases[-1][1].append((args[0], [float(v) for v in args[1:]]))
        elif cmd == "output":
            if not all(isinstance(a, int) for a in args):
                raise ValueError(f"line {n}: output takes node numbers: {line!r}")
            output += args
        elif cmd in MODEL_COMMANDS:
            if cases:
                raise ValueError(f"line {n}: model command {cmd!r} after the first case")
            model.append((n, cmd, args))
        else:
            raise ValueError(f"line {n}: command {cmd!r} is not accepted in a blackbox OpenSees deck")
    return model, cases, output


class Ties:
    """What the equilibrium check needs to know of the model: node positions, supported
    components and the ties, recorded while the model commands run."""

    def __init__(self):
        self.xyz: dict[int, tuple[float, float, float]] = {}
        self.fixed: dict[int, set[int]] = {}
        self.mp: list[tuple[str, int, int, list[tuple[int, int]]]] = []  # kind, retained, constrained, dof pairs

    def record(self, cmd: str, args: list) -> None:
        if cmd == "node":
            self.xyz[args[0]] = tuple(float(v) for v in args[1:4])
        elif cmd == "fix":
            self.fixed.setdefault(args[0], set()).update(i for i, f in enumerate(args[1:7], 1) if f)
        elif cmd == "equalDOF":
            self.mp.append(("equal", args[0], args[1], [(d, d) for d in args[2:]]))
        elif cmd == "equalDOF_Mixed":
            r, c, k = args[0], args[1], args[2]
            self.mp.append(("equal", r, c, [(args[3 + 2 * i], args[4 + 2 * i]) for i in range(k)]))
        elif cmd == "rigidLink":
            self.mp.append(("rigid", args[1], args[2], [(d, d) for d in range(1, 7)]))

    def handler(self) -> str:
        """``Transformation`` (exact, keeps the matrix positive definite) unless a tied node is
        retained by another tie or supported: OpenSees's transformation handler then solves
        another structure without a word (a chain of ties is not followed through), and
        ``Lagrange`` multipliers are used instead (exact too; supported components are then zero
        up to rounding, and are reported as the exact zero the support makes them)."""
        constrained = {c for _, _, c, _ in self.mp}
        retained = {r for _, r, _, _ in self.mp}
        return "Lagrange" if constrained & (retained | set(self.fixed)) else "Transformation"

    def order(self) -> list:
        """The ties, those whose constrained node lies deepest in a chain first (its forces are
        carried to a retained node that may itself be tied to another)."""
        parent = {c: r for _, r, c, _ in self.mp}

        def depth(node: int, seen=()) -> int:
            if node not in parent or node in seen:
                return 0
            return 1 + depth(parent[node], (*seen, node))

        return sorted(self.mp, key=lambda t: -depth(t[2]))

    def residual(self, ops, scale_length: float) -> tuple[float, int, int]:
        """Largest equilibrium residual (forces, and moments / ``scale_length``) at a component
        that is not supported, after the ties' forces went to their retained nodes; with its
        node and component."""
        ops.reactions()
        r = {n: list(ops.nodeReaction(n)) for n in self.xyz}
        for kind, ret, con, pairs in self.order():
            rc, rr = r[con], r[ret]
            if kind == "rigid":
                arm = [a - b for a, b in zip(self.xyz[con], self.xyz[ret])]
                f = rc[:3]
                moment = (arm[1] * f[2] - arm[2] * f[1], arm[2] * f[0] - arm[0] * f[2], arm[0] * f[1] - arm[1] * f[0])
                for i in range(3):
                    rr[i] += f[i]
                    rr[3 + i] += rc[3 + i] + moment[i]
                for i in range(6):
                    rc[i] = 0.0
            else:
                for dr, dc in pairs:
                    rr[dr - 1] += rc[dc - 1]
                    rc[dc - 1] = 0.0
        worst, where = 0.0, (0, 0)
        for n, row in r.items():
            fixed = self.fixed.get(n, ())
            for i, v in enumerate(row, 1):
                if i in fixed:
                    continue
                size = abs(v) / (scale_length if i > 3 else 1.0)
                if size > worst:
                    worst, where = size, (n, i)
        return worst, *where


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        print("usage: _opensees_run.py DECK", file=sys.stderr)
        return 2
    deck = Path(argv[0])
    try:
        model, cases, output = read_deck(deck)
    except (OSError, ValueError) as exc:
        print(f"*** ERROR: {deck}: {exc}")
        return 2
    try:
        import openseespy.opensees as ops
    except ImportError as exc:
        print(f"*** ERROR: openseespy cannot be imported ({exc}); install it with: pip install "
              f"--ignore-requires-python --no-deps openseespy openseespylinux")
        return 5
    t0 = time.perf_counter()
    print(f"OpenSees {ops.version()} (openseespy) run of {deck.name}: {len(model)} model commands, "
          f"{len(cases)} load case(s), {len(output)} output node(s)", flush=True)
    ties = Ties()
    ops.wipe()
    for n, cmd, args in model:
        try:
            refused = getattr(ops, cmd)(*args) not in (None, 0)
        except Exception as exc:  # noqa: BLE001 - openseespy raises its own error type
            refused = f"{type(exc).__name__}: {exc}"
        if refused:                                   # OpenSees's own message is on stderr
            print(f"*** ERROR: deck line {n}: OpenSees refused {cmd} {' '.join(map(str, args))}"
                  + (f" ({refused})" if isinstance(refused, str) else ""))
            return 2
        ties.record(cmd, args)
    missing = sorted(set(output) - set(ties.xyz))
    if missing:
        print(f"*** ERROR: output nodes not in the model: {missing[:10]}")
        return 2
    xs = list(ties.xyz.values()) or [(0.0, 0.0, 0.0)]
    size = max(max(p[i] for p in xs) - min(p[i] for p in xs) for i in range(3)) or 1.0
    for j, (_, loads) in enumerate(cases, 1):     # case j is loaded at time j only
        ops.timeSeries("Path", j, "-time", j - 1.0, float(j), j + 1.0, "-values", 0.0, 1.0, 0.0)
        ops.pattern("Plain", j, j)
        for node, values in loads:
            ops.load(node, *values)
    handler = ties.handler()
    ops.constraints(handler)
    print(f"constraint handler {handler}", flush=True)
    ops.numberer("RCM")
    ops.system("UmfPack")
    ops.algorithm("Linear", "-factorOnce")
    ops.integrator("LoadControl", 1.0)
    ops.analysis("Static")
    out = [f"OPENSEES DISPLACEMENTS {len(cases)} {len(output)}"]
    for j, (name, loads) in enumerate(cases, 1):
        ops.reset()                                   # undeformed, no force left from the case before
        ops.setTime(j - 1.0)
        code = ops.analyze(1)
        if code != 0:
            if code == -3:
                print(f"*** SINGULAR STIFFNESS: the factorization failed in case {j} ({name}), "
                      f"analyze returned {code}")
                return 3
            print(f"*** ERROR: the analysis of case {j} ({name}) failed, analyze returned {code}")
            return 4
        scale = max([abs(v) for _, vs in loads for v in vs[:3]]
                    + [abs(v) / size for _, vs in loads for v in vs[3:]] + [0.0])
        if scale > 0:
            worst, node, comp = ties.residual(ops, size)
            rel = worst / scale
            print(f"case {j} ({name}): equilibrium residual {rel:.3g} of the largest load", flush=True)
            if not rel <= RESIDUAL_TOL:
                print(f"*** SINGULAR STIFFNESS AT NODE {node} COMPONENT {comp}: case {j} ({name}) is "
                      f"out of equilibrium by {rel:.3g} of its largest load there (above {RESIDUAL_TOL:g}): "
                      f"a mechanism or a missing support")
                return 3
        out.append(f"case {j}")
        for node in output:
            u = list(ops.nodeDisp(node))
            for i in ties.fixed.get(node, ()):
                u[i - 1] = 0.0
            if not all(math.isfinite(v) for v in u):
                print(f"*** ERROR: non-finite displacement at node {node} in case {j}")
                return 4
            out.append(f"{node} " + " ".join(repr(float(v)) for v in u))
    out.append("END")
    (deck.parent / "displacements.out").write_text("\n".join(out) + "\n")
    print(f"NORMAL END: {len(cases)} case(s) in {time.perf_counter() - t0:.3f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
