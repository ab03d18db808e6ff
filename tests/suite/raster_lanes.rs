//! The rasterizer's two instruction-set builds of its lane-wise tile loops (baseline SSE2, and
//! AVX2 + FMA chosen at run time; `bbsplat::raster::lanes`) give the same bits: every image, the
//! per-billboard impact and every gradient, on trained-like scenes (tens of blended billboards
//! per pixel), the random benchmark scene, and with the normal and distortion maps.
//!
//! On a CPU without AVX2 both renders take the baseline path and the comparison is trivially
//! equal; the test says so in its output.

use bbsplat::billboards::{
    ActivatedBillboards, RandomSceneConfig, TrainedLikeConfig, random_scene, random_scene_camera, trained_like_scene,
};
use bbsplat::camera::Camera;
use bbsplat::raster::backward::ImageGradients;
use bbsplat::raster::{RenderGradients, RenderSettings, lanes, render, render_backward};
use bbsplat::rng::Rng;
use std::sync::Mutex;

/// Serialises the tests that switch the process-wide build choice.
static SWITCH: Mutex<()> = Mutex::new(());

/// Every output bit of a render and its backward for fixed random image gradients.
fn everything(scene: &ActivatedBillboards, cam: &Camera, settings: &RenderSettings, aux: bool) -> Vec<u32> {
    let set = scene.borrowed();
    let out = render(&set, cam, settings);
    let n = (cam.width * cam.height) as usize;
    let mut rng = Rng::new(7);
    let mut noise = |len: usize| (0..len).map(|_| rng.uniform() - 0.5).collect::<Vec<f32>>();
    let (rgb, alpha, depth, normal, distortion) = (noise(3 * n), noise(n), noise(n), noise(3 * n), noise(n));
    let grads_in = ImageGradients {
        rgb: &rgb,
        alpha: Some(&alpha),
        depth: Some(&depth),
        normal: aux.then_some(&normal[..]),
        distortion: aux.then_some(&distortion[..]),
    };
    let mut grads = RenderGradients::zeros(scene.len(), scene.texture_size);
    let touched = render_backward(&set, &out, &grads_in, &mut grads);
    let mut bits: Vec<u32> = [
        &out.rgb[..],
        &out.alpha,
        &out.depth,
        &out.median_depth,
        &out.normal,
        &out.distortion,
        &out.impact,
        &out.state.final_transmittance,
        &grads.sh,
    ]
    .iter()
    .flat_map(|v| v.iter().map(|x| x.to_bits()))
    .collect();
    bits.extend(grads.positions.iter().flat_map(|p| p.to_array().map(f32::to_bits)));
    bits.extend(grads.quaternions.iter().flat_map(|q| q.map(f32::to_bits)));
    bits.extend(grads.log_scales.iter().flat_map(|s| s.to_array().map(f32::to_bits)));
    bits.extend(grads.textures.iter().flat_map(|t| t.map(f32::to_bits)));
    bits.extend(grads.background.to_array().map(f32::to_bits));
    bits.extend(out.state.blended_slots.iter().copied());
    bits.extend(touched);
    bits.extend([out.stats.evaluated_pairs as u32, out.stats.blended_pairs as u32]);
    bits
}

/// Renders with the baseline build forced, then with the widest the CPU has.
fn both_builds(
    scene: &ActivatedBillboards,
    cam: &Camera,
    settings: &RenderSettings,
    aux: bool,
) -> (Vec<u32>, Vec<u32>) {
    let _guard = SWITCH.lock().unwrap_or_else(|e| e.into_inner());
    lanes::force_baseline(true);
    assert!(!lanes::wide_lanes());
    let baseline = everything(scene, cam, settings, aux);
    lanes::force_baseline(false);
    println!("wide lanes (AVX2 + FMA) on this CPU: {}", lanes::wide_lanes());
    let wide = everything(scene, cam, settings, aux);
    (baseline, wide)
}

#[test]
fn baseline_and_wide_builds_agree_bit_for_bit_on_trained_like_scenes() {
    let cam = random_scene_camera(160, 128);
    for config in [
        TrainedLikeConfig::object(3000, 160, 128),
        TrainedLikeConfig::capture(3000, 160, 128),
    ] {
        let scene = trained_like_scene(&config);
        let (baseline, wide) = both_builds(&scene, &cam, &RenderSettings::default(), false);
        assert!(baseline.len() > 100_000);
        assert!(baseline == wide, "the two builds differ");
    }
}

#[test]
fn baseline_and_wide_builds_agree_bit_for_bit_with_the_auxiliary_maps() {
    let cam = random_scene_camera(96, 80);
    let scene = trained_like_scene(&TrainedLikeConfig::object(1500, 96, 80));
    let settings = RenderSettings {
        distortion: true,
        ..RenderSettings::default()
    };
    let (baseline, wide) = both_builds(&scene, &cam, &settings, true);
    assert!(baseline == wide, "the two builds differ");
}

#[test]
fn baseline_and_wide_builds_agree_bit_for_bit_on_the_benchmark_scene() {
    let cam = random_scene_camera(128, 128);
    let scene = random_scene(&RandomSceneConfig::benchmark(8000, 128, 128));
    let (baseline, wide) = both_builds(&scene, &cam, &RenderSettings::default(), false);
    assert!(baseline == wide, "the two builds differ");
}
