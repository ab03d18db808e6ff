//! The mask-weighted training loss (`loss::masked`, `--mask-mode weight`): its gradient against
//! central differences, pixels outside the mask left out exactly, and in a trainer a target
//! changed outside the mask changing no bit of the run.

use bbsplat::demo::{DemoConfig, generate};
use bbsplat::gradcheck::{GradTolerance, StepRule, compare, numerical_gradient};
use bbsplat::loss::TrainingLoss;
use bbsplat::loss::masked::{MaskedBuffers, evaluate_masked};
use bbsplat::loss::ssim::{Padding, Precision, SsimScratch};
use bbsplat::model::RawBillboards;
use bbsplat::rng::Rng;
use bbsplat::train::{TrainConfig, TrainError, TrainView, Trainer};
use glam::Vec3;

/// Render, target and mask of `w × h` RGB: `|render − target| ≥ 0.03` everywhere (the FD steps
/// never cross the L1 kink); mask values 0, 128 or 255 in random pixels.
fn case(w: usize, h: usize, seed: u64) -> (Vec<f32>, Vec<f32>, Vec<u8>) {
    let mut rng = Rng::new(seed);
    let target: Vec<f32> = (0..w * h * 3).map(|_| rng.range(0.1, 0.9)).collect();
    let render: Vec<f32> = target
        .iter()
        .map(|v| v + if rng.uniform() < 0.5 { -1.0 } else { 1.0 } * rng.range(0.03, 0.2))
        .collect();
    let mask: Vec<u8> = (0..w * h)
        .map(|_| [0u8, 128, 255][(rng.uniform() * 3.0) as usize % 3])
        .collect();
    (render, target, mask)
}

fn masked(loss: &TrainingLoss, render: &[f32], target: &[f32], mask: &[u8], w: usize, h: usize) -> (f64, Vec<f32>) {
    let out = evaluate_masked(
        loss,
        render,
        target,
        mask,
        (w, h, 3),
        &mut SsimScratch::default(),
        &mut MaskedBuffers::default(),
    )
    .unwrap();
    (out.loss, out.d_render)
}

#[test]
fn the_masked_loss_gradient_matches_finite_differences() {
    let (w, h) = (10usize, 9usize);
    let f64_loss = TrainingLoss {
        lambda_dssim: 0.5,
        padding: Padding::Same,
        precision: Precision::F64,
        ..TrainingLoss::default()
    };
    // Relative L2 bounds 10× the worst measured over the six seeds (2026-12-03): 1.22e-4 for the
    // default (f32 SSIM values carry the FD noise), 3.71e-6 for f64 SSIM (the weighted images
    // are f32 products, rounded before the loss: above the plain f64 loss's 3.8e-7).
    for seed in 0..6u64 {
        let (render, target, mask) = case(w, h, seed);
        for (config, max_rel_l2) in [(TrainingLoss::default(), 1.2e-3), (f64_loss, 3.7e-5)] {
            // The sum over values (n·mean), so that the gradients are O(1), kept in f64.
            let n = render.len() as f64;
            let loss = |x: &[f32]| masked(&config, x, &target, &mask, w, h).0 * n;
            let idx: Vec<usize> = (0..render.len()).collect();
            let numeric = numerical_gradient(loss, &render, &idx, StepRule::default());
            let (_, d_render) = masked(&config, &render, &target, &mask, w, h);
            let analytic: Vec<f64> = d_render.iter().map(|&g| g as f64 * n).collect();
            let tolerance = GradTolerance {
                max_rel_l2,
                ..GradTolerance::default()
            };
            let report = compare(&analytic, &numeric, &tolerance);
            println!("masked loss, seed {seed}, λ = {}: {report}", config.lambda_dssim);
            assert!(report.passed(), "seed {seed}: {report}");
            // The same check catches the gradient of the weighted images without the chain
            // rule's last factor m (the gradient with respect to render·m, not render).
            let unchained = evaluate_masked_without_chain(&config, &render, &target, &mask, w, h);
            let wrong: Vec<f64> = unchained.iter().map(|&g| g as f64 * n).collect();
            assert!(
                !compare(&wrong, &numeric, &tolerance).passed(),
                "seed {seed}: a wrong gradient passed"
            );
        }
    }
}

/// `∂L/∂(render·m)`: the loss of the weighted images and its gradient as `evaluate` gives it,
/// not multiplied by `m` (what the masked loss would return if it forgot the chain rule).
fn evaluate_masked_without_chain(
    loss: &TrainingLoss,
    render: &[f32],
    target: &[f32],
    mask: &[u8],
    w: usize,
    h: usize,
) -> Vec<f32> {
    let weight = |v: &[f32]| -> Vec<f32> {
        v.chunks_exact(3)
            .zip(mask)
            .flat_map(|(p, &m)| p.iter().map(move |c| c * (m as f32 / 255.0)))
            .collect()
    };
    loss.evaluate(&weight(render), &weight(target), w, h, 3)
        .unwrap()
        .d_render
}

#[test]
fn pixels_outside_the_mask_are_left_out_exactly() {
    let (w, h) = (24usize, 20usize);
    let (render, target, mask) = case(w, h, 11);
    let loss = TrainingLoss::default();
    let (value, grad) = masked(&loss, &render, &target, &mask, w, h);
    // Another render and target wherever the mask is 0: the same loss, bit for bit.
    let (mut render2, mut target2) = (render.clone(), target.clone());
    for (p, &m) in mask.iter().enumerate() {
        if m == 0 {
            for c in 0..3 {
                render2[3 * p + c] = 1.0 - render2[3 * p + c];
                target2[3 * p + c] = 0.3;
            }
        }
    }
    let (value2, grad2) = masked(&loss, &render2, &target2, &mask, w, h);
    assert_eq!(value.to_bits(), value2.to_bits());
    assert_eq!(grad, grad2);
    for (p, &m) in mask.iter().enumerate() {
        if m == 0 {
            assert_eq!(&grad[3 * p..3 * p + 3], &[0.0; 3], "pixel {p}");
        }
    }
    // A full mask is the plain loss, bit for bit.
    let full = vec![255u8; w * h];
    let plain = loss.evaluate(&render, &target, w, h, 3).unwrap();
    let (value_full, grad_full) = masked(&loss, &render, &target, &full, w, h);
    assert_eq!(
        (plain.loss.to_bits(), &plain.d_render),
        (value_full.to_bits(), &grad_full)
    );
    // A mask of the wrong size is refused.
    let err = evaluate_masked(
        &loss,
        &render,
        &target,
        &mask[1..],
        (w, h, 3),
        &mut SsimScratch::default(),
        &mut MaskedBuffers::default(),
    )
    .unwrap_err();
    assert!(err.to_string().contains("mask"), "{err}");
}

/// A trainer on the 32-px demo with every view's left half masked out; `scramble` replaces the
/// targets' left halves. Returns the checkpoint after `steps` steps.
fn masked_run(masked_out: bool, scramble: bool, steps: usize) -> Vec<u8> {
    let demo = generate(&DemoConfig {
        resolution: 32,
        train_views: 6,
        test_views: 1,
        points: 150,
        seed: 4,
    });
    let views: Vec<TrainView> = demo
        .train
        .iter()
        .map(|v| {
            let (w, h) = (v.camera.width as usize, v.camera.height as usize);
            let mask: Vec<u8> = (0..w * h).map(|p| if p % w < w / 2 { 0 } else { 255 }).collect();
            let mut rgb = v.rgb.clone();
            if scramble {
                for (p, &m) in mask.iter().enumerate() {
                    if m == 0 {
                        rgb[3 * p..3 * p + 3].copy_from_slice(&[0.9, 0.1, 0.5]);
                    }
                }
            }
            TrainView {
                rgb: rgb.into(),
                ..TrainView::from_demo(v).with_loss_mask(masked_out.then_some(mask))
            }
        })
        .collect();
    let model = RawBillboards::from_points(&demo.points, &demo.colours, 4, 4);
    let config = TrainConfig {
        iterations: 200,
        background: Vec3::ONE,
        seed: 3,
        ..TrainConfig::default()
    };
    let mut trainer = Trainer::new(model, config);
    for _ in 0..steps {
        trainer.step(&views).unwrap();
    }
    trainer.checkpoint_bytes()
}

#[test]
fn a_trainer_with_a_loss_mask_ignores_the_target_outside_it() {
    // 40 steps of a 200-step run: every one of the 6 views drawn several times, textures on
    // from step 4 (1/64 of the run).
    let masked = masked_run(true, false, 40);
    assert_eq!(
        masked,
        masked_run(true, true, 40),
        "the target outside the mask changed the run"
    );
    // Without the mask the same change of target changes the run (so the check can fail).
    assert_ne!(masked_run(false, false, 40), masked_run(false, true, 40));
    // And the mask itself changes the run.
    assert_ne!(masked, masked_run(false, false, 40));
}

#[test]
fn a_loss_mask_of_the_wrong_size_is_refused() {
    let demo = generate(&DemoConfig {
        resolution: 16,
        train_views: 2,
        test_views: 1,
        points: 20,
        seed: 1,
    });
    let views: Vec<TrainView> = demo
        .train
        .iter()
        .enumerate()
        .map(|(i, v)| TrainView::from_demo(v).with_loss_mask((i == 1).then(|| vec![255u8; 7])))
        .collect();
    let model = RawBillboards::from_points(&demo.points, &demo.colours, 4, 1);
    let mut trainer = Trainer::new(model, TrainConfig::default());
    let err = trainer.step(&views).unwrap_err();
    assert!(matches!(err, TrainError::MaskSize { view: 1, got: 7, .. }), "{err:?}");
    assert!(err.to_string().contains("loss mask has 7 values"), "{err}");
}

#[test]
fn a_coarse_view_keeps_its_loss_mask_averaged_like_its_pixels() {
    use bbsplat::train::resolution::downscale_view;
    let camera = bbsplat::camera::Camera::look_at(Vec3::new(0.0, 0.0, -3.0), Vec3::ZERO, Vec3::Y, 40.0, 40.0, 4, 2);
    let rgb: Vec<f32> = vec![0.5; 4 * 2 * 3];
    // Columns 0 and 1 kept, 2 half, 3 left out.
    let mask: Vec<u8> = (0..8).map(|p| [255, 255, 128, 0][p % 4]).collect();
    let view = TrainView {
        camera,
        rgb: rgb.into(),
        loss_mask: None,
    }
    .with_loss_mask(Some(mask));
    let small = downscale_view(&view, 2).unwrap();
    // Each coarse pixel is the mean of a 2×2 block: 255 and 64 (= round(128 / 2)).
    assert_eq!(small.loss_mask, Some(vec![255, 64]));
    let unmasked = downscale_view(&view.with_loss_mask(None), 2).unwrap();
    assert_eq!(unmasked.loss_mask, None);
}
