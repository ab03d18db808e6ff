//! Machine-readable records of a training run, shared by `bbsplat train`, `bbsplat eval` and the
//! sweep tool.
//!
//! `bbsplat train` writes a [`TrainSummary`] as `summary.json` into its output folder; the sweep
//! tool reads it back. Times are wall-clock seconds, sizes are bytes, PSNR is in dB on 8-bit
//! quantised images (as the reference evaluates), SSIM is the training SSIM (11×11 Gaussian window,
//! σ = 1.5, zero padding) on the same 8-bit images.

use serde::{Deserialize, Serialize};

/// Version of the [`TrainSummary`] layout; bumped when a field changes meaning.
pub const SUMMARY_VERSION: u32 = 1;

/// What one training run produced, as written to `summary.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainSummary {
    /// Layout version ([`SUMMARY_VERSION`]).
    pub version: u32,
    /// The scene folder as given on the command line.
    pub scene: String,
    /// Optimisation steps run.
    pub iterations: usize,
    /// Billboards in the model.
    pub billboards: usize,
    /// Billboards alive at the end (mean alpha above the relocation threshold 0.005).
    pub alive: usize,
    /// Texture side.
    pub texture_size: usize,
    /// Highest SH degree.
    pub sh_degree: u32,
    /// Training image width and height in pixels (of the first training view).
    pub resolution: [u32; 2],
    /// Wall-clock seconds spent in training steps (excluding loading, evaluation and saving), of
    /// the whole run: a resumed run's earlier parts are included ([`crate::train::run_time`]).
    pub train_seconds: f64,
    /// Mean forward-only render time per test frame, milliseconds (NaN without test views).
    #[serde(deserialize_with = "nan_when_null")]
    pub render_ms_per_frame: f64,
    /// Mean test-view PSNR (dB, 8-bit images); NaN without test views (JSON has no NaN:
    /// `summary.json` holds `null`, read back as NaN).
    #[serde(deserialize_with = "nan_when_null")]
    pub test_psnr: f64,
    /// Mean test-view SSIM (8-bit images); NaN (`null` in JSON) without test views.
    #[serde(deserialize_with = "nan_when_null")]
    pub test_ssim: f64,
    /// Number of test views evaluated.
    pub test_views: usize,
    /// Size of the saved model on disk (all files of the model folder), bytes.
    pub model_bytes: u64,
    /// Peak resident memory of the process (`VmHWM`), bytes; 0 where unavailable.
    pub peak_rss_bytes: u64,
    /// The pre-flight estimate of the peak ([`crate::train::footprint::training_bytes`]) when
    /// the caller made one (`bbsplat train` does); absent otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub estimated_peak_bytes: Option<u64>,
    /// The seed of the run.
    pub seed: u64,
    /// Rayon worker threads used.
    pub threads: usize,
    /// Test PSNR/SSIM at each evaluation during training: `(step, seconds, psnr, ssim)`.
    pub curve: Vec<CurvePoint>,
    /// The command line of the run (program name first), for reproducing it; empty in
    /// summaries written before it was recorded.
    #[serde(default)]
    pub command: Vec<String>,
    /// The LPIPS network of [`TrainSummary::test_lpips`] (`vgg`, the reference's, or `alex`);
    /// absent when the run had none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lpips_network: Option<String>,
    /// Mean test-view LPIPS of the final evaluation (8-bit images, [`crate::lpips`]); absent
    /// when not computed ([`TrainSummary::lpips_note`] says why).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub test_lpips: Option<f64>,
    /// Why [`TrainSummary::test_lpips`] is absent (no weights set up, no test views, an image
    /// too small for the network); absent when it is there.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lpips_note: Option<String>,
}

/// Reads a number, or `null` (what `serde_json` writes for a NaN or an infinity) as NaN.
fn nan_when_null<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// Training settings recorded in `summary.json` next to the [`TrainSummary`] fields (a separate
/// struct so that code building a [`TrainSummary`], such as the sweep tool's stand-ins, is not
/// affected; [`TrainSummary`] readers ignore these keys).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RecordedSettings {
    /// Gradient through the compositing clamp: `exact` or `straight-through`
    /// ([`crate::train::TrainConfig::clamp_gradient`]); `exact` in summaries written before it
    /// was recorded (the only one used then).
    #[serde(default = "exact")]
    pub clamp_gradient: String,
    /// Weight of the normal-consistency regulariser
    /// ([`crate::train::geometry::GeometryRegularisers`]); 0 (off) in summaries written before
    /// it existed.
    #[serde(default)]
    pub lambda_normal: f32,
    /// Weight of the depth-distortion regulariser; 0 (off) in older summaries.
    #[serde(default)]
    pub lambda_distortion: f32,
    /// Fraction of the run after which normal consistency was on (recorded with its weight;
    /// absent when the weight is 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub normal_from: Option<f32>,
    /// Fraction of the run after which depth distortion was on (absent when its weight is 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub distortion_from: Option<f32>,
}

fn exact() -> String {
    "exact".into()
}

/// The content of `summary.json`: a [`TrainSummary`], the [`RecordedSettings`] and the
/// [`RunReport`] as one flat JSON object.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SummaryFile {
    /// The run's results.
    #[serde(flatten)]
    pub summary: TrainSummary,
    /// Its settings.
    #[serde(flatten)]
    pub settings: RecordedSettings,
    /// Every warning of the run, printed or not (`--quiet`): the scene's (skipped frames,
    /// damaged images, outlying cameras) and the run's. Empty (or absent in older files) when
    /// there were none.
    #[serde(default)]
    pub warnings: Vec<String>,
    /// What was chosen automatically, the time plan and the growth (absent in older summaries).
    #[serde(flatten, default)]
    pub record: RunReport,
}

/// A setting chosen automatically (not given on the command line) and why.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct AutoChoice {
    /// The setting, named as its flag (`background`, `init`, `billboards`, ...).
    pub setting: String,
    /// The value chosen.
    pub value: String,
    /// The rule and the numbers it used.
    pub reason: String,
}

/// The time budget of a run (`--minutes`) as it went.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlanRecord {
    /// The budget of step time, minutes.
    pub budget_minutes: f64,
    /// Step time spent over the whole run (resumed calls included), minutes.
    pub spent_minutes: f64,
    /// The steps the plan ended with.
    pub planned_steps: usize,
    /// Last estimate of a coarse step, seconds (0 without coarse steps).
    pub coarse_step_seconds: f64,
    /// Last estimate of a full-resolution step, seconds.
    pub fine_step_seconds: f64,
    /// The step full resolution started at, if it did.
    pub fine_from: Option<usize>,
}

/// The billboard count over the run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct GrowthRecord {
    /// Billboards when this call of the run started.
    pub initial: usize,
    /// Billboards at the end.
    pub final_count: usize,
    /// Billboards alive at the end.
    pub alive: usize,
    /// The growth cap (0: no growth).
    pub cap: usize,
}

/// What `bbsplat train` chose and what happened, beyond the [`TrainSummary`].
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RunReport {
    /// Settings chosen automatically, in the order they were chosen.
    #[serde(default)]
    pub automatic: Vec<AutoChoice>,
    /// The time plan, for a `--minutes` run.
    #[serde(default)]
    pub plan: Option<PlanRecord>,
    /// The billboard count.
    #[serde(default)]
    pub growth: Option<GrowthRecord>,
    /// Wall-clock seconds of this call of the run outside the steps (evaluations, checkpoints,
    /// saving, the final evaluation); not counted in the time budget.
    #[serde(default)]
    pub other_seconds: f64,
}

/// One evaluation during training.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CurvePoint {
    /// Steps done.
    pub step: usize,
    /// Training wall-clock seconds so far (evaluation time excluded).
    pub seconds: f64,
    /// Mean test PSNR (dB, 8-bit). A run without test views records no curve point; files of
    /// earlier builds hold one with `null` scores, read as NaN.
    #[serde(deserialize_with = "nan_when_null")]
    pub psnr: f64,
    /// Mean test SSIM (8-bit); `null` read as NaN, as [`CurvePoint::psnr`].
    #[serde(deserialize_with = "nan_when_null")]
    pub ssim: f64,
}

/// Peak resident set size of this process in bytes (`VmHWM` of `/proc/self/status`), or 0 when
/// the platform does not expose it.
pub fn peak_rss_bytes() -> u64 {
    let Ok(status) = std::fs::read_to_string("/proc/self/status") else {
        return 0;
    };
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|rest| rest.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
        .map_or(0, |kb| kb * 1024)
}

/// CPU time consumed so far by all threads of this process, in milliseconds (the first field of
/// each `/proc/self/task/*/schedstat`), or 0 when the platform does not expose it. On a shared
/// machine it excludes the time the threads waited for a core, so differences of it measure work
/// done rather than wall time; the benchmark harnesses (`examples/raster_stats`,
/// `examples/model_stats`) report both.
///
/// Part of the `tools` feature.
///
/// ```
/// let before = bbsplat::report::process_cpu_ms();
/// let x: f64 = (0..100_000).map(|i| (i as f64).sqrt()).sum();
/// assert!(x > 0.0 && bbsplat::report::process_cpu_ms() >= before);
/// ```
#[cfg(feature = "tools")]
pub fn process_cpu_ms() -> f64 {
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else {
        return 0.0;
    };
    tasks
        .filter_map(|t| std::fs::read_to_string(t.ok()?.path().join("schedstat")).ok())
        .filter_map(|s| s.split_whitespace().next()?.parse::<f64>().ok())
        .sum::<f64>()
        / 1e6
}
