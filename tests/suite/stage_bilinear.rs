//! Bilinear texture sampling: forward invariants, the VJP against finite differences, the
//! one-sided convention at texel borders, non-finite coordinates, and broken backwards that the
//! checker must reject (including the paper's Algorithm 1 as printed).
//!
//! Tolerance measurement: `cargo test --test suite stage_bilinear:: -- --ignored --nocapture` runs the
//! property's case generator over many seeds and prints the worst observed statistics.

use bbsplat::gradcheck::{GradReport, GradTolerance, StepRule, check_vjp, random_weights};
use bbsplat::stages::bilinear::{self, taps};
use bbsplat::strategies;
use glam::Vec2;
use proptest::prelude::*;
use proptest::strategy::ValueTree;
use proptest::test_runner::{RngSeed, TestRunner};

/// Tolerance of the bilinear VJP check (step [`STEP`]).
///
/// Measured with `measure_tolerances` over 32 seeds × 256 cases (8 192 cases) against the
/// probe `atol = 1e-5, rtol = 1e-4`: worst elementwise ratio 1.18 (worst |a − n| = 1.8e-5),
/// worst rel. L2 3.3e-5, worst 1 − cos 4.1e-10, worst |bias| 2.3e-5. Chosen: 4× the worst
/// (elementwise: the probe × 4.7), so a 1 % scale error (rel. L2 = bias = 1e-2) is 75× over
/// the L2 bound.
const BILINEAR_TOL: GradTolerance = GradTolerance {
    atol: 4.7e-5,
    rtol: 4.7e-4,
    max_rel_l2: 1.33e-4,
    min_cosine: 1.0 - 1.7e-9,
    max_bias: 9.4e-5,
};

/// Finite-difference step `5e-3·max(1, |x|)`. The sample is linear in the texels and, inside
/// one cell, linear along u (and along v), so central differences have no truncation error as
/// long as both evaluation points stay in the cell: the coordinates are at least 0.2 texel from
/// every border and the step is at most 5e-3·1.04·63/2 = 0.16 texel (ts = 64). A step 5× the
/// default divides the f32 rounding noise of the sample by 5 (worst elementwise ratio 0.84
/// instead of 5.7 against the probe, over 2048 cases).
const STEP: StepRule = StepRule {
    base: 5e-3,
    relative: true,
};

/// Minimum distance of the property's coordinates from texel borders, in texels.
const MARGIN: f32 = 0.2;

const SIZES: [usize; 5] = [2, 3, 4, 16, 64];

/// One property case: texture size, channels, coordinates, texels, weight seed.
#[derive(Clone, Debug)]
struct Case {
    ts: usize,
    channels: usize,
    uv: Vec2,
    texels: Vec<f32>,
    seed: u64,
}

/// Coordinates off texel borders: mostly inside the square, a quarter in the fade band too.
fn case() -> impl Strategy<Value = Case> {
    (
        prop::sample::select(SIZES.to_vec()),
        prop::sample::select(vec![1usize, 3]),
    )
        .prop_flat_map(|(ts, channels)| {
            let uv = prop_oneof![
                3 => strategies::uv_off_texel_borders(ts, MARGIN),
                1 => strategies::uv_in_support_off_texel_borders(ts, MARGIN),
            ];
            (uv, strategies::texture(ts, channels), any::<u64>()).prop_map(move |(uv, texels, seed)| Case {
                ts,
                channels,
                uv,
                texels,
                seed,
            })
        })
}

/// A texture size from [`SIZES`] and a texture of that size.
fn sized_texture(channels: usize) -> impl Strategy<Value = (usize, Vec<f32>)> {
    prop::sample::select(SIZES.to_vec()).prop_flat_map(move |ts| (Just(ts), strategies::texture(ts, channels)))
}

fn inputs(c: &Case) -> Vec<f32> {
    let mut x = vec![c.uv.x, c.uv.y];
    x.extend_from_slice(&c.texels);
    x
}

fn forward(ts: usize, channels: usize) -> impl Fn(&[f32]) -> Vec<f32> {
    move |x: &[f32]| {
        let mut out = vec![0.0; channels];
        bilinear::sample(&x[2..], ts, channels, x[0], x[1], &mut out);
        out
    }
}

fn vjp(ts: usize, channels: usize) -> impl Fn(&[f32], &[f32]) -> Vec<f32> {
    move |x: &[f32], w: &[f32]| {
        let mut g = vec![0.0; x.len()];
        let (du, dv) = bilinear::sample_vjp(&x[2..], ts, channels, x[0], x[1], w, &mut g[2..]);
        g[0] = du;
        g[1] = dv;
        g
    }
}

fn check_with<B: Fn(&[f32], &[f32]) -> Vec<f32>>(c: &Case, backward: B, tol: &GradTolerance) -> GradReport {
    check_vjp(&inputs(c), forward(c.ts, c.channels), backward, c.seed, STEP, tol)
}

fn check(c: &Case) -> GradReport {
    check_with(c, vjp(c.ts, c.channels), &BILINEAR_TOL)
}

proptest! {
    #![proptest_config(strategies::seeded_config(256))]

    /// The VJP (texels and (u, v)) matches central differences of a random weighted loss.
    #[test]
    fn vjp_matches_finite_differences(c in case()) {
        let r = check(&c);
        prop_assert!(r.passed(), "ts {} channels {} uv {:?}: {r}", c.ts, c.channels, c.uv);
    }

    /// Partition of unity: for |u|, |v| ≤ 1 (borders included) the weights sum to 1.
    #[test]
    fn weights_sum_to_one_inside_the_square(
        ts in prop::sample::select(SIZES.to_vec()),
        u in -1.0f32..=1.0,
        v in -1.0f32..=1.0,
    ) {
        for (u, v) in [(u, v), (u, 1.0), (-1.0, v), (1.0, 1.0), (-1.0, -1.0)] {
            let t = taps(u, v, ts).expect("inside the square there are taps");
            let sum: f32 = t.weights().iter().sum();
            prop_assert!((sum - 1.0).abs() <= 1e-6, "ts {ts} ({u}, {v}): Σw = {sum}");
            prop_assert!(t.weights().iter().all(|&w| (0.0..=1.0).contains(&w)));
            // Strictly inside, the weight derivatives of a partition of unity sum to 0 (at u = 1
            // the right derivative is that of the fade-out, so not there).
            if u.abs() < 1.0 && v.abs() < 1.0 {
                let su: f32 = t.weight_derivatives_u().iter().sum();
                let sv: f32 = t.weight_derivatives_v().iter().sum();
                prop_assert!(su.abs() <= 1e-5 * ts as f32 && sv.abs() <= 1e-5 * ts as f32, "{su} {sv}");
            }
        }
    }

    /// Zero padding: the value is exactly 0 for |u| or |v| ≥ 1 + 2/(ts − 1), and the gradient is
    /// exactly 0 beyond it (at u = −(1 + 2/(ts − 1)) itself the right derivative is that of the
    /// fade-in ramp, see `left_edge_of_support_has_the_ramp_derivative`).
    #[test]
    fn zero_outside_the_support(
        (ts, texels) in sized_texture(3),
        beyond in 0.0f32..3.0,
        other in -1.2f32..1.2,
        side in prop::sample::select(vec![-1.0f32, 1.0]),
        swap: bool,
    ) {
        let edge = 1.0 + 2.0 / (ts - 1) as f64;
        // The smallest f32 at or beyond the edge on this side.
        let mut c = (side as f64 * (edge + beyond as f64)) as f32;
        while (c.abs() as f64) < edge {
            c = if side > 0.0 { c.next_up() } else { c.next_down() };
        }
        let (u, v) = if swap { (other, c) } else { (c, other) };
        let tex = &texels[..];
        let mut out = [1.0f32; 3];
        bilinear::sample(tex, ts, 3, u, v, &mut out);
        prop_assert_eq!(out, [0.0; 3], "ts {} ({}, {})", ts, u, v);
        let exactly_left_edge = bilinear::texel_coordinate(c, ts) == -1.0;
        if !exactly_left_edge {
            let mut d = vec![0.0; tex.len()];
            let g = bilinear::sample_vjp(tex, ts, 3, u, v, &[1.0, -0.5, 2.0], &mut d);
            prop_assert_eq!(g, (0.0, 0.0));
            prop_assert!(d.iter().all(|&x| x == 0.0));
        }
    }

    /// The tap API used by the rasterizer gives bit-identical results to the free functions, and
    /// its VJP accumulates (adds) into the texel gradient.
    #[test]
    fn tap_api_matches_free_functions(c in case(), d_out in proptest::array::uniform3(-1.0f32..1.0)) {
        let t = taps(c.uv.x, c.uv.y, c.ts).unwrap();
        let (mut a, mut b) = (vec![0.0; c.channels], vec![0.0; c.channels]);
        t.sample(&c.texels, c.channels, &mut a);
        bilinear::sample(&c.texels, c.ts, c.channels, c.uv.x, c.uv.y, &mut b);
        prop_assert_eq!(&a, &b);
        if c.channels == 1 {
            prop_assert_eq!(t.sample_one(&c.texels), a[0]);
        }
        let g = &d_out[..c.channels];
        let mut d1 = vec![0.25; c.texels.len()];
        let mut d2 = vec![0.0; c.texels.len()];
        let r1 = t.accumulate_vjp(&c.texels, c.channels, g, &mut d1);
        let r2 = bilinear::sample_vjp(&c.texels, c.ts, c.channels, c.uv.x, c.uv.y, g, &mut d2);
        prop_assert_eq!(r1, r2);
        for (x, y) in d1.iter().zip(&d2) {
            prop_assert_eq!(*x, 0.25 + *y);
        }
    }
}

/// Forward difference `(f(u + h) − f(u))/h` and backward difference of the sampled value along
/// `u` (or `v`), with `h` an exact dyadic step inside one cell.
fn one_sided(texels: &[f32], ts: usize, u: f32, v: f32, along_v: bool) -> (f64, f64) {
    // Half a texel: the sample is exactly linear along u (or v) inside a cell, so the one-sided
    // differences are exact up to rounding, and a large step keeps that rounding small.
    let h = 0.5 * 2.0 / (ts - 1) as f32;
    let eval = |d: f32| {
        let mut o = [0.0f32];
        if along_v {
            bilinear::sample(texels, ts, 1, u, v + d, &mut o);
        } else {
            bilinear::sample(texels, ts, 1, u + d, v, &mut o);
        }
        o[0] as f64
    };
    let f0 = eval(0.0);
    ((eval(h) - f0) / h as f64, (f0 - eval(-h)) / h as f64)
}

/// At exact texel borders (X an integer, here exactly representable for sizes 2^k + 1) the
/// derivative is the right derivative, i.e. that of the cell [X, X + 1). Checked at every
/// border, including the zero-padded edges X = −1, 0, ts − 1, for u and for v.
#[test]
fn texel_borders_use_the_right_derivative() {
    let mut runner = TestRunner::new(strategies::seeded_config(1));
    for ts in [2usize, 3, 5, 9, 17, 65] {
        let tex = strategies::texture(ts, 1).new_tree(&mut runner).unwrap().current();
        let mut differs = 0;
        for k in -1..ts as i64 {
            let border = (2.0 * k as f64 / (ts - 1) as f64 - 1.0) as f32;
            assert_eq!(bilinear::texel_coordinate(border, ts), k as f64, "border must be exact");
            for other in [-0.77f32, 0.1234, 0.9] {
                for along_v in [false, true] {
                    let (u, v) = if along_v { (other, border) } else { (border, other) };
                    let mut d = vec![0.0; tex.len()];
                    let (du, dv) = bilinear::sample_vjp(&tex, ts, 1, u, v, &[1.0], &mut d);
                    let analytic = if along_v { dv } else { du } as f64;
                    let (right, left) = one_sided(&tex, ts, u, v, along_v);
                    let scale = 1.0 + right.abs();
                    assert!(
                        (analytic - right).abs() <= 1e-3 * scale,
                        "ts {ts} k {k} ({u}, {v}) along_v {along_v}: analytic {analytic} vs right {right}"
                    );
                    if (left - right).abs() > 1e-2 * scale {
                        differs += 1;
                    }
                }
            }
        }
        // The convention is observable: left and right derivatives differ at most borders.
        assert!(differs > 0, "ts {ts}: no border had a derivative jump");
    }
}

/// At the left edge of the support (X = −1 exactly) the value is 0 but the derivative is the
/// fade-in ramp's slope `(ts − 1)/2 · texel`, consistent with the right-derivative convention;
/// at the right edge (X = ts) there are no taps.
#[test]
fn left_edge_of_support_has_the_ramp_derivative() {
    let ts = 5;
    let tex: Vec<f32> = (0..25).map(|i| 0.1 + 0.03 * i as f32).collect();
    let (u, v) = (-1.5f32, -1.0f32); // X = −1, Y = 0: the ramp into texel (0, 0)
    let t = taps(u, v, ts).unwrap();
    // Column 0 of rows 0 and 1 (Y = 0, so row 1 has weight 0 too): present, weight 0.
    assert_eq!(t.indices(), &[0, 5]);
    assert_eq!(t.weights(), &[0.0, 0.0]);
    let mut out = [1.0];
    bilinear::sample(&tex, ts, 1, u, v, &mut out);
    assert_eq!(out[0], 0.0);
    let mut d = vec![0.0; 25];
    let (du, dv) = bilinear::sample_vjp(&tex, ts, 1, u, v, &[1.0], &mut d);
    assert_eq!(du, 2.0 * tex[0]);
    assert_eq!(dv, 0.0);
    assert!(taps(1.5, 0.0, ts).is_none()); // X = ts
}

/// Non-finite and huge coordinates give no taps, zero output, zero gradient, no panic.
#[test]
fn non_finite_and_huge_uv_contribute_nothing() {
    let specials = [
        f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::MAX,
        f32::MIN,
        1e30,
        -1e30,
        1e10,
        -1e10,
        16_777_216.0,
        -4.0,
        4.0,
    ];
    for ts in SIZES {
        let tex = vec![0.5f32; 3 * ts * ts];
        for &s in &specials {
            for (u, v) in [(s, 0.0), (0.0, s), (s, s), (s, f32::NAN)] {
                assert!(taps(u, v, ts).is_none(), "ts {ts} ({u}, {v})");
                let mut out = [7.0f32; 3];
                bilinear::sample(&tex, ts, 3, u, v, &mut out);
                assert_eq!(out, [0.0; 3], "ts {ts} ({u}, {v})");
                let mut d = vec![0.0; tex.len()];
                let g = bilinear::sample_vjp(&tex, ts, 3, u, v, &[1.0, 1.0, 1.0], &mut d);
                assert_eq!(g, (0.0, 0.0));
                assert!(d.iter().all(|&x| x == 0.0));
            }
        }
    }
    // Tiny and subnormal coordinates are ordinary points near the centre.
    for s in [f32::MIN_POSITIVE, 1e-45, -1e-45, 0.0, -0.0] {
        assert!(taps(s, s, 16).is_some());
    }
}

// ---------------------------------------------------------------------------------------------
// Broken backwards that the checker must reject.

/// The paper's Algorithm 1 (supplement §6.1) **as printed**, for one channel: the corner
/// `(nwx, nwy)` is never defined (taken here as `(⌊x⌋, ⌊y⌋)`), the texel gradients are assigned
/// with `=` instead of accumulated, there is no bounds check (we add zero padding so that it
/// does not read out of bounds), `T[x, y]` is taken as the texel at column x, row y, and the
/// second gradient line has the typo `gy = −T[nw](sey − x)` instead of `(sex − x)`.
fn algorithm1_as_printed(tex: &[f32], ts: usize, u: f32, v: f32, g: f32, d_tex: &mut [f32]) -> (f32, f32) {
    let x = (u + 1.0) / 2.0 * (ts - 1) as f32;
    let y = (v + 1.0) / 2.0 * (ts - 1) as f32;
    let (fx, fy) = (x.floor(), y.floor());
    let (nex, sex, swx) = (fx + 1.0, fx + 1.0, fx);
    let (ney, sey, swy) = (fy, fy + 1.0, fy + 1.0);
    let (nwx, nwy) = (fx, fy);
    let nw = (sex - x) * (sey - y);
    let ne = (x - swx) * (swy - y);
    let sw = (nex - x) * (y - ney);
    let se = (x - nwx) * (y - nwy);
    let n = ts as i64;
    let at = |cx: f32, cy: f32| -> Option<usize> {
        let (cx, cy) = (cx as i64, cy as i64);
        (cx >= 0 && cx < n && cy >= 0 && cy < n).then(|| (cy * n + cx) as usize)
    };
    let t = |cx: f32, cy: f32| at(cx, cy).map_or(0.0, |i| tex[i]);
    for (cx, cy, w) in [(nwx, nwy, nw), (nex, ney, ne), (swx, swy, sw), (sex, sey, se)] {
        if let Some(i) = at(cx, cy) {
            d_tex[i] = g * w; // "=" as printed
        }
    }
    let mut gx = -t(nwx, nwy) * (sey - y) * g;
    let mut gy = -t(nwx, nwy) * (sey - x) * g; // typo: should be (sex − x)
    gx += t(nex, ney) * (swy - y) * g;
    gy -= t(nex, ney) * (x - swx) * g;
    gx -= t(swx, swy) * (y - ney) * g;
    gy += t(swx, swy) * (nex - x) * g;
    gx += t(sex, sey) * (y - nwy) * g;
    gy += t(sex, sey) * (x - nwx) * g;
    let s = (ts - 1) as f32 / 2.0;
    (gx * s, gy * s)
}

/// Algorithm 1 with its typos fixed (same loop structure): must pass, which shows that the
/// failures below come from the typos and not from the transcription.
fn algorithm1_corrected(tex: &[f32], ts: usize, u: f32, v: f32, g: f32, d_tex: &mut [f32]) -> (f32, f32) {
    let x = (u + 1.0) / 2.0 * (ts - 1) as f32;
    let y = (v + 1.0) / 2.0 * (ts - 1) as f32;
    let (x0, y0) = (x.floor(), y.floor());
    let (x1, y1) = (x0 + 1.0, y0 + 1.0);
    let n = ts as i64;
    let at = |cx: f32, cy: f32| -> Option<usize> {
        let (cx, cy) = (cx as i64, cy as i64);
        (cx >= 0 && cx < n && cy >= 0 && cy < n).then(|| (cy * n + cx) as usize)
    };
    let t = |cx: f32, cy: f32| at(cx, cy).map_or(0.0, |i| tex[i]);
    let taps = [
        (x0, y0, (x1 - x) * (y1 - y)),
        (x1, y0, (x - x0) * (y1 - y)),
        (x0, y1, (x1 - x) * (y - y0)),
        (x1, y1, (x - x0) * (y - y0)),
    ];
    for (cx, cy, w) in taps {
        if let Some(i) = at(cx, cy) {
            d_tex[i] += g * w;
        }
    }
    let gx = (-t(x0, y0) * (y1 - y) + t(x1, y0) * (y1 - y) - t(x0, y1) * (y - y0) + t(x1, y1) * (y - y0)) * g;
    let gy = (-t(x0, y0) * (x1 - x) - t(x1, y0) * (x - x0) + t(x0, y1) * (x1 - x) + t(x1, y1) * (x - x0)) * g;
    let s = (ts - 1) as f32 / 2.0;
    (gx * s, gy * s)
}

type OneChannelVjp = fn(&[f32], usize, f32, f32, f32, &mut [f32]) -> (f32, f32);

fn one_channel_vjp(ts: usize, f: OneChannelVjp) -> impl Fn(&[f32], &[f32]) -> Vec<f32> {
    move |x: &[f32], w: &[f32]| {
        let mut g = vec![0.0; x.len()];
        let (du, dv) = f(&x[2..], ts, x[0], x[1], w[0], &mut g[2..]);
        g[0] = du;
        g[1] = dv;
        g
    }
}

/// The random loss weights of a case are not all tiny: a broken gradient scaled by a weight of
/// 1e-3 hides under the absolute tolerance, so the rejection tests need a real signal.
fn strong_weights(c: &Case) -> bool {
    random_weights(c.channels, c.seed).iter().any(|w| w.abs() > 0.1)
}

/// The analytic gradient of a case with its own random weights.
fn gradient(c: &Case) -> Vec<f32> {
    let w: Vec<f32> = random_weights(c.channels, c.seed).iter().map(|&w| w as f32).collect();
    vjp(c.ts, c.channels)(&inputs(c), &w)
}

fn strong_case() -> impl Strategy<Value = Case> {
    case().prop_filter("loss weights too small to see an error", strong_weights)
}

/// Single-channel cases with ⌊X⌋ ≠ ⌊Y⌋, both ≥ 0 (where the `sey − x` typo is visible: its error
/// is `T[nw]·(⌊Y⌋ − ⌊X⌋)`, zero on the diagonal cells, e.g. always for ts = 2, and when the nw
/// tap is zero padding).
fn case_off_diagonal() -> impl Strategy<Value = Case> {
    strong_case()
        .prop_filter("need a 1-channel texture", |c| c.channels == 1 && c.ts > 2)
        .prop_filter("need 0 <= floor(X) != floor(Y) >= 0", |c| {
            let x0 = bilinear::texel_coordinate(c.uv.x, c.ts).floor();
            let y0 = bilinear::texel_coordinate(c.uv.y, c.ts).floor();
            x0 != y0 && x0 >= 0.0 && y0 >= 0.0
        })
}

proptest! {
    #![proptest_config(strategies::seeded_config(64))]

    #[test]
    fn algorithm1_as_printed_fails(c in case_off_diagonal()) {
        let r = check_with(&c, one_channel_vjp(c.ts, algorithm1_as_printed), &BILINEAR_TOL);
        prop_assert!(!r.passed(), "Algorithm 1 as printed must fail: {r}");
        let r = check_with(&c, one_channel_vjp(c.ts, algorithm1_corrected), &BILINEAR_TOL);
        prop_assert!(r.passed(), "corrected Algorithm 1 must pass: {r}");
    }

    #[test]
    fn sign_flip_of_du_fails(c in strong_case()) {
        let good = vjp(c.ts, c.channels);
        let broken = |x: &[f32], w: &[f32]| { let mut g = good(x, w); g[0] = -g[0]; g };
        // A flip only shows when the true derivative is not ~0.
        prop_assume!(gradient(&c)[0].abs() > 1e-2);
        prop_assert!(!check_with(&c, broken, &BILINEAR_TOL).passed());
    }

    #[test]
    fn missing_texel_scale_fails(c in strong_case()) {
        // Forgetting dX/du = (ts − 1)/2 (invisible for ts = 3, where it is 1).
        prop_assume!(c.ts != 3);
        let good = vjp(c.ts, c.channels);
        let s = (c.ts - 1) as f32 / 2.0;
        let broken = |x: &[f32], w: &[f32]| { let mut g = good(x, w); g[0] /= s; g[1] /= s; g };
        let g = gradient(&c);
        prop_assume!(g[0].abs().max(g[1].abs()) > 1e-2);
        prop_assert!(!check_with(&c, broken, &BILINEAR_TOL).passed());
    }

    #[test]
    fn one_percent_scale_fails(c in strong_case()) {
        let good = vjp(c.ts, c.channels);
        let broken = |x: &[f32], w: &[f32]| good(x, w).into_iter().map(|g| g * 1.01).collect();
        prop_assert!(!check_with(&c, broken, &BILINEAR_TOL).passed());
    }

    /// Clamp-to-edge instead of zero padding in the backward: wrong in the fade band.
    #[test]
    fn clamp_to_edge_backward_fails(
        (ts, texels) in sized_texture(1),
        along in 0.25f32..0.75,
        other in -0.9f32..0.9,
        seed: u64,
    ) {
        // A point in the right fade band: X = ts − 1 + along.
        let u = 2.0 * (ts as f32 - 1.0 + along) / (ts - 1) as f32 - 1.0;
        let c = Case { ts, channels: 1, uv: Vec2::new(u, other), texels, seed };
        prop_assume!(strong_weights(&c));
        let broken = |x: &[f32], w: &[f32]| {
            let mut g = vec![0.0; x.len()];
            // Sample as if the coordinate were clamped into the square.
            let (du, dv) = bilinear::sample_vjp(&x[2..], ts, 1, x[0].min(1.0), x[1], w, &mut g[2..]);
            g[0] = du;
            g[1] = dv;
            g
        };
        prop_assert!(!check_with(&c, broken, &BILINEAR_TOL).passed());
    }
}

/// Algorithm 1's `=` instead of `+=`: with two samples of the same texture in one loss (two
/// pixels hitting the same cell), overwriting loses one pixel's texel gradient.
#[test]
fn overwriting_texel_gradients_fails() {
    let ts = 4;
    let tex: Vec<f32> = (0..16).map(|i| 0.05 + 0.055 * i as f32).collect();
    let pts = [(0.1f32, -0.2f32), (0.2, -0.1)]; // same cell
    let x = tex.clone();
    let forward = |x: &[f32]| {
        pts.iter()
            .map(|&(u, v)| {
                let mut o = [0.0];
                bilinear::sample(&x[..16], ts, 1, u, v, &mut o);
                o[0]
            })
            .collect::<Vec<f32>>()
    };
    let backward = |overwrite: bool| {
        move |x: &[f32], w: &[f32]| {
            let mut g = vec![0.0; x.len()];
            for (k, &(u, v)) in pts.iter().enumerate() {
                let mut d = vec![0.0; 16];
                bilinear::sample_vjp(&x[..16], ts, 1, u, v, &[w[k]], &mut d);
                for (gi, di) in g.iter_mut().zip(&d) {
                    if overwrite {
                        if *di != 0.0 {
                            *gi = *di;
                        }
                    } else {
                        *gi += di;
                    }
                }
            }
            g
        }
    };
    for seed in 0..8 {
        let good = check_vjp(&x, forward, backward(false), seed, STEP, &BILINEAR_TOL);
        assert!(good.passed(), "{good}");
        let bad = check_vjp(&x, forward, backward(true), seed, STEP, &BILINEAR_TOL);
        assert!(!bad.passed(), "overwriting must fail: {bad}");
    }
}

// ---------------------------------------------------------------------------------------------
// Tolerance measurement (ignored by default).

use bbsplat::gradcheck::WorstObserved as Worst;

/// Runs the property's generator over `BBSPLAT_MEASURE_SEEDS` (default 64) seeds × 256 cases
/// and prints the worst statistics against the probe tolerance `atol = 1e-5, rtol = 1e-4`.
#[test]
#[ignore = "measurement: run with --ignored --nocapture"]
fn measure_tolerances() {
    let probe = GradTolerance {
        atol: 1e-5,
        rtol: 1e-4,
        ..BILINEAR_TOL
    };
    let seeds: u64 = std::env::var("BBSPLAT_MEASURE_SEEDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(64);
    let mut worst = Worst::default();
    for seed in 0..seeds {
        let config = ProptestConfig {
            rng_seed: RngSeed::Fixed(1000 + seed),
            ..strategies::seeded_config(256)
        };
        let mut runner = TestRunner::new(config);
        for _ in 0..256 {
            let c = case().new_tree(&mut runner).unwrap().current();
            worst.add(&check_with(&c, vjp(c.ts, c.channels), &probe));
        }
    }
    println!("bilinear, probe atol 1e-5 rtol 1e-4: {worst:?}");
}

fn planes(rgba: &[[f32; 4]]) -> Vec<f32> {
    (0..4).flat_map(|c| rgba.iter().map(move |t| t[c])).collect()
}

/// RGBA sampling equals planar sampling channel by channel, bit for bit, and its VJP equals
/// the dense planar VJP (texel gradients exactly, `(u, v)` up to the order of additions).
#[test]
fn rgba_matches_the_planar_sample_and_vjp() {
    let ts = 5;
    let rgba: Vec<[f32; 4]> = (0..ts * ts)
        .map(|i| {
            let x = i as f32;
            [
                (x * 0.61).cos().abs(),
                (x * 0.23).sin().abs(),
                (x * 0.91).cos().abs(),
                (x * 0.37).sin().abs(),
            ]
        })
        .collect();
    let planar = planes(&rgba);
    for &(u, v) in &[
        (0.13f32, -0.42f32),
        (-1.05, 0.3),
        (0.999, 1.02),
        (0.5, 0.5),
        (1.1, -1.1),
    ] {
        let taps = taps(u, v, ts).unwrap();
        let mut want = [0.0f32; 4];
        taps.sample(&planar, 4, &mut want);
        assert_eq!(
            taps.sample_rgba(&rgba).map(f32::to_bits),
            want.map(f32::to_bits),
            "({u}, {v})"
        );
        let d = [0.2f32, -0.9, 0.4, 0.7];
        let mut dense = vec![0.0; 4 * ts * ts];
        let (ud, vd) = taps.accumulate_vjp(&planar, 4, &d, &mut dense);
        let mut sparse = vec![0.0; 4 * ts * ts];
        let (du, dv) = taps.vjp_rgba(&rgba, d, |i, g| {
            for c in 0..4 {
                sparse[c * ts * ts + i as usize] += g[c];
            }
        });
        assert!((du - ud).abs() < 1e-5 && (dv - vd).abs() < 1e-5, "({u}, {v})");
        assert_eq!(sparse, dense);
    }
}

/// `vjp_rgba` (the four taps side by side, outside taps' terms replaced by +0) against the plain
/// tap-by-tap loop it replaced, bit for bit: `(∂u, ∂v)` and every emitted texel gradient, in
/// order. Interior cells and every border (taps outside the texture), texels with negative
/// values, zeros of both signs and infinities, and upstream gradients with signed zeros, so that
/// the "seen" values and the `∂u`, `∂v` terms include −0, and an unused tap slot (index 0)
/// would meet an infinite texel.
#[test]
fn vjp_rgba_equals_the_tap_by_tap_loop_bit_for_bit() {
    let ts = 8;
    let mut rng = bbsplat::rng::Rng::new(11);
    let specials = [0.0f32, -0.0, 1.0, -1.0, f32::INFINITY, 0.5];
    let gradients = [
        [0.2f32, -0.9, 0.4, 0.7],
        [-0.0, 0.0, -0.0, 0.0],
        [0.0, -0.0, 1.5, -0.0],
        [-0.3, -0.0, -0.0, 2.0],
    ];
    // The loop the lane-wise form replaced: taps in order, each term added as it is formed.
    let reference = |t: &bilinear::BilinearTaps, texels: &[[f32; 4]], d: [f32; 4]| {
        let (mut du, mut dv) = (0.0f32, 0.0f32);
        let mut emitted = Vec::new();
        for k in 0..t.len() {
            let i = t.indices()[k];
            let x = texels[i as usize];
            let seen = x[3] * d[3] + x[0] * d[0] + x[1] * d[1] + x[2] * d[2];
            du += t.weight_derivatives_u()[k] * seen;
            dv += t.weight_derivatives_v()[k] * seen;
            let w = t.weights()[k];
            emitted.push((i, [w * d[0], w * d[1], w * d[2], w * d[3]].map(f32::to_bits)));
        }
        ((du.to_bits(), dv.to_bits()), emitted)
    };
    let mut cases = 0;
    let mut partial = 0;
    for trial in 0..400 {
        let texels: Vec<[f32; 4]> = (0..ts * ts)
            .map(|_| {
                [(); 4].map(|_| {
                    if rng.uniform() < 0.3 {
                        specials[(rng.uniform() * specials.len() as f32) as usize % specials.len()]
                    } else {
                        rng.uniform() * 2.0 - 1.0
                    }
                })
            })
            .collect();
        // Half the cases on the border ring (|c| near 1 + 2/(ts − 1)), where taps fall outside.
        let coordinate = |r: f32| {
            if trial % 2 == 0 {
                r * 2.0 - 1.0
            } else {
                (1.0 + r * 0.28) * if r < 0.5 { -1.0 } else { 1.0 }
            }
        };
        let (u, v) = (coordinate(rng.uniform()), coordinate(rng.uniform()));
        let Some(t) = taps(u, v, ts) else { continue };
        partial += usize::from(t.len() < 4);
        for d in gradients {
            let mut emitted = Vec::new();
            let (du, dv) = t.vjp_rgba(&texels, d, |i, g| emitted.push((i, g.map(f32::to_bits))));
            assert_eq!(
                ((du.to_bits(), dv.to_bits()), emitted),
                reference(&t, &texels, d),
                "({u}, {v}), d = {d:?}"
            );
            cases += 1;
        }
    }
    assert!(
        cases > 1000 && partial > 100,
        "{cases} cases, {partial} with outside taps"
    );
}
