//! Runs `bbsplat train` as one child process per setting.

use super::{Setting, SweepError};
use crate::report::TrainSummary;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

/// Runs `<exe> train <scene> -o <out_root>/<slug> <setting flags> <extra args> --quiet` per
/// setting, with the child's stdout and stderr in `<out_root>/<slug>/train.log`, then reads
/// `<out_root>/<slug>/summary.json`.
///
/// Resumable: when that `summary.json` already exists the child is not started and the file is
/// read instead. A summary whose iterations, texture size or seed disagree with the setting is
/// refused ([`SweepError::Mismatch`]), which catches stale folders.
#[derive(Clone, Debug)]
pub struct SubprocessRunner {
    /// The `bbsplat` executable.
    pub exe: PathBuf,
    /// The scene folder passed to `train`.
    pub scene: PathBuf,
    /// Parent of the per-setting output folders.
    pub out_root: PathBuf,
    /// Flags passed to every run after the setting's own (e.g. `--threads 2`, `--sh-degree 3`).
    /// They are not part of the folder name: change `out_root` when changing them.
    pub extra_args: Vec<String>,
    /// Print one line per setting to stderr (started, resumed, failed).
    pub verbose: bool,
}

/// A [`SubprocessRunner`] with no extra arguments, not verbose, as a closure for
/// [`run_grid`](super::run_grid).
pub fn subprocess_runner(
    exe: PathBuf,
    scene: PathBuf,
    out_root: PathBuf,
) -> impl FnMut(&Setting) -> Result<TrainSummary, SweepError> {
    let runner = SubprocessRunner::new(exe, scene, out_root);
    move |s: &Setting| runner.run(s)
}

impl SubprocessRunner {
    /// A runner with no extra arguments, not verbose.
    pub fn new(exe: PathBuf, scene: PathBuf, out_root: PathBuf) -> Self {
        Self {
            exe,
            scene,
            out_root,
            extra_args: Vec::new(),
            verbose: false,
        }
    }

    /// The output folder of a setting.
    pub fn run_dir(&self, setting: &Setting) -> PathBuf {
        self.out_root.join(setting.slug())
    }

    /// The full argument list of the child for a setting (without the executable).
    pub fn args(&self, setting: &Setting) -> Vec<String> {
        let mut args = vec![
            "train".to_string(),
            self.scene.to_string_lossy().into_owned(),
            "-o".to_string(),
            self.run_dir(setting).to_string_lossy().into_owned(),
        ];
        args.extend(setting.train_args());
        args.extend(self.extra_args.iter().cloned());
        args.push("--quiet".into());
        args
    }

    /// Runs (or resumes) one setting.
    pub fn run(&self, setting: &Setting) -> Result<TrainSummary, SweepError> {
        let dir = self.run_dir(setting);
        let summary_path = dir.join("summary.json");
        let slug = setting.slug();
        if summary_path.exists() {
            if self.verbose {
                eprintln!("{slug}: resumed from {}", summary_path.display());
            }
            return read_summary(&summary_path, setting);
        }
        std::fs::create_dir_all(&dir).map_err(|source| SweepError::Io {
            path: dir.clone(),
            source,
        })?;
        let log_path = dir.join("train.log");
        let log = std::fs::File::create(&log_path).map_err(|source| SweepError::Io {
            path: log_path.clone(),
            source,
        })?;
        let log_err = log.try_clone().map_err(|source| SweepError::Io {
            path: log_path.clone(),
            source,
        })?;
        if self.verbose {
            eprintln!(
                "{slug}: running {} {}",
                self.exe.display(),
                self.args(setting).join(" ")
            );
        }
        let status = Command::new(&self.exe)
            .args(self.args(setting))
            .stdin(Stdio::null())
            .stdout(Stdio::from(log))
            .stderr(Stdio::from(log_err))
            .status()
            .map_err(|source| SweepError::Spawn {
                exe: self.exe.clone(),
                source,
            })?;
        if !status.success() {
            if self.verbose {
                eprintln!("{slug}: failed ({status}), log in {}", log_path.display());
            }
            return Err(SweepError::RunFailed {
                slug,
                status: status.to_string(),
                log: log_path,
            });
        }
        if !summary_path.exists() {
            return Err(SweepError::MissingSummary { path: summary_path });
        }
        read_summary(&summary_path, setting)
    }
}

/// Reads a `summary.json` and checks it against the setting.
fn read_summary(path: &Path, setting: &Setting) -> Result<TrainSummary, SweepError> {
    let text = crate::file_io::read_text_bounded(path, crate::file_io::JSON_FILE)?;
    let summary: TrainSummary = serde_json::from_str(&text).map_err(|source| SweepError::Json {
        path: path.to_path_buf(),
        source,
    })?;
    let checks: [(&'static str, Option<u64>, u64); 3] = [
        (
            "iterations",
            setting.iterations.map(|v| v as u64),
            summary.iterations as u64,
        ),
        (
            "texture_size",
            setting.texture_size.map(|v| v as u64),
            summary.texture_size as u64,
        ),
        ("seed", setting.seed, summary.seed),
    ];
    for (field, expected, found) in checks {
        if let Some(expected) = expected
            && expected != found
        {
            return Err(SweepError::Mismatch {
                path: path.to_path_buf(),
                field,
                expected: expected.to_string(),
                found: found.to_string(),
            });
        }
    }
    Ok(summary)
}
