//! Peak signal-to-noise ratio for images in `[0, 1]` (spec §11):
//! `PSNR = 20·log10(1/√MSE) = −10·log10(MSE)` with the MSE over all channels and pixels.
//!
//! - [`psnr`] works on the float images as given (no clamping), MSE in f64.
//! - [`psnr_u8`] reproduces the reference evaluation, which scores 8-bit PNG files: both images
//!   are first quantised as torchvision's `save_image` does ([`quantize_u8`]: clamp to
//!   `[0, 1]`, ×255, +0.5, truncate), then read back as `v/255`.
//! - Identical images have `MSE = 0` and PSNR `+∞` (returned as `f64::INFINITY`).
//!
//! ```
//! use bbsplat::loss::psnr::{psnr, psnr_u8, quantize_u8};
//! assert_eq!(quantize_u8(0.5), 128);
//! assert_eq!(quantize_u8(1.7), 255);
//! assert_eq!(quantize_u8(-0.1), 0);
//! let a = [0.5, 0.5, 0.5, 0.5];
//! let b = [0.6, 0.4, 0.6, 0.4];
//! assert!((psnr(&a, &b).unwrap() - 20.0).abs() < 1e-5);
//! // 0.501 and 0.5 are the same 8-bit value.
//! assert_eq!(psnr_u8(&[0.501; 4], &[0.5; 4]).unwrap(), f64::INFINITY);
//! ```

use super::{LossError, check_pair, chunked_sum};

/// The 8-bit value an image value is saved as (torchvision `save_image`): `⌊clamp(x, 0, 1)·255
/// + 0.5⌋`. NaN becomes 0.
pub fn quantize_u8(x: f32) -> u8 {
    // `as u8` saturates and maps NaN to 0; the clamp keeps the +0.5 rounding exact at the ends.
    (x.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

/// PSNR of `a` against `b` in dB, both in `[0, 1]` scale: `−10·log10(mean (aᵢ − bᵢ)²)`.
///
/// # Errors
///
/// [`LossError::Empty`] for empty input, [`LossError::BadLength`] if the lengths differ.
pub fn psnr(a: &[f32], b: &[f32]) -> Result<f64, LossError> {
    check_pair(a, b, ["a", "b"])?;
    let sse = chunked_sum(a.len(), |i| {
        let d = a[i] as f64 - b[i] as f64;
        d * d
    });
    Ok(psnr_from_mse(sse / a.len() as f64))
}

/// PSNR of the 8-bit quantised images, as the reference's `metrics.py` computes it from the
/// saved PNG files (see [`quantize_u8`]).
///
/// # Errors
///
/// As [`psnr`].
pub fn psnr_u8(a: &[f32], b: &[f32]) -> Result<f64, LossError> {
    check_pair(a, b, ["a", "b"])?;
    let sse = chunked_sum(a.len(), |i| {
        let d = (quantize_u8(a[i]) as f64 - quantize_u8(b[i]) as f64) / 255.0;
        d * d
    });
    Ok(psnr_from_mse(sse / a.len() as f64))
}

/// `−10·log10(mse)`, `+∞` for `mse = 0`.
fn psnr_from_mse(mse: f64) -> f64 {
    if mse == 0.0 { f64::INFINITY } else { -10.0 * mse.log10() }
}
