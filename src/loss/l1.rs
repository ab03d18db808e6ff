//! Mean absolute error `L1(a, b) = (1/n)·Σ|aᵢ − bᵢ|` over all values (pixels and channels)
//! and its gradient with respect to `a`.
//!
//! The gradient is `sign(aᵢ − bᵢ)/n` with the **subgradient 0 where `aᵢ = bᵢ`** (as PyTorch's
//! `abs` backward). The mean is accumulated in f64 in a fixed order.
//!
//! ```
//! use bbsplat::loss::l1::{l1, l1_vjp};
//! let a = [0.5, 0.2, 0.7, 0.1];
//! let b = [0.25, 0.2, 0.9, 0.1];
//! assert!((l1(&a, &b).unwrap() - 0.1125).abs() < 1e-7);
//! assert_eq!(l1_vjp(&a, &b, 1.0).unwrap(), vec![0.25, 0.0, -0.25, 0.0]);
//! ```

use super::{LossError, check_pair, chunked_sum};
use rayon::prelude::*;

/// Mean absolute difference of `a` and `b` (any layout, equal lengths), in f64.
///
/// # Errors
///
/// [`LossError::Empty`] for empty input, [`LossError::BadLength`] if the lengths differ.
pub fn l1(a: &[f32], b: &[f32]) -> Result<f64, LossError> {
    check_pair(a, b, ["a", "b"])?;
    let sum = chunked_sum(a.len(), |i| (a[i] as f64 - b[i] as f64).abs());
    Ok(sum / a.len() as f64)
}

/// `d_loss · ∂L1/∂a`: `d_loss·sign(aᵢ − bᵢ)/n` (rounded once to f32), 0 where `aᵢ = bᵢ`.
///
/// # Errors
///
/// As [`l1`].
pub fn l1_vjp(a: &[f32], b: &[f32], d_loss: f64) -> Result<Vec<f32>, LossError> {
    check_pair(a, b, ["a", "b"])?;
    let mut out = vec![0.0; a.len()];
    l1_vjp_accumulate(a, b, d_loss, &mut out);
    Ok(out)
}

/// Adds `d_loss · ∂L1/∂a` to `out` (lengths already checked by the caller).
pub(crate) fn l1_vjp_accumulate(a: &[f32], b: &[f32], d_loss: f64, out: &mut [f32]) {
    let step = (d_loss / a.len() as f64) as f32;
    out.par_chunks_mut(1 << 14)
        .zip(a.par_chunks(1 << 14).zip(b.par_chunks(1 << 14)))
        .for_each(|(o, (a, b))| {
            // Both candidates computed and one selected, without a branch: the signs of a
            // render against its target follow no pattern a branch predictor could learn.
            for ((o, &a), &b) in o.iter_mut().zip(a).zip(b) {
                let (up, down) = (*o + step, *o - step);
                *o = if a > b {
                    up
                } else if a < b {
                    down
                } else {
                    *o
                };
            }
        });
}
