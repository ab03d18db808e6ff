//! The Adam optimiser: the first step, dense-mode decay, convergence on a quadratic.

use bbsplat::train::adam::*;

#[test]
fn first_step_moves_by_lr_against_the_gradient_sign() {
    let mut g = AdamGroup::new(2, 3);
    let mut p = [1.0f32, 2.0, 3.0];
    g.step_row(1, &mut p, &[0.5, -2.0, 0.0], 0.1, &AdamParams::default());
    assert!((p[0] - 0.9).abs() < 1e-6 && (p[1] - 2.1).abs() < 1e-6 && p[2] == 3.0);
    assert_eq!(g.steps, vec![0, 1]);
}

#[test]
fn dense_mode_decays_and_moves_an_unseen_row() {
    // After one seen step, a step with zero gradient still moves the row (PyTorch semantics),
    // by lr · (β₁·m₁ / (1 − β₁²)) / (√(β₂·v₁) / √(1 − β₂²)).
    let hp = AdamParams::default();
    let mut g = AdamGroup::new(1, 1);
    let mut p = [0.0f32];
    g.step_row_global(0, &mut p, &[1.0], 0.1, &hp, 1);
    assert!((p[0] + 0.1).abs() < 1e-6);
    g.step_row_global(0, &mut p, &[0.0], 0.1, &hp, 2);
    let (m2, v2) = (0.9 * 0.1f64, 0.999 * 0.001f64);
    let expected = -0.1 - 0.1 * (m2 / (1.0 - 0.81)) / (v2.sqrt() / (1.0 - 0.999f64 * 0.999).sqrt());
    assert!((p[0] as f64 - expected).abs() < 1e-5, "{} vs {expected}", p[0]);
    // Row-sparse mode would not have been called for the unseen row: nothing moves.
    g.reset_row(0);
    assert_eq!((g.m[0], g.v[0], g.steps[0]), (0.0, 0.0, 0));
}

#[test]
fn minimises_a_quadratic() {
    let mut g = AdamGroup::new(1, 1);
    let mut p = [5.0f32];
    for _ in 0..2000 {
        let grad = [2.0 * (p[0] - 1.5)];
        g.step_row(
            0,
            &mut p,
            &grad,
            0.01,
            &AdamParams {
                eps: 1e-8,
                ..Default::default()
            },
        );
    }
    assert!((p[0] - 1.5).abs() < 1e-2, "{}", p[0]);
}
