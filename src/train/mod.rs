//! Training: one view per step, photometric loss + regularisers, analytic gradients, Adam,
//! relocation of dead billboards, checkpoints.
//!
//! What a step does ([`Trainer::step`], method: the BBSplat spec, §5-§7; details and measurements
//! in `docs/training.md`):
//! 1. draws the next view from a shuffled stack (without replacement, refilled when empty);
//! 2. renders it, evaluates `0.8·L1 + 0.2·(1 − SSIM)` and back-propagates it to every billboard;
//! 3. adds the texture regulariser of paper Eq. 9 on the view's impact `Σ α·T` with threshold σ
//!    (default 500) and the opacity regulariser `0.01 · mean alpha` ([`mod@regularise`]);
//! 4. steps Adam ([`adam`]) with the learning rates of [`learning_rates`]: dense (every billboard,
//!    PyTorch semantics, default) or row-sparse (only billboards the view touched), see
//!    [`AdamMode`];
//! 5. every [`TrainConfig::relocate_every`] steps inside the scaled window (500, 25 000)/32 000,
//!    moves dead billboards (mean alpha ≤ 0.005) onto copies of alive ones ([`relocate`]).
//!
//! All milestones scale with [`TrainConfig::iterations`] (the reference's 32 000 = 100 %): the SH
//! degree rises every 1/32 of the run, textures train in [500, 30 000)/32 000, and after
//! 30 000/32 000 only SH rest and (at the final rate) positions keep moving.
//! [`TextureMode::Gaussian`] replaces the learned textures with one opacity per billboard times
//! the fixed initial Gaussian (the "textures off" ablation). [`checkpoint`] saves and restores the
//! whole state bit for bit. Every step checks its loss, gradients and parameters for NaN and
//! infinities ([`finite`], [`TrainError::NonFinite`]). [`TrainConfig::clamp_gradient`] chooses the
//! backward pass through the compositing clamp. [`run()`] is the whole run around the steps
//! (evaluations, checkpoints, stop requests, final save and summary). Everything is
//! deterministic for any thread count.

pub mod adam;
pub mod camera_fit;
pub mod checkpoint;
pub mod depth_sweep;
pub mod error;
pub mod finite;
pub mod footprint;
pub mod geometry;
pub mod grow;
pub mod lazy_adam;
pub mod place;
pub mod regularise;
pub mod relocate;
pub mod resolution;
pub mod row_sums;
pub mod run;
pub mod run_record;
pub mod run_time;
pub mod street;
pub mod texture_step;
pub mod time_budget;
pub mod trained_like_case;
pub mod view_pixels;

use crate::billboards::ActivatedBillboards;
use crate::camera::Camera;
use crate::cpu::Simd;
use crate::loss::TrainingLoss;
use crate::loss::psnr::psnr_u8;
use crate::loss::ssim::SsimScratch;
use crate::model::{RawBillboards, clamped_logit, initial_alpha, logit, sigmoid};
use crate::raster::preprocess::kept_rows_into;
use crate::raster::{
    BackwardScratch, RenderBuffers, RenderGradients, RenderOutput, RenderSettings, SH_FLOATS, render_backward_with,
    render_with,
};
use crate::rng::Rng;
use crate::scene::ViewImage;
pub use crate::stages::composite::ClampGradient;
use adam::{AdamGroup, AdamParams, StepFactors, update_row_with};
pub use checkpoint::CheckpointError;
pub use error::TrainError;
pub use finite::{NonFinite, ParamGroup};
use geometry::GeometryLoss;
use glam::Vec3;
use regularise::{RegulariserValues, RowGradient, TextureTerm, gaussian_opacity_grad, regularise, regulariser_rows_of};
use relocate::{apply_relocation, plan_relocation, split_alpha_logit};
pub use run::{
    RunConfig, RunError, RunOutcome, RunWarning, SnapshotRequest, StepClock, StopReason, StopSignal, TrainEvent, run,
};
use serde::{Deserialize, Serialize};
pub use view_pixels::{OnDemandPixels, ViewPixels};

/// A posed image: camera and interleaved RGB values (8-bit or float, [`ViewPixels`]).
#[derive(Clone, Debug)]
pub struct TrainView {
    /// The camera.
    pub camera: Camera,
    /// `width · height · 3` values.
    pub rgb: ViewPixels,
    /// A mask weighting the loss per pixel (`width · height` values, 255 = keep, 0 = leave out;
    /// [`crate::loss::masked`]), when the scene's masks are used that way
    /// ([`crate::scene::mask::MaskMode::Weight`], [`TrainView::with_loss_mask`]); `None`: every
    /// pixel counts fully.
    pub loss_mask: Option<Vec<u8>>,
}

/// A view's camera and float values, fetched for a depth sweep ([`Trainer::place_on_error`]).
struct FetchedView<'a> {
    camera: Camera,
    rgb: std::borrow::Cow<'a, [f32]>,
}

impl depth_sweep::SweepImage for FetchedView<'_> {
    fn camera(&self) -> &Camera {
        &self.camera
    }
    fn rgb(&self, x: u32, y: u32) -> [f32; 3] {
        let i = 3 * (y as usize * self.camera.width as usize + x as usize);
        [self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]
    }
}

impl TrainView {
    /// A loaded scene view (its background-composited image), kept as its 8-bit values, or on
    /// demand when the scene is ([`crate::scene::on_demand`]).
    pub fn from_view(view: &crate::scene::View) -> Self {
        Self {
            camera: view.camera,
            rgb: match &view.image {
                ViewImage::InMemory(image) => ViewPixels::U8(image.as_bytes().to_vec()),
                ViewImage::OnDemand(image) => ViewPixels::OnDemand(OnDemandPixels::new(image.clone())),
            },
            loss_mask: None,
        }
    }

    /// [`TrainView::from_view`] taking the view's image instead of copying it (the 8-bit
    /// values move; nothing is allocated).
    pub fn from_owned_view(view: crate::scene::View) -> Self {
        Self {
            camera: view.camera,
            rgb: match view.image {
                ViewImage::InMemory(image) => ViewPixels::U8(image.into_bytes()),
                ViewImage::OnDemand(image) => ViewPixels::OnDemand(OnDemandPixels::new(image)),
            },
            loss_mask: None,
        }
    }

    /// [`TrainView::from_view`] of each view, e.g. `TrainView::from_views(&scene.train)`.
    pub fn from_views(views: &[crate::scene::View]) -> Vec<Self> {
        views.iter().map(Self::from_view).collect()
    }

    /// This view with `mask` weighting its loss ([`TrainView::loss_mask`]): what training does
    /// with a scene loaded with [`crate::scene::mask::MaskMode::Weight`], e.g.
    /// `TrainView::from_view(&view).with_loss_mask(view.mask.clone())`. `None` leaves every
    /// pixel weighted fully.
    pub fn with_loss_mask(self, mask: Option<Vec<u8>>) -> Self {
        Self {
            loss_mask: mask,
            ..self
        }
    }

    /// A view of the embedded demo scene ([`crate::demo`], feature `tools`).
    #[cfg(feature = "tools")]
    pub fn from_demo(view: &crate::demo::DemoView) -> Self {
        Self {
            camera: view.camera,
            rgb: view.rgb.clone().into(),
            loss_mask: None,
        }
    }
}

/// How the optimiser treats billboards that received no gradient from the step's view.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum AdamMode {
    /// Every billboard steps every iteration with PyTorch Adam semantics (global step count,
    /// moments of unseen rows decay and keep moving them). The opacity regulariser reaches every
    /// billboard. This is what the reference does. Default (chosen by measurement, see
    /// `docs/training.md`).
    #[default]
    Dense,
    /// Only billboards touched by the step's view are updated, with per-row bias correction;
    /// the opacity regulariser's gradient on unseen billboards is dropped.
    Sparse,
    /// Dense Adam whose texture rows step only when the view can see them ([`lazy_adam`]): a
    /// texture row the view does not see is left as it is, and its zero-gradient steps are
    /// applied in one closed-form move when a view next sees it (or before relocation, growth,
    /// the texture freeze, an export or an evaluation), so that the optimiser's cost follows the
    /// rows a view touches. Geometry and SH step densely, as in [`AdamMode::Dense`]. The same
    /// result as dense Adam up to rounding and Adam's ε, except one thing: the opacity
    /// regulariser's gradient reaches only the billboards the view sees (dense: every
    /// billboard), and its value is summed over them. In [`TextureMode::Gaussian`] (no texture
    /// rows) the same as [`AdamMode::Dense`].
    Lazy,
}

/// What the alpha and colour textures are allowed to be (the "textures on vs off" ablation).
///
/// Its text form ([`TextureMode::as_str`], `Display`, `FromStr`, serde) is `full` or
/// `gaussian`: the value of `bbsplat train --texture-mode` and of a sweep grid's `texture_mode`
/// axis (JSON `"texture_mode": ["full", "gaussian"]`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TextureMode {
    /// Learned alpha and colour textures (BBSplat).
    #[default]
    Full,
    /// Plain Gaussian billboards (2DGS-like): alpha texel `k` of billboard `i` is
    /// `sigmoid(ω_i) · shape_k`, with one learned opacity logit `ω_i` per billboard and `shape`
    /// the fixed initial Gaussian (`G/255` of the reference asset, peak 0.984, masked texels 0);
    /// the colour texture stays at its initial value, so colour is learned through SH only.
    Gaussian,
}

impl TextureMode {
    /// Every mode, in declaration order.
    pub const ALL: [TextureMode; 2] = [TextureMode::Full, TextureMode::Gaussian];

    /// The text form: `full` or `gaussian`.
    ///
    /// ```
    /// use bbsplat::train::TextureMode;
    /// for mode in TextureMode::ALL {
    ///     assert_eq!(mode.as_str().parse::<TextureMode>(), Ok(mode));
    /// }
    /// assert!("none".parse::<TextureMode>().is_err());
    /// ```
    pub fn as_str(self) -> &'static str {
        match self {
            TextureMode::Full => "full",
            TextureMode::Gaussian => "gaussian",
        }
    }
}

impl std::fmt::Display for TextureMode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl std::str::FromStr for TextureMode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        TextureMode::ALL
            .into_iter()
            .find(|m| m.as_str() == s)
            .ok_or_else(|| "expected `full` or `gaussian`".into())
    }
}

/// Training settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrainConfig {
    /// Number of optimisation steps (one view each). Schedule milestones scale with it, the
    /// reference's 32 000 being 100 %.
    pub iterations: usize,
    /// Highest SH degree (0-3).
    pub sh_degree: u32,
    /// Background colour composited behind the billboards.
    pub background: Vec3,
    /// Seed of the view order and of relocation sampling.
    pub seed: u64,
    /// Spatial scale `E` of the position learning rate (1.1 × the largest camera-centre
    /// distance from their mean; see [`crate::scene::split::camera_extent`]).
    pub extent: f32,
    /// Impact threshold σ of the texture regulariser (default 500, the paper's value).
    pub impact_threshold: f32,
    /// Weight of the texture regulariser (default `1e-4`; 0 disables it).
    pub texture_reg_weight: f32,
    /// Weight of the opacity regulariser (default `0.01`; 0 disables it).
    pub opacity_reg_weight: f32,
    /// Dense or row-sparse Adam.
    pub adam: AdamMode,
    /// Learned textures or Gaussian billboards.
    pub texture_mode: TextureMode,
    /// Relocate dead billboards (spec §6).
    pub relocate: bool,
    /// Steps between relocations, not scaled with `iterations` (reference 100); the window
    /// `500/32 000 < (step+1)/iterations < 25 000/32 000` is scaled.
    pub relocate_every: usize,
    /// Grow the set toward this many billboards at every relocation step ([`grow`], spec §6:
    /// `min(cap, ⌊1.05·N⌋)`); 0 (the default) or a cap at or below the count: no growth.
    pub growth_cap: usize,
    /// Share (0 to 1) of each growth step's new billboards placed where the view just rendered
    /// is worst ([`place`]) instead of copied from existing billboards; 0 (the default, the
    /// reference's growth) copies them all. Full-texture mode only ([`TextureMode::Gaussian`]
    /// copies).
    pub error_growth: f32,
    /// Multipliers of the reference learning rates (all 1 by default).
    pub lr_scales: LearningRateScales,
    /// Also multiply every rate by [`run_length_lr_factor`] of the run's current length (off by
    /// default; `bbsplat train` turns it on unless a learning-rate flag is given). Evaluated at
    /// every step, so a time budget's re-planned length is followed.
    pub lr_by_run_length: bool,
    /// How the gradient of a step's backward pass goes through the compositing clamp
    /// `α = min(0.99, a)`: [`ClampGradient::Exact`] (default: zero above the clamp, the
    /// derivative of the forward) or [`ClampGradient::PassThrough`] (straight-through, as the
    /// reference rasterizer does, so that an alpha texel above the clamp still learns). Only the
    /// backward pass depends on it; renders are the same.
    pub clamp_gradient: ClampGradient,
    /// The 2DGS normal-consistency and depth-distortion regularisers ([`geometry`]; off by
    /// default).
    pub geometry: geometry::GeometryRegularisers,
    /// The instruction set of the lane-wise loops (render, loss, regulariser, texture step;
    /// default: the widest the CPU runs). The same bits whatever it is; only the speed differs.
    pub simd: Simd,
}

impl TrainConfig {
    /// What is out of range in this configuration, or `None`: the texture-regulariser threshold
    /// must be finite and ≥ 0, the regulariser weights, background and extent finite (the extent
    /// positive), the SH degree ≤ 3. Checked by every [`Trainer::step`] (a bad setting would
    /// otherwise panic or train on NaN). (Learning-rate multipliers are not: a huge one is a
    /// legitimate way to diverge, caught by the non-finite checks of the step.)
    pub fn problem(&self) -> Option<String> {
        let t = self.impact_threshold;
        if !(t.is_finite() && t >= 0.0) {
            return Some(format!(
                "impact_threshold (texture threshold) {t} is not a finite number ≥ 0"
            ));
        }
        if !(self.texture_reg_weight.is_finite() && self.opacity_reg_weight.is_finite()) {
            return Some("a regulariser weight is not finite".into());
        }
        if !(self.extent.is_finite() && self.extent > 0.0) {
            return Some(format!("extent {} is not a finite number > 0", self.extent));
        }
        if !self.background.is_finite() {
            return Some(format!("background {} is not finite", self.background));
        }
        if self.sh_degree > 3 {
            return Some(format!("SH degree {} > 3", self.sh_degree));
        }
        if !(0.0..=1.0).contains(&self.error_growth) {
            return Some(format!(
                "error_growth {} is not a share between 0 and 1",
                self.error_growth
            ));
        }
        self.geometry.problem()
    }
}

/// Multipliers of the reference learning rates of [`learning_rates`], per parameter group; the
/// schedules (decay, windows, freezes) are unchanged. [`LearningRateScales::REFERENCE`] (all 1)
/// is the reference. Runs much shorter than the reference's 32 000 steps converge faster with
/// larger rates (measured on lego in `docs/quality.md`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LearningRateScales {
    /// Positions.
    pub position: f32,
    /// SH coefficients, degree 0 and higher degrees alike.
    pub sh: f32,
    /// Log-scales and quaternions.
    pub shape: f32,
    /// Alpha and colour texture logits, and the per-billboard opacity of
    /// [`TextureMode::Gaussian`].
    pub texture: f32,
}

impl LearningRateScales {
    /// All 1: the reference's rates.
    pub const REFERENCE: Self = Self::uniform(1.0);

    /// Every group scaled by `factor`.
    pub const fn uniform(factor: f32) -> Self {
        Self {
            position: factor,
            sh: factor,
            shape: factor,
            texture: factor,
        }
    }

    /// The four multipliers in field order (the checkpoint's order).
    pub fn to_array(self) -> [f32; 4] {
        [self.position, self.sh, self.shape, self.texture]
    }
}

impl Default for LearningRateScales {
    fn default() -> Self {
        Self::REFERENCE
    }
}

impl Default for TrainConfig {
    /// The reference settings: 32 000 iterations, SH degree 3, black background, seed 0, extent 1,
    /// σ = 500, weights `1e-4` / `0.01`, dense Adam, full textures, relocation every 100 steps,
    /// the reference learning rates, the exact clamp gradient, no growth (the initial count is the
    /// reference's cap).
    fn default() -> Self {
        Self {
            iterations: 32_000,
            sh_degree: 3,
            background: Vec3::ZERO,
            seed: 0,
            extent: 1.0,
            impact_threshold: regularise::IMPACT_THRESHOLD,
            texture_reg_weight: regularise::TEXTURE_REG_WEIGHT,
            opacity_reg_weight: regularise::OPACITY_REG_WEIGHT,
            adam: AdamMode::Dense,
            texture_mode: TextureMode::Full,
            relocate: true,
            relocate_every: 100,
            growth_cap: 0,
            error_growth: 0.0,
            lr_scales: LearningRateScales::REFERENCE,
            lr_by_run_length: false,
            clamp_gradient: ClampGradient::Exact,
            geometry: geometry::GeometryRegularisers::default(),
            simd: Simd::detect(),
        }
    }
}

/// Reference iteration count, the 100 % point of every milestone.
pub const REFERENCE_ITERATIONS: u64 = 32_000;

/// True when step `step` (0-based) of a run of `iterations` is at or past the reference
/// iteration `reference` (of 32 000): `step · 32 000 ≥ reference · iterations`, exact integers.
pub fn past_milestone(step: usize, iterations: usize, reference: u64) -> bool {
    step as u128 * REFERENCE_ITERATIONS as u128 >= reference as u128 * iterations.max(1) as u128
}

/// Learning rates of one step (spec §7, milestones scaled to the run length).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LearningRates {
    /// Positions.
    pub position: f32,
    /// SH degree-0 coefficients.
    pub sh_dc: f32,
    /// SH coefficients of degree ≥ 1.
    pub sh_rest: f32,
    /// Log-scales.
    pub scale: f32,
    /// Quaternions.
    pub rotation: f32,
    /// Alpha logits.
    pub alpha: f32,
    /// Colour logits.
    pub colour: f32,
    /// Per-billboard opacity logit of [`TextureMode::Gaussian`] (2DGS's 0.05).
    pub opacity: f32,
}

/// Learning rates at `step` (0-based) of a run of `iterations` steps.
///
/// Timeline (reference iterations of 32 000, scaled): position log-linear from `1.6e-4·E` to
/// `1.6e-6·E` over `[0, 30 000)`, then constant; textures at 0.001 (alpha) and 0.0025 (colour) in
/// `[500, 30 000)`, 0 outside; from 30 000 on, SH DC, scale, rotation, textures and the Gaussian
/// opacity are frozen (0) while SH rest keeps 2.5e-4 and positions keep the final `1.6e-6·E`
/// (the reference's quirk, kept). The reference's single iteration 30 001 at which the position
/// rate is also 0 is not reproduced.
pub fn learning_rates(step: usize, iterations: usize, extent: f32) -> LearningRates {
    let progress = step as f32 / iterations.max(1) as f32;
    // Position: log-linear from 1.6e-4·E to 1.6e-6·E over the first 30/32 of the run.
    let p = (progress * 32.0 / 30.0).min(1.0);
    let position = (1.6e-4f32.ln() * (1.0 - p) + 1.6e-6f32.ln() * p).exp() * extent;
    let late = past_milestone(step, iterations, 30_000);
    let textures_on = past_milestone(step, iterations, 500) && !late;
    let early = |lr: f32| if late { 0.0 } else { lr };
    LearningRates {
        position,
        sh_dc: early(0.005),
        sh_rest: 0.005 / 20.0,
        scale: early(0.005),
        rotation: early(0.001),
        alpha: if textures_on { 0.001 } else { 0.0 },
        colour: if textures_on { 0.0025 } else { 0.0 },
        opacity: early(0.05),
    }
}

impl LearningRates {
    /// These rates with each group multiplied by its factor of `scales`.
    pub fn scaled(self, scales: &LearningRateScales) -> Self {
        Self {
            position: self.position * scales.position,
            sh_dc: self.sh_dc * scales.sh,
            sh_rest: self.sh_rest * scales.sh,
            scale: self.scale * scales.shape,
            rotation: self.rotation * scales.shape,
            alpha: self.alpha * scales.texture,
            colour: self.colour * scales.texture,
            opacity: self.opacity * scales.texture,
        }
    }
}

/// Run length up to which [`run_length_lr_factor`] is [`SHORT_RUN_LR_FACTOR`].
pub const SHORT_RUN_STEPS: usize = 7000;
/// Learning-rate factor of short runs (measured on lego: ×4 gave +4.3 dB at 1200 steps and
/// +3.3 dB at 6000 steps over the reference's rates, `docs/quality.md`).
pub const SHORT_RUN_LR_FACTOR: f32 = 4.0;

/// The learning-rate factor of a run of `iterations` steps: [`SHORT_RUN_LR_FACTOR`] up to
/// [`SHORT_RUN_STEPS`], 1 (the reference's rates, made for its 32 000 steps) from 32 000 on,
/// log-linear in the step count between. The two ends are measured (lego, 1200 and 6000 steps
/// at ×4; the reference at 32 000); the interpolation between them is not.
///
/// ```
/// use bbsplat::train::run_length_lr_factor;
/// assert_eq!(run_length_lr_factor(1200), 4.0);
/// assert_eq!(run_length_lr_factor(7000), 4.0);
/// assert_eq!(run_length_lr_factor(32_000), 1.0);
/// let mid = run_length_lr_factor(15_000);
/// assert!(mid > 1.0 && mid < 4.0);
/// ```
pub fn run_length_lr_factor(iterations: usize) -> f32 {
    let (short, full) = (SHORT_RUN_STEPS as f64, REFERENCE_ITERATIONS as f64);
    let n = (iterations.max(1) as f64).clamp(short, full);
    let t = (n / short).ln() / (full / short).ln();
    (SHORT_RUN_LR_FACTOR as f64).powf(1.0 - t) as f32
}

/// Active SH degree at `step`: +1 every 1/32 of the run, up to `max_degree`.
pub fn active_sh_degree(step: usize, iterations: usize, max_degree: u32) -> u32 {
    let per = (iterations / 32).max(1);
    ((step / per) as u32).min(max_degree)
}

/// True when relocation runs after step `step` (0-based): reference iteration `it = step + 1` is a
/// multiple of `every` and lies strictly inside the scaled window `(500, 25 000)` of 32 000.
pub fn relocation_due(step: usize, iterations: usize, every: usize) -> bool {
    let it = step + 1;
    every > 0
        && it.is_multiple_of(every)
        && !past_milestone(it, iterations, 25_000)
        && (it as u128 * REFERENCE_ITERATIONS as u128) > 500 * iterations.max(1) as u128
}

/// One logged step: what a progress bar shows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepLog {
    /// Steps done, this one included.
    pub step: usize,
    /// Index of the step's view in the views passed to [`Trainer::step`] (the coarse views keep
    /// the training views' order, so it indexes those too).
    pub view: usize,
    /// Total loss of the step: photometric + texture + opacity regularisers (+ the geometry
    /// regularisers when on).
    pub loss: f64,
    /// Photometric loss `0.8·L1 + 0.2·(1 − SSIM)` of the step's view.
    pub photometric: f64,
    /// Texture regulariser value (paper Eq. 9).
    pub texture_reg: f64,
    /// Opacity regulariser value.
    pub opacity_reg: f64,
    /// Weighted normal-consistency loss (0 when off, [`geometry`]).
    pub normal_reg: f64,
    /// Weighted depth-distortion loss (0 when off, [`geometry`]).
    pub distortion_reg: f64,
    /// PSNR of the step's render against its view (float images).
    pub psnr: f64,
    /// Billboards the optimiser updated in the step.
    pub updated: usize,
    /// Dead billboards relocated after the step (0 when relocation did not run).
    pub relocated: usize,
    /// Billboards added by growth after the step ([`grow`]; 0 when it did not run).
    pub grown: usize,
}

/// Index of each Adam group in the trainer's array.
pub mod group {
    /// Positions (3 per row).
    pub const POSITION: usize = 0;
    /// Quaternions (4).
    pub const ROTATION: usize = 1;
    /// Log-scales (2).
    pub const SCALE: usize = 2;
    /// SH DC (3).
    pub const SH_DC: usize = 3;
    /// SH rest (45).
    pub const SH_REST: usize = 4;
    /// Alpha logits (`TS²`).
    pub const ALPHA: usize = 5;
    /// Colour logits (`3·TS²`).
    pub const COLOUR: usize = 6;
    /// Gaussian-mode opacity logit (1).
    pub const OPACITY: usize = 7;
    /// Number of groups.
    pub const COUNT: usize = 8;
}

/// Optimiser state of a training run.
///
/// It holds the billboard set in two forms, the raw parameters ([`Trainer::model`]) and their
/// activated copy that the rasterizer reads ([`Trainer::activated`]), kept in sync by every
/// method: from outside, the parameters change only through [`Trainer::edit_model`].
///
/// Deterministic: the same model, config and views give bit-identical results for any rayon
/// thread count, and a run continued from [`Trainer::save_checkpoint`] /
/// [`Trainer::load_checkpoint`] is bit-identical to an uninterrupted one.
pub struct Trainer {
    /// The raw parameters ([`Trainer::model`]; edited from outside only through
    /// [`Trainer::edit_model`]).
    model: RawBillboards,
    /// The activated copy the rasterizer reads ([`Trainer::activated`]): every method that
    /// changes a row of `model` refreshes the row here ([`Trainer::refresh_row`]).
    activated: ActivatedBillboards,
    adam: [AdamGroup; group::COUNT],
    grads: RenderGradients,
    config: TrainConfig,
    order: Vec<usize>,
    rng: Rng,
    step: usize,
    /// `A0` of the texture regulariser: `initial_alpha(TS)` with masked texels 0.
    alpha0: Vec<f32>,
    /// Gaussian-mode shape: `2 · A0` (= `G/255`).
    shape: Vec<f32>,
    /// Gaussian-mode opacity logits (empty in full-texture mode).
    opacity_logits: Vec<f32>,
    /// The storage of the last step's render, recycled by the next (values never carried over).
    render_buffers: RenderBuffers,
    /// Lazy Adam's record of the alpha, colour and SH-rest groups' live steps ([`lazy_adam`];
    /// empty in the other modes).
    lazy_logs: [lazy_adam::LazyLog; 3],
    /// Per billboard, whether the step's view keeps it (lazy Adam; recycled from step to step).
    in_view: Vec<bool>,
    /// The float values of the step's view when it is 8-bit (recycled from step to step).
    target: Vec<f32>,
    /// The SSIM gradient's partial maps (recycled from step to step; values never carried over).
    ssim_scratch: SsimScratch,
    /// The mask-weighted render and target of a view with a loss mask.
    masked_buffers: crate::loss::masked::MaskedBuffers,
    /// The backward pass's records and texel lists (recycled likewise).
    backward_scratch: BackwardScratch,
    /// Per billboard, the regularisers' gradient of the current step, which the texture step
    /// adds as it reads the texture gradients (full textures; empty in Gaussian mode, where
    /// `regularise` adds it in place).
    regulariser_rows: Vec<RowGradient>,
    /// The run's arguments and dataset, saved in the checkpoint ([`run_record`]).
    record: run_record::RunRecord,
    /// The time budget's plan, when the run has one ([`time_budget`]).
    time_plan: Option<time_budget::TimePlan>,
}

fn adam_groups(n: usize, t: usize) -> [AdamGroup; group::COUNT] {
    [
        AdamGroup::new(n, 3),
        AdamGroup::new(n, 4),
        AdamGroup::new(n, 2),
        AdamGroup::new(n, 3),
        AdamGroup::new(n, SH_FLOATS - 3),
        AdamGroup::new(n, t),
        AdamGroup::new(n, 3 * t),
        AdamGroup::new(n, 1),
    ]
}

impl Trainer {
    /// A trainer starting from `model`.
    ///
    /// In [`TextureMode::Gaussian`] each billboard's opacity starts at
    /// `clamp(mean alpha / mean shape, 1e-4, 1 − 1e-4)` (0.5 for a freshly initialised model) and
    /// its alpha logits are overwritten with `logit(o · shape)` so that the model alone renders
    /// what the trainer renders.
    pub fn new(model: RawBillboards, config: TrainConfig) -> Self {
        let adam = adam_groups(model.len(), model.texture_size * model.texture_size);
        Self::with_adam(model, config, adam)
    }

    /// [`Trainer::new`] with given optimiser state (a checkpoint's), so that loading does not
    /// first allocate zero moments only to replace them.
    pub(crate) fn with_adam(model: RawBillboards, config: TrainConfig, adam: [AdamGroup; group::COUNT]) -> Self {
        let n = model.len();
        let t = model.texture_size * model.texture_size;
        let alpha0: Vec<f32> = initial_alpha(model.texture_size)
            .iter()
            .zip(&model.alpha_mask)
            .map(|(&a, &m)| if m { a } else { 0.0 })
            .collect();
        let shape: Vec<f32> = alpha0.iter().map(|&a| 2.0 * a).collect();
        let activated = model.activate();
        let opacity_logits = match config.texture_mode {
            TextureMode::Full => Vec::new(),
            TextureMode::Gaussian => {
                let mean_shape = shape.iter().map(|&x| x as f64).sum::<f64>() / t.max(1) as f64;
                activated
                    .mean_alphas()
                    .iter()
                    .map(|&m| logit((m as f64 / mean_shape.max(1e-12)).clamp(1e-4, 1.0 - 1e-4) as f32))
                    .collect()
            }
        };
        let mut trainer = Self {
            grads: RenderGradients::zeros(n, model.texture_size),
            adam,
            model,
            activated,
            config,
            order: Vec::new(),
            rng: Rng::new(config.seed),
            step: 0,
            alpha0,
            shape,
            opacity_logits,
            render_buffers: RenderBuffers::default(),
            ssim_scratch: SsimScratch::default(),
            masked_buffers: Default::default(),
            backward_scratch: BackwardScratch::default(),
            target: Vec::new(),
            lazy_logs: Default::default(),
            in_view: Vec::new(),
            regulariser_rows: Vec::new(),
            record: run_record::RunRecord::default(),
            time_plan: None,
        };
        if config.texture_mode == TextureMode::Gaussian {
            for b in 0..n {
                trainer.refresh_row(b);
            }
        }
        trainer
    }

    /// The raw parameters being trained (what checkpoints save; [`Trainer::export_model`] gives
    /// the model to save or render).
    pub fn model(&self) -> &RawBillboards {
        &self.model
    }

    /// The activated copy of [`Trainer::model`] the rasterizer reads, in sync with it row for row:
    /// bit for bit [`RawBillboards::activate`] of the model in [`TextureMode::Full`]; in
    /// [`TextureMode::Gaussian`] the alpha texels are `opacity · shape` (the alpha logits are
    /// their clamped logits).
    pub fn activated(&self) -> &ActivatedBillboards {
        &self.activated
    }

    /// Edits the raw parameters between steps with `edit`, then refreshes every row of the
    /// activated copy from them, so that [`Trainer::activated`] stays in sync; returns what
    /// `edit` returns. The optimiser state is kept as it is.
    ///
    /// In [`TextureMode::Gaussian`] the alpha logits follow the opacity logits: edits to them are
    /// overwritten by the refresh (the other parameters are kept).
    ///
    /// # Panics
    /// When `edit` changes the number of billboards, the texture size or the alpha mask (the
    /// optimiser state, the gradients and the regulariser's `A0` are sized and derived from
    /// them); the trainer is then left as `edit` left it, out of sync.
    ///
    /// ```
    /// use bbsplat::model::RawBillboards;
    /// use bbsplat::train::{TrainConfig, Trainer};
    /// use glam::Vec3;
    ///
    /// let model = RawBillboards::from_points(&[Vec3::ZERO, Vec3::X], &[[0.5; 3]; 2], 4, 0);
    /// let mut trainer = Trainer::new(model, TrainConfig::default());
    /// trainer.edit_model(|m| m.positions[1] = Vec3::Y);
    /// assert_eq!(trainer.activated().positions[1], Vec3::Y);
    /// ```
    ///
    /// The two forms themselves are private: no edit can skip the refresh.
    ///
    /// ```compile_fail,E0616
    /// # use bbsplat::model::RawBillboards;
    /// # use bbsplat::train::{TrainConfig, Trainer};
    /// # let model = RawBillboards::from_points(&[glam::Vec3::ZERO], &[[0.5; 3]], 4, 0);
    /// let mut trainer = Trainer::new(model, TrainConfig::default());
    /// trainer.model.positions[0] = glam::Vec3::Y; // error[E0616]: field `model` is private
    /// ```
    pub fn edit_model<R>(&mut self, edit: impl FnOnce(&mut RawBillboards) -> R) -> R {
        let (n, ts) = (self.model.len(), self.model.texture_size);
        let mask = self.model.alpha_mask.clone();
        let result = edit(&mut self.model);
        let m = &self.model;
        let rows_ok = m.positions.len() == n
            && m.quaternions.len() == n
            && m.log_scales.len() == n
            && m.sh.len() == n * SH_FLOATS
            && m.alpha_logits.len() == n * ts * ts
            && m.colour_logits.len() == 3 * n * ts * ts;
        assert!(
            rows_ok && m.texture_size == ts,
            "Trainer::edit_model: the edit changed the number of billboards ({n}) or the texture size ({ts})"
        );
        assert!(
            m.alpha_mask == mask,
            "Trainer::edit_model: the edit changed the alpha mask"
        );
        for b in 0..n {
            self.refresh_row(b);
        }
        result
    }

    /// The raw parameters, the activated copy left as it is (`testing_internals` only).
    #[cfg(feature = "testing")]
    pub(crate) fn model_unsynced_mut(&mut self) -> &mut RawBillboards {
        &mut self.model
    }

    /// The run record saved with the checkpoint ([`run_record`]; empty unless set, or loaded
    /// from a checkpoint of format version 3 or older).
    pub fn run_record(&self) -> &run_record::RunRecord {
        &self.record
    }

    /// Sets the run record saved with every later checkpoint.
    pub fn set_run_record(&mut self, record: run_record::RunRecord) {
        self.record = record;
    }

    /// Steps done so far.
    pub fn step_index(&self) -> usize {
        self.step
    }

    /// The settings of the run.
    pub fn config(&self) -> &TrainConfig {
        &self.config
    }

    /// The time budget's plan, when the run has one.
    pub fn time_plan(&self) -> Option<&time_budget::TimePlan> {
        self.time_plan.as_ref()
    }

    /// Gives the run a time budget ([`time_budget`]; [`run()`] then plans
    /// [`TrainConfig::iterations`] from the measured step times), or removes it with `None`.
    pub fn set_time_plan(&mut self, plan: Option<time_budget::TimePlan>) {
        self.time_plan = plan;
    }

    /// Mutable plan, for [`run()`].
    pub(crate) fn time_plan_mut(&mut self) -> Option<&mut time_budget::TimePlan> {
        self.time_plan.as_mut()
    }

    /// Re-plans the run's length (a time budget's plan; every schedule follows).
    pub(crate) fn set_iterations(&mut self, iterations: usize) {
        self.config.iterations = iterations;
    }

    /// The Adam state, indexed by the constants of [`group`].
    pub fn adam(&self) -> &[AdamGroup; group::COUNT] {
        &self.adam
    }

    /// Gaussian-mode opacity logits, one per billboard (empty in [`TextureMode::Full`]).
    pub fn opacity_logits(&self) -> &[f32] {
        &self.opacity_logits
    }

    /// The first parameter group (in the order of [`ParamGroup`]) holding a NaN or infinite
    /// value, or `None`. One pass over the parameters; [`Trainer::step`] runs it after every
    /// optimiser step.
    pub fn non_finite_parameter(&self) -> Option<ParamGroup> {
        finite::non_finite_parameter(&self.model, &self.opacity_logits)
    }

    /// The model to save or render: the raw parameters, with the alpha logits of
    /// [`TextureMode::Gaussian`] taken from the textures the renderer used (opacity × the fixed
    /// shape, clamped to `[1e-6, 1 − 1e-6]`; masked texels 0). In full-texture mode a copy of
    /// [`Trainer::model`].
    pub fn export_model(&self) -> RawBillboards {
        let mut model = self.model.clone();
        if self.lazy_textures() {
            // Lazy Adam: every row's pending texture steps, on the copy.
            let hp = AdamParams::default();
            let [.., a_alpha, a_colour, _] = &self.adam;
            lazy_adam::caught_up_values(a_alpha, &self.lazy_logs[0], &mut model.alpha_logits, &hp);
            lazy_adam::caught_up_values(a_colour, &self.lazy_logs[1], &mut model.colour_logits, &hp);
            let rest = SH_FLOATS - 3;
            let a_sh_rest = &self.adam[group::SH_REST];
            let mut memo = None;
            for b in 0..model.len() {
                if let Some(pending) = self.lazy_logs[2].pending_memo(a_sh_rest.steps[b], &hp, &mut memo) {
                    let moments = b * rest..(b + 1) * rest;
                    lazy_adam::move_row(
                        &a_sh_rest.m[moments.clone()],
                        &a_sh_rest.v[moments],
                        &mut model.sh[b * SH_FLOATS + 3..(b + 1) * SH_FLOATS],
                        &pending,
                    );
                }
            }
        }
        if self.config.texture_mode == TextureMode::Gaussian {
            let t = model.texture_size * model.texture_size;
            for (i, texel) in self.activated.textures.iter().enumerate() {
                model.alpha_logits[i] = if model.alpha_mask[i % t] {
                    clamped_logit(texel[3])
                } else {
                    0.0
                };
            }
        }
        model
    }

    /// Billboards whose mean alpha exceeds the relocation threshold
    /// [`crate::model::DEAD_ALPHA`] (0.005), measured on the textures the renderer uses.
    pub fn alive_count(&self) -> usize {
        self.activated.alive_count()
    }

    /// Puts view `vi`, just drawn by [`Trainer::next_view`], back: the stack as it was, the RNG
    /// as before a refill (`refills`: the stack was empty; `rng_before`: the RNG then).
    fn undo_draw(&mut self, vi: usize, refills: bool, rng_before: [u64; 4]) {
        if refills {
            self.order.clear();
            self.rng = Rng::from_state(rng_before);
        } else {
            self.order.push(vi);
        }
    }

    fn next_view(&mut self, views: usize) -> usize {
        if self.order.is_empty() {
            self.order = (0..views).collect();
            self.rng.shuffle(&mut self.order);
        }
        self.order.pop().expect("refilled above")
    }

    /// Render settings at the current step.
    pub fn settings(&self) -> RenderSettings {
        let mut settings = RenderSettings {
            background: self.config.background,
            sh_degree: active_sh_degree(self.step, self.config.iterations, self.config.sh_degree),
            simd: self.config.simd,
            ..RenderSettings::default()
        };
        settings.composite.clamp_gradient = self.config.clamp_gradient;
        settings
    }

    fn validate(&self, views: &[TrainView]) -> Result<(), TrainError> {
        if let Some(problem) = self.config.problem() {
            return Err(TrainError::InvalidConfig(problem));
        }
        if views.is_empty() {
            return Err(TrainError::NoViews);
        }
        for (i, v) in views.iter().enumerate() {
            let expected = v.camera.width as usize * v.camera.height as usize * 3;
            if v.rgb.len() != expected {
                return Err(TrainError::ImageSize {
                    view: i,
                    width: v.camera.width,
                    height: v.camera.height,
                    expected,
                    got: v.rgb.len(),
                });
            }
            let pixels = v.camera.width as usize * v.camera.height as usize;
            if let Some(mask) = v.loss_mask.as_ref().filter(|m| m.len() != pixels) {
                return Err(TrainError::MaskSize {
                    view: i,
                    width: v.camera.width,
                    height: v.camera.height,
                    got: mask.len(),
                });
            }
        }
        if let Some(&index) = self.order.iter().find(|&&i| i >= views.len()) {
            return Err(TrainError::ViewSetChanged {
                index,
                views: views.len(),
            });
        }
        Ok(())
    }

    /// One optimisation step on the next view of the shuffled stack (views are drawn without
    /// replacement; the stack is refilled and reshuffled when empty), followed by relocation when
    /// due ([`relocation_due`]).
    ///
    /// The loss is photometric + texture regulariser + opacity regulariser; the gradients of the
    /// regularisers are added to the rasterizer's texture gradients before the optimiser step.
    ///
    /// Every step checks its values (see [`finite`]): the total loss and every gradient before
    /// the optimiser step, every parameter after it.
    ///
    /// # Errors
    /// [`TrainError`] when `views` is empty, an image does not match its camera, or the view
    /// list shrank below an index still on the shuffled stack; the trainer is unchanged then.
    /// [`TrainError::NonFinite`] when the loss or a gradient is NaN or infinite (the step is not
    /// applied and the trainer is unchanged, bit for bit) or a parameter is after the optimiser
    /// step (the step was applied).
    pub fn step(&mut self, views: &[TrainView]) -> Result<StepLog, TrainError> {
        self.validate(views)?;
        // What drawing the view changes, to undo a refused step.
        let (rng_before, refills) = (self.rng.state(), self.order.is_empty());
        let vi = self.next_view(views.len());
        let view = &views[vi];
        let cam = &view.camera;
        // An 8-bit view is converted to floats here, into a buffer recycled from step to step
        // (decoded first when on demand; a view that cannot be read refuses the step).
        let mut target_buffer = std::mem::take(&mut self.target);
        let target = match view.rgb.as_f32(&mut target_buffer) {
            Ok(target) => target,
            Err(e) => {
                self.target = target_buffer;
                self.undo_draw(vi, refills, rng_before);
                return Err(TrainError::ViewImage {
                    view: vi,
                    message: e.to_string(),
                });
            }
        };
        let mut settings = self.settings();
        let geometry = &self.config.geometry;
        let lambda_normal = geometry
            .normal_active(self.step, self.config.iterations)
            .then_some(geometry.lambda_normal);
        let lambda_distortion = geometry
            .distortion_active(self.step, self.config.iterations)
            .then_some(geometry.lambda_distortion);
        settings.distortion = lambda_distortion.is_some();
        let lazy = self.lazy_textures();
        // The catch-up checks the logits it writes, as the texture step does.
        let mut caught_up_finite = true;
        if lazy {
            // The texture and SH-rest rows the view can read, brought up to date before it is
            // drawn (every texture row once the textures are frozen: nothing is pending after
            // that first time).
            let mut in_view = std::mem::take(&mut self.in_view);
            let textures_live = !past_milestone(self.step, self.config.iterations, 30_000);
            kept_rows_into(&self.activated.borrowed(), cam, &mut in_view);
            let textures = textures_live.then_some(in_view.as_slice());
            caught_up_finite = self.catch_up(textures, Some(&in_view));
            self.in_view = in_view;
        }
        let buffers = std::mem::take(&mut self.render_buffers);
        let out = render_with(&self.activated.borrowed(), cam, &settings, buffers);
        let loss_fn = TrainingLoss {
            simd: self.config.simd,
            ..TrainingLoss::default()
        };
        let dims = (cam.width as usize, cam.height as usize, 3);
        let loss = match &view.loss_mask {
            None => loss_fn.evaluate_in(&out.rgb, target, dims, &mut self.ssim_scratch),
            Some(mask) => crate::loss::masked::evaluate_masked(
                &loss_fn,
                &out.rgb,
                target,
                mask,
                dims,
                &mut self.ssim_scratch,
                &mut self.masked_buffers,
            ),
        }
        .expect("sizes validated above");
        let psnr = crate::loss::psnr::psnr(&out.rgb, target).unwrap_or(f64::NAN);
        // Both geometry terms off: no map gradient (the plain backward pass).
        let geometry_loss = GeometryLoss::evaluate(&out, cam, lambda_normal, lambda_distortion);
        let ig = geometry_loss.image_gradients(&loss.d_render);
        let touched = render_backward_with(
            &self.activated.borrowed(),
            &out,
            &ig,
            &mut self.grads,
            &mut self.backward_scratch,
        );
        // Both regularisers in one pass over the texture rows (the bits of one after the other).
        let texture_term = (self.config.texture_reg_weight != 0.0).then_some(TextureTerm {
            alpha0: &self.alpha0,
            impact: &out.impact,
            threshold: self.config.impact_threshold,
            weight: self.config.texture_reg_weight,
        });
        let opacity_weight = (self.config.opacity_reg_weight != 0.0).then_some(self.config.opacity_reg_weight);
        let RegulariserValues {
            texture: texture_reg,
            opacity: opacity_reg,
        } = if self.config.texture_mode == TextureMode::Gaussian {
            // The opacity logits' gradient reads the texture gradients with the regularisers'.
            self.regulariser_rows.clear();
            regularise(
                &self.activated.textures,
                self.model.texture_size * self.model.texture_size,
                texture_term,
                opacity_weight,
                &mut self.grads.textures,
                self.config.simd,
            )
        } else {
            // Only read here: the texture step adds each row's regulariser gradient as it reads
            // the row's gradients (the same bits as adding it in place, one pass fewer over them).
            regulariser_rows_of(
                &self.activated.textures,
                self.model.texture_size * self.model.texture_size,
                texture_term,
                opacity_weight,
                lazy.then_some(self.in_view.as_slice()),
                &mut self.regulariser_rows,
                self.config.simd,
            )
        };
        // Growth this step: how many rows, and those placed on this view's error (drawn now,
        // while the render is at hand; appended after relocation, below).
        let due = relocation_due(self.step, self.config.iterations, self.config.relocate_every);
        let new_rows = if due {
            grow::growth_target(self.model.len(), self.config.growth_cap) - self.model.len()
        } else {
            0
        };
        let placed = (new_rows > 0).then(|| self.place_on_error(new_rows, &out, target, views, vi));
        self.target = target_buffer;
        let placed = match placed.transpose() {
            Ok(placed) => placed,
            Err(e) => {
                self.render_buffers = out.into_buffers();
                self.undo_draw(vi, refills, rng_before);
                self.grads = RenderGradients::zeros(self.model.len(), self.model.texture_size);
                return Err(e);
            }
        };
        self.render_buffers = out.into_buffers();
        let total = if lambda_normal.is_some() || lambda_distortion.is_some() {
            loss.loss + texture_reg + opacity_reg + geometry_loss.normal + geometry_loss.distortion
        } else {
            loss.loss + texture_reg + opacity_reg
        };
        let bad = if total.is_finite() {
            let added = (!self.regulariser_rows.is_empty()).then_some(self.regulariser_rows.as_slice());
            let only = lazy.then_some(self.in_view.as_slice());
            finite::non_finite_gradient_of(&self.grads, added, only).map(NonFinite::Gradient)
        } else {
            Some(NonFinite::Loss)
        };
        if let Some(value) = bad {
            // Refuse the step: the view goes back on the stack, the gradients back to zero.
            self.undo_draw(vi, refills, rng_before);
            self.grads = RenderGradients::zeros(self.model.len(), self.model.texture_size);
            return Err(TrainError::NonFinite {
                step: self.step + 1,
                view: vi,
                value,
            });
        }
        let mut lr =
            learning_rates(self.step, self.config.iterations, self.config.extent).scaled(&self.config.lr_scales);
        if self.config.lr_by_run_length {
            lr = lr.scaled(&LearningRateScales::uniform(run_length_lr_factor(
                self.config.iterations,
            )));
        }
        let (updated, textures_checked) = match self.config.adam {
            AdamMode::Dense | AdamMode::Lazy => {
                for g in &mut self.adam {
                    g.global_step += 1;
                }
                let rows: Vec<u32> = (0..self.model.len() as u32).collect();
                let checked = self.apply(&rows, &lr);
                (rows.len(), checked)
            }
            AdamMode::Sparse => (touched.len(), self.apply(&touched, &lr)),
        };
        // Regulariser gradients may have landed on rows the sparse mode did not consume (the
        // texture step zeroes every row in full-texture mode).
        if self.config.texture_mode == TextureMode::Gaussian {
            self.grads.textures.fill([0.0; 4]);
        }
        self.grads.background = Vec3::ZERO;
        let relocated = if self.config.relocate && due {
            self.relocate()
        } else {
            0
        };
        let grown = match placed {
            Some(placed) => self.grow_rows(new_rows - placed.len(), Some(placed)),
            None => 0,
        };
        self.step += 1;
        // The texture logits were checked as the texture step wrote them, unless some were
        // not written (sparse rows, frozen textures) or were written since (relocation, growth).
        // Lazy Adam writes only the rows the view keeps: those the catch-up and the texture step
        // checked; the others are as they were at the last check.
        let textures_known_finite = textures_checked && caught_up_finite && relocated == 0 && grown == 0;
        if let Some(group) = finite::non_finite_parameter_with(&self.model, &self.opacity_logits, textures_known_finite)
        {
            return Err(TrainError::NonFinite {
                step: self.step,
                view: vi,
                value: NonFinite::Parameter(group),
            });
        }
        Ok(StepLog {
            step: self.step,
            view: vi,
            loss: total,
            photometric: loss.loss,
            texture_reg,
            opacity_reg,
            normal_reg: geometry_loss.normal,
            distortion_reg: geometry_loss.distortion,
            psnr,
            updated,
            relocated,
            grown,
        })
    }

    /// Refreshes the activated row `b` from the raw parameters (and, in Gaussian mode, writes
    /// `o·shape` into both the activated alpha and the model's alpha logits).
    fn refresh_row(&mut self, b: usize) {
        let t = self.model.texture_size * self.model.texture_size;
        if self.config.texture_mode == TextureMode::Gaussian {
            let o = sigmoid(self.opacity_logits[b]);
            for k in 0..t {
                let a = o * self.shape[k];
                self.model.alpha_logits[b * t + k] = if self.model.alpha_mask[k] {
                    logit(a.clamp(1e-12, 1.0 - 1e-7))
                } else {
                    0.0
                };
            }
            self.model.activate_row(b, &mut self.activated);
            for k in 0..t {
                self.activated.textures[b * t + k][3] = o * self.shape[k];
            }
        } else {
            self.model.activate_row(b, &mut self.activated);
        }
    }

    /// One optimiser step of the rows `rows`. Returns true when the texture step wrote every
    /// texture logit that changed since the last check (dense or lazy mode, full textures, not
    /// frozen) and found them all finite.
    fn apply(&mut self, rows: &[u32], lr: &LearningRates) -> bool {
        let hp = AdamParams::default();
        let t = self.model.texture_size * self.model.texture_size;
        let dense = self.config.adam != AdamMode::Sparse;
        let lazy = self.lazy_textures();
        let gaussian = self.config.texture_mode == TextureMode::Gaussian;
        // Texture moments accumulate before the texture window (lr 0, as the reference); after
        // the late freeze the textures never move again, so their groups are skipped.
        let textures_live = !past_milestone(self.step, self.config.iterations, 30_000);
        // Geometry, SH and (Gaussian mode) opacity: 57 floats a row, stepped row by row.
        // Dense rows share each group's step count: its Adam factors, once per step (the texture
        // groups compute theirs in the texture step).
        let [f_pos, f_rot, f_scale, f_sh_dc, f_sh_rest, f_opacity] = {
            let [a_pos, a_rot, a_scale, a_sh_dc, a_sh_rest, _, _, a_opacity] = &self.adam;
            let at = |group: &AdamGroup, lr: f32| StepFactors::new(lr, &hp, group.global_step);
            [
                at(a_pos, lr.position),
                at(a_rot, lr.rotation),
                at(a_scale, lr.scale),
                at(a_sh_dc, lr.sh_dc),
                at(a_sh_rest, lr.sh_rest),
                at(a_opacity, lr.opacity),
            ]
        };
        let geometry_step = GeometryStep {
            factors: [f_pos, f_rot, f_scale, f_sh_dc, f_sh_rest],
            dense,
            hp,
        };
        if gaussian {
            for &b in rows {
                let b = b as usize;
                let [a_pos, a_rot, a_scale, a_sh_dc, a_sh_rest, _, _, a_opacity] = &mut self.adam;
                let m = &mut self.model;
                let g = &self.grads;
                let mut moments =
                    [a_pos, a_rot, a_scale, a_sh_dc, a_sh_rest].map(|g| (&mut g.m[..], &mut g.v[..], &mut g.steps[..]));
                geometry_step.row(
                    b,
                    lr,
                    &mut moments,
                    GeometryMut::of(&mut m.positions, &mut m.quaternions, &mut m.log_scales, &mut m.sh),
                    (&g.positions, &g.quaternions, &g.log_scales, &g.sh),
                    true,
                );
                if textures_live {
                    let w = &mut self.opacity_logits[b..b + 1];
                    let d = gaussian_opacity_grad(w[0], &self.grads.textures[b * t..(b + 1) * t], &self.shape);
                    geometry_step.group_row(a_opacity, b, w, &[d], lr.opacity, f_opacity);
                }
                self.refresh_row(b);
                self.grads.clear_row(b);
            }
            return false;
        }
        // Full textures: the geometry rows (serial, about a millisecond) on one thread while the
        // texture step runs on the others; the two touch disjoint arrays, so the bits are those
        // of one after the other.
        let selected: Vec<bool>;
        let now = self.lazy_logs[0].live_steps() + 1;
        let selection = if lazy {
            texture_step::RowSelection::Lazy {
                selected: &self.in_view,
                now: now.min(u64::from(u32::MAX)) as u32,
            }
        } else if dense {
            texture_step::RowSelection::Dense
        } else {
            let mut s = vec![false; self.model.len()];
            rows.iter().for_each(|&b| s[b as usize] = true);
            selected = s;
            texture_step::RowSelection::Sparse(&selected)
        };
        let added = (!self.regulariser_rows.is_empty()).then_some(self.regulariser_rows.as_slice());
        let [a_pos, a_rot, a_scale, a_sh_dc, a_sh_rest, a_alpha, a_colour, _] = &mut self.adam;
        let (m, g, a) = (&mut self.model, &mut self.grads, &mut self.activated);
        let mut params = GeometryMut::of(&mut m.positions, &mut m.quaternions, &mut m.log_scales, &mut m.sh);
        let mut activated = GeometryMut::of(&mut a.positions, &mut a.quaternions, &mut a.log_scales, &mut a.sh);
        let mut grads = GeometryMut::of(&mut g.positions, &mut g.quaternions, &mut g.log_scales, &mut g.sh);
        // Lazy Adam: SH rest only on the rows the view keeps (the others have no gradient and
        // wait), each marked up to date through this step.
        let sh_rest_now = a_sh_rest.global_step.min(u64::from(u32::MAX)) as u32;
        let in_view = &self.in_view;
        let geometry = || {
            if dense {
                // Every row, in parallel chunks (rows are independent: the bits of the loop below).
                let moments = [&mut *a_pos, &mut *a_rot, &mut *a_scale, &mut *a_sh_dc, &mut *a_sh_rest]
                    .map(|g| (&mut g.m[..], &mut g.v[..], &mut g.steps[..]));
                let all = GeometryRows {
                    params: params.reborrow(),
                    activated: activated.reborrow(),
                    grads: grads.reborrow(),
                    moments,
                    in_view: lazy.then_some(&in_view[..]),
                };
                geometry_step.rows(all, lr, sh_rest_now);
                return;
            }
            // Row-sparse: the rows the view touched, one after the other.
            let mut moments =
                [a_pos, a_rot, a_scale, a_sh_dc, a_sh_rest].map(|g| (&mut g.m[..], &mut g.v[..], &mut g.steps[..]));
            for &b in rows {
                let b = b as usize;
                let read = (&*grads.positions, &*grads.quaternions, &*grads.log_scales, &*grads.sh);
                geometry_step.row(b, lr, &mut moments, params.reborrow(), read, true);
                params.copy_row_to(b, &mut activated, true);
                grads.zero_row(b);
            }
        };
        // Both texture groups chunk by chunk, while each chunk's RGBA texels are in cache.
        let textures = || {
            texture_step::step_texture_pair(
                texture_step::GroupStep {
                    group: a_alpha,
                    logits: &mut m.alpha_logits,
                    channels: 3..4,
                    mask: Some(&m.alpha_mask),
                    lr: lr.alpha,
                },
                texture_step::GroupStep {
                    group: a_colour,
                    logits: &mut m.colour_logits,
                    channels: 0..3,
                    mask: None,
                    lr: lr.colour,
                },
                &mut a.textures,
                &mut g.textures,
                selection,
                added,
                &hp,
                textures_live,
                self.config.simd,
            )
        };
        let ((), [alpha_finite, colour_finite]) = rayon::join(geometry, textures);
        if lazy {
            if textures_live {
                for (log, (group, lr)) in self
                    .lazy_logs
                    .iter_mut()
                    .zip([(&*a_alpha, lr.alpha), (&*a_colour, lr.colour)])
                {
                    log.record(StepFactors::new(lr, &hp, group.global_step));
                }
            }
            self.lazy_logs[2].record(f_sh_rest);
        }
        // Dense and lazy: every logit written this step was checked (lazy writes only kept rows).
        dense && textures_live && alpha_finite && colour_finite
    }

    /// Lazy Adam is on and there are texture rows to be lazy about.
    fn lazy_textures(&self) -> bool {
        self.config.adam == AdamMode::Lazy && self.config.texture_mode == TextureMode::Full
    }

    /// Lazy Adam: brings the alpha and colour rows flagged in `textures` and the SH-rest rows
    /// flagged in `sh_rest` (every row when `None`) up to date with their pending zero-gradient
    /// steps ([`lazy_adam::catch_up_rows`]) and refreshes their activated values. Nothing to do
    /// in the other modes. Returns false when a value it wrote is not finite.
    fn catch_up(&mut self, textures: Option<&[bool]>, sh_rest: Option<&[bool]>) -> bool {
        if !self.lazy_textures() {
            return true;
        }
        let hp = AdamParams::default();
        let [.., a_alpha, a_colour, _] = &mut self.adam;
        let m = &mut self.model;
        let [alpha_log, colour_log, _] = &self.lazy_logs;
        let alpha = lazy_adam::catch_up_rows(
            lazy_adam::CatchUpGroup {
                group: a_alpha,
                log: alpha_log,
                logits: &mut m.alpha_logits,
                channels: 3..4,
                mask: Some(&m.alpha_mask),
            },
            &mut self.activated.textures,
            textures,
            &hp,
            self.config.simd,
        );
        let colour = lazy_adam::catch_up_rows(
            lazy_adam::CatchUpGroup {
                group: a_colour,
                log: colour_log,
                logits: &mut m.colour_logits,
                channels: 0..3,
                mask: None,
            },
            &mut self.activated.textures,
            textures,
            &hp,
            self.config.simd,
        );
        // SH rest (45 values a row, interleaved with SH DC in the model): row by row.
        let rest = SH_FLOATS - 3;
        let [.., a_sh_rest, _, _, _] = &mut self.adam;
        let sh_log = &self.lazy_logs[2];
        let now = sh_log.live_steps().min(u64::from(u32::MAX)) as u32;
        let mut memo = None;
        let mut sh_finite = true;
        for b in 0..m.len() {
            if sh_rest.is_some_and(|s| !s[b]) {
                continue;
            }
            let Some(pending) = sh_log.pending_memo(a_sh_rest.steps[b], &hp, &mut memo) else {
                continue;
            };
            let span = b * SH_FLOATS + 3..(b + 1) * SH_FLOATS;
            let moments = b * rest..(b + 1) * rest;
            lazy_adam::catch_up_row(
                &mut a_sh_rest.m[moments.clone()],
                &mut a_sh_rest.v[moments],
                &mut m.sh[span.clone()],
                pending,
            );
            sh_finite &= m.sh[span.clone()].iter().all(|x| x.is_finite());
            self.activated.sh[span.clone()].copy_from_slice(&m.sh[span]);
            a_sh_rest.steps[b] = now;
        }
        alpha && colour && sh_finite
    }

    /// Relocates dead billboards now (spec §6; normally called by [`Trainer::step`] when due) and
    /// returns how many were moved.
    ///
    /// Dead slots get copies of sources sampled ∝ mean alpha with the trainer's RNG; alpha is split
    /// texel-wise (Gaussian mode: the opacity scalar is split). The Adam moments and update counts
    /// of both the sources and the dead slots are zeroed (the reference zeroes only the sources;
    /// a dead slot's stale moments belong to the billboard that died there).
    pub fn relocate(&mut self) -> usize {
        // Lazy Adam: the sources' textures and moments as dense Adam has them.
        self.catch_up(None, None);
        let plan = plan_relocation(&self.activated.mean_alphas(), &mut self.rng);
        if plan.is_empty() {
            return 0;
        }
        apply_relocation(&mut self.model, &plan);
        if self.config.texture_mode == TextureMode::Gaussian {
            for &(s, n) in &plan.multiplicity {
                self.opacity_logits[s] = split_alpha_logit(self.opacity_logits[s], n + 1);
            }
            for &(d, s) in &plan.moves {
                self.opacity_logits[d] = self.opacity_logits[s];
            }
        }
        let rows = plan
            .multiplicity
            .iter()
            .map(|&(s, _)| s)
            .chain(plan.moves.iter().map(|&(d, _)| d));
        for r in rows {
            for g in &mut self.adam {
                g.reset_row(r);
            }
            self.refresh_row(r);
        }
        plan.moves.len()
    }

    /// Grows the set one step toward [`TrainConfig::growth_cap`] now ([`grow`]; normally called
    /// by [`Trainer::step`] after relocation, on the same schedule) and returns how many
    /// billboards were added.
    ///
    /// New rows are copies of sources drawn ∝ mean alpha with the trainer's RNG, appended in
    /// draw order, alpha split texel-wise with their source (Gaussian mode: the opacity scalar
    /// is split). The new rows start with zero Adam moments and update counts; the sources'
    /// moments and counts are zeroed, as relocation does.
    pub fn grow(&mut self) -> usize {
        let n = self.model.len();
        let target = grow::growth_target(n, self.config.growth_cap);
        self.grow_rows(target - n, None)
    }

    /// The billboards of this step's growth placed on the view's error ([`place`]): the share
    /// [`TrainConfig::error_growth`] of `new_rows` (none in Gaussian mode). Fails only when a
    /// neighbouring view's image cannot be read (on demand).
    fn place_on_error(
        &mut self,
        new_rows: usize,
        out: &RenderOutput,
        target: &[f32],
        views: &[TrainView],
        vi: usize,
    ) -> Result<RawBillboards, TrainError> {
        let cam = &views[vi].camera;
        let share = if self.config.texture_mode == TextureMode::Full {
            self.config.error_growth
        } else {
            0.0
        };
        let count = (new_rows as f64 * share as f64).round() as usize;
        // With a loss mask, the error is that of the weighted images (none outside the mask).
        let weighted = views[vi].loss_mask.as_ref().map(|mask| {
            let (mut weighted_render, mut weighted_target) = (Vec::new(), Vec::new());
            crate::loss::masked::weight_pixels_into(&out.rgb, mask, 3, &mut weighted_render);
            crate::loss::masked::weight_pixels_into(target, mask, 3, &mut weighted_target);
            (weighted_render, weighted_target)
        });
        let (rendered, error_target) = match &weighted {
            None => (out.rgb.as_slice(), target),
            Some((rendered, weighted_target)) => (rendered.as_slice(), weighted_target.as_slice()),
        };
        let view = place::ViewError {
            rendered,
            target: error_target,
            median_depth: &out.median_depth,
        };
        // The depth where the neighbouring views agree on the pixel, searched around the
        // rendered depth; the rendered depth where no depth is distinct (an even surface).
        let sweep = depth_sweep::SweepConfig::default();
        let neighbours = if count > 0 {
            let centres: Vec<Vec3> = views.iter().map(|v| v.camera.centre()).collect();
            depth_sweep::nearest_views(&centres, vi, sweep.neighbours)
        } else {
            Vec::new()
        };
        // The view (its values are the target) and its neighbours, each read once.
        let mut fetched = vec![FetchedView {
            camera: *cam,
            rgb: std::borrow::Cow::Borrowed(target),
        }];
        for &j in &neighbours {
            let rgb = views[j].rgb.to_f32().map_err(|e| TrainError::ViewImage {
                view: j,
                message: e.to_string(),
            })?;
            fetched.push(FetchedView {
                camera: views[j].camera,
                rgb,
            });
        }
        let others: Vec<usize> = (1..fetched.len()).collect();
        let refine = |x: u32, y: u32, z: f32| -> f32 {
            let (near, far) = (z / place::SWEEP_RANGE, z * place::SWEEP_RANGE);
            match depth_sweep::sweep_pixel(&fetched, 0, &others, x, y, near, far, &sweep) {
                Some(found) if found.distinct() => found.depth,
                _ => z,
            }
        };
        Ok(place::place_on_error(
            &view,
            cam,
            count,
            self.model.texture_size,
            &mut self.rng,
            refine,
        ))
    }

    /// Appends `copies` copies of billboards drawn ∝ mean alpha ([`grow`]) and then the rows of
    /// `placed` (if any); returns how many rows were added.
    fn grow_rows(&mut self, copies: usize, placed: Option<RawBillboards>) -> usize {
        // Lazy Adam: the sources' textures and moments as dense Adam has them.
        self.catch_up(None, None);
        let n = self.model.len();
        let plan = grow::plan_growth(&self.activated.mean_alphas(), copies, &mut self.rng);
        let placed_rows = placed.as_ref().map_or(0, RawBillboards::len);
        if plan.is_empty() && placed_rows == 0 {
            return 0;
        }
        let total = n + plan.moves.len() + placed_rows;
        grow::apply_growth(&mut self.model, &plan);
        if let Some(placed) = &placed {
            grow::append_rows(&mut self.model, placed);
        }
        grow::extend_activated(&mut self.activated, total);
        grow::extend_gradients(&mut self.grads, total, self.model.texture_size);
        for g in &mut self.adam {
            grow::extend_adam(g, total);
        }
        if self.config.texture_mode == TextureMode::Gaussian {
            self.opacity_logits.resize(total, 0.0);
            for &(s, c) in &plan.multiplicity {
                self.opacity_logits[s] = split_alpha_logit(self.opacity_logits[s], c + 1);
            }
            for &(d, s) in &plan.moves {
                self.opacity_logits[d] = self.opacity_logits[s];
            }
        }
        for &(s, _) in &plan.multiplicity {
            for g in &mut self.adam {
                g.reset_row(s);
            }
            self.refresh_row(s);
        }
        for d in n..total {
            self.refresh_row(d);
        }
        total - n
    }

    /// Mean PSNR (on 8-bit quantised images, as the reference evaluates) over `views`, rendered
    /// with the full SH degree of the config.
    ///
    /// # Errors
    /// [`TrainError::ViewImage`] when a view's image cannot be read (on demand, its file went
    /// away or changed).
    pub fn evaluate(&self, views: &[TrainView]) -> Result<f64, TrainError> {
        let settings = RenderSettings {
            background: self.config.background,
            sh_degree: self.config.sh_degree,
            simd: self.config.simd,
            ..Default::default()
        };
        let mut buffers = RenderBuffers::default();
        // Lazy Adam: rendered with every row's pending steps applied (on a copy).
        let caught_up = self.lazy_textures().then(|| self.export_model().activate());
        let activated = caught_up.as_ref().unwrap_or(&self.activated);
        let mut total = 0.0;
        for (i, v) in views.iter().enumerate() {
            let truth = v.rgb.to_f32().map_err(|e| TrainError::ViewImage {
                view: i,
                message: e.to_string(),
            })?;
            let out = render_with(
                &activated.borrowed(),
                &v.camera,
                &settings,
                std::mem::take(&mut buffers),
            );
            total += psnr_u8(&out.rgb, &truth).unwrap_or(f64::NAN);
            buffers = out.into_buffers();
        }
        Ok(total / views.len().max(1) as f64)
    }
}

/// The Adam factors and mode of the geometry and SH groups in one step (see [`Trainer::apply`]).
#[derive(Clone, Copy)]
struct GeometryStep {
    /// Position, rotation, scale, SH degree 0 and SH rest: each group's factors at its dense step.
    factors: [StepFactors; 5],
    dense: bool,
    hp: AdamParams,
}

/// Mutable views of the per-row geometry and SH arrays of a model, of its activated copy or of
/// their gradients.
struct GeometryMut<'a> {
    positions: &'a mut [Vec3],
    quaternions: &'a mut [[f32; 4]],
    log_scales: &'a mut [glam::Vec2],
    sh: &'a mut [f32],
}

/// The gradients [`GeometryStep::row`] reads: positions, quaternions, log-scales, SH.
type GeometryGrads<'a> = (&'a [Vec3], &'a [[f32; 4]], &'a [glam::Vec2], &'a [f32]);

impl<'a> GeometryMut<'a> {
    fn of(
        positions: &'a mut [Vec3],
        quaternions: &'a mut [[f32; 4]],
        log_scales: &'a mut [glam::Vec2],
        sh: &'a mut [f32],
    ) -> Self {
        Self {
            positions,
            quaternions,
            log_scales,
            sh,
        }
    }

    fn reborrow(&mut self) -> GeometryMut<'_> {
        GeometryMut::of(self.positions, self.quaternions, self.log_scales, self.sh)
    }

    /// Copies row `b` into `to` (its SH rest only `with_sh_rest`).
    fn copy_row_to(&self, b: usize, to: &mut GeometryMut<'_>, with_sh_rest: bool) {
        to.positions[b] = self.positions[b];
        to.quaternions[b] = self.quaternions[b];
        to.log_scales[b] = self.log_scales[b];
        let sh = if with_sh_rest {
            b * SH_FLOATS..(b + 1) * SH_FLOATS
        } else {
            b * SH_FLOATS..b * SH_FLOATS + 3
        };
        to.sh[sh.clone()].copy_from_slice(&self.sh[sh]);
    }

    /// Sets row `b` to zero.
    fn zero_row(&mut self, b: usize) {
        self.positions[b] = Vec3::ZERO;
        self.quaternions[b] = [0.0; 4];
        self.log_scales[b] = glam::Vec2::ZERO;
        self.sh[b * SH_FLOATS..(b + 1) * SH_FLOATS].fill(0.0);
    }
}

/// A range of rows of every array the dense geometry step writes: the parameters, their
/// activated copy, their gradients and, per group (position, rotation, scale, SH DC, SH rest),
/// the moments and update counts; with lazy Adam, the rows' in-view flags.
struct GeometryRows<'a> {
    params: GeometryMut<'a>,
    activated: GeometryMut<'a>,
    grads: GeometryMut<'a>,
    moments: [GroupRows<'a>; 5],
    in_view: Option<&'a [bool]>,
}

/// One group's moments and update counts (`m`, `v`, `steps`) over a range of rows.
type GroupRows<'a> = (&'a mut [f32], &'a mut [f32], &'a mut [u32]);

/// Values per row of the position, rotation, scale, SH DC and SH rest groups.
const GEOMETRY_ROW_LENS: [usize; 5] = [3, 4, 2, 3, SH_FLOATS - 3];

/// Rows per task of the dense geometry step.
const GEOMETRY_CHUNK: usize = 4096;

impl<'a> GeometryMut<'a> {
    /// The first `mid` rows and the rest.
    fn split_at(self, mid: usize) -> (Self, Self) {
        let (p0, p1) = self.positions.split_at_mut(mid);
        let (q0, q1) = self.quaternions.split_at_mut(mid);
        let (s0, s1) = self.log_scales.split_at_mut(mid);
        let (h0, h1) = self.sh.split_at_mut(mid * SH_FLOATS);
        (GeometryMut::of(p0, q0, s0, h0), GeometryMut::of(p1, q1, s1, h1))
    }
}

impl<'a> GeometryRows<'a> {
    fn len(&self) -> usize {
        self.params.positions.len()
    }

    /// The first `mid` rows and the rest.
    fn split_at(self, mid: usize) -> (Self, Self) {
        let (p0, p1) = self.params.split_at(mid);
        let (a0, a1) = self.activated.split_at(mid);
        let (g0, g1) = self.grads.split_at(mid);
        let mut m0: [Option<GroupRows<'a>>; 5] = Default::default();
        let mut m1: [Option<GroupRows<'a>>; 5] = Default::default();
        for (i, (m, v, steps)) in self.moments.into_iter().enumerate() {
            let n = GEOMETRY_ROW_LENS[i];
            let (ma, mb) = m.split_at_mut(mid * n);
            let (va, vb) = v.split_at_mut(mid * n);
            let (sa, sb) = steps.split_at_mut(mid);
            m0[i] = Some((ma, va, sa));
            m1[i] = Some((mb, vb, sb));
        }
        let (f0, f1) = match self.in_view {
            Some(f) => {
                let (x, y) = f.split_at(mid);
                (Some(x), Some(y))
            }
            None => (None, None),
        };
        let unwrap = |m: [Option<GroupRows<'a>>; 5]| m.map(|g| g.expect("every group split"));
        (
            GeometryRows {
                params: p0,
                activated: a0,
                grads: g0,
                moments: unwrap(m0),
                in_view: f0,
            },
            GeometryRows {
                params: p1,
                activated: a1,
                grads: g1,
                moments: unwrap(m1),
                in_view: f1,
            },
        )
    }
}

impl GeometryStep {
    /// The dense step of every row of `rows` ([`GeometryStep::row`], then the row copied to the
    /// activated set and its gradients zeroed), in parallel chunks of [`GEOMETRY_CHUNK`] rows:
    /// each row's arithmetic is that of the serial loop, so the bits do not depend on the split.
    /// With lazy Adam (`in_view` set), SH rest steps only on the rows in view, each marked up to
    /// date through `sh_rest_now`.
    fn rows(&self, rows: GeometryRows<'_>, lr: &LearningRates, sh_rest_now: u32) {
        if rows.len() > GEOMETRY_CHUNK {
            let mid = rows.len() / 2;
            let (a, b) = rows.split_at(mid);
            rayon::join(|| self.rows(a, lr, sh_rest_now), || self.rows(b, lr, sh_rest_now));
            return;
        }
        let GeometryRows {
            mut params,
            mut activated,
            mut grads,
            mut moments,
            in_view,
        } = rows;
        for r in 0..params.positions.len() {
            let with_sh_rest = in_view.is_none_or(|f| f[r]);
            let read = (&*grads.positions, &*grads.quaternions, &*grads.log_scales, &*grads.sh);
            self.row(r, lr, &mut moments, params.reborrow(), read, with_sh_rest);
            if with_sh_rest && in_view.is_some() {
                moments[4].2[r] = sh_rest_now;
            }
            params.copy_row_to(r, &mut activated, with_sh_rest);
            grads.zero_row(r);
        }
    }

    /// One Adam step of row `b` of one group's moments and counts (`n` values a row): with the
    /// group's `factors` of this step when dense, else with the row's own count and `lr`
    /// (row-sparse; [`AdamGroup::step_row`]). Counts the update in the row's count.
    #[allow(clippy::too_many_arguments)]
    fn update(
        &self,
        (m, v, steps): &mut GroupRows<'_>,
        n: usize,
        b: usize,
        params: &mut [f32],
        grads: &[f32],
        lr: f32,
        factors: StepFactors,
    ) {
        steps[b] = steps[b].saturating_add(1);
        let factors = if self.dense {
            factors
        } else {
            StepFactors::new(lr, &self.hp, u64::from(steps[b]))
        };
        let span = b * n..(b + 1) * n;
        update_row_with(&mut m[span.clone()], &mut v[span], params, grads, factors, &self.hp);
    }

    /// [`GeometryStep::update`] of row `b` of `group`.
    fn group_row(
        &self,
        group: &mut AdamGroup,
        b: usize,
        params: &mut [f32],
        grads: &[f32],
        lr: f32,
        factors: StepFactors,
    ) {
        let n = group.row_len;
        let mut rows = (&mut group.m[..], &mut group.v[..], &mut group.steps[..]);
        self.update(&mut rows, n, b, params, grads, lr, factors);
    }

    /// One Adam step of row `b` of the position, rotation, scale, SH degree-0 and (when
    /// `with_sh_rest`) SH rest groups (`moments`, in that order) on `params` with the gradients
    /// `grads`.
    fn row(
        &self,
        b: usize,
        lr: &LearningRates,
        moments: &mut [GroupRows<'_>; 5],
        params: GeometryMut<'_>,
        (d_pos, d_quat, d_scale, d_sh): GeometryGrads<'_>,
        with_sh_rest: bool,
    ) {
        let [f_pos, f_rot, f_scale, f_sh_dc, f_sh_rest] = self.factors;
        let [pos, rot, scale, dc, rest] = moments;
        let [n_pos, n_rot, n_scale, n_dc, n_rest] = GEOMETRY_ROW_LENS;
        self.update(
            pos,
            n_pos,
            b,
            params.positions[b].as_mut(),
            &d_pos[b].to_array(),
            lr.position,
            f_pos,
        );
        self.update(
            rot,
            n_rot,
            b,
            &mut params.quaternions[b],
            &d_quat[b],
            lr.rotation,
            f_rot,
        );
        self.update(
            scale,
            n_scale,
            b,
            params.log_scales[b].as_mut(),
            &d_scale[b].to_array(),
            lr.scale,
            f_scale,
        );
        // SH: degree 0 (3 values) and degrees 1-3 (45 values) have their own rates.
        let (sh, d_sh) = (
            &mut params.sh[b * SH_FLOATS..(b + 1) * SH_FLOATS],
            &d_sh[b * SH_FLOATS..(b + 1) * SH_FLOATS],
        );
        let (sh_dc, sh_rest) = sh.split_at_mut(3);
        self.update(dc, n_dc, b, sh_dc, &d_sh[..3], lr.sh_dc, f_sh_dc);
        if with_sh_rest {
            self.update(rest, n_rest, b, sh_rest, &d_sh[3..], lr.sh_rest, f_sh_rest);
        }
    }
}
