//! Quaternion → rotation: FD gradient property, invariants, broken backwards, hard cases.
//!
//! Tolerances were measured with `cargo test --release --test suite stage_rotation:: -- --ignored
//! --nocapture measure` (worst case over 40 seeds × 256 cases per property); the numbers are in
//! `docs/numerics-geometry.md` and next to each constant.

use bbsplat::gradcheck::{GradReport, GradTolerance, StepRule, check_vjp};
use bbsplat::stages::rotation::{QUAT_NORM_SQ_MIN, quat_to_rotation, quat_to_rotation_vjp};
use bbsplat::strategies::{quaternion, seeded_config, unit_quaternion};
use glam::Mat3;
use glam::Vec3;
use proptest::prelude::*;
use proptest::strategy::ValueTree;
use proptest::test_runner::{RngSeed, TestRunner};

/// FD tolerance for `quat_to_rotation_vjp` (step `3e-3·|q|`, see [`step_for`]; `atol` is scaled by
/// `max(1, 1/|q|)` like the gradient, see [`tolerance_for`]). Measured worst over 40 seeds × 256
/// cases, both properties: elementwise ratio 0.28 of this tolerance, rel L2 8.7e-4, 1 − cos
/// 3.8e-7, |bias| 4.9e-4. Chosen: atol 5e-4, rtol 5e-3 (elementwise 3.6× the worst observed),
/// rel L2 3e-3 (3.4×), 1 − cos 2e-6 (5.3×), bias 2e-3 (4.1×). A 1 % scale error (rel L2 = bias =
/// 1e-2) stays well outside.
const ROTATION_TOL: GradTolerance = GradTolerance {
    atol: 5e-4,
    rtol: 5e-3,
    max_rel_l2: 3e-3,
    min_cosine: 1.0 - 2e-6,
    max_bias: 2e-3,
};

/// Orthonormality budget: max |RᵀR − I| and |det R − 1|. Measured worst over 40 seeds × 256 raw
/// quaternions (norms 0.05-20): 1.07e-6 (orthonormality) and 1.13e-6 (determinant), i.e. ~9 ulps
/// of 1. Chosen: 4e-6 (3.5×).
const ORTHONORMAL_TOL: f32 = 4e-6;

fn forward(x: &[f32]) -> Vec<f32> {
    quat_to_rotation([x[0], x[1], x[2], x[3]]).to_cols_array().to_vec()
}

fn vjp(x: &[f32], w: &[f32]) -> Vec<f32> {
    let d = Mat3::from_cols_array(&w.try_into().expect("nine weights"));
    quat_to_rotation_vjp([x[0], x[1], x[2], x[3]], d).to_vec()
}

fn norm(q: [f32; 4]) -> f64 {
    q.iter().map(|&c| c as f64 * c as f64).sum::<f64>().sqrt()
}

/// FD step `3e-3·|q|`: the rotation is a function of `q/|q|`, so the step scales with `|q|`. The
/// value balances f32 rounding noise (the entries of R carry ~1e-6 absolute error, which a step of
/// `1e-3·|q|` amplifies to a relative gradient error of ~3e-3) against truncation error (also
/// ~3e-3 at `1e-2·|q|`); measured optimum near `3e-3·|q|`.
fn step_for(q: [f32; 4]) -> StepRule {
    StepRule::absolute(3e-3 * norm(q))
}

/// [`ROTATION_TOL`] with the absolute tolerance scaled like the gradient, `∝ 1/|q|`.
fn tolerance_for(q: [f32; 4]) -> GradTolerance {
    GradTolerance {
        atol: ROTATION_TOL.atol * (1.0 / norm(q)).max(1.0),
        ..ROTATION_TOL
    }
}

fn check(q: [f32; 4], seed: u64, backward: impl Fn(&[f32], &[f32]) -> Vec<f32>) -> GradReport {
    check_vjp(&q, forward, backward, seed, step_for(q), &tolerance_for(q))
}

/// Raw quaternions with norms log-uniform in `[0.05, 20]`.
fn wide_quaternion() -> impl Strategy<Value = [f32; 4]> {
    (unit_quaternion(), -3.0f32..3.0).prop_map(|(q, e)| q.map(|c| c * e.exp()))
}

fn orthonormality_error(r: Mat3) -> (f32, f32) {
    let e = r.transpose() * r - Mat3::IDENTITY;
    let ortho = e.to_cols_array().iter().fold(0.0f32, |m, v| m.max(v.abs()));
    (ortho, (r.determinant() - 1.0).abs())
}

proptest! {
    #![proptest_config(seeded_config(256))]

    #[test]
    fn gradient_matches_finite_differences(q in quaternion(), seed in any::<u64>()) {
        let r = check(q, seed, vjp);
        prop_assert!(r.passed(), "q = {q:?}: {r}");
    }

    #[test]
    fn gradient_matches_finite_differences_wide_norms(q in wide_quaternion(), seed in any::<u64>()) {
        let r = check(q, seed, vjp);
        prop_assert!(r.passed(), "q = {q:?}: {r}");
    }

    #[test]
    fn rotation_is_orthonormal_with_det_one(q in wide_quaternion()) {
        let (ortho, det) = orthonormality_error(quat_to_rotation(q));
        prop_assert!(ortho <= ORTHONORMAL_TOL && det <= ORTHONORMAL_TOL, "q = {q:?}: {ortho:e} {det:e}");
    }

    #[test]
    fn rotation_ignores_norm_and_sign(q in quaternion(), s in 0.1f32..10.0) {
        let r = quat_to_rotation(q);
        for q2 in [q.map(|c| c * s), q.map(|c| -c)] {
            let d = (quat_to_rotation(q2) - r).to_cols_array().iter().fold(0.0f32, |m, v| m.max(v.abs()));
            prop_assert!(d <= 1e-6, "{q:?} vs {q2:?}: {d:e}");
        }
    }

    #[test]
    fn gradient_is_tangential(q in wide_quaternion(), seed in any::<u64>()) {
        let w = bbsplat::gradcheck::random_weights(9, seed).iter().map(|&v| v as f32).collect::<Vec<_>>();
        let g = vjp(&q, &w);
        let n = q.iter().map(|c| c * c).sum::<f32>().sqrt();
        let gn = g.iter().map(|c| c * c).sum::<f32>().sqrt();
        let radial: f32 = g.iter().zip(q).map(|(a, b)| a * b / n).sum();
        prop_assert!(radial.abs() <= 1e-5 * gn.max(1.0), "radial {radial:e} vs |g| {gn:e}");
    }

    #[test]
    fn matches_hamilton_product_f64(q in wide_quaternion()) {
        // Independent convention check from the definition, in f64: column j of R is the basis
        // vector e_j rotated as the vector part of q·e_j·q̄ / |q|², with q = (w, x, y, z) and the
        // Hamilton product (no closed-form matrix involved). Elementwise |ours − it| ≤ 1e-6.
        let qd = q.map(|c| c as f64);
        let norm_sq: f64 = qd.iter().map(|c| c * c).sum();
        let conj = [qd[0], -qd[1], -qd[2], -qd[3]];
        let r = quat_to_rotation(q);
        for j in 0..3 {
            let mut e = [0.0f64; 4];
            e[j + 1] = 1.0;
            let rotated = hamilton(hamilton(qd, e), conj);
            prop_assert!(rotated[0].abs() <= 1e-9 * norm_sq, "scalar part {}", rotated[0]);
            for i in 0..3 {
                let expected = rotated[i + 1] / norm_sq;
                let ours = r.col(j)[i] as f64;
                prop_assert!((ours - expected).abs() <= 1e-6, "R[{i}][{j}] = {ours} vs {expected} for q = {q:?}");
            }
        }
    }
}

/// Hamilton product of quaternions stored as (w, x, y, z).
fn hamilton(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    [
        a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
        a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
        a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
        a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
    ]
}

/// Fraction of `cases` random quaternions for which `backward` fails the FD check.
fn failure_rate(backward: impl Fn(&[f32], &[f32]) -> Vec<f32> + Copy, cases: u32) -> f64 {
    let mut runner = TestRunner::new(seeded_config(cases));
    let failed = (0..cases)
        .filter(|&i| {
            let q = quaternion().new_tree(&mut runner).unwrap().current();
            !check(q, i as u64, backward).passed()
        })
        .count();
    failed as f64 / cases as f64
}

#[test]
fn broken_backward_sign_flip_fails() {
    let broken = |x: &[f32], w: &[f32]| {
        let mut g = vjp(x, w);
        g[2] = -g[2];
        g
    };
    let rate = failure_rate(broken, 64);
    assert!(rate >= 0.95, "sign flip caught in only {:.0}% of cases", rate * 100.0);
}

#[test]
fn broken_backward_missing_normal_column_fails() {
    // Forgets the contribution of the third column (the normal).
    let broken = |x: &[f32], w: &[f32]| {
        let mut w = w.to_vec();
        w[6..9].fill(0.0);
        vjp(x, &w)
    };
    let rate = failure_rate(broken, 64);
    assert!(
        rate >= 0.95,
        "missing term caught in only {:.0}% of cases",
        rate * 100.0
    );
}

#[test]
fn broken_backward_missing_normalisation_fails() {
    // Treats the quaternion as unit: forgets the 1/|q| factor of the normalisation.
    let broken = |x: &[f32], w: &[f32]| {
        let n = x.iter().map(|c| c * c).sum::<f32>().sqrt();
        vjp(x, w).into_iter().map(|g| g * n).collect()
    };
    let rate = failure_rate(broken, 64);
    assert!(
        rate >= 0.95,
        "missing 1/|q| caught in only {:.0}% of cases",
        rate * 100.0
    );
}

#[test]
fn broken_backward_one_percent_scale_fails() {
    let broken = |x: &[f32], w: &[f32]| vjp(x, w).into_iter().map(|g| g * 1.01).collect();
    let rate = failure_rate(broken, 64);
    assert_eq!(rate, 1.0, "a 1% scale error must always fail");
}

#[test]
fn near_zero_quaternion_gives_identity_and_zero_gradient() {
    let tiny = (QUAT_NORM_SQ_MIN * 0.25).sqrt(); // |q|² = QUAT_NORM_SQ_MIN / 4 · (1 component)
    let d = Mat3::from_cols_array(&[0.3, -1.0, 0.5, 2.0, 0.1, -0.7, 0.9, 0.4, -0.2]);
    for q in [
        [0.0; 4],
        [tiny, 0.0, 0.0, 0.0],
        [0.0, tiny, -tiny, 0.0],
        [-0.0, 0.0, 0.0, -tiny],
        [1e-30; 4],
    ] {
        assert_eq!(quat_to_rotation(q), Mat3::IDENTITY, "{q:?}");
        assert_eq!(quat_to_rotation_vjp(q, d), [0.0; 4], "{q:?}");
    }
    // Just above the threshold: a proper rotation and a finite gradient of size ~1/|q| ≤ 1e4·|d|.
    let c = (QUAT_NORM_SQ_MIN * 1.01 / 4.0).sqrt();
    let q = [c, -c, c, c];
    let (ortho, det) = orthonormality_error(quat_to_rotation(q));
    assert!(ortho <= ORTHONORMAL_TOL && det <= ORTHONORMAL_TOL);
    let g = quat_to_rotation_vjp(q, d);
    assert!(g.iter().all(|v| v.is_finite()), "{g:?}");
    let gn = g.iter().map(|v| v * v).sum::<f32>().sqrt();
    assert!(gn > 0.0 && gn < 1e4 * 4.0 * 3.0, "{gn}");
    // The gradient there still matches finite differences (step relative to |q|).
    let r = check(q, 7, vjp);
    assert!(r.passed(), "{r}");
}

#[test]
fn non_finite_quaternion_is_identity_never_nan() {
    let d = Mat3::from_cols_array(&[1.0; 9]);
    for q in [
        [f32::NAN, 0.0, 0.0, 1.0],
        [1.0, f32::INFINITY, 0.0, 0.0],
        [f32::NEG_INFINITY; 4],
        [1e30, 1e30, 0.0, 0.0], // |q|² overflows to +inf
    ] {
        assert_eq!(quat_to_rotation(q), Mat3::IDENTITY, "{q:?}");
        assert_eq!(quat_to_rotation_vjp(q, d), [0.0; 4], "{q:?}");
    }
    // A NaN upstream gradient propagates (it is the caller's bug), but never panics.
    let g = quat_to_rotation_vjp([1.0, 0.0, 0.0, 0.0], Mat3::from_cols_array(&[f32::NAN; 9]));
    assert!(g.iter().all(|v| v.is_nan()));
}

#[test]
fn large_but_finite_quaternion_is_fine() {
    let q = [3e18, -1e18, 2e18, 0.5e18]; // |q|² ≈ 1.4e37 < f32::MAX
    let (ortho, det) = orthonormality_error(quat_to_rotation(q));
    assert!(ortho <= ORTHONORMAL_TOL && det <= ORTHONORMAL_TOL);
    let g = quat_to_rotation_vjp(q, Mat3::IDENTITY);
    assert!(g.iter().all(|v| v.is_finite()));
}

/// Prints the worst FD errors and orthonormality errors over many seeds (for the docs).
#[test]
#[ignore = "measurement run, see docs/numerics-geometry.md"]
fn measure_tolerances() {
    let (seeds, cases) = (40u64, 256u32);
    for (name, wide) in [("quaternion()", false), ("wide norms", true)] {
        let (mut ratio, mut l2, mut cos, mut bias, mut ortho, mut det) = (0f64, 0f64, 0f64, 0f64, 0f32, 0f32);
        for s in 0..seeds {
            let mut cfg = seeded_config(cases);
            cfg.rng_seed = RngSeed::Fixed(1000 + s);
            let mut runner = TestRunner::new(cfg);
            for i in 0..cases {
                let q = if wide {
                    wide_quaternion().new_tree(&mut runner).unwrap().current()
                } else {
                    quaternion().new_tree(&mut runner).unwrap().current()
                };
                let r = check(q, s * 10_000 + i as u64, vjp);
                ratio = ratio.max(r.worst_ratio);
                l2 = l2.max(r.rel_l2);
                cos = cos.max(1.0 - r.cosine);
                bias = bias.max(r.bias.abs());
                let (o, d) = orthonormality_error(quat_to_rotation(q));
                ortho = ortho.max(o);
                det = det.max(d);
            }
        }
        println!(
            "rotation [{name}]: worst elementwise ratio {ratio:.3e}, rel L2 {l2:.3e}, 1-cos {cos:.3e}, \
             |bias| {bias:.3e}; orthonormality {ortho:.3e}, |det-1| {det:.3e}"
        );
    }
}

#[test]
fn identity_quaternion_is_identity() {
    assert_eq!(quat_to_rotation([3.0, 0.0, 0.0, 0.0]), Mat3::IDENTITY);
}

#[test]
fn threshold_is_a_clean_switch() {
    let below = (QUAT_NORM_SQ_MIN * 0.9).sqrt();
    let above = (QUAT_NORM_SQ_MIN * 1.1).sqrt();
    assert_eq!(quat_to_rotation([0.0, below, 0.0, 0.0]), Mat3::IDENTITY);
    let r = quat_to_rotation([0.0, above, 0.0, 0.0]);
    // 180° about x.
    assert!((r.y_axis + Vec3::Y).length() < 1e-6 && (r.z_axis + Vec3::Z).length() < 1e-6);
}
