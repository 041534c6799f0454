"""Field accessors of the card parsers (``i`` = NASTRAN field number, 1-based): each reads one
field of a card and raises the card's located error (file, line, card, field) when it is wrong."""

from __future__ import annotations

import re

from solver_adapters.bdf.numbers import _INT, _NumberError, _real_or_none, _to_int, _to_real

_REQUIRED = object()


def _int(card, i: int, default=_REQUIRED, *, minimum: int | None = 1) -> int:
    text = card.text(i)
    if not text:
        if default is _REQUIRED:
            raise card.error(i, "required integer field is blank")
        return default
    try:
        value = _to_int(text)
    except _NumberError as exc:
        raise card.error(i, str(exc)) from None
    if minimum is not None and value < minimum:
        raise card.error(i, f"must be >= {minimum}")
    return value


def _real(card, i: int, default=_REQUIRED) -> float:
    text = card.text(i)
    if not text:
        if default is _REQUIRED:
            raise card.error(i, "required real field is blank")
        return default
    try:
        return _to_real(text)
    except _NumberError as exc:
        raise card.error(i, str(exc)) from None


_COMPONENTS = re.compile(r"[1-6]+")


def valid_components(text: str) -> bool:
    """Digits 1-6 without repeats."""
    return bool(_COMPONENTS.fullmatch(text)) and len(set(text)) == len(text)


def _components(card, i: int, *, required: bool) -> str:
    """Component digits 1-6, no repeats, returned sorted (``"321"`` -> ``"123"``)."""
    text = card.text(i)
    if not text:
        if required:
            raise card.error(i, "required component field is blank")
        return ""
    if not valid_components(text):
        raise card.error(i, "components must be digits 1-6 without repeats")
    return "".join(sorted(text))


def _blank(card, i: int, what: str, *, zero_ok: bool = False) -> None:
    text = card.text(i)
    if text and not (zero_ok and _real_or_none(text) == 0.0):
        raise card.error(i, f"{what} not supported (must be blank)")


def _max_fields(card, n: int) -> None:
    for i in range(n + 1, len(card.fields) + 1):
        if card.text(i):
            raise card.error(i, f"{card.name} has at most {n} fields")


def _ignored_reals(card, fields) -> None:
    for i in fields:
        _real(card, i, 0.0)  # read for well-formedness only


def _id_list(c, first: int, last: int) -> list[int | tuple[int, int]]:
    """Integers from field ``first`` on, blanks skipped, ``A THRU B`` kept as ``(A, B)``."""
    items: list[int | tuple[int, int]] = []
    i = first
    while i <= last:
        text = c.text(i)
        if text == "THRU":
            if not items or isinstance(items[-1], tuple):
                raise c.error(i, "THRU must follow a grid ID")
            j = next((k for k in range(i + 1, last + 1) if c.text(k)), None)
            if j is None:
                raise c.error(i, "THRU must be followed by a grid ID")
            hi = _int(c, j)
            if hi < items[-1]:
                raise c.error(j, f"THRU range end {hi} is below its start {items[-1]}")
            items[-1] = (items[-1], hi)
            i = j + 1
            continue
        if text:
            items.append(_int(c, i))
        i += 1
    return items


def _orientation(c) -> tuple[tuple[float, float, float] | None, int | None]:
    """Fields 6-8 of CBAR/CBEAM/BAROR/CBUSH: ``(x, None)``, ``(None, g0)`` or ``(None, None)``
    if blank."""
    if _INT.fullmatch(c.text(6)):
        for i in (7, 8):
            if c.text(i):
                raise c.error(i, "field 6 is an integer (G0), so X2 and X3 must be blank; "
                                 "write a real X1 (e.g. 0.) for an orientation vector")
        return None, _int(c, 6)
    if any(c.text(i) for i in (6, 7, 8)):
        return (_real(c, 6, 0.0), _real(c, 7, 0.0), _real(c, 8, 0.0)), None
    return None, None


def _pin(c, i: int) -> str:
    """Pin flag digits (element components 1-6 released at that end); blank or 0: none."""
    return "" if c.text(i) in ("", "0") else _components(c, i, required=False)
