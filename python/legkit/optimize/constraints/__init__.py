"""The constraint families of a multiphase transcription, one module each, every one a list of `blocks.Block`s built
from a `legkit.optimize.contact.ContactModel`: `dynamics` (collocation defects, linear controls, inverse dynamics),
`stance` (feet on the ground, friction cone, foot torques), `swing` (clearance between the points), `impact`
(velocity across a boundary), `links` (periodic and mirror links, period, quaternion gauge), `limits` (torque-speed
line, input power, yaw) and `rates` (joint rates between the points, force and torque rates)."""
