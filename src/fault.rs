//! A test-only fault-injection hook (feature `fault-injection`, which the crate's own tests turn
//! on; off for a program depending on the crate and for `cargo build`): `BBSPLAT_FAULT_AT=<point>`
//! makes the process abort (`std::process::abort`, as a `kill -9` would end it) when it reaches
//! that point of a save. The integration test
//! `cli_reliability::a_kill_at_any_point_of_the_save_leaves_a_complete_model_and_checkpoint`
//! runs `bbsplat train` once per point and checks that a complete model and checkpoint exist
//! after each. Not meant for users; without the variable a point costs one environment lookup,
//! and without the feature the points are empty functions (and the variable does nothing).
//!
//! Points, in the order of a run's final save:
//! - atomic file writes (`train::checkpoint::write_atomic`, the checkpoint and `summary.json`):
//!   `<file name>:<stage>` for each stage of `ATOMIC_STAGES`;
//! - the model folder (`model_file::save_model`): `model:<stage>` for each stage of
//!   `MODEL_STAGES`.

/// Stages of an atomic file write: the temporary file created, written, flushed to disk, and
/// renamed over the destination.
#[cfg(feature = "fault-injection")]
pub const ATOMIC_STAGES: [&str; 4] = crate::file_io::WRITE_STAGES;

/// Stages of a model save: the temporary folder written, swapped with the previous model (or
/// renamed into place), and the previous model removed.
#[cfg(feature = "fault-injection")]
pub const MODEL_STAGES: [&str; 3] = ["written", "swapped", "cleaned"];

/// Name of the environment variable.
#[cfg(feature = "fault-injection")]
pub const VARIABLE: &str = "BBSPLAT_FAULT_AT";

/// Aborts the process when [`VARIABLE`] equals `"<what>:<stage>"`.
#[cfg(feature = "fault-injection")]
pub fn point(what: &str, stage: &str) {
    if let Some(target) = std::env::var_os(VARIABLE)
        && target
            .to_str()
            .is_some_and(|t| t.strip_prefix(what).and_then(|r| r.strip_prefix(':')) == Some(stage))
    {
        eprintln!("{VARIABLE}: aborting at {what}:{stage}");
        std::process::abort();
    }
}

/// Without the feature: nothing (no environment lookup).
#[cfg(not(feature = "fault-injection"))]
#[inline(always)]
pub(crate) fn point(_what: &str, _stage: &str) {}
