//! `legkit._core`: the compiled half of the `legkit` Python package. Conversions and error mapping only;
//! every computation lives in `legkit-dynamics`.

/// Declares a `#[pyfunction]` of a model: `fn name(py, model, q: ArrayArg<'_>, ...) -> Output { ... }` takes
/// `py: Python<'py>` and `model: PyRef<'_, PyModel>` first, then the arguments given, and returns `PyResult<Output>`;
/// attributes (its docstring, `#[pyo3(signature = ...)]`) go before `fn`.
macro_rules! model_function {
    ($(#[$attr:meta])* fn $name:ident($py:ident, $model:ident $(, $arg:ident: $ty:ty)* $(,)?) -> $out:ty $body:block) => {
        #[pyfunction(crate = "crate::arguments")]
        $(#[$attr])*
        #[allow(clippy::too_many_arguments)]
        pub fn $name<'py>($py: Python<'py>, $model: PyRef<'_, PyModel> $(, $arg: $ty)*) -> PyResult<$out> $body
    };
}

mod agents;
mod arguments;
mod batch;
mod contact;
mod convert;
mod derivatives;
mod dynamics;
mod geometry;
mod integrate;
mod interrupt;
mod kinematics;
mod mass;
mod mjcf;
mod model;
mod shapes;
mod sim;
mod workspace;

use pyo3::prelude::*;

/// The target features the extension is compiled for, behind a marker that `legkit._build` finds in the
/// shared library's bytes before loading it (executing an instruction the CPU lacks would kill the process);
/// `#[used]` keeps the whole record in the library.
#[used]
static TARGET_FEATURES_RECORD: &str = concat!("legkit-target-features=", env!("LEGKIT_TARGET_FEATURES"), ";");

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let features = &TARGET_FEATURES_RECORD["legkit-target-features=".len()..TARGET_FEATURES_RECORD.len() - 1];
    m.add("COMPILED_TARGET_FEATURES", features)?;
    m.add_class::<mass::PyMassProperties>()?;
    m.add_class::<model::PyModel>()?;
    m.add("UrdfWarning", m.py().get_type::<model::UrdfWarning>())?;
    m.add("MjcfWarning", m.py().get_type::<model::MjcfWarning>())?;
    m.add_class::<mjcf::PyMjcf>()?;
    m.add_function(wrap_pyfunction!(mjcf::load_mjcf, m)?)?;
    m.add_class::<sim::PySimulation>()?;
    m.add_class::<sim::PyGround>()?;
    m.add_class::<sim::PySimulationBatch>()?;
    m.add_class::<agents::PyBalanceKernel>()?;
    m.add_function(wrap_pyfunction!(model::resolve_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(kinematics::forward_kinematics, m)?)?;
    m.add_function(wrap_pyfunction!(kinematics::jacobian, m)?)?;
    m.add_function(wrap_pyfunction!(kinematics::jacobian_time_variation, m)?)?;
    m.add_function(wrap_pyfunction!(kinematics::kinematic_hessian, m)?)?;
    m.add_function(wrap_pyfunction!(kinematics::point_velocity_hessian, m)?)?;
    m.add_function(wrap_pyfunction!(kinematics::point_acceleration_hessian, m)?)?;
    m.add_function(wrap_pyfunction!(kinematics::center_of_mass_hessian, m)?)?;
    m.add_function(wrap_pyfunction!(kinematics::centroidal_momentum_hessian, m)?)?;
    m.add_function(wrap_pyfunction!(kinematics::frame_velocity, m)?)?;
    m.add_function(wrap_pyfunction!(kinematics::frame_acceleration, m)?)?;
    m.add_function(wrap_pyfunction!(kinematics::frame_velocity_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(kinematics::frame_acceleration_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(kinematics::center_of_mass, m)?)?;
    m.add_function(wrap_pyfunction!(kinematics::subtree_mass_properties, m)?)?;
    m.add_function(wrap_pyfunction!(kinematics::centroidal_momentum, m)?)?;
    m.add_function(wrap_pyfunction!(kinematics::centroidal_map, m)?)?;
    m.add_function(wrap_pyfunction!(kinematics::centroidal_momentum_rate, m)?)?;
    m.add_function(wrap_pyfunction!(dynamics::rnea, m)?)?;
    m.add_function(wrap_pyfunction!(dynamics::aba, m)?)?;
    m.add_function(wrap_pyfunction!(derivatives::rnea_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(derivatives::rnea_second_order_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(derivatives::aba_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(derivatives::centroidal_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(derivatives::center_of_mass_jacobian, m)?)?;
    m.add_function(wrap_pyfunction!(dynamics::crba, m)?)?;
    m.add_function(wrap_pyfunction!(dynamics::minv, m)?)?;
    m.add_function(wrap_pyfunction!(dynamics::kinetic_energy, m)?)?;
    m.add_function(wrap_pyfunction!(dynamics::potential_energy, m)?)?;
    m.add_function(wrap_pyfunction!(contact::contact_dynamics, m)?)?;
    m.add_function(wrap_pyfunction!(contact::impact, m)?)?;
    m.add_function(wrap_pyfunction!(contact::contact_dynamics_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(contact::impact_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(contact::point_accelerations, m)?)?;
    m.add_function(wrap_pyfunction!(contact::reduced_dynamics, m)?)?;
    m.add_function(wrap_pyfunction!(integrate::integrate, m)?)?;
    m.add_function(wrap_pyfunction!(integrate::difference, m)?)?;
    m.add_function(wrap_pyfunction!(integrate::integrate_jacobians, m)?)?;
    m.add_function(wrap_pyfunction!(integrate::difference_jacobians, m)?)?;
    m.add_function(wrap_pyfunction!(integrate::free_rollout, m)?)?;
    m.add_function(wrap_pyfunction!(geometry::circle_line, m)?)?;
    m.add_function(wrap_pyfunction!(geometry::rotation_toward_line, m)?)?;
    Ok(())
}
