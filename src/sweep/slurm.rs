//! A sweep as Slurm jobs: one array task per setting, and a collect job that runs after every
//! task succeeded (`--dependency=afterok`). Each task runs the very command the local sweep runs
//! for its setting ([`SubprocessRunner::args`]), with `exec` so that Slurm's signals (SIGTERM at
//! the time limit, `scancel`) reach `bbsplat`, which then saves its checkpoint. A task whose
//! setting has a `summary.json` is done and exits at once; one whose folder has a checkpoint (a
//! requeued or resubmitted task) resumes from it. `--iterations` runs are deterministic for any
//! thread count, so a task gives the same model as the local run of its setting.
//!
//! ```
//! use bbsplat::sweep::{SlurmOptions, SubprocessRunner, SweepGrid, slurm_scripts};
//! use std::path::PathBuf;
//! let mut grid = SweepGrid::default();
//! grid.set_axis("billboards", "100,200").unwrap();
//! let runner = SubprocessRunner::new("bbsplat".into(), "scene".into(), "out/runs".into());
//! let collect = vec!["sweep".to_string(), "scene".into(), "--out".into(), "out".into()];
//! let scripts = slurm_scripts(&runner, &grid.settings().unwrap(), &collect, &PathBuf::from("out/slurm"), &SlurmOptions::default());
//! assert!(scripts.array.contains("#SBATCH --array=0-1"));
//! assert!(scripts.submit.contains("--dependency=afterok:"));
//! ```

use super::{Setting, SubprocessRunner};
use std::path::{Path, PathBuf};

/// What the jobs ask of Slurm.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SlurmOptions {
    /// CPUs per array task (`--cpus-per-task`; `bbsplat` gets `--threads` of it). Default 2.
    pub cpus_per_task: u32,
    /// Memory per task in MB (`--mem`); `None`: the partition's default.
    pub mem_mb: Option<u64>,
    /// Time limit per task (`--time`, Slurm's syntax, e.g. `30:00`); `None`: the partition's.
    pub time: Option<String>,
    /// Partition (`--partition`); `None`: the default one.
    pub partition: Option<String>,
}

impl Default for SlurmOptions {
    fn default() -> Self {
        Self {
            cpus_per_task: 2,
            mem_mb: None,
            time: None,
            partition: None,
        }
    }
}

/// The scripts of a sweep on Slurm ([`slurm_scripts`]), to be written into one folder.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SlurmScripts {
    /// `sweep.sbatch`: the array job, one task per setting.
    pub array: String,
    /// `collect.sbatch`: the collect job (the sweep's own command, which reads every task's
    /// summary and writes the reports).
    pub collect: String,
    /// `submit.sh`: submits the array, then the collect job with `afterok` on it; prints both job
    /// ids.
    pub submit: String,
}

/// `s` quoted for a POSIX shell (single quotes; a single quote written as `'\''`).
pub fn shell_quote(s: &str) -> String {
    if !s.is_empty()
        && s.bytes()
            .all(|b| b.is_ascii_alphanumeric() || b"-_./=:,+@%".contains(&b))
    {
        return s.to_string();
    }
    format!("'{}'", s.replace('\'', r"'\''"))
}

fn quote_path(p: &Path) -> String {
    shell_quote(&p.display().to_string())
}

fn header(options: &SlurmOptions, name: &str, log: &Path) -> String {
    let mut h = format!(
        "#!/bin/bash\n#SBATCH --job-name={name}\n#SBATCH --output={}\n#SBATCH --cpus-per-task={}\n",
        log.display(),
        options.cpus_per_task
    );
    if let Some(mem) = options.mem_mb {
        h += &format!("#SBATCH --mem={mem}\n");
    }
    if let Some(time) = &options.time {
        h += &format!("#SBATCH --time={time}\n");
    }
    if let Some(partition) = &options.partition {
        h += &format!("#SBATCH --partition={partition}\n");
    }
    h
}

/// The array job, the collect job and the submit script of `settings` run by `runner`, with the
/// scripts (and their logs) in `dir`; `collect_command` is the command of the collect job (the
/// sweep's command line without its Slurm flags).
///
/// # Panics
/// When `settings` is empty.
pub fn slurm_scripts(
    runner: &SubprocessRunner,
    settings: &[Setting],
    collect_command: &[String],
    dir: &Path,
    options: &SlurmOptions,
) -> SlurmScripts {
    assert!(!settings.is_empty(), "a sweep has at least one setting");
    let mut array = header(options, "bbsplat-sweep", &dir.join("task-%a.log"));
    array += &format!("#SBATCH --array=0-{}\n#SBATCH --open-mode=append\n", settings.len() - 1);
    array += "set -eu\ncase \"$SLURM_ARRAY_TASK_ID\" in\n";
    for (i, s) in settings.iter().enumerate() {
        let args: Vec<String> = runner.args(s).iter().map(|a| shell_quote(a)).collect();
        array += &format!(
            "  {i}) run={}; set -- {} ;;\n",
            quote_path(&runner.run_dir(s)),
            args.join(" ")
        );
    }
    array += "  *) echo \"no setting for task $SLURM_ARRAY_TASK_ID\" >&2; exit 2 ;;\nesac\n";
    array += "# Done: nothing to do. Interrupted (time limit, requeue): resume from the checkpoint.\n";
    array += "if [ -f \"$run/summary.json\" ]; then echo \"$run is done\"; exit 0; fi\n";
    array += "if [ -f \"$run/checkpoint.bin\" ]; then set -- \"$@\" --resume \"$run/checkpoint.bin\"; fi\n";
    array += "mkdir -p \"$run\"\n";
    array += &format!(
        "exec {} \"$@\" --threads \"${{SLURM_CPUS_PER_TASK:-1}}\" >>\"$run/train.log\" 2>&1\n",
        quote_path(&runner.exe)
    );
    let mut collect = header(options, "bbsplat-sweep-collect", &dir.join("collect.log"));
    collect += &format!(
        "set -eu\nexec {}\n",
        collect_command
            .iter()
            .map(|a| shell_quote(a))
            .collect::<Vec<_>>()
            .join(" ")
    );
    let submit = format!(
        "#!/bin/sh\n# Submits the sweep's array job, then its collect job once every task succeeded.\nset -eu\n\
         array=$(sbatch --parsable {})\ncollect=$(sbatch --parsable --dependency=afterok:\"${{array%%;*}}\" {})\n\
         echo \"array job $array, collect job $collect\"\n",
        quote_path(&dir.join("sweep.sbatch")),
        quote_path(&dir.join("collect.sbatch"))
    );
    SlurmScripts { array, collect, submit }
}

/// Writes `scripts` into `dir` (created) as `sweep.sbatch`, `collect.sbatch` and `submit.sh`
/// (executable); returns their paths.
///
/// # Errors
/// When the folder cannot be created or a file written.
pub fn write_slurm_scripts(dir: &Path, scripts: &SlurmScripts) -> std::io::Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir)?;
    let mut paths = Vec::new();
    for (name, text) in [
        ("sweep.sbatch", &scripts.array),
        ("collect.sbatch", &scripts.collect),
        ("submit.sh", &scripts.submit),
    ] {
        let path = dir.join(name);
        crate::file_io::write_atomic(&path, text.as_bytes()).map_err(std::io::Error::other)?;
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755))?;
        }
        paths.push(path);
    }
    Ok(paths)
}
