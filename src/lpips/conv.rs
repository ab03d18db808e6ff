//! The backbone's operations on planar feature maps: convolution + ReLU (as a matrix product of
//! the weights and the unfolded input, `im2col`) and max pooling.
//!
//! A feature map of `c` channels, `h` rows and `w` columns is `c` planes of `h·w` values
//! (`[c][y][x]`, row-major), in `f32`.
//!
//! The convolution unfolds bands of output rows (each band's unfolded input at most
//! [`BAND_VALUES`] values) and multiplies each band with `matrixmultiply::sgemm`, the bands in
//! parallel over rayon. Band sizes depend on the layer's shape only, so the result is the same
//! for any number of threads.
//!
//! ```
//! use bbsplat::lpips::conv::{FeatureMap, conv_relu, max_pool};
//! use bbsplat::lpips::weights::{ConvShape, ConvWeights};
//! // A 3×3 box filter with bias −1 on one 4×4 channel of ones, padding 1: interior 9 − 1.
//! let shape = ConvShape { outputs: 1, inputs: 1, kernel: 3, stride: 1, pad: 1 };
//! let weights = ConvWeights { shape, weight: vec![1.0; 9], bias: vec![-1.0] };
//! let input = FeatureMap { channels: 1, height: 4, width: 4, values: vec![1.0; 16] };
//! let out = conv_relu(&input, &weights);
//! assert_eq!((out.height, out.width), (4, 4));
//! assert_eq!(out.values[5], 8.0); // row 1, column 1
//! assert_eq!(out.values[0], 3.0); // a corner sees 4 ones
//! let pooled = max_pool(&out, 2, 2);
//! assert_eq!(pooled.values, vec![8.0; 4]);
//! ```

use super::weights::ConvWeights;
use rayon::prelude::*;

/// The most values of one band's unfolded input (16 MB of `f32`).
pub const BAND_VALUES: usize = 1 << 22;

/// A planar feature map (module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct FeatureMap {
    /// Channels.
    pub channels: usize,
    /// Rows.
    pub height: usize,
    /// Columns.
    pub width: usize,
    /// `channels·height·width` values, `[c][y][x]`.
    pub values: Vec<f32>,
}

impl FeatureMap {
    /// The `h·w` values of channel `c`.
    pub fn plane(&self, c: usize) -> &[f32] {
        let n = self.height * self.width;
        &self.values[c * n..(c + 1) * n]
    }
}

/// `max(0, conv(input) + bias)` with `weights`' kernel, stride and zero padding.
///
/// # Panics
///
/// When `input.channels` is not the convolution's input count, or the output would be empty
/// (callers check the image size first).
pub fn conv_relu(input: &FeatureMap, weights: &ConvWeights) -> FeatureMap {
    let s = weights.shape;
    assert_eq!(input.channels, s.inputs, "convolution input channels");
    assert!(
        input.height + 2 * s.pad >= s.kernel && input.width + 2 * s.pad >= s.kernel,
        "convolution kernel larger than the padded map"
    );
    let out_h = (input.height + 2 * s.pad - s.kernel) / s.stride + 1;
    let out_w = (input.width + 2 * s.pad - s.kernel) / s.stride + 1;
    let depth = s.inputs * s.kernel * s.kernel;
    let band_rows = (BAND_VALUES / depth / out_w).clamp(1, out_h);
    let bands: Vec<(usize, Vec<f32>)> = (0..out_h.div_ceil(band_rows))
        .into_par_iter()
        .map(|b| {
            let y0 = b * band_rows;
            let rows = band_rows.min(out_h - y0);
            (y0, band(input, weights, y0, rows, out_w))
        })
        .collect();
    let plane = out_h * out_w;
    let mut values = vec![0.0f32; s.outputs * plane];
    for (y0, band) in bands {
        let n = band.len() / s.outputs;
        for o in 0..s.outputs {
            values[o * plane + y0 * out_w..][..n].copy_from_slice(&band[o * n..(o + 1) * n]);
        }
    }
    FeatureMap {
        channels: s.outputs,
        height: out_h,
        width: out_w,
        values,
    }
}

/// Output rows `y0..y0 + rows` of [`conv_relu`], `[outputs][rows·out_w]`.
fn band(input: &FeatureMap, weights: &ConvWeights, y0: usize, rows: usize, out_w: usize) -> Vec<f32> {
    let s = weights.shape;
    let k = s.kernel;
    let depth = s.inputs * k * k;
    let n = rows * out_w;
    // The unfolded input: row (c, ky, kx) holds, for each output pixel of the band, the input
    // value under that kernel tap (0 in the padding).
    let mut unfolded = vec![0.0f32; depth * n];
    for c in 0..s.inputs {
        let plane = input.plane(c);
        for ky in 0..k {
            for kx in 0..k {
                let row = &mut unfolded[((c * k + ky) * k + kx) * n..][..n];
                for r in 0..rows {
                    let iy = ((y0 + r) * s.stride + ky) as isize - s.pad as isize;
                    if iy < 0 || iy >= input.height as isize {
                        continue;
                    }
                    let source = &plane[iy as usize * input.width..][..input.width];
                    let target = &mut row[r * out_w..][..out_w];
                    for (x, t) in target.iter_mut().enumerate() {
                        let ix = (x * s.stride + kx) as isize - s.pad as isize;
                        if ix >= 0 && (ix as usize) < input.width {
                            *t = source[ix as usize];
                        }
                    }
                }
            }
        }
    }
    let mut out = vec![0.0f32; s.outputs * n];
    // SAFETY: `weights.weight` is `outputs × depth` row-major (checked at load), `unfolded` is
    // `depth × n` and `out` is `outputs × n`, both row-major; the strides below describe exactly
    // these buffers, and `out` is written only (beta = 0) and aliases neither input.
    unsafe {
        matrixmultiply::sgemm(
            s.outputs,
            depth,
            n,
            1.0,
            weights.weight.as_ptr(),
            depth as isize,
            1,
            unfolded.as_ptr(),
            n as isize,
            1,
            0.0,
            out.as_mut_ptr(),
            n as isize,
            1,
        );
    }
    for (o, row) in out.chunks_exact_mut(n).enumerate() {
        let b = weights.bias[o];
        for v in row {
            *v = (*v + b).max(0.0);
        }
    }
    out
}

/// The maximum over each `size × size` window at `stride`, no padding, partial windows dropped.
///
/// # Panics
///
/// When the map is smaller than one window.
pub fn max_pool(input: &FeatureMap, size: usize, stride: usize) -> FeatureMap {
    assert!(
        input.height >= size && input.width >= size,
        "max pool window larger than the map"
    );
    let out_h = (input.height - size) / stride + 1;
    let out_w = (input.width - size) / stride + 1;
    let mut values = vec![0.0f32; input.channels * out_h * out_w];
    values.par_chunks_mut(out_h * out_w).enumerate().for_each(|(c, out)| {
        let plane = input.plane(c);
        for y in 0..out_h {
            for x in 0..out_w {
                let mut m = f32::NEG_INFINITY;
                for dy in 0..size {
                    for dx in 0..size {
                        m = m.max(plane[(y * stride + dy) * input.width + x * stride + dx]);
                    }
                }
                out[y * out_w + x] = m;
            }
        }
    });
    FeatureMap {
        channels: input.channels,
        height: out_h,
        width: out_w,
        values,
    }
}
