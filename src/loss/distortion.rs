//! The 2DGS depth-distortion loss (spec §5.3): the mean over pixels of the rasterizer's
//! distortion map ([`crate::raster::RenderOutput::distortion`], method in
//! [`crate::stages::depth_distortion`]), and its gradient with respect to the map.
//!
//! The mean is accumulated in f64 in a fixed order; the gradient is the constant
//! `d_loss / pixels` per pixel (rounded once to f32).
//!
//! ```
//! use bbsplat::loss::distortion::distortion_loss;
//! let map = [0.0, 0.5, 0.25, 0.25];
//! let (value, grad) = distortion_loss(&map, 2.0).unwrap();
//! assert_eq!(value, 0.25);
//! assert_eq!(grad, vec![0.5; 4]);
//! ```

use super::{LossError, chunked_sum};

/// The mean of the distortion map `map` (one value per pixel) and `d_loss · ∂mean/∂map`.
///
/// # Errors
///
/// [`LossError::Empty`] for an empty map.
pub fn distortion_loss(map: &[f32], d_loss: f64) -> Result<(f64, Vec<f32>), LossError> {
    if map.is_empty() {
        return Err(LossError::Empty {
            width: 0,
            height: 0,
            channels: 1,
        });
    }
    let n = map.len();
    let mean = chunked_sum(n, |i| f64::from(map[i])) / n as f64;
    Ok((mean, vec![(d_loss / n as f64) as f32; n]))
}
