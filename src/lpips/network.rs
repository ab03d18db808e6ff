//! The LPIPS distance of an image pair (module docs of [`crate::lpips`]).

use super::conv::{FeatureMap, conv_relu, max_pool};
use super::weights::{Layer, Weights, layers, min_side, weights_path};
use super::{LpipsError, Variant};
use rayon::prelude::*;
use std::path::Path;

/// LPIPS's input z-scoring: `(x − SHIFT) / SCALE` per channel (R, G, B).
const SHIFT: [f32; 3] = [-0.030, -0.088, -0.188];
/// See [`SHIFT`].
const SCALE: [f32; 3] = [0.458, 0.448, 0.450];
/// Added to a pixel's channel-vector length before dividing by it.
const NORM_EPSILON: f64 = 1e-10;
/// Pixels per piece of the per-layer sums (fixed: the sums do not depend on the thread count).
const PIXELS_PER_PIECE: usize = 4096;

/// A loaded LPIPS network.
#[derive(Clone, Debug, PartialEq)]
pub struct Lpips {
    weights: Weights,
}

impl Lpips {
    /// `variant`'s weights from `path` ([`Weights::load`]: shapes and checksum verified).
    ///
    /// # Errors
    ///
    /// See [`Weights::load`].
    pub fn load(path: &Path, variant: Variant) -> Result<Lpips, LpipsError> {
        Ok(Lpips {
            weights: Weights::load(path, variant)?,
        })
    }

    /// `variant`'s weights from the cache folder ([`weights_path`]).
    ///
    /// # Errors
    ///
    /// [`LpipsError::WeightsMissing`], naming the setup command, when they were not set up;
    /// otherwise as [`Lpips::load`].
    pub fn load_cached(variant: Variant) -> Result<Lpips, LpipsError> {
        Self::load(&weights_path(variant)?, variant)
    }

    /// The network.
    pub fn variant(&self) -> Variant {
        self.weights.variant
    }

    /// The LPIPS distance of two `width × height` images (interleaved RGB in `[0, 1]`, rows from
    /// the top): `Σ_layers mean_pixels Σ_c w_c (â_c − b̂_c)²`, with `â`, `b̂` the tapped
    /// activations scaled to unit length over the channels at each pixel.
    ///
    /// # Errors
    ///
    /// [`LpipsError::ImageSize`] when a buffer does not hold `width·height·3` values,
    /// [`LpipsError::TooSmall`] when a side is below the network's
    /// [`min_side`].
    pub fn distance(&self, first: &[f32], second: &[f32], width: usize, height: usize) -> Result<f64, LpipsError> {
        for (which, image) in [("first", first), ("second", second)] {
            if image.len() != width * height * 3 {
                return Err(LpipsError::ImageSize {
                    which,
                    len: image.len(),
                    width,
                    height,
                });
            }
        }
        let variant = self.variant();
        let min = min_side(variant);
        if width < min || height < min {
            return Err(LpipsError::TooSmall {
                variant,
                width,
                height,
                min,
            });
        }
        let taps_a = self.features(first, width, height);
        let taps_b = self.features(second, width, height);
        Ok(taps_a
            .iter()
            .zip(&taps_b)
            .zip(&self.weights.heads)
            .map(|((a, b), head)| layer_distance(a, b, head))
            .sum())
    }

    /// The activations at the taps of one image.
    fn features(&self, image: &[f32], width: usize, height: usize) -> Vec<FeatureMap> {
        let plane = width * height;
        let mut values = vec![0.0f32; 3 * plane];
        let rescale = |x: f32| match self.variant() {
            Variant::Vgg => x,
            Variant::Alex => 2.0 * x - 1.0,
        };
        for (p, rgb) in image.chunks_exact(3).enumerate() {
            for c in 0..3 {
                values[c * plane + p] = (rescale(rgb[c]) - SHIFT[c]) / SCALE[c];
            }
        }
        let mut map = FeatureMap {
            channels: 3,
            height,
            width,
            values,
        };
        let mut convs = self.weights.convs.iter();
        let mut taps = Vec::new();
        for layer in layers(self.variant()) {
            match *layer {
                Layer::Conv(_) => map = conv_relu(&map, convs.next().expect("one weight set per convolution")),
                Layer::MaxPool { size, stride } => map = max_pool(&map, size, stride),
                Layer::Tap => taps.push(map.clone()),
            }
        }
        taps
    }
}

/// `mean_pixels Σ_c head_c (â_c − b̂_c)²` of one tapped layer, in `f64`.
fn layer_distance(a: &FeatureMap, b: &FeatureMap, head: &[f32]) -> f64 {
    let pixels = a.height * a.width;
    let pieces: Vec<f64> = (0..pixels.div_ceil(PIXELS_PER_PIECE))
        .into_par_iter()
        .map(|piece| {
            let range = piece * PIXELS_PER_PIECE..((piece + 1) * PIXELS_PER_PIECE).min(pixels);
            range
                .map(|p| {
                    let length = |m: &FeatureMap| {
                        let sq: f64 = (0..m.channels).map(|c| (m.values[c * pixels + p] as f64).powi(2)).sum();
                        sq.sqrt() + NORM_EPSILON
                    };
                    let (la, lb) = (length(a), length(b));
                    (0..a.channels)
                        .map(|c| {
                            let d = a.values[c * pixels + p] as f64 / la - b.values[c * pixels + p] as f64 / lb;
                            head[c] as f64 * d * d
                        })
                        .sum::<f64>()
                })
                .sum()
        })
        .collect();
    pieces.iter().sum::<f64>() / pixels as f64
}
