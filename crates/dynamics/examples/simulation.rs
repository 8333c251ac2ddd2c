//! A simulation on the ground from Rust: a box on a free-flyer base dropped onto a plane with friction, stepped with
//! legkit's tree engine until it rests. `cargo run --release -p legkit-dynamics --example simulation`.

use legkit_dynamics::sim::{Ground, Options, Simulation};
use legkit_dynamics::{MassProperties, Model, Result};
use nalgebra::{Matrix3, Vector3};

fn main() -> Result<()> {
    let body = MassProperties::solid_box(2.0, Vector3::new(0.3, 0.2, 0.1), Vector3::zeros(), &Matrix3::identity())?;
    let model = Model::new(true, body, "box");
    let options = Options { ground: Some(Ground::plane(0.8)?), ..Options::new(1e-3) };
    let mut sim = Simulation::new(&model, options)?;
    // Half a metre up, tilted about x, spinning slowly: [x, y, z, qx, qy, qz, qw] and [v; ω] in the base frame.
    let angle: f64 = 0.3;
    let q = [0.0, 0.0, 0.5, (angle / 2.0).sin(), 0.0, 0.0, (angle / 2.0).cos()];
    sim.set_state(Some(&q), Some(&[0.0, 0.0, 0.0, 0.0, 0.0, 1.0]))?;
    for second in 1..=2 {
        sim.step(None, 1000)?;
        let contacts = sim.contacts();
        let support: f64 = contacts.iter().map(|c| c.normal_force).sum();
        println!("t = {second} s: height {:.4} m, {} contacts bearing {support:.2} N (weight {:.2} N)", sim.q()[2], contacts.len(), 2.0 * 9.81);
    }
    Ok(())
}
