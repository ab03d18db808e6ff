//! The depth at which neighbouring views agree on a pixel's colour: a plane sweep along one
//! pixel's ray. Error growth ([`crate::train::place`]) uses it to put a new billboard where the
//! scene is rather than where the model renders it.
//!
//! # Rules
//!
//! - **Depths.** [`SweepConfig::depths`] depths log-spaced over `[near, far]` (both included;
//!   one depth: their geometric mean).
//! - **Cost of a depth.** The point at that view depth on the ray through the pixel's centre is
//!   projected into each neighbour view; when the `(2r+1)²` patch around the projection
//!   (nearest pixels, the same orientation as the source patch, `r` =
//!   [`SweepConfig::patch_radius`]) lies wholly inside that image and the point is beyond
//!   [`NEAR_PLANE`] there, the view contributes the mean squared RGB difference between the two
//!   patches. A depth **counts** when at least [`MIN_SEEING`] neighbours contribute; its cost is
//!   their mean.
//! - **Result.** The counting depth of least cost (ties to the nearer depth), its cost and the
//!   median cost over the counting depths; none when no depth counts. It is **distinct**
//!   ([`Sweep::distinct`]) when its cost is below [`DISTINCT`] × that median and at most
//!   [`MAX_COST`]: on an even surface every depth costs about the same (all 0 on a saturated
//!   one) and no depth is distinct, so the caller keeps its own guess.
//! - **Neighbours** ([`nearest_views`]): the views with the nearest camera centres, ties to
//!   the lower index.
//!
//! Pure functions of their inputs: the same answer for any thread count.

use crate::camera::Camera;
use crate::stages::splat_transform::NEAR_PLANE;
use glam::Vec3;

/// A distinct least cost is at most this fraction of the median cost over the depths.
pub const DISTINCT: f32 = 0.25;
/// Largest mean squared RGB difference a distinct depth may have (about 18/255 a channel).
pub const MAX_COST: f32 = 0.005;
/// Fewest neighbour views that must see a depth for it to count.
pub const MIN_SEEING: usize = 2;

/// A posed RGB image the sweep reads (a loaded scene view or a training view).
pub trait SweepImage {
    /// The camera.
    fn camera(&self) -> &Camera;
    /// Pixel `(x, y)` (inside the camera's image) as RGB in `[0, 1]`.
    fn rgb(&self, x: u32, y: u32) -> [f32; 3];
}

/// Sweep settings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SweepConfig {
    /// Depths tried along the ray.
    pub depths: usize,
    /// Neighbour views compared.
    pub neighbours: usize,
    /// Patch half side in pixels.
    pub patch_radius: u32,
}

impl Default for SweepConfig {
    /// 32 depths, 4 neighbours, 5×5 patches.
    fn default() -> Self {
        SweepConfig {
            depths: 32,
            neighbours: 4,
            patch_radius: 2,
        }
    }
}

/// What the sweep of one pixel found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sweep {
    /// The world point at the least-cost depth.
    pub point: Vec3,
    /// That view depth.
    pub depth: f32,
    /// Its cost.
    pub cost: f32,
    /// The median cost over the counting depths.
    pub median_cost: f32,
}

impl Sweep {
    /// A distinct minimum: cost below [`DISTINCT`] × the median (so never when every depth
    /// costs 0, as on a saturated region) and at most [`MAX_COST`].
    pub fn distinct(&self) -> bool {
        self.cost < DISTINCT * self.median_cost && self.cost <= MAX_COST
    }
}

/// The `k` views whose camera centres (`centres`, one per view) are nearest view `i`'s (not
/// `i`), nearest first, ties to the lower index.
pub fn nearest_views(centres: &[Vec3], i: usize, k: usize) -> Vec<usize> {
    let c = centres[i];
    let mut others: Vec<(f32, usize)> = (0..centres.len())
        .filter(|&j| j != i)
        .map(|j| ((centres[j] - c).length(), j))
        .collect();
    others.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    others.into_iter().take(k).map(|(_, j)| j).collect()
}

/// The sweep of pixel `(x, y)` of view `v` over view depths `[near, far]` against the views
/// `neighbours` (module rules); `None` when no depth counts, when the pixel's patch does not
/// fit in its image, or when the range is empty or not positive.
#[allow(clippy::too_many_arguments)]
pub fn sweep_pixel<V: SweepImage>(
    views: &[V],
    v: usize,
    neighbours: &[usize],
    x: u32,
    y: u32,
    near: f32,
    far: f32,
    config: &SweepConfig,
) -> Option<Sweep> {
    let cam = views[v].camera();
    let r = config.patch_radius;
    let fits = x >= r && y >= r && x + r < cam.width && y + r < cam.height;
    if !fits || config.depths == 0 || !(near > 0.0 && far >= near && far.is_finite()) {
        return None;
    }
    let r = r as i64;
    let patch: Vec<[f32; 3]> = patch_offsets(r)
        .map(|(dx, dy)| views[v].rgb((x as i64 + dx) as u32, (y as i64 + dy) as u32))
        .collect();
    let cam_to_world = cam.rotation.transpose();
    let ray = Vec3::new(
        (x as f32 + 0.5 - cam.cx) / cam.fx,
        (y as f32 + 0.5 - cam.cy) / cam.fy,
        1.0,
    );
    let mut best: Option<(f32, Vec3, f32)> = None;
    let mut costs = Vec::with_capacity(config.depths);
    for j in 0..config.depths {
        let t = if config.depths == 1 {
            0.5
        } else {
            j as f32 / (config.depths - 1) as f32
        };
        let depth = near * (far / near).powf(t);
        let world = cam_to_world * (ray * depth - cam.translation);
        let (mut sum, mut seeing) = (0.0f32, 0usize);
        for &n in neighbours {
            if let Some(cost) = patch_cost(&views[n], world, r, &patch) {
                sum += cost;
                seeing += 1;
            }
        }
        if seeing < MIN_SEEING {
            continue;
        }
        let cost = sum / seeing as f32;
        costs.push(cost);
        if best.is_none_or(|(b, _, _)| cost < b) {
            best = Some((cost, world, depth));
        }
    }
    let (cost, point, depth) = best?;
    costs.sort_unstable_by(f32::total_cmp);
    Some(Sweep {
        point,
        depth,
        cost,
        median_cost: costs[costs.len() / 2],
    })
}

/// Offsets of a `(2r+1)²` patch, row by row.
fn patch_offsets(r: i64) -> impl Iterator<Item = (i64, i64)> {
    (-r..=r).flat_map(move |dy| (-r..=r).map(move |dx| (dx, dy)))
}

/// Mean squared RGB difference between `patch` and the patch around `world`'s projection in
/// `view`, or `None` when that patch is not wholly inside the image or the point is not beyond
/// the near plane.
fn patch_cost<V: SweepImage>(view: &V, world: Vec3, r: i64, patch: &[[f32; 3]]) -> Option<f32> {
    let cam = view.camera();
    if cam.world_to_view(world).z <= NEAR_PLANE {
        return None;
    }
    let (px, py) = cam.project(world)?;
    if !(px.is_finite() && py.is_finite()) {
        return None;
    }
    let (cx, cy) = (px.floor() as i64, py.floor() as i64);
    if cx - r < 0 || cy - r < 0 || cx + r >= cam.width as i64 || cy + r >= cam.height as i64 {
        return None;
    }
    let mut sum = 0.0f32;
    for ((dx, dy), a) in patch_offsets(r).zip(patch) {
        let b = view.rgb((cx + dx) as u32, (cy + dy) as u32);
        sum += (0..3).map(|c| (a[c] - b[c]) * (a[c] - b[c])).sum::<f32>();
    }
    Some(sum / (3 * patch.len()) as f32)
}
