//! Errors of a training step.

use super::finite::NonFinite;
use thiserror::Error;

/// Why [`super::Trainer::step`] refused to run or stopped. The trainer's state is unchanged when
/// a step returns an error, except for [`TrainError::NonFinite`] with
/// [`NonFinite::Parameter`], found after the optimiser step was applied.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[non_exhaustive]
pub enum TrainError {
    /// The list of training views is empty.
    #[error("no training views: a training step needs at least one view")]
    NoViews,
    /// A setting of the [`super::TrainConfig`] is out of its range (e.g. a negative or NaN
    /// texture-regulariser threshold); nothing was done.
    #[error("invalid training setting: {0}")]
    InvalidConfig(String),
    /// A view's image does not hold `width · height · 3` values of its camera.
    #[error("training view {view}: image has {got} values but its {width}x{height} camera needs {expected}")]
    ImageSize {
        /// Index of the view in the slice passed to `step`.
        view: usize,
        /// Camera width in pixels.
        width: u32,
        /// Camera height in pixels.
        height: u32,
        /// `width · height · 3`.
        expected: usize,
        /// Values found.
        got: usize,
    },
    /// A view's loss mask ([`super::TrainView::loss_mask`]) does not hold one value per pixel of
    /// its camera.
    #[error("training view {view}: loss mask has {got} values but its {width}x{height} camera has {} pixels", *width as usize * *height as usize)]
    MaskSize {
        /// Index of the view in the slice passed to `step`.
        view: usize,
        /// Camera width in pixels.
        width: u32,
        /// Camera height in pixels.
        height: u32,
        /// Values found.
        got: usize,
    },
    /// A view's image could not be read: an on-demand image ([`crate::scene::on_demand`]) whose
    /// file went away or changed since the scene was loaded. The step was not taken (the trainer
    /// is unchanged).
    #[error("training view {view}: {message}")]
    ViewImage {
        /// Index of the view in the slice passed to `step` (or evaluated).
        view: usize,
        /// What went wrong, naming the file.
        message: String,
    },
    /// The view-order stack (shuffled earlier, or restored from a checkpoint) names a view
    /// beyond the slice passed to `step`: the view list changed within an epoch.
    #[error("the shuffled view order refers to view {index}, but only {views} views were given")]
    ViewSetChanged {
        /// The out-of-range view index.
        index: usize,
        /// Number of views given.
        views: usize,
    },
    /// A NaN or infinite value in a step.
    ///
    /// [`NonFinite::Loss`] and [`NonFinite::Gradient`] are found before the optimiser step,
    /// which is then not applied: the trainer is exactly as before the step (view stack, RNG and
    /// every parameter and moment), so it can be saved as the last good state. For
    /// [`NonFinite::Parameter`] the step was applied (the trainer is at step `step`, with the bad
    /// value): recover from an earlier checkpoint.
    #[error(
        "step {step} (view {view}): {value} is not finite (NaN or infinite){}",
        applied_note(value)
    )]
    NonFinite {
        /// 1-based number of the step (as [`super::StepLog::step`] would have named it).
        step: usize,
        /// Index of the step's view in the slice passed to `step`.
        view: usize,
        /// Which value.
        value: NonFinite,
    },
}

fn applied_note(value: &NonFinite) -> &'static str {
    match value {
        NonFinite::Parameter(_) => "; the step was applied",
        _ => "; the step was not applied",
    }
}
