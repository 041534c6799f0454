"""Chapter 6 (comparison of the simple and complex joint models) reproduced on the fixtures.

Run ``python studies/chapter6.py`` from the repository root (about two minutes; ``--reuse`` only
rewrites the Markdown from the outputs already in the build folder); it rewrites
``studies/chapter6.md`` and ``studies/chapter6/{cube,car}/`` (the ``blackbox compare`` outputs:
report.md, comparison.json, the bar plots like Figures 6.2-6.5, mdse_loads.csv). Working
folders go to ``studies/chapter6/build/`` (git-ignored).

* Truths: the cube joint = Table 5.12 as printed, the car joint = Table 5.18 as printed
  (Chapter 6's "actual joint", Tables 6.1 and 6.8, differ in three entries; see the notes).
* Measurements: ``blackbox simulate`` -- 5 % noise, the joint's DOFs in load cases L1-L12,
  rotations relative to the joint's branch-1 grid (Section 5.2's reference point); L11 and L12 are
  held out, so 10 cases are fitted, as in the dissertation.
* ``blackbox compare`` on both, then the same with seeds 1-8, with the joint made softer, and with
  absolute rotations, to see which findings are robust.
"""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from blackbox import comparison as cmp                                      # noqa: E402
from blackbox import reference_tables as rt                              # noqa: E402
from blackbox.cli import main as cli                                     # noqa: E402
from blackbox.commands import compare as compare_command                  # noqa: E402
from blackbox.commands.output import write_output                         # noqa: E402
from blackbox.joints import ComplexJoint, complex_param_names             # noqa: E402

OUT = ROOT / "studies" / "chapter6"
BUILD = OUT / "build"
NAMES = complex_param_names(3)
SEED = 1                                   # the headline runs; seeds 1-8 in the robustness table
SEEDS = range(1, 9)
CASES = [f"L{i}" for i in range(1, 13)]
HOLDOUT = ["L11", "L12"]


def vec(text: str) -> list[float]:
    return [float(x) for x in text.split()]


# ---- the dissertation's tables (k11 k12 ... k66 in N*m/rad; rotations in rad) ---------------
# Tables 5.12 and 5.18 as printed (blackbox.reference_tables says which entries are questionable)
TABLE_5_12 = list(rt.TABLE_5_12.values())
TABLE_5_18 = list(rt.TABLE_5_18.values())
DISS = {
    "cube": dict(
        tables=dict(params="6.1", mdse="6.2", energy="6.3", iso="6.4", fig="6.2", asm="6.5",
                    params11="6.6", energy11="6.7", fig11="6.3"),
        actual=list(rt.TABLE_6_1_ACTUAL.values()),
        complex=list(rt.TABLE_6_1_COMPLEX.values()),
        simple=list(rt.TABLE_6_1_SIMPLE.values()),
        mdse=vec("-0.0786 0.0083 0.0051 1.0000 -0.0197 -0.0162"),
        energy=(0.3358e-5, 0.0808e-5, 75.93),
        iso_c=vec("-0.7072E-8 0.2172E-7 0.2109E-7 0.3356E-5 -0.5728E-7 -0.4794E-7"),
        iso_s=vec("0.1920E-6 0.8609E-9 0.8337E-8 0.8230E-6 -0.7460E-8 -0.7043E-8"),
        asm_c=vec("0.9186E-5 -0.6189E-6 0.9876E-7 0.4234E-5 -0.8164E-6 0.1624E-6 0.1148E-5 -0.7751E-5 -0.2333E-6"),
        asm_s=vec("0.1410E-5 -0.4580E-6 0.2978E-7 0.3730E-5 -0.6819E-6 0.9190E-7 0.2264E-5 -0.7216E-5 -0.2006E-6"),
        complex11=vec("0.6097E7 -0.7422E6 0.7705E5 0.2892E5 -0.1470E6 0.2803E7 0.6204E7 0.7457E5 -0.2636E5 "
                      "0.6820E5 -0.1602E6 0.3149E6 -0.1246E4 -0.2516E5 0.1906E5 0.3066E6 0.8890E5 0.8190E5 "
                      "0.5995E7 -0.7009E6 0.6049E7"),
        simple11=vec("0.1671E7 0 0 -0.4860E6 0 0 0.3272E7 0 0 -0.7274E6 0 0.4406E6 0 0 -0.1943E6 0.1329E7 0 0 "
                     "0.2536E7 0 0.2061E7"),
        energy11=(0.3386e-5, 0.0841e-5, 75.16), change11="less than 2 %", dominant="theta_x2"),
    "car": dict(
        tables=dict(params="6.8", mdse="6.9", energy="6.10", iso="6.11", fig="6.4", asm="6.12",
                    params11="6.13", energy11="6.14", fig11="6.5"),
        actual=vec("0.3607E7 -0.1321E6 0.2355E5 0.2355E5 -0.1321E6 0.9408E6 0.3607E7 0.2355E5 -0.7697E4 "
                   "-0.1321E6 -0.1321E6 0.1567E6 0.4618E3 -0.7697E4 0.2355E5 0.1567E6 0.2355E5 0.2355E5 "
                   "0.3607E7 -0.1321E6 0.3607E7"),
        complex=vec("0.3572E7 -0.1498E6 0.2123E5 0.2206E5 -0.1178E6 0.8893E6 0.3426E7 0.2513E5 -0.7546E4 "
                    "-0.9650E5 -0.1536E6 0.1406E6 0.4457E3 -0.6581E4 0.2506E5 0.1728E6 0.2286E5 0.2306E5 "
                    "0.3751E7 -0.1436E6 0.3512E7"),
        simple=vec("0.1158E7 0 0 -0.3097E6 0 0 0.2814E7 0 0 -0.2551E7 0 1.3922E7 0 0 -0.6536E7 0.7008E6 0 0 "
                   "0.2903E7 0 0.6852E7"),
        mdse=vec("-0.0021 -0.0067 1.0000 -0.0062 0.0025 -0.0185"),
        energy=(0.8429e-5, 0.1426e-5, 83.08),
        iso_c=vec("-0.1870E-7 -0.5535E-7 0.7128E-5 -0.5453E-7 0.1109E-7 -0.1038E-7"),
        iso_s=vec("-0.4659E-8 -0.8025E-8 0.1278E-6 -0.1094E-7 0.9902E-8 -0.1192E-7"),
        asm_c=vec("0.5399E-6 -0.4359E-6 0.6082E-4 -0.9786E-6 -0.1193E-6 0.1069E-5 0.5269E-6 -0.2260E-7 0.2254E-5"),
        asm_s=vec("0.5014E-6 -0.6427E-7 0.4865E-4 -0.8532E-6 -0.1024E-6 0.9088E-6 0.4819E-6 -0.2357E-7 0.1874E-5"),
        complex11=vec("0.3514E7 -0.1245E6 0.2148E5 0.2274E5 -0.1195E6 0.8436E6 0.4014E7 0.2722E5 -0.7267E4 "
                      "-0.1542E6 -0.1459E6 0.1368E6 0.4798E3 -0.6692E4 0.2761E5 0.1633E6 0.2491E5 0.2467E5 "
                      "0.3432E7 -0.1502E6 0.3592E7"),
        simple11=vec("0.1175E7 0 0 -0.3136E6 0 0 0.2956E7 0 0 -0.2691E7 0 1.3853E7 0 0 -0.6567E7 0.7119E6 0 0 "
                     "0.3146E7 0 0.6749E7"),
        energy11=(0.8488e-5, 0.1475e-5, 82.62), change11="less than 3 %", dominant="theta_z1"),
}
STRUCT = {"cube": dict(fixture="cube", joint="J7", ref=7, truth=TABLE_5_12),
          "car": dict(fixture="car", joint="JB", ref=11, truth=TABLE_5_18)}


# --------------------------------------------------------------------------------------------
# building and running
# --------------------------------------------------------------------------------------------
def truth_text(joint: str, values, seed: int, reference: int | None) -> str:
    kv = ", ".join(f"{n} = {float(v)!r}" for n, v in zip(NAMES, values))
    cases = ", ".join(f'"{c}"' for c in CASES)
    ref = f"reference_grid = {reference}\n" if reference is not None else ""
    return (f"seed = {seed}\n\n[[joints]]\nname = \"{joint}\"\nmodel = \"complex\"\nvalues = {{{kv}}}\n\n"
            f"[noise]\nrelative = 0.05\nfloor = 0.02\n\n[measure]\njoint = true\ncases = [{cases}]\n{ref}")


def make_study(name: str, tag: str, seed: int, scale: float = 1.0, relative: bool = True) -> Path:
    """A copy of the fixture with hold-out cases L11, L12, measured by ``blackbox simulate``."""
    s = STRUCT[name]
    base = BUILD / tag
    if base.exists():
        shutil.rmtree(base)
    src = base / "src"
    shutil.copytree(ROOT / "fixtures" / s["fixture"], src, ignore=shutil.ignore_patterns(
        "measurements.csv", "truth.*", ".blackbox_cache", "README.md", "structure.png"))
    toml = src / "study.toml"
    toml.write_text(toml.read_text().replace("holdout_cases = []", f"holdout_cases = {json.dumps(HOLDOUT)}"))
    truth = base / "truth.toml"
    truth.write_text(truth_text(s["joint"], np.array(s["truth"]) * scale, seed, s["ref"] if relative else None))
    if cli(["simulate", str(src), "--truth", str(truth), "--out", str(base / "study")]) != 0:
        raise SystemExit(f"blackbox simulate failed for {tag}")
    return base / "study"


REUSE = "--reuse" in sys.argv        # rewrite chapter6.md from the build folder's earlier outputs


def headline(name: str) -> dict:
    out = BUILD / f"{name}_compare"
    if REUSE and (out / "comparison.json").exists():
        return json.loads((out / "comparison.json").read_text())
    study = make_study(name, name, SEED)
    if cli(["compare", str(study), "--out", str(out), "--no-cache"]) not in (0, 4):
        raise SystemExit(f"blackbox compare failed for {name}")
    dst = OUT / name
    if dst.exists():
        shutil.rmtree(dst)
    dst.mkdir(parents=True)
    for f in out.iterdir():
        if f.is_file() and f.name != ".blackbox-output":       # not the output folder's marker
            shutil.copy(f, dst / f.name)
    return json.loads((out / "comparison.json").read_text())


def quiet_compare(name: str, tag: str, seed: int, **kw) -> dict:
    if REUSE and (BUILD / f"{tag}_compare" / "comparison.json").exists():
        return json.loads((BUILD / f"{tag}_compare" / "comparison.json").read_text())
    study = make_study(name, tag, seed, **kw)
    res = compare_command.run(study)
    write_output(BUILD / f"{tag}_compare", "compare", res.write)
    return json.loads((BUILD / f"{tag}_compare" / "comparison.json").read_text())


# --------------------------------------------------------------------------------------------
# formatting
# --------------------------------------------------------------------------------------------
def e(v, d: int = 4) -> str:
    return "n/a" if v is None else f"{v:.{d}e}"


def pct(v, d: int = 1) -> str:
    return "n/a" if v is None else f"{100 * v:.{d}f} %"


def iv(u: dict | None) -> str:
    if not u:
        return "n/a"
    lo, hi = u["relative_difference_interval"]
    return f"[{100 * lo:.1f}, {100 * hi:.1f}] %"


def kc(res: dict, model: str) -> list[float]:
    d = res["models"][model]["clamped_stiffness"][0]["K_C"]
    return [d[n] for n in NAMES]


def ci(res: dict) -> list[tuple[float, float]]:
    return [(p["ci_low"], p["ci_high"]) for p in res["models"]["complex"]["parameters"]]


# --------------------------------------------------------------------------------------------
# sections
# --------------------------------------------------------------------------------------------
def k34_check() -> list[str]:
    j = ComplexJoint("J", (1, 2, 3))
    out = ["## The k34 sign and the other printed entries", "",
           "| truth | k34 | smallest eigenvalue of K_C | positive definite |", "|---|---|---|---|"]
    for name, table in (("cube, Table 5.12", TABLE_5_12), ("car, Table 5.18", TABLE_5_18)):
        for sign in (1, -1):
            k = np.array(table)
            k[NAMES.index("k34")] *= sign
            lam = np.linalg.eigvalsh(j.kc_matrix(k))
            out.append(f"| {name}{' (printed)' if sign == 1 else ' (sign flipped)'} | {k[NAMES.index('k34')]:.4g} "
                       f"| {lam.min():.6g} | {bool(lam.min() > 0)} |")
    out += ["", "Both signs keep K_C positive definite (k34 is 0.5 % of the diagonal it couples), so the "
            "printed value is kept: k34 = -0.1530E4 for the cube (Tables 5.12 and 6.1 agree), "
            "+0.4648E3 for the car (Table 5.18; Table 6.8 prints 0.4618E3). Table 5.12 and Table "
            "6.1's 'actual' column also differ in k13 (0.7508E5 vs 0.7805E5, the joint's x<->z "
            "mirror symmetry wants 0.7805E5, see `studies/chapter3.md`) and k24 (-0.2550E5 vs "
            "-0.2551E5); we use Table 5.12 as printed. These are 0.2-1 % of the neighbouring "
            "diagonals and change nothing below.", ""]
    return out


def dissertation_check() -> list[str]:
    """Eq. 34-35 on the dissertation's own estimates (Tables 6.1, 6.8)."""
    j = ComplexJoint("J", (1, 2, 3))
    out = ["## Eq. 34-35 on the dissertation's own estimates", "",
           "Our `blackbox.comparison` applied to the two estimated K_C of Table 6.1 (cube) and Table 6.8 "
           "(car): the MDSE loading, 2E = F^T C F (the tables' 'strain energy' is F . u, twice eq. 35's "
           "E: Table 6.3's E_complex = 0.3358E-5 is Table 6.4's F . u) and the displacements.", "",
           "| | cube: ours | cube: Tables 6.2-6.4 | car: ours | car: Tables 6.9-6.11 |", "|---|---|---|---|---|"]
    rows = {}
    for name in ("cube", "car"):
        d = DISS[name]
        m = cmp.compare_flexibilities(j.rotation_dofs[:6], [cmp.dof_name(j, x) for x in j.rotation_dofs[:6]],
                                      {"complex": cmp.isolated_flexibility(j, d["complex"]),
                                       "simple": cmp.isolated_flexibility(j, d["simple"])})
        rows[name] = (m, d)
    (mc, dc), (mk, dk) = rows["cube"], rows["car"]
    for i, n in enumerate(mc.names):
        out.append(f"| MDSE load {n} | {mc.load[i]:+.4f} | {dc['mdse'][i]:+.4f} | {mk.load[i]:+.4f} | "
                   f"{dk['mdse'][i]:+.4f} |")
    for key, idx, lab in (("complex", 0, "2 E_complex"), ("simple", 1, "2 E_simple")):
        out.append(f"| {lab} | {e(2 * mc.energies[key])} | {e(dc['energy'][idx])} | {e(2 * mk.energies[key])} | "
                   f"{e(dk['energy'][idx])} |")
    out.append(f"| R | {pct(mc.relative_difference, 2)} | {dc['energy'][2]:.2f} % | {pct(mk.relative_difference, 2)} | "
               f"{dk['energy'][2]:.2f} % |")
    for key, lab in (("c", "complex"), ("s", "simple")):
        dev_c = np.max(np.abs(mc.displacements[lab] - dc[f"iso_{key}"])) / np.max(np.abs(dc[f"iso_{key}"]))
        dev_k = np.max(np.abs(mk.displacements[lab] - dk[f"iso_{key}"])) / np.max(np.abs(dk[f"iso_{key}"]))
        out.append(f"| displacements ({lab}): max deviation / max | {100 * dev_c:.2f} % | (Table 6.4) | "
                   f"{100 * dev_k:.2f} % | (Table 6.11) |")
    fu_c = float(np.dot(dk["mdse"], dk["iso_c"]))
    fu_s = float(np.dot(dk["mdse"], dk["iso_s"]))
    dev_load = float(np.max(np.abs(mk.load - dk["mdse"])))
    dev_c = float(np.max(np.abs(mk.displacements["complex"] - dk["iso_c"])) / np.max(np.abs(dk["iso_c"])))
    out += ["", "The cube's Tables 6.2-6.4 are reproduced to their printed digits: our eq. 34-35 is the "
            f"dissertation's. For the car, Table 6.8's estimates give Table 6.9's loading to within {dev_load:.4f} "
            f"and Table 6.11's complex column to {100 * dev_c:.1f} %, but not the simple column: Table 6.8's simple "
            "K_C couples theta_z1 and theta_z2 through kz12 = 0.6536E7 (k36), so a moment on theta_z1 turns "
            f"theta_z2 almost as much (ours {mk.displacements['simple'][5]:.4e}), where Table 6.11 prints "
            f"{dk['iso_s'][5]:.4e}. Nor do Table 6.10's energies follow from Tables 6.9 and 6.11: F . u from those "
            f"two tables is {fu_c:.4e} (complex) and {fu_s:.4e} (simple), R = {100 * (1 - fu_s / fu_c):.1f} %, "
            "where Table 6.10 prints 0.8429E-5, 0.1426E-5 and 83.08 %. The car's Chapter 6 tables are not "
            "mutually consistent; we compare with them as printed.", ""]
    return out


def params_table(res: dict, d: dict, truth: dict, key11: bool = False) -> list[str]:
    t = d["tables"]
    num = t["params11"] if key11 else t["params"]
    out = [f"| parameter | truth (ours) | actual (Table {t['params']}) | complex: ours [95 % CI] | "
           f"complex: Table {num} | simple K_C: ours | simple K_C: Table {num} |", "|---|---|---|---|---|---|---|"]
    c, s = kc(res, "complex"), kc(res, "simple")
    tv = list(truth.values())[0]
    dc, ds = (d["complex11"], d["simple11"]) if key11 else (d["complex"], d["simple"])
    for i, n in enumerate(NAMES):
        lo, hi = ci(res)[i]
        out.append(f"| {n} | {e(tv[n])} | {e(d['actual'][i])} | {e(c[i])} [{e(lo, 2)}, {e(hi, 2)}] | {e(dc[i])} | "
                   f"{e(s[i])} | {e(ds[i])} |")
    return out


def fit_line(res: dict) -> str:
    m = res["models"]
    def h(r):
        ho = r["holdout"]
        if ho["rms_error"] is None:
            return "n/a"
        return f"{e(ho['rms_error'], 3)}, chi2/n {ho['chi2'] / max(ho['n_obs'], 1):.3g}"

    ms = res["model_selection"]
    return (f"Fit: simple reduced chi2 = {m['simple']['fit']['reduced_chi2']:.3g}, BIC = "
            f"{m['simple']['fit']['bic']:.5g}, hold-out (L11, L12) RMS error {h(m['simple'])}; complex "
            f"reduced chi2 = {m['complex']['fit']['reduced_chi2']:.3g}, BIC = {m['complex']['fit']['bic']:.5g}, "
            f"hold-out RMS error {h(m['complex'])} (the RMS error is dominated by the absolute rows of the "
            f"reference grid; chi2/n weighs every row by its sigma). BIC prefers the {ms['preferred_by_bic']} model "
            f"(delta BIC {ms['delta_bic']:.4g}; likelihood ratio {ms['statistic']:.4g} on {ms['dof']} "
            f"degrees of freedom).")


def mdse_table(jt: dict, printed: list[float] | None, table: str) -> list[str]:
    out = ([f"| DOF | ours | Table {table} |", "|---|---|---|"] if printed else ["| DOF | ours |", "|---|---|"])
    for i, n in enumerate(jt["names"]):
        out.append(f"| {n} | {jt['mdse_load'][i]:+.4f} |" + (f" {printed[i]:+.4f} |" if printed else ""))
    return out


def energy_rows(jt: dict, printed: tuple | None, table: str) -> list[str]:
    se = jt["strain_energy"]
    out = ["| | 2 E_complex | 2 E_simple | 2 E_truth | R | R 95 % interval | (E_truth - E_simple)/E_truth |",
           "|---|---|---|---|---|---|---|",
           f"| ours | {e(2 * se['complex'])} | {e(2 * se['simple'])} | {e(2 * se['truth'])} | "
           f"{pct(se['relative_difference'], 2)} | {iv(se.get('uncertainty'))} | "
           f"{pct(se['relative_difference_truth_vs_simple'], 2)} |"]
    if printed:
        out.append(f"| Table {table} | {e(printed[0])} | {e(printed[1])} | | {printed[2]:.2f} % | | |")
    return out


def disp_table(jt: dict, c: list[float], s: list[float], table: str, inf: bool = False) -> list[str]:
    dd = jt["displacements"]
    head = "| DOF | complex: ours | simple: ours | truth: ours |" + (" infinitely flexible: ours |" if inf else "") + \
        f" complex: Table {table} | simple: Table {table} |"
    out = [head, "|---|---|---|---|" + ("---|" if inf else "") + "---|---|"]
    for i, n in enumerate(jt["names"]):
        out.append(f"| {n} | {e(dd['complex'][i])} | {e(dd['simple'][i])} | {e(dd['truth'][i])} |"
                   + (f" {e(dd['infinitely_flexible'][i])} |" if inf else "") + f" {e(c[i])} | {e(s[i])} |")
    return out


def structure_section(name: str, res: dict) -> list[str]:
    d = DISS[name]
    t = d["tables"]
    j = res["joints"][0]
    iso, asm = j["isolated"], j["assembly"]
    w = res["with_mdse"]
    j2 = w["joints"][0]
    ch = w["parameter_changes"]
    sa = asm["strain_energy"]
    fixed = w["under_first_mdse_loading"][0]
    out = [f"## {name.capitalize()} (Tables {t['params']}-{t['energy11']}, Figures {t['fig']}, {t['fig11']})", "",
           f"Full report: [`chapter6/{name}/report.md`](chapter6/{name}/report.md); solver runs: "
           f"{res['solver']['runs']} for both identifications, {w['simulation_solver_runs']} to simulate the MDSE "
           f"case, {w['identification_solver_runs']} for the re-identification (superposition).", "",
           f"### Identified parameters (Table {t['params']})", "", *params_table(res, d, res["truth"]), "",
           fit_line(res), "",
           f"### MDSE loading, isolated joint (Table {t['mdse']})", "",
           *mdse_table(iso, d["mdse"], t["mdse"]), "",
           f"Dominant: **{iso['dominant']['name']}**, {100 * iso['dominant']['share']:.1f} % of the squared "
           f"load (dissertation: {d['dominant']}).", "",
           f"### Strain energy, isolated joint (Table {t['energy']}; 2E = F^T C F as the table)", "",
           *energy_rows(iso, d["energy"], t["energy"]), "",
           f"### Joint displacements, isolated joint (Table {t['iso']}; each under its own MDSE loading)", "",
           *disp_table(iso, d["iso_c"], d["iso_s"], t["iso"]), "",
           f"### Joint in the structure (Figure {t['fig']}, Table {t['asm']})", "",
           f"![assembly](chapter6/{name}/energy_assembly.png) ![isolated](chapter6/{name}/energy_isolated.png)", "",
           "| | 2 E_complex | 2 E_simple | 2 E_infinitely flexible | 2 E_truth | R | R 95 % interval | "
           "simple error / infinitely-flexible error |", "|---|---|---|---|---|---|---|---|",
           f"| ours | {e(2 * sa['complex'])} | {e(2 * sa['simple'])} | {e(2 * sa['infinitely_flexible'])} | "
           f"{e(2 * sa['truth'])} | {pct(sa['relative_difference'], 2)} | {iv(sa.get('uncertainty'))} | "
           f"{pct(sa['simple_error_over_infinitely_flexible_error'], 1)} |",
           f"| dissertation | (Figure {t['fig']}: not in the text) | | | | 'no significant difference' | | ~30 % |", "",
           f"MDSE loading in the structure: dominant **{asm['dominant']['name']}** "
           f"({100 * asm['dominant']['share']:.1f} %).", "",
           *disp_table(asm, d["asm_c"], d["asm_s"], t["asm"], inf=True), "",
           f"### With the MDSE case added: the 11-case study (Tables {t['params11']}, {t['energy11']}, "
           f"Figure {t['fig11']})", "",
           *params_table(w, d, res["truth"], key11=True), "", fit_line(w), "",
           f"Parameter changes from the 10-case fit: complex median {ch['complex']['median_abs_change_percent']:.3g} % "
           f"of each value (max {ch['complex']['max_abs_change_percent']:.3g} %, on the smallest entries; "
           f"max {ch['complex']['max_change_percent_of_largest_diagonal']:.3g} % of the largest diagonal), simple "
           f"median {ch['simple']['median_abs_change_percent']:.3g} % (max "
           f"{ch['simple']['max_change_percent_of_largest_diagonal']:.3g} % of the largest diagonal); "
           f"dissertation: {d['change11']}.", "",
           *energy_rows(j2["isolated"], d["energy11"], t["energy11"]), "",
           f"(Recomputed MDSE loading, dominant {j2['isolated']['dominant']['name']}; under the first loading: "
           f"R = {pct(fixed['isolated']['strain_energy']['relative_difference'], 2)} isolated, "
           f"{pct(fixed['assembly']['strain_energy']['relative_difference'], 2)} in the structure.) In the structure "
           f"with the MDSE case: R = {pct(j2['assembly']['strain_energy']['relative_difference'], 2)} "
           f"{iv(j2['assembly']['strain_energy'].get('uncertainty'))}, simple error / infinitely-flexible error = "
           f"{pct(j2['assembly']['strain_energy']['simple_error_over_infinitely_flexible_error'])}.", "",
           f"![assembly, 11 cases](chapter6/{name}/energy_assembly_mdse.png) "
           f"![isolated, 11 cases](chapter6/{name}/energy_isolated_mdse.png)", ""]
    return out


def summary(res: dict) -> dict:
    j, w = res["joints"][0], res["with_mdse"]["joints"][0]
    return dict(dom=j["isolated"]["dominant"]["name"], share=j["isolated"]["dominant"]["share"],
                R=j["isolated"]["strain_energy"]["relative_difference"],
                Rint=j["isolated"]["strain_energy"].get("uncertainty"),
                Rt=j["isolated"]["strain_energy"]["relative_difference_truth_vs_simple"],
                Ra=j["assembly"]["strain_energy"]["relative_difference"],
                ratio=j["assembly"]["strain_energy"]["simple_error_over_infinitely_flexible_error"],
                dom_a=j["assembly"]["dominant"]["name"],
                R11=w["isolated"]["strain_energy"]["relative_difference"],
                Rt11=w["isolated"]["strain_energy"]["relative_difference_truth_vs_simple"],
                chg=res["with_mdse"]["parameter_changes"]["complex"]["median_abs_change_percent"],
                chi_s=res["models"]["simple"]["fit"]["reduced_chi2"],
                bic=res["model_selection"]["preferred_by_bic"])


def robustness(runs: dict) -> list[str]:
    out = ["## Robustness: seeds 1-8", "",
           "Each row a new simulation (seed) of the same truth, the full `blackbox compare`. R: isolated "
           "joint; R_true = (E_truth - E_simple)/E_truth at the same loading; 'after': with the MDSE case.", "",
           "| structure | seed | dominant (share) | R [95 % interval] | R_true | R in structure | "
           "simple err / inf.-flex. err | R after | R_true after | complex median change | simple reduced chi2 |",
           "|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, rows in runs.items():
        for seed, s in rows:
            out.append(f"| {name} | {seed} | {s['dom']} ({100 * s['share']:.0f} %) | {pct(s['R'])} {iv(s['Rint'])} | "
                       f"{pct(s['Rt'])} | {pct(s['Ra'])} | {pct(s['ratio'])} | {pct(s['R11'])} | {pct(s['Rt11'])} | "
                       f"{s['chg']:.2g} % | {s['chi_s']:.3g} |")
    out.append("")
    for name, rows in runs.items():
        R = np.array([s["R"] for _, s in rows])
        Rt = np.array([s["Rt"] for _, s in rows])
        doms = sorted({s["dom"] for _, s in rows})
        shares = [s["share"] for _, s in rows]
        out.append(f"- {name}: R = {100 * R.mean():.0f} % on average "
                   f"(range {100 * R.min():.0f}-{100 * R.max():.0f} %), "
                   f"R_true {100 * Rt.mean():.0f} % ({100 * Rt.min():.0f}-{100 * Rt.max():.0f} %); dominant DOF "
                   f"{', '.join(doms)} with {100 * min(shares):.0f}-{100 * max(shares):.0f} % of the squared load.")
    return out + [""]


def stiffness_scan(rows) -> list[str]:
    out = ["## The assembly error ratio and the joint's stiffness (cube, seed 1)", "",
           "The truth K_C of Table 5.12 times a factor: the dissertation's '~30 %' (simple-model error as a "
           "fraction of the infinitely-flexible error) depends on how flexible the joint is next to the "
           "members around it.", "",
           "| K_C factor | R isolated | R in structure | simple err / inf.-flex. err | R_true in structure |",
           "|---|---|---|---|---|"]
    for f, res in rows:
        j = res["joints"][0]
        a = j["assembly"]["strain_energy"]
        out.append(f"| {f:g} | {pct(j['isolated']['strain_energy']['relative_difference'])} | "
                   f"{pct(a['relative_difference'])} | {pct(a['simple_error_over_infinitely_flexible_error'])} | "
                   f"{pct(a['relative_difference_truth_vs_simple'])} |")
    return out + [""]


def absolute_vs_relative(rel: dict, ab: dict) -> list[str]:
    def ident(res):
        p = res["models"]["complex"]["parameters"]
        return sum(q["identifiable"] for q in p), len(p)

    def width(res):
        p = res["models"]["complex"]["parameters"]
        wv = [(q["ci_high"] - q["ci_low"]) / abs(q["value"]) for q in p
              if q["ci_low"] is not None and q["ci_high"] is not None and q["name"] in ("k11", "k33", "k44", "k66")]
        return f"{100 * np.median(wv):.0f} %" if wv else "n/a (not identifiable)"

    out = ["## Why relative (reference-point) rotations (cube, seed 1)", "",
           "The same truth measured with 5 % noise on the *absolute* rotations (no reference grid): the "
           "relative rotations that carry the joint's stiffness are ~1/400 of the absolute ones (the joint "
           "is 30-300 times stiffer than the halfway springs, `studies/chapter3.md`), so 5 % of the absolute "
           "rotation buries them.", "",
           "| measurement | complex parameters identifiable | median 95 % CI width / value (k11, k33, k44, k66) | "
           "R isolated [95 % interval] | R_true | BIC prefers |", "|---|---|---|---|---|---|"]
    for lab, res in (("relative to branch 1's grid (Section 5.2)", rel), ("absolute", ab)):
        j = res["joints"][0]["isolated"]["strain_energy"]
        n_id, n = ident(res)
        out.append(f"| {lab} | {n_id} of {n} (rank {res['models']['complex']['rank']}) | {width(res)} | "
                   f"{pct(j['relative_difference'])} {iv(j.get('uncertainty'))} | "
                   f"{pct(j['relative_difference_truth_vs_simple'])} | {res['model_selection']['preferred_by_bic']} |")
    return out + [""]


def _vals(runs, name, key):
    return np.array([sm[key] for _, sm in runs[name]])


def _range(runs, name, key) -> str:
    v = _vals(runs, name, key)
    return f"{100 * v.min():.1f}-{100 * v.max():.1f} %"


def findings(res: dict, runs: dict) -> list[str]:
    """The dissertation's findings with verdicts from explicit thresholds over seeds 1-8."""
    c, k = summary(res["cube"]), summary(res["car"])
    rows = []

    def verdict(name, key, test, yes, no):
        v = _vals(runs, name, key)
        ok = np.array([test(x) for x in v])
        return yes if ok.all() else (no if not ok.any() else f"in {ok.sum()} of {len(ok)} seeds")

    def dom(name):
        sh = _vals(runs, name, "share")
        doms = sorted({sm["dom"] for _, sm in runs[name]})
        return (f"{'/'.join(doms)}, {100 * sh.min():.1f}-{100 * sh.max():.1f} %; "
                + verdict(name, "share", lambda x: x > 0.9, "yes", "no") + " (> 90 % on one DOF)")

    rows.append(("the isolated-joint MDSE loading is practically a unit moment on one DOF",
                 "cube theta_x2, car theta_z1", f"{c['dom']} {100 * c['share']:.1f} %",
                 f"{k['dom']} {100 * k['share']:.1f} %",
                 f"cube: {dom('cube')}; car: {dom('car')}"))
    for key, what, diss, test, yes, no in (
            ("R", "large strain-energy difference for the isolated joint, R", "76 % (Table 6.3), 83 % (Table 6.10)",
             lambda x: x > 0.3, "yes (> 30 %)", "no (< 30 %)"),
            ("Rt", "... the true joint vs the simple fit, R_true (same loading)", "(no truth in the tables)",
             lambda x: x > 0.3, "yes (> 30 %)", "no (< 30 %)"),
            ("Ra", "small difference in the structure", "'no significant difference' (Figs. 6.2, 6.4)",
             lambda x: x < 0.1, "yes (< 10 %)", "no (> 10 %)"),
            ("ratio", "simple-model error / infinitely-flexible error in the structure", "roughly 30 %",
             lambda x: 0.1 < x < 0.6, "yes (10-60 %)", "no (outside 10-60 %)"),
            ("chg", "re-identification with the MDSE case changes the (complex) parameters little",
             "< 2 % (cube), < 3 % (car)", lambda x: x < 5, "yes (median change < 5 %)", "no (median change > 5 %)"),
            ("R11", "the models still differ after it (coupling, not a poor experiment)",
             "75 %, 83 % (Tables 6.7, 6.14)",
             lambda x: x > 0.3, "yes (R > 30 %)", "no (R < 30 %)")):
        fmt = (lambda v: f"{v:.2g} %") if key == "chg" else pct
        rng = (lambda name: f"{_vals(runs, name, key).min():.2g}-{_vals(runs, name, key).max():.2g} %") \
            if key == "chg" else (lambda name: _range(runs, name, key))
        rows.append((what, diss, f"{fmt(c[key])} ({rng('cube')})", f"{fmt(k[key])} ({rng('car')})",
                     f"cube: {verdict('cube', key, test, yes, no)}; car: {verdict('car', key, test, yes, no)}"))
    out = ["## The dissertation's findings, checked", "",
           "Our numbers: seed 1 (seeds 1-8 in brackets). Verdicts from the thresholds given, over all eight seeds.", "",
           "| finding | dissertation | cube | car | holds here? |", "|---|---|---|---|---|"]
    return out + [f"| {' | '.join(r)} |" for r in rows] + [""]


def top_changes(res: dict, n: int = 3) -> list[str]:
    ps = res["with_mdse"]["parameter_changes"]["complex"]["parameters"]
    top = sorted(ps, key=lambda p: -abs(p["change_percent"] or 0.0))[:n]
    return [f"{p['name']} {p['change_percent']:+.0f} % (of {p['before']:.3g})" for p in top]


def discussion(res: dict, runs: dict, scan, absolute: dict) -> list[str]:
    c, k = summary(res["cube"]), summary(res["car"])
    sc = {f: x["joints"][0]["assembly"]["strain_energy"]["simple_error_over_infinitely_flexible_error"]
          for f, x in scan}
    cube_asm = res["cube"]["joints"][0]["assembly"]["strain_energy"]
    m = lambda name, key: 100 * float(np.mean(_vals(runs, name, key)))          # noqa: E731
    r = lambda name, key: _range(runs, name, key)                               # noqa: E731
    car_doms = sorted({sm["dom"] for _, sm in runs["car"]})
    cube_simple = res["cube"]["models"]["simple"]["clamped_stiffness"][0]["K_C"]
    ab = absolute["models"]["complex"]
    return ["## Discussion", "",
            "**Eq. 34-35 are implemented as the dissertation did.** Fed the dissertation's own estimates (Table "
            "6.1), `blackbox.comparison` reproduces Tables 6.2, 6.3 and 6.4 to their printed digits (also a test, "
            "`tests/test_compare.py`). The tables' 'strain energy' is F^T C F, twice eq. 35's 1/2 F^T C F; "
            "`comparison.json` has E = 1/2 F^T C F, the tables above 2E; R is the same either way. The car's "
            "Tables 6.9-6.11 are not consistent with each other or with Table 6.8's simple K_C (section above), "
            "so the car cannot be checked this way.", "",
            f"**One dominant DOF.** The cube's isolated-joint MDSE loading is a unit moment on {c['dom']} in every "
            f"seed ({r('cube', 'share')} of the squared load). The dissertation has theta_x2; the cube joint "
            "is symmetric under the mirror x<->z that swaps branch 1 (member 3-7, along -z) and branch 2 (member "
            "7-8, along -x) and maps theta_x2 onto theta_z1 (k33 = k44 = 0.3122E6 in Table 5.12). Which of the "
            "two equally soft DOFs wins depends on which one the simple fit makes too stiff: the dissertation's "
            f"simple fit has k44 = 0.1328E7 > k33 = 0.4401E6, ours k33 = {cube_simple['k33']:.4g} > k44 = "
            f"{cube_simple['k44']:.4g}. The car joint has the same pair (k33 = k44 = 0.1567E6 in Table 5.18) and "
            f"its MDSE loading lies in that plane: mostly {' or '.join(car_doms)}, {r('car', 'share')} of the "
            "squared load on one DOF -- a unit moment in some seeds, a mix in others. The rule behind it: the "
            "flexibility difference is largest along the softest directions of the joint that the simple model "
            "gets wrong.", "",
            f"**Large isolated-joint difference: the cube yes, the car no.** The cube's coupling is real: the true "
            f"joint and our simple fit differ by R_true = {m('cube', 'Rt'):.0f} % ({r('cube', 'Rt')}) under the "
            f"MDSE loading, and the fitted complex model sees the same (R = {m('cube', 'R'):.0f} %, narrow "
            "interval). Smaller than the dissertation's 76 % because our simple fit is closer to the truth: with "
            "the relative rotations of Section 5.2 the weighted least squares sends the branch-1-2 springs to 0 "
            "(Table 5.12's k14, k25, k36 are positive: the best simple model would want *negative* springs "
            "there), where the dissertation's simple fit keeps them at 0.19-0.73E6. For the car R = "
            f"{m('car', 'R'):.0f} % ({r('car', 'R')}) and R_true = {m('car', 'Rt'):.0f} % ({r('car', 'Rt')}): "
            "Table 5.18 couples the car joint's soft DOFs weakly (k13 = k23 = k36 = 0.02E6 against k33 = "
            "0.16E6), so a simple model represents them well. R's interval (from the fits' covariances) is "
            "wide for the car: the 10-case complex fit is poorly determined along the soft directions, and the "
            "MDSE loading, chosen to maximise the difference of the two *fitted* models, partly finds that "
            "estimation error (seed 1: R = "
            f"{pct(k['R'])} against R_true = {pct(k['Rt'])}). The dissertation's 83 % rests on a simple fit "
            "with k33 = 1.39E7, 90 times the actual 0.157E6 (Table 6.8) although a simple model can match k33 "
            "(it is kz12 + kz13): far from the best simple model. Hence `blackbox compare` reports R's spread "
            "and, when a truth is known, R_true.", "",
            f"**Small difference in the structure: holds**: R = {m('cube', 'Ra'):.0f} % (cube) and "
            f"{m('car', 'Ra'):.0f} % (car) where the isolated joints differ by {m('cube', 'R'):.0f} % and "
            f"{m('car', 'R'):.0f} %.", "",
            f"**Simple-model error ~30 % of the infinitely-flexible error: not here ({m('cube', 'ratio'):.1f} % "
            f"cube, {m('car', 'ratio'):.1f} % car).** The ratio compares the joint-model error with the error of "
            "dropping the joint's stiffness altogether. Table 5.12's joint is 30-300 times stiffer than the "
            "'halfway' springs of Chapter 5 (`studies/chapter3.md`), so K_J = 0 changes the structure's energy "
            f"by a factor ~{cube_asm['infinitely_flexible'] / cube_asm['complex']:.0f} "
            "and any joint-model error is small next to that. A softer joint raises the ratio (scan above: "
            f"{100 * sc[0.1]:.1f} % at 1/10, {100 * sc[0.01]:.1f} % at 1/100 of Table 5.12) but not to 30 % in "
            "this range. The dissertation's Figures 6.2 and 6.4 are not in the text, so its energies cannot be "
            "compared directly.", "",
            "**The 11-case study.** The MDSE case (simulated from the same truth, scaled so that its largest joint "
            "rotation equals the largest of the study's cases) changes the cube's complex estimate by a median "
            f"{np.mean(_vals(runs, 'cube', 'chg')):.1f} % (per seed {_vals(runs, 'cube', 'chg').min():.1f}-"
            f"{_vals(runs, 'cube', 'chg').max():.1f} %; the largest relative changes are on the smallest entries, "
            f"seed 1: {', '.join(top_changes(res['cube']))}) and leaves R at {m('cube', 'R11'):.0f} %: the "
            "difference is coupling, as the dissertation concludes. The car's complex estimate moves by a median "
            f"{_vals(runs, 'car', 'chg').min():.0f}-{_vals(runs, 'car', 'chg').max():.0f} % per seed and R falls "
            f"to {m('car', 'R11'):.0f} % ({r('car', 'R11')}), close to R_true after ({r('car', 'Rt11')}): there "
            "the first difference was partly a weak experiment in the MDSE direction, which is what the MDSE "
            "case repairs. Without a truth (real data) `blackbox compare` writes the loading as "
            "`mdse_loads.csv`, the recommended next experiment.", "",
            "**Why the reference point.** With 5 % noise on the absolute rotations the near-rigid joint is not "
            f"identifiable: the complex model's rank is {ab['rank']} of 21, every parameter is flagged, and R "
            "and BIC are meaningless (last section). Section 5.2's relative measurement makes Chapter 6 "
            "possible on these truths, so every study here uses `reference_grid` = the joint's branch-1 grid.", ""]


def main() -> None:
    BUILD.mkdir(parents=True, exist_ok=True)
    res = {name: headline(name) for name in ("cube", "car")}
    runs = {name: [(s, summary(res[name]) if s == SEED else summary(quiet_compare(name, f"{name}_s{s}", s)))
                   for s in SEEDS] for name in ("cube", "car")}
    scan = [(1.0, res["cube"])] + [(f, quiet_compare("cube", f"cube_x{f:g}", SEED, scale=f)) for f in (0.1, 0.01)]
    absolute = quiet_compare("cube", "cube_absolute", SEED, relative=False)
    out = ["# Chapter 6 on the fixtures: comparison of the simple and complex joint models", "",
           "Generated by `python studies/chapter6.py` (reference adapter; `blackbox simulate` + `blackbox "
           "compare`). Discussion at the end.", "",
           "**Setup.** Truths: the cube joint J7 = Table 5.12 as printed, the car joint JB = Table 5.18 as "
           "printed (complex model, branch 3 clamped). Measurements (`blackbox simulate`, seed 1): the joint's "
           "12 DOFs in load cases L1-L12, 5 % noise (floored at 2 % of the case's largest quantity of the "
           "same kind), the branch rotations measured relative to branch 1's grid (Section 5.2's reference "
           "point, see the last section for why); L11 and L12 are held out, so both models are fitted to 10 "
           "cases as in the dissertation. `blackbox compare` condenses once (1 solver run) and identifies "
           "the simple model (start: the fixture's `initial`) and the complex model (start: the simple fit's "
           "K_C). E = 1/2 F^T C F (eq. 35); the dissertation's tables list F^T C F = 2E, so the tables "
           "below show 2E. N, m, rad.", "",
           *k34_check(), *dissertation_check(), *findings(res, runs),
           *structure_section("cube", res["cube"]), *structure_section("car", res["car"]),
           *robustness(runs), *stiffness_scan(scan), *absolute_vs_relative(res["cube"], absolute),
           *discussion(res, runs, scan, absolute)]
    (ROOT / "studies" / "chapter6.md").write_text("\n".join(out))
    print("\n".join(out))


if __name__ == "__main__":
    main()
