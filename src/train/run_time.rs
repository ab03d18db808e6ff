//! The time a run has spent, kept across `--resume`: a small JSON file beside the checkpoint
//! ([`RUN_TIME_FILE`], written by [`super::run::run`] after every checkpoint) that holds the
//! seconds spent in steps and outside them up to the checkpoint's step, tied to that checkpoint
//! by its step and its checksum (the checkpoint's last 8 bytes). The checkpoint itself holds no
//! wall-clock time, so that runs with the same seed write the same checkpoint bytes.
//!
//! A resumed run starts its clocks from these figures, so `summary.json` reports the time of the
//! whole run. When the file is missing or belongs to another checkpoint (copied, or written by
//! an interrupted save), [`read_beside`] says why and the resumed run counts from zero, with a
//! warning in the summary.
//!
//! ```
//! use bbsplat::train::run_time::RunTime;
//! let t = RunTime { step: 500, train_seconds: 61.5, other_seconds: 3.0, checkpoint_checksum: 7 };
//! let text = serde_json::to_string(&t).unwrap();
//! assert_eq!(serde_json::from_str::<RunTime>(&text).unwrap(), t);
//! ```

use serde::{Deserialize, Serialize};
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

/// File name of the run time, in the checkpoint's folder.
pub const RUN_TIME_FILE: &str = "run_time.json";

/// The size limit of a run-time file (it holds four numbers).
const RUN_TIME: crate::file_io::Limit = crate::file_io::Limit {
    bytes: 64 * 1024,
    what: "run-time file",
    plural: "run-time files",
};

/// The time spent by a run up to a checkpoint (module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RunTime {
    /// The checkpoint's step (steps done).
    pub step: usize,
    /// Seconds spent in steps, every earlier part of the run included.
    pub train_seconds: f64,
    /// Seconds spent outside steps (loading, evaluations, saves), every earlier part included.
    pub other_seconds: f64,
    /// The checkpoint's checksum (its last 8 bytes, little-endian).
    pub checkpoint_checksum: u64,
}

/// The run-time file of the checkpoint at `checkpoint`: [`RUN_TIME_FILE`] in its folder.
pub fn path_beside(checkpoint: &Path) -> PathBuf {
    match checkpoint.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.join(RUN_TIME_FILE),
        _ => PathBuf::from(RUN_TIME_FILE),
    }
}

/// The checksum stored in the checkpoint file at `path` (its last 8 bytes).
///
/// # Errors
/// The file cannot be opened or read, or is shorter than 8 bytes.
pub fn checkpoint_checksum(path: &Path) -> std::io::Result<u64> {
    let mut f = std::fs::File::open(path)?;
    let len = f.metadata()?.len();
    if len < 8 {
        return Err(std::io::Error::new(
            std::io::ErrorKind::UnexpectedEof,
            "shorter than a checksum",
        ));
    }
    f.seek(SeekFrom::Start(len - 8))?;
    let mut b = [0u8; 8];
    f.read_exact(&mut b)?;
    Ok(u64::from_le_bytes(b))
}

/// The run time recorded beside the checkpoint at `checkpoint`, whose trainer is at `step`; or
/// why there is none that belongs to it (missing, unreadable, or of another checkpoint).
pub fn read_beside(checkpoint: &Path, step: usize) -> Result<RunTime, String> {
    let path = path_beside(checkpoint);
    let why = |what: String| format!("{}: {what}; the time before step {step} is not counted", path.display());
    let text = crate::file_io::read_bounded(&path, RUN_TIME).map_err(|e| why(format!("cannot be read ({e})")))?;
    let time: RunTime = serde_json::from_slice(&text).map_err(|e| why(format!("is not valid ({e})")))?;
    let checksum = checkpoint_checksum(checkpoint).map_err(|e| why(format!("the checkpoint cannot be read ({e})")))?;
    if time.step != step {
        return Err(why(format!("belongs to another checkpoint (of step {})", time.step)));
    }
    if time.checkpoint_checksum != checksum {
        return Err(why("belongs to another checkpoint (its checksum differs)".into()));
    }
    let valid = |s: f64| s.is_finite() && s >= 0.0;
    if !(valid(time.train_seconds) && valid(time.other_seconds)) {
        return Err(why("holds a negative or non-finite time".into()));
    }
    Ok(time)
}
