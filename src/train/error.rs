//! Errors of a training step.

use thiserror::Error;

/// Why [`super::Trainer::step`] refused to run. The trainer's state is unchanged when a step
/// returns an error.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum TrainError {
    /// The list of training views is empty.
    #[error("no training views: a training step needs at least one view")]
    NoViews,
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
    /// The view-order stack (shuffled earlier, or restored from a checkpoint) names a view
    /// beyond the slice passed to `step`: the view list changed within an epoch.
    #[error("the shuffled view order refers to view {index}, but only {views} views were given")]
    ViewSetChanged {
        /// The out-of-range view index.
        index: usize,
        /// Number of views given.
        views: usize,
    },
}
