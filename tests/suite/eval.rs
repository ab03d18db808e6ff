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
            masked_psnr: None,
            masked_ssim: None,
        },
        ViewMetrics {
            name: "b".into(),
            psnr: 30.0,
            ssim: 0.7,
            render_ms: 3.0,
            lpips: None,
            masked_psnr: None,
            masked_ssim: None,
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
        mask: None,
    };
    assert!(evaluate_views(&b.borrowed(), [v], &RenderSettings::default(), |_, _| {}).is_err());
}

#[test]
fn masked_metrics_count_only_the_mask_pixels() {
    use bbsplat::eval::masked_image_metrics;
    let (w, h) = (24, 20);
    let truth: Vec<f32> = (0..w * h * 3).map(|i| (i % 11) as f32 / 11.0).collect();
    let mut mask = vec![0u8; w * h];
    let mut render = truth.clone();
    for y in 0..h {
        for x in 0..w {
            if x < w / 2 {
                mask[y * w + x] = 255;
            } else {
                render[3 * (y * w + x)] = 1.0 - truth[3 * (y * w + x)];
            }
        }
    }
    let whole = bbsplat::eval::image_metrics(&render, &truth, w, h).unwrap();
    let masked = masked_image_metrics(&render, &truth, &mask, w, h).unwrap().unwrap();
    assert!(
        whole.psnr.is_finite() && masked.psnr.is_infinite(),
        "{whole:?} {masked:?}"
    );
    // SSIM windows reach across the mask edge: masked SSIM is higher, still below 1.
    assert!(masked.ssim > whole.ssim && masked.ssim < 1.0, "{whole:?} {masked:?}");
    // An error inside the mask: the masked MSE is the squared error over 3 x the mask pixels.
    let mut inside = truth.clone();
    inside[0] = (truth[0] + 0.2).min(1.0);
    let d = bbsplat::loss::psnr::quantize_u8(inside[0]) as f64 - bbsplat::loss::psnr::quantize_u8(truth[0]) as f64;
    let mse = (d / 255.0).powi(2) / (3 * w * h / 2) as f64;
    let m = masked_image_metrics(&inside, &truth, &mask, w, h).unwrap().unwrap();
    assert!(
        (m.psnr + 10.0 * mse.log10()).abs() < 1e-5,
        "{} against {}",
        m.psnr,
        -10.0 * mse.log10()
    );
    assert!(masked_image_metrics(&render, &truth, &mask[1..], w, h).is_err());
    // The report and the table label them.
    let cam = Camera::look_at(
        glam::Vec3::Z * 3.0,
        glam::Vec3::ZERO,
        glam::Vec3::Y,
        8.0,
        8.0,
        w as u32,
        h as u32,
    );
    let b = bbsplat::billboards::ActivatedBillboards::empty(4);
    let v = EvalView {
        name: "v",
        camera: &cam,
        rgb: truth.clone().into(),
        mask: Some(&mask),
    };
    let r = evaluate_views(&b.borrowed(), [v], &RenderSettings::default(), |_, _| {}).unwrap();
    assert!(r.mean_masked_psnr.is_some() && r.views[0].masked_ssim.is_some());
    assert!(r.table().contains("masked PSNR"));
    let json = serde_json::to_string(&r).unwrap();
    assert!(json.contains("mean_masked_psnr"));
}
