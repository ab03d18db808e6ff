//! Image losses and metrics (spec §5.1 and §11): L1, SSIM with its analytic backward, PSNR,
//! and the training photometric loss `(1 − λ)·L1 + λ·(1 − SSIM)`.
//!
//! # Conventions
//!
//! - **Images** are `f32` slices, **interleaved** and **row-major**: the value of channel `ch`
//!   of pixel `(x, y)` (column `x`, row `y`) is at `(y·width + x)·channels + ch`. Colour values
//!   are in `[0, 1]` for display; the losses accept any finite values (the render is not
//!   clamped in training).
//! - `a` / `render` is the image the gradient is taken with respect to; `b` / `target` is the
//!   ground truth and is treated as constant.
//! - Scalar results (means) and upstream scalar derivatives are **f64**; means are accumulated
//!   in a fixed order, so they are deterministic whatever the number of threads. Gradients
//!   with respect to images are f32. SSIM works internally in f64 (see [`ssim`]), or in
//!   f32 where asked ([`ssim::ssim_with_grad_f32`]; the training loss's default,
//!   [`TrainingLoss::precision`]).
//! - Every function checks the buffer lengths against the stated shape and returns a
//!   [`LossError`] rather than panicking.
//!
//! Numbers (tolerances, timings) are in `docs/numerics-init-loss.md`.
//!
//! ```
//! use bbsplat::loss::{training_loss, psnr::psnr};
//! let (w, h) = (16, 12);
//! let gt: Vec<f32> = (0..w * h * 3).map(|i| (i % 7) as f32 / 7.0).collect();
//! let render: Vec<f32> = gt.iter().map(|v| v + 0.05).collect();
//! let (loss, grad) = training_loss(&render, &gt, w, h).unwrap();
//! assert!(loss > 0.0 && loss < 0.1);
//! assert_eq!(grad.len(), render.len());
//! assert!((psnr(&render, &gt).unwrap() - 26.0206).abs() < 1e-3); // MSE = 0.0025
//! ```

pub mod distortion;
pub mod l1;
pub mod masked;
pub mod normal_consistency;
pub mod psnr;
pub mod ssim;

use crate::cpu::Simd;
use rayon::prelude::*;
use ssim::{Padding, Precision, SsimOptions, SsimScratch};
use thiserror::Error;

/// Errors of the loss functions: shapes that do not match the buffers.
#[derive(Clone, Debug, PartialEq, Eq, Error)]
#[non_exhaustive]
pub enum LossError {
    /// A buffer does not hold the number of values its shape implies.
    #[error("{which} holds {got} values but {expected} were expected")]
    BadLength {
        /// Which argument: `"a"`, `"b"`, `"render"`, `"target"`, `"d_map"` or `"mask"`.
        which: &'static str,
        /// The number of values expected from the shape (or from the first image).
        expected: usize,
        /// The number of values given.
        got: usize,
    },
    /// The image has no pixel or no channel.
    #[error("the image is empty ({width}×{height}×{channels})")]
    Empty {
        /// Width in pixels.
        width: usize,
        /// Height in pixels.
        height: usize,
        /// Channels per pixel.
        channels: usize,
    },
    /// "Valid" padding needs at least one full 11×11 window inside the image.
    #[error("valid padding needs an image of at least 11×11 pixels, got {width}×{height}")]
    TooSmallForValid {
        /// Width in pixels.
        width: usize,
        /// Height in pixels.
        height: usize,
    },
}

/// Checks that `a` and `b` are non-empty and of equal length.
pub(crate) fn check_pair(a: &[f32], b: &[f32], names: [&'static str; 2]) -> Result<(), LossError> {
    if a.is_empty() {
        return Err(LossError::Empty {
            width: 0,
            height: 0,
            channels: 0,
        });
    }
    if b.len() != a.len() {
        return Err(LossError::BadLength {
            which: names[1],
            expected: a.len(),
            got: b.len(),
        });
    }
    Ok(())
}

/// Values per parallel work item in the chunked reductions.
const SUM_CHUNK: usize = 1 << 14;

/// `Σ_i f(i)` over `0..n` in f64, summed sequentially within fixed chunks and then over the
/// chunks in order: the same result for any number of threads.
pub(crate) fn chunked_sum<F>(n: usize, f: F) -> f64
where
    F: Fn(usize) -> f64 + Sync,
{
    let partial: Vec<f64> = (0..n.div_ceil(SUM_CHUNK))
        .into_par_iter()
        .map(|c| (c * SUM_CHUNK..((c + 1) * SUM_CHUNK).min(n)).map(&f).sum())
        .collect();
    partial.iter().sum()
}

/// The photometric training loss `(1 − λ)·L1 + λ·(1 − SSIM)` (spec §5.1) with its gradient.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrainingLoss {
    /// The weight `λ` of the `1 − SSIM` term (reference `lambda_dssim = 0.2`).
    pub lambda_dssim: f64,
    /// SSIM padding (reference: [`Padding::Same`]).
    pub padding: Padding,
    /// The arithmetic of the SSIM term: [`Precision::F32`] (as the reference's PyTorch code,
    /// and twice the vector lanes) or [`Precision::F64`] (the proven reference).
    pub precision: Precision,
    /// The instruction set of the SSIM passes (default: the widest the CPU runs; the same bits
    /// whatever it is).
    pub simd: Simd,
}

impl Default for TrainingLoss {
    /// The reference setting: `λ = 0.2`, "same" zero padding, SSIM in f32.
    fn default() -> Self {
        Self {
            lambda_dssim: 0.2,
            padding: Padding::Same,
            precision: Precision::F32,
            simd: Simd::detect(),
        }
    }
}

/// The value of the training loss, its parts, and its gradient with respect to the render.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainingLossOutput {
    /// `(1 − λ)·l1 + λ·(1 − ssim)`.
    pub loss: f64,
    /// Mean absolute error.
    pub l1: f64,
    /// Mean SSIM.
    pub ssim: f64,
    /// `∂loss/∂render`, same layout as the render.
    pub d_render: Vec<f32>,
}

impl TrainingLoss {
    /// Evaluates the loss and its gradient for a `width × height × channels` interleaved render
    /// against the ground truth `target`.
    ///
    /// # Errors
    ///
    /// [`LossError`] if a buffer does not match the shape, or the image is too small for
    /// "valid" padding.
    pub fn evaluate(
        &self,
        render: &[f32],
        target: &[f32],
        width: usize,
        height: usize,
        channels: usize,
    ) -> Result<TrainingLossOutput, LossError> {
        self.evaluate_in(render, target, (width, height, channels), &mut SsimScratch::default())
    }

    /// [`TrainingLoss::evaluate`] of a `(width, height, channels)` render, with the SSIM
    /// gradient's partial maps in the caller's `scratch` (kept from call to call, so that a
    /// training step allocates none).
    ///
    /// # Errors
    ///
    /// As [`TrainingLoss::evaluate`].
    pub fn evaluate_in(
        &self,
        render: &[f32],
        target: &[f32],
        dims: (usize, usize, usize),
        scratch: &mut SsimScratch,
    ) -> Result<TrainingLossOutput, LossError> {
        let lambda = self.lambda_dssim;
        // d/d(render) of −λ·SSIM, then add the L1 part in place.
        let options = SsimOptions {
            padding: self.padding,
            simd: self.simd,
        };
        let (ssim, mut d_render) =
            ssim::ssim_with_grad_in(render, target, dims, options, -lambda, self.precision, scratch)?;
        let l1 = l1::l1(render, target)?;
        l1::l1_vjp_accumulate(render, target, 1.0 - lambda, &mut d_render);
        let loss = (1.0 - lambda) * l1 + lambda * (1.0 - ssim);
        Ok(TrainingLossOutput {
            loss,
            l1,
            ssim,
            d_render,
        })
    }
}

/// The reference training loss `0.8·L1 + 0.2·(1 − SSIM)` on RGB images (3 interleaved
/// channels, "same" padding) and its gradient with respect to `render`. Use
/// [`TrainingLoss::evaluate`] for another `λ`, padding or channel count.
///
/// # Errors
///
/// [`LossError`] if a buffer does not hold `width·height·3` values.
pub fn training_loss(
    render: &[f32],
    target: &[f32],
    width: usize,
    height: usize,
) -> Result<(f64, Vec<f32>), LossError> {
    let out = TrainingLoss::default().evaluate(render, target, width, height, 3)?;
    Ok((out.loss, out.d_render))
}
