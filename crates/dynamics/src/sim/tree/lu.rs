//! Dense LU factors with partial pivoting, in place, and their solves: the step's Jacobian M̃ + Jᵀ H J
//! (`transition`), unsymmetric where a sliding contact's friction bound follows its normal impulse. No allocation.

use nalgebra::DMatrix;

/// LU factors of the square `m` with partial pivoting, in place (L unit lower below the diagonal, U on and above),
/// the row swapped in at each column into `pivots`; false if `m` is singular.
pub(super) fn lu_factor(m: &mut DMatrix<f64>, pivots: &mut Vec<usize>) -> bool {
    let n = m.nrows();
    pivots.clear();
    for j in 0..n {
        let (p, largest) = (j..n).map(|i| (i, m[(i, j)].abs())).fold((j, -1.0), |best, x| if x.1 > best.1 { x } else { best });
        if !(largest > 0.0) {
            return false;
        }
        pivots.push(p);
        m.swap_rows(j, p);
        let (left, right) = m.as_mut_slice().split_at_mut((j + 1) * n);
        let pivot_column = &mut left[j * n..];
        let inverse = 1.0 / pivot_column[j];
        pivot_column[j + 1..].iter_mut().for_each(|l| *l *= inverse);
        // The Schur complement: each later column less its row j times L's column j.
        for column in right.chunks_exact_mut(n) {
            let u = column[j];
            if u != 0.0 {
                column[j + 1..].iter_mut().zip(&pivot_column[j + 1..]).for_each(|(x, l)| *x -= l * u);
            }
        }
    }
    true
}

/// Solves (`lu_factor`'s factors) x = rhs for every column of `rhs`, in place: the swaps, L forward, U back.
pub(super) fn lu_solve(lu: &DMatrix<f64>, pivots: &[usize], rhs: &mut DMatrix<f64>) {
    let n = lu.nrows();
    if n == 0 {
        return;
    }
    let factors = lu.as_slice();
    for x in rhs.as_mut_slice().chunks_exact_mut(n) {
        for (j, &p) in pivots.iter().enumerate() {
            x.swap(j, p);
        }
        for j in 0..n {
            let xj = x[j];
            x[j + 1..].iter_mut().zip(&factors[j * n + j + 1..(j + 1) * n]).for_each(|(x, l)| *x -= l * xj);
        }
        for j in (0..n).rev() {
            let column = &factors[j * n..(j + 1) * n];
            x[j] /= column[j];
            let xj = x[j];
            x[..j].iter_mut().zip(&column[..j]).for_each(|(x, u)| *x -= u * xj);
        }
    }
}
