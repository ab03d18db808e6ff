//! The training configuration `bbsplat train` uses, chosen for a scene: the library's front
//! door to the defaults that win.
//!
//! [`TrainConfig::default`] is the reference's configuration (32 000 steps at its learning
//! rates, no growth, full resolution throughout). Runs of a few thousand steps on two cores do
//! much better with settings chosen from the scene and the run length: the billboard budget and
//! growth cap from the views and SfM points ([`crate::init::budget`]), where growth places its
//! billboards, the initialisation (SfM points, the visual hull of alpha masks, or random points
//! plus a background shell), learning rates scaled to the run length
//! ([`crate::train::run_length_lr_factor`]) and a coarse-to-fine schedule. [`TrainPlan::new`]
//! makes those choices, each with its reason ([`AutoChoice`]), from a [`Scene`] and a
//! [`TrainRequest`] that fixes whatever the caller wants fixed. `bbsplat train` builds its
//! request from its flags and calls exactly this, so a program that embeds the crate gets the
//! same model as the command line for the same scene, request and seed (tested bit for bit in
//! `tests/suite/plan.rs`).
//!
//! The background is chosen when the scene is loaded, from the data (white for NeRF-synthetic
//! images with alpha, black otherwise): load with [`crate::scene::data_background::load_with_data_background`] and pass its
//! [`BackgroundChoice`] so that the choice is recorded with the others.
//!
//! ```no_run
//! use bbsplat::plan::{RunLength, TrainPlan, TrainRequest};
//! use bbsplat::scene::{LoadOptions, data_background::load_with_data_background};
//! use bbsplat::train::{StopSignal, TrainView};
//!
//! let (scene, background) = load_with_data_background("data/lego".as_ref(), &LoadOptions::default())?;
//! let request = TrainRequest { length: RunLength::Minutes(5.0), ..TrainRequest::default() };
//! let plan = TrainPlan::new(&scene, Some(&background), &request)?;
//! for choice in &plan.choices {
//!     println!("{}: {} ({})", choice.setting, choice.value, choice.reason);
//! }
//! let (model, _) = plan.init_model(&scene)?;
//! let mut trainer = plan.trainer(model);
//! let (train, test) = (TrainView::from_views(&scene.train), TrainView::from_views(&scene.test));
//! let settings = bbsplat::RunConfig { output: Some("out/lego".into()), ..plan.run_config() };
//! bbsplat::run(&mut trainer, &train, &test, &settings, &StopSignal::new(), |_| {})?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use crate::init::budget::{BudgetInputs, budget_for, growth_cap};
use crate::init::hull::HullConfig;
use crate::init::scene_init::{InitError, InitReport, PointlessInit, init_model_with};
use crate::model::RawBillboards;
use crate::model_file::MAX_TEXTURE_SIZE;
use crate::report::AutoChoice;
use crate::scene::Scene;
use crate::scene::data_background::BackgroundChoice;
use crate::train::footprint::scene_training_bytes;
use crate::train::geometry::GeometryRegularisers;
use crate::train::resolution::ResolutionSchedule;
use crate::train::run::RunConfig;
use crate::train::time_budget::TimePlan;
use crate::train::{
    AdamMode, ClampGradient, LearningRateScales, TextureMode, TrainConfig, Trainer, run_length_lr_factor,
};
use glam::Vec3;

/// Steps of a run whose length is not given (`bbsplat train` without `--iterations` or
/// `--minutes`).
pub const DEFAULT_STEPS: usize = 7000;

/// Default texture side TS.
pub const DEFAULT_TEXTURE_SIZE: usize = 16;

/// Default downscale factor of the coarse phase of the coarse-to-fine schedule (measured on
/// lego, `docs/quality.md`).
pub const DEFAULT_COARSE_FACTOR: u32 = 2;

/// Default fraction of the run trained on the coarse images.
pub const DEFAULT_COARSE_UNTIL: f64 = 0.5;

/// Default voxels per side of the visual-hull grid.
pub const DEFAULT_HULL_RESOLUTION: usize = 128;

/// Largest hull grid side accepted (1024³ voxels is already 1.1 G voxels, each projected into
/// every view).
pub const MAX_HULL_RESOLUTION: usize = 1024;

/// Largest coarse-phase downscale factor accepted.
pub const MAX_COARSE_FACTOR: u32 = 64;

/// How long a run is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RunLength {
    /// Exactly this many steps: reproducible to the bit.
    Steps(usize),
    /// This many minutes of step time: the steps and every schedule are planned from the step
    /// time measured while training ([`crate::train::time_budget`]); the result depends on the
    /// machine's speed.
    Minutes(f64),
}

impl Default for RunLength {
    fn default() -> Self {
        Self::Steps(DEFAULT_STEPS)
    }
}

/// How a scene without SfM points is initialised.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum InitMethod {
    /// The visual hull when the images have alpha masks, else random points in the box the
    /// cameras look at plus a background shell; with SfM points, the points, the sky sphere and
    /// a background shell.
    #[default]
    Auto,
    /// Uniform random points in the scene box (the reference).
    Random,
    /// Points on the visual hull carved from the images' alpha masks.
    Hull,
}

/// What the caller fixes. Every `None` is chosen by [`TrainPlan::new`] from the scene; the other
/// fields' defaults are `bbsplat train`'s.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrainRequest {
    /// The run's length (default [`DEFAULT_STEPS`] steps).
    pub length: RunLength,
    /// Initial billboard count (default: from the scene, [`crate::init::budget::budget_for`]).
    pub billboards: Option<usize>,
    /// Growth cap, 0 for no growth (default: from the scene, [`crate::init::budget::growth_cap`]).
    pub growth_cap: Option<usize>,
    /// Share (0-1) of growth placed on the worst pixels ([`TrainConfig::error_growth`]; default:
    /// 1 without SfM points, 0 with them).
    pub error_growth: Option<f32>,
    /// Learning-rate multipliers (default: every rate times the run-length factor
    /// [`run_length_lr_factor`], followed as a time budget re-plans the length).
    pub lr_scales: Option<LearningRateScales>,
    /// Initialisation of scenes without SfM points (default [`InitMethod::Auto`]).
    pub init: InitMethod,
    /// Voxels per side of the visual-hull grid (default [`DEFAULT_HULL_RESOLUTION`]).
    pub hull_resolution: usize,
    /// Texture side TS (default [`DEFAULT_TEXTURE_SIZE`]).
    pub texture_size: usize,
    /// Highest SH degree, 0-3 (default 3).
    pub sh_degree: u32,
    /// Seed of the initialisation, the view order and relocation (default 0).
    pub seed: u64,
    /// Threshold σ of the texture regulariser (default 500, the paper's).
    pub texture_threshold: f32,
    /// Learned textures or Gaussian billboards (default full textures).
    pub texture_mode: TextureMode,
    /// Dense or row-sparse Adam (default dense, the reference).
    pub adam: AdamMode,
    /// Recycle dead billboards (default on).
    pub relocate: bool,
    /// The gradient through the compositing clamp (default exact).
    pub clamp_gradient: ClampGradient,
    /// The 2DGS normal and depth-distortion regularisers (default off).
    pub geometry: GeometryRegularisers,
    /// Coarse-to-fine schedule (default: the first half on images downscaled by 2).
    pub resolution: ResolutionSchedule,
}

impl Default for TrainRequest {
    fn default() -> Self {
        Self {
            length: RunLength::default(),
            billboards: None,
            growth_cap: None,
            error_growth: None,
            lr_scales: None,
            init: InitMethod::Auto,
            hull_resolution: DEFAULT_HULL_RESOLUTION,
            texture_size: DEFAULT_TEXTURE_SIZE,
            sh_degree: 3,
            seed: 0,
            texture_threshold: crate::train::regularise::IMPACT_THRESHOLD,
            texture_mode: TextureMode::Full,
            adam: AdamMode::Dense,
            relocate: true,
            clamp_gradient: ClampGradient::Exact,
            geometry: GeometryRegularisers::default(),
            resolution: ResolutionSchedule {
                factor: DEFAULT_COARSE_FACTOR,
                until: DEFAULT_COARSE_UNTIL,
            },
        }
    }
}

/// A setting of a [`TrainRequest`] out of range.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{setting} {problem}")]
pub struct PlanError {
    /// The setting, named as `bbsplat train`'s flag without the dashes (`texture-size`).
    pub setting: &'static str,
    /// What is wrong, with the value given.
    pub problem: String,
}

fn problem(setting: &'static str, problem: String) -> Result<(), PlanError> {
    Err(PlanError { setting, problem })
}

impl TrainRequest {
    /// The first setting out of range, named as its flag: texture size 2 to
    /// [`MAX_TEXTURE_SIZE`], billboards ≥ 1, SH degree ≤ 3, steps ≥ 1, minutes finite and > 0,
    /// shares and fractions in `[0, 1]`, the threshold finite and ≥ 0, the hull grid 2 to
    /// [`MAX_HULL_RESOLUTION`], the coarse factor 1 to [`MAX_COARSE_FACTOR`], learning-rate
    /// factors finite and ≥ 0, the geometry regularisers as [`GeometryRegularisers::problem`].
    ///
    /// # Errors
    /// The first [`PlanError`] found, in the order above.
    pub fn check(&self) -> Result<(), PlanError> {
        let ts = self.texture_size;
        if ts < 2 {
            problem("texture-size", format!("must be at least 2 (got {ts})"))?;
        }
        if ts > MAX_TEXTURE_SIZE {
            problem(
                "texture-size",
                format!("must be at most {MAX_TEXTURE_SIZE} (got {ts}): a model folder cannot store larger textures"),
            )?;
        }
        if self.billboards == Some(0) {
            problem("billboards", "must be at least 1".into())?;
        }
        if self.sh_degree > 3 {
            problem("sh-degree", format!("must be 0, 1, 2 or 3 (got {})", self.sh_degree))?;
        }
        match self.length {
            RunLength::Steps(0) => problem("iterations", "must be at least 1".into())?,
            RunLength::Minutes(m) if !(m.is_finite() && m > 0.0) => {
                problem("minutes", format!("must be a finite number > 0 (got {m})"))?
            }
            _ => {}
        }
        if let Some(share) = self.error_growth
            && !(0.0..=1.0).contains(&share)
        {
            problem("error-growth", format!("must be a share between 0 and 1 (got {share})"))?;
        }
        let factor = self.resolution.factor;
        if !(1..=MAX_COARSE_FACTOR).contains(&factor) {
            problem(
                "coarse-factor",
                format!("must be between 1 and {MAX_COARSE_FACTOR} (got {factor})"),
            )?;
        }
        if !(0.0..=1.0).contains(&self.resolution.until) {
            problem(
                "coarse-until",
                format!("must be a fraction between 0 and 1 (got {})", self.resolution.until),
            )?;
        }
        let t = self.texture_threshold;
        if !(t.is_finite() && t >= 0.0) {
            problem("texture-threshold", format!("must be a finite number ≥ 0 (got {t})"))?;
        }
        let r = self.hull_resolution;
        if !(2..=MAX_HULL_RESOLUTION).contains(&r) {
            problem(
                "hull-resolution",
                format!("must be between 2 and {MAX_HULL_RESOLUTION} (got {r})"),
            )?;
        }
        if let Some(scales) = self.lr_scales
            && let Some(bad) = scales.to_array().into_iter().find(|f| !(f.is_finite() && *f >= 0.0))
        {
            problem("lr-scale", format!("factors must be finite numbers ≥ 0 (got {bad})"))?;
        }
        if let Some(text) = self.geometry.problem() {
            problem("lambda-normal/lambda-dist", text)?;
        }
        Ok(())
    }
}

/// The full training configuration for one scene, with every automatic choice and its reason.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainPlan {
    /// The trainer's settings (its `iterations` is the provisional length of a time budget).
    pub config: TrainConfig,
    /// Initial billboard count.
    pub billboards: usize,
    /// Texture side TS.
    pub texture_size: usize,
    /// How the billboards are initialised.
    pub init: PointlessInit,
    /// Coarse-to-fine schedule ([`RunConfig::resolution`]).
    pub resolution: ResolutionSchedule,
    /// The time budget, for a [`RunLength::Minutes`] run.
    pub time_plan: Option<TimePlan>,
    /// The settings chosen here and why, in the order `bbsplat train` prints them (only those
    /// the request left open).
    pub choices: Vec<AutoChoice>,
}

fn choice(setting: &str, value: impl ToString, reason: impl Into<String>) -> AutoChoice {
    AutoChoice {
        setting: setting.into(),
        value: value.to_string(),
        reason: reason.into(),
    }
}

impl TrainPlan {
    /// Plans a run on `scene` as `request` asks, choosing what it leaves open. `background` is
    /// how the scene's background was chosen when it was loaded
    /// ([`crate::scene::data_background::load_with_data_background`]), recorded as a choice; `None` when the caller chose it.
    ///
    /// # Errors
    /// A setting of `request` out of range ([`TrainRequest::check`]).
    pub fn new(
        scene: &Scene,
        background: Option<&BackgroundChoice>,
        request: &TrainRequest,
    ) -> Result<Self, PlanError> {
        request.check()?;
        let mut choices = Vec::new();
        if let Some(b) = background {
            let name = if b.background.rgb() == [1.0; 3] {
                "white"
            } else {
                "black"
            };
            choices.push(choice("background", name, b.reason.clone()));
        }
        let inputs = BudgetInputs::from_scene(scene, request.texture_size);
        let billboards = request.billboards.unwrap_or_else(|| {
            let b = budget_for(&inputs);
            choices.push(choice("billboards", b.billboards, b.reason));
            b.billboards
        });
        let growth_cap = request.growth_cap.unwrap_or_else(|| {
            let cap = growth_cap(&inputs, billboards);
            choices.push(choice("growth-cap", cap.billboards, cap.reason));
            cap.billboards
        });
        // A finite SfM point, as the budget rule counts them.
        let has_points = inputs.sfm_points.is_some();
        let error_growth = request.error_growth.unwrap_or_else(|| {
            let (share, reason) = if has_points {
                (
                    0,
                    "the scene has SfM points: growth copies billboards in proportion to alpha, as the reference \
                     (placing them on the error lost 0.2-0.6 dB on beer_colmap at 30 minutes)",
                )
            } else {
                (
                    1,
                    "no SfM points: growth places its billboards on the worst pixels of the view just trained, \
                     at the depth where the neighbouring views agree (see docs/quality.md)",
                )
            };
            choices.push(choice("error-growth", share, reason));
            share as f32
        });
        let iterations = match request.length {
            RunLength::Steps(n) => n,
            RunLength::Minutes(_) => DEFAULT_STEPS,
        };
        if request.lr_scales.is_none() {
            // A time budget's length is planned while it runs; the factor follows it.
            let (value, steps) = match request.length {
                RunLength::Steps(n) => (format!("{:.2}", run_length_lr_factor(n)), format!("{n} steps")),
                RunLength::Minutes(_) => ("by run length".to_string(), "the planned steps".to_string()),
            };
            choices.push(choice(
                "lr-scale",
                value,
                format!(
                    "a factor of the run length ({steps}): 4 up to 7000 steps, 1 at the reference's 32 000, \
                     log-linear between (lego: x4 gave +4.3 dB at 1200 steps, +3.3 dB at 6000)"
                ),
            ));
        }
        let hull = HullConfig {
            resolution: request.hull_resolution,
            ..HullConfig::default()
        };
        let init = match request.init {
            InitMethod::Random => PointlessInit::Random,
            InitMethod::Hull => PointlessInit::Hull(hull),
            InitMethod::Auto => {
                let resolved = PointlessInit::Auto(hull).resolve(scene);
                let (value, reason) = if has_points {
                    (
                        "sfm+shell",
                        "the scene has SfM points: farthest-point sample of them plus a sky sphere, the rest of the budget on a background shell",
                    )
                } else if matches!(resolved, PointlessInit::Hull(_)) {
                    (
                        "hull",
                        "no SfM points, alpha masks present: the visual hull of the masks, in the box the cameras look at",
                    )
                } else {
                    (
                        "random+shell",
                        "no SfM points, no alpha masks: random points in the box the cameras look at plus a background shell",
                    )
                };
                choices.push(choice("init", value, reason));
                PointlessInit::Auto(hull)
            }
        };
        let config = TrainConfig {
            iterations,
            sh_degree: request.sh_degree,
            background: Vec3::from_array(scene.background.rgb()),
            seed: request.seed,
            extent: scene.extent,
            impact_threshold: request.texture_threshold,
            adam: request.adam,
            texture_mode: request.texture_mode,
            relocate: request.relocate,
            growth_cap,
            error_growth,
            lr_scales: request.lr_scales.unwrap_or(LearningRateScales::REFERENCE),
            lr_by_run_length: request.lr_scales.is_none(),
            clamp_gradient: request.clamp_gradient,
            geometry: request.geometry,
            ..TrainConfig::default()
        };
        Ok(Self {
            config,
            billboards,
            texture_size: request.texture_size,
            init,
            resolution: request.resolution,
            time_plan: match request.length {
                RunLength::Minutes(m) => Some(TimePlan::new(m)),
                RunLength::Steps(_) => None,
            },
            choices,
        })
    }

    /// The initial billboards of the plan on `scene` (the scene it was planned for), and what
    /// the initialisation did.
    ///
    /// # Errors
    /// As [`init_model_with`].
    pub fn init_model(&self, scene: &Scene) -> Result<(RawBillboards, InitReport), InitError> {
        init_model_with(scene, self.billboards, self.texture_size, self.config.seed, &self.init)
    }

    /// A trainer of `model` under this plan (its time budget set, when it has one).
    pub fn trainer(&self, model: RawBillboards) -> Trainer {
        let mut trainer = Trainer::new(model, self.config);
        trainer.set_time_plan(self.time_plan);
        trainer
    }

    /// The run settings of this plan: its coarse-to-fine schedule and its choices (recorded in
    /// the summary); everything else [`RunConfig::default`].
    pub fn run_config(&self) -> RunConfig {
        RunConfig {
            resolution: self.resolution,
            automatic: self.choices.clone(),
            ..RunConfig::default()
        }
    }

    /// Estimated peak memory of training this plan on `scene`, bytes
    /// ([`crate::train::footprint::scene_training_bytes`], growth included).
    pub fn training_bytes(&self, scene: &Scene) -> u64 {
        scene_training_bytes(self.billboards, self.config.growth_cap, self.texture_size, scene)
    }
}
