"""URDF loading time against the number of links: chains of 10^3 to 10^5 revolute links (issue target: a 10^5-link
URDF in under 2 s), `lk.Model.from_urdf` on a file; median and min of repeats, and the time per link, which stays
flat when loading is linear.

Run: python benches/urdf_load.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import legkit as lk


def chain_urdf(links: int) -> str:
    """A URDF chain of `links` links on revolute joints."""
    inertial = '<inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>'
    parts = ['<robot name="chain">', f'<link name="l0">{inertial}</link>']
    for i in range(1, links):
        parts.append(f'<link name="l{i}">{inertial}</link>')
        parts.append(f'<joint name="j{i}" type="revolute"><parent link="l{i - 1}"/><child link="l{i}"/>'
                     '<origin xyz="0 0 -0.1"/><axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="10" velocity="1"/></joint>')
    parts.append("</robot>")
    return "\n".join(parts)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    print("links     median s    min s   median us/link")
    with tempfile.TemporaryDirectory() as folder:
        for links in (1_000, 10_000, 100_000):
            path = Path(folder) / f"chain{links}.urdf"
            path.write_text(chain_urdf(links))
            times = []
            for _ in range(args.repeats):
                start = time.perf_counter()
                lk.Model.from_urdf(str(path))
                times.append(time.perf_counter() - start)
            median = statistics.median(times)
            print(f"{links:7d} {median:10.3f} {min(times):8.3f} {median * 1e6 / links:12.2f}")


if __name__ == "__main__":
    main()
