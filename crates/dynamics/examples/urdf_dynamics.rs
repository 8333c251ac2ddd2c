//! A URDF robot's dynamics and derivatives from Rust: load it, run RNEA, ABA, CRBA and Minv and the ABA derivatives on
//! one state, see the named errors the checked entry points return for bad input, and run a batch of ABA calls on all
//! cores. `cargo run --release -p legkit-dynamics --example urdf_dynamics`.

use legkit_dynamics::algorithms;
use legkit_dynamics::parallel::{self, DataPool};
use legkit_dynamics::urdf::{load_urdf, UrdfOptions};
use legkit_dynamics::{Data, Result};

fn main() -> Result<()> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/two_link_pendulum.urdf");
    let model = load_urdf(path, &UrdfOptions::default())?.model;
    let mut data = Data::new(&model);
    println!("{} bodies, nq {}, nv {}", model.nbodies(), model.nq(), model.nv());

    let (q, v, tau) = ([0.3, -0.6], [0.1, 0.2], [0.5, -0.25]);
    let ddq = algorithms::aba(&model, &mut data, &q, &v, &tau, None)?.clone();
    let back = algorithms::rnea(&model, &mut data, &q, &v, ddq.as_slice(), None)?;
    println!("ABA q̈ = {:?}; RNEA(q̈) = {:?} = τ", ddq.as_slice(), back.as_slice());
    let mass = algorithms::crba(&model, &mut data, &q)?.clone();
    let inverse = algorithms::minv(&model, &mut data, &q)?;
    let identity = nalgebra::DMatrix::<f64>::identity(model.nv(), model.nv());
    println!("M = {mass:.4}M⁻¹ M is the identity to {:.1e}", (inverse * &mass - identity).amax());
    let (ddq_dq, _, _) = algorithms::aba_derivatives(&model, &mut data, &q, &v, &tau, None)?;
    println!("∂q̈/∂q = {ddq_dq:.4}");

    // Bad input is an error naming the argument; nothing is written.
    println!("{}", algorithms::aba(&model, &mut data, &q[..1], &v, &tau, None).unwrap_err());
    println!("{}", algorithms::aba(&model, &mut data, &q, &[0.0, f64::NAN], &tau, None).unwrap_err());
    let other = load_urdf(path, &UrdfOptions::default())?.model;
    println!("{}", algorithms::aba(&other, &mut data, &q, &v, &tau, None).unwrap_err());

    // ABA on 100,000 states on all cores, each thread with a workspace from the pool.
    let n = 100_000;
    let states: Vec<f64> = (0..2 * n).map(|k| (k as f64 * 0.001).sin()).collect();
    let mut accelerations = vec![0.0; 2 * n];
    parallel::aba(&DataPool::new(&model), &states, &states, &vec![0.0; 2 * n], &mut accelerations, None).map_err(|failure| failure.error)?;
    println!("q̈ of state {}: {:?}", n - 1, &accelerations[2 * n - 2..]);
    Ok(())
}
