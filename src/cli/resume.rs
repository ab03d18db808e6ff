//! What `--resume` compares: the run record ([`bbsplat::train::run_record`]) of the flags and
//! the dataset of this command against the one stored in the checkpoint.

use super::common::MaskModeArg;
use super::train_args::TrainArgs;
use anyhow::Result;
use bbsplat::scene::Scene;
use bbsplat::train::run_record::{DatasetFingerprint, RunRecord};
use std::path::Path;

/// The record of this command: every flag that changes the model or the optimisation (not
/// `--threads`, `--eval-*`, `--save-every`, `--stop-after`, `--quiet`, `--output`, `--resume`,
/// `--overwrite`; nor `--iterations` and `--minutes`, which `train` checks against the
/// checkpoint's step count or time plan), and the fingerprint of the loaded scene's views.
pub fn record_of(args: &TrainArgs, scene: &Scene) -> RunRecord {
    let opt = |x: Option<f32>| x.map_or("(default)".to_string(), |v| v.to_string());
    let arguments = [
        (
            "--growth-cap",
            args.growth_cap.map_or("(from the scene)".into(), |n| n.to_string()),
        ),
        (
            "--billboards",
            args.billboards.map_or("(from the scene)".into(), |n| n.to_string()),
        ),
        ("--texture-size", args.texture_size.to_string()),
        ("--sh-degree", args.sh_degree.to_string()),
        ("--seed", args.seed.to_string()),
        ("--texture-threshold", args.texture_threshold.to_string()),
        ("--texture-mode", args.texture_mode.as_str().to_string()),
        ("--adam", format!("{:?}", args.adam).to_lowercase()),
        ("--no-relocate", args.no_relocate.to_string()),
        ("--init", format!("{:?}", args.init).to_lowercase()),
        ("--hull-resolution", args.hull_resolution.to_string()),
        ("--coarse-factor", args.coarse_factor.to_string()),
        ("--coarse-until", args.coarse_until.to_string()),
        ("--lr-scale", opt(args.lr_scale)),
        ("--lr-position", opt(args.lr_position)),
        ("--lr-sh", opt(args.lr_sh)),
        ("--lr-shape", opt(args.lr_shape)),
        ("--lr-texture", opt(args.lr_texture)),
        ("--clamp-gradient", format!("{:?}", args.clamp_gradient).to_lowercase()),
        // The background in effect (given, or chosen from the data).
        ("--background", format!("{:?}", scene.background).to_lowercase()),
        ("--downscale", args.scene_args.downscale.to_string()),
        (
            "--max-width",
            args.scene_args.max_width.map_or("(none)".into(), |w| w.to_string()),
        ),
        ("--test-every", args.scene_args.test_every.to_string()),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect::<std::collections::BTreeMap<String, String>>();
    // The geometry regularisers are recorded only when on, so that a run without them keeps
    // the record of checkpoints written before they existed.
    let mut arguments = arguments;
    // Likewise a mask mode other than the default (it changes what the loss sees).
    if args.scene_args.mask_mode != MaskModeArg::Composite {
        let mode = format!("{:?}", args.scene_args.mask_mode).to_lowercase();
        arguments.insert("--mask-mode".into(), mode);
    }
    // Likewise the model a run starts from (its views are in the dataset fingerprint below).
    if let Some(model) = &args.init_model {
        arguments.insert("--init-model".into(), model.display().to_string());
    }
    // Likewise the error-growth share (recorded when given).
    if let Some(share) = args.error_growth {
        arguments.insert("--error-growth".into(), share.to_string());
    }
    if args.lambda_normal != 0.0 {
        arguments.insert("--lambda-normal".into(), args.lambda_normal.to_string());
        arguments.insert("--normal-from".into(), args.normal_from.to_string());
    }
    if args.lambda_dist != 0.0 {
        arguments.insert("--lambda-dist".into(), args.lambda_dist.to_string());
        arguments.insert("--dist-from".into(), args.dist_from.to_string());
    }
    let views = scene
        .train
        .iter()
        .chain(&scene.test)
        .map(|v| (v.name.as_str(), &v.camera));
    RunRecord {
        arguments,
        dataset: Some(DatasetFingerprint::of_views(views)),
    }
}

/// Refuses to resume from `checkpoint` (whose record is `stored`) when `now` differs, naming
/// every difference. Returns a note when the checkpoint has no record (format version 3 or
/// older), in which case nothing could be compared.
pub fn check(checkpoint: &Path, stored: &RunRecord, now: &RunRecord) -> Result<Option<String>> {
    if stored.is_empty() {
        return Ok(Some(format!(
            "note: {} records neither the run's flags nor its dataset (an older checkpoint format): they were not checked",
            checkpoint.display()
        )));
    }
    let differences = stored.differences(now);
    anyhow::ensure!(
        differences.is_empty(),
        "{}: --resume continues the same run, but this command differs from it:\n  {}\nresume with the scene and flags of that run, or start a new run (another output folder, or --overwrite)",
        checkpoint.display(),
        differences.join("\n  ")
    );
    Ok(None)
}
