//! The trainable billboard set in its raw form ([`RawBillboards`]): raw parameters,
//! initialisation and activation.
//!
//! Raw parameters follow the BBSplat spec, §1: position, raw quaternion (w, x, y, z), two log
//! half side lengths, 48 SH coefficients (`[coeff][rgb]`), and alpha and colour texture
//! *logits*. Activated textures (`sigmoid(logit)`) are what the rasterizer sees. Alpha texels
//! that start at exactly zero in the reference initialisation (15 of 256 at TS = 16) stay zero
//! through an explicit mask shared by every billboard, instead of infinite logits.

use crate::billboards::ActivatedBillboards;
pub use crate::billboards::alive::{DEAD_ALPHA, is_alive, mean_alpha};
use crate::init::knn::mean_sq_dist_3nn;
use crate::raster::SH_FLOATS;
use crate::rng::Rng;
use crate::stages::sh::rgb_to_sh;
use glam::{Vec2, Vec3};

/// The reference initial alpha texture (`assets/alpha_init_gaussian_small.png`, 16×16, values
/// 0-255, row = v index, column = u index), before the 0.5 factor.
pub const INITIAL_ALPHA_16: [[u8; 16]; 16] = [
    [0, 0, 0, 1, 2, 3, 3, 4, 4, 4, 3, 2, 1, 1, 0, 0],
    [0, 0, 1, 2, 4, 6, 9, 10, 11, 10, 7, 5, 3, 2, 1, 0],
    [0, 1, 3, 5, 10, 15, 21, 25, 25, 23, 18, 12, 7, 4, 2, 1],
    [1, 2, 5, 11, 20, 32, 43, 51, 53, 48, 37, 26, 15, 8, 3, 1],
    [2, 4, 10, 20, 36, 57, 77, 92, 96, 86, 67, 46, 27, 14, 7, 3],
    [3, 6, 15, 32, 57, 89, 121, 144, 149, 135, 106, 72, 43, 22, 10, 4],
    [3, 9, 21, 43, 77, 121, 166, 197, 204, 184, 144, 99, 59, 31, 13, 5],
    [4, 10, 25, 51, 92, 144, 197, 234, 242, 219, 171, 117, 70, 36, 16, 7],
    [4, 11, 25, 53, 96, 149, 204, 242, 251, 226, 177, 121, 72, 37, 17, 7],
    [4, 10, 23, 48, 86, 135, 184, 219, 226, 204, 160, 110, 65, 34, 15, 6],
    [3, 7, 18, 37, 67, 106, 144, 171, 177, 160, 126, 86, 51, 26, 12, 5],
    [2, 5, 12, 26, 46, 72, 99, 117, 121, 110, 86, 59, 35, 18, 8, 3],
    [1, 3, 7, 15, 27, 43, 59, 70, 72, 65, 51, 35, 21, 11, 5, 2],
    [1, 2, 4, 8, 14, 22, 31, 36, 37, 34, 26, 18, 11, 6, 2, 1],
    [0, 1, 2, 3, 7, 10, 13, 16, 17, 15, 12, 8, 5, 2, 1, 0],
    [0, 0, 1, 1, 3, 4, 5, 7, 7, 6, 5, 3, 2, 1, 0, 0],
];

/// The full alpha asset `G` for side `ts`: `table/255` (values in `[0, 251/255]`), the 16×16
/// table resampled with align-corners bilinear interpolation for other sizes (exact copy at 16):
/// texel `(r, c)` samples the table at `(r·15/(ts−1), c·15/(ts−1))`; `ts = 1` takes the table's
/// corner `(0, 0)`. This is the reference `G` of the alpha compression (`docs/model-format.md`);
/// the initial alpha is `0.5·G` ([`initial_alpha`]).
///
/// ```
/// use bbsplat::model::{alpha_asset, initial_alpha};
/// let g = alpha_asset(16);
/// assert_eq!(g[8 * 16 + 8], 251.0 / 255.0);
/// // The initial alpha is exactly half the asset, at any size.
/// for ts in [4, 16, 23] {
///     let (g, a) = (alpha_asset(ts), initial_alpha(ts));
///     assert!(g.iter().zip(&a).all(|(g, a)| 0.5 * g == *a));
/// }
/// ```
pub fn alpha_asset(ts: usize) -> Vec<f32> {
    let table = |r: usize, c: usize| INITIAL_ALPHA_16[r][c] as f32 / 255.0;
    if ts == 16 {
        return (0..256).map(|i| table(i / 16, i % 16)).collect();
    }
    let mut out = Vec::with_capacity(ts * ts);
    for r in 0..ts {
        for c in 0..ts {
            let map = |i: usize| if ts > 1 { i as f32 * 15.0 / (ts - 1) as f32 } else { 0.0 };
            let (y, x) = (map(r), map(c));
            let (y0, x0) = (y.floor() as usize, x.floor() as usize);
            let (y1, x1) = ((y0 + 1).min(15), (x0 + 1).min(15));
            let (fy, fx) = (y - y0 as f32, x - x0 as f32);
            let top = table(y0, x0) * (1.0 - fx) + table(y0, x1) * fx;
            let bottom = table(y1, x0) * (1.0 - fx) + table(y1, x1) * fx;
            out.push(top * (1.0 - fy) + bottom * fy);
        }
    }
    out
}

/// The initial alpha texture for side `ts`: `0.5·G` with `G` = [`alpha_asset`]`(ts)` (the
/// 16×16 table / 255, resampled with align-corners bilinear interpolation for other sizes).
/// Values in `[0, 0.5)`; texels that are exactly zero stay zero during training (see
/// [`RawBillboards::alpha_mask`]). Scaling by 0.5 is exact in floating point, so this is bit for bit
/// half of the asset.
pub fn initial_alpha(ts: usize) -> Vec<f32> {
    alpha_asset(ts).into_iter().map(|g| 0.5 * g).collect()
}

/// The per-texel alpha mask of side `ts`: `true` where the asset is non-zero. Texels outside
/// the mask are held at alpha 0 (spec §1.1: 15 of 256 texels at TS = 16).
pub fn standard_alpha_mask(ts: usize) -> Vec<bool> {
    alpha_asset(ts).iter().map(|&g| g > 0.0).collect()
}

/// `ln(p / (1 − p))`.
#[inline]
pub fn logit(p: f32) -> f32 {
    (p / (1.0 - p)).ln()
}

/// [`logit`] of an activated value clamped to `[1e-6, 1 − 1e-6]` first, so that 0 and 1 map to
/// finite logits (±13.8).
#[inline]
pub fn clamped_logit(p: f32) -> f32 {
    logit(p.clamp(1e-6, 1.0 - 1e-6))
}

/// `1 / (1 + e^{−x})`, with the vectorisable exponential [`crate::exp_f32::exp_f32`] (within
/// 3 ulp of the exact value; 0 and 1 at the infinities).
#[inline]
pub fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + crate::exp_f32::exp_f32(-x))
}

/// The *raw* form of the billboard set: the trainable parameters as optimised and saved
/// (texture logits, log half sides, raw quaternions, SH). [`RawBillboards::activate`] gives the
/// [`ActivatedBillboards`] the renderer needs. The three forms of the set:
/// [`crate::billboards`].
#[derive(Clone, Debug, PartialEq)]
pub struct RawBillboards {
    /// Centres (world).
    pub positions: Vec<Vec3>,
    /// Raw quaternions (w, x, y, z).
    pub quaternions: Vec<[f32; 4]>,
    /// Log half side lengths.
    pub log_scales: Vec<Vec2>,
    /// SH coefficients, 48 per billboard.
    pub sh: Vec<f32>,
    /// Alpha logits, `TS²` per billboard. The crate's constructors ([`RawBillboards::from_points`],
    /// `model_file::load_model`, checkpoints) allocate both logit arrays with
    /// [`crate::memory`]'s huge-page hint; a model assembled by hand works the same, only
    /// without the hint.
    pub alpha_logits: Vec<f32>,
    /// Colour logits, `3·TS²` per billboard.
    pub colour_logits: Vec<f32>,
    /// Per texel (shared by all billboards): false for texels held at alpha 0.
    pub alpha_mask: Vec<bool>,
    /// Texture side.
    pub texture_size: usize,
}

impl RawBillboards {
    /// Number of billboards.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// True when the model has no billboard.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// The billboards `i` for which `keep(i)` holds, in their order, as a model of the same
    /// texture size and alpha mask.
    ///
    /// ```
    /// use bbsplat::model::RawBillboards;
    /// use glam::Vec3;
    /// let m = RawBillboards::from_points(&[Vec3::ZERO, Vec3::X, Vec3::Y], &[[0.5; 3]; 3], 4, 0);
    /// let odd = m.rows_where(|i| i % 2 == 1);
    /// assert_eq!((odd.len(), odd.positions[0]), (1, Vec3::X));
    /// assert_eq!(odd.alpha_logits, m.alpha_logits[16..32]);
    /// ```
    pub fn rows_where(&self, keep: impl Fn(usize) -> bool) -> RawBillboards {
        let t = self.texture_size * self.texture_size;
        let rows: Vec<usize> = (0..self.len()).filter(|&i| keep(i)).collect();
        let gather = |values: &[f32], width: usize| -> Vec<f32> {
            rows.iter()
                .flat_map(|&i| values[i * width..(i + 1) * width].iter().copied())
                .collect()
        };
        RawBillboards {
            positions: rows.iter().map(|&i| self.positions[i]).collect(),
            quaternions: rows.iter().map(|&i| self.quaternions[i]).collect(),
            log_scales: rows.iter().map(|&i| self.log_scales[i]).collect(),
            sh: gather(&self.sh, SH_FLOATS),
            alpha_logits: gather(&self.alpha_logits, t),
            colour_logits: gather(&self.colour_logits, 3 * t),
            alpha_mask: self.alpha_mask.clone(),
            texture_size: self.texture_size,
        }
    }

    /// Mean activated alpha of billboard `i` over all `TS²` texels: [`mean_alpha`] of
    /// `sigmoid(logit)` on unmasked texels and 0 on masked ones. Panics if `i ≥ len()`.
    ///
    /// ```
    /// use bbsplat::model::RawBillboards;
    /// use glam::Vec3;
    /// let m = RawBillboards::from_points(&[Vec3::ZERO, Vec3::X], &[[0.5; 3]; 2], 16, 0);
    /// assert!((m.mean_alpha(0) - 0.0875).abs() < 1e-3); // the initial texture's mean
    /// assert_eq!(m.alive_count(), 2);
    /// ```
    pub fn mean_alpha(&self, i: usize) -> f32 {
        let t = self.texture_size * self.texture_size;
        assert!(i < self.len(), "billboard {i} of {}", self.len());
        let row = &self.alpha_logits[i * t..(i + 1) * t];
        mean_alpha(
            row.iter()
                .zip(&self.alpha_mask)
                .map(|(&l, &m)| if m { sigmoid(l) } else { 0.0 }),
            t,
        )
    }

    /// Billboards that are alive ([`is_alive`]: mean alpha above [`DEAD_ALPHA`]), the ones
    /// relocation would not move.
    pub fn alive_count(&self) -> usize {
        (0..self.len()).filter(|&i| is_alive(self.mean_alpha(i))).count()
    }

    /// Initialises one billboard per point (spec §1.1): alpha `0.5·G`, colour texture 0.1,
    /// SH DC `RGB2SH(colour) − 0.1`, higher SH 0, both log-scales
    /// `ln √max(d̄², 1e-7)` with `d̄²` the mean squared distance to the 3 nearest other points,
    /// rotation from 4 uniform `[0, 1)` numbers (seeded).
    ///
    /// `d̄²` comes from [`mean_sq_dist_3nn`] (k-d tree, `O(N log N)`, exact: equal bit for bit to
    /// the brute-force oracle; a single point, or a non-finite one, gets the `1e-7` floor).
    /// Deterministic for a given seed and independent of the number of threads.
    pub fn from_points(points: &[Vec3], colours: &[[f32; 3]], texture_size: usize, seed: u64) -> Self {
        assert_eq!(points.len(), colours.len(), "one colour per point");
        let n = points.len();
        let t = texture_size * texture_size;
        let alpha0 = initial_alpha(texture_size);
        let alpha_mask = standard_alpha_mask(texture_size);
        let alpha_row: Vec<f32> = alpha0.iter().map(|&a| if a > 0.0 { logit(a) } else { 0.0 }).collect();
        let mean_sq_3nn = mean_sq_dist_3nn(points);
        let mut rng = Rng::new(seed);
        let mut model = RawBillboards {
            positions: points.to_vec(),
            quaternions: Vec::with_capacity(n),
            log_scales: Vec::with_capacity(n),
            sh: vec![0.0; n * SH_FLOATS],
            alpha_logits: crate::memory::with_capacity(n * t),
            colour_logits: crate::memory::filled(n * 3 * t, logit(0.1)),
            alpha_mask,
            texture_size,
        };
        for i in 0..n {
            model
                .quaternions
                .push([rng.uniform(), rng.uniform(), rng.uniform(), rng.uniform()]);
            model.log_scales.push(Vec2::splat(mean_sq_3nn[i].max(1e-7).sqrt().ln()));
            for c in 0..3 {
                model.sh[i * SH_FLOATS + c] = rgb_to_sh(colours[i][c]) - 0.1;
            }
            model.alpha_logits.extend_from_slice(&alpha_row);
        }
        model
    }

    /// The raw form of activated billboards (e.g. a generated scene to train on): texture logits
    /// by [`clamped_logit`], no texel masked, geometry and SH copied. `activate` of the result
    /// gives back the textures within the clamp (values in `[1e-6, 1 − 1e-6]` exactly up to
    /// float rounding).
    pub fn from_activated(b: &ActivatedBillboards) -> Self {
        let t = b.texture_size * b.texture_size;
        let mut alpha_logits = crate::memory::with_capacity(b.textures.len());
        let mut colour_logits = crate::memory::with_capacity(3 * b.textures.len());
        for row in b.textures.chunks_exact(t.max(1)) {
            alpha_logits.extend(row.iter().map(|texel| clamped_logit(texel[3])));
            for c in 0..3 {
                colour_logits.extend(row.iter().map(|texel| clamped_logit(texel[c])));
            }
        }
        RawBillboards {
            positions: b.positions.clone(),
            quaternions: b.quaternions.clone(),
            log_scales: b.log_scales.clone(),
            sh: b.sh.clone(),
            alpha_logits,
            colour_logits,
            alpha_mask: vec![true; t],
            texture_size: b.texture_size,
        }
    }

    /// Activated textures and geometry in the layout of the rasterizer: the planar alpha and
    /// colour logits become interleaved RGBA texels `[sigmoid(r), sigmoid(g), sigmoid(b),
    /// sigmoid(alpha)]` (masked alpha texels 0).
    pub fn activate(&self) -> ActivatedBillboards {
        let mut b = ActivatedBillboards {
            positions: self.positions.clone(),
            quaternions: self.quaternions.clone(),
            log_scales: self.log_scales.clone(),
            sh: self.sh.clone(),
            textures: crate::memory::filled(self.alpha_logits.len(), [0.0; 4]),
            texture_size: self.texture_size,
        };
        for i in 0..self.len() {
            self.activate_row(i, &mut b);
        }
        b
    }

    /// Refreshes billboard `i` of `out` (geometry, SH and activated textures) from the model.
    pub fn activate_row(&self, i: usize, out: &mut ActivatedBillboards) {
        let t = self.texture_size * self.texture_size;
        out.positions[i] = self.positions[i];
        out.quaternions[i] = self.quaternions[i];
        out.log_scales[i] = self.log_scales[i];
        out.sh[i * SH_FLOATS..(i + 1) * SH_FLOATS].copy_from_slice(&self.sh[i * SH_FLOATS..(i + 1) * SH_FLOATS]);
        let colour = &self.colour_logits[i * 3 * t..(i + 1) * 3 * t];
        for (k, texel) in out.textures[i * t..(i + 1) * t].iter_mut().enumerate() {
            *texel = [
                sigmoid(colour[k]),
                sigmoid(colour[t + k]),
                sigmoid(colour[2 * t + k]),
                if self.alpha_mask[k] {
                    sigmoid(self.alpha_logits[i * t + k])
                } else {
                    0.0
                },
            ];
        }
    }
}
