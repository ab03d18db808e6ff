//! The training loss with pixels weighted out by an object mask ([`crate::scene::mask::MaskMode::Weight`]):
//! render and target are both multiplied by `m = mask / 255` before the loss, and the gradient
//! by `m` after it (the chain rule of `L(r·m, t·m)`), the way nerfstudio's splatfacto uses
//! masks. A pixel with `m = 0` contributes nothing to L1, scores SSIM 1 in windows that lie
//! wholly outside the mask, and its render value receives a gradient of exactly 0: what the
//! billboards draw there is free. Means stay over all pixels (as the reference-class tools do),
//! so the loss's scale follows the mask's area.
//!
//! ```
//! use bbsplat::loss::TrainingLoss;
//! use bbsplat::loss::masked::{MaskedBuffers, evaluate_masked};
//! use bbsplat::loss::ssim::SsimScratch;
//! let (w, h) = (12, 12);
//! let target: Vec<f32> = (0..w * h * 3).map(|i| (i % 5) as f32 / 5.0).collect();
//! let render = vec![0.5f32; w * h * 3];
//! // Keep the left half only.
//! let mask: Vec<u8> = (0..w * h).map(|p| if p % w < w / 2 { 255 } else { 0 }).collect();
//! let (mut scratch, mut buffers) = (SsimScratch::default(), MaskedBuffers::default());
//! let out = evaluate_masked(&TrainingLoss::default(), &render, &target, &mask, (w, h, 3), &mut scratch, &mut buffers)
//!     .unwrap();
//! // The right half's render receives no gradient.
//! assert!((0..w * h).filter(|p| p % w >= w / 2).all(|p| out.d_render[3 * p..3 * p + 3] == [0.0; 3]));
//! ```

use super::ssim::SsimScratch;
use super::{LossError, TrainingLoss, TrainingLossOutput};

/// The weighted copies of render and target, kept from call to call so that a training step
/// allocates nothing. Their contents never affect a result (each is overwritten whole).
#[derive(Clone, Debug, Default)]
pub struct MaskedBuffers {
    render: Vec<f32>,
    target: Vec<f32>,
}

/// `values` (interleaved, `channels` per pixel) with each pixel's channels multiplied by
/// `mask[pixel] / 255`, written into `out` (resized to `values.len()`).
pub fn weight_pixels_into(values: &[f32], mask: &[u8], channels: usize, out: &mut Vec<f32>) {
    out.clear();
    out.extend_from_slice(values);
    weight_pixels(out, mask, channels);
}

/// Each pixel's `channels` values of `values` multiplied by `mask[pixel] / 255` in place.
pub fn weight_pixels(values: &mut [f32], mask: &[u8], channels: usize) {
    for (pixel, &m) in values.chunks_exact_mut(channels).zip(mask) {
        let weight = m as f32 / 255.0;
        for v in pixel {
            *v *= weight;
        }
    }
}

/// `loss` of `render · m` against `target · m` (`m = mask / 255`, one value per pixel of
/// `dims = (width, height, channels)`), with its gradient with respect to `render`
/// (`m · ∂L/∂(render·m)`). The reported `l1` and `ssim` are those of the weighted images.
///
/// # Errors
///
/// [`LossError::BadLength`] (`which: "mask"`) when `mask` does not hold `width · height` values;
/// otherwise as [`TrainingLoss::evaluate`].
pub fn evaluate_masked(
    loss: &TrainingLoss,
    render: &[f32],
    target: &[f32],
    mask: &[u8],
    dims: (usize, usize, usize),
    scratch: &mut SsimScratch,
    buffers: &mut MaskedBuffers,
) -> Result<TrainingLossOutput, LossError> {
    let (width, height, channels) = dims;
    if mask.len() != width * height {
        return Err(LossError::BadLength {
            which: "mask",
            expected: width * height,
            got: mask.len(),
        });
    }
    weight_pixels_into(render, mask, channels, &mut buffers.render);
    weight_pixels_into(target, mask, channels, &mut buffers.target);
    let mut out = loss.evaluate_in(&buffers.render, &buffers.target, dims, scratch)?;
    weight_pixels(&mut out.d_render, mask, channels);
    Ok(out)
}
