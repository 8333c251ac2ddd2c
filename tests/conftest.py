"""Hypothesis profiles and shared strategies for the legkit tests.

Profiles (select with the environment variable LEGKIT_HYPOTHESIS_PROFILE):
  legkit   (default; what CI runs) derandomized: the same examples every run, so CI is reproducible; no
           deadline; 100 examples per property (hypothesis' default), or exactly n for a test decorated
           with `@examples(n)`;
  quick    a quarter of that (at least min(n, 5)), for a fast local loop;
  thorough ten times as many, random ones (not derandomized), for occasional deep runs.
Every property test takes its example count from `examples(n)` (never a hard-coded
`settings(max_examples=...)`), so the selected profile governs all of them.
No example database is written (database=None) so test runs leave no files behind; a failing example is
printed together with a @reproduce_failure blob.

Strategies return plain numpy data (never legkit objects), so this module does not import legkit.
"""

from __future__ import annotations

import os
import signal
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).resolve().parent))

import reference as ref  # noqa: E402

settings.register_profile(
    "legkit",
    max_examples=100,
    derandomize=True,
    deadline=None,
    database=None,
    print_blob=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)
settings.register_profile("quick", parent=settings.get_profile("legkit"), max_examples=25)
settings.register_profile("thorough", parent=settings.get_profile("legkit"), max_examples=1000, derandomize=False)
PROFILE = os.environ.get("LEGKIT_HYPOTHESIS_PROFILE", "legkit")
settings.load_profile(PROFILE)
_EXAMPLE_FACTOR = {"legkit": 1.0, "quick": 0.25, "thorough": 10.0}.get(PROFILE, 1.0)


def ctrl_c_restored() -> None:
    """`preexec_fn` of a child a test sends SIGINT: Ctrl-C back to its default disposition. A test run started with
    SIGINT ignored (a background job of a non-interactive shell, nohup) passes that on to its children, and a Python
    started so installs no KeyboardInterrupt handler."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def examples(n: int) -> settings:
    """@settings for a property that runs n examples under the default profile: n/4 (at least min(n, 5))
    under quick, 10 n under thorough. The other settings come from the selected profile."""
    return settings(max_examples=max(min(n, 5), int(n * _EXAMPLE_FACTOR)))


def reals(lo: float, hi: float):
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False)


def vectors(lo: float = -10.0, hi: float = 10.0):
    return st.tuples(reals(lo, hi), reals(lo, hi), reals(lo, hi)).map(lambda v: np.array(v, dtype=np.float64))


@st.composite
def rotations(draw):
    """A uniformly-ish distributed proper rotation from a random quaternion (orthonormal to ~1e-16)."""
    q = draw(
        st.tuples(reals(-1, 1), reals(-1, 1), reals(-1, 1), reals(-1, 1)).filter(
            lambda q: np.linalg.norm(q) > 0.1
        )
    )
    return ref.quaternion_to_rotation(np.array(q))


# Direction components: mostly uniform, sometimes exactly 0 or tiny, so that nearly axis-aligned directions
# (the usual trigger of branch/basis-selection bugs) are probed on purpose.
_COMPONENTS = st.one_of(
    reals(-1, 1),
    reals(-1, 1),
    st.sampled_from([0.0, -0.0, 1e-300, -1e-60, 1e-30, -1e-16, 1e-12, -1e-8, 1e-5]),
)


@st.composite
def directions(draw, min_norm: float = 1e-3, max_norm: float = 1e3):
    """A non-zero, generally non-unit direction vector: a random unit vector times a random length."""
    v = draw(
        st.tuples(_COMPONENTS, _COMPONENTS, _COMPONENTS)
        .map(lambda t: np.array(t, dtype=np.float64))
        .filter(lambda v: np.linalg.norm(v) > 0.1)
    )
    length = draw(reals(np.log(min_norm), np.log(max_norm)).map(np.exp))
    return ref.unit(v) * length


@dataclass(frozen=True)
class Body:
    """A random physical body: its (mass, com, inertia about com) and an equivalent six-point cloud.

    The cloud is an independent witness for the brute-force references: six masses m/6 at
    com +- sqrt(3) l_k e_k (e_k the principal axes) have total mass m, centre com and second moments
    2 (m/6) 3 l_k^2 = m l_k^2 = s_k, hence exactly the inertia built in `bodies`.
    """

    mass: float
    com: np.ndarray
    inertia: np.ndarray
    cloud_masses: np.ndarray
    cloud_positions: np.ndarray

    @property
    def args(self):
        return self.mass, self.com, self.inertia


@st.composite
def bodies(draw, mass_range=(0.01, 100.0), com_range=(-10.0, 10.0), length_range=(0.01, 2.0)):
    """A random physical body (see Body) with mass, com and principal radii in the given ranges.

    Principal moments come from positive second moments s_k = m l_k^2: I1 = s2 + s3, I2 = s1 + s3,
    I3 = s1 + s2, which satisfy the triangle inequality with a strict margin (I1 + I2 - I3 = 2 s3 > 0);
    the tensor is rotated to a random frame and symmetrised exactly.
    """
    mass = draw(reals(*mass_range))
    com = draw(vectors(*com_range))
    lengths = np.array(draw(st.tuples(*[reals(*length_range)] * 3)))
    r = draw(rotations())
    s1, s2, s3 = mass * lengths**2
    inertia = r @ np.diag([s2 + s3, s1 + s3, s1 + s2]) @ r.T
    inertia = 0.5 * (inertia + inertia.T)
    offsets = (np.sqrt(3.0) * lengths)[None, :] * r  # column k: sqrt(3) l_k e_k
    positions = np.concatenate([com + offsets.T, com - offsets.T])
    return Body(mass, com, inertia, np.full(6, mass / 6.0), positions)


@st.composite
def point_clouds(draw, min_points: int = 1, max_points: int = 12):
    """(masses (n,), positions (n, 3)) with masses in [0.01, 100] and positions in [-10, 10]^3."""
    n = draw(st.integers(min_points, max_points))
    masses = np.array(draw(st.lists(reals(0.01, 100.0), min_size=n, max_size=n)))
    positions = np.array(draw(st.lists(vectors(), min_size=n, max_size=n))).reshape(n, 3)
    return masses, positions
