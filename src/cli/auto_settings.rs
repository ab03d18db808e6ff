//! The settings `bbsplat train` chooses when their flags are not given, each with the rule that
//! chose it: background (from the data), initialisation, billboard count, growth cap, where
//! growth places billboards, learning rates. They are
//! printed at the start and recorded in `summary.json` ([`AutoChoice`]).

use super::train::{DEFAULT_ITERATIONS, InitArg, TrainArgs};
use anyhow::Result;
use bbsplat::init::budget::{BudgetInputs, budget_for, growth_cap};
use bbsplat::init::hull::HullConfig;
use bbsplat::init::scene_init::PointlessInit;
use bbsplat::report::AutoChoice;
use bbsplat::scene::Scene;
use bbsplat::scene::data_background::BackgroundChoice;
use bbsplat::train::run_length_lr_factor;

/// What the flags left open, resolved for one scene.
#[derive(Clone, Debug)]
pub struct AutoSettings {
    /// Initial billboard count.
    pub billboards: usize,
    /// Growth cap (0: no growth).
    pub growth_cap: usize,
    /// Share of growth placed on the error ([`bbsplat::train::TrainConfig::error_growth`]).
    pub error_growth: f32,
    /// Initialisation of a scene without SfM points.
    pub pointless: PointlessInit,
    /// The automatic choices and why (only those not given as flags).
    pub choices: Vec<AutoChoice>,
}

fn choice(setting: &str, value: impl ToString, reason: impl Into<String>) -> AutoChoice {
    AutoChoice {
        setting: setting.into(),
        value: value.to_string(),
        reason: reason.into(),
    }
}

/// Resolves the open settings of `args` for `scene`, loaded with `background`.
pub fn resolve(args: &TrainArgs, scene: &Scene, background: &BackgroundChoice) -> Result<AutoSettings> {
    let mut choices = Vec::new();
    if args.scene_args.background.is_none() {
        let name = if background.background.rgb() == [1.0; 3] {
            "white"
        } else {
            "black"
        };
        choices.push(choice("background", name, background.reason.clone()));
    }
    let inputs = BudgetInputs::from_scene(scene, args.texture_size);
    let billboards = match args.billboards {
        Some(n) => {
            anyhow::ensure!(n >= 1, "--billboards must be at least 1");
            n
        }
        None => {
            let b = budget_for(&inputs);
            choices.push(choice("billboards", b.billboards, b.reason));
            b.billboards
        }
    };
    let growth_cap = match args.growth_cap {
        Some(cap) => cap,
        None => {
            let cap = growth_cap(&inputs, billboards);
            choices.push(choice("growth-cap", cap.billboards, cap.reason));
            cap.billboards
        }
    };
    // A finite SfM point, as the budget rule counts them.
    let has_points = inputs.sfm_points.is_some();
    let error_growth = match args.error_growth {
        Some(share) => share,
        None if has_points => {
            choices.push(choice(
                "error-growth",
                0,
                "the scene has SfM points: growth copies billboards in proportion to alpha, as the reference \
                 (placing them on the error lost 0.2-0.6 dB on beer_colmap at 30 minutes)",
            ));
            0.0
        }
        None => {
            choices.push(choice(
                "error-growth",
                1,
                "no SfM points: growth places its billboards on the worst pixels of the view just trained, \
                 at the depth where the neighbouring views agree (see docs/quality.md)",
            ));
            1.0
        }
    };
    if args.lr_by_run_length() {
        // A time budget's length is planned while it runs; the factor follows it.
        let length = match args.minutes {
            Some(_) => None,
            None => Some(args.iterations.unwrap_or(DEFAULT_ITERATIONS)),
        };
        let (value, steps) = match length {
            Some(n) => (format!("{:.2}", run_length_lr_factor(n)), format!("{n} steps")),
            None => ("by run length".to_string(), "the planned steps".to_string()),
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
        resolution: args.hull_resolution,
        ..HullConfig::default()
    };
    let pointless = match args.init {
        InitArg::Random => PointlessInit::Random,
        InitArg::Hull => PointlessInit::Hull(hull),
        InitArg::Auto => {
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
    Ok(AutoSettings {
        billboards,
        growth_cap,
        error_growth,
        pointless,
        choices,
    })
}
