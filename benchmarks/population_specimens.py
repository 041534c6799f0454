"""Specimen studies of one joint design, simulated from a log-normal population (for the
population benchmark, the tests and the worked example).

``make_specimens(STUDY, OUT, n, centre, spread, seed)`` writes ``OUT/<prefix>_01`` ...: copies of
the study whose measurements are simulated (``blackbox simulate``, the study's noise model from
its ``truth.toml`` when it has one, else 5 %) at joint parameters drawn per specimen and per
parameter from ``log k ~ N(log centre, log(1 + spread^2))``. ``population_truth.json`` beside
them records the population and every specimen's truth.
"""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import numpy as np

from blackbox.commands import simulate
from blackbox.declared import declared_model
from blackbox.study import load_study


def _toml_value(v) -> str:
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return repr(v)


def make_specimens(study: str | Path, out: str | Path, n: int, centre, spread, *, seed: int = 1,
                   prefix: str = "specimen", noise: dict | None = None, measure: dict | None = None,
                   outliers: dict[int, float] | None = None) -> list[Path]:
    """``n`` specimen studies (module docstring); ``centre``/``spread``: one value or one per
    parameter of the study's declared model; ``outliers``: ``{specimen index: factor}`` scales
    that specimen's first parameter (a specimen that does not belong)."""
    study = Path(study)
    st = load_study(study)
    dm = declared_model(st)
    labels = dm.param_labels
    p = len(labels)
    centre = np.broadcast_to(np.asarray(centre, float), (p,))
    spread = np.broadcast_to(np.asarray(spread, float), (p,))
    tau = np.sqrt(np.log1p(spread ** 2))
    rng = np.random.default_rng(seed)
    base = {}
    if (study / "truth.toml").is_file():
        base = tomllib.loads((study / "truth.toml").read_text())
    noise = noise if noise is not None else base.get("noise", {"relative": 0.05})
    measure = measure if measure is not None else base.get("measure", {"joint": True})
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    folders, record = [], []
    for s in range(n):
        k = np.exp(np.log(centre) + tau * rng.standard_normal(p))
        if outliers and s in outliers:
            k[0] *= outliers[s]
        lines = [f"seed = {seed * 1000 + s}", ""]
        for jname in dict.fromkeys(j for j, _ in labels):
            vals = {name: float(v) for (j, name), v in zip(labels, k) if j == jname}
            lines += ["[[joints]]", f'name = "{jname}"', 'model = "simple"',
                      "values = {" + ", ".join(f"{a} = {b!r}" for a, b in vals.items()) + "}", ""]
        lines += ["[noise]"] + [f"{a} = {_toml_value(b)}" for a, b in noise.items()] + [""]
        lines += ["[measure]"] + [f"{a} = {_toml_value(b)}" for a, b in measure.items()] + [""]
        folder = out / f"{prefix}_{s + 1:02d}"
        truth = out / f".{prefix}_{s + 1:02d}.truth.toml"
        truth.write_text("\n".join(lines))
        res = simulate.run(st, truth)
        folder.mkdir()
        res.write(folder)
        truth.unlink()
        folders.append(folder)
        record.append({"study": folder.name, "parameters": [{"joint": j, "name": nm, "value": float(v)}
                                                            for (j, nm), v in zip(labels, k)]})
    (out / "population_truth.json").write_text(json.dumps(
        {"source": str(study), "seed": seed, "parameters": [
            {"joint": j, "name": nm, "center": float(c), "spread": float(sp)}
            for (j, nm), c, sp in zip(labels, centre, spread)], "specimens": record}, indent=2))
    return folders
