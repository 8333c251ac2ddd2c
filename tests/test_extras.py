"""The base install (NumPy and SciPy) and the extras: with every optional module made unimportable, the library's
base features work and each optional feature raises an ImportError naming its extra and install command."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

import legkit
from legkit import _extras

ROOT = Path(__file__).resolve().parents[1]
OPTIONAL = ("casadi", "matplotlib", "tqdm", "meshcat", "PIL", "pyarrow", "optuna", "ray")

# A meta-path finder that refuses every optional module, as an environment without the extras would.
BLOCK = f"""
import sys
class Block:
    def find_spec(self, name, path=None, target=None):
        if name.partition(".")[0] in {OPTIONAL!r}:
            raise ModuleNotFoundError(f"No module named {{name!r}} (blocked)", name=name)
        return None
sys.meta_path.insert(0, Block())
"""

BASE = """
import numpy as np
import legkit as lk
import legkit.stability as st
from legkit.agents import AgentNetwork, GroundContact
from legkit.control import run_balance
from legkit.robots.quadruped import build_quadruped
from legkit.robots.superbot import random_tree
from legkit.strain.benchtop import synthetic_benchtop
from legkit.strain.pose import tripod_pose

robot = build_quadruped()
q = np.zeros(robot.model.nq)
q[6] = 1.0
a = lk.aba(robot.model, q, np.zeros(robot.model.nv), np.zeros(robot.model.nv))
assert np.all(np.isfinite(a)) and a[2] < 0  # falls
sim = lk.Simulation(robot.model, dt=1e-3)
sim.q = q
sim.step(n=20)
assert sim.time > 0.019 and sim.q[2] < 0

tree = random_tree(6, 2, 0)
AgentNetwork(tree, ground=[GroundContact(0, 0, np.eye(3), np.zeros(3), np.zeros(3), np.array([0.0, 0.0, 1.0]))])
(result,) = run_balance([tree], duration=0.02, progress=False, runs=None)[:1]

synthetic_benchtop(seed=0)
tripod_pose(np.array([[0.1, 0.0, 0.0], [-0.1, 0.1, 0.0], [-0.1, -0.1, 0.0]]))

feet = np.array([[0.2, 0.1, 0.0], [0.2, -0.1, 0.0], [-0.2, 0.1, 0.0], [-0.2, -0.1, 0.0]])
assert st.static_stability_margin([0.0, 0.0, 0.3], feet) > 0
assert len(st.static_equilibrium_region([(p, [0.0, 0.0, 1.0]) for p in feet], mu=0.8)) >= 3
for module in {optional!r}:
    assert module not in sys.modules, module
print("base ok")
"""

# Each optional feature, and the extra its ImportError must name.
FEATURES = [
    ("optimize", "import numpy as np\nfrom legkit.optimize import solve\nsolve(None, np.zeros(1))"),
    ("viewer", "import legkit as lk\nfrom legkit.viewer import Viewer\nViewer(lk.Model())"),
    ("viewer", "from pathlib import Path\nfrom legkit.viewer import Scene\nfrom legkit.viewer._render import write_png\n"
               "write_png(Scene(), Path('x.png'))"),
    ("plot", "from legkit import cli\nraise SystemExit(cli.main(['balance', '--duration', '0.01']))"),
    ("plot", "from legkit import cli\nraise SystemExit(cli.main(['gait', '--samples', '8']))"),
    ("sweep", "import legkit.sweeps as sw\nsw.read_results('nowhere')"),
    ("sweep", "from legkit import cli\nraise SystemExit(cli.main(['tune', '--trials', '1']))"),
    ("sweep", "from legkit import cli\nraise SystemExit(cli.main(['sweep', '--trees', '1', '--out', '/nonexistent/never']))"),
    ("cluster", "from legkit.sweeps import RayExecutor\nRayExecutor()"),
]


def _run(code: str) -> subprocess.CompletedProcess[str]:
    # The legkit this test imported: the checkout's python/ folder, or the installed wheel (CI), whose extension the
    # checkout does not hold.
    env = {"PYTHONPATH": str(Path(legkit.__file__).resolve().parents[1]), "PATH": "/usr/bin:/bin", "HOME": str(Path.home())}
    return subprocess.run([sys.executable, "-c", BLOCK + code], capture_output=True, text=True, env=env, timeout=300, cwd=ROOT)


def test_the_base_features_run_without_the_optional_modules() -> None:
    done = _run(BASE.format(optional=OPTIONAL))
    assert done.returncode == 0 and "base ok" in done.stdout, done.stderr


def test_each_optional_feature_names_its_extra_and_install_command() -> None:
    for extra, code in FEATURES:
        done = _run(code)
        output = done.stdout + done.stderr
        assert done.returncode != 0, (extra, output)
        assert f"'{extra}' extra" in output and f".venv/bin/pip install '.[{extra}]'" in output, (extra, output)


def test_require_names_the_extra() -> None:
    try:
        _extras.require("numpy", "legkit_no_such_module", extra="plot")
    except _extras.MissingExtra as error:
        assert str(error) == _extras.missing_message("legkit_no_such_module", "plot")
        assert "'plot' extra" in str(error) and ".venv/bin/pip install '.[plot]'" in str(error)
    else:
        raise AssertionError("no ImportError")
    assert isinstance(_extras.MissingExtra("x"), ImportError)
    assert list(_extras.progress([1, 2], enabled=False)) == [1, 2]


def test_the_extras_declared_match_the_modules_legkit_names() -> None:
    tomllib = pytest.importorskip("tomllib")  # Python 3.11+
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    distribution = {"PIL": "pillow", "ray": "ray[tune]"}

    def names(requirements: list[str]) -> set[str]:
        return {r.split(">")[0].split("<")[0].split("=")[0] for r in requirements}

    for module, extra in _extras.EXTRAS.items():
        assert distribution.get(module, module) in names(extras[extra]), (module, extra)
    optional = set().union(*(names(extras[e]) for e in extras if e not in ("all", "test")))
    assert names(extras["all"]) == optional
    assert optional <= names(extras["test"])  # the tests exercise every extra
    assert legkit.__name__ == "legkit"


def test_the_cli_checks_the_extras_an_experiment_run_needs() -> None:
    from legkit.cli import needs

    plot, viewer, optimize = (("matplotlib", "tqdm"), "plot"), (("meshcat", "PIL"), "viewer"), (("casadi",), "optimize")
    assert needs("balance", []) == [plot, viewer]
    assert needs("balance", ["--no-animation"]) == [plot]
    assert needs("gait", []) == [plot]
    assert needs("gait", ["--optimize"]) == [plot, optimize, viewer]
    assert needs("gait", ["--optimize", "--no-animation"]) == [plot, optimize]
    assert needs("strain", ["--help"]) == [] and needs("demo", []) == []
