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
    let text = std::fs::read_to_string(path).map_err(|source| SweepError::Io {
        path: path.to_path_buf(),
        source,
    })?;
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

#[cfg(all(test, unix))]
mod tests {
    use super::*;
    use crate::sweep::{SweepGrid, fake, run_grid};
    use std::os::unix::fs::PermissionsExt;

    fn temp_dir(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("bbsplat-sweep-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    /// A shell script standing in for `bbsplat`: logs its arguments to `<out>/args.txt`, copies
    /// `<out>.json` (prepared by the test) to `<out>/summary.json`, fails when `<out>.fail`
    /// exists.
    fn fake_exe(dir: &Path) -> PathBuf {
        let exe = dir.join("fake-bbsplat");
        std::fs::write(
            &exe,
            "#!/bin/sh\nout=$4\necho \"$@\" >> \"$out/args.txt\"\necho training\n\
             if [ -e \"$out.fail\" ]; then echo boom >&2; exit 3; fi\ncp \"$out.json\" \"$out/summary.json\"\n",
        )
        .unwrap();
        std::fs::set_permissions(&exe, std::fs::Permissions::from_mode(0o755)).unwrap();
        exe
    }

    #[test]
    fn runs_each_setting_once_then_resumes() {
        let dir = temp_dir("runner");
        let exe = fake_exe(&dir);
        let out = dir.join("runs");
        std::fs::create_dir_all(&out).unwrap();
        let mut grid = SweepGrid::default();
        grid.set_axis("billboards", "10,20").unwrap();
        grid.set_axis("iterations", "5").unwrap();
        grid.set_axis("seeds", "7").unwrap();
        let settings = grid.settings().unwrap();
        for s in &settings {
            let json = serde_json::to_string(&fake::summary(s)).unwrap();
            std::fs::write(out.join(format!("{}.json", s.slug())), json).unwrap();
        }
        // The second setting fails the first time.
        let fail_marker = out.join(format!("{}.fail", settings[1].slug()));
        std::fs::write(&fail_marker, "").unwrap();

        let mut runner = SubprocessRunner::new(exe.clone(), PathBuf::from("scenes/x"), out.clone());
        runner.extra_args = vec!["--threads".into(), "1".into()];
        let first = run_grid(&grid, |s| runner.run(s)).unwrap();
        assert_eq!(first.records.len(), 1);
        assert_eq!(first.records[0].summary, fake::summary(&settings[0]));
        let err = first.failures[0].error.to_string();
        assert!(err.contains("it5_bb20_s7") && err.contains("train.log"), "{err}");
        let log = std::fs::read_to_string(out.join("it5_bb20_s7/train.log")).unwrap();
        assert!(log.contains("boom") && log.contains("training"), "{log}");

        let args = std::fs::read_to_string(out.join("it5_bb10_s7/args.txt")).unwrap();
        assert_eq!(
            args.trim(),
            format!(
                "train scenes/x -o {} --iterations 5 --billboards 10 --seed 7 --threads 1 --quiet",
                out.join("it5_bb10_s7").display()
            )
        );

        std::fs::remove_file(&fail_marker).unwrap();
        let second = run_grid(&grid, subprocess_runner(exe, "scenes/x".into(), out.clone())).unwrap();
        assert_eq!(second.records.len(), 2);
        assert!(second.failures.is_empty());
        // The finished run was not started again; the failed one ran a second time.
        let count = |slug: &str| {
            std::fs::read_to_string(out.join(slug).join("args.txt"))
                .unwrap()
                .lines()
                .count()
        };
        assert_eq!(count("it5_bb10_s7"), 1);
        assert_eq!(count("it5_bb20_s7"), 2);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn stale_or_missing_summaries_are_reported_with_their_path() {
        let dir = temp_dir("stale");
        let exe = fake_exe(&dir);
        let setting = Setting {
            iterations: Some(100),
            billboards: None,
            texture_size: None,
            max_width: None,
            texture_threshold: None,
            texture_mode: None,
            seed: None,
        };
        let runner = SubprocessRunner::new(exe, "s".into(), dir.clone());
        // A folder left by a run with other flags.
        let run_dir = runner.run_dir(&setting);
        std::fs::create_dir_all(&run_dir).unwrap();
        let mut stale = fake::summary(&setting);
        stale.iterations = 50;
        std::fs::write(run_dir.join("summary.json"), serde_json::to_string(&stale).unwrap()).unwrap();
        let err = runner.run(&setting).unwrap_err();
        assert!(
            matches!(
                err,
                SweepError::Mismatch {
                    field: "iterations",
                    ..
                }
            ),
            "{err}"
        );
        assert!(err.to_string().contains("summary.json"));
        // A truncated summary.
        std::fs::write(run_dir.join("summary.json"), "{\"version\": 1").unwrap();
        assert!(matches!(runner.run(&setting), Err(SweepError::Json { .. })));
        // A child that succeeds without writing one: the script's `cp` fails, so use `true`.
        std::fs::remove_file(run_dir.join("summary.json")).unwrap();
        let quiet = SubprocessRunner::new("true".into(), "s".into(), dir.clone());
        assert!(matches!(quiet.run(&setting), Err(SweepError::MissingSummary { .. })));
        // A missing executable.
        let missing = SubprocessRunner::new(dir.join("nope"), "s".into(), dir.clone());
        assert!(matches!(missing.run(&setting), Err(SweepError::Spawn { .. })));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
