"""The parsed bulk-data model: one frozen dataclass per supported card (CONTRACT.md section 1).

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
    """CBAR: EID, PID, GA, GB, orientation vector X1 X2 X3 (basic system) or G0."""
    eid: int
    pid: int
    ga: int
    gb: int
    x: tuple[float, float, float] | None = None
    g0: int | None = None
    src: str = ""


@dataclass(frozen=True)
class PBar:
    """PBAR: PID, MID, A, I1 (plane 1, about element z), I2 (plane 2, about element y), J."""
    pid: int
    mid: int
    a: float
    i1: float
    i2: float
    j: float
    src: str = ""


@dataclass(frozen=True)
class Mat1:
    """MAT1: MID, E, G, NU (any two given; the third follows from G = E / (2 (1 + NU)))."""
    mid: int
    e: float
    g: float
    nu: float
    src: str = ""


@dataclass(frozen=True)
class Spc1:
    """SPC1: SID, C (component digits), grids (THRU already expanded)."""
    sid: int
    components: str
    grids: tuple[int, ...]
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
    files: list[str] = field(default_factory=list)

    def spring_stiffness(self, s: Spring) -> float:
        """The spring's K: its own (CELAS2) or its PELAS's (CELAS1)."""
        if s.k is not None:
            return s.k
        return self.pelas[s.pid].k  # presence checked by validate()
