"""MJCF loading time and ABA against MuJoCo on dm_control's humanoid and dog.

* Load time of a generated MJCF tree with default classes, fromto capsules and hinge joints of 100 bodies
  (target < 50 ms), and of 200, 400, 800 and 1600 bodies: the time per kilobyte shows whether loading is linear
  in file size. `lk.Model.from_mjcf` on the XML string; median and min of repeats.
* ABA on dm_control's suite humanoid (free base, 21 hinges) and dog (the dog's free body and its ball, each on
  three slides and a ball joint) against MuJoCo's `mj_forward` with contacts disabled, one Python call each, same
  run, at random states: median of repeats and their ratio.

Run: python benches/mjcf_load.py [--repeats 30]
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import statistics
import time
import warnings
from collections.abc import Callable

import numpy as np

import legkit as lk


def tree_xml(bodies: int, seed: int = 0) -> str:
    """A random tree of `bodies` bodies, each on a hinge (two on every fifth) with a capsule and a sphere."""
    rng = np.random.default_rng(seed)
    children: list[list[int]] = [[] for _ in range(bodies)]
    for b in range(1, bodies):
        children[int(rng.integers(0, b))].append(b)

    def body(b: int, depth: int) -> str:
        axis = " ".join(f"{x:.3f}" for x in rng.normal(size=3))
        joints = f'<joint name="j{b}" axis="{axis}" range="-90 90"/>'
        if b % 5 == 0:
            joints += f'<joint name="k{b}" class="bend" pos="0 0 .02"/>'
        inner = "".join(body(c, depth + 1) for c in children[b])
        return (
            f'<body name="b{b}" pos="{rng.uniform(-.1, .1):.3f} {rng.uniform(-.1, .1):.3f} -0.3" euler="{rng.uniform(-30, 30):.1f} 0 10">'
            f'{joints}<geom type="capsule" fromto="0 0 0 0 0 -0.3"/><geom type="sphere" size="0.04" pos="0 0 -0.3"/>{inner}</body>'
        )

    return (
        '<mujoco><default><geom size="0.03" density="800"/><joint damping="0.1" armature="0.01"/>'
        '<default class="bend"><joint axis="1 0 0" range="-45 45"/></default></default>'
        f"<worldbody>{body(0, 0)}</worldbody></mujoco>"
    )


def timed(call: Callable[[], object], repeats: int) -> tuple[float, float]:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        call()
        times.append(time.perf_counter() - start)
    return statistics.median(times), min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=30)
    args = parser.parse_args()

    print("bodies   kB    median ms   min ms   median us/kB")
    for bodies in (100, 200, 400, 800, 1600):
        xml = tree_xml(bodies)
        model = lk.Model.from_mjcf(xml)
        assert model.nbodies == 1 + bodies + len(range(0, bodies, 5))  # the world, the bodies, one per second joint
        median, best = timed(lambda xml=xml: lk.Model.from_mjcf(xml), args.repeats)
        kb = len(xml) / 1000
        print(f"{bodies:6d} {kb:6.0f} {median * 1e3:10.2f} {best * 1e3:8.2f} {median * 1e6 / kb:12.1f}")

    spec = importlib.util.find_spec("dm_control")
    if spec is None or spec.origin is None:
        print("dm_control is not installed: no ABA comparison")
        return
    import mujoco

    for name in ("humanoid.xml", "dog.xml"):
        path = os.path.join(os.path.dirname(spec.origin), "suite", name)
        m = mujoco.MjModel.from_xml_path(path)
        m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
        d = mujoco.MjData(m)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", lk.MjcfWarning)
            model = lk.Model.from_mjcf(path)
        rng = np.random.default_rng(0)
        # Random states of the same kind in both: each coordinate moved from the file's pose by a random velocity.
        q = lk.integrate(model, model.neutral(), rng.normal(scale=0.3, size=model.nv), 1.0)
        v, tau = rng.normal(size=model.nv), rng.normal(size=model.nv)
        d.qpos[:] = m.qpos0
        mujoco.mj_integratePos(m, d.qpos, rng.normal(scale=0.3, size=m.nv), 1.0)
        d.qvel[:] = rng.normal(size=m.nv)
        aba, _ = timed(lambda model=model, q=q, v=v, tau=tau: lk.aba(model, q, v, tau), args.repeats * 100)
        forward, _ = timed(lambda m=m, d=d: mujoco.mj_forward(m, d), args.repeats * 100)
        print(
            f"{name} (nv={model.nv}, MuJoCo nv={m.nv}): lk.aba {aba * 1e6:.2f} us, "
            f"mj_forward (no contacts) {forward * 1e6:.2f} us, ratio {aba / forward:.2f}"
        )

if __name__ == "__main__":
    main()
