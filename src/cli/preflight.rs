//! Checks of the output folder before a run loads anything: a folder that already holds a run is
//! refused unless the run is continued (`--resume`) or replaced (`--overwrite`); the folder must
//! be writable and `model/`, `checkpoint.bin` and `summary.json` must be free for this run's
//! files; temporary files left by earlier crashed runs are removed. The free-space check runs
//! once the size of the outputs is known.

use anyhow::{Context, Result};
use bbsplat::file_io::{FileKind, kind_of};
use bbsplat::memory::human_bytes;
use bbsplat::model_file::{META_FILE, PLY_FILE};
use bbsplat::train::run::{CHECKPOINT_FILE, MODEL_DIR, SUMMARY_FILE};
use bbsplat::train::run_time::RUN_TIME_FILE;
use std::ffi::OsStr;
use std::path::{Path, PathBuf};

/// Name of the probe file written and removed to check that the folder is writable.
const PROBE_FILE: &str = ".bbsplat-write-probe";

/// The files of a run that `out` already holds (empty when none): a checkpoint, a summary, a
/// model folder.
pub fn existing_run(out: &Path) -> Vec<&'static str> {
    let model = out.join(MODEL_DIR);
    let mut held: Vec<&'static str> = [CHECKPOINT_FILE, SUMMARY_FILE]
        .into_iter()
        .filter(|f| std::fs::symlink_metadata(out.join(f)).is_ok())
        .collect();
    if model.join(META_FILE).exists() || model.join(PLY_FILE).exists() {
        held.push(MODEL_DIR);
    }
    held
}

/// Everything about the output folder `out` that can be checked before loading: see the module
/// docs. `resume` is the checkpoint given with `--resume`. A folder created for the test is
/// removed again.
pub fn output_folder(out: &Path, resume: Option<&Path>, overwrite: bool) -> Result<()> {
    if let Ok(meta) = std::fs::metadata(out) {
        anyhow::ensure!(meta.is_dir(), "{}: exists and is not a folder", out.display());
    }
    let held = existing_run(out);
    if !held.is_empty() && !overwrite {
        let continues_this_run = resume.is_some_and(|r| same_file(r, &out.join(CHECKPOINT_FILE)));
        anyhow::ensure!(
            continues_this_run,
            "{} already holds a run ({}): continue it with --resume {} or replace it with --overwrite",
            out.display(),
            held.join(", "),
            out.join(CHECKPOINT_FILE).display()
        );
    }
    let created = !out.exists();
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create the output folder", out.display()))?;
    remove_leftovers(out);
    let probe = out.join(PROBE_FILE);
    bbsplat::file_io::write_atomic(&probe, b"probe")
        .with_context(|| format!("{}: the output folder is not writable", out.display()))?;
    let _ = std::fs::remove_file(&probe);
    let model = out.join(MODEL_DIR);
    if let Ok(meta) = std::fs::symlink_metadata(&model) {
        anyhow::ensure!(
            !meta.file_type().is_symlink(),
            "{}: is a link; the model is written there: remove it or choose another output folder",
            model.display()
        );
        anyhow::ensure!(
            meta.is_dir(),
            "{}: is a file; the model folder is written there: remove it or choose another output folder",
            model.display()
        );
        let is_model = model.join(META_FILE).exists() || model.join(PLY_FILE).exists();
        let empty = std::fs::read_dir(&model)
            .map(|mut d| d.next().is_none())
            .unwrap_or(false);
        anyhow::ensure!(
            is_model || empty,
            "{}: is a folder that is not a bbsplat model; the model is written there: remove it or choose another output folder",
            model.display()
        );
    }
    for file in [CHECKPOINT_FILE, SUMMARY_FILE, RUN_TIME_FILE] {
        // Links are written through (`bbsplat::file_io::write_atomic`): what they lead to counts.
        let path = out.join(file);
        match kind_of(&path) {
            Ok(FileKind::Regular | FileKind::Missing | FileKind::DanglingLink) => {}
            Ok(kind) => anyhow::bail!(
                "{}: {kind}, not a plain file; this run writes its {file} there",
                path.display()
            ),
            Err(e) => return Err(e).with_context(|| format!("{}: cannot check it", path.display())),
        }
    }
    if created {
        // Created only to test it; the run creates it again when it starts writing, so that a
        // command failing before (a scene that does not load) leaves nothing behind.
        let _ = std::fs::remove_dir(out);
    }
    Ok(())
}

/// Refuses the run when the file system of `out` has less than `needed` bytes free.
/// `BBSPLAT_DISK_LIMIT=<bytes>` replaces the measured free space (for tests: a full disk cannot
/// be made on demand).
pub fn free_space(out: &Path, needed: u64) -> Result<()> {
    let free = std::env::var("BBSPLAT_DISK_LIMIT")
        .ok()
        .and_then(|v| v.parse::<u64>().ok())
        .or_else(|| free_bytes(out.parent().filter(|p| !out.exists() && p.exists()).unwrap_or(out)));
    if let Some(free) = free {
        anyhow::ensure!(
            needed <= free,
            "{}: the outputs need about {}, {} free on its file system",
            out.display(),
            human_bytes(needed),
            human_bytes(free)
        );
    }
    Ok(())
}

/// Bytes available to unprivileged users on the file system of `path` (`statvfs`).
#[cfg(target_os = "linux")]
fn free_bytes(path: &Path) -> Option<u64> {
    use std::os::unix::ffi::OsStrExt;
    let c = std::ffi::CString::new(path.as_os_str().as_bytes()).ok()?;
    let mut s = std::mem::MaybeUninit::<libc::statvfs>::uninit();
    // SAFETY: `c` is a NUL-terminated path and `s` points to writable storage of the right
    // type; statvfs only writes it, and it is read only when the call succeeds.
    let r = unsafe { libc::statvfs(c.as_ptr(), s.as_mut_ptr()) };
    if r != 0 {
        return None;
    }
    // SAFETY: statvfs returned 0, so it filled the structure.
    let s = unsafe { s.assume_init() };
    // The field types differ between targets (u32 on some 32-bit ones).
    #[allow(clippy::unnecessary_cast)]
    let (blocks, size) = (s.f_bavail as u64, s.f_frsize as u64);
    Some(blocks.saturating_mul(size))
}

#[cfg(not(target_os = "linux"))]
fn free_bytes(_path: &Path) -> Option<u64> {
    None
}

/// True when `a` and `b` name the same existing file (or the same path).
fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => a == b,
    }
}

/// The process id in a temporary name written by this program: `.checkpoint.bin.tmp.<pid>.<n>`
/// (atomic files), `.model.tmp-<pid>-<n>` / `.model.old-<pid>-<n>` (model folders).
fn leftover_pid(name: &OsStr) -> Option<u32> {
    let name = name.to_str()?;
    // Only this program's own temporaries: never another hidden file of the folder.
    let ours = [
        CHECKPOINT_FILE,
        SUMMARY_FILE,
        MODEL_DIR,
        PROBE_FILE.trim_start_matches('.'),
    ]
    .iter()
    .any(|f| name.strip_prefix('.').is_some_and(|n| n.starts_with(&format!("{f}."))));
    if !ours {
        return None;
    }
    let rest = name.strip_prefix('.')?;
    let (_, tail) = rest
        .rsplit_once(".tmp.")
        .or_else(|| rest.rsplit_once(".tmp-"))
        .or_else(|| rest.rsplit_once(".old-"))?;
    let pid = tail.split(['.', '-']).next()?;
    pid.parse().ok()
}

/// Whether process `pid` is running (on Linux; elsewhere assumed running, so nothing is removed).
fn is_running(pid: u32) -> bool {
    if !cfg!(target_os = "linux") {
        return true;
    }
    pid == std::process::id() || Path::new("/proc").join(pid.to_string()).exists()
}

/// Removes the temporary files and folders that runs killed during a save left in `out` (those
/// of processes no longer running); returns what was removed.
pub fn remove_leftovers(out: &Path) -> Vec<PathBuf> {
    let mut removed = Vec::new();
    let Ok(entries) = std::fs::read_dir(out) else {
        return removed;
    };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let is_probe = name == PROBE_FILE;
        let stale = is_probe || leftover_pid(&name).is_some_and(|pid| !is_running(pid));
        if !stale {
            continue;
        }
        let path = entry.path();
        let gone = if entry.file_type().is_ok_and(|t| t.is_dir()) {
            std::fs::remove_dir_all(&path)
        } else {
            std::fs::remove_file(&path)
        };
        if gone.is_ok() {
            removed.push(path);
        }
    }
    removed
}
