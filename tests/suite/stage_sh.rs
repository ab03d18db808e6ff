//! Spherical-harmonics colour: the VJP (coefficients and position through the view direction)
//! against finite differences, the basis against an independent f64 evaluation and for
//! orthonormality, view independence of degree 0, degenerate and far directions, and broken
//! backwards the checker must reject.
//!
//! Tolerance measurement: `cargo test --test suite stage_sh:: -- --ignored --nocapture`.

// Index loops mirror the (l, m) and (k, channel) formulas they implement.
#![allow(clippy::needless_range_loop)]

use bbsplat::gradcheck::{GradReport, GradTolerance, StepRule, check_vjp, compare, numerical_gradient, random_weights};
use bbsplat::rng::Rng;
use bbsplat::stages::sh::{
    self, SH_C0, SH_FLOATS, SH_MIN_DISTANCE, rgb_to_sh, sh_basis, sh_coeff_count, sh_colour, sh_colour_batch,
    sh_colour_vjp, sh_colour_vjp_clamped, sh_to_rgb,
};
use bbsplat::strategies;
use bbsplat::testing_internals::sh::{coefficient_pass, coefficient_pass_scalar, raw_colours, raw_colours_scalar};
use glam::{DVec3, Vec3};
use proptest::prelude::*;
use proptest::strategy::ValueTree;
use proptest::test_runner::{RngSeed, TestRunner};

/// Tolerance of the SH VJP check (|d| ∈ [2, 10], step [`STEP`]).
///
/// Measured with `measure_tolerances` over 256 seeds × 256 cases (65 536 cases) against the
/// probe `atol = 1e-5, rtol = 1e-4`: elementwise ratio 2.12 (worst |a − n| = 3.4e-5), rel. L2
/// 3.1e-5, 1 − cos 4.7e-10, |bias| 1.5e-5. Chosen: 4× the worst (elementwise: the probe × 8.5).
const SH_TOL: GradTolerance = GradTolerance {
    atol: 8.5e-5,
    rtol: 8.5e-4,
    max_rel_l2: 1.25e-4,
    min_cosine: 1.0 - 1.9e-9,
    max_bias: 6.2e-5,
};

/// Tolerance of the near-camera SH check (|d| ∈ [0.2, 1], step [`NEAR_STEP`]).
///
/// Measured as above (65 536 cases): elementwise ratio 18.9 (worst |a − n| = 2.9e-4, direction
/// rounding amplified by the 1/|d| gradient), rel. L2 2.2e-4, 1 − cos 2.5e-8, |bias| 1.4e-4.
/// Chosen: 4× the worst.
const SH_NEAR_TOL: GradTolerance = GradTolerance {
    atol: 7.6e-4,
    rtol: 7.6e-3,
    max_rel_l2: 9.0e-4,
    min_cosine: 1.0 - 1.0e-7,
    max_bias: 5.7e-4,
};

/// The step: absolute 1e-2 with camera-to-point distances in [2, 10] (the direction moves by at
/// most 5e-3 rad). The finite-difference error has two parts: truncation, ∝ (h/|d|)², and the
/// f32 rounding of the direction (≈ 1e-7 relative) amplified by |∂colour/∂dir|/h. Measured over
/// 16 384 cases: h = 1e-3 with |d| ∈ [1, 5] gives a worst elementwise ratio 23 (rounding-bound,
/// on position entries); h = 1e-2 with |d| ∈ [2, 10] gives 1.9. The formula is scale-invariant
/// (∂colour/∂position ∝ 1/|d|), so distances near the near plane are covered by
/// `vjp_matches_finite_differences_near` with its own step and tolerance.
const STEP: StepRule = StepRule {
    base: 1e-2,
    relative: false,
};

/// Step for the near property (|d| ∈ [0.2, 1]): h/|d| ≤ 5e-3 as above.
const NEAR_STEP: StepRule = StepRule {
    base: 1e-3,
    relative: false,
};

#[derive(Clone, Debug)]
struct Case {
    degree: u32,
    coeffs: Vec<f32>,
    position: Vec3,
    centre: Vec3,
    seed: u64,
}

/// Raw colour (sum + 0.5) of each channel, to keep cases away from the clamp's kink.
fn raw(c: &Case) -> [f32; 3] {
    let mut b = [0.0; 16];
    let dir = (c.position - c.centre).normalize();
    sh_basis(c.degree, dir, &mut b);
    let mut r = [0.5f32; 3];
    for k in 0..sh_coeff_count(c.degree) {
        for (ch, rc) in r.iter_mut().enumerate() {
            *rc += b[k] * c.coeffs[3 * k + ch];
        }
    }
    r
}

fn case() -> impl Strategy<Value = Case> {
    case_at(2.0..10.0)
}

fn near_case() -> impl Strategy<Value = Case> {
    case_at(0.2..1.0)
}

fn case_at(distance: std::ops::Range<f32>) -> impl Strategy<Value = Case> {
    (
        0u32..=3,
        strategies::sh_coefficients(),
        strategies::direction(),
        distance,
        proptest::array::uniform3(-2.0f32..2.0),
        any::<u64>(),
    )
        .prop_map(|(degree, coeffs, dir, dist, centre, seed)| {
            let centre = Vec3::from_array(centre);
            Case {
                degree,
                coeffs,
                position: centre + dir * dist,
                centre,
                seed,
            }
        })
        .prop_filter("too close to the clamp at 0", |c| raw(c).iter().all(|r| r.abs() > 0.1))
}

fn inputs(c: &Case) -> Vec<f32> {
    let mut x = c.coeffs.clone();
    x.extend(c.position.to_array());
    x
}

fn forward(degree: u32, centre: Vec3) -> impl Fn(&[f32]) -> Vec<f32> {
    move |x: &[f32]| {
        let p = Vec3::from_slice(&x[SH_FLOATS..]);
        sh_colour(degree, &x[..SH_FLOATS], p - centre).rgb.to_array().to_vec()
    }
}

fn vjp(degree: u32, centre: Vec3) -> impl Fn(&[f32], &[f32]) -> Vec<f32> {
    move |x: &[f32], w: &[f32]| {
        let p = Vec3::from_slice(&x[SH_FLOATS..]);
        let mut g = vec![0.0; SH_FLOATS + 3];
        let dp = sh_colour_vjp(
            degree,
            &x[..SH_FLOATS],
            p - centre,
            Vec3::from_slice(w),
            &mut g[..SH_FLOATS],
        );
        g[SH_FLOATS..].copy_from_slice(&dp.to_array());
        g
    }
}

fn check_with<B: Fn(&[f32], &[f32]) -> Vec<f32>>(c: &Case, backward: B, tol: &GradTolerance) -> GradReport {
    check_vjp(&inputs(c), forward(c.degree, c.centre), backward, c.seed, STEP, tol)
}

fn check_near(c: &Case, tol: &GradTolerance) -> GradReport {
    check_vjp(
        &inputs(c),
        forward(c.degree, c.centre),
        vjp(c.degree, c.centre),
        c.seed,
        NEAR_STEP,
        tol,
    )
}

proptest! {
    #![proptest_config(strategies::seeded_config(256))]

    /// VJP for coefficients and position (through the normalised view direction), all degrees,
    /// clamped channels included (gradient gated to 0).
    #[test]
    fn vjp_matches_finite_differences(c in case()) {
        let r = check_with(&c, vjp(c.degree, c.centre), &SH_TOL);
        prop_assert!(r.passed(), "degree {}: {r}", c.degree);
    }

    /// The same for points 0.2-1 units from the camera (down to the near plane).
    #[test]
    fn vjp_matches_finite_differences_near(c in near_case()) {
        let r = check_near(&c, &SH_NEAR_TOL);
        prop_assert!(r.passed(), "degree {}: {r}", c.degree);
    }

    /// Degree 0 is view-independent: same colour from every direction, zero position gradient,
    /// and it equals SH_C0·c + 0.5.
    #[test]
    fn degree_zero_is_view_independent(c in case(), d1 in strategies::direction(), d2 in strategies::direction(), dist in 0.01f32..100.0) {
        let a = sh_colour(0, &c.coeffs, (c.centre + d1 * dist) - c.centre);
        let b = sh_colour(0, &c.coeffs, (c.centre + d2) - c.centre);
        prop_assert_eq!(a, b);
        for ch in 0..3 {
            prop_assert_eq!(a.rgb[ch], sh_to_rgb(c.coeffs[ch]).max(0.0));
        }
        let mut d = vec![0.0; SH_FLOATS];
        let dp = sh_colour_vjp(0, &c.coeffs, (c.centre + d1 * dist) - c.centre, Vec3::ONE, &mut d);
        prop_assert_eq!(dp, Vec3::ZERO);
        prop_assert!(d[3..].iter().all(|&x| x == 0.0));
    }

    /// Coefficients beyond the degree are never read (NaN there changes nothing).
    #[test]
    fn unused_coefficients_are_not_read(c in case()) {
        let mut poisoned = c.coeffs.clone();
        poisoned[3 * sh_coeff_count(c.degree)..].fill(f32::NAN);
        prop_assert_eq!(
            sh_colour(c.degree, &c.coeffs, c.position - c.centre),
            sh_colour(c.degree, &poisoned, c.position - c.centre)
        );
        let (mut d1, mut d2) = (vec![0.0; SH_FLOATS], vec![0.0; SH_FLOATS]);
        let p1 = sh_colour_vjp(c.degree, &c.coeffs, c.position - c.centre, Vec3::ONE, &mut d1);
        let p2 = sh_colour_vjp(c.degree, &poisoned, c.position - c.centre, Vec3::ONE, &mut d2);
        prop_assert_eq!(p1, p2);
        prop_assert_eq!(d1, d2);
    }

    /// The basis agrees with an independent f64 evaluation of the real SH (associated Legendre
    /// functions with the Condon-Shortley phase, order m = −l..l).
    #[test]
    fn basis_matches_associated_legendre(dir in strategies::direction()) {
        let mut b = [0.0; 16];
        sh_basis(3, dir, &mut b);
        let r = real_sh_f64(dir.as_dvec3());
        for k in 0..16 {
            prop_assert!((b[k] as f64 - r[k]).abs() < 2e-6, "k {k}: {} vs {}", b[k], r[k]);
        }
        // Lower degrees are prefixes, zero-filled.
        for degree in 0..3 {
            let mut lower = [1.0; 16];
            sh_basis(degree, dir, &mut lower);
            let n = sh_coeff_count(degree);
            prop_assert_eq!(&lower[..n], &b[..n]);
            prop_assert!(lower[n..].iter().all(|&x| x == 0.0));
        }
    }
}

/// Independent real SH in f64: `Y_lm = √2 K_lm cos(mφ) P_l^m(cos θ)` (m > 0),
/// `√2 K_l|m| sin(|m|φ) P_l^|m|(cos θ)` (m < 0), `K_l0 P_l(cos θ)` (m = 0), with
/// `K_lm = √((2l + 1)/(4π) · (l − m)!/(l + m)!)` and `P_l^m` including `(−1)^m`.
fn real_sh_f64(d: DVec3) -> [f64; 16] {
    let d = d.normalize();
    let (ct, phi) = (d.z, d.y.atan2(d.x));
    let st = (1.0 - ct * ct).max(0.0).sqrt();
    // Associated Legendre P_l^m(ct), 0 ≤ m ≤ l ≤ 3, standard recurrences.
    let mut p = [[0.0f64; 4]; 4];
    p[0][0] = 1.0;
    for m in 1..4 {
        p[m][m] = -(2.0 * m as f64 - 1.0) * st * p[m - 1][m - 1];
    }
    for m in 0..3 {
        p[m + 1][m] = (2.0 * m as f64 + 1.0) * ct * p[m][m];
    }
    for m in 0..4 {
        for l in (m + 2)..4 {
            p[l][m] = ((2.0 * l as f64 - 1.0) * ct * p[l - 1][m] - (l + m - 1) as f64 * p[l - 2][m]) / (l - m) as f64;
        }
    }
    let fact = |n: usize| (1..=n).map(|i| i as f64).product::<f64>();
    let k = |l: usize, m: usize| ((2 * l + 1) as f64 / (4.0 * std::f64::consts::PI) * fact(l - m) / fact(l + m)).sqrt();
    let mut out = [0.0; 16];
    for l in 0..4usize {
        for m in -(l as i64)..=(l as i64) {
            let idx = l * l + (m + l as i64) as usize;
            let am = m.unsigned_abs() as usize;
            out[idx] = match m.signum() {
                0 => k(l, 0) * p[l][0],
                1 => std::f64::consts::SQRT_2 * k(l, am) * (am as f64 * phi).cos() * p[l][am],
                _ => std::f64::consts::SQRT_2 * k(l, am) * (am as f64 * phi).sin() * p[l][am],
            };
        }
    }
    out
}

/// Closed-form values at the axis directions.
#[test]
fn basis_at_axis_directions() {
    let c1 = sh::SH_C1;
    let mut b = [0.0; 16];
    sh_basis(3, Vec3::X, &mut b);
    assert_eq!(&b[..4], &[SH_C0, 0.0, 0.0, -c1]);
    assert!((b[8] - 0.546_274_2).abs() < 1e-6 && (b[6] + 0.315_391_57).abs() < 1e-6);
    assert!((b[15] + 0.590_043_6).abs() < 1e-6 && (b[13] - 0.457_045_8).abs() < 1e-6);
    sh_basis(3, Vec3::Y, &mut b);
    assert_eq!(&b[..4], &[SH_C0, -c1, 0.0, 0.0]);
    assert!((b[8] + 0.546_274_2).abs() < 1e-6);
    sh_basis(3, Vec3::Z, &mut b);
    assert_eq!(&b[..4], &[SH_C0, 0.0, c1, 0.0]);
    // Zonal harmonics at the pole: Y_l0(+z) = √((2l + 1)/(4π)).
    for (k, l) in [(0, 0.0f64), (2, 1.0), (6, 2.0), (12, 3.0)] {
        let expect = ((2.0 * l + 1.0) / (4.0 * std::f64::consts::PI)).sqrt();
        assert!((b[k] as f64 - expect).abs() < 1e-6, "k {k}: {} vs {expect}", b[k]);
    }
    assert!(
        b.iter()
            .enumerate()
            .all(|(k, &x)| [0, 2, 6, 12].contains(&k) || x == 0.0)
    );
}

/// Orthonormality: Gauss-Legendre (in cos θ, 8 nodes) × uniform (in φ, 16 nodes) quadrature is
/// exact for the products of two degree-≤3 harmonics, so ∫ Yᵢ Yⱼ dΩ = δᵢⱼ up to f32 rounding.
#[test]
fn basis_is_orthonormal() {
    let (nodes, weights) = gauss_legendre(8);
    let n_phi = 16;
    let mut gram = [[0.0f64; 16]; 16];
    for (&z, &wz) in nodes.iter().zip(&weights) {
        for j in 0..n_phi {
            let phi = 2.0 * std::f64::consts::PI * j as f64 / n_phi as f64;
            let s = (1.0 - z * z).sqrt();
            let dir = Vec3::new((s * phi.cos()) as f32, (s * phi.sin()) as f32, z as f32);
            let mut b = [0.0; 16];
            sh_basis(3, dir, &mut b);
            let w = wz * 2.0 * std::f64::consts::PI / n_phi as f64;
            for a in 0..16 {
                for c in 0..16 {
                    gram[a][c] += w * b[a] as f64 * b[c] as f64;
                }
            }
        }
    }
    for (a, row) in gram.iter().enumerate() {
        for (c, &g) in row.iter().enumerate() {
            let expect = if a == c { 1.0 } else { 0.0 };
            assert!((g - expect).abs() < 5e-6, "<Y{a}, Y{c}> = {g}");
        }
    }
}

/// Gauss-Legendre nodes and weights on [−1, 1] by Newton iteration on P_n.
fn gauss_legendre(n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut x = Vec::new();
    let mut w = Vec::new();
    for i in 0..n {
        let mut t = (std::f64::consts::PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
        for _ in 0..100 {
            let (mut p0, mut p1) = (1.0, t);
            for k in 2..=n {
                let p2 = ((2 * k - 1) as f64 * t * p1 - (k - 1) as f64 * p0) / k as f64;
                p0 = p1;
                p1 = p2;
            }
            let dp = n as f64 * (t * p1 - p0) / (t * t - 1.0);
            let step = p1 / dp;
            t -= step;
            if step.abs() < 1e-15 {
                let dp = {
                    let (mut q0, mut q1) = (1.0, t);
                    for k in 2..=n {
                        let q2 = ((2 * k - 1) as f64 * t * q1 - (k - 1) as f64 * q0) / k as f64;
                        q0 = q1;
                        q1 = q2;
                    }
                    n as f64 * (t * q1 - q0) / (t * t - 1.0)
                };
                x.push(t);
                w.push(2.0 / ((1.0 - t * t) * dp * dp));
                break;
            }
        }
    }
    assert_eq!(x.len(), n);
    (x, w)
}

#[test]
fn rgb_sh_round_trip() {
    for c in [0.0f32, 0.2, 0.5, 0.9, 1.0] {
        assert!((sh_to_rgb(rgb_to_sh(c)) - c).abs() < 1e-6);
    }
    assert_eq!(rgb_to_sh(0.5), 0.0);
    assert_eq!(SH_C0, 0.28209479177387814_f64 as f32);
}

/// Camera at the point (and within SH_MIN_DISTANCE of it): degree-0 colour, zero position
/// gradient, gradient only for the degree-0 coefficients, never NaN. Just outside the
/// threshold the full degree is used and everything stays finite.
#[test]
fn sh_at_the_camera_position() {
    let mut runner = TestRunner::new(strategies::seeded_config(1));
    let coeffs = strategies::sh_coefficients().new_tree(&mut runner).unwrap().current();
    let centre = Vec3::new(0.3, -1.2, 2.0);
    let dc = sh_colour(0, &coeffs, Vec3::ZERO);
    for offset in [Vec3::ZERO, Vec3::new(0.4e-6, 0.0, 0.0), Vec3::new(0.0, -5e-7, 5e-7)] {
        for degree in 0..=3 {
            let c = sh_colour(degree, &coeffs, offset);
            assert_eq!(c, dc, "degree {degree} offset {offset}");
            let mut d = vec![0.0; SH_FLOATS];
            let dp = sh_colour_vjp(degree, &coeffs, offset, Vec3::new(1.0, -1.0, 0.5), &mut d);
            assert_eq!(dp, Vec3::ZERO);
            assert!(d[..3].iter().all(|x| x.is_finite()) && d[3..].iter().all(|&x| x == 0.0));
        }
    }
    // Just outside: full degree, finite (large) position gradient.
    let offset = Vec3::new(2e-6, 0.0, 0.0);
    let c = sh_colour(3, &coeffs, offset);
    assert!(c.rgb.is_finite());
    let mut d = vec![0.0; SH_FLOATS];
    let dp = sh_colour_vjp(3, &coeffs, offset, Vec3::ONE, &mut d);
    assert!(dp.is_finite() && d.iter().all(|x| x.is_finite()), "{dp}");
    assert!(offset.length() > SH_MIN_DISTANCE);
    // Non-finite positions: defined degree-0 result, no NaN anywhere.
    for p in [
        Vec3::NAN,
        Vec3::new(f32::INFINITY, 0.0, 0.0),
        Vec3::splat(3e19),
        Vec3::new(0.0, f32::NAN, 1.0),
    ] {
        let c = sh_colour(3, &coeffs, p - centre);
        assert_eq!(c, dc, "{p}");
        let mut d = vec![0.0; SH_FLOATS];
        let dp = sh_colour_vjp(3, &coeffs, p - centre, Vec3::ONE, &mut d);
        assert_eq!(dp, Vec3::ZERO);
        assert!(d.iter().all(|x| x.is_finite()));
    }
}

/// A point 1e4 units from the camera: the position gradient (1e-7-1e-5 in size) matches finite
/// differences to 1 %, and equals the gradient at distance 1 divided by 1e4 (scale invariance)
/// to 1e-3. A point 1 unit from a camera 1e4 units from
/// the origin: the direction loses ~1e-3 relative accuracy to the f32 cancellation in
/// `position − centre`, which the colour inherits; it stays finite and close.
#[test]
fn sh_at_1e4_units() {
    let mut runner = TestRunner::new(strategies::seeded_config(1));
    for i in 0..32 {
        let coeffs = strategies::sh_coefficients().new_tree(&mut runner).unwrap().current();
        let dir = strategies::direction().new_tree(&mut runner).unwrap().current();
        let centre = Vec3::new(1.0, -2.0, 0.5);
        let c = Case {
            degree: 3,
            coeffs,
            position: centre + dir * 1e4,
            centre,
            seed: i,
        };
        if raw(&c).iter().any(|r| r.abs() < 0.1) {
            continue;
        }
        let x = inputs(&c);
        let w = random_weights(3, c.seed);
        let wf: Vec<f32> = w.iter().map(|&v| v as f32).collect();
        let analytic: Vec<f64> = vjp(c.degree, c.centre)(&x, &wf).iter().map(|&v| v as f64).collect();
        let f = forward(c.degree, c.centre);
        let loss = |p: &[f32]| f(p).iter().zip(&w).map(|(&y, &wi)| y as f64 * wi).sum::<f64>();
        // Position only, relative step 1e-3·|x| ≈ 10 units (1e-3 rad).
        let idx: Vec<usize> = (SH_FLOATS..SH_FLOATS + 3).collect();
        // Absolute step of 10 units (1e-3 rad): a relative step on a small coordinate would
        // move the colour by less than its f32 resolution.
        let numeric = numerical_gradient(loss, &x, &idx, StepRule::absolute(10.0));
        // FD noise: colour ulp (6e-8) × 3 weighted outputs / (2h = 20) ≈ 9e-9, so atol ≈ 3×
        // that; the whole-vector bounds are 1 % because the gradient itself is only 1e-7-1e-5.
        let tol = GradTolerance {
            atol: 3e-8,
            rtol: 1e-2,
            max_rel_l2: 1e-2,
            min_cosine: 0.9999,
            max_bias: 1e-2,
        };
        let r = compare(&analytic[SH_FLOATS..], &numeric, &tol);
        assert!(r.passed(), "far point {i}: {r}");
        // Scale invariance, exactly: the colour depends on the direction only, so
        // ∂colour/∂position at distance 1e4 is the one at distance 1 divided by 1e4.
        let near = Vec3::from_slice(
            &vjp(c.degree, c.centre)(
                &inputs(&Case {
                    position: centre + dir,
                    ..c.clone()
                }),
                &wf,
            )[SH_FLOATS..],
        );
        let far = Vec3::from_slice(&analytic[SH_FLOATS..].iter().map(|&v| v as f32).collect::<Vec<_>>());
        assert!(
            (far * 1e4 - near).length() <= 1e-3 * near.length() + 1e-7,
            "{far} × 1e4 vs {near}"
        );
    }
    // Camera far from the origin, point close to it: the offset comes from
    // `Camera::view_offset` (f64 subtraction), so the colour is that of the exact offset up to
    // the offset's final rounding; in f32 the same subtraction loses about 1e-3 of it.
    let coeffs = strategies::sh_coefficients().new_tree(&mut runner).unwrap().current();
    let eye = Vec3::new(1e4, -1e4, 1e4);
    let camera = bbsplat::camera::Camera::look_at(eye, eye + Vec3::new(0.3, 0.8, -0.5), Vec3::Z, 100.0, 100.0, 32, 32);
    let offset = Vec3::new(0.6, 0.0, -0.8);
    // A billboard about one unit from the camera (its position rounded to f32 at 1e4).
    let position = camera.centre() + offset;
    let via_camera = camera.view_offset(position);
    let exact_offset = position.as_dvec3() - -(camera.rotation.as_dmat3().transpose() * camera.translation.as_dvec3());
    let in_f32 = position - camera.centre();
    // Measured: 3.0e-8 (the offset's final rounding) against 8.6e-4 for the f32 subtraction.
    assert!(
        (via_camera.as_dvec3() - exact_offset).length() < 3e-7,
        "{via_camera} vs {exact_offset}"
    );
    assert!(
        (in_f32.as_dvec3() - exact_offset).length() > 1e-5,
        "the f32 path should be visibly worse here"
    );
    // The offset is the exact one rounded once, so the colour is the exact offset's colour.
    assert_eq!(via_camera, exact_offset.as_vec3());
    let c = sh_colour(3, &coeffs, via_camera);
    assert!(c.rgb.is_finite());
    let mut d = vec![0.0; SH_FLOATS];
    let dp = sh_colour_vjp(3, &coeffs, via_camera, Vec3::ONE, &mut d);
    assert!(dp.is_finite() && d.iter().all(|x| x.is_finite()));
}

/// Clamp gating at the kink: a strictly negative sum + 0.5 is clamped (zero gradient), exactly
/// 0 is not (the gradient passes), positive passes.
#[test]
fn clamp_gating_is_exact() {
    // A degree-0 coefficient with SH_C0·s + 0.5 == 0 exactly in f32 (found by stepping).
    let mut s = -0.5 / SH_C0;
    while s * SH_C0 + 0.5 < 0.0 {
        s = s.next_up();
    }
    while s * SH_C0 + 0.5 > 0.0 {
        s = s.next_down();
    }
    assert_eq!(s * SH_C0 + 0.5, 0.0, "an exact zero exists for this constant");
    let coeffs = [s, s.next_down(), 1.0];
    let c = sh_colour(0, &coeffs, Vec3::X);
    assert_eq!(c.clamped, [false, true, false]);
    assert_eq!((c.rgb[0], c.rgb[1]), (0.0, 0.0));
    let mut d = [0.0; 3];
    sh_colour_vjp(0, &coeffs, Vec3::X, Vec3::ONE, &mut d);
    assert_eq!(d, [SH_C0, 0.0, SH_C0]);
}

// ---------------------------------------------------------------------------------------------
// Broken backwards that the checker must reject.

fn strong_case(min_degree: u32) -> impl Strategy<Value = Case> {
    case()
        .prop_filter("degree too low", move |c| c.degree >= min_degree)
        .prop_filter("loss weights too small", |c| {
            random_weights(3, c.seed).iter().all(|w| w.abs() > 0.1)
        })
}

/// The true position gradient of a case with its own random weights.
fn position_gradient(c: &Case) -> Vec3 {
    let w: Vec<f32> = random_weights(3, c.seed).iter().map(|&w| w as f32).collect();
    let g = vjp(c.degree, c.centre)(&inputs(c), &w);
    Vec3::from_slice(&g[SH_FLOATS..])
}

proptest! {
    #![proptest_config(strategies::seeded_config(64))]

    /// The view direction detached (the bug Brush's finite-difference suite caught).
    #[test]
    fn detached_view_direction_fails(c in strong_case(1)) {
        prop_assume!(position_gradient(&c).length() > 1e-2);
        let good = vjp(c.degree, c.centre);
        let broken = |x: &[f32], w: &[f32]| { let mut g = good(x, w); g[SH_FLOATS..].fill(0.0); g };
        prop_assert!(!check_with(&c, broken, &SH_TOL).passed());
    }

    /// ∂colour/∂dir used as ∂colour/∂position (no projection onto the tangent plane, no 1/|d|).
    #[test]
    fn unnormalised_direction_gradient_fails(c in strong_case(1)) {
        prop_assume!(position_gradient(&c).length() > 1e-2);
        let centre = c.centre;
        let degree = c.degree;
        let broken = move |x: &[f32], w: &[f32]| {
            let p = Vec3::from_slice(&x[SH_FLOATS..]);
            let mut g = vec![0.0; SH_FLOATS + 3];
            sh_colour_vjp(degree, &x[..SH_FLOATS], p - centre, Vec3::from_slice(w), &mut g[..SH_FLOATS]);
            let dir = (p - centre).normalize();
            let mut db = [0.0f32; 16];
            for (k, d) in db.iter_mut().enumerate().take(sh_coeff_count(degree)) {
                *d = (0..3).map(|ch| w[ch] * x[3 * k + ch]).sum();
            }
            db[0] = 0.0;
            g[SH_FLOATS..].copy_from_slice(&sh::sh_basis_vjp(degree, dir, &db).to_array());
            g
        };
        prop_assert!(!check_with(&c, broken, &SH_TOL).passed());
    }

    /// Gradient not gated for clamped channels.
    #[test]
    fn ungated_clamp_fails(c in strong_case(0).prop_map(|mut c| { c.coeffs[0] = rgb_to_sh(-0.5); c })) {
        // Red is pushed well below the clamp.
        prop_assume!(raw(&c)[0] < -0.1);
        let centre = c.centre;
        let degree = c.degree;
        let broken = move |x: &[f32], w: &[f32]| {
            // The coefficient gradient of the unclamped colour.
            let p = Vec3::from_slice(&x[SH_FLOATS..]);
            let mut b = [0.0; 16];
            sh_basis(degree, (p - centre).normalize(), &mut b);
            let mut g = vjp(degree, centre)(x, w);
            for k in 0..sh_coeff_count(degree) {
                for ch in 0..3 {
                    g[3 * k + ch] = b[k] * w[ch];
                }
            }
            g
        };
        prop_assert!(!check_with(&c, broken, &SH_TOL).passed());
    }

    #[test]
    fn one_percent_scale_fails(c in strong_case(0)) {
        let good = vjp(c.degree, c.centre);
        let broken = |x: &[f32], w: &[f32]| good(x, w).into_iter().map(|g| g * 1.01).collect();
        prop_assert!(!check_with(&c, broken, &SH_TOL).passed());
    }

    #[test]
    fn position_sign_flip_fails(c in strong_case(1)) {
        prop_assume!(position_gradient(&c).length() > 1e-2);
        let good = vjp(c.degree, c.centre);
        let broken = |x: &[f32], w: &[f32]| {
            let mut g = good(x, w);
            g[SH_FLOATS..].iter_mut().for_each(|v| *v = -*v);
            g
        };
        prop_assert!(!check_with(&c, broken, &SH_TOL).passed());
    }
}

// ---------------------------------------------------------------------------------------------
// Tolerance measurement (ignored by default).

use bbsplat::gradcheck::WorstObserved as Worst;

#[test]
#[ignore = "measurement: run with --ignored --nocapture"]
fn measure_tolerances() {
    let probe = GradTolerance {
        atol: 1e-5,
        rtol: 1e-4,
        ..SH_TOL
    };
    let seeds: u64 = std::env::var("BBSPLAT_MEASURE_SEEDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(64);
    let (mut worst, mut worst_near) = (Worst::default(), Worst::default());
    for seed in 0..seeds {
        let config = ProptestConfig {
            rng_seed: RngSeed::Fixed(1000 + seed),
            ..strategies::seeded_config(256)
        };
        let mut runner = TestRunner::new(config);
        for _ in 0..256 {
            let c = case().new_tree(&mut runner).unwrap().current();
            worst.add(&check_with(&c, vjp(c.degree, c.centre), &probe));
            let c = near_case().new_tree(&mut runner).unwrap().current();
            worst_near.add(&check_near(&c, &probe));
        }
    }
    println!("sh, probe atol 1e-5 rtol 1e-4: {worst:?}");
    println!("sh near, probe atol 1e-5 rtol 1e-4: {worst_near:?}");
}

proptest! {
    #![proptest_config(strategies::seeded_config(512))]

    /// The interleaved batch of four colours equals four separate calls bit for bit, including
    /// lanes at the camera (degenerate direction: fewer coefficients, the per-lane fallback),
    /// clamped channels and directions 1e4 away.
    #[test]
    fn batched_colours_equal_single_colours_bit_for_bit(
        degree in 0u32..=3,
        lanes in proptest::array::uniform4((
            proptest::collection::vec(-4.0f32..1.0, 3),
            proptest::collection::vec(-0.5f32..0.5, SH_FLOATS - 3),
            strategies::direction(),
            prop_oneof![1 => Just(0.0f32), 1 => 0.0f32..1e-3, 6 => 0.1f32..1e4],
        )),
    ) {
        let centre = Vec3::new(0.5, -1.0, 2.0);
        let coeffs: Vec<Vec<f32>> = lanes.iter().map(|(dc, rest, _, _)| dc.iter().chain(rest).copied().collect()).collect();
        let positions: [Vec3; 4] = std::array::from_fn(|l| centre + lanes[l].2 * lanes[l].3);
        let batch = sh_colour_batch(degree, std::array::from_fn(|l| coeffs[l].as_slice()), positions.map(|p| p - centre));
        for l in 0..4 {
            let single = sh_colour(degree, &coeffs[l], positions[l] - centre);
            prop_assert_eq!(batch[l].rgb.to_array().map(f32::to_bits), single.rgb.to_array().map(f32::to_bits), "lane {}", l);
            prop_assert_eq!(batch[l].clamped, single.clamped, "lane {}", l);
        }
    }

    /// The rasterizer's backward passes the clamp flags its forward kept to
    /// `sh_colour_vjp_clamped`: it must give `sh_colour_vjp`'s bits for every degree, with
    /// clamped channels (DC down to −4), at the camera position (degenerate direction) and far
    /// away.
    #[test]
    fn clamped_vjp_equals_the_full_vjp_bit_for_bit(
        degree in 0u32..=3,
        dc in proptest::collection::vec(-4.0f32..1.0, 3),
        rest in proptest::collection::vec(-0.5f32..0.5, SH_FLOATS - 3),
        dir in strategies::direction(),
        dist in prop_oneof![Just(0.0f32), 0.0f32..1e-3, 0.1f32..1e4],
        d_rgb in proptest::array::uniform3(-1.0f32..1.0),
    ) {
        let coeffs: Vec<f32> = dc.into_iter().chain(rest).collect();
        let (centre, d_rgb) = (Vec3::new(0.5, -1.0, 2.0), Vec3::from_array(d_rgb));
        let position = centre + dir * dist;
        let clamped = sh_colour(degree, &coeffs, position - centre).clamped;
        let (mut a, mut b) = (vec![0.25f32; SH_FLOATS], vec![0.25f32; SH_FLOATS]);
        let dp_a = sh_colour_vjp_clamped(degree, &coeffs, position - centre, clamped, d_rgb, &mut a);
        let dp_b = sh_colour_vjp(degree, &coeffs, position - centre, d_rgb, &mut b);
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        prop_assert_eq!(bits(&dp_a.to_array()), bits(&dp_b.to_array()));
        prop_assert_eq!(bits(&a), bits(&b));
    }
}

/// A float drawn to exercise rounding and the special values: mostly ordinary magnitudes of
/// both signs, sometimes ±0, a subnormal, a huge value, ±∞ or a NaN with a payload.
fn any_float(rng: &mut Rng) -> f32 {
    match rng.below(24) {
        0 => -0.0,
        1 => 0.0,
        2 => f32::from_bits(0x0000_0123 | (rng.below(2) as u32) << 31),
        3 => 3.0e38 * if rng.below(2) == 0 { 1.0 } else { -1.0 },
        4 => f32::INFINITY,
        5 => f32::NEG_INFINITY,
        6 => f32::from_bits(0x7fc0_0000 | rng.below(1 << 22) as u32 | (rng.below(2) as u32) << 31),
        _ => rng.range(-3.0, 3.0) * 10f32.powi(rng.below(7) as i32 - 3),
    }
}

/// The bits of each float, every NaN mapped to one value: Rust leaves the payload of a NaN
/// result unspecified (the compiler may swap the operands of a commutative operation), so
/// only "is NaN" is comparable there.
fn bits(v: &[f32]) -> Vec<u32> {
    v.iter()
        .map(|x| if x.is_nan() { u32::MAX } else { x.to_bits() })
        .collect()
}

/// The dispatched coefficient pass (SSE on x86-64) equals the scalar reference bit for bit,
/// for every count of basis functions (whole groups of four and remainders), on ordinary
/// and special inputs, and reads or writes nothing past `3n` floats.
#[test]
fn coefficient_pass_equals_the_scalar_reference_bit_for_bit() {
    let seed = 0x5eed_c0ef;
    let mut rng = Rng::new(seed);
    for case in 0..4000 {
        let n = case % 17;
        let coeffs: Vec<f32> = (0..3 * n).map(|_| any_float(&mut rng)).collect();
        let basis: [f32; 16] = std::array::from_fn(|_| any_float(&mut rng));
        let g = [0; 3].map(|_| any_float(&mut rng));
        let start: Vec<f32> = (0..3 * n + 5).map(|_| any_float(&mut rng)).collect();
        let (mut d_fast, mut d_ref) = (start.clone(), start.clone());
        let (mut db_fast, mut db_ref) = ([7.0f32; 16], [7.0f32; 16]);
        coefficient_pass(n, &coeffs, &basis, g, &mut d_fast, &mut db_fast);
        coefficient_pass_scalar(n, &coeffs, &basis, g, &mut d_ref, &mut db_ref);
        assert_eq!(
            bits(&d_fast),
            bits(&d_ref),
            "d_coeffs, case {case}, n = {n}, seed {seed:#x}"
        );
        assert_eq!(
            bits(&db_fast),
            bits(&db_ref),
            "d_basis, case {case}, n = {n}, seed {seed:#x}"
        );
        assert_eq!(bits(&d_fast[3 * n..]), bits(&start[3 * n..]), "past 3n, case {case}");
    }
}

/// More basis functions than the 16 of degree 3 are refused before any read (the SSE pass
/// loads four basis values at a time from the 16-value array).
#[test]
#[should_panic(expected = "at most 16 basis functions")]
fn coefficient_pass_refuses_more_than_16_basis_functions() {
    let (coeffs, mut d) = ([0.5f32; 60], [0.0f32; 60]);
    coefficient_pass(20, &coeffs, &[0.25; 16], [1.0; 3], &mut d, &mut [0.0; 16]);
}

/// The dispatched batched raw colours (SSE on x86-64) equal the scalar reference bit for
/// bit, for every count of basis functions, batch sizes 1 and 4, coefficient slices of
/// exactly `3n` floats (the last row cannot be read four floats wide) and longer ones.
#[test]
fn raw_colours_equal_the_scalar_reference_bit_for_bit() {
    let seed = 0x5eed_c010;
    let mut rng = Rng::new(seed);
    for case in 0..4000 {
        let n = case % 17;
        let extra = rng.below(3) as usize;
        let store: Vec<Vec<f32>> = (0..4)
            .map(|_| (0..3 * n + extra).map(|_| any_float(&mut rng)).collect())
            .collect();
        let basis: [[f32; 16]; 4] = std::array::from_fn(|_| std::array::from_fn(|_| any_float(&mut rng)));
        let coeffs = [0, 1, 2, 3].map(|l| store[l].as_slice());
        let fast = raw_colours(n, coeffs, &basis);
        let reference = raw_colours_scalar(n, coeffs, &basis);
        for l in 0..4 {
            assert_eq!(
                bits(&fast[l]),
                bits(&reference[l]),
                "case {case}, n = {n}, lane {l}, seed {seed:#x}"
            );
        }
        let one = raw_colours(n, [coeffs[2]], &[basis[2]]);
        assert_eq!(bits(&one[0]), bits(&reference[2]), "a batch of one, case {case}");
    }
}
