//! Rasterizer proofs: tiled = brute-force reference, whole-image finite differences for every
//! parameter group, invariances, determinism across thread counts, and named hard cases.

use bbsplat::billboards::{ActivatedBillboards, RandomSceneConfig, random_scene, random_scene_camera};
use bbsplat::camera::Camera;
use bbsplat::gradcheck::{GradTolerance, compare, directional_derivative, random_weights};
use bbsplat::raster::backward::ImageGradients;
use bbsplat::raster::reference::render_reference;
use bbsplat::raster::{
    RenderBuffers, RenderGradients, RenderOutput, RenderSettings, render, render_backward, render_with,
};
use bbsplat::rng::Rng;
use bbsplat::stages::composite::CompositeParams;
use bbsplat::strategies::seeded_config;
use glam::{Vec2, Vec3};
use proptest::prelude::*;

fn settings(background: Vec3) -> RenderSettings {
    RenderSettings {
        background,
        sh_degree: 3,
        composite: CompositeParams::default(),
        distortion: false,
        ..RenderSettings::default()
    }
}

/// Compositing without the three discontinuities (alpha cut-off, clamp, transmittance stop),
/// for finite-difference checks: the renderer is then smooth apart from texel-border kinks.
pub(crate) fn smooth_settings(background: Vec3) -> RenderSettings {
    RenderSettings {
        background,
        sh_degree: 3,
        composite: CompositeParams::smooth(),
        distortion: false,
        ..RenderSettings::default()
    }
}

pub(crate) fn small_scene(
    n: usize,
    w: u32,
    h: u32,
    ts: usize,
    footprint: f32,
    alpha: (f32, f32),
    seed: u64,
) -> ActivatedBillboards {
    random_scene(&RandomSceneConfig {
        billboards: n,
        width: w,
        height: h,
        texture_size: ts,
        footprint_px: footprint,
        alpha_range: alpha,
        seed,
    })
}

fn max_abs_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max)
}

proptest! {
    #![proptest_config(seeded_config(64))]

    /// The tiled renderer loses no contribution to binning or per-pixel culling: it matches the
    /// brute-force renderer, including billboards much larger than a tile.
    #[test]
    fn tiled_matches_brute_force(
        n in 0usize..40, w in 1u32..70, h in 1u32..70, ts in prop::sample::select(vec![2usize, 3, 4, 16]),
        footprint in 2.0f32..40.0, seed in any::<u64>(), white in any::<bool>(),
    ) {
        let scene = small_scene(n, w, h, ts, footprint, (0.0, 1.0), seed);
        let cam = random_scene_camera(w, h);
        let s = settings(if white { Vec3::ONE } else { Vec3::new(0.1, 0.2, 0.3) });
        let tiled = render(&scene.borrowed(), &cam, &s);
        let reference = render_reference(&scene.borrowed(), &cam, &s);
        // Same operations in the same order per pixel; the only difference is how products like
        // c·α·T associate inside the compositing stage: a few f32 ulps.
        prop_assert!(max_abs_diff(&tiled.rgb, &reference.rgb) < 1e-5, "rgb differs (seed {seed})");
        prop_assert!(max_abs_diff(&tiled.alpha, &reference.alpha) < 1e-5, "alpha differs (seed {seed})");
        prop_assert!(max_abs_diff(&tiled.depth, &reference.depth) < 1e-4, "depth differs (seed {seed})");
        for (a, b) in tiled.impact.iter().zip(&reference.impact) {
            prop_assert!((a - b).abs() <= 1e-5 * (1.0 + b.abs()), "impact {a} vs {b} (seed {seed})");
        }
    }
}

/// Random per-pixel weights for the rgb, alpha and depth maps.
pub(crate) struct WeightedLoss {
    pub rgb: Vec<f64>,
    pub alpha: Vec<f64>,
    pub depth: Vec<f64>,
}

impl WeightedLoss {
    pub(crate) fn new(n_pix: usize, seed: u64) -> Self {
        let depth = random_weights(n_pix, seed + 2).into_iter().map(|w| 0.1 * w).collect();
        Self {
            rgb: random_weights(3 * n_pix, seed),
            alpha: random_weights(n_pix, seed + 1),
            depth,
        }
    }

    fn value(&self, out: &RenderOutput) -> f64 {
        let dot = |a: &[f32], w: &[f64]| a.iter().zip(w).map(|(&x, &y)| x as f64 * y).sum::<f64>();
        dot(&out.rgb, &self.rgb) + dot(&out.alpha, &self.alpha) + dot(&out.depth, &self.depth)
    }

    /// The weights of every output in [`outputs`]' order: rgb, then alpha, then depth.
    pub(crate) fn all(&self) -> Vec<f64> {
        self.rgb.iter().chain(&self.alpha).chain(&self.depth).copied().collect()
    }

    pub(crate) fn f32s(v: &[f64]) -> Vec<f32> {
        v.iter().map(|&x| x as f32).collect()
    }
}

/// Parameter groups of a billboard set, flattened for the checker.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Group {
    Positions,
    LogScales,
    Quaternions,
    Sh,
    Alpha,
    Colour,
}

pub(crate) fn flatten(b: &ActivatedBillboards, g: Group) -> Vec<f32> {
    match g {
        Group::Positions => b.positions.iter().flat_map(|p| p.to_array()).collect(),
        Group::LogScales => b.log_scales.iter().flat_map(|p| p.to_array()).collect(),
        Group::Quaternions => b.quaternions.iter().flatten().copied().collect(),
        Group::Sh => b.sh.clone(),
        Group::Alpha => b.textures.iter().map(|t| t[3]).collect(),
        Group::Colour => b.textures.iter().flat_map(|t| [t[0], t[1], t[2]]).collect(),
    }
}

pub(crate) fn unflatten(b: &mut ActivatedBillboards, g: Group, x: &[f32]) {
    match g {
        Group::Positions => b.positions = x.chunks(3).map(Vec3::from_slice).collect(),
        Group::LogScales => b.log_scales = x.chunks(2).map(Vec2::from_slice).collect(),
        Group::Quaternions => b.quaternions = x.chunks(4).map(|c| [c[0], c[1], c[2], c[3]]).collect(),
        Group::Sh => b.sh = x.to_vec(),
        Group::Alpha => b.textures.iter_mut().zip(x).for_each(|(t, &a)| t[3] = a),
        Group::Colour => b
            .textures
            .iter_mut()
            .zip(x.chunks(3))
            .for_each(|(t, c)| t[..3].copy_from_slice(c)),
    }
}

pub(crate) fn analytic(g: &RenderGradients, group: Group) -> Vec<f64> {
    let v: Vec<f32> = match group {
        Group::Positions => g.positions.iter().flat_map(|p| p.to_array()).collect(),
        Group::LogScales => g.log_scales.iter().flat_map(|p| p.to_array()).collect(),
        Group::Quaternions => g.quaternions.iter().flatten().copied().collect(),
        Group::Sh => g.sh.clone(),
        Group::Alpha => g.textures.iter().map(|t| t[3]).collect(),
        Group::Colour => g.textures.iter().flat_map(|t| [t[0], t[1], t[2]]).collect(),
    };
    v.into_iter().map(f64::from).collect()
}

fn gradients(scene: &ActivatedBillboards, cam: &Camera, s: &RenderSettings, loss: &WeightedLoss) -> RenderGradients {
    masked_backward(scene, &render(&scene.borrowed(), cam, s), &loss.all(), false)
}

/// Checks one parameter group: every element by central differences when the group is small,
/// otherwise 48 sampled elements plus 4 random directions over the whole group. The measured
/// errors are printed (`--nocapture` shows them), then asserted.
fn check_group(
    scene: &ActivatedBillboards,
    cam: &Camera,
    s: &RenderSettings,
    group: Group,
    seed: u64,
    tol: &GradTolerance,
) {
    let report = group_report(scene, cam, s, group, seed, tol, 1.0);
    eprintln!(
        "measure {group:?} seed {seed}: worst_ratio {:.3e} rel_l2 {:.3e} direction_error {:.3e} cosine_gap {:.3e} bias {:.3e}",
        report.elements.worst_ratio,
        report.elements.rel_l2,
        report.worst_direction,
        1.0 - report.elements.cosine,
        report.elements.bias.abs()
    );
    assert!(
        report.passed(),
        "group {group:?}, seed {seed}: {}; worst direction {:.3e}",
        report.elements,
        report.worst_direction
    );
}

/// What [`group_report`] measured: the sampled elements and the worst random direction.
struct GroupReport {
    elements: bbsplat::gradcheck::GradReport,
    /// Worst `|numeric − analytic| / Σ|analytic·direction|` over the directions.
    worst_direction: f64,
}

impl GroupReport {
    fn passed(&self) -> bool {
        self.elements.passed() && self.worst_direction <= DIRECTION_TOLERANCE
    }
}

/// The FD comparison of [`check_group`], with the analytic gradient multiplied by `scale`
/// (1 for the real check; the catch tests pass 1.01).
fn group_report(
    scene: &ActivatedBillboards,
    cam: &Camera,
    s: &RenderSettings,
    group: Group,
    seed: u64,
    tol: &GradTolerance,
    scale: f64,
) -> GroupReport {
    let loss = WeightedLoss::new(cam.pixel_count(), seed);
    let g = gradients(scene, cam, s, &loss);
    let an: Vec<f64> = analytic(&g, group).iter().map(|a| a * scale).collect();
    let x = flatten(scene, group);
    let eval = |p: &[f32]| {
        let mut b = scene.clone();
        unflatten(&mut b, group, p);
        loss.value(&render(&b.borrowed(), cam, s))
    };
    let mut rng = Rng::new(seed ^ 0x5eed);
    let indices: Vec<usize> = if x.len() <= 96 {
        (0..x.len()).collect()
    } else {
        (0..48).map(|_| rng.below(x.len() as u64) as usize).collect()
    };
    // Textures enter the image linearly and SH smoothly: a large step has no truncation error
    // to speak of and keeps the f32 rounding noise small.
    let step = bbsplat::gradcheck::StepRule::absolute(1e-2);
    let numeric = bbsplat::gradcheck::numerical_gradient(eval, &x, &indices, step);
    let picked: Vec<f64> = indices.iter().map(|&i| an[i]).collect();
    let elements = compare(&picked, &numeric, tol);
    let mut worst_direction = 0.0f64;
    for d in 0..4 {
        let dir = random_weights(x.len(), seed * 31 + d);
        let dd = directional_derivative(eval, &x, &dir, step.base);
        let dot: f64 = an.iter().zip(&dir).map(|(a, b)| a * b).sum();
        let size = an.iter().zip(&dir).map(|(a, b)| (a * b).abs()).sum::<f64>().max(1e-12);
        worst_direction = worst_direction.max((dd - dot).abs() / size);
    }
    GroupReport {
        elements,
        worst_direction,
    }
}

/// All output values of a render (rgb, alpha, depth), flattened.
pub(crate) fn outputs(out: &RenderOutput) -> Vec<f32> {
    out.rgb.iter().chain(&out.alpha).chain(&out.depth).copied().collect()
}

/// Whole-image check of a geometric parameter group with a *boundary band*.
///
/// Each pixel value is piecewise smooth in the geometry: its derivative jumps where the pixel
/// centre crosses a texel border or the edge of the texture support. A finite-difference step
/// that straddles such a kink averages two one-sided derivatives, so a handful of pixels can
/// dominate the error of an image-wide sum. For each checked parameter we therefore take
/// per-output central differences at `h` and `h/2`; outputs where the two disagree (by more than
/// f32 noise allows) straddle a kink and form the band. The band is dropped from the weighted
/// loss for that parameter, the analytic gradient of the same masked loss is computed by a
/// backward pass, and the two are compared with tight tolerances. The band must stay a small
/// fraction of the outputs the parameter moves (asserted).
fn check_group_banded(
    scene: &ActivatedBillboards,
    cam: &Camera,
    s: &RenderSettings,
    group: Group,
    seed: u64,
    tol: &GradTolerance,
) {
    let (report, fraction) = banded_report(scene, cam, s, group, seed, tol, 1.0);
    // Measured worst band fraction over 64 seeds: 8 % (TS = 8, billboards of ~14 px).
    assert!(
        fraction < 0.15,
        "group {group:?}, seed {seed}: {:.1} % of the moved outputs straddle kinks",
        100.0 * fraction
    );
    assert!(report.passed(), "group {group:?}, seed {seed}: {report}");
}

/// One parameter's banded central difference (the method of [`check_group_banded`]): `x[i]`
/// moved by ±`h` (rounded to f32, the actual steps used), per-output one-sided differences at
/// +h and −h, and the outputs where they disagree (a kink within [x − h, x + h], including one
/// exactly at x, which h-versus-h/2 comparisons miss) left out: their weights are zeroed when
/// `kinks` is set. Returns the weighted central difference over the other outputs, the masked
/// weights (for the analytic side), the banded count and the count of outputs whose central
/// difference exceeds `moved_above`.
pub(crate) struct BandedStep {
    pub numeric: f64,
    pub masked_weights: Vec<f64>,
    pub banded: usize,
    pub moved: usize,
}

#[allow(clippy::too_many_arguments)]
pub(crate) fn banded_difference(
    x: &[f32],
    i: usize,
    h: f64,
    base_values: &[f32],
    render_at: &dyn Fn(&[f32]) -> Vec<f32>,
    weights: &[f64],
    kinks: bool,
    moved_above: f64,
) -> BandedStep {
    let at = |step: f64| {
        let mut p = x.to_vec();
        p[i] = (x[i] as f64 + step) as f32;
        (render_at(&p), p[i] as f64 - x[i] as f64)
    };
    let ((plus, hp), (minus, hm)) = (at(h), at(-h));
    let difference = |a: &[f32], b: &[f32], d: f64| -> Vec<f64> {
        a.iter().zip(b).map(|(&a, &b)| (a as f64 - b as f64) / d).collect()
    };
    let forward = difference(&plus, base_values, hp);
    let backward = difference(base_values, &minus, -hm);
    let d2 = difference(&plus, &minus, hp - hm);
    let band: Vec<bool> = forward
        .iter()
        .zip(&backward)
        .map(|(a, b)| kinks && (a - b).abs() > 2e-3 * (1.0 + a.abs().max(b.abs())))
        .collect();
    let masked_weights: Vec<f64> = weights
        .iter()
        .zip(&band)
        .map(|(&w, &b)| if b { 0.0 } else { w })
        .collect();
    BandedStep {
        numeric: masked_weights.iter().zip(&d2).map(|(w, d)| w * d).sum::<f64>(),
        masked_weights,
        banded: band.iter().filter(|&&b| b).count(),
        moved: d2.iter().filter(|d| d.abs() > moved_above).count(),
    }
}

/// The backward pass of a [`banded_difference`]'s masked weights (rgb, then alpha, then depth,
/// as [`outputs`] lays them out) from `base`, the render they weigh; with the camera gradient
/// when `camera` is set.
pub(crate) fn masked_backward(
    scene: &ActivatedBillboards,
    base: &RenderOutput,
    masked: &[f64],
    camera: bool,
) -> RenderGradients {
    let n_pix = (base.width * base.height) as usize;
    let to_f32 = |r: std::ops::Range<usize>| masked[r].iter().map(|&w| w as f32).collect::<Vec<f32>>();
    let (rgb, alpha, depth) = (
        to_f32(0..3 * n_pix),
        to_f32(3 * n_pix..4 * n_pix),
        to_f32(4 * n_pix..5 * n_pix),
    );
    let mut g = RenderGradients::zeros(scene.len(), scene.texture_size);
    let ig = ImageGradients {
        rgb: &rgb,
        alpha: Some(&alpha),
        depth: Some(&depth),
        normal: None,
        distortion: None,
        camera,
    };
    render_backward(&scene.borrowed(), base, &ig, &mut g);
    g
}

/// The comparison of [`check_group_banded`] and the band's fraction of the moved outputs, with
/// the analytic gradient multiplied by `scale` (1 for the real check; the catch tests pass 1.01).
fn banded_report(
    scene: &ActivatedBillboards,
    cam: &Camera,
    s: &RenderSettings,
    group: Group,
    seed: u64,
    tol: &GradTolerance,
    scale: f64,
) -> (bbsplat::gradcheck::GradReport, f64) {
    let weights = WeightedLoss::new(cam.pixel_count(), seed).all();
    let x = flatten(scene, group);
    let render_at = |p: &[f32]| {
        let mut b = scene.clone();
        unflatten(&mut b, group, p);
        outputs(&render(&b.borrowed(), cam, s))
    };
    let base = render(&scene.borrowed(), cam, s);
    let h = 1e-3f64;
    let (mut analytic_v, mut numeric_v) = (Vec::new(), Vec::new());
    let (mut banded, mut moved) = (0usize, 0usize);
    let base_values = outputs(&base);
    for i in 0..x.len() {
        let step = banded_difference(&x, i, h, &base_values, &render_at, &weights, true, 1e-6);
        banded += step.banded;
        moved += step.moved;
        numeric_v.push(step.numeric);
        let g = masked_backward(scene, &base, &step.masked_weights, false);
        analytic_v.push(analytic(&g, group)[i] * scale);
    }
    let report = compare(&analytic_v, &numeric_v, tol);
    let fraction = banded as f64 / moved.max(1) as f64;
    eprintln!(
        "measure {group:?} seed {seed}: worst_ratio {:.3e} rel_l2 {:.3e} band {fraction:.4} cosine_gap {:.3e} bias {:.3e}",
        report.worst_ratio,
        report.rel_l2,
        1.0 - report.cosine,
        report.bias.abs()
    );
    (report, fraction)
}

/// Tolerance of the whole-image texture and SH checks ([`check_group`]). Measured over 64 seeds
/// of the alpha, colour and SH groups (`FD_SEEDS=64 cargo test --test suite raster::fd_ --
/// --nocapture`, the `measure` lines): worst relative L2 1.0e-4, worst elementwise ratio 0.043
/// against (atol 2e-3, rtol 2e-2), i.e. about 0.43 against the bounds below, 1 − cos 3.6e-9,
/// |bias| 4.0e-5. Each bound is 10× the worst (the elementwise bounds 2.3×), so a 1 % scale
/// error (relative L2 1e-2) fails: tested per group by `whole_image_checks_catch_a_one_percent_error`.
fn image_tolerance() -> GradTolerance {
    GradTolerance {
        atol: 2e-4,
        rtol: 2e-3,
        max_rel_l2: 1e-3,
        min_cosine: 1.0 - 3.6e-8,
        max_bias: 4e-4,
    }
}

/// Bound on a random direction's `|numeric − analytic| / Σ|analytic·direction|` in
/// [`check_group`]: measured worst 9.3e-6 over the same 64 seeds, bound 10×.
const DIRECTION_TOLERANCE: f64 = 9.3e-5;

pub(crate) fn fd_scene(seed: u64) -> (ActivatedBillboards, Camera) {
    fd_scene_with_footprint(seed, 14.0)
}

/// [`fd_scene`] with billboards about `footprint` pixels wide.
fn fd_scene_with_footprint(seed: u64, footprint: f32) -> (ActivatedBillboards, Camera) {
    fd_scene_sized(seed, footprint, 0)
}

/// [`fd_scene_with_footprint`] with `extra` more pixels in each image side.
fn fd_scene_sized(seed: u64, footprint: f32, extra: u32) -> (ActivatedBillboards, Camera) {
    let mut rng = Rng::new(seed);
    let n = 3 + rng.below(10) as usize;
    let w = extra + 24 + rng.below(24) as u32;
    let h = extra + 24 + rng.below(24) as u32;
    let ts = 8;
    let mut scene = small_scene(n, w, h, ts, footprint, (0.05, 0.9), seed);
    // Smooth textures: a bilinear interpolant has a derivative jump at each texel border equal
    // to the texels' second difference, so random texels make the loss a sum of O(1) kinks that
    // a finite-difference step keeps crossing. A Gaussian bump of alpha (faint at the edges, as
    // the method's initial alpha) and low-frequency colour make those jumps small.
    // Centre depths at least 0.25 apart: the compositing order is a discontinuity when two
    // overlapping billboards swap depth, which a finite-difference step must not cross.
    for (k, p) in scene.positions.iter_mut().enumerate() {
        *p *= (2.0 + 0.25 * k as f32 + rng.range(0.0, 0.05)) / p.z;
    }
    let t = ts * ts;
    for b in 0..n {
        let (cx, cy) = (rng.range(2.5, 4.5), rng.range(2.5, 4.5));
        let peak = rng.range(0.5, 0.9);
        let phase = rng.range(0.0, 6.0);
        for r in 0..ts {
            for c in 0..ts {
                let d2 = (c as f32 - cx).powi(2) + (r as f32 - cy).powi(2);
                let texel = &mut scene.textures[b * t + r * ts + c];
                texel[3] = 0.03 + peak * (-d2 / 8.0).exp();
                for (ch, v) in texel[..3].iter_mut().enumerate() {
                    *v = 0.5 + 0.3 * (0.4 * c as f32 + 0.3 * r as f32 + phase + ch as f32).sin();
                }
            }
        }
    }
    // Well-conditioned orientations: normals within ~40° of the optical axis, so that no
    // billboard is seen nearly edge-on (edge-on has its own hard-case tests). Near edge-on,
    // (u, v) changes so fast with the pixel position that the finite-difference step crosses
    // texel-border kinks and the grazing guard.
    for q in &mut scene.quaternions {
        *q = [
            1.0,
            rng.range(-0.35, 0.35),
            rng.range(-0.35, 0.35),
            rng.range(-1.0, 1.0),
        ];
    }
    (scene, random_scene_camera(w, h))
}

macro_rules! fd_test {
    ($name:ident, $group:expr) => {
        #[test]
        fn $name() {
            let seeds = std::env::var("FD_SEEDS")
                .ok()
                .and_then(|v| v.parse().ok())
                .unwrap_or(6u64);
            for seed in 0..seeds {
                let (scene, cam) = fd_scene(seed);
                check_group(
                    &scene,
                    &cam,
                    &smooth_settings(Vec3::new(0.3, 0.5, 0.7)),
                    $group,
                    seed,
                    &image_tolerance(),
                );
            }
        }
    };
}

macro_rules! fd_banded_test {
    ($name:ident, $group:expr) => {
        #[test]
        fn $name() {
            let seeds = std::env::var("FD_SEEDS")
                .ok()
                .and_then(|v| v.parse().ok())
                .unwrap_or(6u64);
            for seed in 0..seeds {
                let (scene, cam) = fd_scene(seed);
                let s = smooth_settings(Vec3::new(0.3, 0.5, 0.7));
                check_group_banded(&scene, &cam, &s, $group, seed, &geometry_tolerance());
            }
        }
    };
}

/// Tolerance of the banded geometry checks. Measured over 64 seeds × 3 groups
/// (`FD_SEEDS=64 cargo test --test suite raster::fd_ -- --nocapture`): worst relative L2 error
/// 9.8e-4, worst elementwise ratio 0.92 against the bounds below, 1 − cos 4.6e-7, |bias| 3.8e-4.
/// Bounds: relative L2 2e-3 (2×), 1 − cos 4e-6 (8.7×), bias 2e-3 (5.3×). A 1 % scale error
/// (relative L2 1e-2) fails: tested per group by `whole_image_checks_catch_a_one_percent_error`.
fn geometry_tolerance() -> GradTolerance {
    GradTolerance {
        atol: 3e-3,
        rtol: 1.5e-2,
        max_rel_l2: 2e-3,
        min_cosine: 1.0 - 4e-6,
        max_bias: 2e-3,
    }
}

fd_banded_test!(fd_positions, Group::Positions);
fd_banded_test!(fd_log_scales, Group::LogScales);
fd_banded_test!(fd_quaternions, Group::Quaternions);
fd_test!(fd_sh, Group::Sh);
fd_test!(fd_alpha_textures, Group::Alpha);

/// Texture gradients of billboards whose screen box lies inside one tile: the tile pass adds
/// those directly to the gradient rows instead of handing them to the per-billboard reduction
/// (the 14-pixel billboards of the other checks mostly span several tiles). Billboards about
/// 4 pixels wide, at least one per scene inside a single tile on average (checked).
#[test]
fn fd_textures_of_billboards_inside_one_tile() {
    let seeds = std::env::var("FD_SEEDS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(6u64);
    let mut single = 0;
    for seed in 0..seeds {
        let (scene, cam) = fd_scene_with_footprint(seed, 4.0);
        let s = smooth_settings(Vec3::new(0.3, 0.5, 0.7));
        let bins = render(&scene.borrowed(), &cam, &s).state.bins;
        single += bins.billboard_offsets.windows(2).filter(|w| w[1] - w[0] == 1).count();
        for group in [Group::Alpha, Group::Colour] {
            check_group(&scene, &cam, &s, group, seed, &image_tolerance());
        }
    }
    assert!(
        single as u64 >= seeds,
        "only {single} single-tile billboards in {seeds} scenes"
    );
}

fd_test!(fd_colour_textures, Group::Colour);

/// Texture gradients of billboards that span several tiles: the texel lists of their entries
/// after the first go through the per-billboard reduction in tile order (the scenes of the other checks, 24-47
/// pixels a side, lie inside one 48-pixel tile, where every entry is its billboard's first).
/// The images are 60-83 pixels a side, so every one crosses a tile border; at least one
/// billboard per scene on average has several entries (checked). Measured on its 6 seeds
/// (`--nocapture`): worst elementwise ratio 0.089 of `image_tolerance`'s bounds, relative L2
/// 2.6e-5, 1 − cos 3.4e-10, |bias| 4.2e-6. Scaling the reduction's texel-list adds by 1.01 fails
/// this test and no other finite-difference check (tried 2026-11-28).
///
/// The geometry groups are not checked here: on these scenes the banded check's whole-image
/// differences meet too many texel kinks (at a step of 1e-3, 16-22 % of the moved outputs
/// straddle one and a quaternion element misses `geometry_tolerance` by 1.4×; at 3e-4 the f32
/// noise does). The f64 reference checks every group across tiles instead, away from every
/// kink: `f64_reference::gradients::gradients_across_tiles`.
#[test]
fn fd_billboards_across_tiles() {
    let seeds = std::env::var("FD_SEEDS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(6u64);
    let mut spanning = 0;
    for seed in 0..seeds {
        let (scene, cam) = fd_scene_sized(seed, 14.0, bbsplat::raster::TILE_SIZE - 12);
        let s = smooth_settings(Vec3::new(0.3, 0.5, 0.7));
        let bins = render(&scene.borrowed(), &cam, &s).state.bins;
        spanning += bins.billboard_offsets.windows(2).filter(|w| w[1] - w[0] > 1).count();
        for group in [Group::Alpha, Group::Colour] {
            check_group(&scene, &cam, &s, group, seed, &image_tolerance());
        }
    }
    assert!(
        spanning as u64 >= seeds,
        "only {spanning} billboards with several tile entries in {seeds} scenes"
    );
}

#[test]
fn fd_background() {
    for seed in 0..4u64 {
        let (scene, cam) = fd_scene(seed);
        let loss = WeightedLoss::new(cam.pixel_count(), seed);
        let s = smooth_settings(Vec3::new(0.3, 0.5, 0.7));
        let g = gradients(&scene, &cam, &s, &loss);
        for c in 0..3 {
            let eval = |bg: f32| {
                let mut s2 = s;
                s2.background[c] = bg;
                loss.value(&render(&scene.borrowed(), &cam, &s2))
            };
            let h = 1e-2;
            let num = (eval(s.background[c] + h) - eval(s.background[c] - h)) / (2.0 * h as f64);
            let an = g.background[c] as f64;
            assert!(
                (num - an).abs() < 1e-3 * (1.0 + an.abs()),
                "seed {seed} channel {c}: {an} vs {num}"
            );
        }
    }
}

/// Every whole-image check catches a wrong gradient with the tolerance it really uses: the
/// analytic gradient of each group scaled by 1.01 (a 1 % error) fails [`check_group`]'s or
/// [`check_group_banded`]'s comparison on every seed the suite runs.
#[test]
fn whole_image_checks_catch_a_one_percent_error() {
    let s = smooth_settings(Vec3::new(0.3, 0.5, 0.7));
    for seed in 0..6 {
        let (scene, cam) = fd_scene(seed);
        for group in [Group::Alpha, Group::Colour, Group::Sh] {
            let right = group_report(&scene, &cam, &s, group, seed, &image_tolerance(), 1.0);
            assert!(right.passed(), "group {group:?}, seed {seed}: {}", right.elements);
            let wrong = group_report(&scene, &cam, &s, group, seed, &image_tolerance(), 1.01);
            assert!(
                !wrong.passed(),
                "group {group:?}, seed {seed}: a 1 % error passed: {}",
                wrong.elements
            );
        }
        for group in [Group::Positions, Group::LogScales, Group::Quaternions] {
            let (wrong, _) = banded_report(&scene, &cam, &s, group, seed, &geometry_tolerance(), 1.01);
            assert!(
                !wrong.passed(),
                "group {group:?}, seed {seed}: a 1 % error passed: {wrong}"
            );
        }
    }
}

fn culled_billboards(ts: usize, seed: u64) -> ActivatedBillboards {
    let mut extra = small_scene(6, 32, 32, ts, 8.0, (0.2, 0.8), seed);
    extra.positions[0].z = -3.0; // behind the camera
    extra.positions[1].z = 0.1; // in front of the camera but before the near plane
    extra.positions[2] = Vec3::new(500.0, 0.0, 4.0); // far off screen
    extra.positions[3] = Vec3::new(0.0, -80.0, 4.0); // off screen
    let t = ts * ts;
    extra.textures[4 * t..6 * t].iter_mut().for_each(|x| x[3] = 0.0); // fully transparent, on screen
    extra
}

#[test]
fn culled_billboards_change_no_bit() {
    let scene = small_scene(20, 40, 36, 16, 10.0, (0.0, 1.0), 11);
    let cam = random_scene_camera(40, 36);
    let s = settings(Vec3::new(0.2, 0.4, 0.6));
    let base = render(&scene.borrowed(), &cam, &s);
    let extra = culled_billboards(16, 12);
    for combined in [scene.concat(&extra), extra.concat(&scene)] {
        let out = render(&combined.borrowed(), &cam, &s);
        assert_eq!(out.rgb, base.rgb);
        assert_eq!(out.alpha, base.alpha);
        assert_eq!(out.depth, base.depth);
    }
}

#[test]
fn hidden_billboard_gets_exactly_zero_gradient() {
    let ts = 8;
    let t = ts * ts;
    let cam = random_scene_camera(32, 32);
    let mut scene = ActivatedBillboards::empty(ts);
    // Three large opaque walls facing the camera, then a small billboard behind them.
    for (k, z) in [2.0f32, 2.5, 3.0].into_iter().enumerate() {
        scene.positions.push(Vec3::new(0.0, 0.0, z));
        scene.quaternions.push([1.0, 0.0, 0.0, 0.0]);
        scene.log_scales.push(Vec2::splat(z.ln())); // far larger than the view
        scene.sh.extend(std::iter::repeat_n(0.1 * k as f32, 48));
        scene.textures.extend(std::iter::repeat_n([0.5, 0.5, 0.5, 1.0], t));
    }
    scene.positions.push(Vec3::new(0.1, 0.0, 5.0));
    scene.quaternions.push([0.9, 0.1, 0.2, 0.0]);
    scene.log_scales.push(Vec2::splat(-1.0));
    scene.sh.extend(std::iter::repeat_n(0.3, 48));
    scene.textures.extend(std::iter::repeat_n([0.4, 0.4, 0.4, 0.7], t));
    let s = settings(Vec3::ONE);
    let loss = WeightedLoss::new(cam.pixel_count(), 5);
    let g = gradients(&scene, &cam, &s, &loss);
    let out = render(&scene.borrowed(), &cam, &s);
    assert!(out.visible[3], "the hidden billboard is on screen");
    assert_eq!(out.impact[3], 0.0);
    assert_eq!(g.positions[3], Vec3::ZERO);
    assert_eq!(g.quaternions[3], [0.0; 4]);
    assert_eq!(g.log_scales[3], Vec2::ZERO);
    assert!(g.sh[3 * 48..4 * 48].iter().all(|&x| x == 0.0));
    assert!(g.textures[3 * t..].iter().flatten().all(|&x| x == 0.0));
    assert!(g.positions[0].length() > 0.0, "the front wall does receive gradient");
}

fn render_and_backward(
    scene: &ActivatedBillboards,
    cam: &Camera,
    s: &RenderSettings,
) -> (RenderOutput, RenderGradients, Vec<u32>) {
    let out = render(&scene.borrowed(), cam, s);
    let (g, touched) = backward_of(scene, cam, &out);
    (out, g, touched)
}

/// The backward pass of `out` under the fixed random per-pixel weighted loss (seed 77) on rgb
/// and alpha: the gradients and the touched billboards.
fn backward_of(scene: &ActivatedBillboards, cam: &Camera, out: &RenderOutput) -> (RenderGradients, Vec<u32>) {
    let mut g = RenderGradients::zeros(scene.len(), scene.texture_size);
    let touched = add_weighted_backward(scene, cam, out, 77, &mut g);
    (g, touched)
}

/// Adds into `g` the backward pass of `out` under the random per-pixel weighted loss of `seed`
/// on rgb and alpha, the camera gradient included; returns the touched billboards.
fn add_weighted_backward(
    scene: &ActivatedBillboards,
    cam: &Camera,
    out: &RenderOutput,
    seed: u64,
    g: &mut RenderGradients,
) -> Vec<u32> {
    let loss = WeightedLoss::new(cam.pixel_count(), seed);
    let (rgb, alpha) = (WeightedLoss::f32s(&loss.rgb), WeightedLoss::f32s(&loss.alpha));
    let ig = ImageGradients {
        rgb: &rgb,
        alpha: Some(&alpha),
        depth: None,
        normal: None,
        distortion: None,
        camera: true,
    };
    render_backward(&scene.borrowed(), out, &ig, g)
}

/// `f` run in a rayon pool of `threads` threads.
fn with_threads<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}

#[test]
fn bit_identical_across_runs_and_thread_counts() {
    // Enough tiles (5 × 4) that 2 and 8 threads each get several, handed out by weight.
    let (w, h) = (240u32, 180u32);
    let (tiles_x, tiles_y) = (
        w.div_ceil(bbsplat::raster::TILE_SIZE),
        h.div_ceil(bbsplat::raster::TILE_SIZE),
    );
    assert!(tiles_x * tiles_y >= 16, "{tiles_x} × {tiles_y} tiles");
    let scene = small_scene(2400, w, h, 16, 12.0, (0.0, 1.0), 21);
    let cam = random_scene_camera(w, h);
    let s = settings(Vec3::splat(0.5));
    let run = |threads: usize| with_threads(threads, || render_and_backward(&scene, &cam, &s));
    let (o1, g1, t1) = run(1);
    // The camera gradient is summed over two chunks of billboards (400 > 256): covered too.
    assert!(g1.camera.rotation.length() > 0.0 && g1.camera.translation.length() > 0.0);
    for threads in [1, 2, 8] {
        let (o, g, t) = run(threads);
        assert_eq!(o.rgb, o1.rgb, "{threads} threads");
        assert_eq!(o.impact, o1.impact, "{threads} threads");
        assert_eq!(g, g1, "{threads} threads");
        assert_eq!(t, t1, "{threads} threads");
    }
}

/// Two views accumulated into one gradient buffer (`render_backward` adds): bit-identical for
/// 1, 2 and 8 threads, and equal to the two views' separate gradients summed up to rounding.
/// The billboards are about 4 pixels wide, so most have a single tile entry and their texture
/// rows receive the second view's contributions one at a time on top of the first view's
/// (the tile pass writes each billboard's first entry directly); the other entries go through
/// the per-billboard reduction.
/// The texture gradients differ from the separate sums by at most 5.4e-8 of the largest
/// `|g₁| + |g₂|` (measured, seed 31); the bound is 1e-6. The SH gradients, summed per view by
/// the reduction, equal the separate sums exactly. A tile pass that overwrote the rows instead
/// of adding fails it by 0.8.
#[test]
fn two_views_accumulate_deterministically() {
    let scene = small_scene(400, 96, 80, 8, 4.0, (0.3, 0.9), 31);
    let cam1 = random_scene_camera(96, 80);
    let cam2 = Camera {
        translation: cam1.translation + Vec3::new(0.07, -0.04, 0.1),
        ..cam1
    };
    let s = settings(Vec3::splat(0.5));
    let bins = render(&scene.borrowed(), &cam1, &s).state.bins;
    let single = bins.billboard_offsets.windows(2).filter(|w| w[1] - w[0] == 1).count();
    let multi = bins.billboard_offsets.windows(2).filter(|w| w[1] - w[0] > 1).count();
    assert!(
        single > 100 && multi > 5,
        "{single} single-entry, {multi} multi-entry billboards"
    );
    // Both views into one buffer (`cams`), or each into its own.
    let backward = |cams: &[&Camera]| {
        let mut g = RenderGradients::zeros(scene.len(), scene.texture_size);
        for &cam in cams {
            add_weighted_backward(&scene, cam, &render(&scene.borrowed(), cam, &s), 5, &mut g);
        }
        g
    };
    let g1 = with_threads(1, || backward(&[&cam1, &cam2]));
    for threads in [2, 8] {
        assert_eq!(
            with_threads(threads, || backward(&[&cam1, &cam2])),
            g1,
            "{threads} threads"
        );
    }
    let separate = [backward(&[&cam1]), backward(&[&cam2])];
    let mut worst = 0.0f32;
    let mut scale = 0.0f32;
    for ((a, x), y) in g1.textures.iter().zip(&separate[0].textures).zip(&separate[1].textures) {
        for c in 0..4 {
            worst = worst.max((a[c] - (x[c] + y[c])).abs());
            scale = scale.max(x[c].abs() + y[c].abs());
        }
    }
    assert!(
        scale > 0.0 && worst <= 1e-6 * scale,
        "texture gradients: {worst:e} off at scale {scale:e}"
    );
    // The SH gradients go through the per-billboard reduction, which adds each view's sum to
    // the row: `(0 + x) + y`, exactly `x + y`.
    for ((a, x), y) in g1.sh.iter().zip(&separate[0].sh).zip(&separate[1].sh) {
        assert_eq!(*a, x + y, "sh");
    }
}

/// The texture gradients are summed per billboard over its entries, each entry's sum in pixel
/// order: first the entry with the most blended pairs (the first of them in tile order on a
/// tie), whose tile writes the billboard's row, then the others in tile order. Every texel of
/// every billboard equals, bit for bit, `((0 + s_owner) + s₁) + …` with the other tiles in
/// order, where `sₜ` is what the backward gives when only tile `t`'s pixels have an upstream
/// gradient (the other tiles then add exact zeros, and a sum that starts at +0 is never −0, so
/// adding them changes no bit). The owner is found here from the forward's pairs
/// (`TileBlended::pairs_by_pixel`), independently of the backward's own count. Owning by the
/// first entry in tile order instead, the rule before, fails this (tried; 56 of the scene's
/// billboards are owned by a later entry). The tie rule is not exercised: the scene has no
/// billboard whose most-blended entries tie, and for two entries the order of the two sums
/// changes no bit anyway (`a + b = b + a`).
#[test]
fn texture_gradients_sum_each_billboards_owner_then_other_entries_in_tile_order() {
    let (w, h) = (96, 80);
    let scene = small_scene(300, w, h, 8, 14.0, (0.3, 0.9), 41);
    let cam = random_scene_camera(w, h);
    let out = render(&scene.borrowed(), &cam, &settings(Vec3::splat(0.5)));
    let bins = &out.state.bins;
    let multi = bins.billboard_offsets.windows(2).filter(|w| w[1] - w[0] > 1).count();
    assert!(multi > 50, "{multi} billboards with several tile entries");
    // Each entry's blended pairs, and each billboard's owning entry.
    let mut entry_pairs = vec![0usize; bins.entries.len()];
    for t in 0..bins.tile_count() {
        for (_, slot, _) in out.state.tiles[t].pairs_by_pixel() {
            entry_pairs[bins.tile_range(t).start + slot as usize] += 1;
        }
    }
    let entries_of =
        |b: usize| &bins.billboard_entries[bins.billboard_offsets[b] as usize..bins.billboard_offsets[b + 1] as usize];
    let owner_tile: Vec<Option<usize>> = (0..scene.len())
        .map(|b| {
            let mut best: Option<(usize, u32)> = None;
            for &e in entries_of(b) {
                if best.is_none_or(|(most, _)| entry_pairs[e as usize] > most) {
                    best = Some((entry_pairs[e as usize], e));
                }
            }
            // The tile holding the owning entry.
            best.map(|(_, e)| {
                (0..bins.tile_count())
                    .find(|&t| bins.tile_range(t).contains(&(e as usize)))
                    .unwrap()
            })
        })
        .collect();
    // Billboards whose owner is not their first entry in tile order: the rule shows on them.
    let moved = (0..scene.len())
        .filter(|&b| {
            let first = entries_of(b).first().copied();
            first.is_some_and(|e| !bins.tile_range(owner_tile[b].unwrap()).contains(&(e as usize)))
        })
        .count();
    assert!(moved > 10, "{moved} billboards owned by an entry after their first");
    let d_rgb: Vec<f32> = (0..3 * cam.pixel_count())
        .map(|i| ((i as u64 * 2_654_435_761) % 1999) as f32 / 1999.0 - 0.5)
        .collect();
    let backward = |d_rgb: &[f32]| {
        let mut g = RenderGradients::zeros(scene.len(), scene.texture_size);
        let ig = ImageGradients::colour(d_rgb);
        render_backward(&scene.borrowed(), &out, &ig, &mut g);
        g.textures
    };
    let whole = backward(&d_rgb);
    // Per tile: the gradients when only its pixels have an upstream gradient.
    let tile = bbsplat::raster::TILE_SIZE;
    let per_tile: Vec<Vec<[f32; 4]>> = (0..bins.tile_count() as u32)
        .map(|t| {
            let (tx, ty) = (t % bins.tiles_x, t / bins.tiles_x);
            let mut masked = vec![0.0f32; d_rgb.len()];
            for j in ty * tile..((ty + 1) * tile).min(h) {
                for i in tx * tile..((tx + 1) * tile).min(w) {
                    let p = 3 * (j * w + i) as usize;
                    masked[p..p + 3].copy_from_slice(&d_rgb[p..p + 3]);
                }
            }
            backward(&masked)
        })
        .collect();
    let texels = scene.texture_size * scene.texture_size;
    let mut expected = vec![[0.0f32; 4]; whole.len()];
    for (b, owner) in owner_tile.iter().enumerate() {
        // The owner's tile first, then the others in tile order.
        let order = owner
            .iter()
            .copied()
            .chain((0..bins.tile_count()).filter(|t| Some(*t) != *owner));
        for t in order {
            for (e, s) in expected[b * texels..(b + 1) * texels]
                .iter_mut()
                .zip(&per_tile[t][b * texels..(b + 1) * texels])
            {
                for c in 0..4 {
                    e[c] += s[c];
                }
            }
        }
    }
    let bits = |g: &[[f32; 4]]| g.iter().flat_map(|t| t.map(f32::to_bits)).collect::<Vec<_>>();
    let differing = bits(&whole)
        .iter()
        .zip(bits(&expected))
        .filter(|(a, b)| *a != b)
        .count();
    assert_eq!(
        differing, 0,
        "{differing} texture-gradient values differ from the owner-first sum"
    );
    assert!(whole.iter().any(|t| t.iter().any(|&x| x != 0.0)));
}

/// Every value a render reports (images, impact, visibility, counters), as bits.
fn render_bits(out: &RenderOutput) -> Vec<u32> {
    let images = [
        &out.rgb,
        &out.alpha,
        &out.depth,
        &out.median_depth,
        &out.normal,
        &out.impact,
    ];
    let mut bits: Vec<u32> = images.iter().flat_map(|v| v.iter().map(|x| x.to_bits())).collect();
    bits.extend(out.visible.iter().map(|&v| u32::from(v)));
    let stats = out.stats;
    bits.extend([stats.tile_entries, stats.evaluated_pairs, stats.blended_pairs].map(|x| x as u32));
    bits
}

/// `render_with` on storage recycled from renders of other scenes (more and fewer billboards,
/// larger and smaller images, other texture sizes) gives the same bits as a fresh `render`, and
/// so does the backward pass that reads its state.
#[test]
fn recycled_buffers_change_no_bit() {
    let cases = [
        (400usize, 96u32, 80u32, 16usize, 12.0f32, 21u64),
        (30, 33, 17, 8, 6.0, 22),
        (900, 130, 64, 4, 9.0, 23),
        (0, 20, 20, 16, 4.0, 24),
        (250, 48, 48, 16, 20.0, 25),
        (400, 96, 80, 16, 12.0, 21),
    ];
    let mut buffers = RenderBuffers::default();
    for (n, w, h, ts, footprint, seed) in cases {
        let scene = small_scene(n, w, h, ts, footprint, (0.0, 1.0), seed);
        let cam = random_scene_camera(w, h);
        let s = settings(Vec3::splat(0.25));
        let (fresh, g_fresh, t_fresh) = render_and_backward(&scene, &cam, &s);
        let recycled = render_with(&scene.borrowed(), &cam, &s, buffers);
        assert_eq!(render_bits(&recycled), render_bits(&fresh), "case seed {seed}");
        assert_eq!(
            backward_of(&scene, &cam, &recycled),
            (g_fresh, t_fresh),
            "case seed {seed}"
        );
        buffers = recycled.into_buffers();
    }
}

fn assert_finite(out: &RenderOutput, g: &RenderGradients) {
    assert!(
        out.rgb
            .iter()
            .chain(&out.alpha)
            .chain(&out.depth)
            .chain(&out.impact)
            .all(|x| x.is_finite())
    );
    assert!(g.positions.iter().all(|p| p.is_finite()));
    assert!(g.log_scales.iter().all(|p| p.is_finite()));
    assert!(g.quaternions.iter().flatten().all(|p| p.is_finite()));
    assert!(g.sh.iter().chain(g.textures.iter().flatten()).all(|x| x.is_finite()));
    assert!(g.background.is_finite());
}

fn one_billboard(position: Vec3, quaternion: [f32; 4], log_scale: f32, ts: usize) -> ActivatedBillboards {
    let mut b = small_scene(1, 8, 8, ts, 4.0, (0.3, 0.9), 1);
    b.positions[0] = position;
    b.quaternions[0] = quaternion;
    b.log_scales[0] = Vec2::splat(log_scale);
    b
}

fn hard_case(scene: &ActivatedBillboards, w: u32, h: u32) -> (RenderOutput, RenderGradients) {
    let cam = random_scene_camera(w, h);
    let (out, g, _) = render_and_backward(scene, &cam, &settings(Vec3::splat(0.5)));
    assert_finite(&out, &g);
    (out, g)
}

#[test]
fn hard_case_crossing_the_near_plane() {
    // Billboard tilted by 60° about x, centre 0.5 in front of the camera, half side e ≈ 2.7: it
    // reaches from behind the camera to far in front of it.
    let (c, s) = (30f32.to_radians().cos(), 30f32.to_radians().sin());
    let scene = one_billboard(Vec3::new(0.0, 0.0, 0.5), [c, s, 0.0, 0.0], 1.0, 16);
    let (out, _) = hard_case(&scene, 32, 32);
    assert!(out.alpha.iter().any(|&a| a > 0.0), "the visible part is drawn");
}

#[test]
fn hard_case_edge_on() {
    // Normal perpendicular to the viewing ray through the centre.
    let s = std::f32::consts::FRAC_1_SQRT_2;
    let scene = one_billboard(Vec3::new(0.0, 0.0, 4.0), [s, 0.0, s, 0.0], -1.0, 16);
    hard_case(&scene, 32, 32);
    let nearly = one_billboard(Vec3::new(0.0, 0.0, 4.0), [s, 0.0, s + 1e-4, 0.0], -1.0, 16);
    hard_case(&nearly, 32, 32);
}

#[test]
fn hard_case_covering_the_whole_screen() {
    let scene = one_billboard(Vec3::new(0.0, 0.0, 3.0), [1.0, 0.0, 0.0, 0.0], 3.0, 16);
    let (out, _) = hard_case(&scene, 40, 30);
    assert!(out.alpha.iter().all(|&a| a > 0.0));
}

#[test]
fn hard_case_smaller_than_a_pixel() {
    let scene = one_billboard(Vec3::new(0.01, 0.02, 4.0), [0.9, 0.1, 0.3, 0.2], -6.0, 16);
    hard_case(&scene, 32, 32);
}

#[test]
fn hard_case_far_away() {
    let scene = one_billboard(Vec3::new(10.0, -5.0, 1.0e4), [0.9, 0.1, 0.3, 0.2], 7.0, 16);
    let (out, _) = hard_case(&scene, 32, 32);
    assert!(out.alpha.iter().any(|&a| a > 0.0));
}

#[test]
fn hard_case_camera_in_the_billboard_plane() {
    // Billboard plane x = 0 contains the camera centre (the origin).
    let s = std::f32::consts::FRAC_1_SQRT_2;
    let scene = one_billboard(Vec3::new(0.0, 0.0, 4.0), [s, 0.0, s, 0.0], 0.5, 16);
    hard_case(&scene, 32, 32);
}

#[test]
fn hard_case_texture_sizes_2_and_64() {
    for ts in [2, 64] {
        let scene = small_scene(10, 40, 40, ts, 15.0, (0.0, 1.0), 3);
        hard_case(&scene, 40, 40);
    }
}

#[test]
fn hard_case_tiny_and_non_square_images() {
    for (w, h) in [(1, 1), (1, 37), (53, 2), (17, 33)] {
        let scene = small_scene(15, w, h, 8, 6.0, (0.0, 1.0), 4);
        hard_case(&scene, w, h);
    }
}

#[test]
fn hard_case_empty_scene() {
    let scene = ActivatedBillboards::empty(16);
    let (out, g) = hard_case(&scene, 20, 10);
    assert!(out.rgb.iter().all(|&c| c == 0.5));
    // Every pixel sees the background: its gradient is the sum of the rgb weights.
    let loss = WeightedLoss::new(200, 77);
    let expect: f64 = loss.rgb.iter().step_by(3).sum();
    assert!((g.background.x as f64 - expect).abs() < 1e-3);
}

/// `render_backward` reports every row it wrote: clearing exactly those rows restores zeros
/// (the trainer relies on this to avoid re-zeroing the whole buffer each step).
#[test]
fn clearing_the_reported_rows_restores_zero_gradients() {
    // Culled and fully transparent billboards receive nothing and must not be reported.
    let scene = small_scene(300, 64, 48, 8, 10.0, (0.0, 1.0), 8).concat(&culled_billboards(8, 9));
    let cam = random_scene_camera(64, 48);
    let (_, mut g, touched) = render_and_backward(&scene, &cam, &settings(Vec3::splat(0.5)));
    assert!(
        !touched.is_empty() && touched.len() < scene.len(),
        "some but not all billboards are seen"
    );
    for &b in &touched {
        g.clear_row(b as usize);
    }
    g.background = Vec3::ZERO;
    g.camera = Default::default();
    assert_eq!(g, RenderGradients::zeros(scene.len(), scene.texture_size));
}

/// The tile pass writes the texture gradients of each billboard's first entry in place, which is
/// only race-free while the tiles' entry ranges partition the entries: a forward output whose
/// (public) bins were altered so that two tiles share entries is refused with a clear panic
/// before any tile runs.
#[test]
#[should_panic(expected = "the tiles' entry ranges must partition the entries in order")]
fn backward_refuses_overlapping_tile_ranges() {
    let scene = small_scene(200, 64, 48, 8, 10.0, (0.2, 0.9), 3);
    let cam = random_scene_camera(64, 48);
    let mut out = render(&scene.borrowed(), &cam, &settings(Vec3::ZERO));
    let offsets = &mut out.state.bins.tile_offsets;
    assert!(offsets[2] > 0, "the scene puts entries in the first tiles");
    offsets[1] = offsets[2]; // tile 0 now overlaps tile 1's entries
    offsets[2] = 0;
    let d_rgb = vec![1e-3f32; 3 * cam.pixel_count()];
    let mut g = RenderGradients::zeros(scene.len(), scene.texture_size);
    let grads_in = ImageGradients::colour(&d_rgb);
    render_backward(&scene.borrowed(), &out, &grads_in, &mut g);
}

/// Texture-gradient rows that do not match the billboard set (here sized for 4×4 textures
/// while the set has 8×8) are refused before the tile pass writes any row in place.
#[test]
#[should_panic(expected = "gradient buffers must match the billboard set")]
fn backward_refuses_texture_gradients_of_another_size() {
    let scene = small_scene(200, 64, 48, 8, 10.0, (0.2, 0.9), 3);
    let cam = random_scene_camera(64, 48);
    let out = render(&scene.borrowed(), &cam, &settings(Vec3::ZERO));
    let mut g = RenderGradients::zeros(scene.len(), 4);
    add_weighted_backward(&scene, &cam, &out, 1, &mut g);
}

/// Non-finite parameters never render as plausible values: a billboard with a NaN or infinite
/// position, log-scale or quaternion component is culled and counted in
/// `RenderStats::non_finite_billboards` (a NaN quaternion used to get the identity rotation of
/// degenerate quaternions and render as an ordinary billboard); NaN SH coefficients or colour
/// texels make the covered pixels NaN; NaN alpha texels are skipped, as the compositing stage
/// skips NaN alphas (the rasterizer's old inline clamp turned them into 0.99), and counted in
/// `RenderStats::nan_alpha_pairs`.
#[test]
fn non_finite_parameters_never_render_as_plausible_values() {
    let scene = small_scene(12, 32, 32, 8, 10.0, (0.3, 0.8), 5);
    let cam = random_scene_camera(32, 32);
    let s = settings(Vec3::splat(0.2));
    let clean = render(&scene.borrowed(), &cam, &s);
    assert_eq!((clean.stats.non_finite_billboards, clean.stats.nan_alpha_pairs), (0, 0));
    assert!(clean.rgb.iter().all(|x| x.is_finite()));
    // The billboard with the largest impact: certainly on screen.
    let b = (0..scene.len())
        .max_by(|&i, &j| clean.impact[i].total_cmp(&clean.impact[j]))
        .unwrap();
    assert!(clean.impact[b] > 1.0);
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        type Edit = Box<dyn Fn(&mut ActivatedBillboards)>;
        let edits: [(&str, Edit); 3] = [
            (
                "position",
                Box::new(move |m: &mut ActivatedBillboards| m.positions[b].y = bad),
            ),
            (
                "log-scale",
                Box::new(move |m: &mut ActivatedBillboards| m.log_scales[b].x = bad),
            ),
            (
                "quaternion",
                Box::new(move |m: &mut ActivatedBillboards| m.quaternions[b][2] = bad),
            ),
        ];
        for (what, edit) in &edits {
            let mut m = scene.clone();
            edit(&mut m);
            let out = render(&m.borrowed(), &cam, &s);
            assert_eq!(out.stats.non_finite_billboards, 1, "{what} = {bad}");
            assert!(!out.visible[b] && out.impact[b] == 0.0, "{what} = {bad}");
            assert!(out.rgb.iter().all(|x| x.is_finite()), "{what} = {bad}");
        }
    }
    // A billboard past the last group of four of a preprocess chunk (the scalar path).
    let mut odd = small_scene(13, 32, 32, 8, 10.0, (0.3, 0.8), 5);
    odd.quaternions[12][0] = f32::NAN;
    odd.positions[3].x = f32::INFINITY;
    assert_eq!(render(&odd.borrowed(), &cam, &s).stats.non_finite_billboards, 2);
    let t = scene.texture_size * scene.texture_size;
    let mut m = scene.clone();
    m.sh[b * 48] = f32::NAN;
    assert!(render(&m.borrowed(), &cam, &s).rgb.iter().any(|x| x.is_nan()), "NaN SH");
    let mut m = scene.clone();
    m.textures[b * t..(b + 1) * t].iter_mut().for_each(|x| x[0] = f32::NAN);
    assert!(
        render(&m.borrowed(), &cam, &s).rgb.iter().any(|x| x.is_nan()),
        "NaN colour texels"
    );
    let mut m = scene.clone();
    m.textures[b * t..(b + 1) * t].iter_mut().for_each(|x| x[3] = f32::NAN);
    let out = render(&m.borrowed(), &cam, &s);
    assert!(
        out.stats.nan_alpha_pairs > 0 && out.impact[b] == 0.0,
        "NaN alpha texels"
    );
    assert!(out.rgb.iter().all(|x| x.is_finite()));
    // The backward of a render with skipped NaN alphas gives the billboard no gradient.
    let mut g = RenderGradients::zeros(m.len(), m.texture_size);
    let d_rgb = vec![1.0; out.rgb.len()];
    let touched = render_backward(&m.borrowed(), &out, &ImageGradients::colour(&d_rgb), &mut g);
    assert!(!touched.contains(&(b as u32)));
    assert!(g.textures.iter().flatten().all(|x| x.is_finite()));
}
