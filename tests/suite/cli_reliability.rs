//! Nothing lost, nothing silently wrong (`bbsplat train` as a hostile user would run it): a
//! folder holding a run is not replaced by mistake; `--resume` continues the same run or
//! refuses; flags out of range, memory that does not fit and output paths that cannot take the
//! run are refused before training; signals stop with a checkpoint; a kill at any point of the
//! save leaves a complete model and checkpoint; damaged images and outlying cameras are refused
//! or flagged, and every warning reaches summary.json.

use super::cli::{export_demo, run_ok, temp, tiny_train_args, write_tiny_blender_scene};
use bbsplat::model_file::load_model;
use bbsplat::train::Trainer;
use std::path::Path;
use std::process::{Command, Output};

fn bbsplat(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_bbsplat"))
        .args(args)
        .env("RUST_BACKTRACE", "0")
        .output()
        .expect("the binary runs")
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Asserts that `out` failed with a message containing `needle`, without a panic and before
/// training started (the line naming the views is printed when training starts).
fn refused(out: &Output, needle: &str) {
    let (err, printed) = (stderr(out), String::from_utf8_lossy(&out.stdout));
    assert!(
        !out.status.success(),
        "accepted; expected {needle:?}:\n{printed}\n{err}"
    );
    assert!(err.contains(needle), "expected {needle:?} in:\n{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(
        !printed.contains("views at"),
        "training started before the refusal:\n{printed}"
    );
}

/// Failure 1: `train` into a folder that holds a run is refused (the run is untouched) unless
/// `--resume` continues it or `--overwrite` replaces it.
#[test]
fn a_folder_holding_a_run_is_refused_unless_resumed_or_overwritten() {
    let root = temp("rel-exists");
    let data = export_demo(&root, 24, 100);
    let out = root.join("out");
    let (d, o) = (data.to_str().unwrap(), out.to_str().unwrap());
    run_ok(&tiny_train_args(d, o, &[]));
    let before = std::fs::read(out.join("checkpoint.bin")).unwrap();
    let again = bbsplat(&tiny_train_args(d, o, &["--seed", "7"]));
    refused(&again, "already holds a run");
    assert!(stderr(&again).contains("--overwrite"));
    assert!(
        std::fs::read(out.join("checkpoint.bin")).unwrap() == before,
        "the run was touched"
    );
    // A resume from another folder's checkpoint into this one is refused too.
    let other = root.join("other");
    run_ok(&tiny_train_args(d, other.to_str().unwrap(), &["--stop-after", "5"]));
    let other_ckpt = other.join("checkpoint.bin");
    refused(
        &bbsplat(&tiny_train_args(d, o, &["--resume", other_ckpt.to_str().unwrap()])),
        "already holds a run",
    );
    // --overwrite replaces it.
    run_ok(&tiny_train_args(d, o, &["--overwrite", "--seed", "3"]));
    assert!(std::fs::read(out.join("checkpoint.bin")).unwrap() != before);
    std::fs::remove_dir_all(&root).ok();
}

/// Failures 3-5: every numeric flag out of range, and runs that cannot fit in memory, are
/// refused at once with a message naming the flag: no panic, no abort.
#[test]
fn out_of_range_flags_and_runs_too_big_for_memory_are_refused_naming_the_flag() {
    let root = temp("rel-flags");
    let data = export_demo(&root, 24, 100);
    let out = root.join("out");
    let (d, o) = (data.to_str().unwrap(), out.to_str().unwrap());
    let train = |flags: &[&str]| {
        let mut args = vec!["train", d, "-o", o];
        args.extend_from_slice(flags);
        let output = Command::new(env!("CARGO_BIN_EXE_bbsplat"))
            .args(&args)
            .env("RUST_BACKTRACE", "0")
            .env("BBSPLAT_MEMORY_LIMIT", "2000000000")
            .output()
            .unwrap();
        // Refused at once: before any billboard was made (the run prints "initialising" first).
        let printed = String::from_utf8_lossy(&output.stdout);
        assert!(
            !printed.contains("initialising") && !printed.contains("views at"),
            "{flags:?} was refused only after it started: {printed}"
        );
        output
    };
    let cases: &[(&[&str], &str)] = &[
        (&["--texture-threshold=-5"], "--texture-threshold"),
        (&["--texture-threshold", "nan"], "--texture-threshold"),
        (&["--texture-threshold", "inf"], "--texture-threshold"),
        (&["--texture-size", "1025"], "--texture-size must be at most 1024"),
        (&["--texture-size", "1"], "--texture-size must be at least 2"),
        (&["--sh-degree", "4"], "--sh-degree"),
        (&["--threads", "0"], "--threads"),
        (&["--coarse-factor", "0"], "--coarse-factor"),
        (&["--coarse-until", "1.5"], "--coarse-until"),
        (&["--hull-resolution", "100000", "--init", "hull"], "--hull-resolution"),
        (&["--billboards", "0"], "--billboards must be at least 1"),
        (&["--billboards", "18446744073709551615"], "available"),
        (&["--billboards", "2000000", "--texture-size", "64"], "needs"),
        (&["--iterations", "0"], "--iterations"),
    ];
    for (flags, needle) in cases {
        let output = train(flags);
        refused(&output, needle);
        if flags[0] == "--billboards" && needle == &"needs" {
            assert!(stderr(&output).contains("--billboards 2000000"), "{}", stderr(&output));
        }
    }
    assert!(!out.join("model").exists() && !out.join("checkpoint.bin").exists());
    // The demo's own flags.
    let demo = |flags: &[&str]| {
        let mut args = vec!["demo", "--iterations", "1"];
        args.extend_from_slice(flags);
        Command::new(env!("CARGO_BIN_EXE_bbsplat"))
            .args(&args)
            .env("RUST_BACKTRACE", "0")
            .env("BBSPLAT_MEMORY_LIMIT", "2000000000")
            .output()
            .unwrap()
    };
    refused(&demo(&["--resolution", "100000"]), "--resolution must be at most");
    refused(&demo(&["--resolution", "8000"]), "needs");
    refused(&demo(&["--billboards", "18446744073709551615"]), "needs");
    refused(&demo(&["--texture-size", "5000"]), "--texture-size");
    std::fs::remove_dir_all(&root).ok();
}

/// Failure 3: a path that is not UTF-8 trains to the end and its summary is written.
#[cfg(unix)]
#[test]
fn a_non_utf8_output_path_trains_and_writes_its_summary() {
    use std::os::unix::ffi::OsStrExt;
    let root = temp("rel-utf8");
    let data = export_demo(&root, 24, 100);
    let out = root.join(std::ffi::OsStr::from_bytes(b"out-\xff\xfe"));
    let output = Command::new(env!("CARGO_BIN_EXE_bbsplat"))
        .args(["train", data.to_str().unwrap(), "-o"])
        .arg(&out)
        .args([
            "--iterations",
            "5",
            "--billboards",
            "60",
            "--texture-size",
            "4",
            "--quiet",
        ])
        .output()
        .unwrap();
    assert!(output.status.success(), "{}", stderr(&output));
    let text = std::fs::read_to_string(out.join("summary.json")).unwrap();
    let file: bbsplat::report::SummaryFile = serde_json::from_str(&text).unwrap();
    assert!(
        file.summary.command.iter().any(|a| a.contains('\u{fffd}')),
        "{:?}",
        file.summary.command
    );
    std::fs::remove_dir_all(&root).ok();
}

/// Failure 4: output paths that cannot take the run are refused before training: an
/// unwritable folder, `model` taken by a file, a link or another folder, `checkpoint.bin` taken
/// by a folder, an output path that is a file.
#[test]
fn output_paths_that_cannot_take_the_run_are_refused_before_training() {
    let root = temp("rel-paths");
    let data = export_demo(&root, 24, 100);
    let d = data.to_str().unwrap();
    let attempt = |out: &Path| bbsplat(&tiny_train_args(d, out.to_str().unwrap(), &[]));
    #[cfg(target_os = "linux")]
    refused(&attempt(Path::new("/proc/self")), "not writable");
    let file_model = root.join("file-model");
    std::fs::create_dir_all(&file_model).unwrap();
    std::fs::write(file_model.join("model"), b"x").unwrap();
    refused(&attempt(&file_model), "is a file");
    let other_folder = root.join("folder-model");
    std::fs::create_dir_all(other_folder.join("model")).unwrap();
    std::fs::write(other_folder.join("model/notes.txt"), b"mine").unwrap();
    refused(&attempt(&other_folder), "not a bbsplat model");
    #[cfg(unix)]
    {
        let link_model = root.join("link-model");
        std::fs::create_dir_all(&link_model).unwrap();
        std::os::unix::fs::symlink(&data, link_model.join("model")).unwrap();
        refused(&attempt(&link_model), "is a link");
    }
    let dir_checkpoint = root.join("dir-checkpoint");
    std::fs::create_dir_all(dir_checkpoint.join("checkpoint.bin")).unwrap();
    refused(
        &bbsplat(&tiny_train_args(d, dir_checkpoint.to_str().unwrap(), &["--overwrite"])),
        "not a plain file",
    );
    let file_out = root.join("a-file");
    std::fs::write(&file_out, b"x").unwrap();
    refused(&attempt(&file_out), "not a folder");
    assert_eq!(std::fs::read(other_folder.join("model/notes.txt")).unwrap(), b"mine");
    std::fs::remove_dir_all(&root).ok();
}

/// Failure 2: `--resume` refuses another dataset and flags that change the model or the
/// optimisation, naming them; the same flags continue.
/// A resumed run is estimated with its views, like a fresh one, and refused when it does not fit.
#[test]
fn a_resumed_run_too_big_for_memory_is_refused_before_training() {
    let root = temp("rel-resume-memory");
    let data = export_demo(&root, 24, 100);
    let out = root.join("out");
    let (d, o) = (data.to_str().unwrap(), out.to_str().unwrap());
    run_ok(&tiny_train_args(d, o, &["--stop-after", "10"]));
    let checkpoint = out.join("checkpoint.bin");
    let before = std::fs::read(&checkpoint).unwrap();
    // Enough for the billboards alone (the check made before the scene loads), not for the
    // run with its 40 views of 24×24.
    let limit = bbsplat::train::footprint::training_bytes(120, 4, 0, 0) + 1;
    let output = Command::new(env!("CARGO_BIN_EXE_bbsplat"))
        .args(tiny_train_args(d, o, &["--resume", checkpoint.to_str().unwrap()]))
        .env("RUST_BACKTRACE", "0")
        .env("BBSPLAT_MEMORY_LIMIT", limit.to_string())
        .output()
        .unwrap();
    refused(&output, "resuming 120 billboards at texture size 4 on 40 views needs");
    assert!(std::fs::read(&checkpoint).unwrap() == before, "the checkpoint changed");
    // With the room the estimate asks for, the same command resumes.
    let output = Command::new(env!("CARGO_BIN_EXE_bbsplat"))
        .args(tiny_train_args(d, o, &["--resume", checkpoint.to_str().unwrap()]))
        .env("BBSPLAT_MEMORY_LIMIT", "2000000000")
        .output()
        .unwrap();
    assert!(output.status.success(), "{}", stderr(&output));
    std::fs::remove_dir_all(&root).ok();
}

#[test]
fn resume_refuses_another_dataset_or_a_changed_flag_naming_it() {
    let root = temp("rel-resume");
    let data = export_demo(&root, 24, 100);
    let other_root = root.join("other");
    let other_data = export_demo(&other_root, 32, 100);
    let out = root.join("out");
    let (d, o) = (data.to_str().unwrap(), out.to_str().unwrap());
    run_ok(&tiny_train_args(d, o, &["--stop-after", "10"]));
    let ckpt = out.join("checkpoint.bin");
    let c = ckpt.to_str().unwrap();
    let stored = Trainer::load_checkpoint(&ckpt).unwrap();
    assert_eq!(stored.run_record().arguments["--sh-degree"], "3");
    assert!(
        stored
            .run_record()
            .dataset
            .as_ref()
            .is_some_and(|f| f.views.len() == 40)
    );
    for (flags, needle) in [
        (
            vec!["--sh-degree", "2"],
            "--sh-degree: the checkpoint's run has 3, this one 2",
        ),
        (
            vec!["--background", "white"],
            "--background: the checkpoint's run has black, this one white",
        ),
        (vec!["--seed", "9"], "--seed"),
        (vec!["--texture-threshold", "100"], "--texture-threshold"),
        // Flags recorded only when given (so that older checkpoints keep their record).
        (
            vec!["--error-growth", "0.5"],
            "--error-growth: the checkpoint's run has (absent), this one 0.5",
        ),
        (
            vec!["--lambda-normal", "0.05"],
            "--lambda-normal: the checkpoint's run has (absent), this one 0.05",
        ),
    ] {
        let mut extra = vec!["--resume", c];
        extra.extend(flags);
        let output = bbsplat(&tiny_train_args(d, o, &extra));
        refused(&output, needle);
    }
    let output = bbsplat(&tiny_train_args(other_data.to_str().unwrap(), o, &["--resume", c]));
    refused(&output, "dataset: view");
    assert_eq!(
        Trainer::load_checkpoint(&ckpt).unwrap().step_index(),
        10,
        "the checkpoint was touched"
    );
    // Flags that do not change the run (threads, evaluation) are free; the run continues.
    run_ok(&tiny_train_args(
        d,
        o,
        &["--resume", c, "--threads", "1", "--eval-views", "3"],
    ));
    assert_eq!(Trainer::load_checkpoint(&ckpt).unwrap().step_index(), 40);
    std::fs::remove_dir_all(&root).ok();
}

/// Failure 7: SIGTERM and SIGHUP, like SIGINT, stop training with a loadable checkpoint and
/// exit status 130. Each signal is sent once the run has printed its first evaluation (step 5);
/// the stop is timed and must come within [`crate::progress::STOP_BOUND_SECONDS`].
#[cfg(unix)]
#[test]
fn sigterm_and_sighup_stop_training_with_a_checkpoint() {
    use crate::progress::{STOP_BOUND_SECONDS, wait_for_lines};
    let root = temp("rel-signals");
    let data = export_demo(&root, 24, 100);
    for signal in ["TERM", "HUP"] {
        let out = root.join(signal);
        let mut child = Command::new(env!("CARGO_BIN_EXE_bbsplat"))
            .args(["train", data.to_str().unwrap(), "-o", out.to_str().unwrap()])
            .args([
                "--iterations",
                "1000000",
                "--billboards",
                "120",
                "--texture-size",
                "4",
                "--eval-every",
                "5",
                "--eval-views",
                "1",
            ])
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        wait_for_lines(&mut child, &["views at", "test PSNR"]);
        let sent = std::time::Instant::now();
        let killed = Command::new("kill")
            .args([&format!("-{signal}"), &child.id().to_string()])
            .status()
            .unwrap();
        assert!(killed.success());
        let output = child.wait_with_output().unwrap();
        println!("SIG{signal}: stopped {:?} after the signal", sent.elapsed());
        assert!(
            sent.elapsed().as_secs_f64() < STOP_BOUND_SECONDS,
            "SIG{signal}: stopped after {:?}",
            sent.elapsed()
        );
        let err = stderr(&output);
        assert_eq!(output.status.code(), Some(130), "SIG{signal}: {err}");
        assert!(err.contains("interrupted at step"), "{err}");
        let trainer = Trainer::load_checkpoint(out.join("checkpoint.bin")).unwrap();
        assert!(trainer.step_index() > 0);
    }
    std::fs::remove_dir_all(&root).ok();
}

/// Copies the files of a run folder (`checkpoint.bin`, `summary.json`, `model/`).
fn copy_run(from: &Path, to: &Path) {
    std::fs::create_dir_all(to.join("model")).unwrap();
    for f in ["checkpoint.bin", "summary.json"] {
        std::fs::copy(from.join(f), to.join(f)).unwrap();
    }
    for e in std::fs::read_dir(from.join("model")).unwrap() {
        let e = e.unwrap();
        std::fs::copy(e.path(), to.join("model").join(e.file_name())).unwrap();
    }
}

/// Names starting with a dot in `dir` (temporary files and folders of a save).
fn hidden_entries(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.'))
        .collect()
}

/// Failures 3 and 8: the process is killed (aborted, as `kill -9`) at every write and rename of
/// the final save sequence (checkpoint, model, summary; the test-only hook `BBSPLAT_FAULT_AT`,
/// see `bbsplat::fault`) while it replaces an earlier run with `--overwrite`. After each kill a
/// complete model and a complete checkpoint exist, and the next start removes the temporary
/// files the killed one left.
#[test]
fn a_kill_at_any_point_of_the_save_leaves_a_complete_model_and_checkpoint() {
    let root = temp("rel-fault");
    let data = export_demo(&root, 24, 100);
    let d = data.to_str().unwrap();
    let base = root.join("base");
    run_ok(&tiny_train_args(d, base.to_str().unwrap(), &[]));
    let mut points: Vec<String> = Vec::new();
    for file in ["checkpoint.bin", "summary.json"] {
        points.extend(bbsplat::fault::ATOMIC_STAGES.iter().map(|s| format!("{file}:{s}")));
    }
    points.extend(bbsplat::fault::MODEL_STAGES.iter().map(|s| format!("model:{s}")));
    assert_eq!(points.len(), 11);
    for point in &points {
        let out = root.join(format!("at-{}", point.replace(':', "-")));
        copy_run(&base, &out);
        let o = out.to_str().unwrap();
        let output = Command::new(env!("CARGO_BIN_EXE_bbsplat"))
            .args(tiny_train_args(d, o, &["--overwrite", "--seed", "5"]))
            .env(bbsplat::fault::VARIABLE, point)
            .output()
            .unwrap();
        let err = stderr(&output);
        assert!(!output.status.success(), "{point}: not killed");
        assert!(
            err.contains(&format!("aborting at {point}")),
            "{point} not reached: {err}"
        );
        let (model, meta) = load_model(&out.join("model")).unwrap_or_else(|e| panic!("{point}: model: {e}"));
        assert_eq!((model.len(), meta.billboards), (120, 120), "{point}");
        let trainer =
            Trainer::load_checkpoint(out.join("checkpoint.bin")).unwrap_or_else(|e| panic!("{point}: checkpoint: {e}"));
        assert_eq!(trainer.step_index(), 40, "{point}");
        // The next start removes what the killed process left, and completes.
        run_ok(&tiny_train_args(d, o, &["--overwrite", "--seed", "5"]));
        assert_eq!(hidden_entries(&out), Vec::<String>::new(), "{point}: leftovers");
        assert!(out.join("summary.json").exists());
    }
    std::fs::remove_dir_all(&root).ok();
}

/// Writes a NeRF-synthetic scene of 12 train and 2 test RGB views on a ring of radius 3, with
/// train view 5 moved `outlier` times as far from the centre; `damage` replaces train view 3's
/// image with a JPEG cut halfway through its image data.
fn write_ring_scene(dir: &Path, outlier: f32, damage: bool) {
    let size = 32u32;
    for (split, count) in [("train", 12), ("test", 2)] {
        std::fs::create_dir_all(dir.join(split)).unwrap();
        let mut frames = Vec::new();
        for i in 0..count {
            // Test views between training views (at 0.5 they were at the poses of training views
            // 3 and 9, with their images: a leak the loader now leaves out).
            let a = (i as f32 + if split == "test" { 0.3 } else { 0.0 }) * std::f32::consts::TAU / count as f32;
            let radius = if split == "train" && i == 5 { 3.0 * outlier } else { 3.0 };
            let eye = glam::Vec3::new(radius * a.cos(), radius * a.sin(), 1.0);
            let z = eye.normalize();
            let x = glam::Vec3::Z.cross(z).normalize();
            let y = z.cross(x);
            let m = [
                [x.x, y.x, z.x, eye.x],
                [x.y, y.y, z.y, eye.y],
                [x.z, y.z, z.z, eye.z],
                [0.0, 0.0, 0.0, 1.0],
            ];
            let name = format!("{split}/r_{i}");
            let img = image::RgbImage::from_fn(size, size, |px, py| image::Rgb([(px * 8) as u8, (py * 8) as u8, 90]));
            let path = dir.join(format!("{name}.png"));
            if damage && split == "train" && i == 3 {
                let mut jpeg = Vec::new();
                image::DynamicImage::ImageRgb8(img)
                    .write_to(&mut std::io::Cursor::new(&mut jpeg), image::ImageFormat::Jpeg)
                    .unwrap();
                // Cut halfway through the scan (the entropy-coded image data after `FF DA`).
                let scan = jpeg.windows(2).rposition(|w| w == [0xFF, 0xDA]).unwrap();
                jpeg.truncate(scan + (jpeg.len() - scan) / 2);
                std::fs::write(&path, jpeg).unwrap();
            } else {
                img.save(&path).unwrap();
            }
            frames.push(serde_json::json!({ "file_path": format!("./{name}"), "transform_matrix": m }));
        }
        let json = serde_json::json!({ "camera_angle_x": 0.6, "frames": frames });
        std::fs::write(dir.join(format!("transforms_{split}.json")), json.to_string()).unwrap();
    }
}

/// Failure 6: a truncated JPEG is refused, naming the file; `--allow-damaged-images` trains on
/// it and summary.json records the warning even with `--quiet`.
#[test]
fn a_truncated_jpeg_is_refused_or_trained_on_with_a_recorded_warning() {
    let root = temp("rel-jpeg");
    let data = root.join("data");
    write_ring_scene(&data, 1.0, true);
    let out = root.join("out");
    let args = |extra: &[&str]| {
        let mut a = vec![
            "train",
            data.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "--iterations",
            "5",
            "--billboards",
            "60",
            "--texture-size",
            "4",
            "--quiet",
        ];
        a.extend_from_slice(extra);
        a.into_iter().map(String::from).collect::<Vec<_>>()
    };
    let a = args(&[]);
    let refusal = bbsplat(&a.iter().map(String::as_str).collect::<Vec<_>>());
    refused(&refusal, "truncated JPEG");
    assert!(stderr(&refusal).contains("r_3.png"), "{}", stderr(&refusal));
    let a = args(&["--allow-damaged-images"]);
    run_ok(&a.iter().map(String::as_str).collect::<Vec<_>>());
    let file: bbsplat::report::SummaryFile =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert!(
        file.warnings
            .iter()
            .any(|w| w.contains("r_3.png") && w.contains("truncated JPEG")),
        "{:?}",
        file.warnings
    );
    std::fs::remove_dir_all(&root).ok();
}

/// Failure 6: one camera far from all others is reported by name and left out of the scene
/// extent (which stays that of the ring).
#[test]
fn an_outlying_camera_is_reported_and_left_out_of_the_extent() {
    let root = temp("rel-outlier");
    let ring = root.join("ring");
    let far = root.join("far");
    write_ring_scene(&ring, 1.0, false);
    write_ring_scene(&far, 100.0, false);
    let options = bbsplat::scene::LoadOptions {
        print_warnings: false,
        ..Default::default()
    };
    let plain = bbsplat::scene::load(&ring, &options).unwrap();
    assert!(plain.warnings.is_empty(), "{:?}", plain.warnings);
    let scene = bbsplat::scene::load(&far, &options).unwrap();
    assert_eq!(scene.warnings.len(), 1, "{:?}", scene.warnings);
    assert!(scene.warnings[0].contains("r_5") && scene.warnings[0].contains("scene extent"));
    // Without the outlier the ring's cameras are all on one circle: the extent is close to the
    // plain ring's, not ~100 times larger.
    assert!(
        scene.extent < 1.5 * plain.extent,
        "{} vs {}",
        scene.extent,
        plain.extent
    );
    std::fs::remove_dir_all(&root).ok();
}

/// Failure 8: temporary files that earlier killed runs left in the output folder are removed at
/// start (those of running processes, and other hidden files, are kept).
#[test]
fn leftovers_of_killed_runs_are_removed_at_start() {
    let root = temp("rel-leftovers");
    let data = export_demo(&root, 24, 100);
    let out = root.join("out");
    std::fs::create_dir_all(out.join(".model.tmp-999999999-0")).unwrap();
    std::fs::write(out.join(".model.tmp-999999999-0/point_cloud.ply"), b"half").unwrap();
    std::fs::write(out.join(".checkpoint.bin.tmp.999999999.3"), b"half").unwrap();
    std::fs::write(out.join(".summary.json.tmp.999999998.0"), b"half").unwrap();
    let alive = format!(".checkpoint.bin.tmp.{}.0", std::process::id());
    std::fs::write(out.join(&alive), b"in progress").unwrap();
    let users = ".notes.tmp.999999999.0".to_string();
    std::fs::write(out.join(&users), b"not ours").unwrap();
    run_ok(&tiny_train_args(data.to_str().unwrap(), out.to_str().unwrap(), &[]));
    let mut left = hidden_entries(&out);
    left.sort();
    assert_eq!(left, vec![alive, users]);
    std::fs::remove_dir_all(&root).ok();
}

/// Failure 7: a signal before training starts (here during a long visual-hull initialisation)
/// ends the process at once with status 130, and no run is written. The signal is sent once
/// the run has printed that it is initialising; the initialisation must not have finished
/// (no "initial billboards" line: carving the hull at 512³ takes longer than the stop, tens of ms) and the
/// stop comes within [`crate::progress::STOP_BOUND_SECONDS`].
#[cfg(unix)]
#[test]
fn a_signal_before_training_starts_exits_at_once_without_writing_a_run() {
    use crate::progress::STOP_BOUND_SECONDS;
    let root = temp("rel-loading");
    let data = root.join("data");
    write_tiny_blender_scene(&data, true);
    let out = root.join("out");
    let mut child = Command::new(env!("CARGO_BIN_EXE_bbsplat"))
        .args([
            "train",
            data.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "--iterations",
            "10",
        ])
        .args([
            "--billboards",
            "100",
            "--texture-size",
            "4",
            "--init",
            "hull",
            "--hull-resolution",
            "512",
        ])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // The rest of the output is read on a thread: collect it to see what was printed after.
    let stdout = child.stdout.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        use std::io::BufRead;
        for line in std::io::BufReader::new(stdout).lines().map_while(Result::ok) {
            tx.send(line).ok();
        }
    });
    let printed_before: Vec<String> = rx.iter().take_while(|l| !l.contains("initialising")).collect();
    let sent = std::time::Instant::now();
    assert!(
        Command::new("kill")
            .args(["-TERM", &child.id().to_string()])
            .status()
            .unwrap()
            .success()
    );
    let output = child.wait_with_output().unwrap();
    println!("stopped {:?} after the signal", sent.elapsed());
    assert!(
        sent.elapsed().as_secs_f64() < STOP_BOUND_SECONDS,
        "stopped after {:?}",
        sent.elapsed()
    );
    let printed: Vec<String> = printed_before.into_iter().chain(rx.try_iter()).collect();
    let err = stderr(&output);
    assert!(
        !printed
            .iter()
            .any(|l| l.contains("initial billboards") || l.contains("views at")),
        "the initialisation had finished before the signal was handled: {printed:?}"
    );
    assert_eq!(output.status.code(), Some(130), "{err}");
    assert!(err.contains("before training started"), "{err}");
    assert!(!out.join("checkpoint.bin").exists() && !out.join("model").exists());
    std::fs::remove_dir_all(&root).ok();
}

/// Failures 4-5: a file system without room for the estimated outputs is refused before
/// training (`BBSPLAT_DISK_LIMIT` stands in for a nearly full disk).
#[test]
fn too_little_free_space_is_refused_before_training() {
    let root = temp("rel-disk");
    let data = export_demo(&root, 24, 100);
    let out = root.join("out");
    let output = Command::new(env!("CARGO_BIN_EXE_bbsplat"))
        .args(tiny_train_args(data.to_str().unwrap(), out.to_str().unwrap(), &[]))
        .env("RUST_BACKTRACE", "0")
        .env("BBSPLAT_DISK_LIMIT", "1000")
        .output()
        .unwrap();
    refused(&output, "free on its file system");
    std::fs::remove_dir_all(&root).ok();
}

/// Failure 4: when writing fails after training started (here the checkpoint path is taken by a
/// folder in the middle of the run), the trained state is saved elsewhere and the message says
/// where; that checkpoint loads.
#[cfg(unix)]
#[test]
fn a_write_failure_during_training_rescues_the_trained_state() {
    let root = temp("rel-rescue");
    let data = export_demo(&root, 24, 100);
    let out = root.join("out");
    let mut child = Command::new(env!("CARGO_BIN_EXE_bbsplat"))
        .args(["train", data.to_str().unwrap(), "-o", out.to_str().unwrap()])
        .args([
            "--iterations",
            "1000000",
            "--billboards",
            "120",
            "--texture-size",
            "4",
            "--eval-every",
            "40",
            "--eval-views",
            "1",
        ])
        .args(["--save-every", "20"])
        .env("RUST_BACKTRACE", "0")
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // The evaluation at step 40 is printed after the checkpoint of step 20 was saved.
    crate::progress::wait_for_lines(&mut child, &["views at", "test PSNR"]);
    let ckpt = out.join("checkpoint.bin");
    // The run renames a new checkpoint into place every 20 steps: retry until the folder wins.
    let taken = (0..1000).any(|_| {
        std::fs::remove_file(&ckpt).ok();
        std::fs::create_dir(&ckpt).is_ok()
    });
    assert!(taken, "could not put a folder at {}", ckpt.display());
    let output = child.wait_with_output().unwrap();
    let err = stderr(&output);
    assert!(!output.status.success(), "{err}");
    let rescued = err
        .split_whitespace()
        .find(|w| w.contains("bbsplat-rescued-"))
        .unwrap_or_else(|| panic!("no rescue named in: {err}"));
    let rescued = Path::new(rescued.trim_end_matches([':', ')', ',']));
    let trainer = Trainer::load_checkpoint(rescued).unwrap();
    assert!(trainer.step_index() >= 20, "step {}", trainer.step_index());
    std::fs::remove_file(rescued).ok();
    std::fs::remove_dir_all(&root).ok();
}
