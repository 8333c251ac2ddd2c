//! `legkit.load_mjcf` and `legkit.Mjcf`: a MuJoCo model file read into a `Model`, with its joints,
//! actuators and options.

use legkit_dynamics::mjcf::{self, JointKind};
use numpy::PyArray1;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::convert::{kernel_error, numbers, vector_to_numpy, Vector};
use crate::model::{read_mjcf, PyModel};
use crate::sim::{PyGround, PySimulation};

/// An MJCF file read into a `Model` (`model`), with its hinge, slide and free joints (`joints`), its joint
/// actuators (`actuators`, `actuator_torques`), `<option>`'s `timestep` and `gravity`, its floor (`ground`),
/// and the `warnings`; `simulation()` simulates it on its floor at its timestep.
#[pyclass(name = "Mjcf", module = "legkit")]
pub struct PyMjcf {
    inner: mjcf::Mjcf,
    model: Py<PyModel>,
}

/// `load_mjcf(path_or_xml, floating_base=None, strict=False)`: the MJCF as an `Mjcf` (see
/// `Model.from_mjcf` for what is read).
#[pyfunction(crate = "crate::arguments")]
#[pyo3(signature = (path_or_xml, floating_base = None, strict = false))]
pub fn load_mjcf(py: Python<'_>, path_or_xml: &Bound<'_, PyAny>, floating_base: Option<bool>, strict: bool) -> PyResult<PyMjcf> {
    let inner = read_mjcf(py, path_or_xml, floating_base, strict)?;
    let model = Py::new(py, PyModel::wrap(inner.model.clone()))?;
    Ok(PyMjcf { inner, model })
}

#[pymethods]
#[pyo3(crate = "crate::arguments")]
impl PyMjcf {
    #[getter]
    fn model(&self, py: Python<'_>) -> Py<PyModel> {
        self.model.clone_ref(py)
    }
    /// The kept joints in MuJoCo's order: dicts {name, type ("hinge", "slide", "free"), body, idx_q, idx_v}.
    #[getter]
    fn joints<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let list = PyList::empty(py);
        for j in &self.inner.joints {
            let d = PyDict::new(py);
            d.set_item("name", &j.name)?;
            d.set_item(
                "type",
                match j.kind {
                    JointKind::Hinge => "hinge",
                    JointKind::Slide => "slide",
                    JointKind::Free => "free",
                    JointKind::Ball => "ball",
                },
            )?;
            d.set_item("body", j.body)?;
            d.set_item("idx_q", j.idx_q)?;
            d.set_item("idx_v", j.idx_v)?;
            list.append(d)?;
        }
        Ok(list)
    }
    /// The joint actuators: dicts {name, joint, dof, gear, gain (3,), bias (3,), ctrlrange, forcerange}
    /// (a range is None when not limited); see `actuator_torques`.
    #[getter]
    fn actuators<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let list = PyList::empty(py);
        for a in &self.inner.actuators {
            let d = PyDict::new(py);
            d.set_item("name", &a.name)?;
            d.set_item("joint", &a.joint)?;
            d.set_item("dof", a.dof)?;
            d.set_item("gear", a.gear)?;
            d.set_item("gain", a.gain.to_vec())?;
            d.set_item("bias", a.bias.to_vec())?;
            d.set_item("ctrlrange", a.ctrlrange.map(|r| r.to_vec()))?;
            d.set_item("forcerange", a.forcerange.map(|r| r.to_vec()))?;
            list.append(d)?;
        }
        Ok(list)
    }
    /// `<option timestep>` (s).
    #[getter]
    fn timestep(&self) -> f64 {
        self.inner.timestep
    }
    /// `<option gravity>` (m/s², world frame); also the model's gravity.
    #[getter]
    fn gravity<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        vector_to_numpy(py, &self.inner.gravity)
    }
    /// The floor: the world body's first colliding plane geom, placed as in MuJoCo, with its sliding friction
    /// (a `Ground`); None when the file has none.
    #[getter]
    fn ground(&self) -> Option<PyGround> {
        self.inner.ground.clone().map(|ground| PyGround { ground })
    }
    /// `Simulation(model, dt=timestep, ground=ground, **options)`: the model on its own floor at the file's
    /// timestep (`options` are `Simulation`'s, `dt` and `ground` among them to override the file's).
    #[pyo3(signature = (**options))]
    fn simulation<'py>(&self, py: Python<'py>, options: Option<&Bound<'py, PyDict>>) -> PyResult<Bound<'py, PyAny>> {
        let arguments = PyDict::new(py);
        arguments.set_item("dt", self.inner.timestep)?;
        arguments.set_item("ground", self.ground())?;
        if let Some(options) = options {
            arguments.update(options.as_mapping())?;
        }
        py.get_type::<PySimulation>().call((self.model.clone_ref(py),), Some(&arguments))
    }
    /// What was loaded with a warning (also raised as `MjcfWarning`s).
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.inner.warnings.clone()
    }
    /// The joint torques (nv,) the actuators apply for controls `ctrl` (one per actuator) at (q, v), as
    /// MuJoCo's `qfrc_actuator`: force = gain ctrl + bias (affine in the actuator length gear q and
    /// velocity gear v), ctrl and force clamped to their ranges, torque gear force.
    fn actuator_torques<'py>(&self, py: Python<'py>, q: Vector<'_>, v: Vector<'_>, ctrl: Vector<'_>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let (q, v, ctrl) = (numbers("q", &q)?, numbers("v", &v)?, numbers("ctrl", &ctrl)?);
        let tau = self.inner.actuator_torques(&q, &v, &ctrl).map_err(kernel_error)?;
        Ok(PyArray1::from_slice(py, tau.as_slice()))
    }
    fn __repr__(&self) -> String {
        format!(
            "Mjcf(nbodies={}, nv={}, joints={}, actuators={}, warnings={})",
            self.inner.model.nbodies(),
            self.inner.model.nv(),
            self.inner.joints.len(),
            self.inner.actuators.len(),
            self.inner.warnings.len()
        )
    }
}
