//! Gradient checking: central finite differences taken in f64 around f32 kernels.
//!
//! The kernels of this crate compute in f32. To check an analytic gradient we perturb one f32
//! input at a time by `±h`, evaluate a scalar loss in f64 from the kernel's f32 outputs, and take
//! the central difference `(L(x+h) − L(x−h)) / (x₊ − x₋)` in f64, where `x₊ − x₋` is the step
//! actually representable in f32 (not the nominal `2h`). The analytic and numeric gradients are
//! then compared elementwise (`|a − n| ≤ atol + rtol·max(|a|, |n|)`) and as whole vectors
//! (relative L2 error, cosine similarity, signed bias), because elementwise tolerances loose
//! enough for finite-difference noise let a uniform 1 % scale error or a small missing term
//! through, while the aggregate checks do not.
//!
//! The module is public so that other crates can use it in their own property tests.
//!
//! ```
//! use bbsplat::gradcheck::{check_vjp, GradTolerance, StepRule};
//! // f(x) = (x0·x1, sin x0): the VJP with cotangent w is (w0·x1 + w1·cos x0, w0·x0).
//! let forward = |x: &[f32]| vec![x[0] * x[1], x[0].sin()];
//! let vjp = |x: &[f32], w: &[f32]| vec![w[0] * x[1] + w[1] * x[0].cos(), w[0] * x[0]];
//! let report = check_vjp(&[0.7, -1.3], forward, vjp, 42, StepRule::default(), &GradTolerance::default());
//! assert!(report.passed(), "{report}");
//! ```

use crate::rng::Rng;
use std::fmt;

/// How the finite-difference step is chosen for each input.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepRule {
    /// Nominal step.
    pub base: f64,
    /// If true the step for input `x` is `base · max(1, |x|)`, so that large coordinates are
    /// perturbed by more than their f32 spacing; otherwise it is `base`.
    pub relative: bool,
}

impl Default for StepRule {
    /// `h = 1e-3 · max(1, |x|)`. For an f32 kernel whose loss is O(1), the rounding noise of the
    /// difference is about `ε_f32 / h ≈ 6e-5` and the truncation error `h²·|f'''|/6 ≈ 2e-7·|f'''|`;
    /// `1e-3` keeps both small for the well-conditioned inputs of our strategies.
    fn default() -> Self {
        Self {
            base: 1e-3,
            relative: true,
        }
    }
}

impl StepRule {
    /// An absolute step `h` for every input.
    pub fn absolute(h: f64) -> Self {
        Self {
            base: h,
            relative: false,
        }
    }

    fn step_for(&self, x: f32) -> f64 {
        if self.relative {
            self.base * (x.abs() as f64).max(1.0)
        } else {
            self.base
        }
    }
}

/// Pass criteria for comparing an analytic gradient with a numeric one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GradTolerance {
    /// Elementwise absolute tolerance.
    pub atol: f64,
    /// Elementwise relative tolerance (relative to `max(|analytic|, |numeric|)`).
    pub rtol: f64,
    /// Maximum `‖a − n‖₂ / ‖n‖₂` over the whole vector.
    pub max_rel_l2: f64,
    /// Minimum cosine similarity between `a` and `n`.
    pub min_cosine: f64,
    /// Maximum `|Σ(a − n)| / Σ|n|`: catches an error with a consistent sign.
    pub max_bias: f64,
}

impl Default for GradTolerance {
    /// Defaults suited to f32 kernels with O(1) inputs and outputs and the default step:
    /// elementwise `atol = 1e-4, rtol = 1e-2`, whole-vector relative L2 error `≤ 2e-3`,
    /// cosine `≥ 0.99999`, bias `≤ 2e-3`. A 1 % scale error (relative L2 = bias = 1e-2) fails.
    fn default() -> Self {
        Self {
            atol: 1e-4,
            rtol: 1e-2,
            max_rel_l2: 2e-3,
            min_cosine: 0.99999,
            max_bias: 2e-3,
        }
    }
}

impl GradTolerance {
    /// The same tolerance with every bound multiplied by `factor` (cosine bound moved towards
    /// 0 by `factor` times its distance to 1).
    pub fn scaled(&self, factor: f64) -> Self {
        Self {
            atol: self.atol * factor,
            rtol: self.rtol * factor,
            max_rel_l2: self.max_rel_l2 * factor,
            min_cosine: 1.0 - (1.0 - self.min_cosine) * factor,
            max_bias: self.max_bias * factor,
        }
    }
}

/// The outcome of a gradient comparison, naming the worst element.
#[derive(Clone, Debug, PartialEq)]
pub struct GradReport {
    /// Number of elements compared.
    pub len: usize,
    /// Index of the element with the largest `|a − n| / (atol + rtol·max(|a|,|n|))`.
    pub worst_index: usize,
    /// Analytic value at `worst_index`.
    pub worst_analytic: f64,
    /// Numeric value at `worst_index`.
    pub worst_numeric: f64,
    /// `|a − n| / (atol + rtol·max(|a|,|n|))` at `worst_index`; the elementwise check passes
    /// when this is ≤ 1.
    pub worst_ratio: f64,
    /// Largest absolute difference over all elements.
    pub max_abs_err: f64,
    /// `‖a − n‖₂ / ‖n‖₂` (0 when both vectors are below the absolute tolerance).
    pub rel_l2: f64,
    /// Cosine similarity of `a` and `n` (1 when both are below the absolute tolerance).
    pub cosine: f64,
    /// `Σ(a − n) / Σ|n|` (0 when both are below the absolute tolerance).
    pub bias: f64,
    /// The tolerance the report was judged against.
    pub tolerance: GradTolerance,
    /// Any non-finite value found (index), which fails the check.
    pub non_finite: Option<usize>,
}

impl GradReport {
    /// True when every criterion holds.
    pub fn passed(&self) -> bool {
        self.failures().is_empty()
    }

    /// A list of the criteria that failed, in words.
    pub fn failures(&self) -> Vec<String> {
        let t = &self.tolerance;
        let mut f = Vec::new();
        if let Some(i) = self.non_finite {
            f.push(format!("non-finite value at index {i}"));
        }
        if self.worst_ratio > 1.0 {
            f.push(format!(
                "element {}: analytic {:.6e} vs numeric {:.6e} (|diff| = {:.3e} > atol {:.1e} + rtol {:.1e}·max)",
                self.worst_index,
                self.worst_analytic,
                self.worst_numeric,
                (self.worst_analytic - self.worst_numeric).abs(),
                t.atol,
                t.rtol
            ));
        }
        if self.rel_l2 > t.max_rel_l2 {
            f.push(format!("relative L2 error {:.3e} > {:.1e}", self.rel_l2, t.max_rel_l2));
        }
        if self.cosine < t.min_cosine {
            f.push(format!("cosine similarity {:.8} < {:.8}", self.cosine, t.min_cosine));
        }
        if self.bias.abs() > t.max_bias {
            f.push(format!("signed bias {:.3e} exceeds {:.1e}", self.bias, t.max_bias));
        }
        f
    }
}

impl fmt::Display for GradReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let verdict = if self.passed() { "passed" } else { "FAILED" };
        writeln!(
            f,
            "gradient check {verdict} over {} elements: worst element {} (analytic {:.6e}, numeric {:.6e}, \
             ratio to tolerance {:.3}), max |diff| {:.3e}, rel L2 {:.3e}, cosine {:.9}, bias {:.3e}",
            self.len,
            self.worst_index,
            self.worst_analytic,
            self.worst_numeric,
            self.worst_ratio,
            self.max_abs_err,
            self.rel_l2,
            self.cosine,
            self.bias
        )?;
        for failure in self.failures() {
            writeln!(f, "  - {failure}")?;
        }
        Ok(())
    }
}

/// The worst value of every criterion over many [`GradReport`]s: what a tolerance should be set
/// from ("measured, not guessed"). Feed it the reports of a property run over many seeds, print
/// it, and choose bounds at a stated multiple of the worst values.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct WorstObserved {
    /// Number of reports added.
    pub cases: usize,
    /// Largest elementwise ratio to the tolerance.
    pub ratio: f64,
    /// Largest absolute difference.
    pub max_abs: f64,
    /// Largest relative L2 error.
    pub rel_l2: f64,
    /// Largest `1 − cosine`.
    pub one_minus_cos: f64,
    /// Largest `|bias|`.
    pub bias: f64,
}

impl WorstObserved {
    /// Folds one report in.
    ///
    /// # Panics
    /// When the report has a non-finite value: a measurement must not hide one.
    pub fn add(&mut self, r: &GradReport) {
        assert!(r.non_finite.is_none(), "{r}");
        self.cases += 1;
        self.ratio = self.ratio.max(r.worst_ratio);
        self.max_abs = self.max_abs.max(r.max_abs_err);
        self.rel_l2 = self.rel_l2.max(r.rel_l2);
        self.one_minus_cos = self.one_minus_cos.max(1.0 - r.cosine);
        self.bias = self.bias.max(r.bias.abs());
    }
}

/// Central difference of `loss` with respect to input `index` of `x`.
///
/// The perturbed inputs are rounded to f32 and the divisor is the step that was actually taken.
/// The step is at least 4 f32 spacings of `x[index]`.
pub fn central_difference<F>(loss: &mut F, x: &[f32], index: usize, step: StepRule) -> f64
where
    F: FnMut(&[f32]) -> f64,
{
    let mut probe = x.to_vec();
    // Never step by less than 4 f32 spacings of x: below that the rounded step is mostly noise
    // (or zero, which would divide by zero).
    let ulp = (x[index].abs().max(f32::MIN_POSITIVE) as f64) * f32::EPSILON as f64;
    let h = step.step_for(x[index]).max(4.0 * ulp);
    let plus = (x[index] as f64 + h) as f32;
    let minus = (x[index] as f64 - h) as f32;
    probe[index] = plus;
    let l_plus = loss(&probe);
    probe[index] = minus;
    let l_minus = loss(&probe);
    (l_plus - l_minus) / (plus as f64 - minus as f64)
}

/// Numeric gradient of `loss` at `x` for the inputs listed in `indices` (in that order).
pub fn numerical_gradient<F>(mut loss: F, x: &[f32], indices: &[usize], step: StepRule) -> Vec<f64>
where
    F: FnMut(&[f32]) -> f64,
{
    indices
        .iter()
        .map(|&i| central_difference(&mut loss, x, i, step))
        .collect()
}

/// Central difference of `loss` along `direction`: `(L(x + h·d) − L(x − h·d)) / 2h` with
/// `h = step.base` (absolute). Use for large parameter vectors where a per-element check is too
/// expensive; compare against `Σ gᵢ dᵢ`. The difference is taken with the f32-rounded inputs;
/// the divisor is the nominal `2h`, so choose `h` well above the f32 spacing of `x`.
pub fn directional_derivative<F>(mut loss: F, x: &[f32], direction: &[f64], step: f64) -> f64
where
    F: FnMut(&[f32]) -> f64,
{
    assert_eq!(x.len(), direction.len(), "direction must match the input length");
    let shifted = |sign: f64| -> Vec<f32> {
        x.iter()
            .zip(direction)
            .map(|(&xi, &di)| (xi as f64 + sign * step * di) as f32)
            .collect()
    };
    let plus = shifted(1.0);
    let minus = shifted(-1.0);
    (loss(&plus) - loss(&minus)) / (2.0 * step)
}

/// Compares an analytic gradient with a numeric one.
pub fn compare(analytic: &[f64], numeric: &[f64], tolerance: &GradTolerance) -> GradReport {
    assert_eq!(
        analytic.len(),
        numeric.len(),
        "analytic and numeric gradients differ in length"
    );
    let t = tolerance;
    let mut report = GradReport {
        len: analytic.len(),
        worst_index: 0,
        worst_analytic: analytic.first().copied().unwrap_or(0.0),
        worst_numeric: numeric.first().copied().unwrap_or(0.0),
        worst_ratio: 0.0,
        max_abs_err: 0.0,
        rel_l2: 0.0,
        cosine: 1.0,
        bias: 0.0,
        tolerance: *t,
        non_finite: None,
    };
    let (mut dd, mut nn, mut aa, mut an, mut sum_diff, mut sum_abs_n) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    for (i, (&a, &n)) in analytic.iter().zip(numeric).enumerate() {
        if !a.is_finite() || !n.is_finite() {
            report.non_finite.get_or_insert(i);
            continue;
        }
        let diff = a - n;
        let ratio = diff.abs() / (t.atol + t.rtol * a.abs().max(n.abs()));
        if ratio > report.worst_ratio {
            report.worst_ratio = ratio;
            report.worst_index = i;
            report.worst_analytic = a;
            report.worst_numeric = n;
        }
        report.max_abs_err = report.max_abs_err.max(diff.abs());
        dd += diff * diff;
        nn += n * n;
        aa += a * a;
        an += a * n;
        sum_diff += diff;
        sum_abs_n += n.abs();
    }
    // Whole-vector criteria only make sense when the gradient is not pure noise: if both vectors
    // are within the absolute tolerance everywhere the elementwise check has said all there is.
    let floor = t.atol * t.atol * analytic.len() as f64;
    if nn > floor || aa > floor {
        report.rel_l2 = dd.sqrt() / nn.sqrt().max(f64::MIN_POSITIVE);
        report.cosine = an / (aa.sqrt() * nn.sqrt()).max(f64::MIN_POSITIVE);
        report.bias = sum_diff / sum_abs_n.max(f64::MIN_POSITIVE);
    }
    report
}

/// `Σ wᵢ·yᵢ` in f64: the random weighted loss used to turn a vector-valued kernel into a scalar.
pub fn weighted_sum(outputs: &[f32], weights: &[f64]) -> f64 {
    assert_eq!(outputs.len(), weights.len(), "one weight per output");
    outputs.iter().zip(weights).map(|(&y, &w)| y as f64 * w).sum()
}

/// `n` seeded weights uniform in `[-1, 1)`, used as the cotangent of a random weighted loss.
pub fn random_weights(n: usize, seed: u64) -> Vec<f64> {
    let mut rng = Rng::new(seed);
    (0..n).map(|_| 2.0 * rng.uniform_f64() - 1.0).collect()
}

/// Checks a vector-Jacobian product against finite differences of a random weighted loss.
///
/// `forward(x)` returns the kernel's outputs; `vjp(x, w)` must return `∂(w·forward(x))/∂x`.
/// The weights `w` are drawn from `seed` (uniform in `[-1, 1)`), so a failing case is
/// reproducible from the seed printed by the caller.
pub fn check_vjp<F, B>(
    x: &[f32],
    forward: F,
    vjp: B,
    seed: u64,
    step: StepRule,
    tolerance: &GradTolerance,
) -> GradReport
where
    F: Fn(&[f32]) -> Vec<f32>,
    B: Fn(&[f32], &[f32]) -> Vec<f32>,
{
    let n_out = forward(x).len();
    let weights = random_weights(n_out, seed);
    let weights_f32: Vec<f32> = weights.iter().map(|&w| w as f32).collect();
    let analytic: Vec<f64> = vjp(x, &weights_f32).iter().map(|&g| g as f64).collect();
    assert_eq!(analytic.len(), x.len(), "the VJP must return one gradient per input");
    let indices: Vec<usize> = (0..x.len()).collect();
    let numeric = numerical_gradient(|p| weighted_sum(&forward(p), &weights), x, &indices, step);
    compare(&analytic, &numeric, tolerance)
}
