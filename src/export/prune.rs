//! Which billboards are worth exporting (spec §10.3 step 1): impact summed over the training
//! views, and the largest alpha texel.

use crate::camera::Camera;
use crate::raster::{ActivatedRef, RenderBuffers, RenderSettings, render_with};

/// The pruning thresholds; [`Default`] gives the reference's values.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PruneRule {
    /// A billboard is kept only if its impact over the total impact is `>` this (reference: 1e-6).
    pub min_impact_share: f64,
    /// A billboard is kept only if its largest alpha texel is `>` this (reference: 0.2).
    pub min_max_alpha: f32,
}

impl Default for PruneRule {
    fn default() -> Self {
        Self {
            min_impact_share: 1e-6,
            min_max_alpha: 0.2,
        }
    }
}

/// Per billboard, the sum over `cameras` of its impact (the sum of its blending weights
/// `alpha·T` over the pixels of a render, spec §3.3 step 7), accumulated in f64 in camera order.
pub fn accumulate_impact<'c>(
    set: &ActivatedRef<'_>,
    cameras: impl IntoIterator<Item = &'c Camera>,
    settings: &RenderSettings,
) -> Vec<f64> {
    let mut total = vec![0.0f64; set.len()];
    // The render's storage recycled from view to view (the same impacts, fewer fresh pages).
    let mut buffers = RenderBuffers::default();
    for camera in cameras {
        let out = render_with(set, camera, settings, std::mem::take(&mut buffers));
        for (t, &i) in total.iter_mut().zip(&out.impact) {
            *t += f64::from(i);
        }
        buffers = out.into_buffers();
    }
    total
}

/// The indices of the billboards kept by `rule`, ascending: impact share `impact[i] / Σ impact`
/// `> rule.min_impact_share` and largest alpha texel (`textures` RGBA, `texels` per billboard)
/// `> rule.min_max_alpha`. When the total impact is 0 no billboard passes the impact test.
///
/// ```
/// use bbsplat::export::prune::{PruneRule, kept_billboards};
/// // Two billboards of one texel each: the second is too transparent.
/// let textures = [[0.5, 0.5, 0.5, 0.9], [0.5, 0.5, 0.5, 0.1]];
/// assert_eq!(kept_billboards(&[1.0, 1.0], &textures, 1, &PruneRule::default()), vec![0]);
/// ```
pub fn kept_billboards(impact: &[f64], textures: &[[f32; 4]], texels: usize, rule: &PruneRule) -> Vec<usize> {
    let total: f64 = impact.iter().sum();
    (0..impact.len())
        .filter(|&i| {
            let share = if total > 0.0 { impact[i] / total } else { 0.0 };
            let max_alpha = textures[i * texels..(i + 1) * texels]
                .iter()
                .map(|t| t[3])
                .fold(f32::NEG_INFINITY, f32::max);
            share > rule.min_impact_share && max_alpha > rule.min_max_alpha
        })
        .collect()
}
