//! The mass-property agents of a SuperBot robot on a synchronous bus, and the per-joint balancing controller
//! [Moll 2006, Algorithms 1–2]: the balance experiment's control loop, one call per control step.
//!
//! `legkit.agents.AgentNetwork` and `legkit.control.BalanceController` (Python) are the reference
//! implementation, and the only one of the asynchronous, lossy bus; this kernel is their synchronous bus
//! (every message sent in a round arrives in the next, intact), agent for agent and message for message:
//! the same algorithms, the same change-driven messages, the same counts.

mod balance;
mod network;

pub use balance::{Controller, Schedule, Scheme};
pub use network::{GroundContact, ModuleSpec, Network};

use nalgebra::{Matrix3, Vector3};

/// Connectors per module: 0–2 on block A (part 0), 3–5 on block B (part 3).
pub const SLOTS: usize = 6;
/// Packed moments about a frame's origin: `[m, h = m c (3), P = sum m r r^T (9, row-major)]`, the layout of
/// `legkit.agents.moments`: composition is addition, an empty estimate is zeros.
pub type Moments = [f64; 13];

/// Moments expressed in the frame in which their frame has pose (r, t) (`legkit.agents.moments.transform`):
/// h' = R h + m t, P' = R P R^T + (R h) t^T + t (R h)^T + m t t^T.
pub(crate) fn transform(r: &Matrix3<f64>, t: &Vector3<f64>, x: &Moments) -> Moments {
    let m = x[0];
    let h = Vector3::new(x[1], x[2], x[3]);
    let p = Matrix3::from_row_slice(&x[4..]);
    let g = r * h;
    let mt = t * m;
    let second = r * p * r.transpose() + g * t.transpose() + t * g.transpose() + mt * t.transpose();
    let mut out = [0.0; 13];
    out[0] = m;
    out[1..4].copy_from_slice((g + mt).as_slice());
    for i in 0..3 {
        for j in 0..3 {
            // The upper triangle mirrored: exactly symmetric, as the Python agents keep it.
            out[4 + 3 * i + j] = second[(i.min(j), i.max(j))];
        }
    }
    out
}

fn add(a: &mut Moments, b: &Moments) {
    a.iter_mut().zip(b).for_each(|(a, b)| *a += b);
}

/// The inverse pose (R^T, -R^T t).
fn inverse(r: &Matrix3<f64>, t: &Vector3<f64>) -> (Matrix3<f64>, Vector3<f64>) {
    let rt = r.transpose();
    let it = -(rt * t);
    (rt, it)
}

#[cfg(test)]
mod tests;
