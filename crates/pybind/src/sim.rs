//! `legkit.Simulation` and `legkit.Ground`: conversions around `legkit_dynamics::sim`.

use legkit_dynamics::model::check_vector;
use legkit_dynamics::sim::{
    dof_coordinates, Backend, FrictionLaw, Ground, Options, Rollout, Servo, Simulation, DEFAULT_SOLVER_ITERATIONS, MAX_SOLVER_ITERATIONS,
    MAX_SUBSTEPS,
};
use legkit_dynamics::validate::{array_len, cancellable, with_capacity};
use legkit_dynamics::Transform;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Instant;

use nalgebra::{DMatrix, Vector3};
use numpy::{PyArray1, PyArray2, PyArray3};
use pyo3::exceptions::{PyRuntimeError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::{PyDict, PyList, PyTuple};

use crate::convert::{batch_error, batch_error_noting, homogeneous, kernel_error, to_numpy, transform, Floats, Integer};
use crate::interrupt::{in_pieces, interruptible, Pace};
use crate::model::PyModel;
use crate::shapes::shape_overrides;
use legkit_dynamics::algorithms::finite_result;
use legkit_dynamics::parallel::on_all_threads;

/// Terrain for a `Simulation`: `Ground.plane(friction)` (the plane z = 0) or
/// `Ground.heightfield(heights, cell_size, friction)`.
/// One step's Jacobians (A, B) from the simulation's state; a RuntimeError where they overflow (a state of
/// huge velocities), not NaN returned without a word.
fn finite_jacobians(sim: &mut Simulation, tau: Option<&[f64]>) -> legkit_dynamics::Result<(DMatrix<f64>, DMatrix<f64>)> {
    let (mut a, mut b) = (DMatrix::zeros(0, 0), DMatrix::zeros(0, 0));
    sim.transition_jacobians(tau, &mut a, &mut b)?;
    finite_result(a.as_slice())?;
    finite_result(b.as_slice())?;
    Ok((a, b))
}

/// A rollout's controls: the rows of `view` (..., N, nv) as one row-major vector, copied with fallible allocation.
fn control_rows(view: &numpy::ndarray::ArrayViewD<'_, f64>, nv: usize) -> PyResult<Vec<f64>> {
    let mut rows = with_capacity("controls", view.len()).map_err(kernel_error)?;
    rows.extend(view.iter().copied());
    if view.shape().last() != Some(&nv) {
        return Err(PyValueError::new_err(format!("controls: expected rows of {nv} values (shape (N, {nv})), got shape {:?}", view.shape())));
    }
    Ok(rows)
}

/// One rollout's outcome with its Jacobians checked finite (a RuntimeError where they overflow, as `finite_jacobians`).
fn finite_rollout(sim: &mut Simulation, controls: &[f64], jacobians: bool) -> legkit_dynamics::Result<Rollout> {
    let mut out = Rollout::default();
    sim.rollout(controls, jacobians, &mut out)?;
    finite_result(&out.a)?;
    finite_result(&out.b)?;
    Ok(out)
}

/// The arrays of `outs` (one per simulation, each of `n` steps), stacked with `batch` leading (None: one simulation):
/// (q, v), and with `jacobians` (q, v, A, B).
fn rollout_arrays<'py>(
    py: Python<'py>, batch: Option<usize>, n: usize, (nq, nv): (usize, usize), outs: Vec<Rollout>, jacobians: bool,
) -> PyResult<Bound<'py, PyTuple>> {
    let lead: Vec<usize> = batch.into_iter().chain([n]).collect();
    let shaped = |tail: &[usize], take: &dyn Fn(&Rollout) -> &[f64]| {
        let shape: Vec<usize> = lead.iter().chain(tail).copied().collect();
        let mut all = with_capacity("controls", shape.iter().product()).map_err(kernel_error)?;
        outs.iter().for_each(|o| all.extend_from_slice(take(o)));
        Ok::<_, PyErr>(to_numpy(py, shape, all).into_any())
    };
    let mut arrays = vec![shaped(&[nq], &|o| &o.q)?, shaped(&[nv], &|o| &o.v)?];
    if jacobians {
        arrays.push(shaped(&[2 * nv, 2 * nv], &|o| &o.a)?);
        arrays.push(shaped(&[2 * nv, 3 * nv], &|o| &o.b)?);
    }
    PyTuple::new(py, arrays)
}

#[pyclass(name = "Ground", module = "legkit", frozen)]
pub struct PyGround {
    pub ground: Ground,
}

#[pymethods]
#[pyo3(crate = "crate::arguments")]
impl PyGround {
    /// The plane z = 0, solid below, with Coulomb friction coefficient `friction` (>= 0); with `placement`
    /// (a 4x4 transform or an (R, t) pair, plane to world) the plane z = 0 of that frame, its normal the
    /// frame's z axis, as MuJoCo places a plane geom.
    #[staticmethod]
    #[pyo3(signature = (friction = 0.8, placement = None))]
    fn plane(friction: f64, placement: Option<&Bound<'_, PyAny>>) -> PyResult<Self> {
        let placement = placement.map(transform).transpose()?.unwrap_or_default();
        Ok(PyGround { ground: Ground::placed_plane(friction, placement).map_err(kernel_error)? })
    }

    /// Terrain heights (m) on a regular grid: `heights[i, j]` is the height at
    /// x = (i − (nx − 1)/2) cell_size, y = (j − (ny − 1)/2) cell_size (the grid is centred on the origin;
    /// each cell is two planar triangles; no ground outside the grid). `heights` is (nx, ny) with
    /// nx, ny >= 2, `cell_size` > 0 (m), `friction` >= 0.
    #[staticmethod]
    #[pyo3(signature = (heights, cell_size, friction = 0.8))]
    fn heightfield(heights: Floats<'_>, cell_size: f64, friction: f64) -> PyResult<Self> {
        let view = heights.get("heights")?;
        if view.ndim() != 2 {
            return Err(PyValueError::new_err(format!("heights: expected a 2-D array (nx, ny), got shape {:?}", view.shape())));
        }
        let (nx, ny) = (view.shape()[0], view.shape()[1]);
        // A broadcast view may stand for far more numbers than it holds: allocate the copy fallibly.
        let mut heights = with_capacity("heights", nx.saturating_mul(ny)).map_err(kernel_error)?;
        heights.extend(view.t().iter().copied());
        let matrix = DMatrix::from_vec(nx, ny, heights);
        Ok(PyGround { ground: Ground::heightfield(matrix, cell_size, friction).map_err(kernel_error)? })
    }

    /// "plane" or "heightfield".
    #[getter]
    fn kind(&self) -> &'static str {
        match self.ground {
            Ground::Plane { .. } => "plane",
            Ground::Heightfield { .. } => "heightfield",
        }
    }

    #[getter]
    fn friction(&self) -> f64 {
        self.ground.friction()
    }

    /// The height samples (nx, ny) of a heightfield, None for a plane.
    #[getter]
    fn heights<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray2<f64>>> {
        match &self.ground {
            Ground::Heightfield { heights, .. } => Some(to_numpy(py, heights.shape(), heights.transpose().as_slice().to_vec())),
            Ground::Plane { .. } => None,
        }
    }

    /// The plane's frame in the world, a 4x4 transform (the identity: z = 0); None for a heightfield.
    #[getter]
    fn placement<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray2<f64>>> {
        match &self.ground {
            Ground::Plane { placement, .. } => Some(to_numpy(py, (4, 4), homogeneous(placement).to_vec())),
            Ground::Heightfield { .. } => None,
        }
    }

    /// Grid spacing (m) of a heightfield, None for a plane.
    #[getter]
    fn cell_size(&self) -> Option<f64> {
        match &self.ground {
            Ground::Heightfield { cell_size, .. } => Some(*cell_size),
            Ground::Plane { .. } => None,
        }
    }

    fn __repr__(&self) -> String {
        match &self.ground {
            Ground::Plane { friction, placement } if *placement == Transform::identity() => format!("Ground.plane(friction={friction})"),
            Ground::Plane { friction, placement } => {
                format!(
                    "Ground.plane(friction={friction}, placement=<origin {:?}, normal {:?}>)",
                    placement.translation.as_slice(),
                    placement.rotation.column(2).as_slice()
                )
            }
            Ground::Heightfield { heights, cell_size, friction } => {
                format!("Ground.heightfield(<{}x{} heights>, cell_size={cell_size}, friction={friction})", heights.nrows(), heights.ncols())
            }
        }
    }
}

/// A contact simulation of a `Model`.
///
/// `Simulation(model, dt=1e-3, ground=None, shapes=None, self_collision=False, substeps=1, backend="tree",
/// solver_iterations=50, friction_law="coulomb")`: `ground` a `Ground` or None;
/// `shapes` maps bodies (index or name) to ("box", (sx, sy, sz)) full edge lengths, ("sphere", r),
/// ("capsule", half_height, r), ("cylinder", half_height, r) along z or ("convex", points (n, 3)) (their
/// convex hull), each optionally followed by a 4x4 placement in the body frame (default: at the body's
/// COM, body axes), or to None for no collider; unlisted bodies get the model's URDF collision shapes,
/// else the uniform box with their mass and principal moments (massless bodies none).
/// The model's `damping` (N m s/rad) acts on each joint, and its `armature` (kg m², a geared motor's
/// reflected rotor inertia) adds to each joint's inertia. `backend` is "tree" (legkit's reduced-coordinate engine:
/// O(n) dynamics, parry contacts, a warm-started Newton contact solver with at most `solver_iterations`
/// iterations, servos and damping integrated implicitly) or "rapier" (Rapier's multibody,
/// the reference). `friction_law` (tree engine) is "coulomb" (Coulomb's law) or "cone" (its convex relaxation
/// |f_t| <= mu f_n). Both integrate semi-implicitly to first order in dt / `substeps`. `substeps` and
/// `solver_iterations` are at most 1000 (a step is the unit Ctrl-C interrupts at, so it stays short); shape
/// sizes and offsets at most 1e6 m.
/// The robot starts at `model.neutral()`, at rest, at time 0.
#[pyclass(name = "Simulation", module = "legkit")]
pub struct PySimulation {
    sim: Simulation,
    /// `model`: the model simulated, made on first use (a frozen copy: the Model the simulation was built from may
    /// change afterwards, and the simulation does not follow).
    model: PyOnceLock<Py<PyModel>>,
    pace: Pace,
    /// `transition_jacobians`' pace, per substep.
    jacobian_pace: Pace,
}

/// A per-degree-of-freedom parameter: a scalar (applied to the joint coordinates, `base` on a floating
/// base's six) or an (nv,) array.
fn per_dof(argument: &'static str, value: &Floats<'_>, nv: usize, floating: bool, base: f64) -> PyResult<Vec<f64>> {
    let view = value.get(argument)?;
    match view.ndim() {
        0 => {
            let x = view[[]];
            Ok((0..nv).map(|k| if floating && k < 6 { base } else { x }).collect())
        }
        1 if view.len() == nv => Ok(view.iter().copied().collect()),
        _ => Err(PyValueError::new_err(format!("{argument}: expected a scalar or shape ({nv},), got {:?}", view.shape()))),
    }
}

fn vector_argument(argument: &'static str, value: &Floats<'_>, n: usize) -> PyResult<Vec<f64>> {
    let view = value.get(argument)?;
    if view.ndim() != 1 || view.len() != n {
        return Err(PyValueError::new_err(format!("{argument}: expected shape ({n},), got {:?}", view.shape())));
    }
    Ok(view.iter().copied().collect())
}

// `Simulation`'s text signature shows the default solver iterations as a number.
const _: () = assert!(DEFAULT_SOLVER_ITERATIONS == 50);

#[pymethods]
#[pyo3(crate = "crate::arguments")]
impl PySimulation {
    #[new]
    #[pyo3(signature = (model, dt = 1e-3, ground = None, shapes = None, self_collision = false, substeps = Integer::new(1), backend = "tree", solver_iterations = Integer::new(DEFAULT_SOLVER_ITERATIONS as i128), friction_law = "coulomb"),
        text_signature = "(model, dt=0.001, ground=None, shapes=None, self_collision=False, substeps=1, backend='tree', solver_iterations=50, friction_law='coulomb')")]
    #[allow(clippy::too_many_arguments)]
    fn new(
        model: PyRef<'_, PyModel>, dt: f64, ground: Option<PyRef<'_, PyGround>>, shapes: Option<Bound<'_, PyDict>>, self_collision: bool,
        substeps: Integer, backend: &str, solver_iterations: Integer, friction_law: &str,
    ) -> PyResult<Self> {
        let mut options = Options::new(dt);
        options.ground = ground.map(|g| g.ground.clone());
        options.self_collision = self_collision;
        options.substeps = substeps.within("substeps", 1, MAX_SUBSTEPS as u64)? as usize;
        options.solver_iterations = solver_iterations.within("solver_iterations", 1, MAX_SOLVER_ITERATIONS as u64)? as usize;
        options.backend = Backend::parse(backend).map_err(kernel_error)?;
        options.friction_law = FrictionLaw::parse(friction_law).map_err(kernel_error)?;
        options.shapes = shape_overrides(shapes.as_ref(), |key| model.body_index("body", key))?;
        let sim = Simulation::new(&model.model, options).map_err(kernel_error)?;
        Ok(PySimulation { sim, model: PyOnceLock::new(), pace: Pace::default(), jacobian_pace: Pace::default() })
    }

    /// The Model simulated: a copy of the one it was built from, as it was then, that cannot change (changing
    /// that Model afterwards changes neither the simulation nor this).
    #[getter]
    fn model(slf: &Bound<'_, Self>) -> PyResult<Py<PyModel>> {
        let (py, this) = (slf.py(), reading(slf)?);
        this.model.get_or_try_init(py, || Py::new(py, PyModel::frozen(this.sim.model().clone()))).map(|m| m.clone_ref(py))
    }

    /// Newton iterations of the contact solver in the last (sub)step on the tree engine (it stops once
    /// the velocities converge, or at `solver_iterations`); None on Rapier.
    #[getter]
    fn last_solver_iterations(slf: &Bound<'_, Self>) -> PyResult<Option<usize>> {
        Ok(reading(slf)?.sim.last_solver_iterations())
    }

    /// The tree engine's friction law: "cone" (the convex relaxation, the default) or "coulomb".
    #[getter]
    fn friction_law(slf: &Bound<'_, Self>) -> PyResult<&'static str> {
        Ok(reading(slf)?.sim.options().friction_law.name())
    }

    /// "tree" or "rapier".
    #[getter]
    fn backend(slf: &Bound<'_, Self>) -> PyResult<&'static str> {
        Ok(reading(slf)?.sim.options().backend.name())
    }

    /// Advances `n` steps (in Rust, GIL released) with feed-forward generalized forces `tau` (nv,) held
    /// over the steps (None: zero); servos, if set, add to it and the sum is clipped to the servo's torque
    /// limit and the joint's effort limit (`Model.limits`), whichever is tighter. Joint position limits
    /// are enforced as constraints.
    /// On a floating base tau[:6] is a wrench [f, n] on the base, in its frame, at its origin (as `aba`).
    /// Raises RuntimeError, naming the step and the body, if the state would stop being finite or explode
    /// (a speed or position beyond 1e6); the simulation is then exactly as before that step. Ctrl-C
    /// interrupts a long call between steps (KeyboardInterrupt), keeping the steps taken.
    /// `targets` (n, nv): the servos' position targets per velocity coordinate for each of n steps (base
    /// entries unused; n defaults to its rows, and must match them if given), so a controller tracking a
    /// trajectory at the simulation's rate makes one call; the servos then keep the last row's targets.
    #[pyo3(signature = (tau = None, n = None, targets = None))]
    fn step(slf: &Bound<'_, Self>, tau: Option<Floats<'_>>, n: Option<Integer>, targets: Option<Floats<'_>>) -> PyResult<()> {
        let n = n.map(|n| n.within("n", 0, i64::MAX as u64)).transpose()?;
        let mut this = in_use(slf)?;
        let nv = this.sim.model().nv();
        let tau = tau.map(|t| vector_argument("tau", &t, nv)).transpose()?;
        let Some(targets) = targets else {
            let PySimulation { sim, pace, .. } = &mut *this;
            return in_pieces(slf.py(), n.unwrap_or(1), pace, |k| sim.step(tau.as_deref(), k as usize).map_err(kernel_error));
        };
        let view = targets.get("targets")?;
        if view.ndim() != 2 || view.shape()[1] != nv {
            return Err(PyValueError::new_err(format!("targets: expected shape (n, {nv}), got {:?}", view.shape())));
        }
        let rows = view.shape()[0] as u64;
        if let Some(n) = n.filter(|&n| n != rows) {
            return Err(PyValueError::new_err(format!("n: {n} steps asked with {rows} rows of targets (leave n out to take one step per row)")));
        }
        // A broadcast view may stand for more numbers than memory holds: copied with fallible allocation.
        let mut targets = with_capacity("targets", view.len()).map_err(kernel_error)?;
        targets.extend(view.iter().copied());
        if let Some(k) = targets.iter().position(|x| !x.is_finite()) {
            return Err(PyValueError::new_err(format!("targets: row {}, element {} is not finite ({})", k / nv, k % nv, targets[k])));
        }
        let PySimulation { sim, pace, .. } = &mut *this;
        let mut done = 0;
        in_pieces(slf.py(), rows, pace, |k| {
            let piece = &targets[done * nv..(done + k as usize) * nv];
            done += k as usize;
            sim.step_targets(tau.as_deref(), piece).map_err(kernel_error)
        })
    }

    /// Steps once per row of `controls` (N, nv), each row one step's feed-forward tau, from the current state under the
    /// current servos, as MuJoCo's `rollout` steps a state (GIL released; Ctrl-C stops it between steps): returns
    /// (q (N, nq), v (N, nv)), the state after each step, and with `jacobians=True` (q, v, A (N, 2 nv, 2 nv),
    /// B (N, 2 nv, 3 nv)), each step's transition Jacobians at its start as `transition_jacobians` gives them: one call
    /// per iteration of a shooting method or iLQR. The simulation advances as N calls of `step(controls[k])` (the
    /// same states, bit for bit). ValueError for controls of another shape, no rows or a value not finite (nothing
    /// moves); a step that fails raises RuntimeError at its last good state, the steps before it taken, as `step`.
    #[pyo3(signature = (controls, jacobians = false))]
    fn rollout<'py>(slf: &Bound<'py, Self>, controls: Floats<'_>, jacobians: bool) -> PyResult<Bound<'py, PyTuple>> {
        let py = slf.py();
        let mut this = in_use(slf)?;
        let sizes = (this.sim.model().nq(), this.sim.model().nv());
        let view = controls.get("controls")?;
        if view.ndim() != 2 {
            return Err(PyValueError::new_err(format!("controls: expected shape (N, {}), got {:?}", sizes.1, view.shape())));
        }
        let controls = control_rows(&view, sizes.1)?;
        let sim = &mut this.sim;
        let out = interruptible(py, "rollout", |_| finite_rollout(sim, &controls, jacobians))?.map_err(kernel_error)?;
        rollout_arrays(py, None, out.v.len() / sizes.1.max(1), sizes, vec![out], jacobians)
    }

    /// The transition Jacobians of one step from the current state (GIL released), as MuJoCo's
    /// `mjd_transitionFD`: A = ∂x⁺/∂x (2 nv, 2 nv) and B = ∂x⁺/∂u (2 nv, 3 nv), for the state x = (δq, v), q
    /// on its tangent space (q ⊕ δq, as `integrate`), and the controls u = (tau, target_q, target_v): B's columns are
    /// the feed-forward tau (nv), the servos' position targets and their velocity targets (nv each, per
    /// velocity coordinate; zero on a floating base's six). Analytic through the converged contact solve;
    /// the step's contact set, contact zones (apart, sticking, sliding), saturated servos and active limits
    /// are held. Nothing changes (state, time, contact history, `contacts()`). Tree backend; a step of several substeps is chained (docs/derivatives.md).
    #[pyo3(signature = (tau = None))]
    fn transition_jacobians<'py>(slf: &Bound<'py, Self>, tau: Option<Floats<'_>>) -> PyResult<Bound<'py, PyTuple>> {
        let py = slf.py();
        let mut this = in_use(slf)?;
        let nv = this.sim.model().nv();
        let tau = tau.map(|t| vector_argument("tau", &t, nv)).transpose()?;
        let PySimulation { sim, jacobian_pace, .. } = &mut *this;
        // A chain of substeps that may run past one piece runs where Ctrl-C can stop it (`interruptible`); a short one
        // is not worth a thread.
        let substeps = sim.options().substeps as u64;
        let started = Instant::now();
        let (a, b) = if jacobian_pace.fits_one_piece(substeps) {
            py.detach(|| finite_jacobians(sim, tau.as_deref()))
        } else {
            interruptible(py, "transition_jacobians", |_| finite_jacobians(sim, tau.as_deref()))?
        }
        .map_err(kernel_error)?;
        jacobian_pace.record(started.elapsed(), substeps);
        // Copied row by row into a fallibly reserved vector: a MemoryError naming the model, not an abort.
        let row_major = |m: &DMatrix<f64>| -> PyResult<Vec<f64>> {
            let mut out = with_capacity("model", m.len()).map_err(kernel_error)?;
            out.extend((0..m.nrows()).flat_map(|i| (0..m.ncols()).map(move |j| m[(i, j)])));
            Ok(out)
        };
        PyTuple::new(py, [to_numpy(py, (2 * nv, 2 * nv), row_major(&a)?), to_numpy(py, (2 * nv, 3 * nv), row_major(&b)?)])
    }

    /// Position/velocity servos, evaluated every step in Rust:
    /// τ = clip(kp (target_q − q) + kd (target_v − v) + tau, ±min(torque_limit, effort limit)) per velocity
    /// coordinate, the effort limit being the model's (`Model.limits`, inf if none).
    /// `kp` (N m/rad), `kd` (N m s/rad), `torque_limit` (N m, may be inf): scalars (joint coordinates only;
    /// a floating base is never servoed) or (nv,) arrays (zero gains on a floating base's six).
    /// `target_q`: a configuration (nq,) whose joint coordinates are the targets (None: the current q);
    /// `target_v`: (nv,) (None: zero). Clear servos with kp = kd = 0.
    #[pyo3(signature = (kp, kd = None, torque_limit = None, target_q = None, target_v = None))]
    fn set_servo(
        slf: &Bound<'_, Self>, kp: Floats<'_>, kd: Option<Floats<'_>>, torque_limit: Option<Floats<'_>>, target_q: Option<Floats<'_>>,
        target_v: Option<Floats<'_>>,
    ) -> PyResult<()> {
        let mut this = in_use(slf)?;
        let model = this.sim.model();
        let (nq, nv, floating) = (model.nq(), model.nv(), model.floating_base());
        let kp = per_dof("kp", &kp, nv, floating, 0.0)?;
        let kd = kd.map(|k| per_dof("kd", &k, nv, floating, 0.0)).transpose()?.unwrap_or_else(|| vec![0.0; nv]);
        let limit =
            torque_limit.map(|l| per_dof("torque_limit", &l, nv, floating, f64::INFINITY)).transpose()?.unwrap_or_else(|| vec![f64::INFINITY; nv]);
        let configuration = match target_q {
            Some(t) => {
                let t = vector_argument("target_q", &t, nq)?;
                check_vector("target_q", &t, nq).map_err(kernel_error)?;
                t
            }
            None => this.sim.q().to_vec(),
        };
        let mut targets = vec![0.0; nv];
        dof_coordinates(model, &configuration, &mut targets);
        let target_v = target_v.map(|t| vector_argument("target_v", &t, nv)).transpose()?.unwrap_or_else(|| vec![0.0; nv]);
        let servo = Servo::new(model, kp, kd, limit, targets, target_v).map_err(kernel_error)?;
        this.sim.set_servo(servo).map_err(kernel_error)
    }

    /// Configuration (nq,) in legkit's layout; setting it moves the robot (velocity, time and contact
    /// history kept).
    #[getter]
    fn q<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let q = reading(slf)?.sim.q().to_vec();
        Ok(to_numpy(slf.py(), q.len(), q))
    }

    #[setter]
    fn set_q(slf: &Bound<'_, Self>, q: Floats<'_>) -> PyResult<()> {
        let mut this = in_use(slf)?;
        let q = vector_argument("q", &q, this.sim.model().nq())?;
        this.sim.set_state(Some(&q), None).map_err(kernel_error)
    }

    /// Velocity (nv,) in legkit's layout (a floating base's [v_lin, ω] in its own frame); settable.
    #[getter]
    fn v<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let v = reading(slf)?.sim.v().to_vec();
        Ok(to_numpy(slf.py(), v.len(), v))
    }

    #[setter]
    fn set_v(slf: &Bound<'_, Self>, v: Floats<'_>) -> PyResult<()> {
        let mut this = in_use(slf)?;
        let v = vector_argument("v", &v, this.sim.model().nv())?;
        this.sim.set_state(None, Some(&v)).map_err(kernel_error)
    }

    /// Simulated time (s).
    #[getter]
    fn time(slf: &Bound<'_, Self>) -> PyResult<f64> {
        Ok(reading(slf)?.sim.time())
    }

    /// Step length (s).
    #[getter]
    fn dt(slf: &Bound<'_, Self>) -> PyResult<f64> {
        Ok(reading(slf)?.sim.options().dt)
    }

    /// Generalized forces applied during the last step (nv,): servo plus feed-forward, clipped to the
    /// servo's torque limit and the joint's effort limit.
    #[getter]
    fn applied_tau<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let tau = reading(slf)?.sim.applied_tau().to_vec();
        Ok(to_numpy(slf.py(), tau.len(), tau))
    }

    /// Penetration (m) the engine leaves uncorrected: the contact tolerance.
    #[getter]
    fn contact_tolerance(slf: &Bound<'_, Self>) -> PyResult<f64> {
        Ok(reading(slf)?.sim.contact_tolerance())
    }

    /// World pose of every body, (nbodies, 4, 4).
    fn body_poses<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyArray3<f64>>> {
        let poses = reading(slf)?.sim.body_poses();
        let data = poses.iter().flat_map(homogeneous).collect();
        Ok(to_numpy(slf.py(), (poses.len(), 4, 4), data))
    }

    /// Contact points of the last step as a dict of arrays over k points: "body" (k,) int (the body the
    /// force acts on), "other" (k,) int (the other body, -1 for the ground), "point" (k, 3) world,
    /// "normal" (k, 3) unit, pointing into "body", "normal_force" (k,) N >= 0, "tangential_force" (k, 3) N
    /// (friction on "body"), "depth" (k,) penetration (m). Forces are averages over the step.
    fn contacts<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyDict>> {
        let (py, contacts) = (slf.py(), reading(slf)?.sim.contacts());
        let k = contacts.len();
        let rows = |f: &dyn Fn(&legkit_dynamics::sim::Contact) -> Vector3<f64>| -> Vec<f64> {
            contacts.iter().flat_map(|c| f(c).as_slice().to_vec()).collect()
        };
        let out = PyDict::new(py);
        out.set_item("body", to_numpy(py, k, contacts.iter().map(|c| c.body as i64).collect::<Vec<i64>>()))?;
        out.set_item("other", to_numpy(py, k, contacts.iter().map(|c| c.other.map_or(-1, |o| o as i64)).collect::<Vec<i64>>()))?;
        out.set_item("point", to_numpy(py, (k, 3), rows(&|c| c.point)))?;
        out.set_item("normal", to_numpy(py, (k, 3), rows(&|c| c.normal)))?;
        out.set_item("normal_force", to_numpy(py, k, contacts.iter().map(|c| c.normal_force).collect::<Vec<f64>>()))?;
        out.set_item("tangential_force", to_numpy(py, (k, 3), rows(&|c| c.tangential_force)))?;
        out.set_item("depth", to_numpy(py, k, contacts.iter().map(|c| c.depth).collect::<Vec<f64>>()))?;
        Ok(out)
    }

    /// Starts over at time 0 from (q, v) (None: neutral configuration, zero velocity) with no contact
    /// history: bit-identical to a new Simulation set to that state. Servo settings are kept.
    #[pyo3(signature = (q = None, v = None))]
    fn reset(slf: &Bound<'_, Self>, q: Option<Floats<'_>>, v: Option<Floats<'_>>) -> PyResult<()> {
        let mut this = in_use(slf)?;
        let model = this.sim.model();
        let q = match q {
            Some(q) => vector_argument("q", &q, model.nq())?,
            None => model.neutral().as_slice().to_vec(),
        };
        let v = match v {
            Some(v) => vector_argument("v", &v, model.nv())?,
            None => vec![0.0; model.nv()],
        };
        this.sim.reset(&q, &v).map_err(kernel_error)
    }

    fn __repr__(slf: &Bound<'_, Self>) -> PyResult<String> {
        let this = reading(slf)?;
        let (model, options) = (this.sim.model(), this.sim.options());
        Ok(format!(
            "Simulation(nq={}, nv={}, dt={}, time={}, backend={:?})",
            model.nq(),
            model.nv(),
            options.dt,
            this.sim.time(),
            options.backend.name()
        ))
    }
}

/// The simulation, borrowed to change it: a RuntimeError saying so if another thread is using it (stepping
/// it with the GIL released), where pyo3 would say only "Already borrowed".
fn in_use<'py>(slf: &Bound<'py, PySimulation>) -> PyResult<PyRefMut<'py, PySimulation>> {
    slf.try_borrow_mut().map_err(|_| busy())
}

/// The Simulation to read, or the same error as `in_use` while another thread steps it.
fn reading<'py>(slf: &Bound<'py, PySimulation>) -> PyResult<PyRef<'py, PySimulation>> {
    slf.try_borrow().map_err(|_| busy())
}

fn busy() -> PyErr {
    PyRuntimeError::new_err("Simulation: in use by another thread (a step is running); a Simulation takes one caller at a time")
}

/// Steps many simulations at once on all cores (GIL released), each in its own thread of work: the
/// plants of a sweep or of an experiment's schemes. `SimulationBatch(simulations)` groups existing
/// `Simulation`s (any models, any backends); they stay usable on their own.
#[pyclass(name = "SimulationBatch", module = "legkit")]
pub struct PySimulationBatch {
    members: Vec<Py<PySimulation>>,
    pace: Pace,
    /// `transition_jacobians`' pace, per substep of all the simulations.
    jacobian_pace: Pace,
}

#[pymethods]
#[pyo3(crate = "crate::arguments")]
impl PySimulationBatch {
    #[new]
    fn new(simulations: Vec<Bound<'_, PyAny>>) -> PyResult<Self> {
        if simulations.is_empty() {
            return Err(PyValueError::new_err("simulations: need at least one Simulation"));
        }
        let mut members: Vec<Py<PySimulation>> = Vec::with_capacity(simulations.len());
        for (i, item) in simulations.iter().enumerate() {
            let sim = item.cast::<PySimulation>().map_err(|_| {
                PyTypeError::new_err(format!(
                    "simulations[{i}]: expected a Simulation, got {}",
                    item.get_type().name().map_or_else(|_| "?".into(), |n| n.to_string())
                ))
            })?;
            if members.iter().any(|m| m.is(sim)) {
                return Err(PyValueError::new_err(format!("simulations[{i}]: the same Simulation appears twice")));
            }
            members.push(sim.clone().unbind());
        }
        Ok(PySimulationBatch { members, pace: Pace::default(), jacobian_pace: Pace::default() })
    }

    /// Advances every simulation `n` steps, in parallel. `tau`: None (zero), one (nv,) array for all, a
    /// (B, nv) array, or a list of B arrays (or None), one per simulation (each its own nv). Every tau is
    /// checked before anything moves. The call is per member: a simulation that diverges stops at its last
    /// good state (as `Simulation.step` leaves it) while the others complete their n steps; then a
    /// RuntimeError names the lowest such index and its reason, and says which members stopped after how many
    /// steps; its `steps` attribute lists the steps each member took in this call.
    #[pyo3(signature = (tau = None, n = Integer::new(1)), text_signature = "($self, tau=None, n=1)")]
    fn step(&self, py: Python<'_>, tau: Option<Bound<'_, PyAny>>, n: Integer) -> PyResult<()> {
        let n = n.within("n", 0, i64::MAX as u64)?;
        let mut guards = self.borrow_all(py)?;
        let taus = self.torques(&guards, tau)?;
        let before: Vec<u64> = guards.iter().map(|g| g.sim.steps()).collect();
        let mut sims: Vec<(usize, &mut Simulation, &Option<Vec<f64>>)> =
            guards.iter_mut().zip(&taus).enumerate().map(|(i, (g, t))| (i, &mut g.sim, t)).collect();
        // The first failure, by index; a failed simulation stops, the others go on.
        let mut failure: Option<(usize, legkit_dynamics::Error)> = None;
        in_pieces(py, n, &self.pace, |k| {
            // Each simulation is stepped by one thread, so the results do not depend on which.
            let items: Vec<_> = sims.iter_mut().map(|(i, sim, tau)| (*i, &mut **sim, tau.as_deref())).collect();
            let outcomes = on_all_threads(items, || (), |_, _, (i, sim, tau)| sim.step(tau, k as usize).err().map(|e| (i, e)));
            let failed: Vec<(usize, legkit_dynamics::Error)> = outcomes.into_iter().flatten().collect();
            sims.retain(|(i, _, _)| !failed.iter().any(|(f, _)| f == i));
            failure = failure.take().into_iter().chain(failed).min_by_key(|(i, _)| *i);
            Ok(())
        })?;
        let Some((first, error)) = failure else { return Ok(()) };
        let taken: Vec<u64> = guards.iter().zip(&before).map(|(g, b)| g.sim.steps() - b).collect();
        let stopped: Vec<String> = taken.iter().enumerate().filter(|&(_, &t)| t < n).map(|(i, t)| format!("simulations[{i}] after {t}")).collect();
        let note = format!(
            "; per member: {} of {n} steps stopped at the last good state, the other {} took all {n} (steps: each member's)",
            stopped.join(", "),
            taken.len() - stopped.len()
        );
        let error = batch_error_noting(error, first, &note);
        error.value(py).setattr("steps", taken)?;
        Err(error)
    }

    /// Every simulation's transition Jacobians at its current state, in parallel (GIL released): A (B, 2 nv, 2 nv)
    /// and B (B, 2 nv, 3 nv), as `Simulation.transition_jacobians` (all simulations must share nv); `tau` as in
    /// `step`. Nothing changes. An error names the lowest index it came from.
    #[pyo3(signature = (tau = None))]
    fn transition_jacobians<'py>(&self, py: Python<'py>, tau: Option<Bound<'_, PyAny>>) -> PyResult<Bound<'py, PyTuple>> {
        let mut guards = self.borrow_all(py)?;
        let nv = guards[0].sim.model().nv();
        if guards.iter().any(|g| g.sim.model().nv() != nv) {
            return Err(PyValueError::new_err("simulations: they differ in nv; ask each simulation for its own Jacobians"));
        }
        let taus = self.torques(&guards, tau)?;
        let items: Vec<_> = guards.iter_mut().map(|g| &mut g.sim).zip(&taus).collect();
        // As `Simulation.transition_jacobians`, over the substeps of all the simulations.
        let substeps = items.iter().map(|(sim, _)| sim.options().substeps as u64).sum();
        let jacobians = |flag: &Arc<AtomicBool>| {
            on_all_threads(items, || (), |_, _, (sim, tau)| cancellable(Arc::clone(flag), || finite_jacobians(sim, tau.as_deref())))
        };
        let started = Instant::now();
        let outcomes = if self.jacobian_pace.fits_one_piece(substeps) {
            py.detach(|| jacobians(&Arc::default()))
        } else {
            interruptible(py, "transition_jacobians", jacobians)?
        };
        self.jacobian_pace.record(started.elapsed(), substeps);
        let count = outcomes.len();
        let len = |columns: usize| array_len("simulations", &[count, 2 * nv, columns * nv], std::mem::size_of::<f64>()).map_err(kernel_error);
        let mut a_all = with_capacity("simulations", len(2)?).map_err(kernel_error)?;
        let mut b_all = with_capacity("simulations", len(3)?).map_err(kernel_error)?;
        for (i, outcome) in outcomes.into_iter().enumerate() {
            let (a, b) = outcome.map_err(|e| batch_error(e, i))?;
            a_all.extend_from_slice(a.transpose().as_slice());
            b_all.extend_from_slice(b.transpose().as_slice());
        }
        PyTuple::new(py, [to_numpy(py, (count, 2 * nv, 2 * nv), a_all), to_numpy(py, (count, 2 * nv, 3 * nv), b_all)])
    }

    /// Every simulation's `Simulation.rollout` from its own state, in parallel (GIL released; Ctrl-C stops them between
    /// steps), as MuJoCo's `rollout` over a batch of initial states: `controls` (B, N, nv), one sequence per simulation,
    /// or (N, nv) for all; returns (q (B, N, nq), v (B, N, nv)) and with `jacobians=True` also A (B, N, 2 nv, 2 nv)
    /// and B (B, N, 2 nv, 3 nv). All simulations must share nq and nv. Every control is checked before anything moves;
    /// a simulation that fails stops at its last good state while the others complete, and the error names the
    /// lowest index.
    #[pyo3(signature = (controls, jacobians = false))]
    fn rollout<'py>(&self, py: Python<'py>, controls: Floats<'_>, jacobians: bool) -> PyResult<Bound<'py, PyTuple>> {
        let mut guards = self.borrow_all(py)?;
        let sizes = (guards[0].sim.model().nq(), guards[0].sim.model().nv());
        if guards.iter().any(|g| (g.sim.model().nq(), g.sim.model().nv()) != sizes) {
            return Err(PyValueError::new_err("simulations: they differ in nq or nv; roll each simulation out on its own"));
        }
        let count = guards.len();
        let view = controls.get("controls")?;
        let shared = match view.shape() {
            [_, k] if *k == sizes.1 => true,
            [b, _, k] if *b == count && *k == sizes.1 => false,
            shape => return Err(PyValueError::new_err(format!("controls: expected shape (N, {0}) or ({count}, N, {0}), got {shape:?}", sizes.1))),
        };
        let rows = control_rows(&view, sizes.1)?;
        let per = if shared { rows.len() } else { rows.len() / count };
        let items: Vec<_> =
            guards.iter_mut().enumerate().map(|(i, g)| (&mut g.sim, if shared { &rows[..] } else { &rows[i * per..(i + 1) * per] })).collect();
        let outcomes = interruptible(py, "rollout", |flag| {
            on_all_threads(items, || (), |_, _, (sim, controls)| cancellable(Arc::clone(flag), || finite_rollout(sim, controls, jacobians)))
        })?;
        let mut outs = Vec::with_capacity(count);
        for (i, outcome) in outcomes.into_iter().enumerate() {
            outs.push(outcome.map_err(|e| batch_error(e, i))?);
        }
        rollout_arrays(py, Some(count), per / sizes.1.max(1), sizes, outs, jacobians)
    }

    /// The grouped simulations, in order.
    #[getter]
    fn simulations(&self, py: Python<'_>) -> Vec<Py<PySimulation>> {
        self.members.iter().map(|m| m.clone_ref(py)).collect()
    }

    /// Configurations (B, nq) (all simulations must share nq).
    #[getter]
    fn q<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        self.stack(py, "q", |s| s.q())
    }

    /// Velocities (B, nv) (all simulations must share nv).
    #[getter]
    fn v<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        self.stack(py, "v", |s| s.v())
    }

    fn __len__(&self) -> usize {
        self.members.len()
    }

    fn __repr__(&self) -> String {
        format!("SimulationBatch(<{} simulations>)", self.members.len())
    }
}

impl PySimulationBatch {
    /// Every simulation, borrowed for writing; an error naming the first one in use elsewhere.
    fn borrow_all<'py>(&self, py: Python<'py>) -> PyResult<Vec<PyRefMut<'py, PySimulation>>> {
        self.members
            .iter()
            .enumerate()
            .map(|(i, m)| m.bind(py).try_borrow_mut().map_err(|_| PyRuntimeError::new_err(format!("simulations[{i}]: in use elsewhere"))))
            .collect()
    }

    /// One feed-forward per simulation, checked (length, finite) before any step.
    fn torques(&self, guards: &[PyRefMut<'_, PySimulation>], tau: Option<Bound<'_, PyAny>>) -> PyResult<Vec<Option<Vec<f64>>>> {
        let count = guards.len();
        let Some(tau) = tau.filter(|t| !t.is_none()) else { return Ok(vec![None; count]) };
        let per_sim: Vec<Option<Vec<f64>>> = if tau.is_instance_of::<PyList>() || tau.is_instance_of::<PyTuple>() {
            let list: Vec<Option<Floats<'_>>> = tau.extract()?;
            if list.len() != count {
                return Err(PyValueError::new_err(format!("tau: expected {count} entries (one per simulation), got {}", list.len())));
            }
            list.iter()
                .enumerate()
                .map(|(i, t)| {
                    t.as_ref()
                        .map(|t| {
                            vector_argument("tau", t, guards[i].sim.model().nv())
                                .map_err(|e| PyValueError::new_err(format!("tau[{i}]: {}", e.value(tau.py()))))
                        })
                        .transpose()
                })
                .collect::<PyResult<_>>()?
        } else {
            let array: Floats<'_> = tau.extract()?;
            let view = array.get("tau")?;
            let nv = guards[0].sim.model().nv();
            if guards.iter().any(|g| g.sim.model().nv() != nv) {
                return Err(PyValueError::new_err("tau: the simulations differ in nv; pass a list of arrays, one per simulation"));
            }
            match view.shape() {
                [k] if *k == nv => vec![Some(view.iter().copied().collect()); count],
                [b, k] if *b == count && *k == nv => (0..count).map(|i| Some((0..nv).map(|j| view[[i, j]]).collect())).collect(),
                shape => return Err(PyValueError::new_err(format!("tau: expected shape ({nv},) or ({count}, {nv}), got {shape:?}"))),
            }
        };
        for (i, (t, g)) in per_sim.iter().zip(guards).enumerate() {
            if let Some(t) = t {
                check_vector("tau", t, g.sim.model().nv()).map_err(|e| batch_error(e, i))?;
            }
        }
        Ok(per_sim)
    }

    fn stack<'py>(&self, py: Python<'py>, what: &str, get: impl Fn(&Simulation) -> &[f64]) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let rows: Vec<Vec<f64>> = self.members.iter().map(|m| get(&m.bind(py).borrow().sim).to_vec()).collect();
        let width = rows[0].len();
        if rows.iter().any(|r| r.len() != width) {
            return Err(PyValueError::new_err(format!("{what}: the simulations differ in size; read each simulation's {what}")));
        }
        Ok(to_numpy(py, (rows.len(), width), rows.concat()))
    }
}
