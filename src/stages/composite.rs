//! Front-to-back alpha compositing of a depth-ordered list of entries, and its backward pass.
//!
//! Forward, exactly as the reference rasterizer (spec §3.3), for entries `i = 0, 1, …` in depth
//! order with raw alpha `aᵢ` and `C` feature channels `cᵢ` (colour plus extra channels such as
//! depth), starting from transmittance `T = 1`:
//! 1. `αᵢ = min(max_alpha, aᵢ)` (clamp, default 0.99);
//! 2. if `αᵢ < min_alpha` (default 1/255) the entry is **skipped** (a NaN alpha is skipped too);
//! 3. `test_T = T·(1 − αᵢ)`; if `test_T < min_transmittance` (default 1e-4) compositing
//!    **stops without blending this entry**;
//! 4. otherwise `out += cᵢ·αᵢ·T` (the entry's weight, or "impact", is `wᵢ = αᵢ·T`) and `T = test_T`.
//!
//! The result is `out = Σ wᵢ cᵢ + T_final · background`.
//!
//! Backward, **without recovering `T` by division by `1 − α`** (which loses all precision once
//! `T` underflows, see `docs/numerics-appearance.md`): the `Tᵢ` are recomputed front to back
//! (bit-identical to the forward), then a back-to-front pass carries the "colour behind"
//! `Bᵢ = α_next c_next + (1 − α_next) B_next` over the blended entries, starting from
//! `B_last = background`, so that
//! `∂L/∂αᵢ = Tᵢ · Σ_ch (cᵢ − Bᵢ)·g_ch`, `∂L/∂cᵢ = wᵢ g`, `∂L/∂background = T_final g`.
//! Skipped entries, the stopping entry and everything after it get zero gradient (the forward is
//! locally constant in them; the thresholds themselves are jump discontinuities).
//!
//! The clamp at `max_alpha`: see [`ClampGradient`]. Our default is the exact derivative of the
//! forward ([`ClampGradient::Exact`]: zero when `a > max_alpha`); the reference rasterizer passes
//! the gradient through as if unclamped ([`ClampGradient::PassThrough`]).
//!
//! The rasterizer's hot loop uses [`CompositeState`] (forward) and [`CompositeBackState`]
//! (backward), which work on fixed-size feature arrays and never allocate; [`composite`] and
//! [`composite_vjp`] are the vector-based reference entry points built on the same steps.
//!
//! ```
//! use bbsplat::stages::composite::{composite, CompositeParams};
//! let alphas = [0.5, 0.5];
//! let features = [1.0, 0.0, /* entry 1 */ 0.0, 1.0];
//! let out = composite(&alphas, &features, 2, &[0.0, 0.0], &CompositeParams::default());
//! assert_eq!(out.features, vec![0.5, 0.25]);
//! assert_eq!(out.weights, vec![0.5, 0.25]);
//! assert_eq!(out.final_transmittance, 0.25);
//! assert_eq!(out.n_used, 2);
//! ```

use glam::Vec4;

/// How the gradient goes through the clamp `α = min(max_alpha, a)`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ClampGradient {
    /// The derivative of the forward: `∂α/∂a = 1` for `a ≤ max_alpha`, `0` for `a > max_alpha`
    /// (left derivative at `a = max_alpha`). Checked against finite differences.
    #[default]
    Exact,
    /// The reference rasterizer's behaviour: `∂α/∂a = 1` always (a straight-through estimator,
    /// so that an alpha texture above the clamp still receives a gradient). Not the derivative of
    /// the forward; use for comparisons with the reference.
    PassThrough,
}

/// Thresholds of the compositing loop. [`Default`] gives the reference values with the exact
/// clamp gradient; [`CompositeParams::reference`] also reproduces the reference's clamp
/// gradient. Tests may relax the thresholds (e.g. [`CompositeParams::smooth`]) to get a smooth
/// function.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CompositeParams {
    /// Upper clamp of alpha (reference 0.99): keeps `1 − α ≥ 0.01`, so one entry can never make
    /// the transmittance exactly 0.
    pub max_alpha: f32,
    /// Entries with clamped alpha below this are skipped (reference 1/255: below one 8-bit level).
    pub min_alpha: f32,
    /// Compositing stops before an entry that would bring the transmittance below this
    /// (reference 1e-4). The stopping entry itself is not blended; with `max_alpha = 0.99` a stop
    /// needs `T < 0.01`, so the dropped entries weigh less than 0.01 in total (not 1e-4).
    pub min_transmittance: f32,
    /// Gradient through the `max_alpha` clamp.
    pub clamp_gradient: ClampGradient,
}

/// Reference clamp of alpha.
pub const MAX_ALPHA: f32 = 0.99;
/// Reference skip threshold for alpha, 1/255.
pub const MIN_ALPHA: f32 = 1.0 / 255.0;
/// Reference transmittance stop threshold.
pub const MIN_TRANSMITTANCE: f32 = 1e-4;

impl Default for CompositeParams {
    /// `max_alpha = 0.99`, `min_alpha = 1/255`, `min_transmittance = 1e-4`, exact clamp gradient.
    fn default() -> Self {
        Self {
            max_alpha: MAX_ALPHA,
            min_alpha: MIN_ALPHA,
            min_transmittance: MIN_TRANSMITTANCE,
            clamp_gradient: ClampGradient::Exact,
        }
    }
}

impl CompositeParams {
    /// The reference rasterizer exactly: default thresholds and [`ClampGradient::PassThrough`].
    pub fn reference() -> Self {
        Self {
            clamp_gradient: ClampGradient::PassThrough,
            ..Self::default()
        }
    }

    /// No thresholds at all (`max_alpha = 1`, `min_alpha = 0`, `min_transmittance = 0`): the
    /// forward is then a multilinear polynomial in the alphas, smooth everywhere on `[0, 1]`.
    pub fn smooth() -> Self {
        Self {
            max_alpha: 1.0,
            min_alpha: 0.0,
            min_transmittance: 0.0,
            clamp_gradient: ClampGradient::Exact,
        }
    }
}

/// One blended entry: what the forward used and what the backward needs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Blend {
    /// Alpha after the clamp.
    pub alpha: f32,
    /// Transmittance in front of the entry, `Tᵢ`.
    pub transmittance: f32,
    /// Blending weight `αᵢ·Tᵢ` (the entry's "impact").
    pub weight: f32,
    /// Transmittance behind the entry, `Tᵢ·(1 − αᵢ)`.
    pub next_transmittance: f32,
    /// True when the raw alpha was above `max_alpha` (the clamp was active).
    pub clamped: bool,
}

/// The decision for one entry.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Step {
    /// Alpha below `min_alpha` (or NaN): the entry is ignored.
    Skip,
    /// The entry would bring the transmittance below `min_transmittance`: compositing ends here
    /// and the entry is not blended (also returned for every entry after a stop).
    Stop,
    /// The entry is blended.
    Blend(Blend),
}

/// Classifies one entry with raw alpha `a` in front of transmittance `transmittance`
/// (the three thresholds of the module docs, in the reference's order).
///
/// ```
/// use bbsplat::stages::composite::{classify, CompositeParams, Step};
/// let p = CompositeParams::default();
/// assert_eq!(classify(1.0, 0.001, &p), Step::Skip);
/// assert_eq!(classify(2e-4, 0.9, &p), Step::Stop);
/// let Step::Blend(b) = classify(1.0, 1.5, &p) else { panic!() };
/// assert_eq!((b.alpha, b.clamped), (0.99, true));
/// ```
#[inline]
pub fn classify(transmittance: f32, a: f32, params: &CompositeParams) -> Step {
    let clamped = a > params.max_alpha;
    let alpha = if clamped { params.max_alpha } else { a };
    if alpha.is_nan() || alpha < params.min_alpha {
        return Step::Skip;
    }
    let next = transmittance * (1.0 - alpha);
    if next < params.min_transmittance {
        return Step::Stop;
    }
    Step::Blend(Blend {
        alpha,
        transmittance,
        weight: alpha * transmittance,
        next_transmittance: next,
        clamped,
    })
}

/// Per-pixel front-to-back compositing state for the rasterizer's hot loop: transmittance and
/// `C` accumulated feature channels, no allocation.
///
/// ```
/// use bbsplat::stages::composite::{CompositeParams, CompositeState, Step};
/// let p = CompositeParams::default();
/// let mut s = CompositeState::<3>::new();
/// // Decide from alpha first, and only sample the colour texture if the entry is blended.
/// if let Step::Blend(b) = s.step(0.5, &p) {
///     s.blend(&b, &[1.0, 0.5, 0.0]);
/// }
/// assert_eq!(s.finish(&[1.0, 1.0, 1.0]), [1.0, 0.75, 0.5]);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CompositeState<const C: usize> {
    /// Current transmittance `T` (1 at the start).
    pub transmittance: f32,
    /// Accumulated `Σ wᵢ cᵢ` (without the background).
    pub features: [f32; C],
    /// True once compositing has stopped (transmittance threshold reached).
    pub done: bool,
}

impl<const C: usize> Default for CompositeState<C> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const C: usize> CompositeState<C> {
    /// `T = 1`, no features, not done.
    #[inline]
    pub fn new() -> Self {
        Self {
            transmittance: 1.0,
            features: [0.0; C],
            done: false,
        }
    }

    /// Classifies the next entry from its raw alpha without changing the state (after a stop,
    /// always [`Step::Stop`]). On [`Step::Stop`] the caller must call [`CompositeState::stop`]
    /// (or use [`CompositeState::push`]); on [`Step::Blend`] it calls [`CompositeState::blend`].
    #[inline]
    pub fn step(&self, a: f32, params: &CompositeParams) -> Step {
        if self.done {
            return Step::Stop;
        }
        classify(self.transmittance, a, params)
    }

    /// Blends an entry classified by [`CompositeState::step`] with its features.
    #[inline]
    pub fn blend(&mut self, blend: &Blend, features: &[f32; C]) {
        for (acc, &c) in self.features.iter_mut().zip(features) {
            *acc += c * blend.weight;
        }
        self.transmittance = blend.next_transmittance;
    }

    /// Marks the pixel as done.
    #[inline]
    pub fn stop(&mut self) {
        self.done = true;
    }

    /// [`CompositeState::step`] followed by [`CompositeState::blend`] or
    /// [`CompositeState::stop`] as appropriate; returns the step taken.
    #[inline]
    pub fn push(&mut self, a: f32, features: &[f32; C], params: &CompositeParams) -> Step {
        let s = self.step(a, params);
        match s {
            Step::Blend(b) => self.blend(&b, features),
            Step::Stop => self.stop(),
            Step::Skip => {}
        }
        s
    }

    /// The composited result `Σ wᵢ cᵢ + T·background`.
    #[inline]
    pub fn finish(&self, background: &[f32; C]) -> [f32; C] {
        let mut out = self.features;
        for (o, &b) in out.iter_mut().zip(background) {
            *o += self.transmittance * b;
        }
        out
    }
}

/// Gradients for one blended entry, from [`CompositeBackState::pop`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EntryGrad<const C: usize> {
    /// `∂L/∂a` with respect to the **raw** alpha (through the clamp per [`ClampGradient`]).
    pub d_alpha: f32,
    /// `∂L/∂cᵢ = wᵢ·g`.
    pub d_features: [f32; C],
}

/// Back-to-front state of the compositing backward for the hot loop: the "colour behind"
/// `B` of the module docs, starting at the background.
///
/// The caller replays the pixel's forward with [`CompositeState`], keeps the [`Blend`] records
/// (and the features) of the blended entries in a reusable buffer, then calls
/// [`CompositeBackState::pop`] on them in reverse order. `∂L/∂background = T_final·g`.
///
/// ```
/// use bbsplat::stages::composite::{CompositeBackState, CompositeParams, CompositeState, Step};
/// let p = CompositeParams::default();
/// let mut s = CompositeState::<1>::new();
/// let Step::Blend(b) = s.push(0.5, &[2.0], &p) else { panic!() };
/// // out = 0.5·2 + 0.5·bg; ∂out/∂α = c − bg.
/// let mut back = CompositeBackState::new(&[1.0]);
/// let g = back.pop(&b, &[2.0], &[1.0], &p);
/// assert_eq!((g.d_alpha, g.d_features[0]), (1.0, 0.5));
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CompositeBackState<const C: usize> {
    /// The composited features behind the next entry to pop (background at the start).
    pub behind: [f32; C],
}

impl<const C: usize> CompositeBackState<C> {
    /// Starts behind the last blended entry, i.e. at the background.
    #[inline]
    pub fn new(background: &[f32; C]) -> Self {
        Self { behind: *background }
    }

    /// Gradients of the blended entry `blend` (with features `features`) for the upstream
    /// gradient `d_out`, then moves `behind` in front of it.
    #[inline]
    pub fn pop(
        &mut self,
        blend: &Blend,
        features: &[f32; C],
        d_out: &[f32; C],
        params: &CompositeParams,
    ) -> EntryGrad<C> {
        let mut d_features = [0.0; C];
        let d_alpha = back_step(blend, features, d_out, &mut self.behind, &mut d_features, params);
        EntryGrad { d_alpha, d_features }
    }
}

/// One back-to-front step on slices: returns `∂L/∂a`, writes `∂L/∂c` into `d_features`, and
/// updates `behind ← α c + (1 − α) behind`.
#[inline]
fn back_step(
    blend: &Blend,
    features: &[f32],
    d_out: &[f32],
    behind: &mut [f32],
    d_features: &mut [f32],
    params: &CompositeParams,
) -> f32 {
    let alpha = blend.alpha;
    let n = behind.len();
    assert!(
        features.len() == n && d_out.len() == n && d_features.len() == n,
        "features, upstream gradients, state and feature gradients hold the same channels"
    );
    let mut dot = 0.0f32;
    // Four channels at a time in vector registers (each lane the scalar operations below, so
    // the same bits), the products summed into `dot` one by one in channel order.
    let mut ch = 0;
    while ch + 4 <= n {
        let lanes = ch..ch + 4;
        let (c, g) = (
            Vec4::from_slice(&features[lanes.clone()]),
            Vec4::from_slice(&d_out[lanes.clone()]),
        );
        let b = Vec4::from_slice(&behind[lanes.clone()]);
        let [p0, p1, p2, p3] = ((c - b) * g).to_array();
        dot = dot + p0 + p1 + p2 + p3;
        (blend.weight * g).write_to_slice(&mut d_features[lanes.clone()]);
        (alpha * c + (1.0 - alpha) * b).write_to_slice(&mut behind[lanes]);
        ch += 4;
    }
    for ch in ch..n {
        let c = features[ch];
        let g = d_out[ch];
        dot += (c - behind[ch]) * g;
        d_features[ch] = blend.weight * g;
        behind[ch] = alpha * c + (1.0 - alpha) * behind[ch];
    }
    let pass = !blend.clamped || params.clamp_gradient == ClampGradient::PassThrough;
    if pass { blend.transmittance * dot } else { 0.0 }
}

/// Result of [`composite`].
#[derive(Clone, Debug, PartialEq)]
pub struct Composited {
    /// `Σ wᵢ cᵢ + T_final·background`, `C` values.
    pub features: Vec<f32>,
    /// Transmittance after the last blended entry.
    pub final_transmittance: f32,
    /// Per entry `αᵢ·Tᵢ` (the impact), 0 for skipped entries and from the stop on.
    /// `Σ weights = 1 − final_transmittance` up to rounding.
    pub weights: Vec<f32>,
    /// Number of entries examined before the stop: the index of the stopping entry, or the
    /// number of entries when there was no stop.
    pub n_used: usize,
}

/// Gradients from [`composite_vjp`].
#[derive(Clone, Debug, PartialEq)]
pub struct CompositeGrads {
    /// `∂L/∂aᵢ` for the raw alphas (through the clamp per `params.clamp_gradient`).
    pub d_alphas: Vec<f32>,
    /// `∂L/∂cᵢ`, `n × C` interleaved like the features.
    pub d_features: Vec<f32>,
    /// `∂L/∂background`, `C` values.
    pub d_background: Vec<f32>,
}

fn check_inputs(alphas: &[f32], features: &[f32], channels: usize, background: &[f32]) {
    assert_eq!(features.len(), alphas.len() * channels, "features must be n × channels");
    assert_eq!(background.len(), channels, "background must have `channels` values");
}

/// Front-to-back compositing of `alphas.len()` entries in depth order, with `channels` feature
/// channels per entry (`features` is `n × channels`, interleaved per entry) over `background`.
/// See the module docs for the exact semantics.
///
/// # Panics
/// If `features.len() != alphas.len() · channels` or `background.len() != channels`.
pub fn composite(
    alphas: &[f32],
    features: &[f32],
    channels: usize,
    background: &[f32],
    params: &CompositeParams,
) -> Composited {
    check_inputs(alphas, features, channels, background);
    let n = alphas.len();
    let mut out = vec![0.0; channels];
    let mut weights = vec![0.0; n];
    let mut t = 1.0f32;
    let mut n_used = n;
    for (i, &a) in alphas.iter().enumerate() {
        match classify(t, a, params) {
            Step::Skip => {}
            Step::Stop => {
                n_used = i;
                break;
            }
            Step::Blend(b) => {
                let c = &features[i * channels..(i + 1) * channels];
                for (o, &ci) in out.iter_mut().zip(c) {
                    *o += ci * b.weight;
                }
                weights[i] = b.weight;
                t = b.next_transmittance;
            }
        }
    }
    for (o, &bg) in out.iter_mut().zip(background) {
        *o += t * bg;
    }
    Composited {
        features: out,
        final_transmittance: t,
        weights,
        n_used,
    }
}

/// Vector-Jacobian product of [`composite`] for `d_out = ∂L/∂features_out` (`channels` values):
/// recomputes the transmittances front to back, then runs the back-to-front "colour behind"
/// recursion (no division by `1 − α`).
///
/// # Panics
/// As [`composite`], and if `d_out.len() != channels`.
pub fn composite_vjp(
    alphas: &[f32],
    features: &[f32],
    channels: usize,
    background: &[f32],
    params: &CompositeParams,
    d_out: &[f32],
) -> CompositeGrads {
    check_inputs(alphas, features, channels, background);
    assert_eq!(d_out.len(), channels, "d_out must have `channels` values");
    let n = alphas.len();
    // Forward replay: the blended entries and their transmittances.
    let mut blended: Vec<(usize, Blend)> = Vec::with_capacity(n);
    let mut t = 1.0f32;
    for (i, &a) in alphas.iter().enumerate() {
        match classify(t, a, params) {
            Step::Skip => {}
            Step::Stop => break,
            Step::Blend(b) => {
                t = b.next_transmittance;
                blended.push((i, b));
            }
        }
    }
    let mut grads = CompositeGrads {
        d_alphas: vec![0.0; n],
        d_features: vec![0.0; n * channels],
        d_background: d_out.iter().map(|&g| t * g).collect(),
    };
    let mut behind = background.to_vec();
    for &(i, ref b) in blended.iter().rev() {
        let range = i * channels..(i + 1) * channels;
        grads.d_alphas[i] = back_step(
            b,
            &features[range.clone()],
            d_out,
            &mut behind,
            &mut grads.d_features[range],
            params,
        );
    }
    grads
}
