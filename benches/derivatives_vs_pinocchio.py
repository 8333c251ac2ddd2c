"""Side-by-side timing of legkit's and Pinocchio's analytic derivatives, called from Python, on identical models.

For each model (`models.MODELS`: the 18-DoF floating quadruped, the 63-DoF SuperBot-like tree, revolute chains of 64
and 512 links) the script first compares the two libraries at one random state (max |difference| / max |Pinocchio|,
printed; for the ABA derivatives also the residual max |M X + dtau/dx| / (max |M| max |X|) of each side, which shows
whose error it is where the mass matrix is ill-conditioned), then times one call of each, interleaved, in one process:

    legkit:    lk.rnea_derivatives(model, q, v, a)      lk.aba_derivatives(model, q, v, tau)
               lk.centroidal_derivatives(model, q, v, a)
    pinocchio: pin.computeRNEADerivatives(model, data, q, v, a)
               pin.computeABADerivatives(model, data, q, v, tau)
               pin.computeCentroidalDynamicsDerivatives(model, data, q, v, a)   (one preallocated pin.Data per model)

Each figure is the median of `timeit` repeats (7, or 3 with --quick), as benches/dynamics_vs_pinocchio.py times them.
Both return new arrays: legkit's (dq, dv[, M^-1]) and its four centroidal ones, Pinocchio's views of its Data (RNEA,
ABA) and four new 6 x nv matrices (centroidal). Target: legkit / pin <= 0.7 on every row (printed, never asserted).

Last, the configuration space's Jacobians on the quadruped: lk.difference_jacobians(model, q0, q1), both in one call,
against pin.dDifference(model, q0, q1, ARG0) and (..., ARG1), two calls, summed.

Run from the repository root:  python benches/derivatives_vs_pinocchio.py [--quick] [--models quadruped tree ...]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin

import legkit as lk

sys.path.insert(0, str(Path(__file__).resolve().parent))
from dynamics_vs_pinocchio import Settings, relative_error, symmetrised_upper, time_calls  # noqa: E402
from models import MODELS, random_state  # noqa: E402

TARGET_RATIO = 0.7
DEFAULT_MODELS = ("quadruped", "tree", "chain64", "chain512")


def residual(mass: np.ndarray, x: np.ndarray, dtau: np.ndarray) -> float:
    """max |M X + dtau| / (max |M| max |X|): zero for the exact -M^-1 dtau."""
    return float(np.abs(mass @ x + dtau).max() / (np.abs(mass).max() * np.abs(x).max()))


def compare(lk_model, pin_model, pin_data, q, v, tau, acc) -> str:
    pin_rnea = [np.array(x) for x in pin.computeRNEADerivatives(pin_model, pin_data, q, v, acc)[:2]]
    rnea_error = max(relative_error(ours, theirs) for ours, theirs in zip(lk.rnea_derivatives(lk_model, q, v, acc), pin_rnea))
    pin_aba = [np.array(x) for x in pin.computeABADerivatives(pin_model, pin_data, q, v, tau)]
    pin_aba[2] = symmetrised_upper(pin_aba[2])
    ours = lk.aba_derivatives(lk_model, q, v, tau)
    aba_error = max(relative_error(a, b) for a, b in zip(ours, pin_aba))
    pin_centroidal = [np.array(x) for x in pin.computeCentroidalDynamicsDerivatives(pin_model, pin_data, q, v, acc)]
    centroidal_error = max(relative_error(a, b) for a, b in zip(lk.centroidal_derivatives(lk_model, q, v, acc), pin_centroidal))
    mass, dtau = lk.crba(lk_model, q), lk.rnea_derivatives(lk_model, q, v, lk.aba(lk_model, q, v, tau))[0]
    return (
        f"rnea_d {rnea_error:.1e}  aba_d {aba_error:.1e}  centroidal_d {centroidal_error:.1e}  "
        f"(residual legkit {residual(mass, ours[0], dtau):.0e}, pin {residual(mass, pin_aba[0], dtau):.0e})"
    )


def difference_jacobians_row(settings: Settings, rng: np.random.Generator) -> None:
    lk_model, pin_model = MODELS["quadruped"]()
    q0, q1 = random_state(lk_model, rng)[0], random_state(lk_model, rng)[0]
    arguments = (pin.ArgumentPosition.ARG0, pin.ArgumentPosition.ARG1)
    ours = lk.difference_jacobians(lk_model, q0, q1)
    error = max(relative_error(a, np.array(pin.dDifference(pin_model, q0, q1, arg))) for a, arg in zip(ours, arguments))
    calls = [(lk.difference_jacobians, (lk_model, q0, q1))] + [(pin.dDifference, (pin_model, q0, q1, arg)) for arg in arguments]
    legkit, arg0, arg1 = (t.median_us for t in time_calls(calls, settings))
    print(
        f"difference_jacobians, quadruped (nv {lk_model.nv}): legkit {legkit:.1f}us, pin dDifference ARG0 + ARG1 "
        f"{arg0:.1f} + {arg1:.1f} = {arg0 + arg1:.1f}us, ratio {legkit / (arg0 + arg1):.2f}; max rel. difference {error:.0e}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="3 repeats instead of 7")
    parser.add_argument("--models", nargs="+", default=list(DEFAULT_MODELS), choices=sorted(MODELS))
    args = parser.parse_args()
    settings = Settings(repeat=3 if args.quick else 7)
    rng = np.random.default_rng(0)
    print(f"pinocchio {pin.__version__}; medians of {settings.repeat} repeats; target legkit/pin <= {TARGET_RATIO}")
    header = " | ".join(f"{name + ' legkit':>13s} {'pin':>10s} {'ratio':>6s}" for name in ("rnea_d", "aba_d", "cent_d"))
    print(f"{'model':10s} {'nv':>4s} | {header} | agreement")
    for name in args.models:
        lk_model, pin_model = MODELS[name]()
        pin_data = pin_model.createData()
        q, v, tau = random_state(lk_model, rng)
        acc = rng.normal(size=lk_model.nv)
        agreement = compare(lk_model, pin_model, pin_data, q, v, tau, acc)
        timings = time_calls(
            [
                (lk.rnea_derivatives, (lk_model, q, v, acc)),
                (pin.computeRNEADerivatives, (pin_model, pin_data, q, v, acc)),
                (lk.aba_derivatives, (lk_model, q, v, tau)),
                (pin.computeABADerivatives, (pin_model, pin_data, q, v, tau)),
                (lk.centroidal_derivatives, (lk_model, q, v, acc)),
                (pin.computeCentroidalDynamicsDerivatives, (pin_model, pin_data, q, v, acc)),
            ],
            settings,
        )
        medians = [t.median_us for t in timings]
        pairs = " | ".join(f"{ours:11.1f}us {theirs:8.1f}us {ours / theirs:6.2f}" for ours, theirs in zip(medians[::2], medians[1::2]))
        print(f"{name:10s} {lk_model.nv:4d} | {pairs} | {agreement}")
    difference_jacobians_row(settings, rng)


if __name__ == "__main__":
    main()
