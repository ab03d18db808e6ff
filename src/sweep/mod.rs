//! Budget sweeps: train once per point of a grid of settings (billboards, texture size,
//! iterations, resolution, texture threshold and mode, seed) and report speed against error.
//!
//! - [`SweepGrid`] lists values per axis and expands to [`Setting`]s in a stable order; it is
//!   read from JSON ([`SweepGrid::from_json_file`]) or CLI lists ([`SweepGrid::set_axis`]).
//! - [`run_grid`] calls a runner per setting and collects [`SweepRecord`]s; a failing run is
//!   recorded and the sweep continues. [`SubprocessRunner`] runs `bbsplat train` as one child
//!   process per setting (so the reported peak memory is that run's) and reads its
//!   `summary.json` ([`crate::report::TrainSummary`]); settings whose `summary.json` exists are
//!   not run again, so an interrupted sweep resumes.
//! - [`write_outputs`] writes the CSV, JSON, markdown table and SVG plots; [`pareto_front`] is
//!   the pure function behind the Pareto marks.
//!
//! Units: seconds (training wall clock), milliseconds (render time per frame), bytes (model size
//! and peak RSS; the table and plots show MB = 10⁶ bytes), dB (PSNR on 8-bit images).
//!
//! ```
//! use bbsplat::report::{SUMMARY_VERSION, TrainSummary};
//! use bbsplat::sweep::{SweepGrid, run_grid};
//!
//! let mut grid = SweepGrid::default();
//! grid.set_axis("billboards", "100,200").unwrap();
//! // A stand-in for `bbsplat train`: more billboards, better and slower.
//! let outcome = run_grid(&grid, |s| {
//!     let n = s.billboards.unwrap();
//!     Ok(TrainSummary {
//!         version: SUMMARY_VERSION, scene: "fake".into(), iterations: 10, billboards: n, alive: n,
//!         texture_size: 16, sh_degree: 3, resolution: [64, 64], train_seconds: n as f64 / 100.0,
//!         render_ms_per_frame: 1.0, test_psnr: 20.0 + n as f64 / 100.0, test_ssim: 0.8,
//!         test_views: 2, model_bytes: 1000 * n as u64, peak_rss_bytes: 0, estimated_peak_bytes: None, seed: 0, threads: 1,
//!         curve: vec![], command: vec![], lpips_network: None, test_lpips: None, lpips_note: None,
//!     })
//! })
//! .unwrap();
//! assert_eq!(outcome.records.len(), 2);
//! assert!(outcome.failures.is_empty());
//! ```

mod grid;
pub(crate) mod output;
mod pareto;
pub(crate) mod plot;
mod runner;
pub mod slurm;

pub use grid::{AXES, Setting, SweepGrid, parse_list};
pub use output::{CSV_HEADER, SweepFiles, csv_table, markdown_table, write_atomic, write_outputs};
pub use pareto::pareto_front;
pub use plot::{plot_curves_svg, plot_lines_svg, plot_psnr_vs_size_svg, plot_psnr_vs_time_svg};
pub use runner::{SubprocessRunner, subprocess_runner};
pub use slurm::{
    ArrayTask, SlurmOptions, SlurmScripts, array_scripts, shell_quote, slurm_scripts, write_slurm_scripts,
};

use crate::report::TrainSummary;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Errors of the sweep tool; file errors name the file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SweepError {
    /// A file could not be read, written or renamed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// A JSON file (grid or `summary.json`) could not be parsed or written.
    #[error("{path}: {source}")]
    Json {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: serde_json::Error,
    },
    /// A value of a grid axis is malformed or out of range.
    #[error("axis `{axis}`: bad value `{value}`: {reason}")]
    BadValue {
        /// The axis.
        axis: String,
        /// The offending value as written.
        value: String,
        /// Why it was refused.
        reason: String,
    },
    /// An axis name that is not one of [`AXES`].
    #[error("unknown sweep axis `{0}` (expected one of: {axes})", axes = AXES.join(", "))]
    UnknownAxis(String),
    /// The trainer executable could not be started.
    #[error("cannot start {exe}: {source}")]
    Spawn {
        /// The executable.
        exe: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The trainer exited unsuccessfully.
    #[error("run {slug} failed ({status}); see {log}")]
    RunFailed {
        /// The setting's slug.
        slug: String,
        /// The exit status.
        status: String,
        /// The file holding the run's stdout and stderr.
        log: PathBuf,
    },
    /// The trainer exited successfully but wrote no summary.
    #[error("{path}: missing after a successful run")]
    MissingSummary {
        /// The expected `summary.json`.
        path: PathBuf,
    },
    /// A `summary.json` disagrees with the setting it should belong to (e.g. a stale folder).
    #[error("{path}: {field} is {found}, the setting asks for {expected}")]
    Mismatch {
        /// The `summary.json`.
        path: PathBuf,
        /// The field.
        field: &'static str,
        /// The value of the setting.
        expected: String,
        /// The value in the file.
        found: String,
    },
    /// A plot could not be drawn.
    #[error("{path}: plotting failed: {message}")]
    Plot {
        /// The SVG file.
        path: PathBuf,
        /// The plotting library's message.
        message: String,
    },
    /// Any other runner failure (for runners other than [`SubprocessRunner`]).
    #[error("{0}")]
    Other(String),
    /// A file is not a regular file (a folder, a device, a FIFO; an output is then left as it
    /// is) or is larger than [`crate::file_io::JSON_FILE`].
    #[error(transparent)]
    File(crate::file_io::FileError),
}

/// An operating-system error is [`SweepError::Io`]; the rest is [`SweepError::File`].
impl From<crate::file_io::FileError> for SweepError {
    fn from(e: crate::file_io::FileError) -> Self {
        match e {
            crate::file_io::FileError::Io { path, source, .. } => SweepError::Io { path, source },
            other => SweepError::File(other),
        }
    }
}

/// One finished run: its setting and what it produced.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SweepRecord {
    /// The budget flags of the run.
    pub setting: Setting,
    /// The run's `summary.json`.
    pub summary: TrainSummary,
}

/// A setting whose run failed.
#[derive(Debug)]
pub struct SweepFailure {
    /// The setting.
    pub setting: Setting,
    /// What went wrong.
    pub error: SweepError,
}

/// Everything [`run_grid`] collected, in grid order.
#[derive(Debug, Default)]
pub struct SweepOutcome {
    /// Successful runs.
    pub records: Vec<SweepRecord>,
    /// Failed runs.
    pub failures: Vec<SweepFailure>,
}

/// Calls `runner` once per setting of `grid`, in [`SweepGrid::settings`] order, and collects the
/// summaries. A runner error is recorded in [`SweepOutcome::failures`] and the sweep goes on;
/// only an invalid grid is an error.
pub fn run_grid(
    grid: &SweepGrid,
    mut runner: impl FnMut(&Setting) -> Result<TrainSummary, SweepError>,
) -> Result<SweepOutcome, SweepError> {
    let mut outcome = SweepOutcome::default();
    for setting in grid.settings()? {
        match runner(&setting) {
            Ok(summary) => outcome.records.push(SweepRecord { setting, summary }),
            Err(error) => outcome.failures.push(SweepFailure { setting, error }),
        }
    }
    Ok(outcome)
}
