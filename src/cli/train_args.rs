//! The flags of `bbsplat train` and the library request they make
//! ([`bbsplat::plan::TrainRequest`]); their defaults are the library's.

use bbsplat::plan::{self, InitMethod, RunLength, TrainRequest};
use bbsplat::train::geometry::GeometryRegularisers;
use bbsplat::train::resolution::ResolutionSchedule;
use bbsplat::train::{AdamMode, ClampGradient, LearningRateScales, TextureMode};
use clap::builder::{PossibleValuesParser, TypedValueParser};
use clap::{Args, ValueEnum};
use std::path::PathBuf;

use super::common::SceneArgs;

/// Flags of `bbsplat train`.
#[derive(Args, Clone, Debug)]
pub struct TrainArgs {
    /// The dataset: a COLMAP, NeRF-synthetic, NeuS/IDR (cameras_sphere.npz) or LLFF
    /// (poses_bounds.npy) folder, or a transforms.json (auto-detected).
    pub scene: PathBuf,
    /// Output folder (model, checkpoints, summary.json).
    #[arg(short, long)]
    pub output: PathBuf,
    #[command(flatten)]
    pub scene_args: SceneArgs,
    /// Optimisation steps, one image each (the reference's 32 000 is the 100 % point of every
    /// schedule; all milestones scale with this number). Default 7000, unless `--minutes` is
    /// given. Exact and reproducible, unlike `--minutes`.
    #[arg(long, conflicts_with = "minutes")]
    pub iterations: Option<usize>,
    /// A time budget: train for this many minutes of step time (evaluations and saving not
    /// counted), the number of steps and every schedule planned from the step time measured
    /// while training (see docs/training.md). The plan is in the checkpoint: `--resume`
    /// continues it.
    #[arg(long, value_parser = positive_minutes)]
    pub minutes: Option<f64>,
    /// Billboard count (default: derived from the scene, see docs/training.md).
    #[arg(long)]
    pub billboards: Option<usize>,
    /// Texture side TS (TS×TS alpha and colour texels per billboard).
    #[arg(long, default_value_t = plan::DEFAULT_TEXTURE_SIZE)]
    pub texture_size: usize,
    /// Highest SH degree (0-3).
    #[arg(long, default_value_t = 3)]
    pub sh_degree: u32,
    /// Seed of the initialisation and of the view order.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Rayon worker threads (default: all cores). Results do not depend on it.
    #[arg(long)]
    pub threads: Option<usize>,
    /// Evaluate on the test views every n steps (0: only at the end).
    #[arg(long, default_value_t = 1000)]
    pub eval_every: usize,
    /// At most this many test views (evenly spaced) in the intermediate evaluations, at least 1
    /// (a number at least the test view count takes them all; no intermediate evaluation:
    /// --eval-every 0); the final evaluation uses all of them.
    #[arg(long, default_value_t = 25, value_parser = super::flag_parsers::count_between::<1, { usize::MAX }>)]
    pub eval_views: usize,
    /// Write a checkpoint every n steps (0: only on Ctrl-C).
    #[arg(long, default_value_t = 0)]
    pub save_every: usize,
    /// No progress bar or per-evaluation lines; the final summary is still printed.
    #[arg(long)]
    pub quiet: bool,
    /// Serve a live view of the training on http://127.0.0.1:<port>/ (printed as `live view at
    /// ...`): the WebGL2 viewer page, its model refreshed every --view-every steps, with the
    /// step's camera, loss and PSNR (to this machine only, as `view --serve`; docs/export.md).
    #[arg(long)]
    pub view: bool,
    /// Port of --view (0: any free port).
    #[arg(long, default_value_t = 0, requires = "view")]
    pub view_port: u16,
    /// Steps between two models handed to --view (at least 1).
    #[arg(long, default_value_t = 100, requires = "view", value_parser = clap::value_parser!(u64).range(1..))]
    pub view_every: u64,
    /// Also compute LPIPS of the final test views (8-bit images, as `bbsplat eval --lpips`) into
    /// summary.json: `--lpips` is VGG16 as the reference evaluates, `--lpips=alex` AlexNet. Off
    /// by default: VGG costs seconds per 400×400 view on 2 cores (docs/lpips.md). Needs the
    /// weights (`python3 tools/lpips_weights.py`); without them the run trains and the
    /// summary's `lpips_note` says why LPIPS is missing.
    #[arg(long, value_enum, num_args = 0..=1, require_equals = true, default_missing_value = "vgg", value_name = "NETWORK")]
    pub lpips: Option<super::common::LpipsNetwork>,
    /// Threshold σ of the texture regulariser (paper Eq. 9) on a billboard's per-view impact
    /// (Σ α·T over its pixels): billboards with less impact have their textures pulled to the
    /// initial state. The paper uses 500; the current reference code 100.
    #[arg(long, default_value_t = bbsplat::train::regularise::IMPACT_THRESHOLD)]
    pub texture_threshold: f32,
    /// `full`: learned alpha and colour textures (BBSplat); `gaussian`: plain Gaussian billboards
    /// with one opacity each and SH colour only (the "textures off" ablation).
    #[arg(long, default_value_t = TextureMode::Full, value_parser = texture_mode())]
    pub texture_mode: TextureMode,
    /// `dense`: every billboard takes an Adam step each iteration (the reference); `lazy`: dense
    /// Adam whose texture and SH-rest rows step when a view sees them, their skipped steps
    /// applied then (a step's cost follows what the view sees: for large captures); `sparse`:
    /// only billboards the view touched, with per-row bias correction.
    #[arg(long, value_enum, default_value_t = AdamModeArg::Dense)]
    pub adam: AdamModeArg,
    /// Do not recycle dead billboards (mean alpha ≤ 0.005).
    #[arg(long)]
    pub no_relocate: bool,
    /// Grow the set by 5 % every 100 steps (spec §6) up to this many billboards (0: no growth).
    /// Default: from the scene (see docs/training.md).
    #[arg(long)]
    pub growth_cap: Option<usize>,
    /// Share (0-1) of each growth step's new billboards placed where the view just trained on
    /// is rendered worst (camera-facing, at the depth where the neighbouring views agree, in
    /// the target colour) instead of copied from existing billboards ∝ alpha (0: the
    /// reference's growth). Default: from the scene, 1 without SfM points and 0 with them
    /// (docs/quality.md).
    #[arg(long, value_parser = fraction)]
    pub error_growth: Option<f32>,
    /// Stop after this many steps (of `--iterations`) with a checkpoint, as Ctrl-C does: lets a
    /// long run be done in slices with `--resume`.
    #[arg(long)]
    pub stop_after: Option<usize>,
    /// Continue from a checkpoint written by an earlier run (Ctrl-C, a signal, `--stop-after` or
    /// `--save-every`) with the same scene and flags: a different dataset or a flag that changes
    /// the model or the optimisation is refused. Continuing is bit-identical to not stopping.
    #[arg(long)]
    pub resume: Option<PathBuf>,
    /// Replace the run the output folder already holds (without it, such a folder is refused
    /// unless the run is continued with `--resume`). Its files are replaced one by one, each
    /// atomically, as this run writes its own.
    #[arg(long)]
    pub overwrite: bool,
    /// Initialisation of scenes without SfM points, in the box the cameras look at: `auto`
    /// (the hull when the images have alpha masks, else random points plus a background shell),
    /// `random` points (the reference), or `hull`: points on the visual hull carved from the
    /// images' alpha masks (RGBA images such as NeRF-synthetic; see docs/training.md).
    #[arg(long, value_enum, default_value_t = InitArg::Auto)]
    pub init: InitArg,
    /// Start from the billboards of this model folder (a `bbsplat train` output's `model/`, or
    /// a block's `init/` written by `bbsplat blocks split`) instead of initialising them from the
    /// scene; its texture size must be --texture-size. Growth and relocation go on from it.
    #[arg(long, value_name = "MODEL", conflicts_with = "billboards")]
    pub init_model: Option<PathBuf>,
    /// Train and evaluate only the views named in this file, one image name per line as the
    /// scene names them (blank lines and lines starting with `#` skipped); each keeps its split,
    /// so a test view is never trained on. The scene extent follows the training views kept.
    /// How a block trains on its own views (`bbsplat blocks split` writes the file).
    #[arg(long, value_name = "FILE")]
    pub views: Option<PathBuf>,
    /// Voxels per side of the `--init hull` grid.
    #[arg(long, default_value_t = plan::DEFAULT_HULL_RESOLUTION)]
    pub hull_resolution: usize,
    /// Coarse-to-fine: train the first `--coarse-until` of the run on images downscaled by this
    /// factor (1: off, the reference). A coarse step costs about 1/factor² of a full one.
    /// Default 2 (measured on lego, docs/quality.md).
    #[arg(long, default_value_t = plan::DEFAULT_COARSE_FACTOR)]
    pub coarse_factor: u32,
    /// Fraction of the run (0-1) trained on the coarse images when `--coarse-factor` > 1.
    #[arg(long, default_value_t = plan::DEFAULT_COARSE_UNTIL)]
    pub coarse_until: f64,
    /// Multiply every learning rate by this factor (1: the reference's rates; the schedules are
    /// unchanged). Default: a factor of the run length (4 up to 7000 steps, 1 at the reference's
    /// 32 000, log-linear between; measured on lego, see docs/quality.md), used when no
    /// learning-rate flag is given.
    #[arg(long, value_parser = non_negative)]
    pub lr_scale: Option<f32>,
    /// Learning-rate factor of the positions (default: `--lr-scale`).
    #[arg(long, value_parser = non_negative)]
    pub lr_position: Option<f32>,
    /// Learning-rate factor of the SH coefficients (default: `--lr-scale`).
    #[arg(long, value_parser = non_negative)]
    pub lr_sh: Option<f32>,
    /// Learning-rate factor of the log-scales and quaternions (default: `--lr-scale`).
    #[arg(long, value_parser = non_negative)]
    pub lr_shape: Option<f32>,
    /// Learning-rate factor of the alpha and colour textures (default: `--lr-scale`).
    #[arg(long, value_parser = non_negative)]
    pub lr_texture: Option<f32>,
    /// Gradient through the compositing clamp `α = min(0.99, a)`: `exact` (the derivative of the
    /// forward: none above the clamp) or `straight-through` (as if unclamped, as the reference
    /// rasterizer does). See docs/training.md.
    #[arg(long, value_enum, default_value_t = ClampGradientArg::Exact)]
    pub clamp_gradient: ClampGradientArg,
    /// Weight of the 2DGS normal-consistency regulariser (0: off, the reference's default; its
    /// DTU scripts use 0.05): the rendered normals are pulled toward the normals of the rendered
    /// depth. See docs/training.md.
    #[arg(long, default_value_t = 0.0, value_parser = non_negative)]
    pub lambda_normal: f32,
    /// Weight of the 2DGS depth-distortion regulariser (0: off, the reference's default; its DTU
    /// scripts use 100 to 1000): concentrates each pixel's blending weights in depth.
    #[arg(long, default_value_t = 0.0, value_parser = non_negative)]
    pub lambda_dist: f32,
    /// Fraction of the run (0-1) after which `--lambda-normal` applies (default 7000/32000, the
    /// reference's iteration 7000; with `--minutes`, of the planned steps).
    #[arg(long, default_value_t = bbsplat::train::geometry::NORMAL_FROM, value_parser = fraction)]
    pub normal_from: f32,
    /// Fraction of the run (0-1) after which `--lambda-dist` applies (default 3000/32000, the
    /// reference's iteration 3000; with `--minutes`, of the planned steps).
    #[arg(long, default_value_t = bbsplat::train::geometry::DISTORTION_FROM, value_parser = fraction)]
    pub dist_from: f32,
}

/// A number in `[0, 1]` (the regularisers' start fractions).
fn fraction(text: &str) -> Result<f32, String> {
    match text.parse::<f32>() {
        Ok(x) if (0.0..=1.0).contains(&x) => Ok(x),
        Ok(x) => Err(format!("{x} is not a fraction in [0, 1]")),
        Err(e) => Err(format!("{text:?} is not a number: {e}")),
    }
}

/// `--minutes`: a finite number > 0.
fn positive_minutes(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(x) if x.is_finite() && x > 0.0 => Ok(x),
        Ok(x) => Err(format!("{x} is not a finite number > 0")),
        Err(e) => Err(format!("{text:?} is not a number: {e}")),
    }
}

/// A finite number ≥ 0 (the learning-rate factors).
fn non_negative(text: &str) -> Result<f32, String> {
    match text.parse::<f32>() {
        Ok(x) if x.is_finite() && x >= 0.0 => Ok(x),
        Ok(x) => Err(format!("{x} is not a finite number ≥ 0")),
        Err(e) => Err(format!("{text:?} is not a number: {e}")),
    }
}

/// `--texture-mode`: the library's names ([`TextureMode::as_str`]), listed in `--help` and in
/// the error for any other value.
fn texture_mode() -> impl TypedValueParser<Value = TextureMode> {
    PossibleValuesParser::new(TextureMode::ALL.map(TextureMode::as_str))
        .map(|name| name.parse::<TextureMode>().expect("one of the listed names"))
}

impl TrainArgs {
    /// The library's request for these flags ([`bbsplat::plan::TrainPlan::new`] chooses what
    /// they leave open).
    pub fn request(&self) -> TrainRequest {
        TrainRequest {
            length: match (self.iterations, self.minutes) {
                (_, Some(m)) => RunLength::Minutes(m),
                (Some(n), None) => RunLength::Steps(n),
                (None, None) => RunLength::default(),
            },
            billboards: self.billboards,
            growth_cap: self.growth_cap,
            error_growth: self.error_growth,
            lr_scales: (!self.lr_by_run_length()).then(|| self.lr_scales()),
            init: match self.init {
                InitArg::Auto => InitMethod::Auto,
                InitArg::Random => InitMethod::Random,
                InitArg::Hull => InitMethod::Hull,
            },
            hull_resolution: self.hull_resolution,
            texture_size: self.texture_size,
            sh_degree: self.sh_degree,
            seed: self.seed,
            texture_threshold: self.texture_threshold,
            texture_mode: self.texture_mode,
            adam: match self.adam {
                AdamModeArg::Dense => AdamMode::Dense,
                AdamModeArg::Sparse => AdamMode::Sparse,
                AdamModeArg::Lazy => AdamMode::Lazy,
            },
            relocate: !self.no_relocate,
            clamp_gradient: self.clamp_gradient.into(),
            geometry: self.geometry(),
            resolution: ResolutionSchedule {
                factor: self.coarse_factor,
                until: self.coarse_until,
            },
        }
    }

    /// The learning-rate multipliers of the flags (1 where none is given).
    pub fn lr_scales(&self) -> LearningRateScales {
        let all = self.lr_scale.unwrap_or(1.0);
        LearningRateScales {
            position: self.lr_position.unwrap_or(all),
            sh: self.lr_sh.unwrap_or(all),
            shape: self.lr_shape.unwrap_or(all),
            texture: self.lr_texture.unwrap_or(all),
        }
    }

    /// The geometry regularisers of the flags.
    pub fn geometry(&self) -> GeometryRegularisers {
        GeometryRegularisers {
            lambda_normal: self.lambda_normal,
            lambda_distortion: self.lambda_dist,
            normal_from: self.normal_from,
            distortion_from: self.dist_from,
        }
    }

    /// True when no learning-rate flag is given: the rates then follow the run length
    /// ([`bbsplat::train::run_length_lr_factor`]).
    pub fn lr_by_run_length(&self) -> bool {
        [
            self.lr_scale,
            self.lr_position,
            self.lr_sh,
            self.lr_shape,
            self.lr_texture,
        ]
        .iter()
        .all(Option::is_none)
    }
}

/// `--init`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum InitArg {
    /// The hull when the images have alpha masks, else random points plus a background shell.
    Auto,
    /// Uniform random points in the scene box.
    Random,
    /// Points on the surface of the visual hull of the alpha masks.
    Hull,
}

/// `--clamp-gradient`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ClampGradientArg {
    /// Zero gradient where the clamp is active.
    Exact,
    /// The gradient passes through the clamp.
    StraightThrough,
}

impl From<ClampGradientArg> for ClampGradient {
    fn from(c: ClampGradientArg) -> Self {
        match c {
            ClampGradientArg::Exact => ClampGradient::Exact,
            ClampGradientArg::StraightThrough => ClampGradient::PassThrough,
        }
    }
}

/// `--adam`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum AdamModeArg {
    /// All rows every step.
    Dense,
    /// Touched rows only.
    Sparse,
    /// Dense Adam, texture rows brought up to date when a view sees them.
    Lazy,
}
