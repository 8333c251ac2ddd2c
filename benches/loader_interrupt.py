"""Ctrl-C during `Model.from_urdf` and `Model.from_mjcf`: the time from SIGINT to KeyboardInterrupt, in a child
process, with the signal sent at fractions of the load (as timed by the child's own first, whole load), so that
every phase is hit: reading the file, the attribute scan, the XML parse, building the model. Median and max of
repeats, in ms. Files: a URDF chain of revolute links, as many MJCF pendulums, and a URDF whose parse is nearly the whole
load (elements of 1024 attributes), where the loader's thread cannot stop and the caller answers without it.

Run: python benches/loader_interrupt.py [--links 200000] [--repeats 3]
"""

from __future__ import annotations

import argparse
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from urdf_load import chain_urdf

CHILD = """
import sys, time, warnings
import legkit as lk
warnings.simplefilter("ignore")
load, path = getattr(lk.Model, sys.argv[1]), sys.argv[2]
started = time.monotonic()
load(path)
print(time.monotonic() - started, flush=True)
sys.stdin.readline()
try:
    print(time.monotonic(), flush=True)
    load(path)
    print("finished", flush=True)
except KeyboardInterrupt:
    print(time.monotonic(), flush=True)
"""


def bodies_mjcf(bodies: int) -> str:
    """`bodies` pendulums side by side (not nested: XML parsers bound the nesting depth)."""
    return "<mujoco><worldbody>" + "".join(
        f'<body name="b{i}" pos="0 0 -0.1"><joint name="j{i}" type="hinge" axis="0 1 0"/>'
        '<inertial pos="0 0 0" mass="1" diaginertia="0.01 0.01 0.01"/></body>'
        for i in range(bodies)
    ) + "</worldbody></mujoco>"


def answer_ms(loader: str, path: Path, fraction: float) -> tuple[float | None, float]:
    """(ms from SIGINT to KeyboardInterrupt, the whole load in s) with SIGINT at `fraction` of the load; None
    when the second load, quicker than the first on a noisy machine, finished before the signal."""
    child = subprocess.Popen([sys.executable, "-c", CHILD, loader, str(path)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    assert child.stdin is not None and child.stdout is not None
    whole = float(child.stdout.readline())
    child.stdin.write("\n")
    child.stdin.flush()
    started = float(child.stdout.readline())
    time.sleep(max(0.0, started + fraction * whole - time.monotonic()))
    sent = time.monotonic()
    child.send_signal(signal.SIGINT)
    answered = child.stdout.readline().strip()
    child.wait()
    return (None if answered == "finished" else (float(answered) - sent) * 1e3), whole


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--links", type=int, default=200_000)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    element = "<a " + " ".join(f'b{i}="0"' for i in range(1024)) + "/>"
    with tempfile.TemporaryDirectory() as folder:
        files = {
            "from_urdf chain": ("from_urdf", Path(folder) / "chain.urdf", chain_urdf(args.links)),
            "from_mjcf pendulums": ("from_mjcf", Path(folder) / "pendulums.xml", bodies_mjcf(args.links)),
            "from_urdf parse-bound": (
                "from_urdf",
                Path(folder) / "parse.urdf",
                f'<robot name="r"><link name="base"/><documentation>{element * 3000}</documentation></robot>',
            ),
        }
        print(f"{'file':24s} {'load s':>7s} {'SIGINT at':>9s} {'median ms':>10s} {'max ms':>7s}   (machine load {os.getloadavg()[0]:.2f})")
        for name, (loader, path, text) in files.items():
            path.write_text(text)
            for fraction in (0.05, 0.2, 0.4, 0.6, 0.8):
                runs = [answer_ms(loader, path, fraction) for _ in range(args.repeats)]
                ms = [m for m, _ in runs if m is not None]
                whole = statistics.median(w for _, w in runs)
                late = f"   ({len(runs) - len(ms)} loads ended before the signal)" if len(ms) < len(runs) else ""
                if ms:
                    print(f"{name:24s} {whole:7.2f} {fraction:9.2f} {statistics.median(ms):10.1f} {max(ms):7.1f}{late}")


if __name__ == "__main__":
    main()
