//! The mask flags of the command line: a NeuS dataset trains with no flag, its test views' masks
//! give the summary's `masked_test`, `eval --masked` reports the same figures labelled as masked,
//! and a bad `--masks` folder is named.

use super::cli::{run, run_ok, temp};
use super::scene_neus::{known_cameras, write_neus};

/// `bbsplat train DATA -o OUT` for 10 steps of 100 billboards at TS 4, then `extra`.
fn train_args<'a>(data: &'a str, out: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
    let mut args = vec![
        "train",
        data,
        "-o",
        out,
        "--iterations",
        "10",
        "--billboards",
        "100",
        "--texture-size",
        "4",
        "--quiet",
    ];
    args.extend_from_slice(extra);
    args
}

#[test]
fn a_neus_scene_trains_with_no_flag_and_reports_masked_figures() {
    let root = temp("masks");
    let data = root.join("neus");
    write_neus(&data, &known_cameras(), glam::DMat4::IDENTITY, 4.0);
    let out = root.join("out");
    let (d, o) = (data.to_str().unwrap(), out.to_str().unwrap());
    let printed = run_ok(&train_args(d, o, &[]));
    assert!(printed.contains("masked (over the mask pixels) PSNR"), "{printed}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let masked = &summary["masked_test"];
    assert_eq!(masked["views"], 2, "{summary}");
    let psnr = masked["psnr"].as_f64().unwrap();
    assert!(psnr.is_finite(), "{masked}");
    // The summary still reads as a TrainSummary.
    let typed: bbsplat::report::TrainSummary = serde_json::from_value(summary.clone()).unwrap();
    assert_eq!(typed.test_views, 2);

    let model = out.join("model");
    let m = model.to_str().unwrap();
    let json = run_ok(&["eval", m, d, "--masked", "--json"]);
    let report: bbsplat::eval::EvalReport = serde_json::from_str(&json).unwrap();
    assert!((report.mean_masked_psnr.unwrap() - psnr).abs() < 1e-9, "{json}");
    assert!(
        report
            .views
            .iter()
            .all(|v| v.masked_psnr.is_some() && v.masked_ssim.is_some())
    );
    let table = run_ok(&["eval", m, d, "--masked"]);
    assert!(
        table.contains("masked PSNR") && table.contains("masked SSIM"),
        "{table}"
    );
    let plain: bbsplat::eval::EvalReport = serde_json::from_str(&run_ok(&["eval", m, d, "--json"])).unwrap();
    assert!(plain.mean_masked_psnr.is_none() && plain.views.iter().all(|v| v.masked_psnr.is_none()));
    // --mask-mode ignore: the photographs keep their colour outside the mask, so the
    // whole-image figures change while the masked ones are taken over the same pixels.
    let ignored: bbsplat::eval::EvalReport =
        serde_json::from_str(&run_ok(&["eval", m, d, "--masked", "--json", "--mask-mode", "ignore"])).unwrap();
    assert_ne!(ignored.mean_psnr, report.mean_psnr);
    assert!((ignored.mean_masked_psnr.unwrap() - psnr).abs() < 1e-9);
    // A --masks folder that does not exist is named.
    let (ok, err) = run(&["eval", m, d, "--masks", root.join("nowhere").to_str().unwrap()]);
    assert!(!ok && err.contains("nowhere"), "{err}");
    std::fs::remove_dir_all(&root).ok();
}

#[test]
fn mask_mode_weight_trains_on_the_masks_and_is_refused_without_them() {
    let root = temp("mask-weight");
    let data = root.join("neus");
    write_neus(&data, &known_cameras(), glam::DMat4::IDENTITY, 4.0);
    let d = data.to_str().unwrap();
    let train = |out: &str, extra: &[&str]| run(&train_args(d, out, extra));
    let (weighted, composite) = (root.join("weighted"), root.join("composite"));
    let (ok, err) = train(weighted.to_str().unwrap(), &["--mask-mode", "weight"]);
    assert!(ok, "{err}");
    assert!(train(composite.to_str().unwrap(), &[]).0);
    // The loss saw other images: another model.
    let model = |dir: &std::path::Path| std::fs::read(dir.join("model").join("texture_color.npz")).unwrap();
    assert_ne!(model(&weighted), model(&composite));
    // The mode is part of the run's record: resuming the weighted run without it is refused.
    let checkpoint = weighted.join("checkpoint.bin");
    let resumed = root.join("resumed");
    let (ok, err) = train(resumed.to_str().unwrap(), &["--resume", checkpoint.to_str().unwrap()]);
    assert!(!ok && err.contains("--mask-mode"), "{err}");
    // Without masks the mode is refused, naming the scene and what is missing.
    std::fs::remove_dir_all(data.join("mask")).unwrap();
    let (ok, err) = train(root.join("no-masks").to_str().unwrap(), &["--mask-mode", "weight"]);
    assert!(
        !ok && err.contains("no training view has a mask") && err.contains("neus"),
        "{err}"
    );
    std::fs::remove_dir_all(&root).ok();
}
