"""Benchtop calibration data: a compliant four-bar leg model, synthetic data, averaging and filtering.

The compliant four-bar leg (pseudo-rigid-body model)
----------------------------------------------------
RHex's instrumented leg is a four-bar: the hip clamp (ground link), a front and a rear compliant member, and
the shin (coupler) that carries the toe. Configuration is written in leg polar coordinates: length l (hip to
toe, metres) and deflection d (rotation of the hip-toe line about the hip axis, radians, same sign as the hip
angle). Loads are the generalised forces conjugate to (compression c = L0 - l, d): the radial force f_r (N,
positive pushing the toe toward the hip) and the hip-axis torque tau = f_t L0 (N m), f_t being the toe force
perpendicular to the leg, positive toward +d.

Three compliance modes, in series, give the radial and torsional compliance of the leg:
  * the linkage mode: the four-bar has one degree of freedom; the flexures at the roots of both members act
    as one torsional spring k_link on the linkage angle phi. Moving along the coupler curve, the toe both
    compresses and deflects: c = a_r phi, d = a_d phi (the coupler curve linearised at the unloaded leg).
    Its generalised force is the virtual work a_r f_r + a_d tau, so phi = (a_r f_r + a_d tau) / k_link;
  * axial compliance of the members: c += f_r / k_axial (stiff);
  * torsional compliance of the hip clamp: d += tau / k_clamp (stiff). This lumps everything between the
    hip encoder and the roots of the members that twists under hip torque: gearhead output shaft, clamp hub
    and bolts. The default k_clamp = 1000 N m/rad is the order of the stiffest-to-softest part of that chain,
    a 6 mm steel output shaft (G = 79 GPa) with about 1 cm free between gearhead bearing and clamp:
    G pi d^4 / (32 L) = 1.0e3 N m/rad (a machined aluminium clamp hub is stiffer by an order of magnitude).
    The clamp then takes a tenth of the leg's torsional deflection (linkage a_d^2 / k_link = 0.01 rad/(N m)
    against 1 / k_clamp = 0.001): the part of the deflection the single gauge cannot see.
The strain gauge sits near the root of the rear member in a bending bridge: it reads the member's bending
strain, which is proportional to the flexure moment k_link phi, so sigma = g phi (microstrain); the bridge
rejects axial strain and the clamp does not load the member. Hence with rigid secondary modes the
configuration is exactly linear in strain -- the generating coefficients of eq. 1 are
    n1 = (L0, -a_r / g),  n2 = (0, a_d / g)                                   (``generating_coefficients``)
-- and finite secondary stiffnesses add configuration changes the gauge cannot see (the model error of a
single-gauge leg).

The benchtop rig
----------------
The leg is clamped at a hip angle theta above a plate that stands in for the ground. An actuator loads the
toe with a normal force F_n (vertical, positive pushing up on the toe) and a tangential force F_t (along the
body's +x), swept over a grid; the rig's encoders give the true (l, d), a force plate gives (F_n, F_t), and
the strain is sampled at 300 Hz while each load is held, with Gaussian sensor noise and an n-bit ADC. Forces
are resolved along the undeflected leg (angle theta): f_r = F_n cos(theta) + F_t sin(theta),
f_t = F_n sin(theta) - F_t cos(theta).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from legkit._validation import float_array, is_integer, positive_scalar, unmasked
from legkit.robots.rhex import LEG_LENGTH


@dataclass(frozen=True)
class CompliantFourBarLeg:
    """The pseudo-rigid-body compliant four-bar leg described in the module docstring.

    Attributes (SI; strain in microstrain):
        nominal_length: L0, unloaded hip-to-toe length (m).
        linkage_compression: a_r, toe compression per radian of linkage angle (m/rad).
        linkage_deflection: a_d, leg deflection per radian of linkage angle (rad/rad).
        linkage_stiffness: k_link, flexure stiffness of the linkage mode (N m/rad).
        axial_stiffness: k_axial, radial stiffness of the members in series (N/m); inf for rigid.
        clamp_stiffness: k_clamp, torsional stiffness of the hip clamp (N m/rad); inf for rigid.
        gauge_gain: g, rear-member bending strain per radian of linkage angle (microstrain/rad).
    """

    nominal_length: float = LEG_LENGTH
    linkage_compression: float = 0.04
    linkage_deflection: float = 0.2
    linkage_stiffness: float = 4.0
    axial_stiffness: float = 3.0e4
    clamp_stiffness: float = 1000.0
    gauge_gain: float = 2000.0

    def __post_init__(self) -> None:
        for name in ("nominal_length", "linkage_compression", "linkage_stiffness", "gauge_gain"):
            positive_scalar(getattr(self, name), name)
        if not np.isfinite(self.linkage_deflection):
            raise ValueError(f"linkage_deflection must be finite, got {self.linkage_deflection}")
        for name in ("axial_stiffness", "clamp_stiffness"):
            value = getattr(self, name)
            if np.isnan(value) or value <= 0:
                raise ValueError(f"{name} must be positive (inf for a rigid mode), got {value}")

    def compliance(self) -> np.ndarray:
        """2x2 compliance matrix C: (compression m, deflection rad) = C (f_r N, tau N m)."""
        a = np.array([self.linkage_compression, self.linkage_deflection])
        secondary = np.diag([1.0 / self.axial_stiffness, 1.0 / self.clamp_stiffness])
        return np.outer(a, a) / self.linkage_stiffness + secondary

    def deform(self, radial_force: npt.ArrayLike, hip_torque: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(length m, deflection rad, strain microstrain) under generalised loads (f_r N, tau N m), broadcast."""
        f_r = float_array(radial_force, "radial_force")
        tau = float_array(hip_torque, "hip_torque")
        phi = (self.linkage_compression * f_r + self.linkage_deflection * tau) / self.linkage_stiffness
        compression = self.linkage_compression * phi + f_r / self.axial_stiffness
        deflection = self.linkage_deflection * phi + tau / self.clamp_stiffness
        return self.nominal_length - compression, deflection, self.gauge_gain * phi

    def strain_from_displacement(self, length: npt.ArrayLike, deflection: npt.ArrayLike) -> np.ndarray:
        """Gauge strain (microstrain) for an imposed toe displacement (length m, deflection rad), broadcast.

        Inverts the compliance: (f_r, tau) = C^-1 (L0 - l, d), then sigma = g (a_r f_r + a_d tau) / k_link.
        """
        compression = self.nominal_length - float_array(length, "length")
        d = float_array(deflection, "deflection")
        stiffness = np.linalg.inv(self.compliance())
        f_r = stiffness[0, 0] * compression + stiffness[0, 1] * d
        tau = stiffness[1, 0] * compression + stiffness[1, 1] * d
        phi = (self.linkage_compression * f_r + self.linkage_deflection * tau) / self.linkage_stiffness
        return self.gauge_gain * phi

    def generating_coefficients(self) -> tuple[np.ndarray, np.ndarray]:
        """(n1, n2) of the exact linear strain map when the secondary modes are rigid (lowest power first)."""
        n1 = np.array([self.nominal_length, -self.linkage_compression / self.gauge_gain])
        n2 = np.array([0.0, self.linkage_deflection / self.gauge_gain])
        return n1, n2


def leg_frame_loads(
    normal_force: npt.ArrayLike, tangential_force: npt.ArrayLike, leg_angle: npt.ArrayLike, nominal_length: float = LEG_LENGTH
) -> tuple[np.ndarray, np.ndarray]:
    """Generalised leg loads (f_r N, tau N m) from ground-frame toe forces on a leg at ``leg_angle`` (rad).

    f_r = F_n cos a + F_t sin a (toward the hip), f_t = F_n sin a - F_t cos a, tau = f_t L0.
    """
    f_n = float_array(normal_force, "normal_force")
    f_t = float_array(tangential_force, "tangential_force")
    angle = float_array(leg_angle, "leg_angle")
    c, s = np.cos(angle), np.sin(angle)
    return f_n * c + f_t * s, (f_n * s - f_t * c) * nominal_length


def quantize(signal: npt.ArrayLike, bits: int, full_scale: tuple[float, float]) -> np.ndarray:
    """An n-bit ADC: clip to full_scale = (low, high) and round to the nearest of 2**bits evenly spaced levels."""
    values = float_array(signal, "signal")
    if not is_integer(bits) or not 1 <= bits <= 32:
        raise ValueError(f"bits must be an integer between 1 and 32, got {bits!r}")
    low, high = float(full_scale[0]), float(full_scale[1])
    if not (np.isfinite(low) and np.isfinite(high) and high > low):
        raise ValueError(f"full_scale must be a finite (low, high) with high > low, got {full_scale}")
    step = (high - low) / (2**bits - 1)
    return low + np.round((np.clip(values, low, high) - low) / step) * step


@dataclass(frozen=True)
class StrainSensor:
    """Strain acquisition: Gaussian noise (microstrain, std) then an n-bit ADC over full_scale, at rate Hz."""

    noise_std: float = 20.0
    bits: int = 6
    full_scale: tuple[float, float] = (-1000.0, 3000.0)
    rate: float = 300.0

    def __post_init__(self) -> None:
        positive_scalar(self.noise_std, "noise_std", allow_zero=True)
        positive_scalar(self.rate, "rate")
        quantize(0.0, self.bits, self.full_scale)  # validates bits and full_scale

    def measure(self, strain: npt.ArrayLike, rng: np.random.Generator) -> np.ndarray:
        """Noisy, quantised readings of the true strain (any shape)."""
        true = float_array(strain, "strain")
        return quantize(true + self.noise_std * rng.standard_normal(true.shape), self.bits, self.full_scale)


@dataclass(frozen=True)
class BenchtopData:
    """Raw benchtop samples (one row per 300 Hz strain sample; truth repeated while a load is held).

    Attributes: configuration (M,) int load-point id; time (M,) s; strain (M,) microstrain (measured);
    length (M,) m; deflection (M,) rad; normal_force, tangential_force (M,) N; hip_angle (M,) rad.
    """

    configuration: np.ndarray
    time: np.ndarray
    strain: np.ndarray
    length: np.ndarray
    deflection: np.ndarray
    normal_force: np.ndarray
    tangential_force: np.ndarray
    hip_angle: np.ndarray


@dataclass(frozen=True)
class BenchtopSweep:
    """The load grid of the synthetic rig: every combination of hip angle, normal and tangential force."""

    hip_angles: np.ndarray = field(default_factory=lambda: np.linspace(-0.5, 0.5, 11))
    normal_forces: np.ndarray = field(default_factory=lambda: np.linspace(-10.0, 45.0, 12))
    tangential_forces: np.ndarray = field(default_factory=lambda: np.linspace(-25.0, 25.0, 11))
    hold_samples: int = 30


def synthetic_benchtop(
    leg: CompliantFourBarLeg | None = None,
    sweep: BenchtopSweep | None = None,
    sensor: StrainSensor | None = None,
    seed: int = 0,
) -> BenchtopData:
    """Synthetic benchtop calibration data from the compliant four-bar model (see the module docstring).

    Each (hip angle, F_n, F_t) of the sweep is held for ``sweep.hold_samples`` strain samples at
    ``sensor.rate``; loads outside the friction cone or pulling on the toe are included (filter them with
    ``physically_relevant``), as a real rig sweep would record them.
    """
    leg = leg or CompliantFourBarLeg()
    sweep = sweep or BenchtopSweep()
    sensor = sensor or StrainSensor()
    if sweep.hold_samples < 1:
        raise ValueError(f"sweep.hold_samples must be positive, got {sweep.hold_samples}")
    theta, f_n, f_t = (
        grid.ravel()
        for grid in np.meshgrid(
            float_array(sweep.hip_angles, "sweep.hip_angles"),
            float_array(sweep.normal_forces, "sweep.normal_forces"),
            float_array(sweep.tangential_forces, "sweep.tangential_forces"),
            indexing="ij",
        )
    )
    radial, torque = leg_frame_loads(f_n, f_t, theta, leg.nominal_length)
    length, deflection, strain = leg.deform(radial, torque)
    configuration = np.repeat(np.arange(theta.size), sweep.hold_samples)
    rng = np.random.default_rng(seed)
    return BenchtopData(
        configuration=configuration,
        time=np.arange(configuration.size) / sensor.rate,
        strain=sensor.measure(strain[configuration], rng),
        length=length[configuration],
        deflection=deflection[configuration],
        normal_force=f_n[configuration],
        tangential_force=f_t[configuration],
        hip_angle=theta[configuration],
    )


def physically_relevant(normal_force: npt.ArrayLike, tangential_force: npt.ArrayLike, mu: float = 0.5) -> np.ndarray:
    """Boolean mask of loads the ground can apply: F_n > 0 and |F_t| < mu F_n (Coulomb friction, mu >= 0)."""
    f_n = float_array(normal_force, "normal_force")
    f_t = float_array(tangential_force, "tangential_force")
    if f_n.shape != f_t.shape:
        raise ValueError(f"normal_force and tangential_force must have the same shape, got {f_n.shape} and {f_t.shape}")
    positive_scalar(mu, "mu", allow_zero=True)
    return (f_n > 0) & (np.abs(f_t) < mu * f_n)


def average_by_group(groups: npt.ArrayLike, *values: npt.ArrayLike) -> tuple[np.ndarray, list[np.ndarray]]:
    """Mean of each value array over the samples sharing a group id (e.g. a held benchtop load).

    Returns (sorted unique ids, [mean per id for each value array]).
    """
    unmasked(groups, "groups")
    ids = np.asarray(groups)
    if ids.ndim != 1 or not np.issubdtype(ids.dtype, np.integer):
        raise ValueError(f"groups must be a 1-D integer array, got shape {ids.shape} and dtype {ids.dtype}")
    unique, inverse = np.unique(ids, return_inverse=True)
    counts = np.bincount(inverse)
    means = []
    for k, value in enumerate(values):
        array = float_array(value, f"values[{k}]")
        if array.shape != ids.shape:
            raise ValueError(f"values[{k}] must have the shape of groups {ids.shape}, got {array.shape}")
        means.append(np.bincount(inverse, weights=array) / counts)
    return unique, means


def configuration_cells(length: npt.ArrayLike, deflection: npt.ArrayLike, bins: tuple[int, int]) -> np.ndarray:
    """Cell id of each sample on a regular bins[0] x bins[1] grid over the (length, deflection) bounding box."""
    ell = float_array(length, "length")
    d = float_array(deflection, "deflection")
    if ell.shape != d.shape or ell.ndim != 1:
        raise ValueError(f"length and deflection must be 1-D of equal length, got {ell.shape} and {d.shape}")
    n_l, n_d = int(bins[0]), int(bins[1])
    if n_l < 1 or n_d < 1:
        raise ValueError(f"bins must be positive, got {bins}")

    def cell(values: np.ndarray, n: int) -> np.ndarray:
        span = np.ptp(values)
        if span == 0.0:
            return np.zeros(values.shape, dtype=np.int64)
        return np.minimum(((values - values.min()) / span * n).astype(np.int64), n - 1)

    return cell(ell, n_l) * n_d + cell(d, n_d)


def grid_average(
    length: npt.ArrayLike, deflection: npt.ArrayLike, *values: npt.ArrayLike, bins: tuple[int, int] = (20, 20)
) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """Average samples within each occupied cell of a regular grid over configuration space.

    Every occupied cell contributes one point, so densely sampled regions do not dominate the fit.
    Returns (mean length per cell, mean deflection per cell, [mean of each value array per cell]).
    """
    cells = configuration_cells(length, deflection, bins)
    _, means = average_by_group(cells, length, deflection, *values)
    return means[0], means[1], means[2:]


def resample_evenly(
    length: npt.ArrayLike, deflection: npt.ArrayLike, bins: tuple[int, int] = (20, 20), per_cell: int = 1, seed: int = 0
) -> np.ndarray:
    """Indices of at most ``per_cell`` samples drawn at random from each occupied configuration-space cell.

    The result is sorted; cells with fewer samples contribute all of them.
    """
    if not is_integer(per_cell) or per_cell < 1:
        raise ValueError(f"per_cell must be a positive integer, got {per_cell!r}")
    cells = configuration_cells(length, deflection, bins)
    shuffled = np.random.default_rng(seed).permutation(cells.size)
    order = shuffled[np.argsort(cells[shuffled], kind="stable")]
    sorted_cells = cells[order]
    first = np.searchsorted(sorted_cells, sorted_cells, side="left")
    rank = np.arange(order.size) - first
    return np.sort(order[rank < per_cell])
