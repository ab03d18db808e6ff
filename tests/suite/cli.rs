//! The command line refuses bad arguments with a clear message and a non-zero exit status.

use std::process::Command;

pub(super) fn run(args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_bbsplat"))
        .args(args)
        .output()
        .expect("the binary runs");
    (out.status.success(), String::from_utf8_lossy(&out.stderr).into_owned())
}

#[test]
fn demo_rejects_a_texture_smaller_than_two() {
    let (ok, err) = run(&["demo", "--texture-size", "1", "--iterations", "1"]);
    assert!(!ok);
    assert!(err.contains("--texture-size must be at least 2"), "{err}");
}

#[test]
fn demo_rejects_a_tiny_resolution() {
    let (ok, err) = run(&["demo", "--resolution", "4", "--iterations", "1"]);
    assert!(!ok);
    assert!(err.contains("--resolution must be at least 8"), "{err}");
}

#[test]
fn demo_rejects_a_view_count_out_of_range() {
    for (views, message) in [
        ("0", "--views must be at least 1"),
        ("100001", "--views must be at most 100000"),
    ] {
        let (ok, err) = run(&["demo", "--views", views, "--iterations", "1"]);
        assert!(!ok);
        assert!(err.contains(message), "{err}");
    }
}

#[test]
fn unknown_subcommand_is_refused() {
    let (ok, err) = run(&["bogus"]);
    assert!(!ok);
    assert!(err.contains("unrecognized subcommand"), "{err}");
}

#[test]
fn tiny_demo_runs_and_writes_renders() {
    let dir = std::env::temp_dir().join(format!("bbsplat-cli-{}", std::process::id()));
    let args = [
        "demo",
        "--iterations",
        "5",
        "--billboards",
        "50",
        "--resolution",
        "16",
        "-o",
        dir.to_str().unwrap(),
    ];
    let (ok, err) = run(&args);
    assert!(ok, "{err}");
    let pngs = std::fs::read_dir(&dir)
        .unwrap()
        .filter(|e| e.as_ref().unwrap().path().extension().is_some_and(|x| x == "png"))
        .count();
    assert_eq!(pngs, 16, "8 test views, render and truth each");
    assert!(
        std::fs::read_dir(&dir)
            .unwrap()
            // Temporary files are `.<name>.tmp.<pid>.<n>` (file_io::write_atomic); the check
            // looked for names ending in `.tmp` and could not fail.
            .all(|e| !e.unwrap().file_name().to_string_lossy().contains(".tmp"))
    );
    std::fs::remove_dir_all(&dir).ok();
}

pub(crate) fn temp(tag: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("bbsplat-cli-{tag}-{}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    dir
}

pub(crate) fn run_ok(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_bbsplat"))
        .args(args)
        .output()
        .expect("the binary runs");
    assert!(
        out.status.success(),
        "{args:?} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// The whole command-line workflow on a tiny exported demo scene: export, train, render, eval.
#[test]
fn train_render_and_eval_run_on_a_tiny_scene() {
    let root = temp("workflow");
    let data = export_demo(&root, 24, 100);
    let out = root.join("out");
    assert!(data.join("sparse/0/cameras.bin").exists());
    let printed = run_ok(&[
        "train",
        data.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--iterations",
        "20",
        "--billboards",
        "150",
        "--texture-size",
        "4",
        "--eval-every",
        "10",
        "--quiet",
        // LPIPS-VGG of the final test views into the summary, when its weights are set up.
        "--lpips",
    ]);
    assert!(printed.contains("test PSNR"), "{printed}");
    let summary: bbsplat::report::TrainSummary =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!((summary.iterations, summary.texture_size), (20, 4));
    assert_eq!(summary.curve.len(), 2, "one intermediate and one final evaluation");
    assert!(summary.test_psnr.is_finite() && summary.model_bytes > 0);
    let model = out.join("model");
    assert!(model.join("point_cloud.ply").exists());

    let renders = root.join("renders");
    let printed = run_ok(&[
        "render",
        model.to_str().unwrap(),
        data.to_str().unwrap(),
        "-o",
        renders.to_str().unwrap(),
    ]);
    assert!(printed.contains("wrote 5 renders"), "{printed}");
    assert_eq!(std::fs::read_dir(&renders).unwrap().count(), 5);

    let table = run_ok(&["eval", model.to_str().unwrap(), data.to_str().unwrap()]);
    assert_eq!(table.lines().count(), 7, "header, 5 views, mean:\n{table}");
    let json = run_ok(&["eval", model.to_str().unwrap(), data.to_str().unwrap(), "--json"]);
    let report: bbsplat::eval::EvalReport = serde_json::from_str(&json).unwrap();
    assert_eq!(report.views.len(), 5);
    // The evaluation of the saved (8-bit) model is what train reported at the end.
    assert!(
        (report.mean_psnr - summary.test_psnr).abs() < 1e-9,
        "{} {}",
        report.mean_psnr,
        summary.test_psnr
    );
    assert!(report.mean_lpips.is_none() && !json.contains("lpips"), "{json}");

    // `eval --lpips` without the weights refuses, naming the setup command, before rendering.
    let empty_cache = root.join("no-weights");
    std::fs::create_dir_all(&empty_cache).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_bbsplat"))
        .args(["eval", model.to_str().unwrap(), data.to_str().unwrap(), "--lpips"])
        .env("BBSPLAT_CACHE_DIR", &empty_cache)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && out.stdout.is_empty(), "{stderr}");
    assert!(
        stderr.contains("python3 tools/lpips_weights.py") && stderr.contains("lpips-vgg.safetensors"),
        "{stderr}"
    );
    // With the weights (set up by .ci/run): LPIPS-VGG per view, its mean, and train's summary
    // holds the same mean (the 8-bit model, the same views).
    let weights = bbsplat::lpips::weights_path(bbsplat::lpips::Variant::Vgg).unwrap();
    if weights.exists() {
        let json = run_ok(&[
            "eval",
            model.to_str().unwrap(),
            data.to_str().unwrap(),
            "--lpips",
            "--json",
        ]);
        let report: bbsplat::eval::EvalReport = serde_json::from_str(&json).unwrap();
        assert_eq!(report.lpips_network.as_deref(), Some("vgg"));
        let mean = report.mean_lpips.unwrap();
        assert!(
            mean > 0.0 && mean < 1.0 && report.views.iter().all(|v| v.lpips.is_some()),
            "{json}"
        );
        assert_eq!(summary.lpips_network.as_deref(), Some("vgg"));
        assert!(
            (summary.test_lpips.unwrap() - mean).abs() < 1e-12,
            "{:?} {mean}",
            summary.test_lpips
        );
        // AlexNet needs 31 pixels a side: the 24-pixel views are refused, naming the view.
        let out = Command::new(env!("CARGO_BIN_EXE_bbsplat"))
            .args(["eval", model.to_str().unwrap(), data.to_str().unwrap(), "--lpips=alex"])
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && stderr.contains("LPIPS of view") && stderr.contains("too small"),
            "{stderr}"
        );
    } else {
        assert!(summary.test_lpips.is_none() && summary.lpips_note.as_deref().unwrap().contains("lpips_weights.py"));
        super::lpips::missing(
            "train_render_and_eval_run_on_a_tiny_scene (LPIPS part)",
            "no LPIPS weights set up",
        );
    }
    std::fs::remove_dir_all(&root).ok();
}

/// A run without test views (`--test-every 0`) says so instead of printing NaN scores, and its
/// `summary.json` (which holds `null` for them) reads back with NaN scores.
#[test]
fn a_run_without_test_views_says_so_and_its_summary_reads_back() {
    let root = temp("no-test-views");
    let data = export_demo(&root, 24, 100);
    let out = root.join("out");
    let (d, o) = (data.to_str().unwrap(), out.to_str().unwrap());
    let printed = run_ok(&tiny_train_args(d, o, &["--test-every", "0"]));
    assert!(printed.contains("no test views to score"), "{printed}");
    assert!(!printed.contains("NaN"), "{printed}");
    let text = std::fs::read_to_string(out.join("summary.json")).unwrap();
    assert!(text.contains("\"test_psnr\": null"), "{text}");
    let summary: bbsplat::report::TrainSummary = serde_json::from_str(&text).unwrap();
    assert_eq!(summary.test_views, 0);
    assert!(summary.test_psnr.is_nan() && summary.test_ssim.is_nan());
    std::fs::remove_dir_all(&root).ok();
}

#[test]
fn train_names_a_missing_scene_folder() {
    let (ok, err) = run(&["train", "/no/such/scene", "-o", "/tmp/never-written"]);
    assert!(!ok);
    assert!(err.contains("/no/such/scene"), "{err}");
    assert!(!std::path::Path::new("/tmp/never-written").exists());
}

#[test]
fn eval_names_an_unreadable_model() {
    let root = temp("badmodel");
    let data = export_demo(&root, 16, 20);
    let model = root.join("model");
    std::fs::create_dir_all(&model).unwrap();
    std::fs::write(model.join("point_cloud.ply"), b"ply\nformat garbage\n").unwrap();
    let (ok, err) = run(&["eval", model.to_str().unwrap(), data.to_str().unwrap()]);
    assert!(!ok);
    assert!(err.contains("point_cloud.ply") || err.contains("bbsplat.json"), "{err}");
    std::fs::remove_dir_all(&root).ok();
}

/// Exports the demo scene at `resolution` px with `billboards` into `root/data`; returns that folder.
pub(crate) fn export_demo(root: &std::path::Path, resolution: u32, billboards: usize) -> std::path::PathBuf {
    let data = root.join("data");
    let (resolution, billboards) = (resolution.to_string(), billboards.to_string());
    run_ok(&[
        "demo",
        "--export",
        data.to_str().unwrap(),
        "--resolution",
        &resolution,
        "--billboards",
        &billboards,
    ]);
    data
}

/// Trains a model on `data` for 5 steps (`billboards` billboards, TS 4, no evaluation) into
/// `out`; returns the model folder `out/model`.
pub(crate) fn train_five_steps(data: &std::path::Path, out: &std::path::Path, billboards: usize) -> std::path::PathBuf {
    let billboards = billboards.to_string();
    run_ok(&[
        "train",
        data.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--iterations",
        "5",
        "--billboards",
        &billboards,
        "--texture-size",
        "4",
        "--eval-every",
        "0",
        "--quiet",
    ]);
    out.join("model")
}

pub(crate) fn tiny_train_args<'a>(data: &'a str, out: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
    let mut args = vec![
        "train",
        data,
        "-o",
        out,
        "--iterations",
        "40",
        "--billboards",
        "120",
        "--texture-size",
        "4",
        "--eval-every",
        "0",
        "--quiet",
    ];
    args.extend_from_slice(extra);
    args
}

/// `--stop-after 20` then `--resume` ends with exactly the files of an uninterrupted run.
#[test]
fn a_stopped_and_resumed_run_equals_an_uninterrupted_one_bit_for_bit() {
    let root = temp("resume");
    let data = export_demo(&root, 24, 100);
    let (d, a, b) = (
        data.to_str().unwrap(),
        root.join("a").to_str().unwrap().to_string(),
        root.join("b").to_str().unwrap().to_string(),
    );
    run_ok(&tiny_train_args(d, &a, &[]));
    let printed = run_ok(&tiny_train_args(d, &b, &["--stop-after", "20"]));
    assert!(!printed.contains("trained 40 steps"), "{printed}");
    assert!(
        !root.join("b/summary.json").exists(),
        "a stopped run has no summary yet"
    );
    let checkpoint = root.join("b/checkpoint.bin");
    assert_eq!(
        bbsplat::train::Trainer::load_checkpoint(&checkpoint)
            .unwrap()
            .step_index(),
        20
    );
    run_ok(&tiny_train_args(d, &b, &["--resume", checkpoint.to_str().unwrap()]));
    for file in [
        "checkpoint.bin",
        "model/point_cloud.ply",
        "model/texture_alpha.npz",
        "model/texture_color.npz",
        "model/bbsplat.json",
    ] {
        let (x, y) = (
            std::fs::read(root.join("a").join(file)).unwrap(),
            std::fs::read(root.join("b").join(file)).unwrap(),
        );
        assert!(x == y, "{file} differs between the uninterrupted and the resumed run");
    }
    std::fs::remove_dir_all(&root).ok();
}

/// Ctrl-C (SIGINT) saves a loadable checkpoint, leaves no temporary file and exits with 130.
/// The signal is sent once the run has printed its first evaluation (step 5), so the
/// checkpoint has steps however slow the machine.
#[cfg(unix)]
#[test]
fn ctrl_c_saves_a_checkpoint_and_exits_cleanly() {
    let root = temp("sigint");
    let data = export_demo(&root, 24, 100);
    let out = root.join("out");
    let mut child = Command::new(env!("CARGO_BIN_EXE_bbsplat"))
        .args([
            "train",
            data.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
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
    // The handler is installed before the line naming the views is printed; the evaluation line
    // says that steps were taken.
    crate::progress::wait_for_lines(&mut child, &["views at", "test PSNR"]);
    let killed = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(killed.success());
    let output = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(130), "{stderr}");
    assert!(stderr.contains("interrupted at step"), "{stderr}");
    let trainer = bbsplat::train::Trainer::load_checkpoint(out.join("checkpoint.bin")).unwrap();
    assert!(trainer.step_index() > 0);
    assert!(
        std::fs::read_dir(&out)
            .unwrap()
            .all(|e| !e.unwrap().file_name().to_string_lossy().contains("tmp"))
    );
    std::fs::remove_dir_all(&root).ok();
}

/// Writes a tiny NeRF-synthetic scene: 6 train and 2 test views of a disc-shaped object on a ring
/// of cameras, as RGBA PNGs (`alpha = true`) or RGB PNGs.
pub(crate) fn write_tiny_blender_scene(dir: &std::path::Path, alpha: bool) {
    let size = 24u32;
    for split in ["train", "test"] {
        std::fs::create_dir_all(dir.join(split)).unwrap();
        let count = if split == "train" { 6 } else { 2 };
        let mut frames = Vec::new();
        for i in 0..count {
            let a = (i as f32 + if split == "test" { 0.5 } else { 0.0 }) * std::f32::consts::TAU / count as f32;
            let eye = glam::Vec3::new(3.0 * a.cos(), 3.0 * a.sin(), 1.0);
            let z = eye.normalize(); // OpenGL: the camera looks along -z
            let x = glam::Vec3::Z.cross(z).normalize();
            let y = z.cross(x);
            let m = [
                [x.x, y.x, z.x, eye.x],
                [x.y, y.y, z.y, eye.y],
                [x.z, y.z, z.z, eye.z],
                [0.0, 0.0, 0.0, 1.0],
            ];
            let name = format!("{split}/r_{i}");
            let mut img = image::RgbaImage::new(size, size);
            for (px, py, p) in img.enumerate_pixels_mut() {
                let (dx, dy) = (px as f32 + 0.5 - 12.0, py as f32 + 0.5 - 12.0);
                let inside = dx * dx + dy * dy < 36.0;
                *p = image::Rgba([200, 60, 40, if inside { 255 } else { 0 }]);
            }
            let path = dir.join(format!("{name}.png"));
            if alpha {
                img.save(&path).unwrap();
            } else {
                image::DynamicImage::ImageRgba8(img).to_rgb8().save(&path).unwrap();
            }
            frames.push(serde_json::json!({ "file_path": format!("./{name}"), "transform_matrix": m }));
        }
        let json = serde_json::json!({ "camera_angle_x": 0.6, "frames": frames });
        std::fs::write(dir.join(format!("transforms_{split}.json")), json.to_string()).unwrap();
    }
}

/// `--init hull` places the billboards on the visual hull of RGBA views, and refuses, naming
/// the reason, a scene whose images have no alpha channel.
#[test]
fn hull_initialisation_needs_alpha_masks() {
    let root = temp("hull");
    let (rgba, rgb, out) = (root.join("rgba"), root.join("rgb"), root.join("out"));
    write_tiny_blender_scene(&rgba, true);
    write_tiny_blender_scene(&rgb, false);
    let (rgba_s, rgb_s, out_s) = (rgba.to_str().unwrap(), rgb.to_str().unwrap(), out.to_str().unwrap());
    let mut args = tiny_train_args(rgba_s, out_s, &["--init", "hull", "--hull-resolution", "32"]);
    args.retain(|a| *a != "--quiet");
    let printed = run_ok(&args);
    assert!(printed.contains("120 on the visual hull"), "{printed}");
    let (ok, err) = run(&tiny_train_args(rgb_s, out_s, &["--init", "hull", "--overwrite"]));
    assert!(!ok);
    assert!(err.contains("alpha mask"), "{err}");
    std::fs::remove_dir_all(&root).ok();
}

/// Coarse-to-fine: the flag changes the result, and a run stopped inside the coarse phase and
/// resumed (switching to full size after the stop) equals an uninterrupted one bit for bit.
#[test]
fn coarse_to_fine_resumes_across_the_switch_bit_for_bit() {
    let root = temp("coarse");
    let data = export_demo(&root, 24, 100);
    let d = data.to_str().unwrap();
    let out = |name: &str| root.join(name).to_str().unwrap().to_string();
    let (plain, a, b) = (out("plain"), out("a"), out("b"));
    let coarse = ["--coarse-factor", "2", "--coarse-until", "0.5"];
    // The default is coarse-to-fine (the flags above); the reference is --coarse-factor 1.
    run_ok(&tiny_train_args(d, &plain, &["--coarse-factor", "1"]));
    run_ok(&tiny_train_args(d, &a, &coarse));
    let mut stop: Vec<&str> = coarse.to_vec();
    stop.extend(["--stop-after", "10"]);
    run_ok(&tiny_train_args(d, &b, &stop));
    let checkpoint = root.join("b/checkpoint.bin");
    let mut resume: Vec<&str> = coarse.to_vec();
    resume.extend(["--resume", checkpoint.to_str().unwrap()]);
    run_ok(&tiny_train_args(d, &b, &resume));
    let read = |dir: &str, file: &str| std::fs::read(std::path::Path::new(dir).join(file)).unwrap();
    assert!(
        read(&a, "checkpoint.bin") == read(&b, "checkpoint.bin"),
        "resumed run differs"
    );
    assert!(
        read(&a, "checkpoint.bin") != read(&plain, "checkpoint.bin"),
        "--coarse-factor changed nothing"
    );
    let (ok, err) = run(&tiny_train_args(d, &out("bad"), &["--coarse-until", "1.5"]));
    assert!(!ok && err.contains("--coarse-until"), "{err}");
    std::fs::remove_dir_all(&root).ok();
}

/// `--lr-scale` sets every learning-rate factor, `--lr-position/-sh/-shape/-texture` override one
/// group; the checkpoint keeps them. Negative or non-numeric factors are refused by name.
#[test]
fn learning_rate_flags_reach_the_trainer() {
    let root = temp("lr");
    let data = export_demo(&root, 24, 100);
    let (d, out) = (data.to_str().unwrap(), root.join("run").to_str().unwrap().to_string());
    run_ok(&tiny_train_args(
        d,
        &out,
        &[
            "--lr-scale",
            "2",
            "--lr-texture",
            "3",
            "--lr-sh",
            "0.5",
            "--stop-after",
            "1",
        ],
    ));
    let trainer = bbsplat::train::Trainer::load_checkpoint(root.join("run/checkpoint.bin")).unwrap();
    assert_eq!(
        trainer.config().lr_scales,
        bbsplat::train::LearningRateScales {
            position: 2.0,
            sh: 0.5,
            shape: 2.0,
            texture: 3.0,
        }
    );
    assert!(
        !trainer.config().lr_by_run_length,
        "a learning-rate flag turns the run-length factor off"
    );
    for (flag, value) in [("--lr-scale", "-1"), ("--lr-position", "nan"), ("--lr-shape", "fast")] {
        let arg = format!("{flag}={value}");
        let (ok, err) = run(&tiny_train_args(d, &out, &[&arg]));
        assert!(!ok, "{arg} accepted");
        assert!(err.contains(flag) && err.contains(value), "{arg}: {err}");
    }
    std::fs::remove_dir_all(&root).ok();
}

/// `--clamp-gradient straight-through` reaches the trainer, its checkpoint and `summary.json`;
/// an unknown value is refused by name.
#[test]
fn the_clamp_gradient_flag_reaches_the_checkpoint_and_the_summary() {
    let root = temp("clamp");
    let data = export_demo(&root, 24, 100);
    let (d, out) = (data.to_str().unwrap(), root.join("run").to_str().unwrap().to_string());
    run_ok(&tiny_train_args(d, &out, &["--clamp-gradient", "straight-through"]));
    let trainer = bbsplat::train::Trainer::load_checkpoint(root.join("run/checkpoint.bin")).unwrap();
    assert_eq!(
        trainer.config().clamp_gradient,
        bbsplat::train::ClampGradient::PassThrough
    );
    let text = std::fs::read_to_string(root.join("run/summary.json")).unwrap();
    let file: bbsplat::report::SummaryFile = serde_json::from_str(&text).unwrap();
    assert_eq!(file.settings.clamp_gradient, "straight-through");
    let (ok, err) = run(&tiny_train_args(d, &out, &["--clamp-gradient", "sideways"]));
    assert!(!ok && err.contains("sideways"), "{err}");
    std::fs::remove_dir_all(&root).ok();
}

/// `train` takes the background from the data and stores it in the model; `render` and `eval`
/// use the stored one unless `--background` overrides it.
#[test]
fn the_background_of_the_data_is_stored_and_reused() {
    let root = temp("background");
    let (rgba, rgb) = (root.join("rgba"), root.join("rgb"));
    write_tiny_blender_scene(&rgba, true);
    write_tiny_blender_scene(&rgb, false);
    for (data, expected) in [(&rgba, [1.0f32; 3]), (&rgb, [0.0; 3])] {
        let out = root.join(format!("out_{}", expected[0]));
        let (d, o) = (data.to_str().unwrap(), out.to_str().unwrap());
        let mut args = tiny_train_args(d, o, &[]);
        args.retain(|a| *a != "--quiet");
        let printed = run_ok(&args);
        assert!(printed.contains("background: "), "{printed}");
        let meta: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("model/bbsplat.json")).unwrap()).unwrap();
        let stored: Vec<f32> = serde_json::from_value(meta["background"].clone()).unwrap();
        assert_eq!(stored, expected, "{}", data.display());
        let summary: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
        let automatic = summary["automatic"].as_array().unwrap();
        assert!(automatic.iter().any(|c| c["setting"] == "background"), "{summary}");
        let lr = automatic.iter().find(|c| c["setting"] == "lr-scale").unwrap();
        assert_eq!(lr["value"], "4.00", "40 steps: the short-run factor");
        // No SfM points: growth is placed on the error.
        let placed = automatic.iter().find(|c| c["setting"] == "error-growth").unwrap();
        assert_eq!(placed["value"], "1");
        let checkpoint = bbsplat::train::Trainer::load_checkpoint(out.join("checkpoint.bin")).unwrap();
        assert_eq!(checkpoint.config().error_growth, 1.0);
        let model = out.join("model");
        let eval = |extra: &[&str]| {
            let mut args = vec!["eval", model.to_str().unwrap(), d, "--json"];
            args.extend_from_slice(extra);
            serde_json::from_str::<bbsplat::eval::EvalReport>(&run_ok(&args))
                .unwrap()
                .mean_psnr
        };
        // The stored background reproduces train's final evaluation; another one does not.
        let psnr = eval(&[]);
        assert!(
            (psnr - summary["test_psnr"].as_f64().unwrap()).abs() < 1e-9,
            "{psnr} {summary}"
        );
        if expected[0] == 1.0 {
            assert!((eval(&["--background", "black"]) - psnr).abs() > 1e-3);
        }
    }
    std::fs::remove_dir_all(&root).ok();
}

/// `--minutes` with `--iterations` is refused; a budgeted run records its plan.
#[test]
fn minutes_plans_the_run_and_records_it() {
    let root = temp("minutes");
    let data = export_demo(&root, 24, 100);
    let out = root.join("out");
    let (d, o) = (data.to_str().unwrap(), out.to_str().unwrap());
    let (ok, err) = run(&["train", d, "-o", o, "--minutes", "0.1", "--iterations", "10"]);
    assert!(!ok && err.contains("--minutes"), "{err}");
    let (ok, err) = run(&["train", d, "-o", o, "--minutes", "0"]);
    assert!(!ok && err.contains("> 0"), "{err}");
    let printed = run_ok(&[
        "train",
        d,
        "-o",
        o,
        "--minutes",
        "0.05",
        "--texture-size",
        "4",
        "--eval-every",
        "0",
    ]);
    assert!(printed.contains("time budget 0.05 min"), "{printed}");
    assert!(printed.contains("growth cap"), "{printed}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let spent = summary["plan"]["spent_minutes"].as_f64().unwrap();
    assert!((spent / 0.05 - 1.0).abs() <= 0.03, "{spent} {summary}");
    assert_eq!(summary["plan"]["planned_steps"], summary["iterations"]);
    // Without learning-rate flags the rates follow the planned length, recorded as chosen.
    let automatic = summary["automatic"].as_array().unwrap();
    let lr = automatic
        .iter()
        .find(|c| c["setting"] == "lr-scale")
        .expect("lr-scale chosen");
    assert_eq!(lr["value"], "by run length");
    // The demo scene has SfM points: growth copies, as the reference.
    let placed = automatic.iter().find(|c| c["setting"] == "error-growth").unwrap();
    assert_eq!(placed["value"], "0", "{summary}");
    let checkpoint = bbsplat::train::Trainer::load_checkpoint(out.join("checkpoint.bin")).unwrap();
    assert_eq!(checkpoint.config().error_growth, 0.0);
    assert!(checkpoint.config().lr_by_run_length);
    assert_eq!(
        checkpoint.config().lr_scales,
        bbsplat::train::LearningRateScales::REFERENCE
    );
    std::fs::remove_dir_all(&root).ok();
}

/// A budgeted run stopped with `--stop-after` and resumed continues its plan: the steps of both
/// calls take the budget; another budget or `--iterations` on resume is refused.
#[test]
fn a_budgeted_run_resumes_its_plan() {
    let root = temp("minutes_resume");
    let data = export_demo(&root, 24, 100);
    let out = root.join("out");
    let (d, o) = (data.to_str().unwrap(), out.to_str().unwrap());
    let common = ["--texture-size", "4", "--eval-every", "0", "--quiet"];
    let mut first = vec!["train", d, "-o", o, "--minutes", "0.05", "--stop-after", "60"];
    first.extend(common);
    run_ok(&first);
    let checkpoint = out.join("checkpoint.bin");
    let c = checkpoint.to_str().unwrap();
    let stopped = bbsplat::train::Trainer::load_checkpoint(&checkpoint).unwrap();
    let spent_before = stopped.time_plan().unwrap().spent_seconds;
    for bad in [&["--minutes", "0.1"][..], &["--iterations", "100"][..]] {
        let mut args = vec!["train", d, "-o", o, "--resume", c];
        args.extend(common);
        args.extend_from_slice(bad);
        let (ok, err) = run(&args);
        assert!(!ok && err.contains("--minutes 0.05"), "{bad:?}: {err}");
    }
    let mut resume = vec!["train", d, "-o", o, "--resume", c];
    resume.extend(common);
    run_ok(&resume);
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let spent = summary["plan"]["spent_minutes"].as_f64().unwrap();
    assert!((spent / 0.05 - 1.0).abs() <= 0.03, "{spent} {summary}");
    // The summary's time is the whole run's (both calls), as the plan's.
    let whole_run = summary["train_seconds"].as_f64().unwrap();
    assert!(whole_run > spent_before, "{summary}");
    assert!((spent * 60.0 - whole_run).abs() < 1e-6, "{summary}");
    std::fs::remove_dir_all(&root).ok();
}

/// `--lambda-normal`, `--lambda-dist`, `--normal-from`, `--dist-from`: bad values are refused
/// with the flag named; good ones train and are recorded in the summary.
#[test]
fn geometry_regulariser_flags_are_checked_and_recorded() {
    let root = temp("geometry-flags");
    let data = export_demo(&root, 24, 100);
    let out = root.join("out");
    let (d, o) = (data.to_str().unwrap(), out.to_str().unwrap());
    for (flag, value, says) in [
        ("--lambda-normal", "-1", "finite number ≥ 0"),
        ("--lambda-dist", "nan", "finite number ≥ 0"),
        ("--normal-from", "1.5", "fraction"),
        ("--dist-from", "-0.1", "fraction"),
    ] {
        let arg = format!("{flag}={value}");
        let (ok, err) = run(&tiny_train_args(d, o, &[arg.as_str()]));
        assert!(!ok && err.contains(flag) && err.contains(says), "{arg}: {err}");
        assert!(!out.exists(), "{arg}: nothing written");
    }
    let extra = [
        "--lambda-normal",
        "0.05",
        "--lambda-dist",
        "100",
        "--normal-from",
        "0",
        "--dist-from",
        "0.5",
    ];
    run_ok(&tiny_train_args(d, o, &extra));
    let summary = std::fs::read_to_string(out.join("summary.json")).unwrap();
    for field in [
        "\"lambda_normal\": 0.05",
        "\"lambda_distortion\": 100.0",
        "\"normal_from\": 0.0",
        "\"distortion_from\": 0.5",
    ] {
        assert!(summary.contains(field), "{field} in {summary}");
    }
    std::fs::remove_dir_all(&root).ok();
}
