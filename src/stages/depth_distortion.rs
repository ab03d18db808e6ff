//! The 2DGS depth-distortion map of one pixel, forward and backward.
//!
//! Method (spec §3.3 step 6, §4): the hit depth `z` of each blended entry is mapped to
//! `m = (FAR·z − FAR·NEAR) / ((FAR − NEAR)·z)` with [`NEAR`] = 0.2 and [`FAR`] = 100 (0 at the
//! near plane, → `FAR/(FAR − NEAR)` at infinity), and, front to back with the entry's weight
//! `w = α·T` and the transmittance `T` in front of it, starting from `S1 = S2 = 0`:
//!
//! `distortion += (m²·(1 − T) + S2 − 2·m·S1)·w`, then `S1 += m·w`, `S2 += m²·w`.
//!
//! Since `1 − Tᵢ = Σ_{j<i} w_j`, the result is `Σ_i Σ_{j<i} w_i w_j (m_i − m_j)²`: the
//! weighted spread of the hit depths along the ray. Its gradients (2DGS's backward with
//! `DETACH_WEIGHT = 0`), with the pixel's totals `A = Σ w`, `D = Σ w m`, `D2 = Σ w m²` and the
//! upstream gradient `g = ∂L/∂distortion`:
//! - `∂L/∂w_i = g·(m_i²·A + D2 − 2·m_i·D)`: a per-entry quantity that the compositing recursion
//!   turns into `∂L/∂α` exactly as it does a feature channel (see [`weight_gradient`]);
//! - `∂L/∂m_i = 2·g·w_i·(m_i·A − D)`, and `∂m/∂z = FAR·NEAR / ((FAR − NEAR)·z²)`
//!   ([`depth_gradient`]).
//!
//! ```
//! use bbsplat::stages::depth_distortion::{DistortionState, mapped_depth};
//! // Two entries at the same depth: no distortion.
//! let mut s = DistortionState::default();
//! s.add(mapped_depth(2.0), 0.5, 1.0);
//! s.add(mapped_depth(2.0), 0.25, 0.5);
//! assert!(s.distortion.abs() < 1e-7);
//! // At different depths: w₀·w₁·(m₁ − m₀)².
//! let mut s = DistortionState::default();
//! let (m0, m1) = (mapped_depth(1.0), mapped_depth(3.0));
//! s.add(m0, 0.5, 1.0);
//! s.add(m1, 0.25, 0.5);
//! assert!((s.distortion - 0.5 * 0.25 * (m1 - m0).powi(2)).abs() < 1e-7);
//! ```

/// Near value of the depth mapping (the reference's `NEAR_PLANE`).
pub const NEAR: f32 = 0.2;
/// Far value of the depth mapping (the reference's `FAR_PLANE`).
pub const FAR: f32 = 100.0;

/// The mapped depth `m = (FAR·z − FAR·NEAR) / ((FAR − NEAR)·z)` of a hit at view depth `z`.
#[inline]
pub fn mapped_depth(z: f32) -> f32 {
    (FAR * z - FAR * NEAR) / ((FAR - NEAR) * z)
}

/// `∂m/∂z = FAR·NEAR / ((FAR − NEAR)·z²)` of [`mapped_depth`].
#[inline]
pub fn mapped_depth_derivative(z: f32) -> f32 {
    FAR * NEAR / ((FAR - NEAR) * z * z)
}

/// Front-to-back accumulation of one pixel's distortion.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DistortionState {
    /// `Σ w·m` of the entries so far.
    pub s1: f32,
    /// `Σ w·m²` of the entries so far.
    pub s2: f32,
    /// The distortion so far.
    pub distortion: f32,
}

impl DistortionState {
    /// Adds an entry with mapped depth `m`, weight `w = α·T` and transmittance `T` in front of
    /// it (the reference's formula and order of operations).
    #[inline]
    pub fn add(&mut self, m: f32, weight: f32, transmittance: f32) {
        self.distortion += (m * m * (1.0 - transmittance) + self.s2 - 2.0 * m * self.s1) * weight;
        self.s1 += m * weight;
        self.s2 += m * m * weight;
    }
}

/// A pixel's totals over its blended entries: `A = Σ w`, `D = Σ w·m`, `D2 = Σ w·m²`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DistortionTotals {
    /// `Σ w`.
    pub weight: f32,
    /// `Σ w·m`.
    pub mapped: f32,
    /// `Σ w·m²`.
    pub mapped_sq: f32,
}

impl DistortionTotals {
    /// Adds an entry of mapped depth `m` and weight `w`.
    #[inline]
    pub fn add(&mut self, m: f32, weight: f32) {
        self.weight += weight;
        self.mapped += m * weight;
        self.mapped_sq += m * m * weight;
    }
}

/// `∂distortion/∂w_i = m_i²·A + D2 − 2·m_i·D` for an entry of mapped depth `m` (multiply by the
/// upstream gradient). Fed to the compositing backward as the entry's value of an extra feature
/// channel whose upstream gradient is `∂L/∂distortion`, it yields the distortion's share of
/// `∂L/∂α` for every entry (the weights' dependence on the alphas in front is the compositing
/// recursion's).
#[inline]
pub fn weight_gradient(m: f32, totals: &DistortionTotals) -> f32 {
    m * m * totals.weight + totals.mapped_sq - 2.0 * m * totals.mapped
}

/// `∂L/∂z` of an entry at view depth `z` (mapped depth `m`, weight `w`) for the upstream
/// gradient `g = ∂L/∂distortion`: `2·g·w·(m·A − D)·∂m/∂z`.
#[inline]
pub fn depth_gradient(z: f32, m: f32, weight: f32, totals: &DistortionTotals, g: f32) -> f32 {
    2.0 * g * weight * (m * totals.weight - totals.mapped) * mapped_depth_derivative(z)
}
