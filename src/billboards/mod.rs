//! The activated, owned billboard set ([`ActivatedBillboards`], structure of arrays) and a seeded
//! random-scene generator.
//!
//! The billboard set has three forms, one type each:
//!
//! | type | holds | made by |
//! | --- | --- | --- |
//! | [`RawBillboards`](crate::model::RawBillboards) | the optimised parameters: alpha and colour texture *logits* (planar, `[billboard][channel][texel]`), log half sides, raw quaternions, SH; what training updates and model files and checkpoints save | `RawBillboards::from_points`, `model_file::load_model`, `Trainer::export_model` |
//! | [`ActivatedBillboards`] | the same billboards, owned and *activated*: textures `sigmoid(logit)` in `[0, 1]` as interleaved RGBA texels (masked alpha texels 0), geometry and SH copied | [`RawBillboards::activate`](crate::model::RawBillboards::activate) (one row: [`RawBillboards::activate_row`](crate::model::RawBillboards::activate_row)), [`random_scene`] |
//! | [`ActivatedRef<'a>`](ActivatedRef) | the activated arrays, borrowed: what the rasterizer reads | [`ActivatedBillboards::borrowed`], or a struct literal over any slices in the layout |
//!
//! Raw → activated is one way (`activate`); where the raw form is needed back from activated
//! values, the caller takes the `logit` (e.g. `Trainer::export_model` in Gaussian mode).

pub mod alive;
pub mod trained_like;

pub use trained_like::{TrainedLikeConfig, trained_like_scene};

use crate::camera::Camera;
use crate::raster::{ActivatedRef, SH_FLOATS};

// The texture layout conversion, defined next to the layout it reads (`raster::ActivatedRef`).
pub use crate::raster::input::planar_textures;
use crate::rng::Rng;
use glam::{Vec2, Vec3};

/// The *activated*, owned form of the billboard set: textures in `[0, 1]` as interleaved RGBA
/// texels, laid out as [`ActivatedRef`] expects; made from the raw parameters by
/// [`RawBillboards::activate`](crate::model::RawBillboards::activate), borrowed for the
/// rasterizer by [`ActivatedBillboards::borrowed`]. The three forms of the set: the
/// [module documentation](self).
#[derive(Clone, Debug, PartialEq)]
pub struct ActivatedBillboards {
    /// Centres in world coordinates.
    pub positions: Vec<Vec3>,
    /// Raw quaternions (w, x, y, z).
    pub quaternions: Vec<[f32; 4]>,
    /// Log half side lengths.
    pub log_scales: Vec<Vec2>,
    /// SH coefficients, 48 per billboard, `[coeff][rgb]`.
    pub sh: Vec<f32>,
    /// Textures, `TS²` texels `[r, g, b, alpha]` in `[0, 1]` per billboard, row-major.
    pub textures: Vec<[f32; 4]>,
    /// Texture side.
    pub texture_size: usize,
}

impl ActivatedBillboards {
    /// An empty set with textures of side `texture_size`.
    pub fn empty(texture_size: usize) -> Self {
        Self {
            positions: Vec::new(),
            quaternions: Vec::new(),
            log_scales: Vec::new(),
            sh: Vec::new(),
            textures: Vec::new(),
            texture_size,
        }
    }

    /// Number of billboards.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// The mean alpha of each billboard ([`alive::mean_alpha`] of its texels' alpha
    /// channel), in billboard order.
    pub fn mean_alphas(&self) -> Vec<f32> {
        let t = self.texture_size * self.texture_size;
        self.textures
            .chunks_exact(t.max(1))
            .map(|row| alive::mean_alpha(row.iter().map(|x| x[3]), t))
            .collect()
    }

    /// Billboards that are alive ([`alive::is_alive`]: mean alpha above
    /// [`alive::DEAD_ALPHA`]).
    pub fn alive_count(&self) -> usize {
        self.mean_alphas().into_iter().filter(|&m| alive::is_alive(m)).count()
    }

    /// The borrowed form ([`ActivatedRef`]) the rasterizer reads.
    pub fn borrowed(&self) -> ActivatedRef<'_> {
        ActivatedRef {
            positions: &self.positions,
            quaternions: &self.quaternions,
            log_scales: &self.log_scales,
            sh: &self.sh,
            textures: &self.textures,
            texture_size: self.texture_size,
        }
    }

    /// Appends billboard `i` of `other` (same texture size).
    pub fn push_from(&mut self, other: &ActivatedBillboards, i: usize) {
        assert_eq!(self.texture_size, other.texture_size, "texture sizes differ");
        let t = self.texture_size * self.texture_size;
        self.positions.push(other.positions[i]);
        self.quaternions.push(other.quaternions[i]);
        self.log_scales.push(other.log_scales[i]);
        self.sh.extend_from_slice(&other.sh[i * SH_FLOATS..(i + 1) * SH_FLOATS]);
        self.textures.extend_from_slice(&other.textures[i * t..(i + 1) * t]);
    }

    /// Concatenation of `self` and `other`.
    pub fn concat(&self, other: &ActivatedBillboards) -> ActivatedBillboards {
        let mut out = self.clone();
        for i in 0..other.len() {
            out.push_from(other, i);
        }
        out
    }
}

/// Settings of [`random_scene`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RandomSceneConfig {
    /// Number of billboards.
    pub billboards: usize,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Texture side.
    pub texture_size: usize,
    /// Billboard footprint in pixels (side of the square seen face-on); the benchmark scene uses
    /// `width / sqrt(billboards)` so that the overlap per pixel stays roughly constant.
    pub footprint_px: f32,
    /// Alpha texel range; keep inside `(1/255, 0.99)` for smooth tests.
    pub alpha_range: (f32, f32),
    /// Seed.
    pub seed: u64,
}

impl RandomSceneConfig {
    /// The standard benchmark scene of `n` billboards at `width × height` with TS = 16.
    pub fn benchmark(n: usize, width: u32, height: u32) -> Self {
        Self {
            billboards: n,
            width,
            height,
            texture_size: 16,
            footprint_px: width as f32 / (n as f32).sqrt(),
            alpha_range: (0.0, 1.0),
            seed: 0,
        }
    }
}

/// The identity-pose camera of the random scenes: at the origin looking along +z,
/// `fx = fy = width`, principal point at the image centre.
pub fn random_scene_camera(width: u32, height: u32) -> Camera {
    Camera::identity(width, height)
}

/// A seeded random scene in front of [`random_scene_camera`]: centres at uniform pixel positions
/// and view depth in `[2, 8]`, uniformly random rotations, half sides giving the requested
/// footprint, uniform random textures and SH coefficients (DC around mid-grey, higher bands
/// small).
pub fn random_scene(config: &RandomSceneConfig) -> ActivatedBillboards {
    let mut rng = Rng::new(config.seed);
    let cam = random_scene_camera(config.width, config.height);
    let ts = config.texture_size;
    let t = ts * ts;
    let mut b = ActivatedBillboards::empty(ts);
    // The textures are the arrays the rasterizer reads at random rows: huge-page storage.
    b.textures = crate::memory::with_capacity(config.billboards * t);
    let mut colour = vec![0.0f32; 3 * t];
    for _ in 0..config.billboards {
        let (x, y) = (
            rng.range(0.0, config.width as f32),
            rng.range(0.0, config.height as f32),
        );
        let z = rng.range(2.0, 8.0);
        b.positions
            .push(Vec3::new((x - cam.cx) / cam.fx * z, (y - cam.cy) / cam.fy * z, z));
        // Uniform rotation: normalised Gaussian 4-vector.
        let q = [rng.normal(), rng.normal(), rng.normal(), rng.normal()];
        b.quaternions.push(q);
        // Footprint in pixels ≈ 2·s·fx/z  ⇒  s = footprint·z / (2 fx).
        let s = (config.footprint_px * z / (2.0 * cam.fx)).max(1e-6);
        let jitter = Vec2::new(rng.range(-0.2, 0.2), rng.range(-0.2, 0.2));
        b.log_scales.push(Vec2::splat(s.ln()) + jitter);
        for k in 0..SH_FLOATS {
            let v = if k < 3 {
                rng.range(-0.5, 0.5)
            } else {
                rng.range(-0.1, 0.1)
            };
            b.sh.push(v);
        }
        // Drawn as alpha plane then colour planes `[channel][texel]`, then interleaved.
        let (lo, hi) = config.alpha_range;
        let start = b.textures.len();
        b.textures.extend((0..t).map(|_| [0.0, 0.0, 0.0, rng.range(lo, hi)]));
        colour.iter_mut().for_each(|c| *c = rng.uniform());
        for (k, texel) in b.textures[start..].iter_mut().enumerate() {
            for c in 0..3 {
                texel[c] = colour[c * t + k];
            }
        }
    }
    b
}
