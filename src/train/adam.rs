//! Adam on per-billboard rows, in two modes.
//!
//! * **Dense** ([`AdamGroup::step_row_global`] on every row every step): PyTorch `torch.optim.Adam`
//!   semantics. Every row's moments decay every step (with a zero gradient when the row was not
//!   seen) and the bias correction uses the global step count `t` shared by all rows, so a row with
//!   decaying moments keeps moving.
//! * **Row-sparse** ([`AdamGroup::step_row`] on the rows that received a gradient): a row that is
//!   not touched is left exactly as it is (no moment decay, no movement), and the bias correction
//!   uses the row's own count of updates `steps[row]`. This is what a "sparse Adam" does (e.g.
//!   `torch.optim.SparseAdam` and the sparse mode of gsplat), not what the reference does.
//!
//! The update is written in PyTorch's arrangement:
//! `p -= (lr / (1 − β₁ᵗ)) · m / (√v / √(1 − β₂ᵗ) + ε)`.

/// First and second moments of one parameter group, `row_len` values per billboard.
#[derive(Clone, Debug, PartialEq)]
pub struct AdamGroup {
    /// Values per billboard.
    pub row_len: usize,
    /// First moments.
    pub m: Vec<f32>,
    /// Second moments.
    pub v: Vec<f32>,
    /// Per billboard: number of updates applied (bias correction of the row-sparse mode).
    pub steps: Vec<u32>,
    /// Steps of the dense mode (the global `t` of PyTorch's Adam).
    pub global_step: u64,
}

/// Adam hyper-parameters (reference: β₁ 0.9, β₂ 0.999, ε 1e-15).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdamParams {
    /// β₁.
    pub beta1: f32,
    /// β₂.
    pub beta2: f32,
    /// ε.
    pub eps: f32,
}

impl Default for AdamParams {
    fn default() -> Self {
        Self {
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-15,
        }
    }
}

impl AdamGroup {
    /// Zero moments for `rows` billboards of `row_len` values.
    pub fn new(rows: usize, row_len: usize) -> Self {
        Self {
            row_len,
            m: crate::memory::filled(rows * row_len, 0.0),
            v: crate::memory::filled(rows * row_len, 0.0),
            steps: vec![0; rows],
            global_step: 0,
        }
    }

    /// Number of rows.
    pub fn rows(&self) -> usize {
        self.steps.len()
    }

    /// Zeroes the moments and the update count of `row` (after relocation).
    pub fn reset_row(&mut self, row: usize) {
        let n = self.row_len;
        self.m[row * n..(row + 1) * n].fill(0.0);
        self.v[row * n..(row + 1) * n].fill(0.0);
        self.steps[row] = 0;
    }

    /// One dense-mode Adam step of `row` with the global step count `t ≥ 1` (PyTorch semantics;
    /// the caller calls it for every row, with a zero gradient for unseen rows, and advances
    /// [`AdamGroup::global_step`] once per optimiser step). Also counts the update in `steps`.
    pub fn step_row_global(&mut self, row: usize, params: &mut [f32], grads: &[f32], lr: f32, hp: &AdamParams, t: u64) {
        self.step_row_with(row, params, grads, StepFactors::new(lr, hp, t), hp);
    }

    /// One Adam step for billboard `row`: `params -= lr · m̂ / (√v̂ + ε)`, with bias correction by
    /// the number of updates this row has received. Dense PyTorch Adam would also decay the
    /// moments of rows with zero gradient and keep moving them; here a billboard that is not
    /// seen in a view is left exactly as it is. This saves the work on unseen rows; what it saves
    /// and costs in quality against dense Adam is measured in `docs/quality-log.md` ("Dense against
    /// row-sparse Adam").
    pub fn step_row(&mut self, row: usize, params: &mut [f32], grads: &[f32], lr: f32, hp: &AdamParams) {
        // The count this update brings the row to (`step_row_with` stores it).
        let t = u64::from(self.steps[row].saturating_add(1));
        self.step_row_with(row, params, grads, StepFactors::new(lr, hp, t), hp);
    }

    /// One Adam step of `row` with its bias-corrected `factors` (see [`StepFactors`]), counting the
    /// update in `steps`. [`AdamGroup::step_row_global`] and [`AdamGroup::step_row`] compute the
    /// factors per call; the dense trainer computes them once per group and step, as its rows
    /// share the step count.
    pub fn step_row_with(
        &mut self,
        row: usize,
        params: &mut [f32],
        grads: &[f32],
        factors: StepFactors,
        hp: &AdamParams,
    ) {
        self.steps[row] = self.steps[row].saturating_add(1);
        let span = row * self.row_len..(row + 1) * self.row_len;
        update_row_with(&mut self.m[span.clone()], &mut self.v[span], params, grads, factors, hp);
    }
}

/// The scalars of one Adam update at bias-correction step `t ≥ 1` with learning rate `lr`: the
/// step size `lr / (1 − β₁ᵗ)` and `√(1 − β₂ᵗ)`. Computing them costs two integer powers and a
/// square root, more than the update of a row of three values, so rows that share `t` share
/// them ([`AdamGroup::step_row_with`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepFactors {
    step_size: f32,
    bc2_sqrt: f32,
}

impl StepFactors {
    /// The step size `lr / (1 − β₁ᵗ)`.
    pub fn step_size(self) -> f32 {
        self.step_size
    }

    /// `√(1 − β₂ᵗ)`.
    pub fn bc2_sqrt(self) -> f32 {
        self.bc2_sqrt
    }

    /// The factors of a step size and a `√(1 − β₂ᵗ)` (as [`StepFactors::step_size`] and
    /// [`StepFactors::bc2_sqrt`] gave them: how a checkpoint restores them).
    pub fn from_parts(step_size: f32, bc2_sqrt: f32) -> Self {
        Self { step_size, bc2_sqrt }
    }

    /// The factors at step `t` (values of `t` above `i32::MAX` count as `i32::MAX`).
    pub fn new(lr: f32, hp: &AdamParams, t: u64) -> Self {
        let t = t.min(i32::MAX as u64) as i32;
        let bc1 = 1.0 - hp.beta1.powi(t);
        Self {
            step_size: lr / bc1,
            bc2_sqrt: (1.0 - hp.beta2.powi(t)).sqrt(),
        }
    }
}

/// The Adam update of one row (`m`, `v`, `params` and `grads` of equal length) with the
/// [`StepFactors`] of its bias-correction step `t ≥ 1`, in PyTorch's arrangement
/// `p -= (lr / (1 − β₁ᵗ)) · m / (√v / √(1 − β₂ᵗ) + ε)`. The one copy of the update:
/// [`AdamGroup::step_row_with`] (which [`AdamGroup::step_row`] and
/// [`AdamGroup::step_row_global`] call) and the parallel texture step ([`super::texture_step`]).
/// Always inlined, so that it is compiled into the caller's instruction-set variant (the
/// texture step's AVX2 build).
#[inline(always)]
pub fn update_row_with(
    m: &mut [f32],
    v: &mut [f32],
    params: &mut [f32],
    grads: &[f32],
    factors: StepFactors,
    hp: &AdamParams,
) {
    assert_eq!(m.len(), params.len());
    assert_eq!(v.len(), params.len());
    assert_eq!(grads.len(), params.len());
    let StepFactors { step_size, bc2_sqrt } = factors;
    // Zipped slices (no index bounds to check), so that the loop vectorises.
    for (((m, v), p), &g) in m.iter_mut().zip(v.iter_mut()).zip(params.iter_mut()).zip(grads) {
        *m = hp.beta1 * *m + (1.0 - hp.beta1) * g;
        *v = hp.beta2 * *v + (1.0 - hp.beta2) * g * g;
        *p -= step_size * *m / (v.sqrt() / bc2_sqrt + hp.eps);
    }
}
