//! Training summaries: the JSON round trip and the peak memory figure.

use bbsplat::report::*;

#[test]
fn summary_round_trips_through_json() {
    let s = TrainSummary {
        version: SUMMARY_VERSION,
        scene: "demo".into(),
        iterations: 10,
        billboards: 5,
        alive: 4,
        texture_size: 16,
        sh_degree: 3,
        resolution: [96, 96],
        train_seconds: 1.5,
        render_ms_per_frame: 2.0,
        test_psnr: 20.0,
        test_ssim: 0.8,
        test_views: 8,
        model_bytes: 1234,
        peak_rss_bytes: peak_rss_bytes(),
        estimated_peak_bytes: Some(1 << 30),
        seed: 0,
        threads: 2,
        curve: vec![CurvePoint {
            step: 10,
            seconds: 1.5,
            psnr: 20.0,
            ssim: 0.8,
        }],
        command: vec!["bbsplat".into(), "train".into()],
        lpips_network: Some("vgg".into()),
        test_lpips: Some(0.125),
        lpips_note: None,
    };
    let text = serde_json::to_string(&s).unwrap();
    assert_eq!(serde_json::from_str::<TrainSummary>(&text).unwrap(), s);
    // The summary file: the same object with the settings; read as either.
    let file = SummaryFile {
        summary: s.clone(),
        settings: RecordedSettings {
            clamp_gradient: "straight-through".into(),
            lambda_normal: 0.05,
            lambda_distortion: 100.0,
            normal_from: Some(0.25),
            distortion_from: Some(0.125),
        },
        warnings: vec!["a warning".into()],
        record: RunReport {
            automatic: vec![AutoChoice {
                setting: "background".into(),
                value: "white".into(),
                reason: "test".into(),
            }],
            plan: None,
            growth: Some(GrowthRecord {
                initial: 4,
                final_count: 5,
                alive: 4,
                cap: 9,
            }),
            other_seconds: 0.5,
        },
    };
    let text = serde_json::to_string(&file).unwrap();
    assert!(text.contains(r#""clamp_gradient":"straight-through""#), "{text}");
    assert!(text.contains(r#""lambda_normal":0.05"#), "{text}");
    assert!(text.contains(r#""distortion_from":0.125"#), "{text}");
    assert_eq!(serde_json::from_str::<SummaryFile>(&text).unwrap(), file);
    assert_eq!(serde_json::from_str::<TrainSummary>(&text).unwrap(), s);
    // An older summary without the settings reads as exact.
    let old = serde_json::to_string(&s).unwrap();
    assert_eq!(
        serde_json::from_str::<SummaryFile>(&old)
            .unwrap()
            .settings
            .clamp_gradient,
        "exact"
    );
    // ... and without the geometry regularisers (off).
    let settings = serde_json::from_str::<SummaryFile>(&old).unwrap().settings;
    assert_eq!(
        (
            settings.lambda_normal,
            settings.lambda_distortion,
            settings.normal_from,
            settings.distortion_from
        ),
        (0.0, 0.0, None, None)
    );
}

#[test]
fn peak_rss_is_reported_on_linux() {
    if cfg!(target_os = "linux") {
        assert!(peak_rss_bytes() > 1 << 20);
    }
}
