//! The gradient checker itself: it accepts a correct VJP and rejects broken ones.

use bbsplat::gradcheck::*;

fn forward(x: &[f32]) -> Vec<f32> {
    vec![x[0] * x[1] + x[2].exp(), (x[0] - x[2]).sin(), x[1] * x[1] * x[2]]
}

fn vjp_correct(x: &[f32], w: &[f32]) -> Vec<f32> {
    let c = (x[0] - x[2]).cos();
    vec![
        w[0] * x[1] + w[1] * c,
        w[0] * x[0] + w[2] * 2.0 * x[1] * x[2],
        w[0] * x[2].exp() - w[1] * c + w[2] * x[1] * x[1],
    ]
}

const X: [f32; 3] = [0.3, -0.8, 0.5];

#[test]
fn accepts_correct_gradient() {
    for seed in 0..20 {
        let r = check_vjp(
            &X,
            forward,
            vjp_correct,
            seed,
            StepRule::default(),
            &GradTolerance::default(),
        );
        assert!(r.passed(), "seed {seed}: {r}");
    }
}

#[test]
fn rejects_sign_flip() {
    let broken = |x: &[f32], w: &[f32]| {
        let mut g = vjp_correct(x, w);
        g[1] = -g[1];
        g
    };
    let r = check_vjp(&X, forward, broken, 3, StepRule::default(), &GradTolerance::default());
    assert!(!r.passed(), "{r}");
    assert_eq!(r.worst_index, 1, "{r}");
}

#[test]
fn rejects_missing_term() {
    // Drop the sin term's contribution to x2.
    let broken = |x: &[f32], w: &[f32]| {
        let mut g = vjp_correct(x, w);
        g[2] += w[1] * (x[0] - x[2]).cos();
        g
    };
    let r = check_vjp(&X, forward, broken, 5, StepRule::default(), &GradTolerance::default());
    assert!(!r.passed(), "{r}");
}

#[test]
fn rejects_one_percent_scale_error() {
    let broken = |x: &[f32], w: &[f32]| vjp_correct(x, w).into_iter().map(|g| g * 1.01).collect();
    for seed in 0..10 {
        let r = check_vjp(
            &X,
            forward,
            broken,
            seed,
            StepRule::default(),
            &GradTolerance::default(),
        );
        assert!(!r.passed(), "seed {seed}: a 1% scale error must fail: {r}");
        // It is the aggregate checks, not the elementwise one, that see it.
        assert!(r.worst_ratio <= 1.0 || r.rel_l2 > r.tolerance.max_rel_l2);
    }
}

#[test]
fn rejects_non_finite() {
    let broken = |x: &[f32], w: &[f32]| {
        let mut g = vjp_correct(x, w);
        g[0] = f32::NAN;
        g
    };
    let r = check_vjp(&X, forward, broken, 1, StepRule::default(), &GradTolerance::default());
    assert_eq!(r.non_finite, Some(0));
    assert!(!r.passed());
}

#[test]
fn step_is_the_representable_one() {
    // At x = 1e4 the f32 spacing is ~1e-3: the effective step must be used as divisor.
    let mut f = |x: &[f32]| x[0] as f64 * 3.0;
    let d = central_difference(&mut f, &[1.0e4], 0, StepRule::absolute(3e-4));
    assert!((d - 3.0).abs() < 1e-12, "{d}");
}

#[test]
fn directional_matches_dot_product() {
    let w = random_weights(3, 9);
    let loss = |x: &[f32]| weighted_sum(&forward(x), &w);
    let wf: Vec<f32> = w.iter().map(|&v| v as f32).collect();
    let g = vjp_correct(&X, &wf);
    let d = random_weights(3, 11);
    let dd = directional_derivative(loss, &X, &d, 1e-3);
    let dot: f64 = g.iter().zip(&d).map(|(&a, &b)| a as f64 * b).sum();
    assert!((dd - dot).abs() < 1e-4, "{dd} vs {dot}");
}

#[test]
fn all_zero_gradients_pass() {
    let r = compare(&[0.0, 0.0], &[1e-7, -1e-7], &GradTolerance::default());
    assert!(r.passed(), "{r}");
}
