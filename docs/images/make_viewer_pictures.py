"""Makes docs/images/viewer_solo12.png: Solo-12 (example-robot-data) in legkit.viewer, its URDF <visual> meshes
beside the shapes the simulation collides with, rendered by headless Chromium (meshcat's WebGL page).

    python docs/images/make_viewer_pictures.py      # needs chromium (Debian package) and example-robot-data
"""

from __future__ import annotations

import importlib.metadata
import shutil
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

from PIL import Image

import legkit as lk
from legkit import viewer

HERE = Path(__file__).resolve().parent
ROBOTS = Path(str(importlib.metadata.distribution("example-robot-data").locate_file("cmeel.prefix/share/example-robot-data/robots")))


def screenshot(page: Path, picture: Path, size: tuple[int, int]) -> None:
    chromium = shutil.which("chromium")
    if chromium is None:
        sys.exit("chromium not found: apt-get install -y --no-install-recommends chromium")
    subprocess.run(
        [chromium, "--headless", "--no-sandbox", "--disable-gpu", "--use-gl=swiftshader", "--enable-unsafe-swiftshader",
         "--hide-scrollbars", f"--window-size={size[0]},{size[1]}", "--virtual-time-budget=4000", f"--screenshot={picture}", page.as_uri()],
        check=True, capture_output=True, timeout=120,
    )


def main() -> None:
    urdf = ROBOTS / "solo_description" / "robots" / "solo12.urdf"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", lk.UrdfWarning)
        model = lk.Model.from_urdf(urdf, floating_base=True)
    q = model.neutral()
    q[2] = 0.24
    for body, name in enumerate(model.names):  # knees bent, front and hind legs mirrored
        front = 1.0 if name.startswith("F") else -1.0
        if name.endswith("UPPER_LEG"):
            q[model.idx_q[body]] = 0.8 * front
        elif name.endswith("LOWER_LEG"):
            q[model.idx_q[body]] = -1.6 * front
    scene = viewer.Scene(view=(-55.0, 20.0), title="Solo-12 in legkit.viewer",
                         caption="left: the URDF's <visual> meshes; right: the shapes the simulation collides with")
    scene.add_robot(model, q, name="visual", geometry=viewer.visual_shapes(urdf, model), offset=(0.0, -0.3, 0.0), color=(0.62, 0.64, 0.68))
    scene.add_robot(model, q, name="collision", offset=(0.0, 0.3, 0.0), color=(0.95, 0.5, 0.1))
    size = (960, 480)
    with tempfile.TemporaryDirectory() as folder:
        page = scene.write_html(Path(folder) / "solo12.html")
        raw = Path(folder) / "shot.png"
        screenshot(page, raw, size)
        image = Image.open(raw).convert("RGB")
    out = HERE / "viewer_solo12.png"
    image.quantize(colors=128, method=Image.Quantize.MEDIANCUT).save(out, optimize=True)
    print(f"wrote {out} ({out.stat().st_size / 1e3:.0f} kB)")


if __name__ == "__main__":
    main()
