//! A time budget for training (`bbsplat train --minutes M`): the trainer measures its step time
//! while it runs and plans the number of steps, and with it every schedule, so that the steps
//! take `M` minutes in total.
//!
//! # How the plan is made
//!
//! Every schedule of the trainer scales with [`super::TrainConfig::iterations`] (learning-rate
//! decay, SH degree, texture window, relocation and growth window, coarse-to-fine switch), so a
//! time budget is a choice of `iterations`. After every step [`TimePlan::record`] adds the step's
//! wall-clock seconds to what was spent and to a running estimate of the cost of a step of its
//! phase (coarse or full resolution: the plain mean of the first [`WARMUP_STEPS`] steps of the
//! phase, then an exponential average with weight [`COST_WEIGHT`] on the newest, which follows
//! the steps as they slow down with growth). [`TimePlan::planned_iterations`] then re-plans with
//! [`planned_iterations`]: the remaining seconds divided by the estimated costs, the coarse
//! phase (the first `⌈until·N⌉` steps) and the full-resolution rest priced separately.
//!
//! The price of the full-resolution steps decides where the coarse phase ends, so it is
//! measured early: after [`CALIBRATE_AFTER`] coarse steps (when the running estimate has
//! forgotten the slow first steps), [`CALIBRATION_STEPS`] steps train on the
//! full-size images ([`TimePlan::wants_calibration`]; they are ordinary training steps, only at
//! the other resolution); the last one, over the coarse estimate of the time, gives the cost
//! ratio of the two phases, and until the full-resolution phase starts its steps are priced at
//! that ratio times the current coarse estimate (so that a machine-wide slowdown or growth,
//! which slow both phases, do not skew the split). (The ratio is not a constant: a full-size lego step at factor 2 cost 2.7× a coarse one, a demo-scene
//! step 1.2-1.4×, where the per-billboard work dominates.) Before that, the full cost is guessed
//! as the coarse cost times [`FINE_COST_RATIO_PER_PIXEL_RATIO`] × the pixel ratio `factor²`.
//!
//! The switch to full resolution, once it has happened, is pinned ([`TimePlan::fine_from`]):
//! a later re-plan that raises `iterations` cannot send the run back to coarse images. The run
//! ends when the planned count is reached: the last re-plans are made with the costs of the last
//! steps, so the total is within about one step of the budget. Evaluation, checkpoints and saving
//! are outside the budget (only step time counts), as is loading the scene.
//!
//! The plan is part of the trainer and of its checkpoint ([`super::checkpoint`]), so a resumed
//! run continues the same budget with what was spent. A budgeted run depends on the machine's
//! speed and is not reproducible bit for bit; `--iterations` is for exact runs.

use super::resolution::ResolutionSchedule;

/// Steps of a phase whose costs are averaged plainly before the exponential average starts.
pub const WARMUP_STEPS: u64 = 10;
/// Weight of the newest step in the running cost estimate after the warm-up.
pub const COST_WEIGHT: f64 = 0.1;
/// Prior cost of a full-resolution step relative to a coarse one, per unit of pixel ratio
/// (measured on lego: 0.49 s / 0.18 s = 2.7 at a pixel ratio of 4).
pub const FINE_COST_RATIO_PER_PIXEL_RATIO: f64 = 0.68;
/// Coarse steps measured before the calibration steps.
pub const CALIBRATE_AFTER: u64 = 3 * WARMUP_STEPS;
/// Full-resolution steps taken during the coarse phase to price the full-resolution phase.
pub const CALIBRATION_STEPS: u64 = 2;
/// Largest number of steps a plan may choose.
pub const MAX_PLANNED_STEPS: usize = 100_000_000;
/// Steps planned before any step was measured (only step 0 runs under it; its schedules do not
/// depend on the count, except the run-length learning-rate factor, which this short-run count
/// gives its short-run value).
pub const PROVISIONAL_STEPS: usize = 7000;

/// The state of a time-budgeted run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TimePlan {
    /// The budget of step time, seconds.
    pub budget_seconds: f64,
    /// Step time spent so far, seconds (over every call of the run, resumed ones included).
    pub spent_seconds: f64,
    /// Estimated seconds of a coarse step (0 before one was measured).
    pub coarse_step_seconds: f64,
    /// Coarse steps measured.
    pub coarse_steps: u64,
    /// Estimated seconds of a full-resolution step (0 before one was measured).
    pub fine_step_seconds: f64,
    /// Full-resolution steps measured.
    pub fine_steps: u64,
    /// The step at which full resolution started, once it has.
    pub fine_from: Option<usize>,
    /// Full-resolution calibration steps taken during the coarse phase.
    pub calibration_steps: u64,
    /// Cost of the last calibration step over the coarse estimate then (0 before one).
    pub calibrated_ratio: f64,
}

impl TimePlan {
    /// A plan of `minutes` of step time, nothing spent.
    pub fn new(minutes: f64) -> Self {
        Self {
            budget_seconds: minutes * 60.0,
            spent_seconds: 0.0,
            coarse_step_seconds: 0.0,
            coarse_steps: 0,
            fine_step_seconds: 0.0,
            fine_steps: 0,
            fine_from: None,
            calibration_steps: 0,
            calibrated_ratio: 0.0,
        }
    }

    /// True when the next step should be a full-resolution calibration step: a coarse phase is
    /// running, [`CALIBRATE_AFTER`] coarse steps were measured, and fewer than
    /// [`CALIBRATION_STEPS`] full-resolution steps have been.
    pub fn wants_calibration(&self, schedule: &ResolutionSchedule) -> bool {
        schedule.factor > 1
            && schedule.until > 0.0
            && self.fine_from.is_none()
            && self.fine_steps == 0
            && self.coarse_steps >= CALIBRATE_AFTER
            && self.calibration_steps < CALIBRATION_STEPS
    }

    /// Records a full-resolution calibration step of `seconds`: it counts as spent, and (the
    /// first one paying for larger buffers) the last one sets the cost ratio of the two phases
    /// (over the current coarse estimate; ignored while there is none).
    pub fn record_calibration(&mut self, seconds: f64) {
        self.spent_seconds += seconds;
        self.calibration_steps += 1;
        if self.coarse_step_seconds > 0.0 {
            self.calibrated_ratio = seconds / self.coarse_step_seconds;
        }
    }

    /// Seconds of the budget left (may be negative after the last step).
    pub fn remaining_seconds(&self) -> f64 {
        self.budget_seconds - self.spent_seconds
    }

    /// True when step `step` of a run of `iterations` trains on the coarse images: the
    /// schedule's rule until full resolution started, never after.
    pub fn is_coarse(&self, step: usize, iterations: usize, schedule: &ResolutionSchedule) -> bool {
        match self.fine_from {
            Some(from) => step < from,
            None => schedule.is_coarse(step, iterations),
        }
    }

    /// Records step `step` (0-based), which trained `coarse` or not and took `seconds`.
    pub fn record(&mut self, step: usize, coarse: bool, seconds: f64) {
        self.spent_seconds += seconds;
        let (estimate, count) = if coarse {
            (&mut self.coarse_step_seconds, &mut self.coarse_steps)
        } else {
            if self.fine_from.is_none() {
                self.fine_from = Some(step);
            }
            (&mut self.fine_step_seconds, &mut self.fine_steps)
        };
        *count += 1;
        let weight = if *count <= WARMUP_STEPS {
            1.0 / *count as f64
        } else {
            COST_WEIGHT
        };
        *estimate += weight * (seconds - *estimate);
    }

    /// The number of steps to plan now that `step` steps are done ([`planned_iterations`] with
    /// this plan's estimates); [`PROVISIONAL_STEPS`] before any step was measured.
    pub fn planned_iterations(&self, step: usize, schedule: &ResolutionSchedule) -> usize {
        let coarse_phase = schedule.factor > 1 && schedule.until > 0.0 && self.fine_from.is_none();
        let fine = if self.fine_steps > 0 {
            self.fine_step_seconds
        } else if self.calibrated_ratio > 0.0 {
            self.coarse_step_seconds * self.calibrated_ratio
        } else {
            let pixel_ratio = (schedule.factor as f64).powi(2);
            self.coarse_step_seconds * (FINE_COST_RATIO_PER_PIXEL_RATIO * pixel_ratio).max(1.0)
        };
        if fine <= 0.0 {
            return PROVISIONAL_STEPS;
        }
        let coarse = if coarse_phase {
            Some((self.coarse_step_seconds, schedule.until.clamp(0.0, 1.0)))
        } else {
            None
        };
        planned_iterations(step, self.remaining_seconds(), fine, coarse)
    }
}

/// The number of steps `N` of a run with `step` steps done and `remaining` seconds left, a
/// full-resolution step costing `fine` seconds and, while the coarse phase lasts, `coarse =
/// Some((seconds, until))`: the coarse phase being the first `until·N` steps.
///
/// - No coarse phase: `N = step + round(remaining / fine)`.
/// - Coarse phase: `N` solves `remaining = c·(until·N − step) + fine·(1 − until)·N`, when that
///   `N` keeps the current step coarse (`until·N > step`); otherwise the phase ends now and
///   `N = step + round(remaining / fine)`, at most `⌊step / until⌋` (so the switch stays now).
///
/// Never below `step`, at most [`MAX_PLANNED_STEPS`].
///
/// ```
/// use bbsplat::train::time_budget::planned_iterations;
/// // 10 s left at 0.1 s a step: 100 more.
/// assert_eq!(planned_iterations(50, 10.0, 0.1, None), 150);
/// // Nothing spent, half the run coarse at a quarter of the cost: 0.5·N·0.025 + 0.5·N·0.1 = 10.
/// assert_eq!(planned_iterations(0, 10.0, 0.1, Some((0.025, 0.5))), 160);
/// assert_eq!(planned_iterations(70, -1.0, 0.1, None), 70);
/// ```
pub fn planned_iterations(step: usize, remaining: f64, fine: f64, coarse: Option<(f64, f64)>) -> usize {
    let s = step as f64;
    let fine_only = |r: f64| (s + (r.max(0.0) / fine).round()).min(MAX_PLANNED_STEPS as f64);
    let n = match coarse {
        Some((c, until)) if until > 0.0 => {
            // remaining + c·s = N·(c·until + fine·(1 − until)).
            let n = ((remaining.max(0.0) + c * s) / (c * until + fine * (1.0 - until))).max(0.0);
            if until * n > s {
                n.round().min(MAX_PLANNED_STEPS as f64)
            } else {
                fine_only(remaining).min((s / until).floor())
            }
        }
        _ => fine_only(remaining),
    };
    (n as usize).max(step)
}
