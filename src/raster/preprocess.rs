//! Per-billboard preprocessing: transform, normal, depth, SH colour and a tight screen box.

use super::{BillboardSet, RenderSettings};
use crate::camera::Camera;
use crate::stages::sh::sh_colour;
use crate::stages::splat_transform::{SplatTransform, splat_frame, square_screen_bounds, support_half_side};
use glam::Vec3;
use rayon::prelude::*;

/// What the per-pixel passes need of one visible billboard.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Prepared {
    /// Rows of the ray-splat matrix `T`.
    pub transform: SplatTransform,
    /// Unit normal in view space, flipped to face the camera.
    pub normal: Vec3,
    /// View-space depth of the centre, the sort key.
    pub depth: f32,
    /// SH colour (`Σ + 0.5`, clamped at 0), added to the sampled colour texture.
    pub rgb: Vec3,
    /// Per channel: the SH colour was clamped to 0 ([`crate::stages::sh::ShColour::clamped`]),
    /// kept for the backward pass.
    pub sh_clamped: [bool; 3],
    /// The plane's normal was flipped to face the camera (`normal_sign = −1` of
    /// [`crate::stages::splat_transform::SplatFrame`]), kept for the backward pass.
    pub normal_flipped: bool,
    /// First pixel column and row whose centre lies in the screen box (inclusive).
    pub pixel_min: [u32; 2],
    /// Last pixel column and row whose centre lies in the screen box (inclusive).
    pub pixel_max: [u32; 2],
}

/// Prepares one billboard; `None` when it cannot contribute to any pixel of this view (behind
/// the near plane, exactly edge-on, degenerate, or off screen).
pub fn prepare_one(set: &BillboardSet<'_>, i: usize, camera: &Camera, settings: &RenderSettings) -> Option<Prepared> {
    let position = set.positions[i];
    let projected = splat_frame(position, set.log_scales[i], set.quaternions[i], camera)?;
    // Tight box of the texture support square (clipped by the near plane), as pixel indices.
    let rect = square_screen_bounds(&projected.transform, support_half_side(set.texture_size))?
        .pixel_rect(camera.width, camera.height)?;
    let (pixel_min, pixel_max) = ([rect.x_min, rect.y_min], [rect.x_max - 1, rect.y_max - 1]);
    let colour = sh_colour(settings.sh_degree, set.sh_of(i), position, camera.centre());
    Some(Prepared {
        transform: projected.transform,
        normal: projected.normal_view,
        depth: projected.view_depth,
        rgb: colour.rgb,
        sh_clamped: colour.clamped,
        normal_flipped: projected.normal_sign < 0.0,
        pixel_min,
        pixel_max,
    })
}

/// Prepares every billboard in parallel; entry `i` belongs to billboard `i`.
pub fn preprocess(set: &BillboardSet<'_>, camera: &Camera, settings: &RenderSettings) -> Vec<Option<Prepared>> {
    let mut prepared = Vec::new();
    preprocess_into(set, camera, settings, &mut prepared);
    prepared
}

/// [`preprocess`] into `prepared`, reusing its storage (its old values are all replaced).
pub fn preprocess_into(
    set: &BillboardSet<'_>,
    camera: &Camera,
    settings: &RenderSettings,
    prepared: &mut Vec<Option<Prepared>>,
) {
    (0..set.len())
        .into_par_iter()
        .map(|i| prepare_one(set, i, camera, settings))
        .collect_into_vec(prepared);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The backward's two flags (`sh_clamped`, `normal_flipped`) live in what was padding:
    /// the record every per-pixel pass reads stays 84 bytes (80 before the flags, plus the
    /// `Option` tag, which the flags' `bool` niche now absorbs).
    #[test]
    fn prepared_record_stays_84_bytes() {
        assert_eq!(size_of::<Option<Prepared>>(), 84);
    }
}
