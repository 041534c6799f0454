"""`blackbox bench` writes the rows of docs/commands.md; its methods reach the same estimate.

Timings are not asserted (machines are noisy; the figures go in the closing note): only the
structure of the output and the solver-run counts, which are exact.
"""

import json

from blackbox.cli import main


def test_bench_cube_simple(tmp_path):
    assert main(["bench", "--out", str(tmp_path), "--cases", "cube-simple", "--repeat", "1"]) == 0
    rows = json.loads((tmp_path / "bench.json").read_text())
    by = {r["method"]: r for r in rows}
    assert set(by) == {"blackbox", "standard", "forward", "central"}
    for r in rows:
        assert {"case", "method", "adapter", "wall_s", "solver_runs", "right_hand_sides",
                "ratio_to_blackbox"} <= set(r)
        assert r["case"] == "cube-simple" and r["adapter"] == "reference" and r["converged"]
        assert r["same_estimate_as_blackbox"]
    it = by["blackbox"]["iterations"]
    assert by["blackbox"]["solver_runs"] == 1                    # the whole point of Chapter 3
    assert by["blackbox"]["right_hand_sides"] == 12 + 20         # n_B + L in one batch
    # forward: one run for the prediction plus one per parameter (9), every iteration
    assert by["forward"]["solver_runs"] >= it * 9
    assert by["central"]["solver_runs"] >= it * 18
    assert (tmp_path / "bench.md").read_text().startswith("# Benchmark")
