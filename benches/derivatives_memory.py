"""Peak memory of the O(n) algorithms and of the derivatives on long revolute chains, each call in its own process.

Each row builds a chain of n links (1 kg, 0.1 m apart, axes along y, as tests/test_hostile.py's URDF), reads the process's peak
resident set (VmRSS in /proc/self/status) after loading, resets the peak to it, runs one call and reads the peak
(VmHWM): the difference is what the call took at its peak, outputs included. For the derivatives the outputs are printed beside it (nv x nv each,
so they are timed on 2,000 links), and what the call took beyond them is the workspace.

Target (issue 34): the O(n) algorithms and their derivatives use O(n) workspace beyond their outputs; RNEA and ABA
on a 20,000-link chain within 100 MB.

Run from the repository root:  python benches/derivatives_memory.py
"""

from __future__ import annotations

import json
import subprocess
import sys

MB = 2**20

CHILD = """
import json, sys
import numpy as np
import legkit as lk

def status(field):
    return int(open("/proc/self/status").read().split(field + ":")[1].split()[0]) * 1024

links, call = int(sys.argv[1]), sys.argv[2]
model = lk.Model()
body, placement = lk.MassProperties(1.0, np.zeros(3), 0.01 * np.eye(3)), np.eye(4)
placement[2, 3] = -0.1
for i in range(1, links):
    model.add_revolute(i - 1, [0.0, 1.0, 0.0], placement, body, f"j{i}")
q, v, a = np.full(model.nq, 0.1), np.full(model.nv, 0.2), np.full(model.nv, 0.3)
# Resets the peak to the resident set now (Linux's clear_refs), so that loading's own peak does not hide the call's.
with open("/proc/self/clear_refs", "w") as f:
    f.write("5")
before = status("VmRSS")
out = eval(call)
out = out if isinstance(out, tuple) else (out,)
print(json.dumps({"nv": model.nv, "taken": status("VmHWM") - before, "outputs": sum(x.nbytes for x in out)}))
"""

ROWS = [
    (20_000, "lk.rnea(model, q, v, a)"),
    (20_000, "lk.aba(model, q, v, a)"),
    (20_000, "lk.forward_kinematics(model, q)"),
    (20_000, "lk.centroidal_derivatives(model, q, v, a)"),
    (2_000, "lk.rnea_derivatives(model, q, v, a)"),
    (2_000, "lk.aba_derivatives(model, q, v, a)"),
]


def main() -> None:
    print(f"{'links':>6s}  {'call':45s} {'peak taken':>11s} {'outputs':>9s} {'beyond':>9s}")
    for links, call in ROWS:
        result = subprocess.run([sys.executable, "-c", CHILD, str(links), call], capture_output=True, text=True, check=True)
        row = json.loads(result.stdout.strip().splitlines()[-1])
        taken, outputs = row["taken"] / MB, row["outputs"] / MB
        print(f"{links:6d}  {call:45s} {taken:9.1f}MB {outputs:7.1f}MB {max(taken - outputs, 0.0):7.1f}MB")


if __name__ == "__main__":
    main()
