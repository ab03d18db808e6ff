//! The rasterizer's choices made for speed alone (`bbsplat::raster::lanes`) give the same bits:
//! the two instruction-set builds of its lane-wise tile loops (baseline SSE2, and AVX2 + FMA
//! chosen at run time) and the two tile walks (billboard by billboard, pixel by pixel), in every
//! combination: every image, the per-billboard impact and every gradient, on trained-like
//! scenes (tens of blended billboards per pixel), the random benchmark scene (a pixel or two per
//! entry), and with the normal and distortion maps.
//!
//! On a CPU without AVX2 both renders take the baseline path and the comparison is trivially
//! equal; the test says so in its output.

use bbsplat::billboards::{
    ActivatedBillboards, RandomSceneConfig, TrainedLikeConfig, random_scene, random_scene_camera, trained_like_scene,
};
use bbsplat::camera::Camera;
use bbsplat::raster::backward::ImageGradients;
use bbsplat::raster::lanes::{self, TileWalk};
use bbsplat::raster::{RenderGradients, RenderSettings, render, render_backward};
use bbsplat::rng::Rng;
use std::sync::Mutex;

/// Serialises the tests that switch the process-wide choices (here and in
/// `train_texture_step.rs`).
pub(crate) static SWITCH: Mutex<()> = Mutex::new(());

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
        camera: false,
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
    // Each tile's blended pairs (pixel, slot, transmittance in front), in one order whatever
    // the walk grouped them by.
    bits.extend(out.state.tiles.iter().flat_map(|tile| {
        tile.pairs_by_pixel()
            .into_iter()
            .flat_map(|(q, slot, t)| [q, slot, t.to_bits()])
    }));
    bits.extend(touched);
    bits.extend([out.stats.evaluated_pairs as u32, out.stats.blended_pairs as u32]);
    bits
}

/// Renders under every combination of instruction set (baseline forced, or the widest the CPU
/// has) and tile walk (by each tile's size, every tile billboard by billboard, every tile pixel
/// by pixel); returns each combination's name and bits.
fn all_variants(
    scene: &ActivatedBillboards,
    cam: &Camera,
    settings: &RenderSettings,
    aux: bool,
) -> Vec<(String, Vec<u32>)> {
    let _guard = SWITCH.lock().unwrap_or_else(|e| e.into_inner());
    let mut out = Vec::new();
    for baseline in [true, false] {
        lanes::force_baseline(baseline);
        if baseline {
            assert!(!lanes::wide_lanes(), "the baseline build is forced");
        }
        for walk in [TileWalk::Auto, TileWalk::ByEntry, TileWalk::ByPixel] {
            lanes::force_tile_walk(walk);
            let name = format!("baseline {baseline}, {walk:?}");
            out.push((name, everything(scene, cam, settings, aux)));
        }
    }
    lanes::force_baseline(false);
    lanes::force_tile_walk(TileWalk::Auto);
    println!("wide lanes (AVX2 + FMA) on this CPU: {}", lanes::wide_lanes());
    out
}

/// Every variant gives the bits of the first (baseline instruction set, automatic walk).
fn assert_all_equal(variants: &[(String, Vec<u32>)]) {
    let (first_name, first) = &variants[0];
    assert!(first.len() > 10_000);
    for (name, bits) in &variants[1..] {
        assert!(bits == first, "{name} differs from {first_name}");
    }
}

#[test]
fn every_build_and_walk_agree_bit_for_bit_on_trained_like_scenes() {
    let cam = random_scene_camera(160, 128);
    for config in [
        TrainedLikeConfig::object(3000, 160, 128),
        TrainedLikeConfig::capture(3000, 160, 128),
    ] {
        let scene = trained_like_scene(&config);
        assert_all_equal(&all_variants(&scene, &cam, &RenderSettings::default(), false));
    }
}

#[test]
fn every_build_and_walk_agree_bit_for_bit_with_the_auxiliary_maps() {
    let cam = random_scene_camera(96, 80);
    let scene = trained_like_scene(&TrainedLikeConfig::object(1500, 96, 80));
    let settings = RenderSettings {
        distortion: true,
        ..RenderSettings::default()
    };
    assert_all_equal(&all_variants(&scene, &cam, &settings, true));
}

#[test]
fn every_build_and_walk_agree_bit_for_bit_on_the_benchmark_scene() {
    let cam = random_scene_camera(128, 128);
    let scene = random_scene(&RandomSceneConfig::benchmark(8000, 128, 128));
    assert_all_equal(&all_variants(&scene, &cam, &RenderSettings::default(), false));
}
