//! Losses and metrics: SSIM (forward against an independent f64 reference, analytic backward
//! against finite differences, border handling, invariants), L1, PSNR and the training loss.

use bbsplat::gradcheck::{
    GradReport, GradTolerance, StepRule, check_vjp, compare, directional_derivative, numerical_gradient,
    random_weights, weighted_sum,
};
use bbsplat::loss::l1::{l1, l1_vjp};
use bbsplat::loss::psnr::{psnr, psnr_u8, quantize_u8};
use bbsplat::loss::ssim::{
    C1, C2, Padding, Precision, WINDOW_SIZE, gaussian_window, map_size, ssim, ssim_map, ssim_map_vjp, ssim_vjp,
    ssim_with_grad, ssim_with_grad_f32,
};
use bbsplat::loss::{LossError, TrainingLoss, training_loss};
use bbsplat::rng::Rng;
use bbsplat::strategies::seeded_config;
use bbsplat::testing_internals::ssim::{map_len_and_sum_grad, ssim_partials, terms};
use proptest::prelude::*;
use proptest::test_runner::TestRunner;
use std::sync::Mutex;

// ---------------------------------------------------------------------------------------------
// An independent reference: direct 11×11 window sums in f64, no separability, no shared code.
// ---------------------------------------------------------------------------------------------

fn reference_window() -> [f64; 11] {
    let raw: Vec<f64> = (0..11)
        .map(|k| (-((k as f64 - 5.0).powi(2)) / (2.0 * 1.5 * 1.5)).exp())
        .collect();
    let sum: f64 = raw.iter().sum();
    std::array::from_fn(|k| raw[k] / sum)
}

/// Map size and centre offset of the reference.
fn reference_geometry(w: usize, h: usize, padding: Padding) -> (usize, usize, i64) {
    match padding {
        Padding::Same => (w, h, 0),
        Padding::Valid => (w - 10, h - 10, 5),
    }
}

/// One SSIM map value (map pixel `(ox, oy)`, channel `ch`) by direct summation over the 2-D
/// window in f64, zero outside the image.
#[allow(clippy::too_many_arguments)]
fn reference_value(
    a: &[f64],
    b: &[f32],
    w: usize,
    h: usize,
    c: usize,
    off: i64,
    ox: usize,
    oy: usize,
    ch: usize,
) -> f64 {
    let g = reference_window();
    let (mut ma, mut mb, mut saa, mut sbb, mut sab) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for dy in 0..11i64 {
        for dx in 0..11i64 {
            let (y, x) = (oy as i64 + off + dy - 5, ox as i64 + off + dx - 5);
            if x < 0 || y < 0 || x >= w as i64 || y >= h as i64 {
                continue;
            }
            let i = (y as usize * w + x as usize) * c + ch;
            let (va, vb) = (a[i], b[i] as f64);
            let wgt = g[dy as usize] * g[dx as usize];
            ma += wgt * va;
            mb += wgt * vb;
            saa += wgt * va * va;
            sbb += wgt * vb * vb;
            sab += wgt * va * vb;
        }
    }
    let (c1, c2) = (1e-4f64, 9e-4f64);
    let (va, vb, cov) = (saa - ma * ma, sbb - mb * mb, sab - ma * mb);
    (2.0 * ma * mb + c1) * (2.0 * cov + c2) / ((ma * ma + mb * mb + c1) * (va + vb + c2))
}

/// The SSIM map in f64 by direct summation (no separability, no code shared with the crate).
fn reference_map(a: &[f32], b: &[f32], w: usize, h: usize, c: usize, padding: Padding) -> Vec<f64> {
    let a: Vec<f64> = a.iter().map(|&v| v as f64).collect();
    let (ow, oh, off) = reference_geometry(w, h, padding);
    let mut map = Vec::with_capacity(ow * oh * c);
    for oy in 0..oh {
        for ox in 0..ow {
            for ch in 0..c {
                map.push(reference_value(&a, b, w, h, c, off, ox, oy, ch));
            }
        }
    }
    map
}

/// `Σ_p weights[p]·S_p` over the map values whose window contains input value `i` (no other
/// value depends on it), with the reference `S` and the first image in f64: differences of
/// this in `x[i]` are finite differences of the weighted map loss.
#[allow(clippy::too_many_arguments)]
fn reference_local_loss(
    x: &[f64],
    b: &[f32],
    w: usize,
    h: usize,
    c: usize,
    padding: Padding,
    weights: &[f32],
    i: usize,
) -> f64 {
    let (ow, oh, off) = reference_geometry(w, h, padding);
    let (px, py, ch) = ((i / c) % w, i / c / w, i % c);
    let mut total = 0.0;
    for oy in 0..oh {
        for ox in 0..ow {
            if (ox as i64 + off - px as i64).abs() <= 5 && (oy as i64 + off - py as i64).abs() <= 5 {
                let wp = weights[(oy * ow + ox) * c + ch] as f64;
                total += wp * reference_value(x, b, w, h, c, off, ox, oy, ch);
            }
        }
    }
    total
}

fn reference_ssim(a: &[f32], b: &[f32], w: usize, h: usize, c: usize, padding: Padding) -> f64 {
    let m = reference_map(a, b, w, h, c, padding);
    m.iter().sum::<f64>() / m.len() as f64
}

// ---------------------------------------------------------------------------------------------
// Image generators.
// ---------------------------------------------------------------------------------------------

/// Three kinds of image pairs: independent noise, a near-copy (the training regime: SSIM close
/// to 1), and smooth low-contrast images (σ² ≪ C2: the worst-conditioned case).
#[derive(Clone, Copy, Debug)]
enum Kind {
    Independent,
    NearCopy,
    Smooth,
}

fn image_pair(w: usize, h: usize, c: usize, kind: Kind, seed: u64) -> (Vec<f32>, Vec<f32>) {
    let mut rng = Rng::new(seed);
    let n = w * h * c;
    match kind {
        Kind::Independent => {
            let a = (0..n).map(|_| rng.range(0.02, 0.98)).collect();
            let b = (0..n).map(|_| rng.range(0.02, 0.98)).collect();
            (a, b)
        }
        Kind::NearCopy => {
            let b: Vec<f32> = (0..n).map(|_| rng.range(0.1, 0.9)).collect();
            let a = b.iter().map(|v| v + rng.range(-0.05, 0.05)).collect();
            (a, b)
        }
        Kind::Smooth => {
            let (fa, fb, pa, pb) = (
                rng.range(0.1, 0.5),
                rng.range(0.1, 0.5),
                rng.range(0.0, 6.0),
                rng.range(0.0, 6.0),
            );
            let mut a = Vec::with_capacity(n);
            let mut b = Vec::with_capacity(n);
            for y in 0..h {
                for x in 0..w {
                    for ch in 0..c {
                        let t = x as f32 * fa + y as f32 * fb + ch as f32;
                        a.push(0.5 + 0.05 * (t + pa).sin() + rng.range(-0.005, 0.005));
                        b.push(0.45 + 0.05 * (t + pb).cos());
                    }
                }
            }
            (a, b)
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Forward: against the reference, invariants, borders.
// ---------------------------------------------------------------------------------------------

#[test]
fn forward_matches_direct_f64_reference() {
    let mut worst = 0.0f64;
    for (i, &(w, h, c)) in [(7, 9, 1), (16, 11, 3), (24, 20, 3), (11, 11, 1), (33, 17, 2)]
        .iter()
        .enumerate()
    {
        for kind in [Kind::Independent, Kind::NearCopy, Kind::Smooth] {
            let (a, b) = image_pair(w, h, c, kind, 100 + i as u64);
            for padding in [Padding::Same, Padding::Valid] {
                if padding == Padding::Valid && (w < 11 || h < 11) {
                    continue;
                }
                let want = reference_map(&a, &b, w, h, c, padding);
                let got = ssim_map(&a, &b, w, h, c, padding).unwrap();
                assert_eq!(got.len(), want.len());
                for (j, (&g, &r)) in got.iter().zip(&want).enumerate() {
                    let err = (g as f64 - r).abs();
                    worst = worst.max(err);
                    // The map is returned in f32: half an f32 ulp of a value ≤ 1 is 6e-8.
                    assert!(err < 1e-7, "{w}×{h}×{c} {kind:?} {padding:?} map[{j}]: {g} vs {r}");
                }
                let mean = ssim(&a, &b, w, h, c, padding).unwrap();
                let mean_ref = reference_ssim(&a, &b, w, h, c, padding);
                assert!((mean - mean_ref).abs() < 1e-12, "{mean} vs {mean_ref}");
            }
        }
    }
    println!("worst |map − reference| = {worst:.3e}");
}

proptest! {
    #![proptest_config(seeded_config(64))]

    /// Random shapes and contents: mean SSIM within 1e-12 of the f64 reference.
    #[test]
    fn forward_matches_reference_on_random_images(
        w in 1usize..30, h in 1usize..26, three in any::<bool>(), kind in 0usize..3, seed in any::<u64>(), valid in any::<bool>()
    ) {
        let c = if three { 3 } else { 1 };
        let padding = if valid && w >= 11 && h >= 11 { Padding::Valid } else { Padding::Same };
        let kind = [Kind::Independent, Kind::NearCopy, Kind::Smooth][kind];
        let (a, b) = image_pair(w, h, c, kind, seed);
        let got = ssim(&a, &b, w, h, c, padding).unwrap();
        let want = reference_ssim(&a, &b, w, h, c, padding);
        prop_assert!((got - want).abs() < 1e-12, "{} vs {}", got, want);
    }
}

#[test]
fn identical_images_score_one() {
    for &(w, h, c) in &[(1, 1, 1), (7, 9, 3), (40, 30, 3), (11, 11, 1)] {
        for kind in [Kind::Independent, Kind::Smooth] {
            let (a, _) = image_pair(w, h, c, kind, 7);
            for padding in [Padding::Same, Padding::Valid] {
                if let Ok(s) = ssim(&a, &a, w, h, c, padding) {
                    assert!((s - 1.0).abs() < 1e-12, "{w}×{h}×{c} {padding:?}: {s}");
                    let map = ssim_map(&a, &a, w, h, c, padding).unwrap();
                    assert!(map.iter().all(|&v| v == 1.0), "{map:?}");
                    // SSIM(x, x) is a maximum: the gradient vanishes (up to f32 rounding).
                    let g = ssim_vjp(&a, &a, w, h, c, padding, 1.0).unwrap();
                    let gmax = g.iter().fold(0.0f32, |m, v| m.max(v.abs()));
                    assert!(gmax < 1e-10, "{gmax}");
                }
            }
        }
    }
}

#[test]
fn ssim_is_symmetric() {
    for seed in 0..5 {
        let (a, b) = image_pair(19, 14, 3, Kind::Independent, seed);
        for padding in [Padding::Same, Padding::Valid] {
            // Every operation of the forward pass is symmetric in a and b, so bitwise equal.
            assert_eq!(
                ssim(&a, &b, 19, 14, 3, padding).unwrap(),
                ssim(&b, &a, 19, 14, 3, padding).unwrap()
            );
        }
    }
}

#[test]
fn valid_map_is_the_interior_of_the_same_map() {
    let (w, h, c) = (23, 17, 3);
    let (a, b) = image_pair(w, h, c, Kind::Independent, 3);
    let same = ssim_map(&a, &b, w, h, c, Padding::Same).unwrap();
    let valid = ssim_map(&a, &b, w, h, c, Padding::Valid).unwrap();
    assert_eq!(map_size(w, h, Padding::Valid).unwrap(), (w - 10, h - 10));
    for y in 0..h - 10 {
        for x in 0..w - 10 {
            for ch in 0..c {
                assert_eq!(valid[(y * (w - 10) + x) * c + ch], same[((y + 5) * w + x + 5) * c + ch]);
            }
        }
    }
    // The border makes a difference: zero padding lowers SSIM of these images near the edges.
    let s_same = ssim(&a, &b, w, h, c, Padding::Same).unwrap();
    let s_valid = ssim(&a, &b, w, h, c, Padding::Valid).unwrap();
    assert!((s_same - s_valid).abs() > 1e-4, "{s_same} {s_valid}");
}

#[test]
fn zero_padding_at_the_border_matches_closed_form() {
    // Constant images a ≡ u, b ≡ v. With zero padding a window that keeps mass m inside the
    // image sees μa = m·u, G*(a²) = m·u², so σa² = (m − m²)·u² ≠ 0 at the border; σab likewise.
    // u, v are the f32 image values, widened.
    let (w, h, u, v) = (14usize, 12usize, 0.7f32 as f64, 0.4f32 as f64);
    let a = vec![u as f32; w * h];
    let b = vec![v as f32; w * h];
    let map = ssim_map(&a, &b, w, h, 1, Padding::Same).unwrap();
    let g = reference_window();
    let mass = |i: usize, n: usize| -> f64 { (0..11).filter(|&k| (i + k) >= 5 && (i + k - 5) < n).map(|k| g[k]).sum() };
    let (c1, c2) = (C1, C2);
    for y in 0..h {
        for x in 0..w {
            let m = mass(x, w) * mass(y, h);
            let var = m - m * m;
            let s = (2.0 * m * m * u * v + c1) * (2.0 * var * u * v + c2)
                / ((m * m * (u * u + v * v) + c1) * (var * (u * u + v * v) + c2));
            let got = map[y * w + x] as f64;
            assert!((got - s).abs() < 1e-7, "({x}, {y}) m = {m}: {got} vs {s}");
            if (5..w - 5).contains(&x) && (5..h - 5).contains(&y) {
                assert!((m - 1.0).abs() < 1e-6);
            }
        }
    }
    // The corner really differs from the interior.
    assert!((map[0] - map[(h / 2) * w + w / 2]).abs() > 0.01);
    // "valid" sees no border at all: the constant SSIM (2uv + C1)/(u² + v² + C1).
    let valid = ssim(&a, &b, w, h, 1, Padding::Valid).unwrap();
    let want = (2.0 * u * v + c1) / (u * u + v * v + c1);
    assert!((valid - want).abs() < 1e-12, "{valid} vs {want}");
}

#[test]
fn shape_errors_are_reported() {
    let a = vec![0.5f32; 10 * 10 * 3];
    assert_eq!(
        ssim(&a, &a[1..], 10, 10, 3, Padding::Same),
        Err(LossError::BadLength {
            which: "b",
            expected: 300,
            got: 299
        })
    );
    assert_eq!(
        ssim(&a, &a, 10, 10, 3, Padding::Valid),
        Err(LossError::TooSmallForValid { width: 10, height: 10 })
    );
    assert!(matches!(
        ssim(&[], &[], 0, 4, 3, Padding::Same),
        Err(LossError::Empty { .. })
    ));
    let err = ssim_map_vjp(&a, &a, 10, 10, 3, Padding::Same, &[1.0; 3]).unwrap_err();
    assert!(err.to_string().contains("d_map"), "{err}");
    assert!(matches!(l1(&a, &a[..5]), Err(LossError::BadLength { .. })));
    assert!(matches!(psnr(&[], &[]), Err(LossError::Empty { .. })));
    // An 11×11 image has exactly one valid window, centred on the middle pixel.
    let (s, _) = image_pair(11, 11, 1, Kind::Independent, 1);
    let (t, _) = image_pair(11, 11, 1, Kind::Independent, 2);
    let valid = ssim_map(&s, &t, 11, 11, 1, Padding::Valid).unwrap();
    let same = ssim_map(&s, &t, 11, 11, 1, Padding::Same).unwrap();
    assert_eq!(valid, vec![same[5 * 11 + 5]]);
}

#[test]
fn results_do_not_depend_on_the_thread_count() {
    let (w, h, c) = (64, 48, 3);
    let (a, b) = image_pair(w, h, c, Kind::NearCopy, 11);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            (
                ssim(&a, &b, w, h, c, Padding::Same).unwrap(),
                ssim_with_grad(&a, &b, w, h, c, Padding::Same, 1.0).unwrap(),
                ssim_map(&a, &b, w, h, c, Padding::Valid).unwrap(),
                training_loss(&a, &b, w, h).unwrap(),
                l1(&a, &b).unwrap(),
            )
        })
    };
    let one = run(1);
    assert_eq!(one.0, one.1.0, "forward-only and forward+backward agree");
    for threads in [2, 4] {
        assert_eq!(run(threads), one, "{threads} threads");
    }
}

// ---------------------------------------------------------------------------------------------
// Backward: finite differences through bbsplat::gradcheck.
// ---------------------------------------------------------------------------------------------

/// Tolerance of the SSIM gradient checks. The loss is the *sum* of the map (`M·SSIM`, M = map
/// size), so gradients are O(1) whatever the image size. Measured worst values over the 256
/// cases are in docs/numerics-init-loss.md; this is the crate default (a 1 % scale error has
/// relative L2 = bias = 1e-2 and fails it).
fn ssim_tolerance() -> GradTolerance {
    GradTolerance::default()
}

/// Running worst values per check, printed at the end of the property test.
#[derive(Default, Debug)]
struct Worst {
    ratio: f64,
    rel_l2: f64,
    one_minus_cos: f64,
    bias: f64,
    directional: f64,
    cases: usize,
}

impl Worst {
    fn add(&mut self, r: &GradReport) {
        self.ratio = self.ratio.max(r.worst_ratio);
        self.rel_l2 = self.rel_l2.max(r.rel_l2);
        self.one_minus_cos = self.one_minus_cos.max(1.0 - r.cosine);
        self.bias = self.bias.max(r.bias.abs());
        self.cases += 1;
    }
}

static WORST_MEAN: Mutex<Option<Worst>> = Mutex::new(None);
static WORST_MAP: Mutex<Option<Worst>> = Mutex::new(None);

fn record(slot: &Mutex<Option<Worst>>, report: &GradReport, directional: f64) {
    let mut guard = slot.lock().unwrap();
    let w = guard.get_or_insert_with(Worst::default);
    w.add(report);
    w.directional = w.directional.max(directional);
}

/// Indices to check: all of them for small images, otherwise `count` distinct seeded ones
/// (always including the first and last value, which sit in corners).
fn check_indices(n: usize, count: usize, seed: u64) -> Vec<usize> {
    if n <= count {
        return (0..n).collect();
    }
    let mut all: Vec<usize> = (1..n - 1).collect();
    Rng::new(seed).shuffle(&mut all);
    let mut idx = vec![0, n - 1];
    idx.extend_from_slice(&all[..count - 2]);
    idx
}

/// `|FD directional derivative − g·d| / (‖g‖₂·‖d‖₂)` along a random direction over all inputs.
fn directional_error<F>(loss: F, x: &[f32], grad: &[f32], seed: u64) -> f64
where
    F: FnMut(&[f32]) -> f64,
{
    let d = random_weights(x.len(), seed);
    let fd = directional_derivative(loss, x, &d, 1e-3);
    let dot: f64 = grad.iter().zip(&d).map(|(&g, &di)| g as f64 * di).sum();
    let gn = grad.iter().map(|&g| (g as f64).powi(2)).sum::<f64>().sqrt();
    let dn = d.iter().map(|v| v * v).sum::<f64>().sqrt();
    (fd - dot).abs() / (gn * dn).max(1e-12)
}

/// One FD case: the mean SSIM (scaled by M) and the map with random weights.
#[allow(clippy::too_many_arguments)]
fn check_case(
    a: &[f32],
    b: &[f32],
    w: usize,
    h: usize,
    c: usize,
    padding: Padding,
    seed: u64,
    scale_error: f32,
) -> (GradReport, f64, GradReport, f64) {
    let (mw, mh) = map_size(w, h, padding).unwrap();
    let m = (mw * mh * c) as f32;
    let idx = check_indices(a.len(), 96, seed);

    // Mean SSIM, as the trainer uses it.
    let loss = |x: &[f32]| ssim(x, b, w, h, c, padding).unwrap() * m as f64;
    let grad: Vec<f32> = ssim_vjp(a, b, w, h, c, padding, m as f64)
        .unwrap()
        .iter()
        .map(|g| g * scale_error)
        .collect();
    let numeric = numerical_gradient(loss, a, &idx, StepRule::default());
    let analytic: Vec<f64> = idx.iter().map(|&i| grad[i] as f64).collect();
    let mean_report = compare(&analytic, &numeric, &ssim_tolerance());
    let mean_dir = directional_error(loss, a, &grad, seed ^ 0xd1);

    // The map with random weights: catches errors the mean averages away.
    let weights = random_weights(mw * mh * c, seed ^ 0x5eed);
    let wf: Vec<f32> = weights.iter().map(|&v| v as f32).collect();
    let map_grad: Vec<f32> = ssim_map_vjp(a, b, w, h, c, padding, &wf)
        .unwrap()
        .iter()
        .map(|g| g * scale_error)
        .collect();
    // The map comes out in f32, whose rounding (~3e-8 on each of the ~121 values a pixel moves)
    // swamps a finite difference of the f32 kernel; difference the f64 reference instead.
    let mut x: Vec<f64> = a.iter().map(|&v| v as f64).collect();
    let numeric: Vec<f64> = idx
        .iter()
        .map(|&i| {
            let x0 = x[i];
            x[i] = x0 + REFERENCE_STEP;
            let plus = reference_local_loss(&x, b, w, h, c, padding, &wf, i);
            x[i] = x0 - REFERENCE_STEP;
            let minus = reference_local_loss(&x, b, w, h, c, padding, &wf, i);
            x[i] = x0;
            (plus - minus) / (2.0 * REFERENCE_STEP)
        })
        .collect();
    let analytic: Vec<f64> = idx.iter().map(|&i| map_grad[i] as f64).collect();
    let map_report = compare(&analytic, &numeric, &reference_tolerance());
    // And along a random direction through the f32 kernel (all inputs at once).
    let map_loss = |x: &[f32]| weighted_sum(&ssim_map(x, b, w, h, c, padding).unwrap(), &weights);
    let map_dir = directional_error(map_loss, a, &map_grad, seed ^ 0xd2);
    (mean_report, mean_dir, map_report, map_dir)
}

/// Step of the f64 central differences of the reference: truncation ~1e-10 times the third
/// derivative, rounding ~1e-16·|L|/1e-5.
const REFERENCE_STEP: f64 = 1e-5;

/// Tolerance of the analytic gradient against f64 finite differences of the f64 reference:
/// both see the same f64 computation, the analytic one only rounded to f32 at the end.
fn reference_tolerance() -> GradTolerance {
    GradTolerance {
        atol: 1e-6,
        rtol: 1e-5,
        max_rel_l2: 1e-5,
        min_cosine: 1.0 - 1e-10,
        max_bias: 1e-5,
    }
}

/// Directional-derivative tolerance (relative to ‖g‖·‖d‖).
const DIRECTIONAL_TOL: f64 = 2e-3;

fn ssim_case_strategy() -> impl Strategy<Value = (usize, usize, usize, Padding, usize, u64)> {
    (any::<bool>(), any::<bool>(), 0usize..3, any::<u64>()).prop_flat_map(|(valid, three, kind, seed)| {
        let c = if three { 3 } else { 1 };
        let (padding, wmin, hmin) = if valid {
            (Padding::Valid, 11, 11)
        } else {
            (Padding::Same, 7, 9)
        };
        (wmin..=24usize, hmin..=20usize).prop_map(move |(w, h)| (w, h, c, padding, kind, seed))
    })
}

#[test]
fn ssim_backward_matches_finite_differences() {
    let mut runner = TestRunner::new(seeded_config(256));
    let result = runner.run(&ssim_case_strategy(), |(w, h, c, padding, kind, seed)| {
        let kind = [Kind::Independent, Kind::NearCopy, Kind::Smooth][kind];
        let (a, b) = image_pair(w, h, c, kind, seed);
        let (mean, mean_dir, map, map_dir) = check_case(&a, &b, w, h, c, padding, seed, 1.0);
        record(&WORST_MEAN, &mean, mean_dir);
        record(&WORST_MAP, &map, map_dir);
        let what = format!("{w}×{h}×{c} {padding:?} {kind:?} seed {seed}");
        prop_assert!(mean.passed(), "mean SSIM, {}: {}", what, mean);
        prop_assert!(map.passed(), "weighted map, {}: {}", what, map);
        prop_assert!(
            mean_dir < DIRECTIONAL_TOL,
            "mean SSIM directional {:.3e}, {}",
            mean_dir,
            what
        );
        prop_assert!(map_dir < DIRECTIONAL_TOL, "map directional {:.3e}, {}", map_dir, what);
        Ok(())
    });
    println!("worst over the cases (mean SSIM × M): {:?}", WORST_MEAN.lock().unwrap());
    println!("worst over the cases (weighted map):  {:?}", WORST_MAP.lock().unwrap());
    if let Err(e) = result {
        panic!("{e}");
    }
}

#[test]
fn a_one_percent_scale_error_is_caught() {
    let mut caught = 0;
    for seed in 0..12u64 {
        let kind = [Kind::Independent, Kind::NearCopy, Kind::Smooth][seed as usize % 3];
        let padding = if seed % 2 == 0 { Padding::Same } else { Padding::Valid };
        let (a, b) = image_pair(14, 12, 3, kind, seed);
        let (mean, _, map, _) = check_case(&a, &b, 14, 12, 3, padding, seed, 1.01);
        assert!(!mean.passed(), "seed {seed}: {mean}");
        assert!(!map.passed(), "seed {seed}: {map}");
        caught += 1;
    }
    assert_eq!(caught, 12);
}

#[test]
fn analytic_gradient_matches_fd_of_the_f64_reference() {
    // The f64 reference has no f32 forward noise: a central difference with h = 1e-4 is
    // accurate to ~1e-8 relative, so the comparison measures the f32 rounding of the analytic
    // gradient itself.
    let tol = GradTolerance {
        atol: 1e-5,
        rtol: 1e-3,
        max_rel_l2: 1e-4,
        min_cosine: 1.0 - 1e-8,
        max_bias: 1e-4,
    };
    let mut worst_rel_l2 = 0.0f64;
    for (i, &(w, h, c, padding)) in [
        (9usize, 10usize, 1usize, Padding::Same),
        (13, 12, 3, Padding::Valid),
        (12, 9, 3, Padding::Same),
    ]
    .iter()
    .enumerate()
    {
        for kind in [Kind::Independent, Kind::NearCopy, Kind::Smooth] {
            let (a, b) = image_pair(w, h, c, kind, 40 + i as u64);
            let (mw, mh) = map_size(w, h, padding).unwrap();
            let m = (mw * mh * c) as f64;
            let grad = ssim_vjp(&a, &b, w, h, c, padding, m).unwrap();
            let mut x: Vec<f64> = a.iter().map(|&v| v as f64).collect();
            let eval = |x: &[f64]| {
                // The reference takes f32 images; evaluate it in f64 on an f64 copy instead.
                reference_ssim_f64(x, &b, w, h, c, padding) * m
            };
            let hstep = 1e-4;
            let numeric: Vec<f64> = (0..x.len())
                .map(|j| {
                    let x0 = x[j];
                    x[j] = x0 + hstep;
                    let p = eval(&x);
                    x[j] = x0 - hstep;
                    let q = eval(&x);
                    x[j] = x0;
                    (p - q) / (2.0 * hstep)
                })
                .collect();
            let analytic: Vec<f64> = grad.iter().map(|&g| g as f64).collect();
            let r = compare(&analytic, &numeric, &tol);
            worst_rel_l2 = worst_rel_l2.max(r.rel_l2);
            assert!(r.passed(), "{w}×{h}×{c} {padding:?} {kind:?}: {r}");
        }
    }
    println!("analytic (f32) vs FD of the f64 reference: worst relative L2 {worst_rel_l2:.3e}");
}

/// The mean of the reference map for an f64 first image.
fn reference_ssim_f64(a: &[f64], b: &[f32], w: usize, h: usize, c: usize, padding: Padding) -> f64 {
    let (ow, oh, off) = reference_geometry(w, h, padding);
    let mut total = 0.0;
    for oy in 0..oh {
        for ox in 0..ow {
            for ch in 0..c {
                total += reference_value(a, b, w, h, c, off, ox, oy, ch);
            }
        }
    }
    total / (ow * oh * c) as f64
}

#[test]
fn window_matches_reference_window() {
    let g = gaussian_window();
    for (k, (&a, &b)) in g.iter().zip(&reference_window()).enumerate() {
        assert!((a - b).abs() < 1e-15, "tap {k}");
    }
}

// ---------------------------------------------------------------------------------------------
// L1, PSNR and the training loss.
// ---------------------------------------------------------------------------------------------

#[test]
fn l1_value_and_subgradient() {
    let a = [0.0f32, 1.0, 0.5, 0.25];
    let b = [1.0f32, 0.0, 0.5, 0.5];
    assert!((l1(&a, &b).unwrap() - 2.25 / 4.0).abs() < 1e-12);
    assert_eq!(l1_vjp(&a, &b, 2.0).unwrap(), vec![-0.5, 0.5, 0.0, -0.5]);
    // Away from the kink the gradient passes a finite-difference check.
    let mut rng = Rng::new(3);
    let b: Vec<f32> = (0..50).map(|_| rng.uniform()).collect();
    let a: Vec<f32> = b
        .iter()
        .map(|v| v + if rng.uniform() < 0.5 { -1.0 } else { 1.0 } * rng.range(0.05, 0.3))
        .collect();
    let r = check_vjp(
        &a,
        |x| vec![l1(x, &b).unwrap() as f32 * 50.0],
        |x, w| l1_vjp(x, &b, w[0] as f64 * 50.0).unwrap(),
        1,
        StepRule::default(),
        &GradTolerance::default(),
    );
    assert!(r.passed(), "{r}");
}

#[test]
fn psnr_values_and_quantisation() {
    // MSE = 0.01 -> 20 dB; MSE = 1e-4 -> 40 dB.
    assert!((psnr(&[0.1; 6], &[0.2; 6]).unwrap() - 20.0).abs() < 1e-5);
    assert!((psnr(&[0.5; 6], &[0.51; 6]).unwrap() - 40.0).abs() < 1e-4);
    assert_eq!(psnr(&[0.3; 3], &[0.3; 3]).unwrap(), f64::INFINITY);
    // save_image: ⌊clamp(x)·255 + 0.5⌋.
    for (x, q) in [
        (0.0, 0),
        (1.0, 255),
        (0.5, 128),
        (0.499, 127),
        (1.0 / 255.0, 1),
        (0.5 / 255.0, 1),
        (0.49 / 255.0, 0),
        (2.0, 255),
        (-3.0, 0),
        (f32::NAN, 0),
    ] {
        assert_eq!(quantize_u8(x), q, "{x}");
    }
    // Every 8-bit level round-trips.
    for v in 0..=255u8 {
        assert_eq!(quantize_u8(v as f32 / 255.0), v);
    }
    // One level apart everywhere: MSE = 1/255² -> 20·log10(255) = 48.13 dB.
    let a: Vec<f32> = (0..30).map(|i| (i * 7 % 200) as f32 / 255.0).collect();
    let b: Vec<f32> = a.iter().map(|v| v + 1.0 / 255.0).collect();
    assert!((psnr_u8(&a, &b).unwrap() - 20.0 * 255f64.log10()).abs() < 1e-9);
    // Render values outside [0, 1] are clamped before scoring.
    assert_eq!(psnr_u8(&[1.3, -0.2], &[1.0, 0.0]).unwrap(), f64::INFINITY);
}

#[test]
fn training_loss_gradient_matches_finite_differences() {
    let (w, h) = (10usize, 9usize);
    for seed in 0..6u64 {
        let mut rng = Rng::new(seed);
        let gt: Vec<f32> = (0..w * h * 3).map(|_| rng.range(0.1, 0.9)).collect();
        // |render − gt| ≥ 0.03 everywhere: the FD steps (1e-3) never cross the L1 kink.
        let render: Vec<f32> = gt
            .iter()
            .map(|v| v + if rng.uniform() < 0.5 { -1.0 } else { 1.0 } * rng.range(0.03, 0.2))
            .collect();
        // Relative L2 bounds 10× the worst measured over the six seeds (2026-11-26): 1.69e-4
        // for the default, whose SSIM values are f32 (they carry the FD noise), 3.8e-7 in f64.
        for (config, max_rel_l2) in [
            (TrainingLoss::default(), 1.7e-3),
            (
                TrainingLoss {
                    lambda_dssim: 0.5,
                    padding: Padding::Same,
                    precision: Precision::F64,
                    ..TrainingLoss::default()
                },
                3.8e-6,
            ),
        ] {
            // The loss is the sum over values (n·mean) so that gradients are O(1); it stays in
            // f64 (check_vjp would round it to f32, ~2e-6 at 27, i.e. 1e-3 after the FD).
            let n = render.len() as f64;
            let loss = |x: &[f32]| config.evaluate(x, &gt, w, h, 3).unwrap().loss * n;
            let idx: Vec<usize> = (0..render.len()).collect();
            let numeric = numerical_gradient(loss, &render, &idx, StepRule::default());
            let analytic: Vec<f64> = config
                .evaluate(&render, &gt, w, h, 3)
                .unwrap()
                .d_render
                .iter()
                .map(|&g| g as f64 * n)
                .collect();
            let tolerance = GradTolerance {
                max_rel_l2,
                ..GradTolerance::default()
            };
            let r = compare(&analytic, &numeric, &tolerance);
            println!("training loss, seed {seed}, λ = {}: {r}", config.lambda_dssim);
            assert!(r.passed(), "seed {seed} {config:?}: {r}");
        }
        let (loss, grad) = training_loss(&render, &gt, w, h).unwrap();
        let out = TrainingLoss::default().evaluate(&render, &gt, w, h, 3).unwrap();
        assert_eq!((loss, &grad), (out.loss, &out.d_render));
        assert!((loss - (0.8 * out.l1 + 0.2 * (1.0 - out.ssim))).abs() < 1e-12);
    }
}

#[test]
fn training_loss_lambda_extremes() {
    let (w, h) = (12usize, 11usize);
    let (render, gt) = image_pair(w, h, 3, Kind::NearCopy, 5);
    let pure_l1 = TrainingLoss {
        lambda_dssim: 0.0,
        padding: Padding::Same,
        precision: Precision::F64,
        ..TrainingLoss::default()
    }
    .evaluate(&render, &gt, w, h, 3)
    .unwrap();
    assert_eq!(pure_l1.loss, l1(&render, &gt).unwrap());
    assert_eq!(pure_l1.d_render, l1_vjp(&render, &gt, 1.0).unwrap());
    let pure_ssim = TrainingLoss {
        lambda_dssim: 1.0,
        padding: Padding::Valid,
        precision: Precision::F64,
        ..TrainingLoss::default()
    }
    .evaluate(&render, &gt, w, h, 3)
    .unwrap();
    let s = ssim(&render, &gt, w, h, 3, Padding::Valid).unwrap();
    assert!((pure_ssim.loss - (1.0 - s)).abs() < 1e-15);
    assert_eq!(
        pure_ssim.d_render,
        ssim_vjp(&render, &gt, w, h, 3, Padding::Valid, -1.0).unwrap()
    );
}

fn image(n: usize, seed: u64) -> Vec<f32> {
    let mut rng = Rng::new(seed);
    (0..n).map(|_| rng.range(0.05, 0.95)).collect()
}

/// FD check of `value_and_grad` with the given partials against the correct forward.
fn fd_check<P>(partials: P, padding: Padding, seed: u64) -> GradReport
where
    P: Fn(f64, f64, f64, f64, f64) -> [f64; 4] + Sync,
{
    let (w, h, c) = (13, 12, 2);
    let a = image(w * h * c, seed);
    let b = image(w * h * c, seed + 100);
    let (map_len, grad) = map_len_and_sum_grad(&a, &b, w, h, c, padding, partials).unwrap();
    // The loss is the sum of the map (M·SSIM) so that gradients are O(1).
    let m = map_len as f64;
    let analytic: Vec<f64> = grad.iter().map(|&g| g as f64).collect();
    let idx: Vec<usize> = (0..a.len()).collect();
    let numeric = numerical_gradient(
        |x| ssim(x, &b, w, h, c, padding).unwrap() * m,
        &a,
        &idx,
        StepRule::default(),
    );
    compare(&analytic, &numeric, &GradTolerance::default())
}

#[test]
fn correct_partials_pass() {
    for padding in [Padding::Same, Padding::Valid] {
        let r = fd_check(ssim_partials, padding, 1);
        assert!(r.passed(), "{padding:?}: {r}");
    }
}

#[test]
fn dropping_the_covariance_term_fails() {
    // Forget that σab = Sab − μa·μb depends on μa (the −2μb·A1/D part of ∂S/∂μa).
    let broken = |ma: f64, mb: f64, saa: f64, sbb: f64, sab: f64| {
        let [s, d_mu, d_saa, d_sab] = ssim_partials(ma, mb, saa, sbb, sab);
        let (a1, _, b1, b2) = terms(ma, mb, saa, sbb, sab);
        [s, d_mu + 2.0 * mb * a1 / (b1 * b2), d_saa, d_sab]
    };
    for padding in [Padding::Same, Padding::Valid] {
        let r = fd_check(broken, padding, 2);
        assert!(!r.passed(), "{padding:?}: {r}");
    }
}

#[test]
fn dropping_the_sab_gradient_fails() {
    let broken = |ma: f64, mb: f64, saa: f64, sbb: f64, sab: f64| {
        let [s, d_mu, d_saa, _] = ssim_partials(ma, mb, saa, sbb, sab);
        [s, d_mu, d_saa, 0.0]
    };
    let r = fd_check(broken, Padding::Same, 3);
    assert!(!r.passed(), "{r}");
}

#[test]
fn one_percent_scale_fails() {
    let broken = |ma: f64, mb: f64, saa: f64, sbb: f64, sab: f64| {
        let [s, d_mu, d_saa, d_sab] = ssim_partials(ma, mb, saa, sbb, sab);
        [s, 1.01 * d_mu, 1.01 * d_saa, 1.01 * d_sab]
    };
    for seed in 0..4 {
        let r = fd_check(broken, Padding::Same, 10 + seed);
        assert!(!r.passed(), "seed {seed}: {r}");
    }
}

#[test]
fn window_is_normalised_and_symmetric() {
    let g = gaussian_window();
    let sum: f64 = g.iter().sum();
    assert!((sum - 1.0).abs() < 1e-15, "{sum}");
    for k in 0..WINDOW_SIZE {
        assert_eq!(g[k], g[WINDOW_SIZE - 1 - k]);
    }
    assert!(g[5] > g[4] && g[0] > 0.0);
}

/// The SSIM forward and backward rows run an AVX2 build where the CPU has it: the same bits as
/// the baseline build, on one thread and on two, for both paddings, both cotangents and both
/// precisions.
#[test]
fn ssim_builds_and_thread_counts_give_the_same_bits() {
    use bbsplat::cpu::Simd;
    use bbsplat::loss::ssim::SsimOptions;
    let (w, h, c) = (41, 23, 3);
    let mut rng = Rng::new(7);
    let a: Vec<f32> = (0..w * h * c).map(|_| rng.uniform()).collect();
    let b: Vec<f32> = (0..w * h * c).map(|_| rng.uniform()).collect();
    let bits = |x: &[f32]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    for padding in [Padding::Same, Padding::Valid] {
        let (mw, mh) = map_size(w, h, padding).unwrap();
        let d_map: Vec<f32> = (0..mw * mh * c).map(|_| rng.uniform() - 0.5).collect();
        let mut results = Vec::new();
        for (threads, baseline) in [(1, true), (2, true), (1, false), (2, false)] {
            let simd = if baseline { Simd::BASELINE } else { Simd::detect() };
            let options = SsimOptions { padding, simd };
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            let (value, grad) = pool.install(|| ssim_with_grad(&a, &b, w, h, c, options, 0.8).unwrap());
            let vjp = pool.install(|| ssim_map_vjp(&a, &b, w, h, c, options, &d_map).unwrap());
            let (value32, grad32) = pool.install(|| ssim_with_grad_f32(&a, &b, w, h, c, options, 0.8).unwrap());
            results.push((
                value.to_bits(),
                bits(&grad),
                bits(&vjp),
                value32.to_bits(),
                bits(&grad32),
            ));
        }
        assert!(results.iter().all(|r| *r == results[0]), "{padding:?}");
    }
}

// ---------------------------------------------------------------------------------------------
// The f32 path (`ssim_with_grad_f32`, the training loss's default) against the f64 reference.
// ---------------------------------------------------------------------------------------------

/// A render-like pair: a white background (flat, where the f32 variance cancels worst) with a
/// textured disc and a few flat rectangles; `b` is `a` with small seeded changes (a target
/// close to the render, as late in training).
fn render_like_pair(w: usize, h: usize, seed: u64) -> (Vec<f32>, Vec<f32>) {
    let mut rng = Rng::new(seed);
    let mut a = vec![1.0f32; w * h * 3];
    let (cx, cy, r) = (w as f32 * 0.5, h as f32 * 0.5, w.min(h) as f32 * 0.35);
    for y in 0..h {
        for x in 0..w {
            let (dx, dy) = (x as f32 + 0.5 - cx, y as f32 + 0.5 - cy);
            let p = 3 * (y * w + x);
            if dx * dx + dy * dy < r * r {
                for ch in 0..3 {
                    a[p + ch] = 0.4 + 0.3 * ((x as f32 * 0.3 + ch as f32).sin() * (y as f32 * 0.2).cos());
                }
            } else if (x / 16 + y / 16) % 7 == 0 {
                a[p..p + 3].copy_from_slice(&[0.8, 0.6, 0.2]);
            }
        }
    }
    let b = a
        .iter()
        .map(|&v| {
            if v == 1.0 && rng.uniform() < 0.9 {
                v
            } else {
                (v + rng.range(-0.03, 0.03)).clamp(0.0, 1.0)
            }
        })
        .collect();
    (a, b)
}

/// `(|SSIM₃₂ − SSIM₆₄|, ‖g₃₂ − g₆₄‖ / ‖g₆₄‖, max|g₃₂ − g₆₄| / max|g₆₄|)` of
/// `ssim_with_grad_f32` against `ssim_with_grad`.
fn f32_against_f64(a: &[f32], b: &[f32], (w, h, c): (usize, usize, usize), padding: Padding) -> [f64; 3] {
    let (s64, g64) = ssim_with_grad(a, b, w, h, c, padding, 1.0).unwrap();
    let (s32, g32) = ssim_with_grad_f32(a, b, w, h, c, padding, 1.0).unwrap();
    gradient_distance(s64, &g64, s32, &g32)
}

fn gradient_distance(s64: f64, g64: &[f32], s32: f64, g32: &[f32]) -> [f64; 3] {
    let (mut diff2, mut norm2, mut max_diff, mut max_g) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for (&x, &y) in g64.iter().zip(g32) {
        let (x, y) = (x as f64, y as f64);
        diff2 += (x - y) * (x - y);
        norm2 += x * x;
        max_diff = max_diff.max((x - y).abs());
        max_g = max_g.max(x.abs());
    }
    [(s32 - s64).abs(), (diff2 / norm2).sqrt(), max_diff / max_g]
}

/// Bounds of `ssim_with_grad_f32` against `ssim_with_grad`: `[|SSIM₃₂ − SSIM₆₄|, relative L2
/// of the gradient, max |Δg| / max |g|]`, 10× the worst measured (2026-11-26; every case's
/// figures in docs/numerics-init-loss.md). Textured images (no window without structure):
/// measured worst 1.9e-8, 2.3e-6, 6.2e-6.
const F32_TEXTURED: [f64; 3] = [1.9e-7, 2.3e-5, 6.2e-5];
/// Images with flat or smooth low-contrast regions, where `G*(a²) − μa²` cancels in f32
/// (render-like pairs on a white background, smooth low-contrast images, one grey level):
/// measured worst 1.4e-5, 2.7e-4, 4.4e-4.
const F32_FLAT: [f64; 3] = [1.4e-4, 2.7e-3, 4.4e-3];

/// A named image pair with its `(w, h, c)` and its bounds.
type F32Case = (String, Vec<f32>, Vec<f32>, (usize, usize, usize), [f64; 3]);

#[test]
fn f32_ssim_stays_within_measured_bounds_of_the_f64_reference() {
    let mut cases: Vec<F32Case> = Vec::new();
    for (k, kind) in [Kind::Independent, Kind::NearCopy, Kind::Smooth]
        .into_iter()
        .enumerate()
    {
        let (a, b) = image_pair(64, 48, 3, kind, 40 + k as u64);
        let bound = if matches!(kind, Kind::Smooth) {
            F32_FLAT
        } else {
            F32_TEXTURED
        };
        cases.push((format!("{kind:?}"), a, b, (64, 48, 3), bound));
    }
    for (seed, (w, h)) in [(1u64, (96usize, 80usize)), (2, (400, 400))] {
        let (a, b) = render_like_pair(w, h, seed);
        cases.push((format!("render-like {w}×{h}"), a, b, (w, h, 3), F32_FLAT));
    }
    // Flat: both images one grey level, faint noise in one (the variance's worst case).
    let mut rng = Rng::new(9);
    let flat_b = vec![0.9f32; 50 * 40 * 3];
    let flat_a: Vec<f32> = flat_b.iter().map(|v| v + rng.range(-1e-3, 1e-3)).collect();
    cases.push(("flat".into(), flat_a, flat_b, (50, 40, 3), F32_FLAT));
    for (name, a, b, dims, bound) in &cases {
        for padding in [Padding::Same, Padding::Valid] {
            let d = f32_against_f64(a, b, *dims, padding);
            println!(
                "{name} {padding:?}: value {:.2e}, relative L2 {:.2e}, max {:.2e}",
                d[0], d[1], d[2]
            );
            assert!(
                d.iter().zip(bound).all(|(x, b)| x <= b),
                "{name} {padding:?}: {d:?} against {bound:?}"
            );
        }
    }
}

/// The bounds above catch a wrong f32 gradient: a 0.1 % scale error of one partial, or the
/// covariance term dropped, fails even the looser bound of the flat images.
#[test]
fn the_f32_bound_catches_a_wrong_f32_gradient() {
    use bbsplat::testing_internals::ssim::{ssim_partials_f32, sum_and_sum_grad_f32};
    let (textured, flat) = (F32_TEXTURED[1], F32_FLAT[1]);
    let (w, h, c) = (64, 48, 3);
    let (a, b) = image_pair(w, h, c, Kind::NearCopy, 41);
    let (s64, g64) = ssim_with_grad(&a, &b, w, h, c, Padding::Same, 1.0).unwrap();
    let m = (w * h * c) as f64;
    let g64: Vec<f32> = g64.iter().map(|&g| (g as f64 * m) as f32).collect();
    let distance = |partials: &(dyn Fn(f32, f32, f32, f32, f32) -> [f32; 4] + Sync)| {
        let (sum, g32) = sum_and_sum_grad_f32(&a, &b, w, h, c, Padding::Same, partials).unwrap();
        gradient_distance(s64 * m, &g64, sum, &g32)[1]
    };
    let correct = distance(&ssim_partials_f32);
    assert!(correct <= textured, "{correct:e}");
    let scaled = distance(&|ma, mb, saa, sbb, sab| {
        let [s, d_mu, d_saa, d_sab] = ssim_partials_f32(ma, mb, saa, sbb, sab);
        [s, d_mu, d_saa, 1.001 * d_sab]
    });
    let no_covariance = distance(&|ma, mb, saa, sbb, sab| {
        let [s, d_mu, d_saa, d_sab] = ssim_partials_f32(ma, mb, saa, sbb, sab);
        let a1 = 2.0 * ma * mb + C1 as f32;
        let b1 = ma * ma + mb * mb + C1 as f32;
        let b2 = (saa - ma * ma) + (sbb - mb * mb) + C2 as f32;
        [s, d_mu + 2.0 * mb * a1 / (b1 * b2), d_saa, d_sab]
    });
    println!("correct {correct:.2e}, d_sab × 1.001 {scaled:.2e}, covariance dropped {no_covariance:.2e}");
    assert!(scaled > flat, "{scaled:e}");
    assert!(no_covariance > flat, "{no_covariance:e}");
}
