"""Independent work on a Dask cluster (``blackbox.parallel``, ``blackbox batch``).

The clusters are real: ``LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
host="127.0.0.1", dashboard_address=None)`` started here, over loopback TCP, each closed by its
fixture or test. What runs on a cluster is compared with the serial run, bit for bit where the
arithmetic is the same (every task is the serial computation of one item; nothing is reduced
across workers). A worker killed with SIGKILL mid-task: the task is run again on the other
worker, and the solver process it had started is gone.
"""

from __future__ import annotations

import json
import os
import signal
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from blackbox.commands import batch
from blackbox.commands.output import write_output
from blackbox import parallel as par
from blackbox.parallel import SerialExecutor, TaskFailure, chunked, coverage_study, pack_study, unpack_study

from conftest import FIXTURES, copy_fixture, needs_mystran

distributed = pytest.importorskip("distributed")
import cloudpickle  # noqa: E402  (a dependency of distributed)

# the helper tasks below travel to the workers by value (the workers cannot import this module)
cloudpickle.register_pickle_by_value(sys.modules[__name__])


def _square(x):
    if x == 3:
        raise ValueError("three is not allowed")
    return x * x


def _ident(x):
    return x


@pytest.fixture(scope="module")
def cluster():
    ex = par.DaskExecutor(workers=2)
    try:
        # both workers up before any test (on a loaded machine the second can come late, and
        # a test that counts chunked runs would see one worker)
        ex.client.wait_for_workers(2, timeout=120)
        yield ex
    finally:
        ex.close()


def _result_without_times(files: dict) -> dict:
    d = json.loads(files["result.json"])
    d["solver"].pop("wall_s")
    return d


# --------------------------------------------------------------------------------------------
# the interface, serially
# --------------------------------------------------------------------------------------------
def test_serial_map_keeps_order_reports_progress_and_failures():
    seen = []
    ex = SerialExecutor(progress=lambda d, t, f: seen.append((d, t, f)))
    assert ex.map(_square, [1, 2, 4]) == [1, 4, 16]
    assert seen == [(0, 3, 0), (1, 3, 0), (2, 3, 0), (3, 3, 0)]
    out = ex.map(_square, [1, 3, 2], errors="return")
    assert out[0] == 1 and out[2] == 4
    assert isinstance(out[1], TaskFailure) and out[1].index == 1 and "three" in out[1].message
    with pytest.raises(ValueError, match="three"):
        ex.map(_square, [3])


def test_chunked_covers_every_index_once_in_order():
    for n, k in [(10, 3), (3, 8), (1, 1), (400, 8)]:
        parts = chunked(n, k)
        assert [i for r in parts for i in r] == list(range(n))
        assert len(parts) == min(n, k)
        assert max(len(r) for r in parts) - min(len(r) for r in parts) <= 1


def test_without_dask_workers_runs_serially_and_says_how_to_enable(monkeypatch):
    monkeypatch.setattr(par, "dask_available", lambda: False)
    said = []
    ex = par.make_executor(workers=2, warn=said.append)
    assert isinstance(ex, SerialExecutor)
    assert "pip install 'blackbox-joints[distributed]'" in said[0]
    with pytest.raises(ValueError, match=r"blackbox-joints\[distributed\]"):
        par.make_executor(scheduler="tcp://127.0.0.1:1")


def test_study_package_travels_without_the_folder(tmp_path):
    """A study whose deck lives outside its folder (with an INCLUDE), in a folder the user
    allows, is packed with the deck, and rebuilt elsewhere it reads as the original. Without that
    permission the outside deck is refused, not packed."""
    from blackbox.errors import StudyError
    from blackbox.study import ALLOW_OUTSIDE, load_study

    ext = tmp_path / "decks"
    ext.mkdir()
    text = (FIXTURES / "cube" / "model.bdf").read_text()
    lines = text.splitlines()
    cut = next(i for i, ln in enumerate(lines) if ln.startswith("GRID"))
    (ext / "grids.bdf").write_text("\n".join(ln for ln in lines if ln.startswith("GRID")) + "\n")
    (ext / "main.bdf").write_text("\n".join(lines[:cut] + ["INCLUDE 'grids.bdf'"]
                                            + [ln for ln in lines[cut:] if not ln.startswith("GRID")]) + "\n")
    study = copy_fixture("cube", tmp_path / "cube", "model.bdf")
    toml = (study / "study.toml").read_text().replace('deck = "model.bdf"', f'deck = "{ext / "main.bdf"}"')
    (study / "study.toml").write_text(toml)
    (study / ".blackbox_cache").mkdir()
    (study / ".blackbox_cache" / "x.bbc").write_bytes(b"not travelling")
    with pytest.raises(StudyError, match="leads outside the study folder"):
        pack_study(study)
    allowed = ALLOW_OUTSIDE.set((ext,))
    try:
        pkg = pack_study(study)
        assert not any(k.startswith(".blackbox_cache") for k in pkg.files)
        assert {"_external/main.bdf", "_external/grids.bdf"} <= set(pkg.files)
        rebuilt = unpack_study(pkg, tmp_path / "elsewhere")
        a, b = load_study(study, need_measurements=True), load_study(rebuilt, need_measurements=True)
    finally:
        ALLOW_OUTSIDE.reset(allowed)
    assert b.deck_path.is_relative_to(rebuilt)
    assert sorted(a.deck.grids) == sorted(b.deck.grids) and len(a.measurements) == len(b.measurements)
    with pytest.raises(ValueError, match="not a study folder"):
        pack_study(tmp_path / "decks")


def test_a_lost_task_is_a_row_not_lost_work(tmp_path):
    """The executor reports a task whose worker died too often as lost: that study is a row
    with status 'lost', the others are written."""
    class Losing(SerialExecutor):
        def map(self, fn, items, *, errors="raise", progress=None):
            items = list(items)
            out = [fn(x) for x in items[:-1]]
            return out + [TaskFailure(len(items) - 1, "KilledWorker", "worker died 4 times", lost=True)]

    res = batch.run([FIXTURES / "cube", FIXTURES / "cube_joint_only"], executor=Losing(), cache=False,
                    options={"profile": False})
    assert [o.status for o in res.outcomes] == ["ok", "lost"]
    files = write_output(tmp_path / "out", "batch", res.write)
    assert "summary.csv" in files
    rows = (tmp_path / "out" / "summary.csv").read_text().splitlines()
    assert rows[1].startswith("cube,ok,") and rows[2].startswith("cube_joint_only,lost,")
    assert "KilledWorker" in rows[2]
    assert (tmp_path / "out" / "cube" / "result.json").is_file()


# --------------------------------------------------------------------------------------------
# on a LocalCluster
# --------------------------------------------------------------------------------------------
def test_cluster_map_keeps_order_reports_progress_and_failures(cluster):
    seen = []
    assert cluster.workers == 2
    assert cluster.map(_ident, list(range(20)), progress=lambda d, t, f: seen.append((d, t, f))) == list(range(20))
    assert seen[0] == (0, 20, 0) and seen[-1] == (20, 20, 0) and len(seen) == 21
    out = cluster.map(_square, [1, 3, 2], errors="return")
    assert out[0] == 1 and out[2] == 4 and isinstance(out[1], TaskFailure) and not out[1].lost
    with pytest.raises(ValueError, match="three"):
        cluster.map(_square, [2, 3])


def test_batch_on_cluster_equals_serial_and_shares_the_cache(cluster, tmp_path):
    """Two studies and one broken one: the cluster's outputs are the serial ones (the fit bit
    for bit); the broken study is a row; the second run reads every study's batch back from the
    study's own cache, filled by the workers."""
    studies = [copy_fixture(n, tmp_path / n) for n in ("cube", "car")]
    broken = copy_fixture("cube", tmp_path / "broken")
    (broken / "measurements.csv").write_text("case,grid,component,value,sigma\nNOPE,7,1,1.0,0.1\n")
    folders = [*studies, broken]
    opts = {"profile": False}
    ser = batch.run(folders, cache=False, options=opts)
    par_ = batch.run(folders, executor=cluster, cache=True, options=opts)
    assert [o.status for o in ser.outcomes] == ["ok", "ok", "bad_input"]
    assert [o.status for o in par_.outcomes] == [o.status for o in ser.outcomes]
    for a, b in zip(par_.outcomes[:2], ser.outcomes[:2]):
        assert a.parameters == b.parameters and a.reduced_chi2 == b.reduced_chi2
        assert _result_without_times(a.files) == _result_without_times(b.files)
        assert a.worker != "" and a.worker.split(":")[1] != str(os.getpid())   # ran in a worker process
    assert "NOPE" in par_.outcomes[2].message
    assert all(any((s / ".blackbox_cache").rglob("*.bbc")) for s in studies)
    again = batch.run(folders, executor=cluster, cache=True, options=opts)
    assert [o.solver["cached_batches"] for o in again.outcomes[:2]] == [1, 1]
    assert [o.solver["runs"] for o in again.outcomes[:2]] == [0, 0]
    assert [o.parameters for o in again.outcomes] == [o.parameters for o in par_.outcomes]

    out = tmp_path / "out"
    files = write_output(out, "batch", par_.write)
    assert {"cube/", "car/", "broken/", "summary.csv", "summary.md"} <= set(files)
    header, *rows = (out / "summary.csv").read_text().splitlines()
    cols = header.split(",")
    assert cols[:3] == ["study", "status", "reduced_chi2"] and "J7.kx12" in cols and "JB.kx12" in cols
    assert [r.split(",")[0] for r in rows] == ["cube", "car", "broken"]
    assert (out / "cube" / "report.md").is_file() and (out / "broken" / "error.txt").is_file()
    assert "bad_input" in (out / "summary.md").read_text()


def test_coverage_replicates_on_cluster_equal_serial(cluster):
    """Coverage replicates: the same estimates and intervals bit for bit, whatever the
    executor and the chunking, and the same as identifying each replicate directly."""
    from blackbox.identification import identify
    from blackbox.study import load_study
    from blackbox.adapters import make_adapter_for
    from blackbox.declared import declared_model

    study = load_study(FIXTURES / "cube", need_measurements=True)
    dm = declared_model(study)
    model = dm.condense(make_adapter_for(study, cache=False))
    truth, k0 = np.full(9, 1.0e4), np.full(9, 1.0e3)
    kw = dict(replicates=12, holdout=["L20"], profile=False)
    cases = list(range(len(model.c.cases)))
    a = coverage_study(model, truth, dm.boundary, cases, k0, **kw)
    b = coverage_study(model, truth, dm.boundary, cases, k0, executor=cluster, chunks=5, **kw)
    for x, y in [(a.k, b.k), (a.ci_low, b.ci_low), (a.ci_high, b.ci_high), (a.reduced_chi2, b.reduced_chi2)]:
        assert np.array_equal(x, y)
    assert a.converged.all() and a.coverage().shape == (9,)
    # replicate 3 identified directly, with the noise of the coverage test of test_identification.py
    from test_identification import simulate
    obs = simulate(model, truth, dm.boundary, cases, np.random.default_rng([2024, 3]))
    fit_obs, hold = obs.split(["L20"])
    r = identify(model, fit_obs, k0, holdout=hold, profile=False)
    assert np.array_equal(r.k, a.k[3]) and np.array_equal(r.ci_low, a.ci_low[3])


def test_bootstrap_refits_on_cluster_match_identify(cluster):
    from blackbox.study import load_study
    from blackbox.adapters import make_adapter_for
    from blackbox.declared import declared_model
    from blackbox.identification import identify

    study = load_study(FIXTURES / "cube", need_measurements=True)
    dm = declared_model(study)
    model = dm.condense(make_adapter_for(study, cache=False))
    obs, _ = dm.observations(model.c.cases)
    r = identify(model, obs, dm.k0, profile=False, bootstrap=16, seed=3)
    ser = par.bootstrap_samples(model, obs, r, 16, seed=3)
    dist = par.bootstrap_samples(model, obs, r, 16, seed=3, executor=cluster)
    assert np.array_equal(ser, dist)                       # same draws, same refits: bit for bit
    assert ser.shape == r.bootstrap_samples.shape
    np.testing.assert_allclose(ser, r.bootstrap_samples, rtol=1e-9)


def _shared_probe(x, shared):
    """A task of ``map_shared``: which process ran it, which object it was given (kept alive on
    the worker, so that two deserialised copies can never share an id), and ``x + shared[0]``."""
    try:
        from distributed import get_worker
        get_worker().__dict__.setdefault("_test_kept", []).append(shared)
    except ValueError:                   # not on a worker: the serial executor
        pass
    return os.getpid(), id(shared), x + shared[0]


def test_a_shared_value_travels_to_each_worker_once(cluster):
    """``share`` + ``map_shared`` give ``[fn(x, value)]`` in order, serially and on the cluster;
    on the cluster the value is on every worker before the tasks run (scattered with broadcast)
    and every task of a worker gets the one object that worker received (not a copy per task)."""
    value = (5, np.arange(200_000.0))
    ser = SerialExecutor()
    with ser.share(value) as handle:
        assert [r[2] for r in ser.map_shared(_shared_probe, handle, range(4))] == [5, 6, 7, 8]
    with cluster.share(value) as handle:
        assert len(cluster.client.who_has([handle])[handle.key]) == 2
        out = cluster.map_shared(_shared_probe, handle, list(range(16)))
    assert [r[2] for r in out] == [5 + x for x in range(16)]
    ids: dict[int, set] = {}
    for pid, oid, _ in out:
        ids.setdefault(pid, set()).add(oid)
    assert all(len(v) == 1 for v in ids.values()), ids


def test_identify_bootstrap_on_workers_equals_serial(tmp_path, capsys):
    """``blackbox identify --workers 2`` with ``[identification] bootstrap = 24``: the bootstrap
    refits run on a local cluster of 2 workers (the command says so) and result.json is the
    serial one, bit for bit (the same draws, each refit the serial computation from the same
    start; the refits are small enough that BLAS does not split them)."""
    from blackbox.cli import main

    study = copy_fixture("cube", tmp_path / "cube", "*.png")
    toml = (study / "study.toml").read_text().replace("confidence = 0.95", "confidence = 0.95\nbootstrap = 24")
    (study / "study.toml").write_text(toml)
    docs = []
    for name, extra in (("serial", []), ("workers", ["--workers", "2"])):
        assert main(["identify", str(study), "--out", str(tmp_path / name), "--no-cache", *extra]) == 0
        docs.append(_result_without_times({"result.json": (tmp_path / name / "result.json").read_text()}))
    out = capsys.readouterr().out
    assert "parametric bootstrap: 24 refits on 2 workers" in out
    assert all("bootstrap_ci" in p for p in docs[0]["parameters"])
    assert docs[1] == docs[0]


class _Counting:
    """An executor that counts what goes through ``share`` / ``map_shared`` (delegating)."""

    def __init__(self, inner):
        self.inner, self.shared, self.tasks = inner, 0, 0
        self.workers = inner.workers

    def share(self, value):
        self.shared += 1
        return self.inner.share(value)

    def map_shared(self, fn, shared, items, **kw):
        items = list(items)
        self.tasks += len(items)
        return self.inner.map_shared(fn, shared, items, **kw)


def test_diagnose_refits_on_cluster_equal_serial(cluster, tmp_path):
    """The search loop with its refits mapped over the cluster (one task per refitted candidate,
    the split base sent once per refit pass): every round scores, refits and adds what the
    serial loop does. The workers' BLAS is single-threaded, the client's is not (docs/parallel.md),
    so an iteration's rounding differs and the refit may stop at another point of its last step:
    chi2 agrees to 1e-9 relative, each parameter to 1e-4 of its standard deviation (the stopping
    rule, a relative chi2 decrease below 1e-13 at chi2 ~ 1e3-1e4, pins the optimum only to about
    sqrt(1e-13 chi2) ~ 1e-5 std; the reports print 4 digits of a value next to its std)."""
    from blackbox.commands import diagnose as dc
    from blackbox.diagnosis import search

    for folder in ("support_flexibility", "undeclared_joint"):
        (tmp_path / folder).mkdir()
        pr = dc.prepare(FIXTURES / "undeclared" / folder, tmp_path / folder)
        ident = pr.ident

        def loop(executor):
            return search.diagnose(pr.base, pr.boundary, pr.K_deck, pr.joints, ident.k, pr.fit_obs, pr.hold_obs,
                                   pr.candidates, declared_prediction=ident.predicted, executor=executor,
                                   always_map_refits=True)

        ser = loop(None)
        counting = _Counting(cluster)
        par_ = loop(counting)
        # the base is sent once per refit pass with two or more refits: the refit_top best, then
        # the others that could still win (search.refit_schedule), so once or twice a round
        assert len(ser.steps) <= counting.shared <= 2 * len(ser.steps) and counting.tasks == sum(
            sum(1 for c in st.scores if c.refit is not None or c.reason.startswith("refit failed"))
            for st in ser.steps)
        assert len(par_.steps) == len(ser.steps) and ser.added
        for a, b in zip(ser.steps, par_.steps):
            assert [c.effect.key for c in a.scores] == [c.effect.key for c in b.scores]
            assert (a.added is None) == (b.added is None)
            if a.added is not None:
                assert (a.added.effect.key, a.added.effect.variant) == (b.added.effect.key, b.added.effect.variant)
            for ca, cb in zip(a.scores, b.scores):
                assert (ca.refit is None) == (cb.refit is None) and ca.accepted == cb.accepted
                if ca.refit is not None:
                    np.testing.assert_allclose(cb.refit.chi2, ca.refit.chi2, rtol=1e-9)
                    _same_to_std(cb.refit, ca.refit)
        _same_to_std(par_.final, ser.final)


def _same_to_std(got, ref, fraction: float = 1e-4) -> None:
    """Every parameter of ``got`` within ``fraction`` of ``ref``'s standard deviation of it (the
    parameters the data do not determine, infinite std, within 1e-6 relative)."""
    ok = np.isfinite(ref.std)
    dev = np.abs(got.x - ref.x)
    assert np.all(dev[ok] <= fraction * ref.std[ok]), (dev[ok] / ref.std[ok]).max()
    np.testing.assert_allclose(got.x[~ok], ref.x[~ok], rtol=1e-6)


def test_bench_rows_on_cluster_are_the_serial_rows(cluster):
    """``blackbox bench`` with one task per (case, adapter): the same rows in the same order,
    the same solver runs, iterations and estimates (only the timings differ)."""
    from blackbox.commands import bench

    cases = ["cube-simple", "car-simple"]
    ser = bench.run_bench(FIXTURES, ["reference"], cases, 1, progress=lambda s: None)
    dist = bench.bench_rows(FIXTURES, ["reference"], cases, 1, executor=cluster)
    keep = ("case", "method", "adapter", "solver_runs", "right_hand_sides", "iterations", "converged",
            "same_estimate_as_blackbox", "chi2_to_blackbox")
    assert [{k: r[k] for k in keep} for r in dist] == [{k: r[k] for k in keep} for r in ser]
    assert {r["case"] for r in dist} == set(cases) and all(r["wall_s"] > 0 for r in dist)


def _diagnosis_numbers(res) -> dict:
    """What a diagnosis concluded, without its timings: the effects added with their
    parameters, the fit before and after, the final joint parameters, the solver runs."""
    d = res.document
    return {"added": [(e["effect"], tuple(e["where"]), e["variant"], [(p["name"], p["value"], p["std"])
                                                                       for p in e["parameters"]])
                      for e in d["added"]],
            "before": (d["before"]["reduced_chi2"], d["before"]["chi2"]),
            "after": (d["after"]["reduced_chi2"], d["after"]["chi2"]),
            "final": [(j, n, p["value"], p["std"]) for j, rec in d["joint_parameters"]["final"].items()
                      for n, p in rec["parameters"].items()],
            "verdict": d["verdict"],
            "runs": [(r.purpose, r.deck, r.right_hand_sides) for r in res.diagnosis.runs],
            "cost": (res.solver.runs, res.solver.right_hand_sides, res.solver.cached_batches)}


def _diagnose_serial_and_on_cluster(study, cluster) -> tuple[dict, dict]:
    """The same diagnosis serially and with ``executor=cluster``; the conclusions compared: chi2
    to 1e-9 relative, the parameters to 1e-4 of their standard deviation (a round's refits may
    run on the workers, whose BLAS is single-threaded: :func:`_same_to_std`)."""
    from blackbox.commands import diagnose

    serial = _diagnosis_numbers(diagnose.run(study, plots=False))
    on_cluster = _diagnosis_numbers(diagnose.run(study, plots=False, executor=cluster))
    assert serial["added"] and serial["added"][0][0] == "support_flexibility"
    assert [a[:3] for a in on_cluster["added"]] == [a[:3] for a in serial["added"]]

    def close(got, ref):            # (name, value, std) triples
        assert [g[0] for g in got] == [r[0] for r in ref]
        for (_, v, sd), (_, v0, sd0) in zip(got, ref):
            assert abs(v - v0) <= 1e-4 * sd0 if sd0 is not None and np.isfinite(sd0) else v == pytest.approx(v0, 1e-6)
            assert sd == sd0 if sd0 is None else sd == pytest.approx(sd0, rel=1e-6)

    for a, b in zip(on_cluster["added"], serial["added"]):
        close(a[3], b[3])
    for key in ("before", "after"):
        np.testing.assert_allclose(on_cluster[key], serial[key], rtol=1e-9)
    assert [f[:2] for f in on_cluster["final"]] == [f[:2] for f in serial["final"]]
    close([f[1:] for f in on_cluster["final"]], [f[1:] for f in serial["final"]])
    assert on_cluster["verdict"] == serial["verdict"]
    # the same batched runs, in the same order (the condensation's record first, as serially)
    assert on_cluster["runs"] == serial["runs"]
    return serial, on_cluster


def test_diagnose_runs_on_cluster_equal_serial(cluster, tmp_path):
    """``diagnose.run(..., executor=cluster)``, reference solver: the declared condensation and
    the element run are tasks on the workers (from the study packed in memory), the split run
    and the loop run here; the same effects, fit, parameters and solver runs as serially."""
    from blackbox.cli import build_parser

    study = copy_fixture("undeclared/support_flexibility", tmp_path / "study")
    serial, on_cluster = _diagnose_serial_and_on_cluster(study, cluster)
    assert on_cluster["cost"] == serial["cost"]
    # the command line takes --workers / --scheduler for diagnose
    args = build_parser().parse_args(["diagnose", str(study), "--out", str(tmp_path / "o"), "--workers", "2"])
    assert args.workers == 2


@needs_mystran
def test_diagnose_through_mystran_on_cluster_equals_serial(cluster, tmp_path):
    """The same through MYSTRAN: the condensation a task, the element and split runs cut into
    column chunks over the workers; the same conclusions, and every chunk a solver run of its own
    (more runs than serially, the same right-hand sides). Serially one MYSTRAN process at a time
    (``processes = 1``: else the split run's 166 cases would also run as two processes here)."""
    study = copy_fixture("undeclared/support_flexibility", tmp_path / "study")
    toml = (study / "study.toml").read_text()
    (study / "study.toml").write_text(toml.replace('adapter = "reference"', 'adapter = "mystran"')
                                      + "\n[solver.options]\nprocesses = 1\n")
    serial, on_cluster = _diagnose_serial_and_on_cluster(study, cluster)
    assert on_cluster["cost"][1:] == serial["cost"][1:] and on_cluster["cost"][0] > serial["cost"][0]


@needs_mystran
def test_mystran_batch_in_chunks_side_by_side_equals_one_run(cluster, tmp_path, monkeypatch):
    """A MYSTRAN batch cut into column chunks, each a separate MYSTRAN process on a worker,
    gives the one-run values bit for bit; the runs are counted on the client. Deck files that
    are not where the client had them (no shared file system) travel with the chunk."""
    from blackbox.study import load_study
    from blackbox.adapters import make_adapter_for
    from blackbox.declared import declared_model
    from solver_adapters.protocol import LoadMatrix
    from solver_adapters import subprocess as sub

    monkeypatch.setattr("tempfile.tempdir", str(tmp_path))
    study = load_study(FIXTURES / "car", need_measurements=True)
    loads = LoadMatrix.unit(declared_model(study).boundary)
    report = list(study.measurements.all_dofs)
    one = make_adapter_for(study, "mystran", cache=False)
    ref = one.solve(loads, report).values
    # 18 cases: by default no chunk below MIN_CASES_PER_CHUNK, so one run; two chunks when asked
    whole = par.use_executor(make_adapter_for(study, "mystran", cache=False), cluster)
    assert loads.n_cases < 2 * sub.MIN_CASES_PER_CHUNK
    assert np.array_equal(whole.solve(loads, report).values, ref) and whole.stats.runs == 1
    split = par.use_executor(make_adapter_for(study, "mystran", cache=False), cluster, chunks=2)
    got = split.solve(loads, report)
    assert np.array_equal(got.values, ref) and got.cases == loads.cases
    assert split.stats.runs == 2 and split.stats.right_hand_sides == loads.n_cases
    # a chunk whose deck paths do not exist where it runs: rebuilt from the bytes it carries
    files = {f"/nonexistent-client/deck/{Path(p).name}": data for p, data in sub._deck_bytes(one.deck_path).items()}
    moved = one.__class__.__new__(one.__class__)
    moved.__setstate__(one.__getstate__())
    moved.deck_path = Path("/nonexistent-client/deck") / one.deck_path.name
    values, stats = sub._run_chunk((moved, files, loads.select(range(3)), tuple(report)))
    assert np.array_equal(values, ref[:, :3]) and stats.runs == 1


def _solver_task(args):
    """A task that runs a 'solver' (a Python sleeper under the guard): the first attempt sleeps
    long and records its worker's PID, a retry returns at once."""
    from solver_adapters.subprocess import run_solver
    import tempfile

    folder, = args
    marker, pids = Path(folder) / "first_worker", Path(folder) / "solver_pids"
    first = not marker.exists()
    if first:
        marker.write_text(str(os.getpid()))
    script = "import os, sys, time; open(sys.argv[1], 'a').write(f'{os.getpid()}\\n'); time.sleep(float(sys.argv[2]))"
    wd = tempfile.mkdtemp(dir=folder)
    rec = run_solver([sys.executable, "-c", script, str(pids), "120" if first else "0"], Path(wd), timeout_s=300)
    return os.getpid(), rec.returncode


def test_killed_worker_task_is_retried_and_its_solver_killed(tmp_path):
    """SIGKILL of the worker process while its solver runs: the scheduler runs the task again on
    a live worker (allowed_failures), the result arrives, and the guard ended the first solver."""
    import psutil

    with par.DaskExecutor(workers=2, allowed_failures=2) as ex:
        box = {}
        t = threading.Thread(target=lambda: box.setdefault("out", ex.map(_solver_task, [(str(tmp_path),)],
                                                                           errors="return")))
        t.start()
        pids = tmp_path / "solver_pids"
        deadline = time.monotonic() + 30
        while not (pids.exists() and pids.read_text().strip()) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert pids.exists(), "the solver never started"
        solver = int(pids.read_text().split()[0])
        worker = int((tmp_path / "first_worker").read_text())
        assert psutil.pid_exists(solver)
        os.kill(worker, signal.SIGKILL)
        t.join(60)
        assert not t.is_alive(), "the task was not retried"
        (pid, code), = box["out"]
        assert pid != worker and code == 0
        assert len(pids.read_text().split()) == 2            # run twice: killed, then again
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            try:
                if psutil.Process(solver).status() == psutil.STATUS_ZOMBIE:
                    break
            except psutil.NoSuchProcess:
                break
            time.sleep(0.05)
        else:
            pytest.fail(f"the solver {solver} of the killed worker is still running")


def _die(x):
    os.kill(os.getpid(), signal.SIGKILL)


def test_a_task_that_kills_its_workers_is_lost_not_the_others(tmp_path):
    """A task whose worker dies more often than allowed is a TaskFailure marked lost; the other
    tasks' results arrive."""
    with par.DaskExecutor(workers=2, allowed_failures=0) as ex:
        out = ex.map(lambda x: _die(x) if x == 1 else x + 10, [0, 1, 2], errors="return")
    assert out[0] == 10 and out[2] == 12
    assert isinstance(out[1], TaskFailure) and out[1].lost and out[1].error_type == "KilledWorker"


def test_cli_batch_reports_every_study_and_exits_4_when_one_fails(tmp_path, capsys):
    """``blackbox batch``: one sub-folder and one summary row per study; a study that cannot be
    read is a row with its status (never lost work for the others), and the exit code is 4."""
    import csv

    from blackbox.cli import main

    bad = tmp_path / "broken"
    bad.mkdir()
    (bad / "study.toml").write_text("name = \"broken\"\n[solver]\ndeck = \"missing.bdf\"\n")
    out = tmp_path / "out"
    assert main(["batch", str(FIXTURES / "cube"), str(bad), "--out", str(out), "--no-cache"]) == 4
    rows = {r["study"]: r for r in csv.DictReader((out / "summary.csv").open())}
    assert rows["cube"]["status"] == "ok" and float(rows["cube"]["reduced_chi2"]) > 0
    assert rows["broken"]["status"] == "bad_input" and "missing.bdf" in rows["broken"]["error"]
    assert (out / "cube" / "result.json").is_file()
    assert "broken: bad_input" in capsys.readouterr().err
