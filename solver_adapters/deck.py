"""The parsed bulk-data model: one frozen dataclass per supported card (``docs/study-format.md``).

Every entity remembers where it came from (``src``: ``"file:line"``) so that model errors found
later (a CBAR whose PBAR is missing) can still name the file and line.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class Grid:
    """GRID: ID, CP (0 only), X1 X2 X3, CD (0 only), PS (permanent single-point constraints)."""
    id: int
    xyz: tuple[float, float, float]
    ps: str = ""
    src: str = ""


@dataclass(frozen=True)
class CBar:
    """CBAR: EID, PID, GA, GB, orientation vector X1 X2 X3 (basic system) or G0 (BAROR defaults
    already applied), pin flags PA, PB (element components released at end A, B) and offsets
    WA, WB (basic system, from the grid to the bar end; ``None``: no offset)."""
    eid: int
    pid: int
    ga: int
    gb: int
    x: tuple[float, float, float] | None = None
    g0: int | None = None
    src: str = ""
    pa: str = ""
    pb: str = ""
    wa: tuple[float, float, float] | None = None
    wb: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class PBar:
    """PBAR: PID, MID, A, I1 (plane 1, about element z), I2 (plane 2, about element y), J,
    K1, K2 (shear area factors of planes 1 and 2), I12 (product of inertia, int y z dA in the
    element axes; couples the two bending planes).

    ``k1``/``k2`` ``None`` (field blank or 0.0) is NASTRAN's default: infinite transverse shear
    stiffness (Euler-Bernoulli); a value gives the shear stiffness per unit length K*A*G.
    """
    pid: int
    mid: int
    a: float
    i1: float
    i2: float
    j: float
    src: str = ""
    k1: float | None = None
    k2: float | None = None
    i12: float = 0.0


@dataclass(frozen=True)
class Mat1:
    """MAT1: MID, E, G, NU as completed by the reader (NASTRAN's rule, see ``bdf._mat1``)."""
    mid: int
    e: float
    g: float
    nu: float
    src: str = ""


@dataclass(frozen=True)
class Spc1:
    """SPC1: SID, C (component digits), grids (THRU already expanded). An SPC card (enforced
    value zero) is held the same way, one entry per grid and component field."""
    sid: int
    components: str
    grids: tuple[int, ...]
    src: str = ""


@dataclass(frozen=True)
class SpcAdd:
    """SPCADD: SID and the SPC/SPC1 set IDs it combines."""
    sid: int
    sets: tuple[int, ...]
    src: str = ""


@dataclass(frozen=True)
class Prod:
    """PROD: PID, MID, A, J (torsion constant; C and NSM are not stiffness)."""
    pid: int
    mid: int
    a: float
    j: float
    src: str = ""


@dataclass(frozen=True)
class Rod:
    """CROD (``pid`` set) or CONROD (``mid``, ``a``, ``j`` on the element): axial + torsion."""
    eid: int
    ga: int
    gb: int
    pid: int | None = None
    mid: int | None = None
    a: float = 0.0
    j: float = 0.0
    card: str = "CROD"
    src: str = ""


@dataclass(frozen=True)
class Rbe2:
    """RBE2: EID, GN (independent grid), CM (dependent component digits), GM... (dependent grids)."""
    eid: int
    gn: int
    cm: str
    gm: tuple[int, ...]
    src: str = ""


@dataclass(frozen=True)
class Pelas:
    """PELAS: PID, K (GE and S ignored)."""
    pid: int
    k: float
    src: str = ""


@dataclass(frozen=True)
class Spring:
    """CELAS1 (``pid`` set, ``k`` None until resolved) or CELAS2 (``k`` set).

    ``g2``/``c2`` are 0 for a spring to ground.
    """
    eid: int
    g1: int
    c1: int
    g2: int
    c2: int
    k: float | None = None
    pid: int | None = None
    card: str = "CELAS2"
    src: str = ""


@dataclass
class Deck:
    """All supported cards of a deck, keyed by ID. ``files`` lists every file read (INCLUDE)."""
    grids: dict[int, Grid] = field(default_factory=dict)
    cbars: dict[int, CBar] = field(default_factory=dict)
    pbars: dict[int, PBar] = field(default_factory=dict)
    mat1s: dict[int, Mat1] = field(default_factory=dict)
    spc1s: list[Spc1] = field(default_factory=list)
    rbe2s: dict[int, Rbe2] = field(default_factory=dict)
    pelas: dict[int, Pelas] = field(default_factory=dict)
    springs: dict[int, Spring] = field(default_factory=dict)
    spcadds: dict[int, SpcAdd] = field(default_factory=dict)
    prods: dict[int, Prod] = field(default_factory=dict)
    rods: dict[int, Rod] = field(default_factory=dict)
    files: list[str] = field(default_factory=list)
    # cards accepted with no effect on a linear static solve: name -> (count, first "file:line")
    no_effect: dict[str, tuple[int, str]] = field(default_factory=dict)

    def rod_section(self, r: Rod) -> tuple[int, float, float]:
        """``(mid, A, J)`` of a rod: its own (CONROD) or its PROD's (CROD)."""
        if r.pid is None:
            return r.mid, r.a, r.j
        p = self.prods[r.pid]  # presence checked by validate()
        return p.mid, p.a, p.j

    def summary(self) -> str:
        """One line naming the cards read and those accepted with no effect (with counts)."""
        counts = {"GRID": len(self.grids), "CBAR": len(self.cbars), "PBAR": len(self.pbars),
                  "CROD/CONROD": len(self.rods), "PROD": len(self.prods), "MAT1": len(self.mat1s),
                  "SPC/SPC1 entries": len(self.spc1s), "SPCADD": len(self.spcadds),
                  "RBE2": len(self.rbe2s), "PELAS": len(self.pelas), "CELAS1/2": len(self.springs)}
        text = ", ".join(f"{n} {k}" for k, n in counts.items() if n)
        if self.no_effect:
            text += "; accepted with no effect on a linear static solve: " + ", ".join(
                f"{name} x{n} (first at {src})" for name, (n, src) in sorted(self.no_effect.items()))
        return text

    def spring_stiffness(self, s: Spring) -> float:
        """The spring's K: its own (CELAS2) or its PELAS's (CELAS1)."""
        if s.k is not None:
            return s.k
        return self.pelas[s.pid].k  # presence checked by validate()
