//! Dead and alive billboards: the mean alpha of a billboard and the threshold below which
//! relocation moves it (a leaf: [`crate::model`] re-exports these, and [`super::ActivatedBillboards`]
//! counts with them).

/// Billboards whose mean activated alpha is at most this are *dead* (spec §6, the reference's
/// `dead_opacity`): relocation moves them, [`is_alive`] and the `alive_count` methods count the
/// others.
pub const DEAD_ALPHA: f32 = 0.005;

/// The mean alpha of one billboard: its `texels` activated alpha values (`TS²`, masked texels
/// included as 0) summed in f64 in texel order and divided by `texels` (an empty row gives 0).
/// The one definition used by relocation, the alive counts and the Gaussian-mode opacity.
///
/// ```
/// assert_eq!(bbsplat::billboards::alive::mean_alpha([0.5, 0.0, 0.25, 0.25], 4), 0.25);
/// ```
pub fn mean_alpha(alphas: impl IntoIterator<Item = f32>, texels: usize) -> f32 {
    let sum: f64 = alphas.into_iter().map(f64::from).sum();
    (sum / texels.max(1) as f64) as f32
}

/// True when a billboard of mean alpha `mean_alpha` is alive: strictly above [`DEAD_ALPHA`]
/// (NaN is dead).
#[inline]
pub fn is_alive(mean_alpha: f32) -> bool {
    mean_alpha > DEAD_ALPHA
}
