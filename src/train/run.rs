//! The whole training run: steps, coarse-to-fine schedule, periodic evaluation and checkpoints,
//! stop requests, the final save of the 8-bit model, its re-load and final evaluation, and the
//! run's summary (`summary.json`: a [`TrainSummary`] and the [`RecordedSettings`], see
//! [`SummaryFile`]). `bbsplat train` and `bbsplat demo` are thin wrappers around [`run`]; a program
//! embedding the crate gets the same loop.
//!
//! ```no_run
//! use bbsplat::demo::{DemoConfig, generate};
//! use bbsplat::model::RawBillboards;
//! use bbsplat::train::{RunConfig, RunOutcome, StopSignal, TrainConfig, TrainEvent, TrainView, Trainer, run};
//!
//! let scene = generate(&DemoConfig::default());
//! let train: Vec<TrainView> = scene.train.iter().map(TrainView::from_demo).collect();
//! let test: Vec<TrainView> = scene.test.iter().map(TrainView::from_demo).collect();
//! let model = RawBillboards::from_points(&scene.points, &scene.colours, 8, 0);
//! let config = TrainConfig { iterations: 300, ..TrainConfig::default() };
//! let mut trainer = Trainer::new(model, config);
//! let settings = RunConfig { output: Some("out".into()), ..RunConfig::default() };
//! let outcome = run(&mut trainer, &train, &test, &settings, &StopSignal::new(), |event| {
//!     if let TrainEvent::Evaluation { step, psnr, .. } = event {
//!         println!("step {step}: {psnr:.2} dB");
//!     }
//! })?;
//! if let RunOutcome::Finished(summary) = outcome {
//!     println!("test PSNR {:.2} dB", summary.test_psnr);
//! }
//! # Ok::<(), bbsplat::train::RunError>(())
//! ```
//!
//! # What a run does
//!
//! The trainer's own [`TrainConfig`](super::TrainConfig) (iterations, schedules, seed) drives the
//! steps; [`RunConfig`] holds what is around them. From the trainer's current step (0, or the
//! step of a loaded checkpoint) to `iterations`:
//!
//! 1. before each step: if [`RunConfig::stop_after`] steps are done or the [`StopSignal`] was
//!    raised, save the checkpoint (with an output folder) and return [`RunOutcome::Stopped`];
//! 2. one [`Trainer::step`] on the coarse or full-size views ([`RunConfig::resolution`]),
//!    timed (only step time counts as training time), then [`TrainEvent::Step`];
//! 3. every [`RunConfig::save_every`] steps the checkpoint, every [`RunConfig::eval_every`]
//!    steps (not at the last) an evaluation on at most [`RunConfig::eval_views`] evenly spaced
//!    test views ([`TrainEvent::Evaluation`]).
//!
//! At the end, with an output folder, the checkpoint is written first (if the model cannot be
//! saved, [`RunError::ModelSave`] names it: the trained state is not lost), then the model is
//! saved as the reference saves it (8-bit textures, [`crate::model_file`]) in `<output>/model`,
//! and **re-loaded** and evaluated on every test view, as the reference's `render.py` does; the
//! summary goes to `<output>/summary.json` ([`TrainSummary`], with every warning). Without an
//! output folder nothing is written and the final evaluation renders the trainer's float model.
//!
//! The [`StopSignal`] is also checked between the views of every evaluation: an intermediate
//! evaluation is abandoned and the run stops with its checkpoint; during the final phase the run
//! stops (as [`RunOutcome::Stopped`] at the last step) once the checkpoint and model are saved,
//! without a summary; continuing from that checkpoint redoes the final save and evaluation.
//!
//! # Non-finite values
//!
//! [`Trainer::step`] checks the loss and gradients before its optimiser step and the
//! parameters after it; [`run`] also checks the parameters once before the first step, so every
//! step starts from finite parameters. When a step's loss or gradient is not finite the step is
//! not applied, and with an output folder the trainer (exactly the state before that step, with
//! finite parameters) is saved as the checkpoint before [`RunError::Step`] is returned. When a
//! parameter turns non-finite in the optimiser step, nothing is written: the checkpoint on disk
//! stays the last one saved (from a step whose parameters were checked). In both cases the
//! error names the step, the view, the value ([`NonFinite`]) and the checkpoint.
//!
//! Evaluation PSNR and SSIM are those of [`crate::eval`] (8-bit images); with
//! [`RunConfig::lpips`], the final evaluation adds LPIPS ([`crate::eval::lpips_u8`]) to the
//! summary, or the summary says why it has none. Deterministic: the same
//! trainer, views and settings give the same files for any thread count, and a run stopped and
//! continued from its checkpoint writes the same files as one that was not.

use super::resolution::{ResolutionSchedule, downscale_view};
use super::run_time::RunTime;
use super::{CheckpointError, NonFinite, ParamGroup, StepLog, TrainError, TrainView, Trainer};
use crate::billboards::ActivatedBillboards;
use crate::eval::{EvalView, evaluate_views, lpips_u8, until_error};
use crate::loss::LossError;
use crate::lpips::Lpips;
use crate::model_file::scene_mark::SceneMark;
use crate::model_file::{ModelFileError, ModelMeta, load_model, save_model};
use crate::raster::{ActivatedRef, RenderSettings};
use crate::report::{
    AutoChoice, CurvePoint, GrowthRecord, PlanRecord, RecordedSettings, RunReport, SUMMARY_VERSION, SummaryFile,
    TrainSummary, peak_rss_bytes,
};
use crate::stages::composite::ClampGradient;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;
use thiserror::Error;

/// File name of the checkpoint in the output folder.
pub const CHECKPOINT_FILE: &str = "checkpoint.bin";
/// Folder name of the saved model in the output folder.
pub const MODEL_DIR: &str = "model";
/// File name of the summary in the output folder.
pub const SUMMARY_FILE: &str = "summary.json";

/// What surrounds the steps of a run (the steps themselves follow the trainer's
/// [`TrainConfig`](super::TrainConfig)).
#[derive(Clone, Debug, PartialEq)]
pub struct RunConfig {
    /// Evaluate on the test views every n steps (0: only at the end). Default 1000.
    pub eval_every: usize,
    /// At most this many test views (evenly spaced: view `k·len/n` for `k < n`) in the
    /// intermediate evaluations; 0 means all. The final evaluation uses all. Default 25.
    pub eval_views: usize,
    /// Write the checkpoint every n steps (0: only when stopping and at the end). Needs
    /// [`RunConfig::output`]; ignored without. Default 0.
    pub save_every: usize,
    /// Output folder (created): `checkpoint.bin`, `model/`, `summary.json`. `None`: nothing is
    /// written. Default `None`.
    pub output: Option<PathBuf>,
    /// Stop (with a checkpoint) once this many steps of the run are done, as a stop request
    /// does: lets a long run be done in slices. Default `None`.
    pub stop_after: Option<usize>,
    /// Coarse-to-fine schedule (default [`ResolutionSchedule::OFF`]).
    pub resolution: ResolutionSchedule,
    /// The scene's name, recorded in the summary.
    pub scene: String,
    /// The command line, recorded in the summary (program name first; empty when embedded).
    pub command: Vec<String>,
    /// Warnings raised before the run (e.g. [`crate::scene::Scene::warnings`]), recorded in the
    /// summary with the run's own [`RunWarning`]s.
    pub warnings: Vec<String>,
    /// Settings chosen automatically by the caller and why, recorded in the summary.
    pub automatic: Vec<AutoChoice>,
    /// The time already spent by the run a resumed trainer continues
    /// ([`super::run_time::read_beside`]): the clocks start from it, so the summary reports the
    /// whole run. `None` (the default): they start from zero.
    pub earlier_time: Option<RunTime>,
    /// The LPIPS network of the final evaluation (`bbsplat train` gives the reference's VGG
    /// when its weights are set up). `None` (the default): no LPIPS, and the summary's
    /// `lpips_note` says why ([`RunConfig::lpips_note`]).
    pub lpips: Option<Arc<Lpips>>,
    /// Why [`RunConfig::lpips`] is `None`, for the summary (e.g. the weights are not set up);
    /// `None`: "no LPIPS network was given to the run".
    pub lpips_note: Option<String>,
    /// How each step's time is measured: the wall clock (the default), or a cost per pixel for
    /// tests of the time budget that must not depend on the machine's load.
    pub step_clock: StepClock,
    /// Every how many steps [`TrainEvent::Snapshot`] hands over a copy of the activated
    /// billboards (0: never; `bbsplat train --view`).
    pub snapshot_every: usize,
    /// A request for one [`TrainEvent::Snapshot`] after the next step, whatever
    /// [`RunConfig::snapshot_every`] says (`bbsplat train --view`'s "refresh now"); `None`: none.
    pub snapshot_request: Option<SnapshotRequest>,
    /// The caller's estimate of the run's peak memory in bytes (`bbsplat train`'s pre-flight
    /// [`super::footprint::scene_training_bytes`]), recorded in the summary beside the measured
    /// peak; `None` (the default): none.
    pub estimated_peak_bytes: Option<u64>,
}

/// How [`run`] measures the time of a step, which the time budget plans on and the summary
/// reports as `train_seconds`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum StepClock {
    /// Seconds of wall-clock time (the default).
    #[default]
    Wall,
    /// A step counts this many seconds per pixel of the views it draws from (their mean pixel
    /// count: a coarse step counts a quarter of a full one at factor 2), whatever it took: the
    /// same run on any machine under any load, so that a test can check the budget's planning
    /// to the step.
    PerPixel(f64),
}

impl Default for RunConfig {
    fn default() -> Self {
        Self {
            eval_every: 1000,
            eval_views: 25,
            save_every: 0,
            output: None,
            stop_after: None,
            resolution: ResolutionSchedule::OFF,
            scene: String::new(),
            command: Vec::new(),
            warnings: Vec::new(),
            automatic: Vec::new(),
            earlier_time: None,
            lpips: None,
            lpips_note: None,
            step_clock: StepClock::Wall,
            snapshot_every: 0,
            snapshot_request: None,
            estimated_peak_bytes: None,
        }
    }
}

/// A stop request shared with another thread or a signal handler (e.g. Ctrl-C): [`run`] polls it
/// before every step and stops with a checkpoint. Clones share the flag.
#[derive(Clone, Debug, Default)]
pub struct StopSignal(Arc<AtomicBool>);

impl StopSignal {
    /// A signal not raised.
    pub fn new() -> Self {
        Self::default()
    }

    /// Asks the run to stop before its next step.
    pub fn request(&self) {
        self.0.store(true, Ordering::SeqCst);
    }

    /// True once [`StopSignal::request`] was called.
    pub fn is_requested(&self) -> bool {
        self.0.load(Ordering::SeqCst)
    }
}

/// A request for a snapshot shared with another thread (e.g. a live view's server): [`run`]
/// takes it after each step and hands over one [`TrainEvent::Snapshot`] when it was raised.
/// Clones share the request, and are the ones equal to each other.
#[derive(Clone, Debug, Default)]
pub struct SnapshotRequest(Arc<AtomicBool>);

impl PartialEq for SnapshotRequest {
    fn eq(&self, other: &Self) -> bool {
        Arc::ptr_eq(&self.0, &other.0)
    }
}

impl SnapshotRequest {
    /// A request not raised.
    pub fn new() -> Self {
        Self::default()
    }

    /// Asks for a snapshot after the next step (requests before the run takes one count once).
    pub fn request(&self) {
        self.0.store(true, Ordering::SeqCst);
    }

    /// Whether a snapshot was asked for since the last call, clearing the request.
    pub fn take(&self) -> bool {
        self.0.swap(false, Ordering::SeqCst)
    }
}

/// Why a run stopped before its last step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum StopReason {
    /// [`RunConfig::stop_after`] steps were done.
    StopAfter,
    /// The [`StopSignal`] was raised.
    Requested,
}

/// Something worth telling the user that does not stop the run.
#[derive(Clone, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum RunWarning {
    /// No test views: no evaluation (the summary's PSNR and SSIM are NaN).
    NoTestViews,
}

impl std::fmt::Display for RunWarning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RunWarning::NoTestViews => f.write_str("the scene has no test views: nothing will be evaluated"),
        }
    }
}

/// What a run reports to its caller's `on_event`, in order: `Started`, then per step `Step`
/// (and `Checkpoint` / `Evaluation` when due), and at the end `Checkpoint`, `ModelSaved`, `Record`
/// and `Finished` (or `Checkpoint`, `ModelSaved` and `Stopped` when a stop request arrives after
/// the last step), or `Checkpoint` and `Stopped`.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum TrainEvent {
    /// The run starts (after the checks, before the first step).
    Started {
        /// Steps already done (a resumed trainer's step).
        step: usize,
        /// Steps of the whole run.
        iterations: usize,
        /// Training views.
        train_views: usize,
        /// Test views.
        test_views: usize,
        /// Size of the first training view, pixels.
        width: u32,
        /// Height of the first training view, pixels.
        height: u32,
        /// Billboards.
        billboards: usize,
        /// Texture side.
        texture_size: usize,
    },
    /// A warning.
    Warning(RunWarning),
    /// A step was done.
    Step {
        /// The step's log (`log.step` counts the steps done).
        log: StepLog,
        /// Steps of the whole run.
        iterations: usize,
        /// Exponential moving average of the steps' PSNR (weight 0.05 on the newest; the first
        /// step of this call starts it).
        running_psnr: f64,
        /// Billboards relocated so far in this call.
        relocated_total: usize,
        /// Seconds spent in steps so far in the run (a resumed run's earlier parts included).
        train_seconds: f64,
    },
    /// An intermediate evaluation on the test subset.
    Evaluation {
        /// Steps done.
        step: usize,
        /// Mean PSNR, dB (8-bit images).
        psnr: f64,
        /// Mean SSIM (8-bit images).
        ssim: f64,
        /// Seconds spent in steps so far in the run (a resumed run's earlier parts included).
        seconds: f64,
        /// Views evaluated.
        views: usize,
    },
    /// The checkpoint was written.
    Checkpoint {
        /// Steps done.
        step: usize,
        /// The file.
        path: PathBuf,
    },
    /// The model was saved (8-bit textures).
    ModelSaved {
        /// The model folder.
        path: PathBuf,
        /// Size of its files, bytes.
        bytes: u64,
    },
    /// The run stopped before its last step.
    Stopped {
        /// Steps done.
        step: usize,
        /// Why.
        reason: StopReason,
        /// The checkpoint written (with an output folder).
        checkpoint: Option<PathBuf>,
    },
    /// What was chosen and what happened (the [`RunReport`] of `summary.json`), just before
    /// `Finished`.
    Record(Box<RunReport>),
    /// A copy of the activated billboards after a step, every [`RunConfig::snapshot_every`]
    /// steps, for a live view: the copy is shared, so handing
    /// it to another thread costs nothing more. Taking it changes nothing in the run.
    Snapshot {
        /// Steps done.
        step: usize,
        /// The activated billboards after that step.
        billboards: Arc<ActivatedBillboards>,
    },
    /// The run is complete.
    Finished(Box<TrainSummary>),
}

/// How a run ended without error.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum RunOutcome {
    /// Every step done, the model evaluated (and, with an output folder, saved).
    Finished(Box<TrainSummary>),
    /// Stopped before the last step.
    Stopped {
        /// Steps done.
        step: usize,
        /// Why.
        reason: StopReason,
        /// The checkpoint written (with an output folder): continue from it with
        /// [`Trainer::load_checkpoint`] and [`run`].
        checkpoint: Option<PathBuf>,
    },
}

/// Why a run failed. The trainer passed to [`run`] holds the state reached (see each variant).
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum RunError {
    /// No training views.
    #[error("no training views: a run needs at least one")]
    NoTrainViews,
    /// The trainer given to [`run`] holds a NaN or infinite parameter (nothing was done).
    #[error("the trainer at step {step} holds a non-finite {group} value (NaN or infinite) before the run")]
    NonFiniteStart {
        /// The trainer's step.
        step: usize,
        /// The group.
        group: ParamGroup,
    },
    /// A step failed: bad views, or a non-finite value ([`TrainError::NonFinite`]).
    #[error("{source}{}", checkpoint_note(.checkpoint))]
    Step {
        /// The step's error (step, view, value).
        source: TrainError,
        /// The last good checkpoint written by this run: for a non-finite loss or gradient the
        /// state just before the failed step; otherwise the last one saved earlier, untouched.
        /// `None` when this run wrote none.
        checkpoint: Option<PathBuf>,
    },
    /// Writing the checkpoint failed.
    #[error(transparent)]
    Checkpoint(#[from] CheckpointError),
    /// Saving or re-loading the model failed.
    #[error(transparent)]
    Model(#[from] ModelFileError),
    /// Saving the model failed after training; the trained state was written to the checkpoint
    /// first, so nothing is lost: continue from it once the problem is fixed.
    #[error("{source}; the trained state is saved in {}", .checkpoint.display())]
    ModelSave {
        /// Why the model could not be saved.
        source: ModelFileError,
        /// The checkpoint holding the trained state.
        checkpoint: PathBuf,
    },
    /// An evaluation failed (a test image that does not match its camera).
    #[error("evaluating the test views: {0}")]
    Evaluation(#[from] LossError),
    /// A test view's image could not be read for an evaluation (on demand,
    /// [`crate::scene::on_demand`]: its file went away or changed since the scene was loaded).
    #[error("evaluating the test views: test view {view}: {message}")]
    TestImage {
        /// Index of the view among the evaluated views.
        view: usize,
        /// What went wrong, naming the file.
        message: String,
    },
    /// The summary could not be encoded.
    #[error("encoding the summary: {0}")]
    Summary(serde_json::Error),
    /// The output folder or the summary could not be written.
    #[error("{path}: {action}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// What was being done.
        action: &'static str,
        /// The underlying error.
        source: std::io::Error,
    },
}

fn checkpoint_note(checkpoint: &Option<PathBuf>) -> String {
    match checkpoint {
        Some(path) => format!("; the last good state is in {}", path.display()),
        None => String::new(),
    }
}

/// `at_most` evenly spaced items (`k·len/at_most`), or all when `at_most` is 0 or not smaller.
fn evenly_spaced<T>(items: &[T], at_most: usize) -> Vec<&T> {
    if items.len() <= at_most || at_most == 0 {
        return items.iter().collect();
    }
    (0..at_most).map(|k| &items[k * items.len() / at_most]).collect()
}

/// Mean PSNR, SSIM and render milliseconds of `set` over `views`; `None` when `stop` was raised
/// before the last view (checked between views, so a stop request waits for one render).
fn evaluate(
    set: &ActivatedRef<'_>,
    views: &[&TrainView],
    settings: &RenderSettings,
    stop: &StopSignal,
) -> Result<Option<(f64, f64, f64)>, RunError> {
    Ok(evaluate_with_lpips(set, views, settings, stop, None)?.map(|(p, s, ms, _)| (p, s, ms)))
}

/// What the final evaluation says of LPIPS: its mean over the test views, or why there is none.
type LpipsOutcome = Result<f64, String>;

/// Mean PSNR, SSIM, render milliseconds and (with a network) LPIPS of an evaluation.
type Scores = (f64, f64, f64, Option<LpipsOutcome>);

/// [`evaluate`], and with `lpips` the mean LPIPS of the views (or the first view's error, which
/// does not fail the evaluation: the summary records it).
fn evaluate_with_lpips(
    set: &ActivatedRef<'_>,
    views: &[&TrainView],
    settings: &RenderSettings,
    stop: &StopSignal,
    lpips: Option<&Lpips>,
) -> Result<Option<Scores>, RunError> {
    let mut distances: Vec<f64> = Vec::new();
    let mut lpips_error: Option<String> = None;
    // The first view whose image cannot be read ends the evaluation with its error.
    let mut unread: Option<RunError> = None;
    let read = views
        .iter()
        .enumerate()
        .take_while(|_| !stop.is_requested())
        .map(|(i, v)| {
            // An 8-bit view is converted (an on-demand view decoded) for its evaluation only.
            let rgb = v.rgb.to_f32().map_err(|e| RunError::TestImage {
                view: i,
                message: e.to_string(),
            })?;
            Ok(EvalView {
                name: "",
                camera: &v.camera,
                rgb,
                mask: None,
            })
        });
    let report = evaluate_views(set, until_error(read, &mut unread), settings, |view, rendered| {
        if let Some(net) = lpips
            && lpips_error.is_none()
        {
            let (w, h) = (view.camera.width as usize, view.camera.height as usize);
            match lpips_u8(net, rendered, &view.rgb, w, h) {
                Ok(d) => distances.push(d),
                Err(e) => lpips_error = Some(e.to_string()),
            }
        }
    })?;
    if let Some(e) = unread {
        return Err(e);
    }
    if stop.is_requested() {
        return Ok(None);
    }
    let lpips = lpips.map(|_| match lpips_error {
        Some(e) => Err(e),
        None => Ok(distances.iter().sum::<f64>() / distances.len() as f64),
    });
    Ok(Some((report.mean_psnr, report.mean_ssim, report.mean_render_ms, lpips)))
}

/// Writes `text` to `path` with [`crate::train::checkpoint::write_atomic`] (a temporary file in
/// the same folder, flushed to disk, renamed over `path`; removed on error), its I/O errors
/// reported as this run's.
fn write_text_atomic(path: &Path, text: &str) -> Result<(), RunError> {
    crate::train::checkpoint::write_atomic(path, text.as_bytes()).map_err(|e| match e {
        CheckpointError::Io { path, action, source } => RunError::Io { path, action, source },
        other => RunError::Checkpoint(other),
    })
}

/// The name of the clamp gradient in the summary.
fn clamp_gradient_name(c: ClampGradient) -> &'static str {
    match c {
        ClampGradient::Exact => "exact",
        ClampGradient::PassThrough => "straight-through",
    }
}

/// Trains `trainer` from its current step to the end of its run (module docs), on `train`,
/// evaluating on `test`; `on_event` sees every [`TrainEvent`]. The trainer is left at the state
/// reached: trained, stopped, or (on error) as each [`RunError`] variant says.
///
/// The phases are one function each (of the private `RunState`): `start` (checks and setup),
/// per step `step` and `after_step` (periodic checkpoint and evaluation), then `save_final`,
/// `final_evaluation` and `finish` (the summary).
///
/// # Errors
/// [`RunError`]: no training views, a non-finite parameter before the run, a failed step (bad
/// views, non-finite values), or a file that could not be written or re-loaded.
pub fn run(
    trainer: &mut Trainer,
    train: &[TrainView],
    test: &[TrainView],
    config: &RunConfig,
    stop: &StopSignal,
    mut on_event: impl FnMut(&TrainEvent),
) -> Result<RunOutcome, RunError> {
    let on_event: &mut dyn FnMut(&TrainEvent) = &mut on_event;
    let mut state = RunState::start(trainer, train, test, config, stop, on_event)?;
    while trainer.step_index() < trainer.config().iterations {
        if let Some(reason) = state.stop_reason(trainer) {
            let checkpoint = state.save(trainer, on_event)?;
            return Ok(stopped(trainer.step_index(), reason, checkpoint, on_event));
        }
        let step = state.step(trainer, train, on_event)?;
        state.after_step(trainer, step, on_event)?;
    }
    let (model_bytes, saved) = state.save_final(trainer, on_event)?;
    if stop.is_requested() {
        return Ok(state.stopped_after_the_last_step(trainer, on_event));
    }
    let Some(evaluated) = state.final_evaluation(trainer, test, saved.as_ref())? else {
        // Interrupted during the final evaluation: the model and the checkpoint are saved;
        // resuming from the checkpoint (at the last step) redoes the save and evaluation.
        return Ok(state.stopped_after_the_last_step(trainer, on_event));
    };
    state.finish(trainer, test, evaluated, model_bytes, on_event)
}

/// A time budget plans the run's length from the step times measured so far.
fn replan(trainer: &mut Trainer, resolution: &ResolutionSchedule) {
    let step = trainer.step_index();
    if let Some(n) = trainer.time_plan().map(|p| p.planned_iterations(step, resolution)) {
        trainer.set_iterations(n);
    }
}

/// [`TrainEvent::Stopped`] sent, and the outcome it reports.
fn stopped(
    step: usize,
    reason: StopReason,
    checkpoint: Option<PathBuf>,
    on_event: &mut dyn FnMut(&TrainEvent),
) -> RunOutcome {
    on_event(&TrainEvent::Stopped {
        step,
        reason,
        checkpoint: checkpoint.clone(),
    });
    RunOutcome::Stopped {
        step,
        reason,
        checkpoint,
    }
}

/// What a run carries from phase to phase: the settings around the steps, fixed at the start,
/// and what the steps measured so far.
struct RunState<'a> {
    config: &'a RunConfig,
    stop: &'a StopSignal,
    /// The trainer's config at the start (its iterations may be re-planned since).
    tc: super::TrainConfig,
    run_start: Instant,
    initial_billboards: usize,
    /// Size of the first training view, pixels.
    resolution: [u32; 2],
    /// The downscaled training views of the coarse phase (empty without one).
    coarse: Vec<TrainView>,
    /// The run's warnings and the caller's, for the summary.
    warnings: Vec<String>,
    /// Where checkpoints go (`None` without an output folder).
    checkpoint: Option<PathBuf>,
    eval_settings: RenderSettings,
    /// The test views of the intermediate evaluations.
    eval_subset: Vec<&'a TrainView>,
    curve: Vec<CurvePoint>,
    /// Seconds in steps, of the whole run (the earlier parts of a resumed run included).
    train_seconds: f64,
    /// The time of the earlier parts of a resumed run (zero otherwise).
    earlier: RunTime,
    /// The mark of the scene trained on (its training and test views), saved with the model.
    scene_mark: SceneMark,
    running_psnr: f64,
    relocated_total: usize,
    /// The last checkpoint this call wrote (named by a failed step's error).
    last_checkpoint: Option<PathBuf>,
}

impl<'a> RunState<'a> {
    /// Setup: the checks before the run (training views, finite parameters), the time budget's
    /// first plan, the coarse views, [`TrainEvent::Started`] and the warnings, the output folder.
    fn start(
        trainer: &mut Trainer,
        train: &[TrainView],
        test: &'a [TrainView],
        config: &'a RunConfig,
        stop: &'a StopSignal,
        on_event: &mut dyn FnMut(&TrainEvent),
    ) -> Result<Self, RunError> {
        let first = train.first().ok_or(RunError::NoTrainViews)?;
        if let Some(group) = trainer.non_finite_parameter() {
            return Err(RunError::NonFiniteStart {
                step: trainer.step_index(),
                group,
            });
        }
        let tc = *trainer.config();
        let run_start = Instant::now();
        let initial_billboards = trainer.model().len();
        replan(trainer, &config.resolution);
        let iterations = trainer.config().iterations;
        let coarse: Vec<TrainView> = if config.resolution.factor > 1 {
            train
                .iter()
                .enumerate()
                .map(|(i, v)| {
                    downscale_view(v, config.resolution.factor).map_err(|e| RunError::Step {
                        source: TrainError::ViewImage {
                            view: i,
                            message: e.to_string(),
                        },
                        checkpoint: None,
                    })
                })
                .collect::<Result<_, _>>()?
        } else {
            Vec::new()
        };
        on_event(&TrainEvent::Started {
            step: trainer.step_index(),
            iterations,
            train_views: train.len(),
            test_views: test.len(),
            width: first.camera.width,
            height: first.camera.height,
            billboards: trainer.model().len(),
            texture_size: trainer.model().texture_size,
        });
        let mut warnings = config.warnings.clone();
        if test.is_empty() {
            on_event(&TrainEvent::Warning(RunWarning::NoTestViews));
            warnings.push(RunWarning::NoTestViews.to_string());
        }
        let output = config.output.as_deref();
        if let Some(dir) = output {
            std::fs::create_dir_all(dir).map_err(|source| RunError::Io {
                path: dir.to_path_buf(),
                action: "creating the output folder",
                source,
            })?;
        }
        let checkpoint = output.map(|d| d.join(CHECKPOINT_FILE));
        let eval_settings = RenderSettings {
            background: tc.background,
            sh_degree: tc.sh_degree,
            simd: tc.simd,
            ..RenderSettings::default()
        };
        let eval_subset = evenly_spaced(test, config.eval_views);
        let earlier = config.earlier_time.unwrap_or_default();
        Ok(Self {
            config,
            stop,
            tc,
            run_start,
            initial_billboards,
            resolution: [first.camera.width, first.camera.height],
            coarse,
            warnings,
            checkpoint,
            eval_settings,
            eval_subset,
            curve: Vec::new(),
            train_seconds: earlier.train_seconds,
            earlier,
            scene_mark: SceneMark::of_cameras(train.iter().chain(test).map(|v| &v.camera)),
            running_psnr: f64::NAN,
            relocated_total: 0,
            last_checkpoint: None,
        })
    }

    /// Why the run stops before the next step, if it does.
    fn stop_reason(&self, trainer: &Trainer) -> Option<StopReason> {
        if self.config.stop_after.is_some_and(|n| trainer.step_index() >= n) {
            Some(StopReason::StopAfter)
        } else if self.stop.is_requested() {
            Some(StopReason::Requested)
        } else {
            None
        }
    }

    /// Writes the checkpoint (with an output folder), then [`TrainEvent::Checkpoint`].
    fn save(&self, trainer: &Trainer, on_event: &mut dyn FnMut(&TrainEvent)) -> Result<Option<PathBuf>, RunError> {
        let Some(path) = &self.checkpoint else {
            return Ok(None);
        };
        trainer.save_checkpoint(path)?;
        self.save_run_time(trainer, path)?;
        on_event(&TrainEvent::Checkpoint {
            step: trainer.step_index(),
            path: path.clone(),
        });
        Ok(Some(path.clone()))
    }

    /// Seconds outside steps so far, of the whole run.
    fn other_seconds(&self) -> f64 {
        let this_call = self.run_start.elapsed().as_secs_f64() - (self.train_seconds - self.earlier.train_seconds);
        self.earlier.other_seconds + this_call.max(0.0)
    }

    /// The run's time so far beside the checkpoint just written at `checkpoint`
    /// ([`super::run_time`]).
    fn save_run_time(&self, trainer: &Trainer, checkpoint: &Path) -> Result<(), RunError> {
        let io = |action| {
            move |source| RunError::Io {
                path: checkpoint.to_path_buf(),
                action,
                source,
            }
        };
        let time = RunTime {
            step: trainer.step_index(),
            train_seconds: self.train_seconds,
            other_seconds: self.other_seconds(),
            checkpoint_checksum: super::run_time::checkpoint_checksum(checkpoint)
                .map_err(io("reading the checksum back"))?,
        };
        let text = serde_json::to_string_pretty(&time).map_err(RunError::Summary)?;
        write_text_atomic(&super::run_time::path_beside(checkpoint), &text)
    }

    /// One step on the coarse or full-size views, timed; the time recorded in the time plan,
    /// which then re-plans the run's length; then [`TrainEvent::Step`]. Returns the steps done.
    fn step(
        &mut self,
        trainer: &mut Trainer,
        train: &[TrainView],
        on_event: &mut dyn FnMut(&TrainEvent),
    ) -> Result<usize, RunError> {
        let t0 = Instant::now();
        let (step_before, planned) = (trainer.step_index(), trainer.config().iterations);
        let config = self.config;
        let resolution = &config.resolution;
        let (is_coarse, calibrating) = match trainer.time_plan() {
            Some(plan) if plan.wants_calibration(resolution) => (false, true),
            Some(plan) => (plan.is_coarse(step_before, planned, resolution), false),
            None => (resolution.is_coarse(step_before, planned), false),
        };
        let views = if is_coarse { &self.coarse } else { train };
        let log = match trainer.step(views) {
            Ok(log) => log,
            Err(source) => return Err(self.step_failed(trainer, source, on_event)),
        };
        let seconds = match config.step_clock {
            StepClock::Wall => t0.elapsed().as_secs_f64(),
            StepClock::PerPixel(per_pixel) => {
                let pixels: u64 = views.iter().map(|v| v.camera.pixel_count() as u64).sum();
                per_pixel * pixels as f64 / views.len() as f64
            }
        };
        self.train_seconds += seconds;
        if let Some(plan) = trainer.time_plan_mut() {
            if calibrating {
                plan.record_calibration(seconds);
            } else {
                plan.record(step_before, is_coarse, seconds);
            }
        }
        replan(trainer, resolution);
        let iterations = trainer.config().iterations;
        self.running_psnr = if self.running_psnr.is_nan() {
            log.psnr
        } else {
            0.95 * self.running_psnr + 0.05 * log.psnr
        };
        self.relocated_total += log.relocated;
        let step = log.step;
        on_event(&TrainEvent::Step {
            log,
            iterations,
            running_psnr: self.running_psnr,
            relocated_total: self.relocated_total,
            train_seconds: self.train_seconds,
        });
        Ok(step)
    }

    /// The error of a failed step, naming the last good checkpoint: a refused step (non-finite
    /// loss or gradient) left the trainer as it was before the step, with parameters checked
    /// after the previous step (or before the run), and is saved as that state.
    fn step_failed(&self, trainer: &Trainer, source: TrainError, on_event: &mut dyn FnMut(&TrainEvent)) -> RunError {
        let refused = matches!(
            source,
            TrainError::NonFinite {
                value: NonFinite::Loss | NonFinite::Gradient(_),
                ..
            }
        );
        let checkpoint = if refused && self.checkpoint.is_some() {
            match self.save(trainer, on_event) {
                Ok(checkpoint) => checkpoint,
                Err(e) => return e,
            }
        } else {
            self.last_checkpoint.clone()
        };
        RunError::Step { source, checkpoint }
    }

    /// After step `step`: the checkpoint every [`RunConfig::save_every`] steps, the evaluation
    /// on the test subset every [`RunConfig::eval_every`] (not at the last step; abandoned when a
    /// stop request arrives, which the next turn of the loop handles).
    fn after_step(
        &mut self,
        trainer: &Trainer,
        step: usize,
        on_event: &mut dyn FnMut(&TrainEvent),
    ) -> Result<(), RunError> {
        let config = self.config;
        let iterations = trainer.config().iterations;
        // Both are asked (the request is taken even at a scheduled snapshot: it is then served).
        let requested = config.snapshot_request.as_ref().is_some_and(SnapshotRequest::take);
        if requested || (config.snapshot_every > 0 && step.is_multiple_of(config.snapshot_every)) {
            on_event(&TrainEvent::Snapshot {
                step,
                billboards: Arc::new(trainer.activated().clone()),
            });
        }
        if config.save_every > 0 && step.is_multiple_of(config.save_every) {
            self.last_checkpoint = self.save(trainer, on_event)?;
        }
        if config.eval_every > 0
            && step.is_multiple_of(config.eval_every)
            && step < iterations
            && !self.eval_subset.is_empty()
        {
            let Some((psnr, ssim, _)) = evaluate(
                &trainer.activated().borrowed(),
                &self.eval_subset,
                &self.eval_settings,
                self.stop,
            )?
            else {
                return Ok(());
            };
            self.curve.push(CurvePoint {
                step,
                seconds: self.train_seconds,
                psnr,
                ssim,
            });
            on_event(&TrainEvent::Evaluation {
                step,
                psnr,
                ssim,
                seconds: self.train_seconds,
                views: self.eval_subset.len(),
            });
        }
        Ok(())
    }

    /// The final save, with an output folder: the checkpoint first (if the model cannot be
    /// saved, the trained state is not lost), then the model as the reference saves it (8-bit
    /// textures), re-loaded as the reference's render.py evaluates it. Returns the model's bytes
    /// (0 without an output folder) and the re-loaded set, activated (`None` without).
    fn save_final(
        &self,
        trainer: &Trainer,
        on_event: &mut dyn FnMut(&TrainEvent),
    ) -> Result<(u64, Option<ActivatedBillboards>), RunError> {
        let Some(dir) = self.config.output.as_deref() else {
            return Ok((0, None));
        };
        let tc = &self.tc;
        let written = self.save(trainer, on_event)?;
        let model_dir = dir.join(MODEL_DIR);
        let meta = ModelMeta {
            scene: Some(self.scene_mark.clone()),
            ..ModelMeta::for_model(trainer.model(), tc.sh_degree, tc.background.to_array())
        };
        let model_bytes = match save_model(&model_dir, &trainer.export_model(), &meta) {
            Ok(bytes) => bytes,
            Err(source) => {
                return Err(match written {
                    Some(checkpoint) => RunError::ModelSave { source, checkpoint },
                    None => RunError::Model(source),
                });
            }
        };
        on_event(&TrainEvent::ModelSaved {
            path: model_dir.clone(),
            bytes: model_bytes,
        });
        let (model, _) = load_model(&model_dir)?;
        Ok((model_bytes, Some(model.activate())))
    }

    /// A stop request after the last step, once the checkpoint and model are saved.
    fn stopped_after_the_last_step(&self, trainer: &Trainer, on_event: &mut dyn FnMut(&TrainEvent)) -> RunOutcome {
        stopped(
            trainer.step_index(),
            StopReason::Requested,
            self.checkpoint.clone(),
            on_event,
        )
    }

    /// Mean PSNR, SSIM and render milliseconds on every test view (NaN without test views) of
    /// the re-loaded model `saved`, or of the trainer's float model without one; `None` when a
    /// stop request interrupts.
    fn final_evaluation(
        &self,
        trainer: &Trainer,
        test: &[TrainView],
        saved: Option<&ActivatedBillboards>,
    ) -> Result<Option<Scores>, RunError> {
        if test.is_empty() {
            return Ok(Some((f64::NAN, f64::NAN, f64::NAN, None)));
        }
        let all_test: Vec<&TrainView> = test.iter().collect();
        let set = match saved {
            Some(b) => b.borrowed(),
            None => trainer.activated().borrowed(),
        };
        let lpips = self.config.lpips.as_deref();
        evaluate_with_lpips(&set, &all_test, &self.eval_settings, self.stop, lpips)
    }

    /// The end: the final evaluation on the curve, the summary and the record
    /// ([`TrainEvent::Record`]), `summary.json` with an output folder, then
    /// [`TrainEvent::Finished`].
    fn finish(
        mut self,
        trainer: &Trainer,
        test: &[TrainView],
        (test_psnr, test_ssim, render_ms, lpips): Scores,
        model_bytes: u64,
        on_event: &mut dyn FnMut(&TrainEvent),
    ) -> Result<RunOutcome, RunError> {
        let config = self.config;
        let tc = self.tc;
        let iterations = trainer.config().iterations;
        let other_seconds = self.other_seconds();
        // The curve holds evaluations only: none without test views.
        if !test.is_empty() {
            self.curve.push(CurvePoint {
                step: iterations,
                seconds: self.train_seconds,
                psnr: test_psnr,
                ssim: test_ssim,
            });
        }
        let summary = TrainSummary {
            version: SUMMARY_VERSION,
            scene: config.scene.clone(),
            iterations,
            billboards: trainer.model().len(),
            alive: trainer.alive_count(),
            texture_size: trainer.model().texture_size,
            sh_degree: tc.sh_degree,
            resolution: self.resolution,
            train_seconds: self.train_seconds,
            render_ms_per_frame: render_ms,
            test_psnr,
            test_ssim,
            test_views: test.len(),
            model_bytes,
            peak_rss_bytes: peak_rss_bytes(),
            estimated_peak_bytes: config.estimated_peak_bytes,
            seed: tc.seed,
            threads: rayon::current_num_threads(),
            curve: self.curve,
            command: config.command.clone(),
            lpips_network: config.lpips.as_ref().map(|net| net.variant().name().to_string()),
            test_lpips: lpips.as_ref().and_then(|l| l.as_ref().ok().copied()),
            lpips_note: match (&lpips, &config.lpips) {
                (Some(Ok(_)), _) => None,
                (Some(Err(e)), _) => Some(format!("LPIPS not computed: {e}")),
                (None, Some(_)) => Some("LPIPS not computed: no test views".into()),
                (None, None) => Some(format!(
                    "LPIPS not computed: {}",
                    config
                        .lpips_note
                        .as_deref()
                        .unwrap_or("no LPIPS network was given to the run")
                )),
            },
        };
        let record = RunReport {
            automatic: config.automatic.clone(),
            plan: trainer.time_plan().map(|p| PlanRecord {
                budget_minutes: p.budget_seconds / 60.0,
                spent_minutes: p.spent_seconds / 60.0,
                planned_steps: iterations,
                coarse_step_seconds: p.coarse_step_seconds,
                fine_step_seconds: p.fine_step_seconds,
                fine_from: p.fine_from,
            }),
            growth: Some(GrowthRecord {
                initial: self.initial_billboards,
                final_count: trainer.model().len(),
                alive: summary.alive,
                cap: trainer.config().growth_cap,
            }),
            other_seconds,
        };
        on_event(&TrainEvent::Record(Box::new(record.clone())));
        let summary = if let Some(dir) = config.output.as_deref() {
            let file = SummaryFile {
                summary,
                settings: RecordedSettings {
                    clamp_gradient: clamp_gradient_name(tc.clamp_gradient).to_string(),
                    lambda_normal: tc.geometry.lambda_normal,
                    lambda_distortion: tc.geometry.lambda_distortion,
                    normal_from: (tc.geometry.lambda_normal != 0.0).then_some(tc.geometry.normal_from),
                    distortion_from: (tc.geometry.lambda_distortion != 0.0).then_some(tc.geometry.distortion_from),
                },
                warnings: self.warnings,
                record,
            };
            let text = serde_json::to_string_pretty(&file).map_err(RunError::Summary)?;
            write_text_atomic(&dir.join(SUMMARY_FILE), &text)?;
            file.summary
        } else {
            summary
        };
        let summary = Box::new(summary);
        on_event(&TrainEvent::Finished(summary.clone()));
        Ok(RunOutcome::Finished(summary))
    }
}
