"""legkit.sweeps: the declarative spec, batched execution locally and on Ray, verified resumable Parquet output
with provenance, interruption, the CLI's one-line errors, figures and tuning. Small trees (4 modules) and short
runs keep every sweep here to seconds; the two Ray tests spend most of their time starting Ray."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pyarrow.parquet as pq
import pytest
import ray

from conftest import ctrl_c_restored
from legkit.control import SCHEMES, GainSchedule, closed_loop
from legkit.robots.superbot import random_tree
from legkit.sweeps import SweepSpec, read_results, run_batch, run_sweep, task_size
from legkit.sweeps import cli as sweep_cli
from legkit.sweeps import tune as tuning
from legkit.sweeps.execute import checksum

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
        closed_loop.run_balance(trees, 0.01, runs=[closed_loop.RunSpec(1, GainSchedule())], progress=False)
    with pytest.raises(ValueError, match=r"^runs\[0\].noise"):
        closed_loop.run_balance(trees, 0.01, runs=[closed_loop.RunSpec(0, GainSchedule(), noise=-1.0)], progress=False)
    with pytest.raises(ValueError, match="^bus"):
        closed_loop.run_balance(trees, 0.01, loss=0.1, bus=closed_loop.BusConfig(), progress=False)


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
    reference = closed_loop.run_balance([random_tree(4, 2, s) for s in range(2)], 0.1, progress=False)
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
    noisy = closed_loop.RunSpec(0, GainSchedule.paper("distance"), noise=0.02, noise_seed=7)
    together = closed_loop.run_balance(trees, 0.05, runs=[closed_loop.RunSpec(1, GainSchedule("constant", c0=0.0)), noisy], progress=False)
    alone = closed_loop.run_balance(trees, 0.05, runs=[noisy], progress=False)
    assert together[0].energy == 0.0
    np.testing.assert_array_equal(together[1].distance, alone[0].distance)
    quiet = closed_loop.run_balance(trees, 0.05, runs=[closed_loop.RunSpec(0, GainSchedule.paper("distance"))], progress=False)
    assert not np.array_equal(quiet[0].distance, alone[0].distance)


def test_a_run_on_a_lossy_delayed_bus_does_not_depend_on_its_batch():
    """On an asynchronous bus a run draws its losses, duplicates and delays from generators of its own
    (RunSpec.bus_seed): the same RunSpec gives the same result alone and between other runs."""
    trees = [random_tree(4, 2, 0), random_tree(6, 2, 1), random_tree(4, 2, 2)]
    bus = closed_loop.BusConfig(mode="async", loss=0.3, delay_max=4, duplication=0.1)
    run = closed_loop.RunSpec(1, GainSchedule.paper("distance"), bus_seed=11)
    others = [closed_loop.RunSpec(0, GainSchedule.paper("constant")), closed_loop.RunSpec(2, GainSchedule.paper("momentum"), bus_seed=3)]
    together = closed_loop.run_balance(trees, 0.1, runs=[others[0], run, others[1]], bus=bus, progress=False)[1]
    alone = closed_loop.run_balance(trees, 0.1, runs=[run], bus=bus, progress=False)[0]
    np.testing.assert_array_equal(together.distance, alone.distance)
    assert (together.messages_per_module_second, together.energy) == (alone.messages_per_module_second, alone.energy)
    # The faults are real: the reliable bus, or the same bus with another run seed, give other results.
    reliable = closed_loop.run_balance(trees, 0.1, runs=[run], progress=False)[0]
    reseeded = closed_loop.run_balance(
        trees, 0.1, runs=[closed_loop.RunSpec(1, GainSchedule.paper("distance"), bus_seed=12)], bus=bus, progress=False,
    )[0]
    assert not np.array_equal(reliable.distance, alone.distance)
    assert not np.array_equal(reseeded.distance, alone.distance)
    with pytest.raises(ValueError, match="^bus: run_balance gives every run its own stream"):
        closed_loop.run_balance(trees, 0.1, runs=[run], bus=closed_loop.BusConfig(mode="async", streams=((7, 0),)), progress=False)
    with pytest.raises(ValueError, match=r"^runs\[0\].bus_seed"):
        closed_loop.run_balance(trees, 0.1, runs=[closed_loop.RunSpec(0, GainSchedule(), bus_seed=-1)], bus=bus, progress=False)


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


# --- Integrity, provenance, interruption, work split (issue 39) -----------------------------------------------

TINY = dict(trees=2, modules=4, branches=2, duration=0.05, schemes=["constant", "momentum"], batch_size=2)


@pytest.fixture(scope="module")
def tiny_sweep(tmp_path_factory):
    """A finished tiny sweep (2 batches of 2 runs), run in this process: the reference for damaged copies."""
    out = tmp_path_factory.mktemp("tiny")
    return out, run_sweep(SweepSpec(**TINY), out, workers=1, progress=False, figures=False)


def _rewrite(path, table, metadata=None):
    """Write ``table`` over the part ``path``, keeping (or replacing) the provenance in its metadata."""
    import pyarrow as pa

    metadata = pq.read_schema(path).metadata if metadata is None else metadata
    pq.write_table(table.replace_schema_metadata(metadata), path)
    del pa


def _damage(kind, parts):
    import pyarrow as pa
    import pyarrow.compute as pc

    first, second = parts / "batch-00000.parquet", parts / "batch-00001.parquet"
    table = pq.read_table(first)
    if kind == "fewer rows":
        _rewrite(first, table.slice(0, 1))
    elif kind == "another batch's rows":
        first.write_bytes(second.read_bytes())
    elif kind == "zero rows":
        _rewrite(first, table.slice(0, 0))
    elif kind == "duplicated rows":
        _rewrite(first, pa.concat_tables([table, table.slice(0, 1)]))
    elif kind == "dropped column":
        _rewrite(first, table.drop_columns(["energy"]))
    elif kind == "retyped column":
        _rewrite(first, table.set_column(table.schema.get_field_index("index"), "index", pc.cast(table.column("index"), pa.float64())))
    elif kind == "cut file":
        first.write_bytes(first.read_bytes()[:200])
    elif kind == "no provenance":
        _rewrite(first, table, metadata={})
    elif kind == "another build":
        # A whole part of another build: its provenance and the checksum of its values.
        other = json.loads(pq.read_schema(first).metadata[b"legkit.provenance"])
        other["build"] = "0" * 16
        table = table.set_column(table.schema.get_field_index("build"), "build", pa.array(["0" * 16] * table.num_rows))
        _rewrite(first, table, metadata={b"legkit.provenance": json.dumps(other).encode(), b"legkit.sha256": checksum(table).encode()})
    elif kind == "flipped bit":
        flip_stored_value(first, "final")
    elif kind == "no checksum":
        metadata = pq.read_schema(first).metadata
        _rewrite(first, table, metadata={b"legkit.provenance": metadata[b"legkit.provenance"]})
    elif kind == "stray batch":
        (parts / "batch-00099.parquet").write_bytes(first.read_bytes())
    return parts / ("batch-00099.parquet" if kind == "stray batch" else "batch-00000.parquet")


def flip_stored_value(path, column):
    """Flips one bit (mantissa bit 40) of the first value of ``column`` where the file stores it (not a copy in
    its statistics): the file still reads, that value differs by about 1e-4 of itself, nothing else changes."""
    data = path.read_bytes()
    value = pq.read_table(path).column(column)[0].as_py()
    stored = np.float64(value).tobytes()
    at = data.find(stored)
    while at >= 0:
        flipped = bytearray(data)
        flipped[at + 5] ^= 0x01
        path.write_bytes(bytes(flipped))
        try:
            changed = pq.read_table(path).column(column)[0].as_py()
        except Exception:  # noqa: BLE001 - this copy was the one a header needs: try the next
            changed = value
        if changed != value:
            assert 0 < abs(changed - value) < 1e-3 * abs(value), (value, changed)
            return
        at = data.find(stored, at + 1)
    path.write_bytes(data)
    raise AssertionError(f"no stored copy of {value!r} in {path} changes {column} when flipped")


DAMAGE = ["fewer rows", "another batch's rows", "zero rows", "duplicated rows", "dropped column", "retyped column", "cut file",
          "no provenance", "another build", "stray batch", "flipped bit", "no checksum"]


@pytest.mark.parametrize("kind", DAMAGE)
def test_a_damaged_part_is_run_again_with_a_line_or_refused_with_strict(kind, tiny_sweep, tmp_path):
    """Every kind of damaged part ends in the uninterrupted table (no run lost or duplicated), with one line
    naming the file; with strict, a ValueError naming it and nothing written."""
    import shutil

    reference_out, reference = tiny_sweep
    out = tmp_path / "copy"
    shutil.copytree(reference_out, out)
    (out / "results.parquet").unlink()
    damaged = _damage(kind, out / "parts")
    before = {p.name: p.read_bytes() for p in (out / "parts").iterdir()}
    with pytest.raises(ValueError, match=rf"^strict: {damaged}"):
        run_sweep(SweepSpec(**TINY), out, workers=1, progress=False, figures=False, strict=True)
    assert {p.name: p.read_bytes() for p in (out / "parts").iterdir()} == before and not (out / "results.parquet").exists()
    lines = []
    table = run_sweep(SweepSpec(**TINY), out, workers=1, progress=False, figures=False, log=lines.append)
    assert len(lines) == 1 and lines[0].startswith(str(damaged)), lines
    assert_same_table(table, reference)
    assert_same_table(pq.read_table(out / "results.parquet"), reference)
    assert sorted(table.column("run_id").to_pylist()) == sorted(SweepSpec(**TINY).run_id(r) for r in SweepSpec(**TINY).runs())
    # The re-run part checks out now: a second resume keeps every part and says nothing.
    lines.clear()
    run_sweep(SweepSpec(**TINY), out, workers=1, progress=False, figures=False, log=lines.append)
    assert lines == ([lines[0]] if kind == "stray batch" else [])


def test_a_flipped_bit_fails_its_checksum_and_results_record_version_commit_build_and_spec(tiny_sweep, tmp_path):
    """A bit flipped in a stored value reads without a word from Parquet: the part's checksum catches it (one
    line, the batch recomputed), and results.parquet's, read_results refusing it; results.parquet's metadata
    holds this build's provenance (version, commit, build), the spec id and the builds of its rows."""
    import shutil

    from legkit.sweeps import provenance

    reference_out, reference = tiny_sweep
    results = reference_out / "results.parquet"
    record = json.loads(pq.read_schema(results).metadata[b"legkit.provenance"])
    mine = provenance()
    assert record == {**mine, "spec_id": SweepSpec(**TINY).spec_id, "builds": [mine["build"]]}
    assert pq.read_schema(results).metadata[b"legkit.sha256"].decode() == checksum(pq.read_table(results))
    out = tmp_path / "copy"
    shutil.copytree(reference_out, out)
    part = out / "parts" / "batch-00000.parquet"
    flip_stored_value(part, "final")
    flip_stored_value(out / "results.parquet", "final")
    mismatch = r"holds values other than those written \(sha256 [0-9a-f]{16}, recorded [0-9a-f]{16}\)"
    results_refused = rf"^out: {re.escape(str(out / 'results.parquet'))} {mismatch}; run the sweep again to rebuild it from its parts$"
    with pytest.raises(ValueError, match=results_refused):
        read_results(out)
    lines = []
    table = run_sweep(SweepSpec(**TINY), out, workers=1, progress=False, figures=False, log=lines.append)
    assert len(lines) == 1 and re.fullmatch(rf"{re.escape(str(part))}: {mismatch}; running its batch again", lines[0]), lines
    assert_same_table(table, reference)
    assert_same_table(read_results(out), reference)


def test_provenance_is_recorded_and_another_build_refused_unless_allowed(tiny_sweep, tmp_path):
    import shutil

    from legkit.sweeps import provenance

    reference_out, reference = tiny_sweep
    mine = provenance()
    assert set(reference.column("build").to_pylist()) == {mine["build"]}
    stored = json.loads((reference_out / "spec.json").read_text())
    assert stored["provenance"] == mine
    assert {"legkit", "build", "extension", "engine", "python", "platform", "commit"} <= set(mine)
    assert mine["engine"]["servo_torque_limit"] == 1.0
    for part in (reference_out / "parts").iterdir():
        assert json.loads(pq.read_schema(part).metadata[b"legkit.provenance"]) == mine
    # A folder started by another build: refused, unless allow_mixed, which keeps its (self-consistent) parts.
    out = tmp_path / "other-build"
    shutil.copytree(reference_out, out)
    (out / "results.parquet").unlink()
    stored["provenance"] = {**mine, "build": "0" * 16, "commit": "f" * 40}
    (out / "spec.json").write_text(json.dumps(stored))
    _damage("another build", out / "parts")
    with pytest.raises(ValueError, match=r"^out: .* was started by legkit .* build 0{16}, commit ffffffffff.*--allow-mixed"):
        run_sweep(SweepSpec(**TINY), out, workers=1, progress=False, figures=False)
    mixed = run_sweep(SweepSpec(**TINY), out, workers=1, progress=False, figures=False, allow_mixed=True, log=pytest.fail)
    assert mixed.column("build").to_pylist() == ["0" * 16] * 2 + [mine["build"]] * 2
    assert json.loads((out / "spec.json").read_text())["resumed_by"] == [mine]
    # A garbled spec.json: one line naming the file.
    (out / "spec.json").write_text("{garbled")
    with pytest.raises(ValueError, match=rf"^out: {out / 'spec.json'} is not a sweep's spec.json"):
        run_sweep(SweepSpec(**TINY), out, workers=1, progress=False)


def test_task_size_and_split_spread_runs_over_the_workers():
    from legkit.sweeps.execute import TASK_FLOOR, split

    # The docs' first example (24 runs, one batch of 48) on 2 workers: several tasks, each of >= TASK_FLOOR runs.
    assert task_size(24, 2, 48) == TASK_FLOOR and len(split(list(range(24)), TASK_FLOOR)) == 6
    for runs, workers, batch in [(1, 1, 48), (1002, 2, 48), (1002, 64, 48), (5, 3, 2), (100_000, 2, 48)]:
        size = task_size(runs, workers, batch)
        assert min(batch, TASK_FLOOR) <= size <= batch
        tasks = -(-runs // size)
        assert tasks >= min(-(-runs // batch) * 1, 2 * workers) or size == min(batch, TASK_FLOOR)
    for n, size in [(1, 4), (7, 3), (48, 5), (48, 48)]:
        pieces = split(list(range(n)), size)
        assert [x for p in pieces for x in p] == list(range(n))
        assert max(map(len, pieces)) <= size and max(map(len, pieces)) - min(map(len, pieces)) <= 1


@pytest.mark.slow
def test_the_table_does_not_depend_on_how_runs_are_split_into_tasks(tiny_sweep, tmp_path, monkeypatch):
    """One run per task in this process, and the default split on a 2-process pool: the same table."""
    from legkit.sweeps import execute

    _, reference = tiny_sweep
    spec = SweepSpec(**{**TINY, "batch_size": 4})
    pooled = run_sweep(spec, tmp_path / "pool", workers=2, progress=False, figures=False)
    monkeypatch.setattr(execute, "TASK_FLOOR", 1)
    monkeypatch.setattr(execute, "TASKS_PER_WORKER", 10_000)
    assert execute.task_size(len(spec.runs()), 1, 4) == 1
    alone = run_sweep(spec, tmp_path / "alone", workers=1, progress=False, figures=False)
    assert_same_table(alone, pooled)
    assert_same_table(alone.drop_columns(["batch"]), reference.drop_columns(["batch"]))


def _descendants(pid):
    """Every process below ``pid`` (from /proc), found before the driver dies."""
    children = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                stat = open(f"/proc/{entry}/stat").read()
            except OSError:
                continue
            children.setdefault(int(stat.rsplit(")", 1)[1].split()[1]), []).append(int(entry))
    found, stack = [], [pid]
    while stack:
        for child in children.get(stack.pop(), []):
            found.append(child)
            stack.append(child)
    return found


def _alive(pid):
    try:
        return open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def _start_sweep(tmp_path, spec_values, workers=2):
    spec_file = tmp_path / "spec.json"
    spec_file.write_text(json.dumps(spec_values))
    out = tmp_path / "out"
    process = subprocess.Popen(
        [sys.executable, "-m", "legkit.cli", "sweep", "--spec", str(spec_file), "--out", str(out), "--workers", str(workers), "--no-figures"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=os.environ.copy(), preexec_fn=ctrl_c_restored,
    )
    return process, out


def _wait_for(condition, process, seconds=120):
    deadline = time.monotonic() + seconds
    while not condition() and time.monotonic() < deadline and process.poll() is None:
        time.sleep(0.05)
    assert condition(), process.poll()


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_killing_the_driver_leaves_no_process_behind(tmp_path):
    """kill -9 of a sweep's driver while its pool works: every worker (and the resource tracker) exits."""
    process, out = _start_sweep(tmp_path, {**TINY, "trees": 8, "duration": 3.0, "batch_size": 4})
    try:
        # The pool's workers (and the resource tracker) are up: waiting for a part instead raced the sweep's end on an
        # idle machine, where the pool had closed by the time it was read.
        _wait_for(lambda: len(_descendants(process.pid)) >= 2, process)
        below = _descendants(process.pid)
    finally:
        process.kill()
        process.communicate()
    _assert_gone(below)


def _assert_gone(pids):
    deadline = time.monotonic() + 30  # a liveness bound, far above the watchdog's half second
    while any(_alive(p) for p in pids) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not [p for p in pids if _alive(p)]


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_ctrl_c_stops_at_once_keeps_the_parts_and_exits_130(tmp_path):
    spec_values = {**TINY, "trees": 8, "duration": 3.0, "batch_size": 2}
    process, out = _start_sweep(tmp_path, spec_values)
    _wait_for(lambda: list((out / "parts").glob("batch-*.parquet")), process)
    below = _descendants(process.pid)
    process.send_signal(signal.SIGINT)
    _, err = process.communicate(timeout=60)
    assert process.returncode == 130, err
    last = err.strip().splitlines()[-1]
    assert re.fullmatch(rf"legkit sweep: interrupted; \d+ of 16 runs are kept in {out}: run the same command again to resume", last), err
    assert "Traceback" not in err
    _assert_gone(below)
    kept = {p.name: p.stat().st_mtime_ns for p in (out / "parts").glob("batch-*.parquet")}
    assert 1 <= len(kept) < 8 and int(last.split("; ")[1].split()[0]) == 2 * len(kept)
    resumed = run_sweep(SweepSpec(**spec_values), out, workers=1, progress=False, figures=False, log=pytest.fail)
    assert resumed.num_rows == 16
    assert all((out / "parts" / n).stat().st_mtime_ns == t for n, t in kept.items())


@pytest.mark.slow
def test_commands_fail_in_one_line_before_creating_output(tmp_path, capsys, monkeypatch):
    out = tmp_path / "never"
    cases = [
        (["--spec", str(tmp_path / "missing.json")], "--spec: cannot read"),
        (["--spec", str(tmp_path / "garbled.json")], f"--spec: '{tmp_path / 'garbled.json'}' is not JSON"),
        (["--schemes", "distance", "--c1", "momentum=1"], "c1: values given for ['momentum'], which the sweep does not run"),
        (["--ray", "auto"], "ray: no Ray cluster found at 'auto'; start one with `ray start --head`"),
    ]
    (tmp_path / "garbled.json").write_text("{trees: 2")
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    if ray.is_initialized() or _ray_cluster_running():
        cases.pop()  # a cluster is up on this machine: --ray auto would find it
    for argv, message in cases:
        assert sweep_cli.main([*argv, "--trees", "2", "--modules", "4", "--branches", "2", "--duration", "0.02", "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"legkit sweep: {message}") and err.count("\n") == 1, err
        assert not out.exists()
    # Optional dependencies, checked up front with the install command.
    import importlib.util

    real = importlib.util.find_spec
    for module, extra, command in [("pyarrow", "sweep", sweep_cli.main), ("optuna", "sweep", tuning.main), ("ray", "cluster", sweep_cli.main)]:
        monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a, hidden=module: None if name == hidden else real(name, *a))
        argv = ["--out", str(out), "--ray", "local"] if command is sweep_cli.main else ["--trials", "1"]
        assert command(argv) == 2
        err = capsys.readouterr().err
        assert err.endswith(f"{module} is not installed; it comes with legkit's '{extra}' extra: install it from the legkit checkout with "
                           f".venv/bin/pip install '.[{extra}]'\n") and err.count("\n") == 1, err
        assert not out.exists()
        monkeypatch.setattr(importlib.util, "find_spec", real)


def _ray_cluster_running():
    return any(
        "raylet" in open(f"/proc/{p}/comm").read() for p in os.listdir("/proc") if p.isdigit() and os.path.exists(f"/proc/{p}/comm")
    ) if sys.platform.startswith("linux") else True


def _synthetic_table(varying, outlier=False):
    import itertools

    import pyarrow as pa

    rng = np.random.default_rng(0)
    rows = []
    values = {"loss": [0.0, 0.1, 0.3], "delay": [1, 4], "terrain": [0.0, 0.01], "noise": [0.0, 0.02], "friction": [0.8]}
    axes = {a: (values[a] if a in varying else values[a][:1]) for a in values}
    for scheme in SCHEMES:
        for c0, c1 in itertools.product([0.0, 0.5, 1.0], [0.1, 1.0, 3.0]):
            for combo in itertools.product(*axes.values()):
                final = 1e3 if outlier and (c0, c1) == (0.0, 0.1) else rng.random()
                rows.append({"run_id": f"{len(rows)}", "scheme": scheme, "c0": c0, "c1": c1, **dict(zip(axes, combo)), "final": final,
                             "t10": rng.random(), "energy": 10 ** rng.uniform(0, 3)})
    return pa.Table.from_pylist(rows)


def test_figures_are_legible_for_any_number_of_axes_and_robust_to_outliers():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from legkit.sweeps import figures

    for varying in ([], ["loss"], ["loss", "delay", "terrain", "noise"]):
        figure = figures.distributions_figure(figures._columns(_synthetic_table(varying)))
        figure.canvas.draw()
        renderer = figure.canvas.get_renderer()
        for axis in figure.axes:
            boxes = [t.get_window_extent(renderer) for t in axis.get_xticklabels() if t.get_visible() and t.get_text()]
            assert all(not a.overlaps(b) for a, b in zip(boxes, boxes[1:])), varying
            # Inside the figure: not cut off at the bottom.
            assert all(b.y0 >= 0 for b in boxes), varying
        plt.close(figure)
    heat = figures.heatmap_figure(figures._columns(_synthetic_table([], outlier=True)))
    image = heat.axes[0].images[0]
    low, high = image.get_clim()
    assert high < 1.0  # the 1e3 cell is clipped; the others (in [0, 1)) spread over the colours
    assert "5–95 % quantiles" in heat.axes[-1].get_ylabel()
    plt.close(heat)


def test_servo_torques_are_limited_to_the_stall_torque(monkeypatch):
    """run_balance clips every joint torque to the servo's limit: the paper's constant scheme (K_P = 10 N m/rad
    on errors of tenths of a radian) saturates it, and never exceeds it."""
    from legkit.robots import superbot as sb

    applied = []
    real_batch = closed_loop.lk.SimulationBatch

    class Recording:
        def __init__(self, simulations):
            self._batch = real_batch(simulations)

        def __getattr__(self, name):
            return getattr(self._batch, name)

        def step(self, taus, **kwargs):
            if taus is not None:
                applied.append(np.abs(np.asarray(taus)).max())
            return self._batch.step(taus, **kwargs)

    monkeypatch.setattr(closed_loop.lk, "SimulationBatch", Recording)
    for limit in (0.05, 1.0):
        applied.clear()
        trees = [random_tree(4, 2, 0, sb.ModuleParameters(servo_torque_limit=limit))]
        closed_loop.run_balance(trees, 0.05, runs=[closed_loop.RunSpec(0, GainSchedule.paper("constant"))], progress=False)
        assert max(applied) == limit
    assert sb.ModuleParameters().servo_torque_limit == sb.SERVO_TORQUE_LIMIT == 1.0
    for bad in (0.0, -1.0, float("nan"), "1"):
        with pytest.raises(ValueError, match="^servo_torque_limit"):
            sb.ModuleParameters(servo_torque_limit=bad)


@pytest.mark.slow
def test_ray_local_starts_an_instance_even_when_ray_address_names_a_cluster(tiny_sweep, tmp_path, monkeypatch):
    """--ray local means a new local instance, whatever RAY_ADDRESS says (here an address where nothing
    listens); the run's table is the in-process one, and the instance is shut down after."""
    _, reference = tiny_sweep
    monkeypatch.setenv("RAY_ADDRESS", "127.0.0.1:9")
    assert not ray.is_initialized()
    table = run_sweep(SweepSpec(**TINY), tmp_path / "ray-local", ray="local", progress=False, figures=False)
    assert not ray.is_initialized()
    assert_same_table(table, reference)


def test_rows_from_a_worker_of_another_build_are_refused_unless_allowed(tmp_path, monkeypatch):
    """A worker (a cluster node) with another legkit build: the sweep stops naming both builds, before
    writing its rows; with allow_mixed the rows are kept under their own build, and the part checks out."""
    from legkit.sweeps import execute

    real = execute.run_batch

    def other_node(spec_values, runs, threads=None):
        return [{**row, "build": "f" * 16} for row in real(spec_values, runs, threads)]

    monkeypatch.setattr(execute, "run_batch", other_node)
    spec = SweepSpec(**{**TINY, "trees": 1, "batch_size": 4})
    with pytest.raises(ValueError, match=r"^ray: a worker ran legkit build f{16}, this driver is build [0-9a-f]{16}"):
        run_sweep(spec, tmp_path / "refused", workers=1, progress=False, figures=False)
    assert not list((tmp_path / "refused" / "parts").glob("*.parquet"))
    table = run_sweep(spec, tmp_path / "mixed", workers=1, progress=False, figures=False, allow_mixed=True)
    assert set(table.column("build").to_pylist()) == {"f" * 16}
    monkeypatch.setattr(execute, "run_batch", real)
    assert execute.ResultStore(tmp_path / "mixed", spec, allow_mixed=True).verify_part(0) is None
