//! A sweep (or any set of `bbsplat train` runs: `bbsplat benchmark --slurm`'s scenes,
//! [`array_scripts`]) as Slurm jobs: one array task per setting, and a collect job that runs
//! after every task succeeded (`--dependency=afterok`). Each task runs the very command the local
//! sweep runs for its setting ([`SubprocessRunner::args`]), with `exec` so that Slurm's signals (SIGTERM at
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

/// The scripts of an array job and its collect job ([`array_scripts`]; a sweep's:
/// [`slurm_scripts`]), to be written into one folder ([`write_slurm_scripts`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SlurmScripts {
    /// What the jobs are (`sweep`, `benchmark`): the jobs' names are `bbsplat-<job>` and
    /// `bbsplat-<job>-collect`, the array script's file `<job>.sbatch`.
    pub job: String,
    /// `<job>.sbatch`: the array job, one task per run.
    pub array: String,
    /// `collect.sbatch`: the collect job (a command that reads every task's summary and writes
    /// the reports).
    pub collect: String,
    /// `submit.sh`: submits the array, then the collect job with `afterok` on it; prints both job
    /// ids.
    pub submit: String,
}

/// One task of an array job: the run folder it trains into and the `bbsplat` arguments that
/// train it there (without `--threads` and `--resume`, which the task adds).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ArrayTask {
    /// The run folder (`-o` of its arguments): done when it holds `summary.json`, resumed when it
    /// holds `checkpoint.bin`.
    pub run_dir: PathBuf,
    /// The arguments of `bbsplat` (from the subcommand on).
    pub args: Vec<String>,
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
    let tasks: Vec<ArrayTask> = settings
        .iter()
        .map(|s| ArrayTask {
            run_dir: runner.run_dir(s),
            args: runner.args(s),
        })
        .collect();
    array_scripts("sweep", &runner.exe, &tasks, collect_command, dir, options)
}

/// The array job of `tasks` (each `exec`s `exe` with its arguments, `--threads` of its CPUs and
/// `--resume` of its checkpoint when it has one; a task whose run is done exits at once), the
/// collect job running `collect_command` (`exec`ed likewise) once every task succeeded, and the
/// submit script, with the scripts (and their logs) in `dir`. `job` names them
/// ([`SlurmScripts::job`]).
///
/// # Panics
/// When `tasks` is empty.
pub fn array_scripts(
    job: &str,
    exe: &Path,
    tasks: &[ArrayTask],
    collect_command: &[String],
    dir: &Path,
    options: &SlurmOptions,
) -> SlurmScripts {
    assert!(!tasks.is_empty(), "an array job has at least one task");
    let mut array = header(options, &format!("bbsplat-{job}"), &dir.join("task-%a.log"));
    array += &format!("#SBATCH --array=0-{}\n#SBATCH --open-mode=append\n", tasks.len() - 1);
    array += "set -eu\ncase \"$SLURM_ARRAY_TASK_ID\" in\n";
    for (i, task) in tasks.iter().enumerate() {
        let args: Vec<String> = task.args.iter().map(|a| shell_quote(a)).collect();
        array += &format!(
            "  {i}) run={}; set -- {} ;;\n",
            quote_path(&task.run_dir),
            args.join(" ")
        );
    }
    array += "  *) echo \"no task $SLURM_ARRAY_TASK_ID\" >&2; exit 2 ;;\nesac\n";
    array += "# Done: nothing to do. Interrupted (time limit, requeue): resume from the checkpoint.\n";
    array += "if [ -f \"$run/summary.json\" ]; then echo \"$run is done\"; exit 0; fi\n";
    array += "if [ -f \"$run/checkpoint.bin\" ]; then set -- \"$@\" --resume \"$run/checkpoint.bin\"; fi\n";
    array += "mkdir -p \"$run\"\n";
    array += &format!(
        "exec {} \"$@\" --threads \"${{SLURM_CPUS_PER_TASK:-1}}\" >>\"$run/train.log\" 2>&1\n",
        quote_path(exe)
    );
    let mut collect = header(options, &format!("bbsplat-{job}-collect"), &dir.join("collect.log"));
    collect += &format!(
        "set -eu\nexec {}\n",
        collect_command
            .iter()
            .map(|a| shell_quote(a))
            .collect::<Vec<_>>()
            .join(" ")
    );
    let submit = format!(
        "#!/bin/sh\n# Submits the {job}'s array job, then its collect job once every task succeeded.\nset -eu\n\
         array=$(sbatch --parsable {})\ncollect=$(sbatch --parsable --dependency=afterok:\"${{array%%;*}}\" {})\n\
         echo \"array job $array, collect job $collect\"\n",
        quote_path(&dir.join(format!("{job}.sbatch"))),
        quote_path(&dir.join("collect.sbatch"))
    );
    SlurmScripts {
        job: job.to_string(),
        array,
        collect,
        submit,
    }
}

/// Writes `scripts` into `dir` (created) as `<job>.sbatch`, `collect.sbatch` and `submit.sh`
/// (executable); returns their paths.
///
/// # Errors
/// When the folder cannot be created or a file written.
pub fn write_slurm_scripts(dir: &Path, scripts: &SlurmScripts) -> std::io::Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir)?;
    let mut paths = Vec::new();
    let array_file = format!("{}.sbatch", scripts.job);
    for (name, text) in [
        (array_file.as_str(), &scripts.array),
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
