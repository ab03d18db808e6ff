//! Seeded scenes whose render statistics look like those of trained models: tens of
//! semi-transparent billboards per pixel, screen sizes spread over an order of magnitude, alpha
//! textures that are mostly near 0 with a soft blob of low to middling opacity. The random
//! benchmark scene of [`super::random_scene`] blends 0.7 billboards per pixel; trained lego and
//! beer_colmap states blend 9-20 (`docs/benchmarks.md` has the measured statistics of both and
//! of these scenes, side by side, from [`crate::raster::WorkloadStats`]).
//!
//! The scene is seen by [`super::random_scene_camera`] (at the origin looking along +z,
//! `fx = fy = width`). Centres fill a ball (or a thick shell) at depth [`OBJECT_DEPTH`] whose disk on screen covers
//! the requested fraction of the image (an object on an empty background, like lego), and, for a
//! capture like beer_colmap, a share of them in a slab filling the whole view.

use super::{ActivatedBillboards, random_scene_camera};
use crate::raster::SH_FLOATS;
use crate::rng::Rng;
use glam::{Vec2, Vec3};

/// View depth of the centre of the object (lego's cameras are about 4 units from its centre).
pub const OBJECT_DEPTH: f32 = 4.0;

/// Settings of [`trained_like_scene`]; the presets [`TrainedLikeConfig::object`] and
/// [`TrainedLikeConfig::capture`] match measured trained states.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrainedLikeConfig {
    /// Number of billboards.
    pub billboards: usize,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Texture side.
    pub texture_size: usize,
    /// Fraction of the image covered by the object's disk.
    pub coverage: f32,
    /// Fraction of the billboards in the object; the others fill the whole view as a slab of
    /// centres at depths `OBJECT_DEPTH · [0.6, 1.4]` (a captured background).
    pub object_fraction: f32,
    /// Inner radius of the shell of centres, as a fraction of the object's radius (0: a full
    /// ball; trained billboards gather near surfaces).
    pub shell_inner: f32,
    /// How far billboards turn away from facing the camera: the quaternion is
    /// `(1, t·g₁, t·g₂, tan(φ/2))` normalised, `g` standard normal, `φ` uniform (a random spin
    /// about the view axis), `t` this value. 0 faces the camera; large values approach uniformly
    /// random rotations. Trained billboards tend to face the cameras that trained them.
    pub tilt: f32,
    /// Median side, in pixels, of a billboard seen face-on (log-normal).
    pub median_side_px: f32,
    /// Standard deviations of the log of the side below and above the median (a split normal:
    /// trained states have a long tail of small billboards and a short one of large ones).
    pub side_log_sigma: (f32, f32),
    /// The peak alpha of a billboard's blob is uniform in this range.
    pub alpha_peak: (f32, f32),
    /// Alpha outside the blob, uniform in this range per billboard and clamped at 0: trained
    /// textures are mostly faint rather than exactly transparent, yet some are.
    pub alpha_floor: (f32, f32),
    /// The blob's radius, as a fraction of the texture's half side, is uniform in this range.
    pub blob_radius: (f32, f32),
    /// Seed.
    pub seed: u64,
}

impl TrainedLikeConfig {
    /// An object on an empty background, like a trained NeRF-synthetic lego state: `n`
    /// billboards at `width × height`, TS = 16. The sizes scale with the image width and with
    /// `1/√n` from the measured 10k-billboard state at 400 px, so that the work per pixel stays
    /// the same whatever `n`.
    pub fn object(n: usize, width: u32, height: u32) -> Self {
        let scale = width as f32 / 400.0 * (10_000.0 / n.max(1) as f32).sqrt();
        let median_side_px = 15.0 * scale;
        // The object covers a third of the image, its billboards included: its centres fill a
        // disk smaller by 1.9 median sides (measured: billboards reach that far beyond it).
        let area = (width * height) as f32;
        let covered_radius = (0.33 * area / std::f32::consts::PI).sqrt();
        let radius = (covered_radius - 1.9 * median_side_px).max(0.25 * covered_radius);
        Self {
            billboards: n,
            width,
            height,
            texture_size: 16,
            coverage: std::f32::consts::PI * radius * radius / area,
            object_fraction: 1.0,
            shell_inner: 0.3,
            tilt: 1.0,
            median_side_px,
            side_log_sigma: (1.2, 0.6),
            alpha_peak: (0.15, 0.8),
            alpha_floor: (-0.03, 0.05),
            blob_radius: (0.5, 1.2),
            seed: 0,
        }
    }

    /// A capture filling the whole view, like a trained beer_colmap state: `n` billboards at
    /// `width × height`, TS = 16, sizes scaled as in [`TrainedLikeConfig::object`]; a quarter of
    /// them in a foreground object.
    pub fn capture(n: usize, width: u32, height: u32) -> Self {
        let scale = width as f32 / 400.0 * (10_000.0 / n.max(1) as f32).sqrt();
        Self {
            coverage: 0.4,
            object_fraction: 0.25,
            shell_inner: 0.7,
            tilt: 0.3,
            median_side_px: 4.5 * scale,
            side_log_sigma: (1.3, 1.2),
            alpha_peak: (0.1, 0.7),
            ..Self::object(n, width, height)
        }
    }
}

/// A seeded trained-like scene (see the [module documentation](self)).
pub fn trained_like_scene(config: &TrainedLikeConfig) -> ActivatedBillboards {
    let mut rng = Rng::new(config.seed);
    let cam = random_scene_camera(config.width, config.height);
    let ts = config.texture_size;
    let mut b = ActivatedBillboards::empty(ts);
    b.textures = crate::memory::with_capacity(config.billboards * ts * ts);
    let (w, h) = (config.width as f32, config.height as f32);
    // The object's radius on screen and in the world at OBJECT_DEPTH.
    let radius_px = (config.coverage * w * h / std::f32::consts::PI).sqrt();
    let radius = radius_px * OBJECT_DEPTH / cam.fx;
    for _ in 0..config.billboards {
        let position = if rng.uniform() >= config.object_fraction {
            let (x, y) = (rng.range(0.0, w), rng.range(0.0, h));
            let z = OBJECT_DEPTH * rng.range(0.6, 1.4);
            Vec3::new((x - cam.cx) / cam.fx * z, (y - cam.cy) / cam.fy * z, z)
        } else {
            // Uniform in the shell: a Gaussian direction and a cube-root radius.
            let d = Vec3::new(rng.normal(), rng.normal(), rng.normal()).normalize_or(Vec3::X);
            let inner = config.shell_inner.powi(3);
            let r = radius * (inner + (1.0 - inner) * rng.uniform()).cbrt();
            Vec3::new(0.0, 0.0, OBJECT_DEPTH) + d * r
        };
        b.positions.push(position);
        let spin = (rng.range(-0.5, 0.5) * std::f32::consts::PI).tan();
        b.quaternions
            .push([1.0, config.tilt * rng.normal(), config.tilt * rng.normal(), spin]);
        // Side in pixels ≈ 2·s·fx/z  ⇒  s = side·z / (2 fx).
        let g = rng.normal();
        let sigma = if g < 0.0 {
            config.side_log_sigma.0
        } else {
            config.side_log_sigma.1
        };
        let side_px = config.median_side_px * (sigma * g).exp();
        let s = (side_px * position.z / (2.0 * cam.fx)).max(1e-6);
        let jitter = Vec2::new(rng.range(-0.2, 0.2), rng.range(-0.2, 0.2));
        b.log_scales.push(Vec2::splat(s.ln()) + jitter);
        for k in 0..SH_FLOATS {
            b.sh.push(if k < 3 {
                rng.range(-0.3, 0.3)
            } else {
                rng.range(-0.05, 0.05)
            });
        }
        push_blob_texture(&mut b.textures, ts, config, &mut rng);
    }
    b
}

/// Appends one billboard's `ts²` RGBA texels: a base colour with per-texel noise, and an alpha
/// blob (peak, floor, centre, radius drawn from `config`) falling smoothly from the peak to the
/// floor at its radius.
fn push_blob_texture(textures: &mut Vec<[f32; 4]>, ts: usize, config: &TrainedLikeConfig, rng: &mut Rng) {
    let peak = rng.range(config.alpha_peak.0, config.alpha_peak.1);
    let floor = rng.range(config.alpha_floor.0, config.alpha_floor.1);
    let radius = rng.range(config.blob_radius.0, config.blob_radius.1);
    let centre = Vec2::new(rng.range(-0.3, 0.3), rng.range(-0.3, 0.3));
    let base = Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 0.6;
    for row in 0..ts {
        for col in 0..ts {
            // Texel centre in [-1, 1]² over the texture.
            let at = Vec2::new(
                (col as f32 + 0.5) / ts as f32 * 2.0 - 1.0,
                (row as f32 + 0.5) / ts as f32 * 2.0 - 1.0,
            );
            let falloff = (1.0 - (at - centre).length_squared() / (radius * radius)).max(0.0);
            let alpha = floor + (peak - floor).max(0.0) * falloff * falloff;
            let noise = Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 0.2;
            let c = (base + noise).min(Vec3::ONE);
            textures.push([c.x, c.y, c.z, alpha]);
        }
    }
}
