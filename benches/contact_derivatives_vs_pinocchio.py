"""Side-by-side timing of legkit's and Pinocchio's frame-kinematics and contact derivatives, called from Python, on the
18-DoF floating quadruped of `models.py` with a contact point at each foot (0.22 m below each knee).

Rows (one call of each, interleaved, in one process; medians of `timeit` repeats, as benches/dynamics_vs_pinocchio.py):

    frame_acc_d  lk.frame_acceleration_derivatives(model, q, v, a, foot, point)        (local_world_aligned)
                 pin.computeForwardKinematicsDerivatives + pin.getFrameAccelerationDerivatives
    contact      lk.contact_dynamics(model, q, v, tau, feet)
                 pin.constraintDynamics                                                (4 CONTACT_3D, LOCAL_WORLD_ALIGNED)
    contact_d    lk.contact_dynamics_derivatives(model, q, v, tau, feet)               (q̈ and forces, and their derivatives)
                 pin.constraintDynamics + pin.computeConstraintDynamicsDerivatives
    impact_d     lk.impact_derivatives(model, q, v, feet)
                 pin.impulseDynamics + pin.computeImpulseDynamicsDerivatives

Pinocchio's derivatives need its forward pass first, so its two calls run in one Python function (about 0.1 µs more
than two bare calls). Pinocchio's proximal settings: mu = 0, one iteration (the exact KKT solve). Before timing, the
script prints each pair's largest difference relative to Pinocchio's largest entry (Pinocchio's "local_world_aligned"
frame derivatives hold the frame's origin still; the comparison adds back what its motion contributes, and
Pinocchio's impulse ddq_dv is that of the velocity change). Target: legkit / pin <= 0.7 on contact_d (printed, never
asserted).

Run from the repository root:  python benches/contact_derivatives_vs_pinocchio.py [--quick]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin

import legkit as lk

sys.path.insert(0, str(Path(__file__).resolve().parent))
from dynamics_vs_pinocchio import Settings, relative_error, time_calls  # noqa: E402
from models import MODELS, random_state  # noqa: E402

TARGET_RATIO = 0.7
FOOT = np.array([0.0, 0.0, -0.22])
LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="3 repeats instead of 7")
    args = parser.parse_args()
    settings = Settings(repeat=3 if args.quick else 7)
    lk_model, pin_model = MODELS["quadruped"]()
    knees = [j for j in range(1, pin_model.njoints) if pin_model.names[j].endswith("knee")]
    feet = [(j - 1, FOOT) for j in knees]  # legkit body i is Pinocchio joint i + 1 on a floating base
    contacts, datas = pin.StdVec_RigidConstraintModel(), pin.StdVec_RigidConstraintData()
    for j in knees:
        contacts.append(pin.RigidConstraintModel(pin.ContactType.CONTACT_3D, pin_model, j, pin.SE3(np.eye(3), FOOT), LWA))
    for c in contacts:
        datas.append(c.createData())
    frame = pin_model.addFrame(pin.Frame("foot", knees[0], pin.SE3(np.eye(3), FOOT), pin.FrameType.OP_FRAME))
    pin_data = pin_model.createData()
    pin.initConstraintDynamics(pin_model, pin_data, contacts, datas)
    prox = pin.ProximalSettings(1e-14, 0.0, 1)
    rng = np.random.default_rng(0)
    q, v, tau = random_state(lk_model, rng)
    acc = rng.normal(size=lk_model.nv)

    def pin_frame(q, v, a):
        pin.computeForwardKinematicsDerivatives(pin_model, pin_data, q, v, a)
        return pin.getFrameAccelerationDerivatives(pin_model, pin_data, frame, LWA)

    def pin_contact(q, v, tau):
        pin.constraintDynamics(pin_model, pin_data, q, v, tau, contacts, datas, prox)
        return pin.computeConstraintDynamicsDerivatives(pin_model, pin_data, contacts, datas, prox)

    def pin_impact(q, v):
        pin.impulseDynamics(pin_model, pin_data, q, v, contacts, datas, 0.0, prox)
        return pin.computeImpulseDynamicsDerivatives(pin_model, pin_data, contacts, datas, 0.0, prox)

    # Agreement.
    ours = lk.frame_acceleration_derivatives(lk_model, q, v, acc, feet[0][0], FOOT)
    theirs = [np.array(x) for x in pin_frame(q, v, acc)]
    jacobian = lk.jacobian(lk_model, q, feet[0][0], FOOT)
    for i, value in ((0, lk.frame_velocity(lk_model, q, v, feet[0][0], FOOT)), (1, lk.frame_acceleration(lk_model, q, v, acc, feet[0][0], FOOT))):
        theirs[i][:3] += np.cross(value[3:], jacobian[:3].T).T
    frame_error = max(relative_error(a, b) for a, b in zip(ours, theirs))
    pin_contact(q, v, tau)
    names = ("ddq_dq", "ddq_dv", "ddq_dtau", "dlambda_dq", "dlambda_dv", "dlambda_dtau")
    contact_error = max(
        relative_error(a.reshape(-1, lk_model.nv), np.array(getattr(pin_data, n)))
        for a, n in zip(lk.contact_dynamics_derivatives(lk_model, q, v, tau, feet), names)
    )
    pin_impact(q, v)
    wanted = [
        np.array(pin_data.ddq_dq),
        np.array(pin_data.ddq_dv) + np.eye(lk_model.nv),
        np.array(pin_data.dlambda_dq),
        np.array(pin_data.dlambda_dv),
    ]
    impact_error = max(relative_error(a.reshape(-1, lk_model.nv), b) for a, b in zip(lk.impact_derivatives(lk_model, q, v, feet), wanted))
    print(f"pinocchio {pin.__version__}; quadruped (nv {lk_model.nv}), 4 feet; medians of {settings.repeat} repeats")
    print(f"agreement: frame_acc_d {frame_error:.1e}  contact_d {contact_error:.1e}  impact_d {impact_error:.1e}")

    rows = [
        ("frame_acc_d", (lk.frame_acceleration_derivatives, (lk_model, q, v, acc, feet[0][0], FOOT)), (pin_frame, (q, v, acc))),
        (
            "contact",
            (lk.contact_dynamics, (lk_model, q, v, tau, feet)),
            (pin.constraintDynamics, (pin_model, pin_data, q, v, tau, contacts, datas, prox)),
        ),
        ("contact_d", (lk.contact_dynamics_derivatives, (lk_model, q, v, tau, feet)), (pin_contact, (q, v, tau))),
        ("impact_d", (lk.impact_derivatives, (lk_model, q, v, feet)), (pin_impact, (q, v))),
    ]
    timings = time_calls([call for _, ours, theirs in rows for call in (ours, theirs)], settings)
    print(f"{'':12s} {'legkit':>10s} {'pin':>10s} {'ratio':>6s}")
    for (name, _, _), ours, theirs in zip(rows, timings[0::2], timings[1::2]):
        print(f"{name:12s} {ours.median_us:8.1f}us {theirs.median_us:8.1f}us {ours.median_us / theirs.median_us:6.2f}")
    print(f"target: contact_d legkit / pin <= {TARGET_RATIO}")


if __name__ == "__main__":
    main()
