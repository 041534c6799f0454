"""MAT1: isotropic material, completed as NASTRAN does."""

from __future__ import annotations

from solver_adapters.bdf.fields import _ignored_reals, _int, _max_fields, _real
from solver_adapters.deck import Mat1


def _mat1(r, c) -> None:
    """MAT1: MID E G NU (RHO A TREF GE ST SC SS MCSID read, no effect on a static stiffness).

    Completion, as in the MSC Nastran Quick Reference Guide, MAT1 remark 3 (E = 2 (1 + NU) G):

    ======  ======  ======  =========================================
    E       G       NU      result
    ======  ======  ======  =========================================
    given   given   given   used as given (also when inconsistent)
    given   given   blank   NU = E / (2 G) - 1
    given   blank   given   G = E / (2 (1 + NU))
    blank   given   given   E = 2 (1 + NU) G
    given   blank   blank   G = 0, NU = 0
    blank   given   blank   E = 0, NU = 0
    blank   blank   any     error: E or G must be given
    ======  ======  ======  =========================================

    Ranges (QRG): E >= 0, G >= 0, -1 < NU <= 0.5 for a given NU; E = G = 0 is an error.
    """
    _max_fields(c, 13)
    mid = _int(c, 2)
    e, g, nu = (_real(c, i, None) for i in (3, 4, 5))
    _ignored_reals(c, range(6, 13))  # RHO A TREF GE ST SC SS
    _int(c, 13, 0, minimum=0)        # MCSID
    for i, value, name in ((3, e, "E"), (4, g, "G")):
        if value is not None and value < 0.0:
            raise c.error(i, f"{name} must be >= 0")
    if nu is not None and not -1.0 < nu <= 0.5:
        raise c.error(5, "Poisson's ratio NU must satisfy -1 < NU <= 0.5")
    if e is None and g is None:
        raise c.error(3, "MAT1 needs E or G (blank E and G: no stiffness)")
    if e is not None and g is not None:
        if nu is None:
            if g == 0.0:
                raise c.error(4, "G = 0 with E given and NU blank: NU = E / (2 G) - 1 is undefined")
            nu = e / (2.0 * g) - 1.0
    elif g is None:
        g = e / (2.0 * (1.0 + nu)) if nu is not None else 0.0
        nu = 0.0 if nu is None else nu
    else:
        e = 2.0 * g * (1.0 + nu) if nu is not None else 0.0
        nu = 0.0 if nu is None else nu
    if e == 0.0 and g == 0.0:
        raise c.error(3, "E and G are both zero: the material has no stiffness")
    r.claim("MAT1", mid, c, 2)
    r.deck.mat1s[mid] = Mat1(mid, e, g, nu, c.src)


PARSERS = {"MAT1": _mat1}
