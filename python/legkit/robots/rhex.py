"""RHex: body and leg geometry constants, and a legkit Model (free-flyer base, six one-DoF hips).

Body frame: origin at the body's geometric centre (taken as its centre of mass), x forward, y left, z up.
Every hip axis is parallel to the body y axis; the hip angle theta is a rotation about +y measured from
the leg pointing straight down, so a positive theta swings the toe backwards (toward -x). A clock-driven
RHex walking forward turns every leg in the +theta direction.

Numbers follow the published RHex figures (Saranli, Buehler, Koditschek 2001; Lin, Komsuoglu, Koditschek
2003): body about 0.5 m x 0.2 m, total mass about 7 kg, hip-to-toe leg length about 0.17 m.

Leg order (used everywhere in ``legkit.strain``): 0 left front, 1 left middle, 2 left rear, 3 right front,
4 right middle, 5 right rear. ``TRIPODS`` lists the two alternating tripods, each ordered as
(same-side rear, same-side front, opposite middle): the first two toes then span a line roughly along the
body x axis, which is what the support frame of ``legkit.strain.pose.tripod_pose`` takes as its x axis.
"""

from __future__ import annotations

import numpy as np

import legkit as lk
from legkit._validation import float_array

BODY_LENGTH = 0.50  # m, along x
BODY_WIDTH = 0.20  # m, along y
BODY_THICKNESS = 0.05  # m, along z
TOTAL_MASS = 7.0  # kg, body plus six legs
LEG_MASS = 0.08  # kg, one compliant leg
BODY_MASS = TOTAL_MASS - 6 * LEG_MASS  # kg
LEG_LENGTH = 0.17  # m, unloaded hip-to-toe distance
HIP_SPACING = 0.20  # m, front-to-middle and middle-to-rear hip distance along x
HIP_LATERAL = 0.125  # m, hip axis offset from the body mid-plane (the legs sit outside the 0.2 m body)

LEG_NAMES = ("left_front", "left_middle", "left_rear", "right_front", "right_middle", "right_rear")

#: Hip positions in the body frame, (6, 3) metres, in LEG_NAMES order.
HIP_POSITIONS = np.array(
    [
        [HIP_SPACING, HIP_LATERAL, 0.0],
        [0.0, HIP_LATERAL, 0.0],
        [-HIP_SPACING, HIP_LATERAL, 0.0],
        [HIP_SPACING, -HIP_LATERAL, 0.0],
        [0.0, -HIP_LATERAL, 0.0],
        [-HIP_SPACING, -HIP_LATERAL, 0.0],
    ]
)
HIP_POSITIONS.setflags(write=False)

#: The alternating tripods as leg indices, each ordered (same-side rear, same-side front, opposite middle).
TRIPODS = ((2, 0, 4), (5, 3, 1))

#: Axis of every hip joint in the body frame.
HIP_AXIS = np.array([0.0, 1.0, 0.0])
HIP_AXIS.setflags(write=False)


def leg_mass_properties() -> lk.MassProperties:
    """One leg as a thin slab from the hip (origin) down to the unloaded toe, in the leg's own frame."""
    return lk.MassProperties.solid_box(LEG_MASS, [0.02, 0.03, LEG_LENGTH], center=[0.0, 0.0, -LEG_LENGTH / 2])


def rhex_model() -> lk.Model:
    """RHex as a legkit Model: a free-flyer body (box, ``BODY_MASS``) and six revolute hips about +y.

    Bodies are numbered base first, then the legs in ``LEG_NAMES`` order (body i + 1 is leg i); joint
    zero (q = neutral) is every leg pointing straight down. The leg compliance is not part of the rigid
    model: it lives in ``legkit.strain.benchtop.CompliantFourBarLeg``.
    """
    body = lk.MassProperties.solid_box(BODY_MASS, [BODY_LENGTH, BODY_WIDTH, BODY_THICKNESS])
    model = lk.Model(floating_base=True, base=body, base_name="body")
    for name, hip in zip(LEG_NAMES, HIP_POSITIONS):
        model.add_revolute(0, HIP_AXIS, placement=(np.eye(3), hip), body=leg_mass_properties(), name=name)
    return model


#: Mass split of one compliant leg (``rhex_compliant_model``), kg: hip clamp; the two compliant members (thin
#: composite strips); the shin (the four-bar's rigid coupler) with the toe and its rubber tread. The shin and
#: toe are most of a four-bar leg's mass, and they are what rides on the compression spring.
COMPLIANT_LEG_MASSES = (0.02, 0.02, 0.04)
#: Fraction of the leg length, from the toe up, taken by the shin; the members span the rest up to the hip.
SHIN_FRACTION = 1.0 / 3.0
#: Reflected rotor inertia of a hip gearmotor about the hip axis (kg m^2), carried by the hip clamp body.
HIP_ROTOR_INERTIA = 1.0e-3


def rhex_compliant_model(spring_axis: object) -> lk.Model:
    """RHex with compliant legs: each leg is a hip, a deflection joint and a compression slider (18 joints).

    Leg i adds three bodies (bodies 3i+1, 3i+2, 3i+3, named ``<leg>_hip``, ``<leg>_flex``, ``<leg>_toe``):
      * hip: revolute about +y at the hip (the motor, angle theta); a 0.02 kg clamp carrying the reflected
        gearmotor rotor inertia ``HIP_ROTOR_INERTIA`` about y (a disk), so a hip servo acts on a real inertia;
      * flex: revolute about +y at the same point (the leg deflection beyond the clamp, rad); the compliant
        members, a 0.02 kg slab from the hip down to the shin (the upper 1 - ``SHIN_FRACTION`` of the leg);
      * toe: prismatic along ``spring_axis`` (a unit vector in the flex frame, 3-vector with zero y; coordinate
        in metres): the shin and toe, a 0.04 kg slab over the lowest ``SHIN_FRACTION`` of the leg, ending at
        the toe (0, 0, -LEG_LENGTH). (``COMPLIANT_LEG_MASSES``; the whole shin moves with the compression.)
    With zero joint coordinates the leg is the rigid leg of ``rhex_model``. The flex and toe joints are meant
    to be held by stiff position servos acting as the leg springs (see ``legkit.strain.simulated``, which
    chooses the axis and stiffnesses that match the compliant four-bar leg of ``legkit.strain.benchtop``).

    Raises:
        TypeError: spring_axis is not numeric.
        ValueError: spring_axis is not a finite unit 3-vector in the xz plane.
    """
    axis = float_array(spring_axis, "spring_axis")
    if axis.shape != (3,) or abs(np.linalg.norm(axis) - 1.0) > 1e-9 or axis[1] != 0.0:
        raise ValueError(f"spring_axis must be a finite unit 3-vector with zero y component, got {spring_axis!r}")
    clamp_mass, member_mass, shin_mass = COMPLIANT_LEG_MASSES
    rotor = 0.5 * HIP_ROTOR_INERTIA
    clamp = lk.MassProperties(clamp_mass, np.zeros(3), np.diag([rotor, HIP_ROTOR_INERTIA, rotor]))
    shin = SHIN_FRACTION * LEG_LENGTH
    members = lk.MassProperties.solid_box(
        member_mass, [0.02, 0.03, LEG_LENGTH - shin], center=[0.0, 0.0, -(LEG_LENGTH - shin) / 2]
    )
    toe = lk.MassProperties.solid_box(shin_mass, [0.02, 0.03, shin], center=[0.0, 0.0, -LEG_LENGTH + shin / 2])
    body = lk.MassProperties.solid_box(BODY_MASS, [BODY_LENGTH, BODY_WIDTH, BODY_THICKNESS])
    model = lk.Model(floating_base=True, base=body, base_name="body")
    for name, hip in zip(LEG_NAMES, HIP_POSITIONS):
        hip_body = model.add_revolute(0, HIP_AXIS, placement=(np.eye(3), hip), body=clamp, name=f"{name}_hip")
        flex = model.add_revolute(hip_body, HIP_AXIS, placement=None, body=members, name=f"{name}_flex")
        model.add_prismatic(flex, axis, placement=None, body=toe, name=f"{name}_toe")
    return model
