//! Regularisers and the Gaussian-billboard opacity chain against central finite differences
//! (`bbsplat::gradcheck`, f64 differences around the f32 kernels).
//!
//! Every check is paired with a deliberately broken gradient that must fail.
//!
//! Tolerances: the default [`GradTolerance`] (elementwise `1e-4 + 1e-2·max`, relative L2 `2e-3`,
//! cosine `0.99999`, bias `2e-3`). Measured worst over the 20 seeds of each check (printed by the
//! tests): texture + opacity regulariser elementwise ratio 0.006, rel-L2 8.2e-5, bias 1.3e-5;
//! Gaussian chain ratio 0.09, rel-L2 1.5e-4, bias 1.2e-4. The defaults are 10-25× above the worst
//! observed values, and the broken variants fail them.

use bbsplat::billboards::planar_textures;
use bbsplat::gradcheck::{GradReport, GradTolerance, StepRule, WorstObserved, check_vjp, compare, numerical_gradient};
use bbsplat::model::{initial_alpha, sigmoid};
use bbsplat::rng::Rng;
use bbsplat::train::regularise::{
    TextureTerm, chain_sigmoid, gaussian_alpha, gaussian_opacity_grad, opacity_regulariser, regularise,
    texture_regulariser,
};

const TS: usize = 4;
const T: usize = TS * TS;
const N: usize = 5;
/// λ and σ chosen so that λ·w_i ≤ 1: loss and gradients O(1), where the absolute tolerance means
/// something (the trainer's λ = 1e-4 only rescales).
const SIGMA: f32 = 500.0;
const LAMBDA_TEX: f32 = 1.0 / 500.0;
const LAMBDA_OP: f32 = 0.5;

struct Case {
    /// Alpha logits (`N·T`) then colour logits (`3·N·T`).
    x: Vec<f32>,
    impact: Vec<f32>,
    alpha0: Vec<f32>,
    mask: Vec<bool>,
}

/// Planar activated alpha (`N·T`) and colour (`3·N·T`, `[billboard][channel][texel]`).
fn activate(case: &Case, x: &[f32]) -> (Vec<f32>, Vec<f32>) {
    let alpha = (0..N * T)
        .map(|k| if case.mask[k % T] { sigmoid(x[k]) } else { 0.0 })
        .collect();
    let colour = x[N * T..].iter().map(|&v| sigmoid(v)).collect();
    (alpha, colour)
}

/// The rasterizer's RGBA texels of planar alpha and colour.
fn rgba(alpha: &[f32], colour: &[f32]) -> Vec<[f32; 4]> {
    (0..N * T)
        .map(|j| {
            let (i, k) = (j / T, j % T);
            let c = |ch: usize| colour[i * 3 * T + ch * T + k];
            [c(0), c(1), c(2), alpha[j]]
        })
        .collect()
}

fn loss(case: &Case, x: &[f32]) -> f64 {
    let (alpha, colour) = activate(case, x);
    let tex = rgba(&alpha, &colour);
    let mut d = vec![[0.0; 4]; N * T];
    texture_regulariser(&tex, &case.alpha0, &case.impact, SIGMA, LAMBDA_TEX, &mut d)
        + opacity_regulariser(&tex, T, LAMBDA_OP, &mut d)
}

/// Analytic gradient wrt the logits. `broken` selects a deliberate mistake.
fn analytic(case: &Case, broken: Option<&str>) -> Vec<f64> {
    let (alpha, colour) = activate(case, &case.x);
    let tex = rgba(&alpha, &colour);
    let mut d = vec![[0.0; 4]; N * T];
    texture_regulariser(&tex, &case.alpha0, &case.impact, SIGMA, LAMBDA_TEX, &mut d);
    opacity_regulariser(&tex, T, LAMBDA_OP, &mut d);
    let (da, dc) = planar_textures(&d, T);
    let mut out = vec![0.0f32; 4 * N * T];
    let (oa, oc) = out.split_at_mut(N * T);
    if broken == Some("ignore mask") {
        // Chaining through sigmoid(logit) without the mask: masked texels get a gradient.
        let unmasked: Vec<f32> = case.x[..N * T].iter().map(|&v| sigmoid(v)).collect();
        chain_sigmoid(&unmasked, &da, None, oa);
    } else {
        chain_sigmoid(&alpha, &da, Some(&case.mask), oa);
    }
    chain_sigmoid(&colour, &dc, None, oc);
    if broken == Some("mean over all billboards") {
        // Normalising the texture term by N instead of |vis|: rescale the colour part.
        let vis = case.impact.iter().filter(|&&i| i > 0.0).count() as f32;
        for g in oc.iter_mut() {
            *g *= vis / N as f32;
        }
    }
    out.iter().map(|&g| g as f64).collect()
}

fn make_case(seed: u64) -> Case {
    let mut rng = Rng::new(seed);
    let alpha0 = initial_alpha(TS);
    let mask: Vec<bool> = alpha0.iter().map(|&a| a > 0.0).collect();
    loop {
        let x: Vec<f32> = (0..4 * N * T).map(|_| rng.range(-3.0, 3.0)).collect();
        // Billboard 0 unseen, 1 above σ (unregularised), the others weakly visible.
        let impact = vec![
            0.0,
            650.0,
            rng.range(1.0, 480.0),
            rng.range(1.0, 480.0),
            rng.range(1.0, 480.0),
        ];
        let case = Case {
            x,
            impact,
            alpha0: alpha0.clone(),
            mask: mask.clone(),
        };
        // Stay away from the kink of |mean(alpha − A0)| (an f32 step of 1e-3 moves the mean by
        // far less than 1e-2).
        let (alpha, _) = activate(&case, &case.x);
        let far = (0..N).all(|i| {
            let m: f32 = (0..T).map(|k| alpha[i * T + k] - case.alpha0[k]).sum::<f32>() / T as f32;
            m.abs() > 1e-2
        });
        if far {
            return case;
        }
    }
}

fn check(case: &Case, broken: Option<&str>) -> GradReport {
    let indices: Vec<usize> = (0..case.x.len()).collect();
    let numeric = numerical_gradient(|x| loss(case, x), &case.x, &indices, StepRule::default());
    compare(&analytic(case, broken), &numeric, &GradTolerance::default())
}

#[test]
fn regularisers_match_finite_differences() {
    let mut worst = WorstObserved::default();
    for seed in 0..20 {
        let case = make_case(seed);
        let r = check(&case, None);
        assert!(r.passed(), "seed {seed}: {r}");
        worst.add(&r);
    }
    eprintln!("texture + opacity regulariser, worst over 20 seeds: {worst:?}");
}

#[test]
fn regulariser_check_rejects_an_ignored_alpha_mask() {
    let case = make_case(3);
    let r = check(&case, Some("ignore mask"));
    assert!(!r.passed(), "seed 3: a gradient on masked texels must fail: {r}");
}

#[test]
fn regulariser_check_rejects_the_wrong_normaliser() {
    let case = make_case(4);
    let r = check(&case, Some("mean over all billboards"));
    assert!(!r.passed(), "seed 4: normalising by N instead of |vis| must fail: {r}");
}

fn gaussian_check(seed: u64, broken: bool) -> GradReport {
    let mut rng = Rng::new(seed);
    let shape: Vec<f32> = initial_alpha(TS).iter().map(|&a| 2.0 * a).collect();
    let omega: Vec<f32> = (0..N).map(|_| rng.range(-3.0, 3.0)).collect();
    let forward = |w: &[f32]| gaussian_alpha(w, &shape);
    let vjp = |w: &[f32], cot: &[f32]| -> Vec<f32> {
        (0..w.len())
            .map(|i| {
                let d: Vec<[f32; 4]> = cot[i * T..(i + 1) * T].iter().map(|&a| [0.0, 0.0, 0.0, a]).collect();
                let g = gaussian_opacity_grad(w[i], &d, &shape);
                if broken {
                    // Forgetting the sigmoid's derivative o(1 − o).
                    let o = sigmoid(w[i]);
                    g / (o * (1.0 - o))
                } else {
                    g
                }
            })
            .collect()
    };
    check_vjp(
        &omega,
        forward,
        vjp,
        seed,
        StepRule::default(),
        &GradTolerance::default(),
    )
}

#[test]
fn gaussian_opacity_chain_matches_finite_differences() {
    let mut worst = WorstObserved::default();
    for seed in 0..20 {
        let r = gaussian_check(seed, false);
        assert!(r.passed(), "seed {seed}: {r}");
        worst.add(&r);
    }
    eprintln!("Gaussian opacity chain, worst over 20 seeds: {worst:?}");
}

#[test]
fn gaussian_check_rejects_a_missing_sigmoid_derivative() {
    let r = gaussian_check(7, true);
    assert!(!r.passed(), "seed 7: {r}");
}

#[test]
fn empty_visibility_is_zero_not_nan() {
    let t = 4;
    let tex = vec![[0.2, 0.2, 0.2, 0.3]; 2 * t];
    let mut d = vec![[0.0; 4]; 2 * t];
    let v = texture_regulariser(&tex, &[0.1; 4], &[0.0, 0.0], 500.0, 1e-4, &mut d);
    assert_eq!(v, 0.0);
    assert!(d.iter().flatten().all(|&g| g == 0.0));
    assert_eq!(opacity_regulariser(&[], 16, 0.01, &mut []), 0.0);
}

#[test]
fn strongly_visible_billboards_are_not_regularised() {
    let t = 4;
    let tex = vec![[0.2, 0.2, 0.2, 0.3]; 2 * t];
    let mut d = vec![[0.0; 4]; 2 * t];
    // Billboard 0 at impact 600 ≥ σ: weight 0. Billboard 1 at 100: weight 400, |vis| = 2.
    let v = texture_regulariser(&tex, &[0.1; 4], &[600.0, 100.0], 500.0, 1e-4, &mut d);
    let expected = 1e-4 * (0.2 + 0.2) * 400.0 / 2.0;
    assert!((v - expected).abs() < 1e-9, "{v} vs {expected}");
    assert!(d[..t].iter().flatten().all(|&g| g == 0.0));
    assert!(d[t..].iter().flatten().all(|&g| g > 0.0));
}

/// The fused pass gives the bits of the two regularisers one after the other: every gradient
/// (added onto random starting values, signed zeros among them) and both values, on billboards
/// below, at and above the threshold and not visible; also with either term off. The starting
/// values are of the size of the additions, so that their order shows in the bits (adding the
/// opacity term first was tried and fails this test).
#[test]
fn the_fused_pass_equals_the_two_regularisers_in_turn() {
    let (t, n) = (16, 9);
    let mut rng = Rng::new(41);
    let tex: Vec<[f32; 4]> = (0..n * t).map(|_| std::array::from_fn(|_| rng.uniform())).collect();
    let start: Vec<[f32; 4]> = (0..n * t)
        .map(|k| {
            std::array::from_fn(|c| {
                if (k + c) % 5 == 0 {
                    -0.0
                } else {
                    (rng.uniform() - 0.5) * 1e-3
                }
            })
        })
        .collect();
    let alpha0: Vec<f32> = (0..t).map(|k| 0.05 * k as f32).collect();
    let impact = [0.0, 12.0, 499.0, 500.0, 800.0, 0.5, 250.0, -1.0, 60.0];
    let term = TextureTerm {
        alpha0: &alpha0,
        impact: &impact,
        threshold: 500.0,
        weight: 1e-4,
    };
    let bits = |d: &[[f32; 4]]| d.iter().flatten().map(|x| x.to_bits()).collect::<Vec<_>>();
    for (with_texture, with_opacity) in [(true, true), (true, false), (false, true)] {
        let mut apart = start.clone();
        let texture_value = if with_texture {
            texture_regulariser(&tex, &alpha0, &impact, 500.0, 1e-4, &mut apart)
        } else {
            0.0
        };
        let opacity_value = if with_opacity {
            opacity_regulariser(&tex, t, 0.01, &mut apart)
        } else {
            0.0
        };
        let mut fused = start.clone();
        let values = regularise(
            &tex,
            t,
            with_texture.then_some(term),
            with_opacity.then_some(0.01),
            &mut fused,
            bbsplat::cpu::Simd::detect(),
        );
        assert_eq!(
            bits(&fused),
            bits(&apart),
            "texture {with_texture}, opacity {with_opacity}"
        );
        assert_eq!(values.texture.to_bits(), texture_value.to_bits());
        assert_eq!(values.opacity.to_bits(), opacity_value.to_bits());
        assert_ne!(bits(&fused), bits(&start), "the regularisers add something");
    }
}
