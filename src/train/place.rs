//! Billboards placed where a view is rendered badly: the error-driven part of growth.
//!
//! Growth as the reference does it ([`super::grow`]) copies existing billboards in proportion to
//! their alpha, so it adds detail where the set already is and can never reach a region the set
//! missed (a railing, a staircase, a far floor rendered as a blur). With
//! [`super::TrainConfig::error_growth`] above 0, that share of each growth step's new billboards
//! is instead placed on the training view just rendered:
//!
//! 1. pixel `p` is drawn with probability ∝ `e_p²`, `e_p = Σ_c |rendered − target|` (the L1
//!    error the loss sees, squared so that the worst regions get most of the draws), with
//!    replacement, by the trainer's RNG;
//! 2. a point uniform inside the pixel is lifted to a view depth: the caller's `refine_depth`
//!    of the pixel and the depth `z` of the rendered surface there (the median depth of the
//!    render, [`crate::RenderOutput::median_depth`]; where the render has none, the median of
//!    the view's median depths). The trainer refines with a plane sweep
//!    ([`super::depth_sweep`]) over `[z / `[`SWEEP_RANGE`]`, z · `[`SWEEP_RANGE`]`]` against the
//!    four training views with the nearest cameras, and keeps `z` where no depth is distinct:
//!    the model renders a region it missed at the depth of whatever covers it (a wall for a
//!    railing in front of it), and a billboard placed there fits this view only;
//! 3. the billboard faces the camera (its axes the camera's right, down and forward axes), has
//!    the half side [`HALF_SIDE_PX`] pixels at that depth, and the target colour of the pixel
//!    (set as the SH colour the way initialisation sets a point's, [`RawBillboards::from_points`]:
//!    alpha `0.5·G`, colour texture 0.1).
//!
//! The billboards start as small camera-facing patches of the right colour at the depth the
//! views agree on (or the model's); training moves, turns and resizes them like any other.

use crate::camera::Camera;
use crate::model::RawBillboards;
use crate::rng::Rng;
use glam::{Mat3, Quat, Vec2, Vec3};

/// Half side, in pixels of the view it is placed from, of a placed billboard.
pub const HALF_SIDE_PX: f32 = 4.0;

/// The plane sweep that refines a placement depth `z` searches `[z / SWEEP_RANGE, z ·
/// SWEEP_RANGE]`.
pub const SWEEP_RANGE: f32 = 2.0;

/// One view's render and its target, what placement reads (`width · height` pixels, RGB
/// interleaved row by row).
#[derive(Clone, Copy, Debug)]
pub struct ViewError<'a> {
    /// The rendered RGB.
    pub rendered: &'a [f32],
    /// The target RGB.
    pub target: &'a [f32],
    /// The render's median depth per pixel (0: none).
    pub median_depth: &'a [f32],
}

/// The billboards to place: `count` draws on the view (empty when the view has no error, no
/// rendered depth anywhere, or `count` is 0). `refine_depth(x, y, z)` gives the depth used for
/// pixel `(x, y)` whose rendered depth is `z` (`|_, _, z| z` keeps the render's; called once a
/// draw, in draw order). Positions, camera-facing rotations, half sides and
/// colours, in draw order, as rows of a [`RawBillboards`] of texture size `texture_size`.
///
/// # Panics
/// When the slices do not hold the camera's pixels.
pub fn place_on_error(
    view: &ViewError<'_>,
    cam: &Camera,
    count: usize,
    texture_size: usize,
    rng: &mut Rng,
    refine_depth: impl Fn(u32, u32, f32) -> f32,
) -> RawBillboards {
    let (w, h) = (cam.width as usize, cam.height as usize);
    assert_eq!(view.rendered.len(), 3 * w * h, "rendered RGB of the camera's size");
    assert_eq!(view.target.len(), 3 * w * h, "target RGB of the camera's size");
    assert_eq!(view.median_depth.len(), w * h, "a median depth per pixel");
    let empty = || RawBillboards::from_points(&[], &[], texture_size, 0);
    if count == 0 {
        return empty();
    }
    let Some(fallback_depth) = median_positive(view.median_depth) else {
        return empty();
    };
    // Cumulative weights in f64 (a fixed order: the same draws for any thread count).
    let mut cumulative = Vec::with_capacity(w * h);
    let mut total = 0.0f64;
    for p in 0..w * h {
        let e: f64 = (0..3)
            .map(|c| (view.rendered[3 * p + c] as f64 - view.target[3 * p + c] as f64).abs())
            .sum();
        if e.is_finite() {
            total += e * e;
        }
        cumulative.push(total);
    }
    if total <= 0.0 {
        return empty();
    }
    let cam_to_world = cam.rotation.transpose();
    let facing = quaternion_of(cam_to_world);
    let mut points = Vec::with_capacity(count);
    let mut colours = Vec::with_capacity(count);
    let mut half_sides = Vec::with_capacity(count);
    for _ in 0..count {
        let u = rng.uniform() as f64 * total;
        let p = cumulative.partition_point(|&c| c <= u).min(w * h - 1);
        let depth = view.median_depth[p];
        let z = if depth > 0.0 && depth.is_finite() {
            depth
        } else {
            fallback_depth
        };
        let z = match refine_depth((p % w) as u32, (p / w) as u32, z) {
            refined if refined > 0.0 && refined.is_finite() => refined,
            _ => z,
        };
        let x = (p % w) as f32 + rng.uniform();
        let y = (p / w) as f32 + rng.uniform();
        let in_view = Vec3::new((x - cam.cx) / cam.fx * z, (y - cam.cy) / cam.fy * z, z);
        points.push(cam_to_world * (in_view - cam.translation));
        colours.push(std::array::from_fn(|c| view.target[3 * p + c].clamp(0.0, 1.0)));
        half_sides.push(HALF_SIDE_PX * z / cam.fx.max(cam.fy));
    }
    let mut placed = RawBillboards::from_points(&points, &colours, texture_size, 0);
    for (i, s) in half_sides.into_iter().enumerate() {
        placed.quaternions[i] = facing;
        placed.log_scales[i] = Vec2::splat(s.ln());
    }
    placed
}

/// The raw quaternion `[w, x, y, z]` of the rotation whose columns are `m`'s.
fn quaternion_of(m: Mat3) -> [f32; 4] {
    let q = Quat::from_mat3(&m).normalize();
    [q.w, q.x, q.y, q.z]
}

/// The median of the positive finite values (the lower middle one for an even count), `None`
/// when there are none.
fn median_positive(values: &[f32]) -> Option<f32> {
    let mut v: Vec<f32> = values.iter().copied().filter(|d| *d > 0.0 && d.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    let mid = (v.len() - 1) / 2;
    let (_, m, _) = v.select_nth_unstable_by(mid, f32::total_cmp);
    Some(*m)
}
