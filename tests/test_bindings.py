"""The bindings' contract with Python arrays: a batched call reads its array arguments once, with the GIL
held, before its kernels run without the GIL, so another thread writing an argument meanwhile cannot change
what the call computes (reading it during the GIL-free work would be a data race); and it reads them by
their strides, whatever their memory order."""

from __future__ import annotations

import threading

import numpy as np

import legkit as lk


def chain(n_bodies: int) -> lk.Model:
    model = lk.Model(floating_base=False, base=None)
    link = lk.MassProperties.solid_box(0.5, [0.1, 0.04, 0.04], center=[0.05, 0.0, 0.0])
    for body in range(n_bodies):
        model.add_revolute(body, [0.0, 1.0, 0.2 * (body % 3)], (np.eye(3), [0.1, 0.0, 0.0]), link, f"link{body}")
    return model


def test_a_writer_thread_cannot_change_a_batched_call_while_it_runs():
    """A thread cycles the rows of q through three configurations while ABA runs on 4000 rows of a 100-body
    chain. The call works on one snapshot of q, taken mid-cycle at worst: every result row is ABA of one of
    the three configurations, and at most two of them appear (the rows already rewritten and the rest)."""
    model = chain(100)
    rows = 4000
    configurations = np.array([np.full(model.nq, angle) for angle in (0.1, -0.4, 0.7)])
    expected = lk.aba(model, configurations, np.zeros((3, model.nv)), np.zeros((3, model.nv)))
    q = np.repeat(configurations[:1], rows, axis=0)
    zeros = np.zeros((rows, model.nv))
    stop = threading.Event()

    def write() -> None:
        cycle = 0
        while not stop.is_set():
            cycle += 1
            for i in range(rows):
                q[i] = configurations[cycle % 3]  # one small row assignment per statement, GIL held

    writer = threading.Thread(target=write)
    writer.start()
    try:
        results = [lk.aba(model, q, zeros, zeros) for _ in range(5)]
    finally:
        stop.set()
        writer.join()
    for result in results:
        distance = np.abs(result[:, None, :] - expected[None, :, :]).max(axis=2)  # (rows, 3)
        match = distance.argmin(axis=1)
        assert np.all(distance[np.arange(rows), match] <= 1e-9 * np.abs(expected).max()), "a row matches no configuration"
        assert len(set(match.tolist())) <= 2, f"the call saw configurations {sorted(set(match.tolist()))}: q changed under it"


def test_batched_calls_read_arrays_in_any_memory_order():
    """Fortran-ordered arrays (a transpose's layout), strided views, column slices and C-ordered copies of the same numbers give
    the same results bit for bit. Fortran order used to be read as if it were C order: wrong numbers, silently."""
    model = chain(6)
    rng = np.random.default_rng(7)
    q, v, a = (rng.normal(size=(5, model.nv)) for _ in range(3))
    layouts = {
        "fortran": np.asfortranarray,
        "transposed copy": lambda x: np.ascontiguousarray(x.T).T,
        "strided": lambda x: np.repeat(x, 2, axis=0)[::2],
        "column slice": lambda x: np.concatenate([x, -x], axis=1)[:, : x.shape[1]],  # rows contiguous, apart
    }
    points = [rng.normal(size=(5, 3)) for _ in range(5)]

    def batch_step(taus: np.ndarray) -> np.ndarray:
        batch = lk.SimulationBatch([lk.Simulation(model, dt=1e-3) for _ in range(len(taus))])
        batch.step(taus)
        return batch.v

    calls = {
        "rnea": lambda f: lk.rnea(model, f(q), f(v), f(a)),
        "aba": lambda f: lk.aba(model, f(q), f(v), f(a)),
        "forward_kinematics": lambda f: lk.forward_kinematics(model, f(q)),
        "center_of_mass": lambda f: lk.center_of_mass(model, f(q)),
        "crba": lambda f: lk.crba(model, f(q)),
        "jacobian": lambda f: lk.jacobian(model, f(q), 3),
        "SimulationBatch.step": lambda f: batch_step(f(a)),
        "rotation_toward_line": lambda f: np.stack(lk.rotation_toward_line(*(f(p) for p in points))),
    }
    for name, call in calls.items():
        expected = call(np.ascontiguousarray)
        for layout, make in layouts.items():
            assert np.array_equal(call(make), expected), f"{name} with {layout} arguments"
