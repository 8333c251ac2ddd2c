"""legkit's example robots as ``lk.Model`` builders: SuperBot modules and trees of them (Moll et al., IROS 2006),
a quadruped and a biped like those of Hardt & von Stryk (RoboCup 2002), RHex (Lin et al., ICRA 2003), and the
motors that drive their joints. See docs/robots.md."""

from legkit.robots import biped, legs, motors, quadruped, rhex, superbot
from legkit.robots.biped import Biped, BipedParameters, build_biped
from legkit.robots.legs import model_to_urdf
from legkit.robots.motors import BIPED_MOTOR, QUADRUPED_MOTOR, MotorParameters
from legkit.robots.quadruped import Quadruped, QuadrupedParameters, build_quadruped
from legkit.robots.rhex import rhex_compliant_model, rhex_model
from legkit.robots.superbot import Connection, ModuleParameters, ModuleTree, random_tree

__all__ = [
    "biped", "legs", "motors", "quadruped", "rhex", "superbot",
    "Biped", "BipedParameters", "build_biped", "Quadruped", "QuadrupedParameters", "build_quadruped",
    "rhex_model", "rhex_compliant_model", "Connection", "ModuleParameters", "ModuleTree", "random_tree",
    "MotorParameters", "QUADRUPED_MOTOR", "BIPED_MOTOR", "model_to_urdf",
]
