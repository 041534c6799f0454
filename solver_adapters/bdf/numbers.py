"""NASTRAN numbers: one field at a time (:func:`parse_int`, :func:`parse_real`, the readers'
``_to_int``/``_to_real``) and a whole column of fields at once (:func:`int_column`,
:func:`real_column`) for the cards converted in bulk.

A column converter never decides an error: it returns the values it could read and a mask of
the fields it could not; the cards holding those are read one at a time by the card's own
parser, which gives the located error (or reads a spelling the column converter leaves to it).
"""

from __future__ import annotations

import re

import numpy as np

from solver_adapters.errors import NumberFieldError as _NumberError
from solver_adapters.protocol import DeckFormatError

_INT = re.compile(r"[+-]?\d+")
# mantissa, then an explicit exponent (E/D) or NASTRAN's implicit one (1.0-3 = 1.0E-3)
_REAL = re.compile(r"([+-]?(?:\d+\.\d*|\.\d+|\d+))(?:[ED]([+-]?\d+)|([+-]\d+))?")
_MAX_INT = 2**31 - 1

# numpy >= 2 has the string ufuncs (np.strings), fast; numpy 1.x the same names in np.char
strings = getattr(np, "strings", np.char)


def _to_int(s: str) -> int:
    if _INT.fullmatch(s):
        value = int(s)
        if abs(value) > _MAX_INT:
            raise _NumberError("integer out of range (32-bit)")
        return value
    if s and _real_or_none(s) is not None:
        raise _NumberError("integer field given a real")
    raise _NumberError("not an integer")


def _to_real(s: str) -> float:
    value = _real_or_none(s)
    if value is None:
        raise _NumberError("not a real number")
    if not np.isfinite(value):
        raise _NumberError("real number out of range")
    return value


def _real_or_none(s: str) -> float | None:
    m = _REAL.fullmatch(s.upper())
    if m is None:
        return None
    mantissa, explicit, implicit = m.groups()
    if implicit is not None and "." not in mantissa:
        return None
    exponent = explicit if explicit is not None else implicit
    return float(mantissa + ("e" + exponent if exponent is not None else ""))


def parse_int(text: str) -> int:
    """A NASTRAN integer (``12``, ``-3``, ``+7``). A real (``1.``) is an error, as in NASTRAN."""
    try:
        return _to_int(text.strip())
    except _NumberError as exc:
        raise DeckFormatError(str(exc), value=text) from None


def parse_real(text: str) -> float:
    """A NASTRAN real: ``1.0``, ``1.``, ``.5``, ``1.0E+3``, ``1.0D3``, ``1.0+3``, ``-2.5-7``.

    Lenient where NASTRAN is strict: integer text (``0``, ``12``) and an exponent without a decimal
    point (``1E3``) are accepted. The implicit-exponent form needs a decimal point (``1+3`` is an
    error). Non-finite values (``nan``, ``1.0E+999``) are errors.
    """
    try:
        return _to_real(text.strip())
    except _NumberError as exc:
        raise DeckFormatError(str(exc), value=text) from None


def print_halfwidth(text: str) -> float:
    """Half the unit of the last digit a real field was printed with (``"0.005208"``: 5e-7,
    ``"5.2-3"``: 5e-5): how far the value it stands for may lie from the printed one."""
    m = _REAL.fullmatch(text.strip().upper())
    if m is None:
        return 0.0
    mantissa, explicit, implicit = m.groups()
    decimals = len(mantissa.partition(".")[2])
    return 0.5 * 10.0 ** (int(explicit or implicit or 0) - decimals)


SAME_PRINTED_RTOL = 1e-3
"""Two prints of one value differ by the rounding of the shorter one, which keeps at least four
significant digits in any 8-column field of a pre-processor (5e-4 relative at worst)."""


def same_printed(text_a: str, a: float, text_b: str, b: float) -> bool:
    """Whether two printed reals may stand for one value: they differ by no more than the
    rounding of the less precise print and by at most :data:`SAME_PRINTED_RTOL` of the larger
    (``0.005208`` and ``0.0052083`` do; ``1.`` and ``1.4``, ``0.`` and ``.1`` do not)."""
    diff = abs(a - b)
    return (diff <= max(print_halfwidth(text_a), print_halfwidth(text_b)) * (1.0 + 1e-9)
            and diff <= SAME_PRINTED_RTOL * max(abs(a), abs(b)))


def typed(text: str) -> int | float | str | None:
    """A field's value as NASTRAN reads it: blank -> None, an integer, a real (any spelling,
    ``1.-3`` too), else the word (upper case)."""
    t = text.strip().upper()
    if not t:
        return None
    if _INT.fullmatch(t):
        return int(t)
    value = _real_or_none(t)
    return value if value is not None and np.isfinite(value) else t


# --------------------------------------------------------------------------------------------
# columns: stripped byte strings (numpy "S" arrays), as the card table holds them
# --------------------------------------------------------------------------------------------
def _suspect(col: np.ndarray) -> np.ndarray | None:
    """Fields that numpy's float parser would read although NASTRAN's grammar does not: it
    follows Python's float(), which takes an underscore between digits ("1_000"); "nan" and
    "inf" are caught as non-finite values. None when the column has no underscore at all."""
    if b"_" not in np.ascontiguousarray(col).tobytes():
        return None
    return strings.find(col, b"_") >= 0


def _parse_reals(col: np.ndarray, blank: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(values, ok)`` of the non-blank fields of ``col`` that numpy's float parser reads."""
    n = col.shape[0]
    ok = ~blank
    bad = _suspect(col)
    if bad is not None:
        ok &= ~bad
    src = col if ok.all() else np.where(ok, col, b"0")
    try:
        return src.astype(float), ok
    except ValueError:
        values = np.zeros(n)
        for i in np.flatnonzero(ok).tolist():
            try:
                values[i] = float(src[i])
            except ValueError:
                ok[i] = False
        return values, ok


def int_column(col: np.ndarray, default: int | None = None, minimum: int | None = 1):
    """``(values, ok)``: the integers of a column of stripped fields. A blank field is
    ``default`` (``None``: a blank is not ok); a field that is not a plain integer within 32 bits
    and >= ``minimum`` is not ok (its value is then meaningless)."""
    n = col.shape[0]
    blank = col == b""
    if blank.all():
        return np.full(n, default or 0, np.int64), np.full(n, default is not None)
    ok = int_like(col)                        # NASTRAN's grammar exactly: [+-]digits
    values = np.zeros(n, np.int64)
    digits = np.where(ok, col, b"0")
    if digits.dtype.itemsize > 18:                       # could overflow int64: one by one
        for i in np.flatnonzero(ok).tolist():
            v = int(digits[i])
            values[i], ok[i] = (v, True) if abs(v) <= _MAX_INT else (0, False)
    else:
        values = digits.astype(np.int64)
    ok &= np.abs(values) <= _MAX_INT
    if minimum is not None:
        ok &= values >= minimum
    if default is not None and blank.any():
        values[blank] = default
        ok |= blank
    return values, ok


def real_column(col: np.ndarray, default: float | None = None):
    """``(values, ok)``: the reals of a column of stripped fields, every NASTRAN spelling
    (``1.5``, ``1.5E+3``, ``1.5D3``, ``1.5+3``, integer text). A blank field is ``default``
    (``None``: a blank is not ok); a field that is no finite real is not ok."""
    n = col.shape[0]
    blank = col == b""
    if blank.all():
        return np.full(n, default or 0.0), np.full(n, default is not None)
    values, ok = _parse_reals(col, blank)
    ok &= np.isfinite(values)
    for i in np.flatnonzero(~ok & ~blank).tolist():       # 1.5-3, 1.5D3, and the bad ones
        v = _real_or_none(col[i].decode("utf-8", "replace"))
        if v is not None and np.isfinite(v):
            values[i], ok[i] = v, True
    if default is not None and blank.any():
        values[blank] = default
        ok |= blank
    return values, ok


def int_like(col: np.ndarray) -> np.ndarray:
    """Fields written as an integer, ``[+-]?digits`` (what tells a G0 from an X1)."""
    n, width = col.shape[0], col.dtype.itemsize
    if n == 0 or width == 0:
        return np.zeros(n, bool)
    u8 = np.ascontiguousarray(col).view(np.uint8).reshape(n, width)
    digit = (u8 >= 48) & (u8 <= 57)
    sign = (u8[:, 0] == 43) | (u8[:, 0] == 45)
    first_digit = np.where(sign, digit[:, 1] if width > 1 else False, digit[:, 0])
    rest = digit[:, 1:] | (u8[:, 1:] == 0)
    return first_digit & rest.all(axis=1)
