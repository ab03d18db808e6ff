//! Intrinsics stated for one image size, scaled to the size of the image found.
//!
//! Benchmark datasets ship downscaled images with the intrinsics of the full-size ones: LLFF's
//! `poses_bounds.npy` states the full size (`H`, `W`) beside the focal length, NeuS/IDR's
//! `cameras_sphere.npz` states no size at all (DTU's matrices are for 1600×1200). The
//! intrinsics are scaled per axis by the exact size ratio (`fx·w/W`, `cx·w/W`, and likewise in
//! y), pixel edges mapping onto pixel edges (top-left image corner at `(0, 0)`), as
//! [`crate::scene::LoadOptions::downscale`] scales them.
//!
//! ```
//! use bbsplat::scene::colmap::Intrinsics;
//! use bbsplat::scene::reference_size::{ReferenceSize, scale_to_image};
//! let k = Intrinsics { fx: 2900.0, fy: 2900.0, cx: 820.0, cy: 620.0, distortion: Default::default() };
//! // No size stated: the factor is the integer nearest 2·cx / width (here 1640 / 400 → 4).
//! let s = scale_to_image(&k, ReferenceSize::FromPrincipalPoint, 400, 300).unwrap();
//! assert_eq!((s.fx, s.cx, s.cy), (725.0, 205.0, 155.0));
//! let s = scale_to_image(&k, ReferenceSize::Given { width: 4032.0, height: 3024.0 }, 504, 378).unwrap();
//! assert_eq!(s.fx, 362.5);
//! assert!(scale_to_image(&k, ReferenceSize::Given { width: 4032.0, height: 3024.0 }, 504, 504).is_err());
//! ```

use super::colmap::Intrinsics;

/// The image size the intrinsics were stated for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ReferenceSize {
    /// Stated by the file, pixels.
    Given {
        /// Width, pixels.
        width: f64,
        /// Height, pixels.
        height: f64,
    },
    /// Not stated: the image was downscaled by an integer factor `n` from a size whose centre is
    /// near the principal point, `n = round(2·cx / width)`; `2·cy / height` must agree with it
    /// within [`FACTOR_TOLERANCE`] (relative), and so must `2·cx / width`.
    FromPrincipalPoint,
}

/// Relative disagreement allowed between the factor from the principal point and the integer
/// factor chosen (a principal point a few percent off the centre is common; DTU's is 3 %).
pub const FACTOR_TOLERANCE: f64 = 0.15;

/// Largest difference, pixels, between the image's height and the reference height scaled by
/// the width ratio (rounding of the downscaled size); more means another aspect ratio (a crop).
pub const ASPECT_SLACK_PX: f64 = 1.0;

/// `k` (stated for `reference`) scaled to an image of `width × height` pixels.
///
/// # Errors
/// A message saying why the size found does not fit the reference: another aspect ratio, or no
/// integer factor that explains the principal point.
pub fn scale_to_image(k: &Intrinsics, reference: ReferenceSize, width: u32, height: u32) -> Result<Intrinsics, String> {
    let (w, h) = (width as f64, height as f64);
    let (rw, rh) = match reference {
        ReferenceSize::Given { width: rw, height: rh } => {
            if !(rw > 0.0 && rh > 0.0 && rw.is_finite() && rh.is_finite()) {
                return Err(format!("the stated image size {rw}x{rh} is not positive"));
            }
            if (rh * w / rw - h).abs() > ASPECT_SLACK_PX {
                return Err(format!(
                    "the image is {width}x{height} but the camera is stated for {rw}x{rh}: another aspect ratio \
                     (a crop?), the intrinsics cannot be scaled to it"
                ));
            }
            (rw, rh)
        }
        ReferenceSize::FromPrincipalPoint => {
            let (fx, fy) = (2.0 * k.cx / w, 2.0 * k.cy / h);
            let n = fx.round();
            let off = |f: f64| (f - n).abs() / n;
            if n.is_nan() || n < 1.0 || off(fx) > FACTOR_TOLERANCE || off(fy) > FACTOR_TOLERANCE {
                return Err(format!(
                    "the principal point ({}, {}) is not near the centre of the {width}x{height} image or of a size \
                     an integer number of times larger (2·cx/width = {fx:.3}, 2·cy/height = {fy:.3}): the size the \
                     intrinsics are for is unknown",
                    k.cx, k.cy
                ));
            }
            (n * w, n * h)
        }
    };
    let (sx, sy) = (w / rw, h / rh);
    Ok(Intrinsics {
        fx: k.fx * sx,
        fy: k.fy * sy,
        cx: k.cx * sx,
        cy: k.cy * sy,
        distortion: k.distortion,
    })
}
