//! `legkit._core`: the compiled half of the `legkit` Python package. Conversions and error mapping only;
//! every computation lives in `legkit-dynamics`.

mod batch;
mod convert;
mod dynamics;
mod geometry;
mod mass;
mod model;

use pyo3::prelude::*;

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<mass::PyMassProperties>()?;
    m.add_class::<model::PyModel>()?;
    m.add_function(wrap_pyfunction!(dynamics::forward_kinematics, m)?)?;
    m.add_function(wrap_pyfunction!(dynamics::rnea, m)?)?;
    m.add_function(wrap_pyfunction!(dynamics::aba, m)?)?;
    m.add_function(wrap_pyfunction!(dynamics::crba, m)?)?;
    m.add_function(wrap_pyfunction!(dynamics::minv, m)?)?;
    m.add_function(wrap_pyfunction!(geometry::circle_line, m)?)?;
    m.add_function(wrap_pyfunction!(geometry::rotation_toward_line, m)?)?;
    Ok(())
}
