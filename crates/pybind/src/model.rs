//! `legkit.Model`: a kinematic tree built body by body (or from URDF), with a cached workspace.

use std::ffi::CString;
use std::sync::Mutex;

use legkit_dynamics::mesh;
use legkit_dynamics::mjcf::{self, MjcfOptions};
use legkit_dynamics::urdf::{load_urdf, UrdfOptions};
use legkit_dynamics::{Data, Joint, JointLimits, MassProperties, Model};
use numpy::{PyArray1, PyArray2};
use pyo3::exceptions::{PyFileNotFoundError, PyIndexError, PyTypeError, PyUserWarning, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyString};

use crate::convert::{homogeneous, kernel_error, number, shown, source_text, to_numpy, transform, vector3, vector_to_numpy, Floats, Integer, Vector};
use crate::interrupt::on_worker;
use crate::mass::PyMassProperties;
use crate::shapes::{colliders, shape_overrides};

pyo3::create_exception!(
    legkit,
    UrdfWarning,
    PyUserWarning,
    "A URDF loaded as written although it is not quite valid (a non-physical inertia, effort=\"0\", ...); the message names the element."
);

pyo3::create_exception!(
    legkit,
    MjcfWarning,
    PyUserWarning,
    "An MJCF loaded without something legkit does not model (a tendon, a sensor, a joint's stiffness, ...); the message names it."
);

/// A kinematic tree: body 0 is the base (fixed to the world, or a free flyer with
/// q = [x, y, z, qx, qy, qz, qw] and v = [v_lin, v_ang] in the base frame); every other body hangs off a
/// revolute, prismatic or fixed joint placed in its parent's frame. Bodies are numbered parent first.
#[pyclass(name = "Model", module = "legkit")]
pub struct PyModel {
    pub model: Model,
    workspace: Mutex<Option<Box<Data>>>,
    /// A Simulation's own copy (`Simulation.model`): it describes what is simulated, so it does not change.
    frozen: bool,
}

impl PyModel {
    pub fn wrap(model: Model) -> Self {
        Self { model, workspace: Mutex::new(None), frozen: false }
    }

    pub fn frozen(model: Model) -> Self {
        Self { frozen: true, ..Self::wrap(model) }
    }

    /// The model to change, or a ValueError if it is a Simulation's.
    fn changed(&mut self) -> PyResult<&mut Model> {
        if self.frozen {
            return Err(PyValueError::new_err(
                "model: a Simulation's model (sim.model) describes what it simulates and cannot change; change the Model it was built from and build a new Simulation",
            ));
        }
        Ok(&mut self.model)
    }

    /// The cached workspace (or a new one if another thread holds it); hand it back with `put_back`.
    pub fn take_workspace(&self) -> Box<Data> {
        let cached = self.workspace.try_lock().ok().and_then(|mut w| w.take());
        cached.unwrap_or_else(|| Box::new(Data::new(&self.model)))
    }

    pub fn put_back(&self, data: Box<Data>) {
        if let Ok(mut w) = self.workspace.try_lock() {
            *w = Some(data);
        }
    }

    fn add(
        &mut self, parent: &Bound<'_, PyAny>, joint: Joint, placement: Option<&Bound<'_, PyAny>>, body: Option<PyMassProperties>,
        name: Option<String>, limits: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<usize> {
        let parent = self.body_index("parent", parent)?;
        let limits = joint_limits(limits)?;
        let placement = placement.map(transform).transpose()?.unwrap_or_default();
        let body = body.map_or_else(MassProperties::zero, |b| b.0);
        let name = name.unwrap_or_else(|| format!("body{}", self.model.nbodies()));
        let index = self.changed()?.add_body(parent, joint, placement, body, &name, limits).map_err(kernel_error)?;
        *self.workspace.get_mut().unwrap_or_else(|e| e.into_inner()) = None;
        Ok(index)
    }

    fn per_body<T>(&self, value: impl Fn(&Model, usize) -> T) -> Vec<T> {
        (0..self.model.nbodies()).map(|i| value(&self.model, i)).collect()
    }

    /// One value per velocity coordinate from an array (nv,), or from one number for every joint's (zero on
    /// a free-flyer base).
    fn per_coordinate(&self, argument: &str, value: &Floats<'_>) -> PyResult<Vec<f64>> {
        let values = value.get(argument)?;
        let nv = self.model.nv();
        match values.shape() {
            [] => {
                let (base, value) = (if self.model.floating_base() { 6 } else { 0 }, *values.first().expect("a 0-d array holds one number"));
                Ok((0..nv).map(|k| if k < base { 0.0 } else { value }).collect())
            }
            [n] if *n == nv => Ok(values.iter().copied().collect()),
            shape => Err(PyValueError::new_err(format!("{argument}: expected one number or shape ({nv},), got {shape:?}"))),
        }
    }

    /// A body given by index or by name, as the argument named `argument`: IndexError for an index out of range or
    /// a name no body has.
    pub fn body_index(&self, argument: &str, body: &Bound<'_, PyAny>) -> PyResult<usize> {
        if let Ok(name) = body.cast::<PyString>() {
            let name = name.to_str()?;
            return self.model.body_index(name).ok_or_else(|| PyIndexError::new_err(format!("{argument}: no body is named {name:?}")));
        }
        let index =
            body.extract::<Integer>()?.value(argument).map_err(|_| PyTypeError::new_err(format!("{argument}: expected an index or a name")))?;
        match usize::try_from(index) {
            Ok(i) if i < self.model.nbodies() => Ok(i),
            _ => Err(PyIndexError::new_err(format!("{argument}: index {} is out of range for {} bodies", shown(index), self.model.nbodies()))),
        }
    }
}

/// Joint limits from None (no limits), a (lower, upper) pair (any sequence of two numbers), or a dict with
/// any of the keys "lower", "upper", "effort", "velocity" (absent keys: no bound).
fn joint_limits(value: Option<&Bound<'_, PyAny>>) -> PyResult<JointLimits> {
    let Some(value) = value else { return Ok(JointLimits::NONE) };
    let limits = if let Ok(dict) = value.cast::<PyDict>() {
        let mut limits = JointLimits::NONE;
        for (key, item) in dict.iter() {
            let key: String = key.extract().map_err(|_| PyTypeError::new_err("limits: dict keys must be strings"))?;
            let slot = match key.as_str() {
                "lower" => &mut limits.lower,
                "upper" => &mut limits.upper,
                "effort" => &mut limits.effort,
                "velocity" => &mut limits.velocity,
                other => return Err(PyValueError::new_err(format!("limits: unknown key {other:?} (expected lower, upper, effort, velocity)"))),
            };
            *slot = number(&item).ok_or_else(|| PyTypeError::new_err(format!("limits: {key} must be a number")))?;
        }
        limits
    } else {
        // pyo3 refuses to read a str as a sequence.
        let pair: Vec<Bound<'_, PyAny>> = value
            .extract()
            .map_err(|_| PyTypeError::new_err("limits: expected None, a (lower, upper) pair or a dict with keys lower, upper, effort, velocity"))?;
        let [lower, upper] = &pair[..] else {
            return Err(PyValueError::new_err(format!("limits: expected a (lower, upper) pair, got {} values", pair.len())));
        };
        // `number`, not `f64`'s extraction, which takes a bool for 1.
        let bound =
            |item: &Bound<'_, PyAny>, name: &str| number(item).ok_or_else(|| PyTypeError::new_err(format!("limits: {name} must be a number")));
        JointLimits { lower: bound(lower, "lower")?, upper: bound(upper, "upper")?, ..JointLimits::NONE }
    };
    JointLimits::new(limits.lower, limits.upper, limits.effort, limits.velocity).map_err(kernel_error)
}

/// A read-only NumPy copy of `values`, so that writing into it fails instead of changing nothing.
fn read_only<'py>(py: Python<'py>, values: &[f64]) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let array = PyArray1::from_slice(py, values);
    array.call_method1("setflags", (false,))?;
    Ok(array)
}

/// Reads an MJCF (path or XML string) off the GIL, raising its warnings as `MjcfWarning`s.
pub fn read_mjcf(py: Python<'_>, path_or_xml: &Bound<'_, PyAny>, floating_base: Option<bool>, strict: bool) -> PyResult<mjcf::Mjcf> {
    let source = source_text(py, path_or_xml)?;
    let options = MjcfOptions { floating_base, strict };
    let loaded = on_worker(py, "from_mjcf", move || mjcf::load_mjcf(&source, &options))?.map_err(kernel_error)?;
    let category = py.get_type::<MjcfWarning>();
    for warning in &loaded.warnings {
        PyErr::warn(py, &category, &CString::new(format!("mjcf: {warning}"))?, 2)?;
    }
    Ok(loaded)
}

#[pymethods]
#[pyo3(crate = "crate::arguments")]
impl PyModel {
    #[new]
    #[pyo3(signature = (floating_base = false, base = None, base_name = "base", gravity = None))]
    fn new(floating_base: bool, base: Option<PyMassProperties>, base_name: &str, gravity: Option<Vector<'_>>) -> PyResult<Self> {
        let mut model = Model::new(floating_base, base.map_or_else(MassProperties::zero, |b| b.0), base_name);
        if let Some(g) = gravity {
            model.gravity = legkit_dynamics::validate::finite_vector("gravity", vector3("gravity", &g)?).map_err(kernel_error)?;
        }
        Ok(Self::wrap(model))
    }

    /// A model from a URDF file path or an XML string: links become bodies named after them (the root link
    /// is the base), revolute/continuous/prismatic/fixed joints their joints, named as in the file, `<limit>`s
    /// their limits. q and v are Pinocchio's (`buildModelFromUrdf`; with `JointModelFreeFlyer()` for
    /// `floating_base`), coordinate for coordinate: joints depth first from the root, a link's children in the
    /// order of their joints' names; but a continuous joint's q is its angle, where Pinocchio's is (cos, sin).
    /// What exporters write and Pinocchio loads (non-physical inertias, `effort="0"`) loads as written
    /// with a `UrdfWarning` naming the element, or is a ValueError if `strict`. `<collision>` meshes
    /// become convex hulls; `package://` names resolve in `package_dirs`, then `ROS_PACKAGE_PATH`, then
    /// the file's folder's ancestors (a mesh not found: a warning, and the link's inertia box). A string
    /// starting with `<` (after a byte order mark and blanks) is XML; a path that is not a regular file is
    /// refused before it is opened. Ctrl-C interrupts the load (KeyboardInterrupt).
    #[staticmethod]
    #[pyo3(signature = (path_or_xml, floating_base = false, strict = false, package_dirs = None))]
    fn from_urdf(
        py: Python<'_>, path_or_xml: &Bound<'_, PyAny>, floating_base: bool, strict: bool, package_dirs: Option<Vec<std::path::PathBuf>>,
    ) -> PyResult<Self> {
        let source = source_text(py, path_or_xml)?;
        let options = UrdfOptions { floating_base, strict, package_dirs: package_dirs.unwrap_or_default() };
        let urdf = on_worker(py, "from_urdf", move || load_urdf(&source, &options))?.map_err(kernel_error)?;
        let category = py.get_type::<UrdfWarning>();
        for warning in &urdf.warnings {
            PyErr::warn(py, &category, &CString::new(format!("urdf: {warning}"))?, 1)?;
        }
        Ok(Self::wrap(urdf.model))
    }

    /// A model from a MuJoCo MJCF file path or XML string (`load_mjcf` gives its joints, actuators and
    /// options too): bodies in MuJoCo's order, hinge and slide joints with q equal to MuJoCo's qpos, a
    /// top-level free joint as the free-flyer base (`floating_base=None`: as the file says; False welds it;
    /// True frees the single top-level body), `<default>` classes, `<include>`, every orientation form with
    /// `<compiler angle>` (degrees unless set), inertias from `<inertial>` or from geoms as MuJoCo's
    /// compiler, collision shapes from geoms, `<option gravity>`; ball joints become spherical joints. What legkit
    /// does not model (tendons, equality constraints, sensors, joint stiffness, ...) loads with an
    /// `MjcfWarning` naming it, or is a ValueError if `strict`. Ctrl-C interrupts the load. See docs/mjcf.md.
    #[staticmethod]
    #[pyo3(signature = (path_or_xml, floating_base = None, strict = false))]
    fn from_mjcf(py: Python<'_>, path_or_xml: &Bound<'_, PyAny>, floating_base: Option<bool>, strict: bool) -> PyResult<Self> {
        Ok(Self::wrap(read_mjcf(py, path_or_xml, floating_base, strict)?.model))
    }

    /// Adds a body on a revolute joint about `axis` (in the joint frame); returns its index. `limits`:
    /// None, a (lower, upper) angle range (rad), or a dict with any of lower, upper (rad; ±inf for
    /// none), effort (N m) and velocity (rad/s) (> 0; inf for none). Enforced by `Simulation` (range and
    /// effort), ignored by the dynamics algorithms.
    #[pyo3(signature = (parent, axis, placement = None, body = None, name = None, limits = None))]
    fn add_revolute(
        &mut self, parent: &Bound<'_, PyAny>, axis: Vector<'_>, placement: Option<&Bound<'_, PyAny>>, body: Option<PyMassProperties>,
        name: Option<String>, limits: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<usize> {
        self.add(parent, Joint::Revolute(vector3("axis", &axis)?), placement, body, name, limits)
    }

    /// Adds a body on a prismatic joint along `axis` (in the joint frame); returns its index. `limits` as
    /// for `add_revolute`, in m, N and m/s.
    #[pyo3(signature = (parent, axis, placement = None, body = None, name = None, limits = None))]
    fn add_prismatic(
        &mut self, parent: &Bound<'_, PyAny>, axis: Vector<'_>, placement: Option<&Bound<'_, PyAny>>, body: Option<PyMassProperties>,
        name: Option<String>, limits: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<usize> {
        self.add(parent, Joint::Prismatic(vector3("axis", &axis)?), placement, body, name, limits)
    }

    /// Adds a body on a helical joint about `axis` (in the joint frame) with `pitch` (m/rad): the body turns
    /// by q about the axis and moves pitch q along it. Returns its index; `limits` as for `add_revolute`
    /// (rad, N m, rad/s). The tree engine simulates it; Rapier's multibody has no such joint.
    #[pyo3(signature = (parent, axis, pitch, placement = None, body = None, name = None, limits = None))]
    #[allow(clippy::too_many_arguments)]
    fn add_helical(
        &mut self, parent: &Bound<'_, PyAny>, axis: Vector<'_>, pitch: f64, placement: Option<&Bound<'_, PyAny>>, body: Option<PyMassProperties>,
        name: Option<String>, limits: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<usize> {
        self.add(parent, Joint::Helical { axis: vector3("axis", &axis)?, pitch }, placement, body, name, limits)
    }

    /// Adds a body on a ball (spherical) joint; returns its index. Its coordinates are a unit quaternion
    /// `[qx, qy, qz, qw]` (as the free-flyer base's) and its velocity the angular velocity in the body's frame
    /// (Pinocchio's `JointModelSpherical`). The tree engine simulates it (no position servo on it); Rapier refuses it.
    #[pyo3(signature = (parent, placement = None, body = None, name = None))]
    fn add_spherical(
        &mut self, parent: &Bound<'_, PyAny>, placement: Option<&Bound<'_, PyAny>>, body: Option<PyMassProperties>, name: Option<String>,
    ) -> PyResult<usize> {
        self.add(parent, Joint::Spherical, placement, body, name, None)
    }

    /// Adds a body rigidly attached to `parent`; returns its index.
    #[pyo3(signature = (parent, placement = None, body = None, name = None))]
    fn add_fixed(
        &mut self, parent: &Bound<'_, PyAny>, placement: Option<&Bound<'_, PyAny>>, body: Option<PyMassProperties>, name: Option<String>,
    ) -> PyResult<usize> {
        self.add(parent, Joint::Fixed, placement, body, name, None)
    }

    #[getter]
    fn nq(&self) -> usize {
        self.model.nq()
    }
    #[getter]
    fn nv(&self) -> usize {
        self.model.nv()
    }
    #[getter]
    fn nbodies(&self) -> usize {
        self.model.nbodies()
    }
    #[getter]
    fn floating_base(&self) -> bool {
        self.model.floating_base()
    }
    /// Parent index of each body; the base is its own parent (`parents[0] == 0`), as in Pinocchio and Rust's
    /// `Model::parent`.
    #[getter]
    fn parents(&self) -> Vec<usize> {
        self.per_body(Model::parent)
    }
    /// Each body's name (a URDF's link names, an MJCF's body names), in body order.
    #[getter]
    fn names(&self) -> Vec<String> {
        self.per_body(|model, i| model.name(i).to_owned())
    }
    /// The names of the joints with coordinates, in q (and v) order: Pinocchio's `model.names[1:]` for a URDF,
    /// a floating base's joint first as "root_joint"; MuJoCo's for an MJCF (a free joint off the floating base as
    /// four: its name, then ":y", ":z" and ":rotation").
    #[getter]
    fn joint_names(&self) -> Vec<String> {
        let moving = (0..self.model.nbodies()).filter(|&i| self.model.joint(i).nq() > 0);
        moving.map(|i| self.model.joint_name(i).to_owned()).collect()
    }
    /// `joint_index(name)`: the body the joint named `name` moves (Pinocchio's `getJointId`), so its coordinates
    /// start at `idx_q[i]` and `idx_v[i]`; IndexError naming `name` if no joint has it.
    fn joint_index(&self, name: &str) -> PyResult<usize> {
        self.model.joint_index(name).ok_or_else(|| PyIndexError::new_err(format!("name: no joint is named {name:?}")))
    }
    #[getter]
    fn gravity<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        vector_to_numpy(py, &self.model.gravity)
    }
    /// Each velocity coordinate's armature (kg m² or kg), as Pinocchio's `model.armature`: a geared motor's
    /// rotor inertia reflected through its gearbox. RNEA, CRBA, ABA, Minv, the kinetic energy and `Simulation` use
    /// M + diag(armature). Read-only; set it whole: an array (nv,), or one number for every joint (a
    /// free-flyer base's six coordinates have none and stay 0). Zero by default.
    #[getter]
    fn armature<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        read_only(py, self.model.armature())
    }
    #[setter]
    fn set_armature(&mut self, value: Floats<'_>) -> PyResult<()> {
        let values = self.per_coordinate("armature", &value)?;
        self.changed()?.set_armature(&values).map_err(kernel_error)
    }
    /// Each velocity coordinate's viscous damping (N m s/rad or N s/m): `Simulation` applies −damping v
    /// (implicitly); the dynamics functions ignore it, as Pinocchio's. Set as `armature`. Zero by default.
    #[getter]
    fn damping<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        read_only(py, self.model.damping())
    }
    #[setter]
    fn set_damping(&mut self, value: Floats<'_>) -> PyResult<()> {
        let values = self.per_coordinate("damping", &value)?;
        self.changed()?.set_damping(&values).map_err(kernel_error)
    }
    #[getter]
    fn total_mass(&self) -> f64 {
        self.model.total_mass()
    }
    /// Index of each body's first configuration coordinate.
    #[getter]
    fn idx_q(&self) -> Vec<usize> {
        self.per_body(Model::idx_q)
    }
    /// Index of each body's first velocity coordinate.
    #[getter]
    fn idx_v(&self) -> Vec<usize> {
        self.per_body(Model::idx_v)
    }

    /// "free_flyer", "fixed", "revolute", "prismatic", "helical" or "spherical".
    fn joint_type(&self, body: &Bound<'_, PyAny>) -> PyResult<&'static str> {
        Ok(self.model.joint(self.body_index("body", body)?).kind())
    }

    /// The unit axis of a revolute, prismatic or helical joint, None otherwise.
    fn joint_axis<'py>(&self, py: Python<'py>, body: &Bound<'py, PyAny>) -> PyResult<Option<Bound<'py, PyArray1<f64>>>> {
        Ok(self.model.joint(self.body_index("body", body)?).axis().map(|a| vector_to_numpy(py, &a)))
    }

    /// The pitch (m/rad) of a helical joint, None otherwise.
    fn joint_pitch(&self, body: &Bound<'_, PyAny>) -> PyResult<Option<f64>> {
        Ok(match *self.model.joint(self.body_index("body", body)?) {
            Joint::Helical { pitch, .. } => Some(pitch),
            _ => None,
        })
    }

    /// The limits of the body's joint as a dict {lower, upper, effort, velocity} (rad or m, N m or N,
    /// rad/s or m/s; ±inf where unbounded), or None if the joint has none (always for the base and
    /// fixed joints).
    fn limits<'py>(&self, py: Python<'py>, body: &Bound<'py, PyAny>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let limits = self.model.limits(self.body_index("body", body)?);
        if !limits.is_limited() {
            return Ok(None);
        }
        let dict = PyDict::new(py);
        for (key, value) in [("lower", limits.lower), ("upper", limits.upper), ("effort", limits.effort), ("velocity", limits.velocity)] {
            dict.set_item(key, value)?;
        }
        Ok(Some(dict))
    }

    /// The body's mass properties in its own frame.
    fn body(&self, body: &Bound<'_, PyAny>) -> PyResult<PyMassProperties> {
        Ok(PyMassProperties(*self.model.body(self.body_index("body", body)?)))
    }

    /// A copy of the model in which `body` has the mass properties `mass_properties` (its own frame); joints,
    /// placements, limits and collision shapes unchanged.
    fn with_body(&self, body: &Bound<'_, PyAny>, mass_properties: PyMassProperties) -> PyResult<Self> {
        Ok(Self::wrap(self.model.with_body(self.body_index("body", body)?, mass_properties.0)))
    }

    /// The 4x4 placement of the body's joint frame in its parent's frame.
    fn placement<'py>(&self, py: Python<'py>, body: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        Ok(to_numpy(py, (4, 4), homogeneous(self.model.placement(self.body_index("body", body)?)).to_vec()))
    }

    /// The neutral configuration (zero joints, identity base orientation).
    fn neutral<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        to_numpy(py, self.model.nq(), self.model.neutral().as_slice().to_vec())
    }

    /// What `Simulation(model, shapes=shapes)` collides with: a list of (body, kind, size, placement),
    /// kind "box" (size: full edge lengths), "sphere" (radius,), "capsule" or "cylinder" (half_height,
    /// radius) along the shape's z axis; placement (4, 4) the shape frame in the body frame. `shapes`
    /// overrides bodies as in `Simulation`; other bodies take the model's URDF collision shapes, else a
    /// box with the body's inertia.
    #[pyo3(signature = (shapes = None))]
    fn colliders<'py>(&self, py: Python<'py>, shapes: Option<&Bound<'py, PyDict>>) -> PyResult<Bound<'py, pyo3::types::PyList>> {
        colliders(py, &self.model, shape_overrides(shapes, |key| self.body_index("body", key))?)
    }

    fn __repr__(&self) -> String {
        format!(
            "Model(nbodies={}, nq={}, nv={}, floating_base={}, mass={:.6})",
            self.model.nbodies(),
            self.model.nq(),
            self.model.nv(),
            if self.model.floating_base() { "True" } else { "False" },
            self.model.total_mass()
        )
    }
}

/// `resolve_mesh(filename, urdf=None, package_dirs=None)`: the file a URDF's mesh `filename` names, as
/// `Model.from_urdf` finds it: `package://name/rest` in `package_dirs` (each a folder holding packages, or
/// the package itself), then `ROS_PACKAGE_PATH`, then `AMENT_PREFIX_PATH`'s `share/` folders, then the folders
/// above the file `urdf`; relative names against `urdf`'s folder, then `package_dirs` (see
/// `legkit_dynamics::mesh::resolve_mesh` for every form read). FileNotFoundError naming where it looked;
/// ValueError for a name that climbs out of its package, or a symbolic link out of it to a file of another kind.
#[pyfunction(crate = "crate::arguments")]
#[pyo3(signature = (filename, urdf = None, package_dirs = None))]
pub fn resolve_mesh(filename: &str, urdf: Option<std::path::PathBuf>, package_dirs: Option<Vec<std::path::PathBuf>>) -> PyResult<std::path::PathBuf> {
    let folder = urdf.as_deref().and_then(std::path::Path::parent);
    mesh::resolve_mesh(filename, folder, &package_dirs.unwrap_or_default()).map_err(|e| match e.argument() {
        "filename" => PyValueError::new_err(e.to_string()),
        _ => PyFileNotFoundError::new_err(e.to_string()),
    })
}
