//! Structural similarity (SSIM) as Inria 3DGS and BBSplat train and evaluate with it, and its
//! analytic gradient with respect to the first image.
//!
//! # Definition
//!
//! Per channel, with `G` the 11×11 Gaussian window (σ = 1.5, normalised to sum 1; separable,
//! the outer product of the normalised 1-D window [`gaussian_window`]) and `*` the 2-D
//! correlation with zero padding:
//!
//! ```text
//! μa = G*a   μb = G*b   σa² = G*(a²) − μa²   σb² = G*(b²) − μb²   σab = G*(a·b) − μa·μb
//! S  = (2·μa·μb + C1)·(2·σab + C2) / ((μa² + μb² + C1)·(σa² + σb² + C2)),  C1 = 0.01², C2 = 0.03²
//! ```
//!
//! and `SSIM` is the mean of the map `S` over all map pixels and channels. The constants assume
//! a data range of 1.
//!
//! # Padding (the border)
//!
//! - [`Padding::Same`] (reference, Inria `conv2d(padding = 5)`): the map has one value per
//!   image pixel, windows reaching past the border see zeros there. Near the border the
//!   window mass inside the image is below 1, which lowers μ and inflates σ² (zeros look like
//!   structure), so border values are not those of a cropped image.
//! - [`Padding::Valid`] (gsplat's fused SSIM): only the `(w − 10) × (h − 10)` positions whose
//!   window lies inside the image. Its values equal the interior of the "same" map bit for bit.
//!   Needs `w, h ≥ 11`.
//!
//! # Gradient
//!
//! With `D = B1·B2`, `A1 = 2μaμb + C1`, `A2 = 2σab + C2`, `B1 = μa² + μb² + C1`,
//! `B2 = σa² + σb² + C2` and the raw moments `Saa = G*(a²)`, `Sab = G*(a·b)`, the partials of
//! one map value (with `b` constant) are
//!
//! ```text
//! ∂S/∂μa  = 2μb·(A2 − A1)/D − 2μa·S·(1/B1 − 1/B2)
//! ∂S/∂Saa = −S/B2
//! ∂S/∂Sab = 2·A1/D
//! ```
//!
//! and the gradient for a map cotangent `ω` is `Gᵀ*(ω·∂S/∂μa) + 2a·Gᵀ*(ω·∂S/∂Saa) +
//! b·Gᵀ*(ω·∂S/∂Sab)`, where `Gᵀ*` is the adjoint of the padded correlation (the same symmetric
//! window, shifted back for "valid"). For the mean, `ω = d_ssim / (number of map values)`.
//!
//! # Precision
//!
//! Inputs and gradients are f32, but the moments, the map values and the backward are computed
//! in **f64**. The variance `G*(a²) − μa²` cancels catastrophically where the image is flat: in
//! f32 the error of the difference is ~1e-7 against `σ² + C2 ≈ 1e-3`, which makes the map
//! wrong by up to ~1e-4 relative (enough to hide or fake gradient errors in a finite-difference
//! check), while in f64 it is ~1e-13 (measured: map within 3e-8 of a direct f64 reference,
//! i.e. the f32 rounding of the output).
//!
//! The training loss runs the same passes in f32 ([`ssim_with_grad_f32`], twice the vector
//! lanes: the training loss at 400×400×3 takes about half its f64 time), as the reference's
//! PyTorch code does. Every pass and formula is one generic copy over the precision, so the
//! f32 path is the code the finite-difference tests prove, run in f32 arithmetic; its distance
//! from the f64 path is measured and bounded in the tests (gradient relative L2 about 5e-5 on
//! render-like images, 3e-4 on a flat grey image).
//!
//! # Cost and determinism
//!
//! Two 11-tap 1-D passes per moment (5 moments forward, 3 backward), i.e. `O(pixels·11)` per
//! map. The forward works one map row at a time (the vertical pass over the products formed on
//! the fly, then the horizontal pass), in parallel over rows with rayon, and keeps only the
//! three weighted partial maps for the backward (24 bytes per map value); the backward again
//! works one image row at a time. Each pass keeps a chunk of outputs in registers while it
//! walks the taps (no read-modify-write of a row per tap), and the partials of a row are
//! computed in a loop of their own, apart from the in-order sum of the row's values, so that
//! they run in vector lanes. The partial maps' storage is kept per calling thread from one call
//! to the next (11.5 MB at 400×400×3), so that a training loop neither allocates nor zeroes it
//! every step (every value is written before it is read). Every output value is accumulated by one thread in a fixed
//! tap order and the mean is summed in f64 per row and then over rows in order, so results are
//! identical for any number of threads.
//!
//! ```
//! use bbsplat::loss::ssim::{Padding, ssim, ssim_vjp};
//! let (w, h, c) = (12, 11, 3);
//! let a: Vec<f32> = (0..w * h * c).map(|i| ((i * 37) % 101) as f32 / 100.0).collect();
//! assert!((ssim(&a, &a, w, h, c, Padding::Same).unwrap() - 1.0).abs() < 1e-12);
//! let b: Vec<f32> = a.iter().map(|v| 1.0 - v).collect();
//! let s = ssim(&a, &b, w, h, c, Padding::Valid).unwrap();
//! assert!(s < 0.0); // anti-correlated
//! let g = ssim_vjp(&a, &b, w, h, c, Padding::Valid, 1.0).unwrap();
//! assert_eq!(g.len(), a.len());
//! ```

use super::LossError;
use crate::cpu::Simd;
use rayon::prelude::*;
use std::ops::{Add, Div, Mul, Neg, Sub};

/// The arithmetic the SSIM passes run in: f64 (the reference, [`ssim_with_grad`] and the other
/// public functions) or f32 ([`ssim_with_grad_f32`], twice the vector lanes). One generic copy
/// of every pass and formula serves both, so the f32 path is the proven code run in another
/// precision.
pub(crate) trait Real:
    Copy
    + Send
    + Sync
    + 'static
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
{
    const ZERO: Self;
    const ONE: Self;
    const TWO: Self;
    /// [`C1`] and [`C2`] in this precision.
    const C1: Self;
    const C2: Self;
    fn of_f32(x: f32) -> Self;
    fn of_f64(x: f64) -> Self;
    fn to_f32(self) -> f32;
    fn to_f64(self) -> f64;
    /// The partial-map storage of this precision in `scratch` (see [`value_and_grad`]).
    fn partial_maps(scratch: &mut SsimScratch) -> &mut Vec<Self>;
}

impl Real for f64 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    const TWO: Self = 2.0;
    const C1: Self = C1;
    const C2: Self = C2;
    #[inline(always)]
    fn of_f32(x: f32) -> Self {
        x as f64
    }
    #[inline(always)]
    fn of_f64(x: f64) -> Self {
        x
    }
    #[inline(always)]
    fn to_f32(self) -> f32 {
        self as f32
    }
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self
    }
    fn partial_maps(scratch: &mut SsimScratch) -> &mut Vec<Self> {
        &mut scratch.maps_f64
    }
}

impl Real for f32 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    const TWO: Self = 2.0;
    const C1: Self = C1 as f32;
    const C2: Self = C2 as f32;
    #[inline(always)]
    fn of_f32(x: f32) -> Self {
        x
    }
    #[inline(always)]
    fn of_f64(x: f64) -> Self {
        x as f32
    }
    #[inline(always)]
    fn to_f32(self) -> f32 {
        self
    }
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self as f64
    }
    fn partial_maps(scratch: &mut SsimScratch) -> &mut Vec<Self> {
        &mut scratch.maps_f32
    }
}

/// Side of the square window.
pub const WINDOW_SIZE: usize = 11;
/// Half side of the window: the "same" zero padding width.
pub const RADIUS: usize = 5;
/// Standard deviation of the Gaussian window in pixels.
pub const SIGMA: f64 = 1.5;
/// Luminance stabiliser `(0.01·L)²` for data range `L = 1`.
pub const C1: f64 = 0.01 * 0.01;
/// Contrast stabiliser `(0.03·L)²` for data range `L = 1`.
pub const C2: f64 = 0.03 * 0.03;

/// The arithmetic of the SSIM passes (see [`ssim_with_grad_f32`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Precision {
    /// f64: the reference, whose gradient the finite-difference tests prove.
    F64,
    /// f32: the same code in f32 arithmetic, twice the vector lanes; within a measured bound
    /// of [`Precision::F64`].
    #[default]
    F32,
}

/// How windows at the image border are handled (see the [module documentation](self)).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Padding {
    /// Zero padding of 5 pixels: one map value per pixel (reference, the default).
    #[default]
    Same,
    /// No padding: only windows fully inside the image, `(w − 10) × (h − 10)` map values.
    Valid,
}

/// How the SSIM gradient passes run: the padding of the map, and the instruction set of their
/// lane-wise loops (the same bits whatever it is; only the speed differs). A [`Padding`] alone
/// converts to it with the widest instruction set the CPU runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct SsimOptions {
    /// How windows at the border are handled.
    pub padding: Padding,
    /// The instruction set ([`Simd::detect`] by default).
    pub simd: Simd,
}

impl From<Padding> for SsimOptions {
    fn from(padding: Padding) -> Self {
        Self {
            padding,
            simd: Simd::detect(),
        }
    }
}

/// Storage for the SSIM gradient's weighted partial maps, owned by the caller and kept from
/// call to call ([`ssim_with_grad_in`]): 24 bytes per map value in f64 (11.5 MB at 400×400×3),
/// 12 in f32. Its contents never affect a result: every value is written before it is read.
#[derive(Clone, Debug, Default)]
pub struct SsimScratch {
    maps_f64: Vec<f64>,
    maps_f32: Vec<f32>,
}

/// The normalised 1-D Gaussian window: `exp(−(k − 5)²/(2σ²))` for `k in 0..11`, divided by
/// its sum, in f64. The 2-D window is its outer product.
pub fn gaussian_window() -> [f64; WINDOW_SIZE] {
    let raw: [f64; WINDOW_SIZE] = std::array::from_fn(|k| {
        let d = k as f64 - RADIUS as f64;
        (-d * d / (2.0 * SIGMA * SIGMA)).exp()
    });
    let sum: f64 = raw.iter().sum();
    raw.map(|v| v / sum)
}

/// Size `(width, height)` of the SSIM map of a `width × height` image.
///
/// # Errors
///
/// [`LossError::Empty`] for a zero size, [`LossError::TooSmallForValid`] for "valid" padding on
/// an image smaller than 11×11.
pub fn map_size(width: usize, height: usize, padding: Padding) -> Result<(usize, usize), LossError> {
    Ok(Geometry::new(width, height, 1, padding)?.map_dims())
}

/// Mean SSIM of `a` against `b` (interleaved, row-major, `width × height × channels`).
///
/// # Errors
///
/// [`LossError`] if a buffer does not hold `width·height·channels` values, the image is empty,
/// or it is smaller than 11×11 with "valid" padding.
pub fn ssim(
    a: &[f32],
    b: &[f32],
    width: usize,
    height: usize,
    channels: usize,
    padding: Padding,
) -> Result<f64, LossError> {
    let geo = Geometry::new(width, height, channels, padding)?;
    geo.check(a, b)?;
    let row_sums: Vec<f64> = (0..geo.oh)
        .into_par_iter()
        .map_init(
            || Scratch::<f64>::new(&geo),
            |scratch, oy| {
                let [ma, mb, saa, sbb, sab] = scratch.row_moments(a, b, &geo, oy);
                (0..geo.out_row())
                    .map(|j| ssim_value(ma[j], mb[j], saa[j], sbb[j], sab[j]))
                    .sum::<f64>()
            },
        )
        .collect();
    Ok(row_sums.iter().sum::<f64>() / geo.map_len() as f64)
}

/// The SSIM map: `map_width × map_height × channels` values, interleaved and row-major like
/// the images (map size from [`map_size`]).
///
/// # Errors
///
/// As [`ssim`].
pub fn ssim_map(
    a: &[f32],
    b: &[f32],
    width: usize,
    height: usize,
    channels: usize,
    padding: Padding,
) -> Result<Vec<f32>, LossError> {
    let geo = Geometry::new(width, height, channels, padding)?;
    geo.check(a, b)?;
    let mut map = vec![0.0f32; geo.map_len()];
    map.par_chunks_mut(geo.out_row()).enumerate().for_each_init(
        || Scratch::<f64>::new(&geo),
        |scratch, (oy, row)| {
            let [ma, mb, saa, sbb, sab] = scratch.row_moments(a, b, &geo, oy);
            for (j, s) in row.iter_mut().enumerate() {
                *s = ssim_value(ma[j], mb[j], saa[j], sbb[j], sab[j]) as f32;
            }
        },
    );
    Ok(map)
}

/// `d_ssim · ∂SSIM/∂a`: the gradient of the mean SSIM with respect to `a`, scaled by the
/// upstream derivative `d_ssim` of the (f64) scalar SSIM (`b` is constant). Same layout as `a`.
///
/// # Errors
///
/// As [`ssim`].
pub fn ssim_vjp(
    a: &[f32],
    b: &[f32],
    width: usize,
    height: usize,
    channels: usize,
    options: impl Into<SsimOptions>,
    d_ssim: f64,
) -> Result<Vec<f32>, LossError> {
    Ok(ssim_with_grad(a, b, width, height, channels, options, d_ssim)?.1)
}

/// The mean SSIM and `d_ssim · ∂SSIM/∂a` in one pass (the forward work is shared).
///
/// # Errors
///
/// As [`ssim`].
pub fn ssim_with_grad(
    a: &[f32],
    b: &[f32],
    width: usize,
    height: usize,
    channels: usize,
    options: impl Into<SsimOptions>,
    d_ssim: f64,
) -> Result<(f64, Vec<f32>), LossError> {
    let scratch = &mut SsimScratch::default();
    ssim_with_grad_in(
        a,
        b,
        (width, height, channels),
        options.into(),
        d_ssim,
        Precision::F64,
        scratch,
    )
}

/// [`ssim_with_grad`] computed in f32 instead of f64: the same passes and formulas (one generic
/// copy), in twice as many vector lanes, as the reference's PyTorch code computes them. The
/// training loss uses it ([`super::Precision::F32`], the default). Each map value is still
/// summed into the mean in f64, and the results are the same for any thread count and on
/// either instruction set.
///
/// The variance `G*(a²) − μa²` loses f32 digits where the image is flat (see the [module
/// documentation](self)), so the values are not those of [`ssim_with_grad`]: on 400×400 renders
/// and targets the SSIM differs by a few 1e-7 and the gradient's relative L2 distance is about
/// 5e-5 (bounds measured and asserted in `tests/suite/loss_ssim.rs`, figures in
/// `docs/numerics-init-loss.md`).
///
/// # Errors
///
/// As [`ssim`].
pub fn ssim_with_grad_f32(
    a: &[f32],
    b: &[f32],
    width: usize,
    height: usize,
    channels: usize,
    options: impl Into<SsimOptions>,
    d_ssim: f64,
) -> Result<(f64, Vec<f32>), LossError> {
    let scratch = &mut SsimScratch::default();
    ssim_with_grad_in(
        a,
        b,
        (width, height, channels),
        options.into(),
        d_ssim,
        Precision::F32,
        scratch,
    )
}

/// The mean SSIM and its gradient scaled by `d_ssim` ([`ssim_with_grad`] in
/// [`Precision::F64`], [`ssim_with_grad_f32`] in [`Precision::F32`]) of `(width, height,
/// channels)` images, with the partial maps in the caller's `scratch` (no allocation of them
/// once it has held an image this size).
///
/// # Errors
///
/// As [`ssim`].
pub fn ssim_with_grad_in(
    a: &[f32],
    b: &[f32],
    (width, height, channels): (usize, usize, usize),
    options: SsimOptions,
    d_ssim: f64,
    precision: Precision,
    scratch: &mut SsimScratch,
) -> Result<(f64, Vec<f32>), LossError> {
    let geo = Geometry::new(width, height, channels, options.padding)?;
    geo.check(a, b)?;
    let weight = d_ssim / geo.map_len() as f64;
    let pass = Pass {
        cot: Cotangent::Uniform(weight),
        simd: options.simd,
    };
    let (sum, grad) = match precision {
        Precision::F64 => value_and_grad(a, b, &geo, pass, ssim_partials::<f64>, f64::partial_maps(scratch)),
        Precision::F32 => value_and_grad(a, b, &geo, pass, ssim_partials::<f32>, f32::partial_maps(scratch)),
    };
    Ok((sum / geo.map_len() as f64, grad))
}

/// The vector-Jacobian product of [`ssim_map`]: `Σ_p d_map[p]·∂S_p/∂a`, for a cotangent
/// `d_map` with the map's layout and size.
///
/// # Errors
///
/// As [`ssim`], and [`LossError::BadLength`] if `d_map` does not match the map size.
pub fn ssim_map_vjp(
    a: &[f32],
    b: &[f32],
    width: usize,
    height: usize,
    channels: usize,
    options: impl Into<SsimOptions>,
    d_map: &[f32],
) -> Result<Vec<f32>, LossError> {
    let options = options.into();
    let geo = Geometry::new(width, height, channels, options.padding)?;
    geo.check(a, b)?;
    if d_map.len() != geo.map_len() {
        return Err(LossError::BadLength {
            which: "d_map",
            expected: geo.map_len(),
            got: d_map.len(),
        });
    }
    let pass = Pass {
        cot: Cotangent::Map(d_map),
        simd: options.simd,
    };
    let maps = &mut Vec::new();
    Ok(value_and_grad(a, b, &geo, pass, ssim_partials::<f64>, maps).1)
}

/// Number of moment maps: μa, μb, G*(a²), G*(b²), G*(a·b).
const MOMENTS: usize = 5;
/// Number of backward maps: ∂/∂μa, ∂/∂Saa, ∂/∂Sab.
const PARTIALS: usize = 3;

/// Image and map dimensions for one call.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Geometry {
    w: usize,
    h: usize,
    c: usize,
    /// Map width and height.
    ow: usize,
    oh: usize,
    /// Map pixel `i` is centred on image pixel `i + off` (0 for "same", 5 for "valid").
    off: isize,
    g: [f64; WINDOW_SIZE],
}

impl Geometry {
    pub(crate) fn new(w: usize, h: usize, c: usize, padding: Padding) -> Result<Self, LossError> {
        if w == 0 || h == 0 || c == 0 {
            return Err(LossError::Empty {
                width: w,
                height: h,
                channels: c,
            });
        }
        let (ow, oh, off) = match padding {
            Padding::Same => (w, h, 0),
            Padding::Valid => {
                if w < WINDOW_SIZE || h < WINDOW_SIZE {
                    return Err(LossError::TooSmallForValid { width: w, height: h });
                }
                (w - 2 * RADIUS, h - 2 * RADIUS, RADIUS as isize)
            }
        };
        Ok(Self {
            w,
            h,
            c,
            ow,
            oh,
            off,
            g: gaussian_window(),
        })
    }

    fn check(&self, a: &[f32], b: &[f32]) -> Result<(), LossError> {
        let expected = self.w * self.h * self.c;
        for (which, buf) in [("a", a), ("b", b)] {
            if buf.len() != expected {
                return Err(LossError::BadLength {
                    which,
                    expected,
                    got: buf.len(),
                });
            }
        }
        Ok(())
    }

    fn map_dims(&self) -> (usize, usize) {
        (self.ow, self.oh)
    }

    /// Values per image row.
    fn in_row(&self) -> usize {
        self.w * self.c
    }

    /// Values per map row.
    fn out_row(&self) -> usize {
        self.ow * self.c
    }

    pub(crate) fn map_len(&self) -> usize {
        self.ow * self.oh * self.c
    }

    /// The window [`gaussian_window`] rounded to precision `R`.
    fn window<R: Real>(&self) -> [R; WINDOW_SIZE] {
        self.g.map(R::of_f64)
    }
}

/// `out[i] = Σ_k g[k]·input[i + k − 5 + off]` over pixels (each `stride` values), zero outside
/// `0..n_in`; `out` holds `n_out` pixels. Taps are added to 0 in increasing `k`, skipping those
/// outside, so an output whose window is inside the image gets the same bits whatever the
/// padding. Always inlined, so that it runs in its caller's instruction-set variant.
#[inline(always)]
fn correlate_row<R: Real>(input: &[R], out: &mut [R], n_in: usize, stride: usize, off: isize, g: &[R; WINDOW_SIZE]) {
    let n_out = out.len() / stride;
    let r = RADIUS as isize;
    // Output pixels lo..hi have all 11 taps inside 0..n_in.
    let lo = (r - off).clamp(0, n_out as isize) as usize;
    let hi = (n_in as isize - r - off).clamp(lo as isize, n_out as isize) as usize;
    for i in (0..lo).chain(hi..n_out) {
        for ch in 0..stride {
            let mut acc = R::ZERO;
            for (k, &gk) in g.iter().enumerate() {
                let x = i as isize + k as isize - r + off;
                if x >= 0 && x < n_in as isize {
                    acc = acc + gk * input[x as usize * stride + ch];
                }
            }
            out[i * stride + ch] = acc;
        }
    }
    if hi > lo {
        let len = (hi - lo) * stride;
        let start = (lo as isize + off - r) as usize * stride;
        let taps: [&[R]; WINDOW_SIZE] = std::array::from_fn(|k| &input[start + k * stride..][..len]);
        tap_sums(&taps, g, &mut out[lo * stride..hi * stride]);
    }
}

/// Per-thread buffers for one map row of moments.
struct Scratch<R> {
    /// The vertical pass of a, b, a², b², a·b: five image-width rows.
    vertical: Vec<R>,
    /// The five moment rows of the map: μa, μb, Saa, Sbb, Sab.
    moments: Vec<R>,
    /// The window in this precision.
    g: [R; WINDOW_SIZE],
}

impl<R: Real> Scratch<R> {
    fn new(geo: &Geometry) -> Self {
        Self {
            vertical: vec![R::ZERO; MOMENTS * geo.in_row()],
            moments: vec![R::ZERO; MOMENTS * geo.out_row()],
            g: geo.window(),
        }
    }

    /// The five moments of map row `oy`: the vertical pass over the products (formed on the
    /// fly; in f64 the products of f32 values are exact), then the horizontal pass.
    #[inline(always)]
    fn row_moments(&mut self, a: &[f32], b: &[f32], geo: &Geometry, oy: usize) -> [&[R]; MOMENTS] {
        let lin = geo.in_row();
        let (ks, y0) = window_rows(oy, geo.off, geo.h);
        let rows_a = window_slices(a, y0, ks.len(), lin);
        let rows_b = window_slices(b, y0, ks.len(), lin);
        let taps = &self.g[ks.clone()];
        let mut vertical = split5_mut(&mut self.vertical, lin);
        let full = lin - lin % MOMENT_CHUNK;
        for j in (0..full).step_by(MOMENT_CHUNK) {
            moment_sums::<R, MOMENT_CHUNK>((&rows_a, &rows_b), taps, j, &mut vertical);
        }
        for j in full..lin {
            moment_sums::<R, 1>((&rows_a, &rows_b), taps, j, &mut vertical);
        }
        let lout = geo.out_row();
        for (src, dst) in self.vertical.chunks(lin).zip(self.moments.chunks_mut(lout)) {
            correlate_row(src, dst, geo.w, geo.c, geo.off, &self.g);
        }
        split5(&self.moments, lout)
    }
}

/// `out[m] = Σ_k g[k]·rows[oy + k − 5 + off][m]` for each of the `maps` interleaved maps of a
/// buffer laid out `[row][map][len]` with `n_rows` rows; rows outside are zero. Each output is
/// summed in registers from 0 in increasing `k`, skipping the rows outside.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn vertical_pass<R: Real>(
    rows: &[R],
    maps: usize,
    len: usize,
    n_rows: usize,
    oy: usize,
    off: isize,
    g: &[R; WINDOW_SIZE],
    out: &mut [R],
) {
    let width = maps * len;
    let (ks, y0) = window_rows(oy, off, n_rows);
    let src = window_slices(rows, y0, ks.len(), width);
    let taps = &g[ks];
    tap_sums(&src[..taps.len()], taps, out);
}

/// `out[j] = Σ_t taps[t]·rows[t][j]`, each output summed from 0 in increasing `t`, sixteen
/// outputs at a time in registers. Every row holds at least `out.len()` values.
#[inline(always)]
fn tap_sums<R: Real>(rows: &[&[R]], taps: &[R], out: &mut [R]) {
    let full = out.len() - out.len() % TAP_CHUNK;
    let (chunks, tail) = out.split_at_mut(full);
    for (j, dst) in (0..full).step_by(TAP_CHUNK).zip(chunks.chunks_exact_mut(TAP_CHUNK)) {
        tap_chunk::<R, TAP_CHUNK>(rows, taps, j, dst);
    }
    for (j, dst) in (full..).zip(tail.chunks_exact_mut(1)) {
        tap_chunk::<R, 1>(rows, taps, j, dst);
    }
}

/// `dst[l] = Σ_t taps[t]·rows[t][j + l]` for the `N` outputs from `j`, summed in registers (the
/// one copy of [`tap_sums`]' arithmetic, for its chunks and its tail).
#[inline(always)]
fn tap_chunk<R: Real, const N: usize>(rows: &[&[R]], taps: &[R], j: usize, dst: &mut [R]) {
    let mut sum = [R::ZERO; N];
    for (row, &gk) in rows.iter().zip(taps) {
        let x: &[R; N] = row[j..j + N].try_into().expect("chunk");
        for l in 0..N {
            sum[l] = sum[l] + gk * x[l];
        }
    }
    dst.copy_from_slice(&sum);
}

/// The five vertical moment sums (`a`, `b`, `a²`, `b²`, `a·b`, products in `R`) of the `N`
/// columns from `j`, each summed in registers from 0 in tap order, written into the five rows
/// of `out` (the one copy of this arithmetic, for the chunks and the tail of a row).
#[inline(always)]
fn moment_sums<R: Real, const N: usize>(
    (rows_a, rows_b): (&[&[f32]; WINDOW_SIZE], &[&[f32]; WINDOW_SIZE]),
    taps: &[R],
    j: usize,
    out: &mut [&mut [R]; MOMENTS],
) {
    let mut sums = [[R::ZERO; N]; MOMENTS];
    for (t, &gk) in taps.iter().enumerate() {
        let ra: &[f32; N] = rows_a[t][j..j + N].try_into().expect("chunk");
        let rb: &[f32; N] = rows_b[t][j..j + N].try_into().expect("chunk");
        for l in 0..N {
            let (x, z) = (R::of_f32(ra[l]), R::of_f32(rb[l]));
            sums[0][l] = sums[0][l] + gk * x;
            sums[1][l] = sums[1][l] + gk * z;
            sums[2][l] = sums[2][l] + gk * (x * x);
            sums[3][l] = sums[3][l] + gk * (z * z);
            sums[4][l] = sums[4][l] + gk * (x * z);
        }
    }
    for (dst, sum) in out.iter_mut().zip(&sums) {
        dst[j..j + N].copy_from_slice(sum);
    }
}

/// Values per register chunk of the moments' vertical pass (five sums each).
const MOMENT_CHUNK: usize = 8;
/// Values per register chunk of [`tap_sums`].
const TAP_CHUNK: usize = 16;

/// The taps `k` of the window around output row `oy` whose rows `oy + k − 5 + off` lie in
/// `0..n_rows`, and the row of the first of them.
#[inline(always)]
fn window_rows(oy: usize, off: isize, n_rows: usize) -> (std::ops::Range<usize>, usize) {
    let first = oy as isize - RADIUS as isize + off;
    let lo = (-first).clamp(0, WINDOW_SIZE as isize) as usize;
    let hi = (n_rows as isize - first).clamp(lo as isize, WINDOW_SIZE as isize) as usize;
    (lo..hi, (first + lo as isize).max(0) as usize)
}

/// The `count` consecutive rows of `width` values of `buf` from row `y0`, in the first
/// `count` slots; the other slots (window taps outside the image) are empty.
#[inline(always)]
fn window_slices<T>(buf: &[T], y0: usize, count: usize, width: usize) -> [&[T]; WINDOW_SIZE] {
    std::array::from_fn(|t| {
        if t < count {
            &buf[(y0 + t) * width..][..width]
        } else {
            &[]
        }
    })
}

fn split5<R>(buf: &[R], len: usize) -> [&[R]; MOMENTS] {
    std::array::from_fn(|m| &buf[m * len..(m + 1) * len])
}

fn split5_mut<R>(buf: &mut [R], len: usize) -> [&mut [R]; MOMENTS] {
    let mut it = buf.chunks_mut(len);
    std::array::from_fn(|_| it.next().expect("five rows"))
}

/// One SSIM map value from the five moments.
#[inline]
fn ssim_value<R: Real>(ma: R, mb: R, saa: R, sbb: R, sab: R) -> R {
    let (a1, a2, b1, b2) = terms(ma, mb, saa, sbb, sab);
    (a1 * a2) / (b1 * b2)
}

/// `(A1, A2, B1, B2)` of the SSIM formula.
#[inline]
pub(crate) fn terms<R: Real>(ma: R, mb: R, saa: R, sbb: R, sab: R) -> (R, R, R, R) {
    let (maa, mbb, mab) = (ma * ma, mb * mb, ma * mb);
    let a1 = R::TWO * mab + R::C1;
    let a2 = R::TWO * (sab - mab) + R::C2;
    let b1 = maa + mbb + R::C1;
    let b2 = (saa - maa) + (sbb - mbb) + R::C2;
    (a1, a2, b1, b2)
}

/// `[S, ∂S/∂μa, ∂S/∂Saa, ∂S/∂Sab]` for one map value.
#[inline]
pub(crate) fn ssim_partials<R: Real>(ma: R, mb: R, saa: R, sbb: R, sab: R) -> [R; 4] {
    let (a1, a2, b1, b2) = terms(ma, mb, saa, sbb, sab);
    let d = b1 * b2;
    // S exactly as `ssim_value` computes it, so forward-only and forward+backward agree.
    let s = (a1 * a2) / d;
    // One more division: 1/B1 = B2/D and 1/B2 = B1/D.
    let inv_d = R::ONE / d;
    let d_mu = R::TWO * (mb * (a2 - a1) - ma * s * (b2 - b1)) * inv_d;
    let d_saa = -s * b1 * inv_d;
    let d_sab = R::TWO * a1 * inv_d;
    [s, d_mu, d_saa, d_sab]
}

/// The cotangent of the map: one weight for all values (the mean) or one per value.
#[derive(Clone, Copy)]
pub(crate) enum Cotangent<'a> {
    Uniform(f64),
    Map(&'a [f32]),
}

/// What [`value_and_grad`] is asked: the cotangent of the map, and the instruction set.
#[derive(Clone, Copy)]
pub(crate) struct Pass<'a> {
    pub(crate) cot: Cotangent<'a>,
    pub(crate) simd: Simd,
}

/// Forward and backward in one go: returns `(Σ S over the map, ∂(Σ ω·S)/∂a)`.
///
/// `partials` computes `[S, ∂S/∂μa, ∂S/∂Saa, ∂S/∂Sab]` from the moments (a parameter so that
/// tests can inject faults); `dbuf` is the storage of the weighted partial maps (its contents
/// are overwritten).
pub(crate) fn value_and_grad<R, P>(
    a: &[f32],
    b: &[f32],
    geo: &Geometry,
    Pass { cot, simd }: Pass<'_>,
    partials: P,
    dbuf: &mut Vec<R>,
) -> (f64, Vec<f32>)
where
    R: Real,
    P: Fn(R, R, R, R, R) -> [R; 4] + Sync,
{
    let lout = geo.out_row();
    let lin = geo.in_row();

    // Per map row: the sum of S, and the three weighted partial maps.
    // Every value is written below before it is read: the caller's storage, neither zeroed nor
    // freshly allocated.
    crate::memory::resize_for_overwrite(dbuf, geo.oh * PARTIALS * lout, R::ZERO);
    let mut row_sums = vec![0.0f64; geo.oh];
    let wide = simd.avx2_fma();
    dbuf.par_chunks_mut(PARTIALS * lout)
        .zip(row_sums.par_iter_mut())
        .enumerate()
        .for_each_init(
            || (Scratch::new(geo), vec![R::ZERO; lout]),
            |scratch, (oy, (drow, sum))| {
                let row = MapRow { oy, drow, sum };
                #[cfg(target_arch = "x86_64")]
                if wide {
                    // SAFETY: `wide` is `Simd::avx2_fma`: the CPU has AVX2 and FMA.
                    unsafe { map_row_avx2(scratch, (a, b), geo, cot, &partials, row) };
                    return;
                }
                let _ = wide;
                map_row(scratch, (a, b), geo, cot, &partials, row);
            },
        );

    let dbuf: &[R] = dbuf;
    // Per image row: the adjoint of the vertical pass (map rows to image rows, shift −off),
    // the adjoint of the horizontal pass, then the chain rule through a, a², a·b.
    let mut grad = vec![0.0f32; geo.h * lin];
    grad.par_chunks_mut(lin).enumerate().for_each_init(
        || {
            (
                vec![R::ZERO; PARTIALS * lout],
                vec![R::ZERO; PARTIALS * lin],
                geo.window(),
            )
        },
        |buffers, (y, out)| {
            #[cfg(target_arch = "x86_64")]
            if wide {
                // SAFETY: `wide` is `Simd::avx2_fma`: the CPU has AVX2 and FMA.
                unsafe { grad_row_avx2(buffers, (a, b), geo, dbuf, y, out) };
                return;
            }
            grad_row(buffers, (a, b), geo, dbuf, y, out);
        },
    );
    (row_sums.iter().sum(), grad)
}

/// One map row of [`value_and_grad`]'s forward: map row `oy`, its three weighted partial rows
/// `drow` and its sum of `S`.
struct MapRow<'r, R> {
    oy: usize,
    drow: &'r mut [R],
    sum: &'r mut f64,
}

/// [`map_row`] compiled for AVX2 and FMA: f64 in four lanes instead of two, the same operations
/// (Rust fuses no multiply-add by itself), so the same bits as the baseline build
/// ([`Simd::BASELINE`] selects that one; tested in `loss_ssim`).
///
/// # Safety
/// The CPU must support AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn map_row_avx2<R, P>(
    scratch: &mut (Scratch<R>, Vec<R>),
    ab: (&[f32], &[f32]),
    geo: &Geometry,
    cot: Cotangent<'_>,
    partials: &P,
    row: MapRow<'_, R>,
) where
    R: Real,
    P: Fn(R, R, R, R, R) -> [R; 4],
{
    map_row(scratch, ab, geo, cot, partials, row);
}

/// The moments of one map row, its `S` values summed and its weighted partials.
#[inline(always)]
fn map_row<R, P>(
    scratch: &mut (Scratch<R>, Vec<R>),
    (a, b): (&[f32], &[f32]),
    geo: &Geometry,
    cot: Cotangent<'_>,
    partials: &P,
    row: MapRow<'_, R>,
) where
    R: Real,
    P: Fn(R, R, R, R, R) -> [R; 4],
{
    let MapRow { oy, drow, sum } = row;
    let lout = geo.out_row();
    let (scratch, values) = scratch;
    let [ma, mb, saa, sbb, sab] = scratch.row_moments(a, b, geo, oy);
    let (d_mu, rest) = drow.split_at_mut(lout);
    let (d_saa, d_sab) = rest.split_at_mut(lout);
    // The partials in one loop without a carried sum (so that it runs in vector lanes), then
    // the values summed in map order.
    let moments = MomentRows { ma, mb, saa, sbb, sab };
    let outputs = (d_mu, d_saa, d_sab, &mut values[..]);
    match cot {
        Cotangent::Uniform(w) => weighted_partials(moments, std::iter::repeat(R::of_f64(w)), partials, outputs),
        Cotangent::Map(m) => {
            let weights = m[oy * lout..(oy + 1) * lout].iter().map(|&w| R::of_f32(w));
            weighted_partials(moments, weights, partials, outputs);
        }
    }
    *sum = values.iter().fold(0.0f64, |acc, &s| acc + s.to_f64());
}

/// The five moment rows of one map row.
#[derive(Clone, Copy)]
struct MomentRows<'r, R> {
    ma: &'r [R],
    mb: &'r [R],
    saa: &'r [R],
    sbb: &'r [R],
    sab: &'r [R],
}

/// `S` of each map value of a row into `values`, and its three partials times the value's
/// weight into `d_mu`, `d_saa`, `d_sab`.
#[inline(always)]
fn weighted_partials<R, P, W>(
    m: MomentRows<'_, R>,
    weights: W,
    partials: &P,
    (d_mu, d_saa, d_sab, values): (&mut [R], &mut [R], &mut [R], &mut [R]),
) where
    R: Real,
    P: Fn(R, R, R, R, R) -> [R; 4],
    W: Iterator<Item = R>,
{
    let moments = m.ma.iter().zip(m.mb).zip(m.saa).zip(m.sbb).zip(m.sab);
    let outputs = d_mu
        .iter_mut()
        .zip(d_saa.iter_mut())
        .zip(d_sab.iter_mut())
        .zip(values.iter_mut());
    for (((((&ma, &mb), &saa), &sbb), &sab), ((((d_mu, d_saa), d_sab), value), w)) in moments.zip(outputs.zip(weights))
    {
        let [s, p_mu, p_saa, p_sab] = partials(ma, mb, saa, sbb, sab);
        *value = s;
        *d_mu = w * p_mu;
        *d_saa = w * p_saa;
        *d_sab = w * p_sab;
    }
}

/// [`grad_row`] compiled for AVX2 and FMA (the same bits; see [`map_row_avx2`]).
///
/// # Safety
/// The CPU must support AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn grad_row_avx2<R: Real>(
    buffers: &mut (Vec<R>, Vec<R>, [R; WINDOW_SIZE]),
    ab: (&[f32], &[f32]),
    geo: &Geometry,
    dbuf: &[R],
    y: usize,
    out: &mut [f32],
) {
    grad_row(buffers, ab, geo, dbuf, y, out);
}

/// The gradient of image row `y`: the adjoint of the vertical pass (map rows to image rows,
/// shift −off), the adjoint of the horizontal pass, then the chain rule through a, a², a·b.
#[inline(always)]
fn grad_row<R: Real>(
    (vertical, horizontal, g): &mut (Vec<R>, Vec<R>, [R; WINDOW_SIZE]),
    (a, b): (&[f32], &[f32]),
    geo: &Geometry,
    dbuf: &[R],
    y: usize,
    out: &mut [f32],
) {
    let (lout, lin) = (geo.out_row(), geo.in_row());
    vertical_pass(dbuf, PARTIALS, lout, geo.oh, y, -geo.off, g, vertical);
    for (src, dst) in vertical.chunks(lout).zip(horizontal.chunks_mut(lin)) {
        correlate_row(src, dst, geo.ow, geo.c, -geo.off, g);
    }
    let (t_mu, rest) = horizontal.split_at(lin);
    let (t_saa, t_sab) = rest.split_at(lin);
    let (ra, rb) = (&a[y * lin..(y + 1) * lin], &b[y * lin..(y + 1) * lin]);
    for j in 0..lin {
        out[j] = (t_mu[j] + R::TWO * R::of_f32(ra[j]) * t_saa[j] + R::of_f32(rb[j]) * t_sab[j]).to_f32();
    }
}
