//! Evaluation: metrics on 8-bit images, the report's means and table, bad input.

use bbsplat::camera::Camera;
use bbsplat::eval::{EvalReport, EvalView, ViewMetrics, evaluate_views, image_metrics};
use bbsplat::raster::RenderSettings;

#[test]
fn metrics_are_taken_on_8_bit_images() {
    // A difference below half a quantisation step vanishes; one full step does not.
    let truth: Vec<f32> = (0..12 * 12 * 3).map(|i| (i % 200) as f32 / 255.0).collect();
    let tiny: Vec<f32> = truth.iter().map(|v| v + 0.4 / 255.0).collect();
    assert!(image_metrics(&tiny, &truth, 12, 12).unwrap().psnr.is_infinite());
    let step: Vec<f32> = truth.iter().map(|v| v + 1.0 / 255.0).collect();
    let m = image_metrics(&step, &truth, 12, 12).unwrap();
    // Every value is off by exactly 1/255 (none reach the clamp): PSNR = 20·log10(255).
    assert!((m.psnr - 20.0 * 255f64.log10()).abs() < 1e-9, "{}", m.psnr);
    assert!(m.ssim < 1.0 && m.ssim > 0.9);
}

#[test]
fn report_means_and_table() {
    let views = vec![
        ViewMetrics {
            name: "a".into(),
            psnr: 20.0,
            ssim: 0.5,
            render_ms: 1.0,
            lpips: None,
        },
        ViewMetrics {
            name: "b".into(),
            psnr: 30.0,
            ssim: 0.7,
            render_ms: 3.0,
            lpips: None,
        },
    ];
    let r = EvalReport::from_views(views);
    assert_eq!((r.mean_psnr, r.mean_render_ms), (25.0, 2.0));
    assert!((r.mean_ssim - 0.6).abs() < 1e-12);
    let t = r.table();
    assert_eq!(t.lines().count(), 4);
    assert!(
        !t.contains("LPIPS") && !serde_json::to_string(&r).unwrap().contains("lpips"),
        "{t}"
    );
    // With LPIPS: a column, per-view values and their mean, in the table and the JSON.
    let r = r.with_lpips(bbsplat::lpips::Variant::Vgg, &[0.1, 0.3]);
    assert!((r.mean_lpips.unwrap() - 0.2).abs() < 1e-12 && r.views[1].lpips == Some(0.3));
    let t = r.table();
    assert!(
        t.lines().next().unwrap().ends_with("LPIPS-vgg") && t.lines().last().unwrap().ends_with("0.2000"),
        "{t}"
    );
    let back: EvalReport = serde_json::from_str(&serde_json::to_string(&r).unwrap()).unwrap();
    assert_eq!(back, r);
    assert!(t.lines().last().unwrap().starts_with("mean"));
}

#[test]
fn a_mismatched_image_is_an_error() {
    let cam = Camera::look_at(glam::Vec3::Z * 3.0, glam::Vec3::ZERO, glam::Vec3::Y, 8.0, 8.0, 8, 8);
    let b = bbsplat::billboards::ActivatedBillboards::empty(4);
    let short = vec![0.0f32; 10];
    let v = EvalView {
        name: "x",
        camera: &cam,
        rgb: short.into(),
    };
    assert!(evaluate_views(&b.borrowed(), [v], &RenderSettings::default(), |_, _| {}).is_err());
}
