//! Camera alignment under a frozen model ([`fit_camera`]): a camera moved off the one that made
//! the image is brought back.

use super::raster::small_scene;
use bbsplat::billboards::random_scene_camera;
use bbsplat::camera::Camera;
use bbsplat::loss::TrainingLoss;
use bbsplat::raster::{RenderSettings, render};
use bbsplat::train::camera_fit::{CameraStepSizes, fit_camera};
use glam::Vec3;

fn settings() -> RenderSettings {
    RenderSettings {
        background: Vec3::new(0.2, 0.3, 0.4),
        ..RenderSettings::default()
    }
}

/// Angle of the rotation between two cameras' orientations, radians (f64: the f32 arc cosine
/// near 1 cannot tell angles below 5e-4 apart).
fn angle_between(a: &Camera, b: &Camera) -> f64 {
    let r = a.rotation.as_dmat3() * b.rotation.as_dmat3().transpose();
    // The skew part: sin θ times the axis (acos of the trace loses small angles in any precision).
    let axis = glam::DVec3::new(
        r.y_axis.z - r.z_axis.y,
        r.z_axis.x - r.x_axis.z,
        r.x_axis.y - r.y_axis.x,
    );
    (0.5 * axis.length()).asin()
}

#[test]
fn a_moved_camera_is_brought_back_to_the_one_that_made_the_image() {
    let (w, h) = (64, 48);
    let s = settings();
    for seed in 0..3u64 {
        // Billboards covering the view, opaque enough to show their textures.
        let scene = small_scene(80, w, h, 8, 16.0, (0.6, 1.0), seed);
        let truth = random_scene_camera(w, h);
        let target = render(&scene.borrowed(), &truth, &s).rgb;
        let start = truth.adjusted(Vec3::new(0.01, -0.008, 0.012), Vec3::new(0.03, -0.02, 0.05), 1.02);
        // The focal length and the distance along the axis trade against each other; 300 steps
        // undo both (150 left 30 % of them).
        let sizes = CameraStepSizes {
            rotation: 2e-3,
            translation: 5e-3,
            focal: 2e-3,
        };
        let fit = fit_camera(&scene.borrowed(), &start, &target, &s, 300, &sizes).unwrap();
        // The loss reported is the returned camera's.
        let again = TrainingLoss::default()
            .evaluate(
                &render(&scene.borrowed(), &fit.camera, &s).rgb,
                &target,
                w as usize,
                h as usize,
                3,
            )
            .unwrap();
        assert_eq!(again.loss, fit.loss_after, "seed {seed}");
        let (angle0, angle1) = (angle_between(&start, &truth), angle_between(&fit.camera, &truth));
        let (shift0, shift1) = (
            (start.centre() - truth.centre()).length(),
            (fit.camera.centre() - truth.centre()).length(),
        );
        let (focal0, focal1) = (
            (start.fx / truth.fx - 1.0).abs(),
            (fit.camera.fx / truth.fx - 1.0).abs(),
        );
        eprintln!(
            "measure seed {seed}: loss {:.3e} -> {:.3e}, angle {angle0:.2e} -> {angle1:.2e}, centre {shift0:.2e} -> {shift1:.2e}, focal {focal0:.2e} -> {focal1:.2e}",
            fit.loss_before, fit.loss_after
        );
        // Measured over the three seeds: loss ×1.3e-4 at worst, angle ×1.7e-4, centre ×1.2e-4, focal
        // error ×9e-5; the bounds are 6-9× those.
        assert!(
            fit.loss_after < 1e-3 * fit.loss_before,
            "seed {seed}: loss {} -> {}",
            fit.loss_before,
            fit.loss_after
        );
        assert!(angle1 < 1e-3 * angle0, "seed {seed}: angle {angle0} -> {angle1}");
        assert!(shift1 < 1e-3 * shift0, "seed {seed}: centre {shift0} -> {shift1}");
        assert!(focal1 < 8e-4 * focal0, "seed {seed}: focal {focal0} -> {focal1}");
    }
}

/// A fit never returns a worse camera: with step sizes far too large (each step throws the
/// camera about), it returns the best camera it rendered, here the one it was given.
#[test]
fn a_fit_that_only_gets_worse_returns_the_given_camera() {
    let (w, h) = (40, 32);
    let s = settings();
    let scene = small_scene(40, w, h, 8, 12.0, (0.6, 1.0), 5);
    let truth = random_scene_camera(w, h);
    let target = render(&scene.borrowed(), &truth, &s).rgb;
    let start = truth.adjusted(Vec3::new(0.0, 0.002, 0.0), Vec3::ZERO, 1.0);
    let sizes = CameraStepSizes {
        rotation: 0.3,
        translation: 1.0,
        focal: 0.3,
    };
    let fit = fit_camera(&scene.borrowed(), &start, &target, &s, 5, &sizes).unwrap();
    assert_eq!(fit.camera, start);
    assert_eq!(fit.loss_after, fit.loss_before);
    // And with sound steps from the same start, it does move.
    let sound = CameraStepSizes {
        rotation: 1e-3,
        translation: 1e-3,
        focal: 1e-3,
    };
    let fit = fit_camera(&scene.borrowed(), &start, &target, &s, 5, &sound).unwrap();
    assert!(fit.loss_after < fit.loss_before);
}
