//! `legkit._core.BalanceKernel`: the synchronous agent network and balancing controller of
//! `legkit_dynamics::agents`, built and driven by `legkit.control.balance.BalanceKernel`.

use legkit_dynamics::agents::{Controller, GroundContact, ModuleSpec, Network, Schedule, Scheme, SLOTS};
use nalgebra::{Matrix3, Vector3};
use numpy::ndarray::ArrayViewD;
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;

use crate::convert::{kernel_error, to_numpy, FloatArray, Floats, Integer};
use crate::interrupt::{in_pieces, Pace, SignalCheck};

#[pyclass(name = "BalanceKernel", module = "legkit")]
pub struct PyBalanceKernel {
    network: Network,
    controller: Controller,
    torques: Vec<[f64; 3]>,
    pace: Pace,
}

/// `value` as a flat row-major vector of `shape`; ValueError naming `argument` otherwise.
fn flat(argument: &str, value: &Floats<'_>, shape: &[usize]) -> PyResult<Vec<f64>> {
    let view: ArrayViewD<'_, f64> = value.get(argument)?;
    if view.shape() != shape {
        return Err(PyValueError::new_err(format!("{argument}: expected shape {shape:?}, got {:?}", view.shape())));
    }
    Ok(view.iter().copied().collect())
}

fn matrix(entries: &[f64]) -> Matrix3<f64> {
    Matrix3::from_row_slice(&entries[..9])
}

fn index(argument: &str, value: i64, bound: usize) -> PyResult<usize> {
    usize::try_from(value).ok().filter(|&v| v < bound).ok_or_else(|| PyValueError::new_err(format!("{argument}: {value} is out of 0..{bound}")))
}

fn angle_rows(angles: &[f64]) -> Vec<[f64; 3]> {
    angles.chunks_exact(3).map(|a| [a[0], a[1], a[2]]).collect()
}

#[pymethods]
#[pyo3(crate = "crate::arguments")]
impl PyBalanceKernel {
    /// Internal: see `legkit.control.balance.BalanceKernel`, which builds it from an `AgentNetwork` and a
    /// `BalanceController`. Links are numbered 6 module + slot.
    #[new]
    #[allow(clippy::too_many_arguments)]
    fn new(
        partner_link: Vec<i64>, mate: Floats<'_>, part_moments: Floats<'_>, connector_rotation: Floats<'_>, connector_position: Floats<'_>,
        joint_axes: [usize; 3], joint_z: [f64; 3], ground_module: Vec<i64>, ground_block: Vec<i64>, ground_pose: Floats<'_>, ground_line: Floats<'_>,
        ground_priority: Vec<f64>, angles: Floats<'_>, scheme: Vec<i64>, gains: Floats<'_>, limit: f64, width: f64,
    ) -> PyResult<Self> {
        let links = partner_link.len();
        let n = links / SLOTS;
        let partner =
            partner_link.iter().map(|&p| if p < 0 { Ok(None) } else { index("partner_link", p, links).map(Some) }).collect::<PyResult<_>>()?;
        let mate = flat("mate", &mate, &[links, 3, 3])?.chunks_exact(9).map(matrix).collect();
        let parts = flat("part_moments", &part_moments, &[4, 13])?;
        let rotations = flat("connector_rotation", &connector_rotation, &[SLOTS, 3, 3])?;
        let positions = flat("connector_position", &connector_position, &[SLOTS, 3])?;
        if joint_axes.iter().any(|&a| a > 2) {
            return Err(PyValueError::new_err("joint_axes: each must be 0, 1 or 2"));
        }
        let spec = ModuleSpec {
            part_moments: std::array::from_fn(|k| parts[13 * k..13 * k + 13].try_into().expect("13 entries")),
            connector_rotation: std::array::from_fn(|s| matrix(&rotations[9 * s..])),
            connector_position: std::array::from_fn(|s| Vector3::from_column_slice(&positions[3 * s..3 * s + 3])),
            joint_axes,
            joint_z,
        };
        let k = ground_module.len();
        if ground_block.len() != k || ground_priority.len() != k {
            return Err(PyValueError::new_err("ground_block, ground_priority: need one per ground contact"));
        }
        let pose = flat("ground_pose", &ground_pose, &[k, 3, 4])?;
        let line = flat("ground_line", &ground_line, &[k, 6])?;
        let ground = (0..k)
            .map(|c| {
                let p = &pose[12 * c..12 * c + 12];
                let l = &line[6 * c..6 * c + 6];
                Ok(GroundContact {
                    module: index("ground_module", ground_module[c], n)?,
                    block: index("ground_block", ground_block[c], 2)?,
                    rotation: Matrix3::new(p[0], p[1], p[2], p[4], p[5], p[6], p[8], p[9], p[10]),
                    translation: Vector3::new(p[3], p[7], p[11]),
                    line_point: Vector3::new(l[0], l[1], l[2]),
                    line_direction: Vector3::new(l[3], l[4], l[5]),
                    priority: ground_priority[c],
                })
            })
            .collect::<PyResult<_>>()?;
        let angles = angle_rows(&flat("angles", &angles, &[n, 3])?);
        let network = Network::new(spec, partner, mate, ground, &angles).map_err(kernel_error)?;
        if scheme.len() != n {
            return Err(PyValueError::new_err(format!("scheme: need one per module ({n})")));
        }
        let gains = flat("gains", &gains, &[n, 5])?;
        let schedules = (0..n)
            .map(|m| {
                let g = &gains[5 * m..5 * m + 5];
                let scheme = match scheme[m] {
                    0 => Scheme::Constant,
                    1 => Scheme::Distance,
                    2 => Scheme::Momentum,
                    other => return Err(PyValueError::new_err(format!("scheme[{m}]: {other} is not 0, 1 or 2"))),
                };
                Ok(Schedule { scheme, c0: g[0], c1: g[1], kp0: g[2], ki0: g[3], kd0: g[4] })
            })
            .collect::<PyResult<_>>()?;
        Ok(PyBalanceKernel { network, controller: Controller::new(schedules, limit, width), torques: vec![[0.0; 3]; n], pace: Pace::default() })
    }

    /// Runs rounds until nothing is pending or on the wire; returns the rounds run. Ctrl-C stops it between
    /// rounds (KeyboardInterrupt).
    fn run_until_quiescent(&mut self, py: Python<'_>, max_rounds: Integer) -> PyResult<u64> {
        let max_rounds = max_rounds.within("max_rounds", 0, i64::MAX as u64)?;
        let mut signals = SignalCheck::default();
        for rounds in 0..=max_rounds {
            if self.network.quiescent() {
                return Ok(rounds);
            }
            signals.poll(py)?;
            self.network.round();
        }
        Err(PyRuntimeError::new_err(format!("max_rounds: the network did not fall silent within {max_rounds} rounds")))
    }

    /// One control step: the agents read `angles` (N, 3), run `rounds` rounds, and every joint computes its
    /// torque after `dt` s; returns the torques (N, 3) N m. Bad angles leave the state unchanged; Ctrl-C
    /// stops a long run of rounds between rounds (KeyboardInterrupt, no torques).
    fn step<'py>(&mut self, py: Python<'py>, angles: Floats<'_>, dt: f64, rounds: Integer) -> PyResult<FloatArray<'py>> {
        let rounds = rounds.within("rounds", 0, i64::MAX as u64 - 1)?;
        let n = self.network.n_modules();
        let angles = angle_rows(&flat("angles", &angles, &[n, 3])?);
        if !(dt.is_finite() && dt > 0.0) {
            return Err(PyValueError::new_err(format!("dt: must be > 0, got {dt}")));
        }
        let PyBalanceKernel { network, controller, torques, pace } = self;
        // Unit 0 is the observation, units 1..=rounds the rounds; the last piece ends with the torques.
        let mut done = 0;
        in_pieces(py, rounds + 1, pace, |k| {
            for unit in done..done + k {
                if unit == 0 {
                    network.observe(&angles).map_err(kernel_error)?;
                } else {
                    network.round();
                }
            }
            done += k;
            if done == rounds + 1 {
                controller.torques(network, dt, torques).map_err(kernel_error)?;
            }
            Ok(())
        })?;
        Ok(to_numpy(py, vec![n, 3], torques.iter().flatten().copied().collect()))
    }

    /// Data messages sent by each module so far (all channels), (N,).
    #[getter]
    fn sent_by_module<'py>(&self, py: Python<'py>) -> Bound<'py, numpy::PyArray1<i64>> {
        to_numpy(py, self.network.n_modules(), self.network.sent_by_module().map(|s| s as i64).collect())
    }

    /// Each agent's module-frame estimates of what lies beyond its connectors, (N, 6, 13).
    fn estimates<'py>(&self, py: Python<'py>) -> FloatArray<'py> {
        let n = self.network.n_modules();
        let data = (0..n).flat_map(|m| (0..SLOTS).flat_map(move |s| *self.network.estimate(m, s))).collect();
        to_numpy(py, vec![n, SLOTS, 13], data)
    }

    /// Each agent's belief of its module frame's world pose: rotations (N, 3, 3), translations (N, 3).
    fn world_poses<'py>(&self, py: Python<'py>) -> (FloatArray<'py>, FloatArray<'py>) {
        let n = self.network.n_modules();
        let poses: Vec<_> = (0..n).map(|m| self.network.world_pose(m)).collect();
        let rotations = poses.iter().flat_map(|(r, _)| r.transpose().as_slice().to_vec()).collect();
        let translations = poses.iter().flat_map(|(_, t)| t.as_slice().to_vec()).collect();
        (to_numpy(py, vec![n, 3, 3], rotations), to_numpy(py, vec![n, 3], translations))
    }
}
