"""DEQATN equations evaluated without Python's ``eval``: a small recursive-descent parser of
NASTRAN's FORTRAN-like expressions (MSC QRG DEQATN).

``F(X1, X2, ...) = expression; G = expression; ...``: the arguments of the first statement
are bound in order, each later statement names an intermediate value, and the equation's value
is the last statement's. Expressions: numbers (``1.``, ``2.5E-3``, ``1.D0``), names, ``+ - * /``,
``**`` (right-associative, above unary minus: ``-X**2`` is ``-(X**2)``), parentheses and the
functions of :data:`FUNCTIONS`. Anything else is an :class:`EquationError` saying what.
"""

from __future__ import annotations

import math
import re
from solver_adapters.errors import EquationError

_TOKEN = re.compile(r"\s*(?:(?P<num>(?:\d+\.?\d*|\.\d+)(?:[EeDd][+-]?\d+)?)|(?P<name>[A-Za-z][A-Za-z0-9_]*)"
                    r"|(?P<op>\*\*|[-+*/(),=]))")


def _avg(*a):
    return sum(a) / len(a)


FUNCTIONS = {
    "ABS": (1, abs), "SQRT": (1, math.sqrt), "EXP": (1, math.exp), "LOG": (1, math.log),
    "LOG10": (1, math.log10), "SIN": (1, math.sin), "COS": (1, math.cos), "TAN": (1, math.tan),
    "ASIN": (1, math.asin), "ACOS": (1, math.acos), "ATAN": (1, math.atan),
    "ATAN2": (2, math.atan2), "SINH": (1, math.sinh), "COSH": (1, math.cosh),
    "TANH": (1, math.tanh), "MOD": (2, math.fmod), "DIM": (2, lambda a, b: max(a - b, 0.0)),
    "MIN": (-1, min), "MAX": (-1, max), "SUM": (-1, lambda *a: sum(a)), "AVG": (-1, _avg),
    "SSQ": (-1, lambda *a: sum(x * x for x in a)), "RSS": (-1, lambda *a: math.sqrt(sum(x * x for x in a))),
}
"""Function name -> (number of arguments, -1: one or more; the function)."""




def _tokens(text: str) -> list[tuple[str, str]]:
    out, pos = [], 0
    text = text.rstrip()
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if m is None or m.end() == pos:
            raise EquationError(f"cannot read {text[pos:].strip()[:20]!r}")
        kind = m.lastgroup
        out.append((kind, m.group(kind).upper()))
        pos = m.end()
    return out


class _Parser:
    def __init__(self, tokens: list[tuple[str, str]], env: dict[str, float]) -> None:
        self.t, self.i, self.env = tokens, 0, env

    def peek(self) -> str | None:
        return self.t[self.i][1] if self.i < len(self.t) else None

    def take(self, value: str | None = None) -> tuple[str, str]:
        if self.i >= len(self.t):
            raise EquationError("the expression ends too early")
        tok = self.t[self.i]
        if value is not None and tok[1] != value:
            raise EquationError(f"expected {value!r}, found {tok[1]!r}")
        self.i += 1
        return tok

    def expr(self) -> float:
        v = self.term()
        while self.peek() in ("+", "-"):
            v = v + self.term() if self.take()[1] == "+" else v - self.term()
        return v

    def term(self) -> float:
        v = self.unary()
        while self.peek() in ("*", "/"):
            if self.take()[1] == "*":
                v *= self.unary()
            else:
                d = self.unary()
                if d == 0.0:
                    raise EquationError("division by zero")
                v /= d
        return v

    def unary(self) -> float:
        if self.peek() in ("+", "-"):
            sign = -1.0 if self.take()[1] == "-" else 1.0
            return sign * self.unary()
        return self.power()

    def power(self) -> float:
        base = self.atom()
        if self.peek() == "**":
            self.take()
            try:
                return float(base ** self.unary())
            except (OverflowError, ZeroDivisionError, TypeError) as exc:
                raise EquationError(f"power: {exc}") from None
        return base

    def atom(self) -> float:
        kind, value = self.take()
        if kind == "num":
            return float(value.replace("D", "E"))
        if kind == "name":
            if self.peek() == "(":
                return self.call(value)
            if value not in self.env:
                raise EquationError(f"{value} has no value (not an argument nor a name defined before)")
            return self.env[value]
        if value == "(":
            v = self.expr()
            self.take(")")
            return v
        raise EquationError(f"unexpected {value!r}")

    def call(self, name: str) -> float:
        if name not in FUNCTIONS:
            raise EquationError(f"function {name} is not evaluated here (known: {', '.join(FUNCTIONS)})")
        n, f = FUNCTIONS[name]
        self.take("(")
        args = [self.expr()]
        while self.peek() == ",":
            self.take()
            args.append(self.expr())
        self.take(")")
        if (n > 0 and len(args) != n) or not args:
            raise EquationError(f"{name} takes {n} argument(s), given {len(args)}")
        try:
            return float(f(*args))
        except (ValueError, OverflowError, ZeroDivisionError) as exc:
            raise EquationError(f"{name}{tuple(args)}: {exc}") from None


def arguments(text: str) -> list[str]:
    """The argument names of the equation's first statement ``F(X1, X2, ...) = ...``."""
    first = text.split(";", 1)[0]
    m = re.match(r"\s*[A-Za-z][A-Za-z0-9_]*\s*\(([^)]*)\)\s*=", first)
    if m is None:
        raise EquationError("the first statement must be F(X1, X2, ...) = expression")
    names = [a.strip().upper() for a in m.group(1).split(",")]
    if not all(re.fullmatch(r"[A-Z][A-Z0-9_]*", a) for a in names):
        raise EquationError(f"arguments {m.group(1)!r} are not names")
    return names


def evaluate(text: str, values: list[float]) -> float:
    """The value of the DEQATN equation ``text`` with its arguments bound to ``values`` in order."""
    names = arguments(text)
    if len(names) != len(values):
        raise EquationError(f"the equation has {len(names)} argument(s) ({', '.join(names)}), "
                            f"given {len(values)}")
    env = dict(zip(names, values))
    result = None
    for k, statement in enumerate(s for s in text.split(";") if s.strip()):
        lhs, eq, rhs = statement.partition("=")
        if not eq:
            raise EquationError(f"statement {k + 1} has no '='")
        target = lhs.split("(")[0].strip().upper()
        p = _Parser(_tokens(rhs), env)
        result = p.expr()
        if p.i != len(p.t):
            raise EquationError(f"statement {k + 1}: unexpected {p.t[p.i][1]!r}")
        if not math.isfinite(result):
            raise EquationError(f"statement {k + 1} is not finite")
        env[target] = result
    if result is None:
        raise EquationError("no statement")
    return result
