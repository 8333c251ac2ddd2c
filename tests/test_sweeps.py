"""legkit.sweeps: the declarative spec, batched execution locally and on Ray, resumable Parquet output, the
CLI, figures and tuning. Small trees (4 modules) and short runs keep the file to well under a minute."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pyarrow.parquet as pq
import pytest
import ray

from legkit.control import SCHEMES, GainSchedule
from legkit.experiments import balance
from legkit.robots.superbot import random_tree
from legkit.sweeps import SweepSpec, read_results, run_batch, run_sweep
from legkit.sweeps import cli as sweep_cli
from legkit.sweeps import tune as tuning

SMALL = dict(trees=2, modules=4, branches=2, duration=0.1)


def assert_same_table(a, b):
    assert a.column_names == b.column_names and a.num_rows == b.num_rows
    for name in a.column_names:
        x, y = np.asarray(a.column(name).to_pylist()), np.asarray(b.column(name).to_pylist())
        if x.dtype.kind == "f":
            assert np.array_equal(x, y, equal_nan=True), name
        else:
            assert np.array_equal(x, y), name


def test_spec_expands_the_grid_with_deterministic_ids_and_batches():
    spec = SweepSpec(**SMALL, c1=[0.1, 0.5], loss=[0.0, 0.2], noise=[0.0, 0.01], batch_size=5)
    runs = spec.runs()
    # 2 trees x (constant once, ignoring c1; distance and momentum twice) x 2 losses x 2 noise levels
    assert len(runs) == 2 * (1 + 2 + 2) * 2 * 2
    assert all(r.c1 == 0.0 for r in runs if r.scheme == "constant")
    ids = [spec.run_id(r) for r in runs]
    assert len(set(ids)) == len(ids)
    # The same run has the same id in another spec (another batch size, another grid around it).
    other = SweepSpec(**SMALL, c1=[0.5], loss=[0.2], batch_size=3)
    assert {other.run_id(r) for r in other.runs()} <= set(ids)
    assert other.spec_id != spec.spec_id
    batches = spec.batches()
    assert sorted((r for b in batches for r in b), key=runs.index) == runs
    assert all(len(b) <= 5 and len({r.bus_key for r in b}) == 1 for b in batches)
    assert SweepSpec.from_dict(spec.to_dict()) == spec
    # Paper defaults per scheme; a mapping sets one scheme and leaves the others at the paper's.
    paper = {r.scheme: (r.c0, r.c1) for r in SweepSpec(**SMALL).runs()}
    assert paper == {s: (GainSchedule.paper(s).c0, GainSchedule.paper(s).c1) for s in SCHEMES}
    mapped = SweepSpec(**SMALL, c1={"momentum": [2.0, 3.0]}).runs()
    assert {(r.scheme, r.c1) for r in mapped} == {("constant", 0.0), ("distance", 0.1), ("momentum", 2.0), ("momentum", 3.0)}


@pytest.mark.parametrize(
    "arguments, name",
    [
        (dict(trees=0), "trees"), (dict(trees=[1, 1]), "trees"), (dict(schemes=["pid"]), "schemes"), (dict(c0=[-1.0]), "c0"),
        (dict(c1={"pid": [1.0]}), "c1"), (dict(loss=[1.0]), "loss"), (dict(delay=[0]), "delay"), (dict(terrain=[-0.01]), "terrain"),
        (dict(noise=[float("nan")]), "noise"), (dict(duration=0.0), "duration"), (dict(batch_size=0), "batch_size"),
        (dict(branches=6), "branches"), (dict(kp0=[]), "kp0"), (dict(friction=0.8), "friction"),
    ],
)
def test_bad_specs_raise_errors_naming_the_argument(arguments, name):
    with pytest.raises((ValueError, TypeError), match=rf"^{name}"):
        SweepSpec(**arguments)


def test_bad_run_arguments_raise_errors_naming_them(tmp_path):
    with pytest.raises(ValueError, match="^spec: unknown"):
        SweepSpec.from_dict({"tree": 3})
    with pytest.raises(TypeError, match="^spec"):
        run_sweep({"trees": 2}, tmp_path)
    with pytest.raises(ValueError, match="^workers"):
        run_sweep(SweepSpec(**SMALL), tmp_path / "w", workers=0)
    trees = [random_tree(4, 2, 0)]
    with pytest.raises(ValueError, match=r"^runs\[0\].tree"):
        balance.run_balance(trees, 0.01, runs=[balance.RunSpec(1, GainSchedule())], progress=False)
    with pytest.raises(ValueError, match=r"^runs\[0\].noise"):
        balance.run_balance(trees, 0.01, runs=[balance.RunSpec(0, GainSchedule(), noise=-1.0)], progress=False)
    with pytest.raises(ValueError, match="^bus"):
        balance.run_balance(trees, 0.01, loss=0.1, bus=balance.BusConfig(), progress=False)


@pytest.fixture(scope="module")
def faults_spec():
    return SweepSpec(**SMALL, schemes=["constant", "momentum"], loss=[0.0, 0.3], terrain=[0.0, 0.005], noise=[0.0, 0.02], batch_size=8)


@pytest.fixture(scope="module")
def local_table(faults_spec, tmp_path_factory):
    out = tmp_path_factory.mktemp("local")
    table = run_sweep(faults_spec, out, workers=1, progress=False)
    return out, table


@pytest.mark.slow
def test_sweep_writes_parquet_figures_and_the_paper_runs_of_legkit_balance(local_table, faults_spec):
    out, table = local_table
    assert table.num_rows == len(faults_spec.runs()) == 2 * 2 * 8
    assert_same_table(pq.read_table(out / "results.parquet"), table)
    assert_same_table(read_results(out), table)
    assert (out / "distributions.png").stat().st_size > 0
    rows = table.to_pylist()
    assert [r["index"] for r in rows] == list(range(len(rows)))
    for r in rows:
        assert r["final"] >= 0 and r["energy"] > 0 and r["messages"] > 0 and r["initial"] > 0
    # Replicate 0 on the plane, reliable bus, no noise, is the run of `legkit balance` with the same tree seed.
    reference = balance.run_balance([random_tree(4, 2, s) for s in range(2)], 0.1, progress=False)
    for expected in (e for e in reference if e.scheme in ("constant", "momentum")):
        key = (expected.tree, expected.scheme, 0.0, 0.0, 0.0)
        (row,) = [r for r in rows if (r["tree_seed"], r["scheme"], r["loss"], r["terrain"], r["noise"]) == key]
        assert (row["final"], row["overshoot"], row["energy"]) == (expected.final, expected.overshoot, expected.energy)
    # Each fault changes the outcome: lossy buses send more (retransmissions and acknowledgements aside,
    # data messages are retransmitted), noise and terrain move the COM elsewhere.
    base = {(r["tree_seed"], r["scheme"]): r for r in rows if (r["loss"], r["terrain"], r["noise"]) == (0.0, 0.0, 0.0)}
    for r in rows:
        if (r["loss"], r["terrain"], r["noise"]) != (0.0, 0.0, 0.0):
            assert r["final"] != base[(r["tree_seed"], r["scheme"])]["final"]


def test_zero_gains_spend_no_energy_and_noise_is_per_run():
    """A schedule with zero gains applies no torque: zero energy. A run's sensor noise comes from its own
    generator: the same noisy run gives the same result beside other runs or alone."""
    trees = [random_tree(4, 2, 0), random_tree(4, 2, 1)]
    noisy = balance.RunSpec(0, GainSchedule.paper("distance"), noise=0.02, noise_seed=7)
    together = balance.run_balance(trees, 0.05, runs=[balance.RunSpec(1, GainSchedule("constant", c0=0.0)), noisy], progress=False)
    alone = balance.run_balance(trees, 0.05, runs=[noisy], progress=False)
    assert together[0].energy == 0.0
    np.testing.assert_array_equal(together[1].distance, alone[0].distance)
    quiet = balance.run_balance(trees, 0.05, runs=[balance.RunSpec(0, GainSchedule.paper("distance"))], progress=False)
    assert not np.array_equal(quiet[0].distance, alone[0].distance)


def test_a_run_on_a_lossy_delayed_bus_does_not_depend_on_its_batch():
    """On an asynchronous bus a run draws its losses, duplicates and delays from generators of its own
    (RunSpec.bus_seed): the same RunSpec gives the same result alone and between other runs."""
    trees = [random_tree(4, 2, 0), random_tree(6, 2, 1), random_tree(4, 2, 2)]
    bus = balance.BusConfig(mode="async", loss=0.3, delay_max=4, duplication=0.1)
    run = balance.RunSpec(1, GainSchedule.paper("distance"), bus_seed=11)
    others = [balance.RunSpec(0, GainSchedule.paper("constant")), balance.RunSpec(2, GainSchedule.paper("momentum"), bus_seed=3)]
    together = balance.run_balance(trees, 0.1, runs=[others[0], run, others[1]], bus=bus, progress=False)[1]
    alone = balance.run_balance(trees, 0.1, runs=[run], bus=bus, progress=False)[0]
    np.testing.assert_array_equal(together.distance, alone.distance)
    assert (together.messages_per_module_second, together.energy) == (alone.messages_per_module_second, alone.energy)
    # The faults are real: the reliable bus, or the same bus with another run seed, give other results.
    reliable = balance.run_balance(trees, 0.1, runs=[run], progress=False)[0]
    reseeded = balance.run_balance(trees, 0.1, runs=[balance.RunSpec(1, GainSchedule.paper("distance"), bus_seed=12)], bus=bus, progress=False)[0]
    assert not np.array_equal(reliable.distance, alone.distance)
    assert not np.array_equal(reseeded.distance, alone.distance)
    with pytest.raises(ValueError, match="^bus: run_balance gives every run its own stream"):
        balance.run_balance(trees, 0.1, runs=[run], bus=balance.BusConfig(mode="async", streams=((7, 0),)), progress=False)
    with pytest.raises(ValueError, match=r"^runs\[0\].bus_seed"):
        balance.run_balance(trees, 0.1, runs=[balance.RunSpec(0, GainSchedule(), bus_seed=-1)], bus=bus, progress=False)


@pytest.mark.slow
@pytest.mark.parametrize("loss, delay", [(0.0, 1), (0.2, 3)])
def test_a_run_does_not_depend_on_its_batch(loss, delay):
    """Terrain, noise, start angles, gains and bus faults are the run's own: the same run alone or in a batch
    of other trees and settings gives the same row, on the reliable bus and on a lossy, delayed one."""
    spec = SweepSpec(trees=[3, 5], modules=4, branches=2, duration=0.05, terrain=[0.0, 0.005], noise=[0.0, 0.02], seeds=2, loss=[loss], delay=[delay])
    runs = [r for r in spec.runs() if r.scheme != "momentum"]
    together = run_batch(spec.to_dict(), runs)
    for k in (len(runs) - 1, len(runs) // 2):
        (alone,) = run_batch(spec.to_dict(), [runs[k]])
        assert alone.keys() == together[k].keys()
        assert all(alone[c] == together[k][c] or np.isnan(alone[c]) and np.isnan(together[k][c]) for c in alone), (alone, together[k])


@pytest.mark.slow
def test_killed_sweep_resumes_to_the_uninterrupted_table(tmp_path, local_table, faults_spec):
    _, uninterrupted = local_table
    out = tmp_path / "killed"
    spec_file = tmp_path / "spec.json"
    import json

    spec_file.write_text(json.dumps(faults_spec.to_dict()))
    total = len(faults_spec.batches())
    process = subprocess.Popen(
        [sys.executable, "-m", "legkit.cli", "sweep", "--spec", str(spec_file), "--out", str(out), "--workers", "1", "--no-figures"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=os.environ.copy(),
    )
    try:
        deadline = time.monotonic() + 30
        while not list((out / "parts").glob("batch-*.parquet")) and time.monotonic() < deadline and process.poll() is None:
            time.sleep(0.02)
    finally:
        process.send_signal(signal.SIGKILL)
        process.wait()
    finished = sorted(p.name for p in (out / "parts").glob("batch-*.parquet"))
    assert 1 <= len(finished) < total, finished
    before = {p.name: p.stat().st_mtime_ns for p in (out / "parts").glob("batch-*.parquet")}
    resumed = run_sweep(faults_spec, out, workers=1, progress=False, figures=False)
    assert all((out / "parts" / name).stat().st_mtime_ns == mtime for name, mtime in before.items())  # not redone
    assert_same_table(resumed, uninterrupted)
    with pytest.raises(ValueError, match="^out: .* holds another sweep"):
        run_sweep(SweepSpec(**SMALL), out, workers=1, progress=False)


@pytest.mark.slow
def test_ray_gives_the_local_results_and_tuning(local_table, faults_spec, tmp_path, capsys):
    """The sweep on Ray tasks equals the local one; tuning on Ray Tune (OptunaSearch, the paper's constants
    first, one sampled trial within TPE's random start-up) finds the constants and scores the local Optuna
    search finds, and validates them on the same held-out runs."""
    _, local = local_table
    tiny_tune = dict(schemes=["momentum"], train=2, test=1, trials=2, per_round=2, duration=0.03, modules=4, branches=2)
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        on_ray = run_sweep(faults_spec, tmp_path / "ray", progress=False, figures=False)
        capsys.readouterr()
        (tuned_on_ray,) = tuning.tune(**tiny_tune, progress=True)
        assert "momentum: 2 trials on Ray Tune" in capsys.readouterr().err
    finally:
        ray.shutdown()
    assert_same_table(on_ray, local)
    (tuned_here,) = tuning.tune(**tiny_tune, progress=False)
    assert tuned_on_ray.tuned == tuned_here.tuned and tuned_on_ray.tuned != tuned_on_ray.paper
    assert (tuned_on_ray.train_score_paper, tuned_on_ray.train_score_tuned) == (tuned_here.train_score_paper, tuned_here.train_score_tuned)
    for which in ("paper", "tuned"):
        np.testing.assert_array_equal(tuned_on_ray.test_final[which], tuned_here.test_final[which])
        np.testing.assert_array_equal(tuned_on_ray.test_t10[which], tuned_here.test_t10[which])


@pytest.mark.slow
def test_local_pool_gives_the_in_process_results(local_table, faults_spec, tmp_path):
    _, local = local_table
    pooled = run_sweep(faults_spec, tmp_path / "pool", workers=2, progress=False, figures=False)
    assert_same_table(pooled, local)


@pytest.mark.slow
def test_cli(tmp_path, capsys):
    assert sweep_cli.main(["--trees", "3", "--c0", "0:1:3", "--c1", "distance=0.1,0.2", "--dry-run"]) == 0
    # 3 trees x (constant 3 c0 + distance 3 c0 x 2 c1 + momentum 3 c0 x paper c1)
    assert capsys.readouterr().out.startswith(f"{3 * (3 + 6 + 3)} runs")
    assert sweep_cli.main(["--loss", "2", "--dry-run"]) == 2
    assert "loss" in capsys.readouterr().err
    assert sweep_cli.main(["--c1", "pid=1", "--dry-run"]) == 2
    assert "--c1" in capsys.readouterr().err
    out = tmp_path / "cli"
    assert sweep_cli.main(["--trees", "2", "--modules", "4", "--branches", "2", "--duration", "0.05", "--schemes", "distance",
                           "--c0", "0", "0.5", "--c1", "0.1", "1", "--workers", "1", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "distance" in printed and "results.parquet (8 runs)" in printed
    assert (out / "heatmap.png").stat().st_size > 0 and (out / "distributions.png").stat().st_size > 0


def test_tune_starts_from_the_paper_and_reports_held_out_spread(capsys):
    results = tuning.tune(["distance"], train=2, test=2, trials=3, per_round=3, duration=0.05, modules=4, branches=2, progress=False)
    (result,) = results
    assert result.paper == tuning.constants(GainSchedule.paper("distance"))
    assert result.train_score_tuned <= result.train_score_paper  # the paper's constants are the first trial
    assert result.test_final["paper"].shape == result.test_final["tuned"].shape == (2,)
    text = tuning.report(results)
    assert "held-out trees (2)" in text and "paper" in text and "tuned" in text
    with pytest.raises(ValueError, match="^schemes"):
        tuning.tune(["pid"])
    with pytest.raises(ValueError, match="^train"):
        tuning.tune(train=0)
