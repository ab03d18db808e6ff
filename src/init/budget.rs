//! The default billboard budget: model only what a scene needs.
//!
//! The reference fixes the count per dataset (`--cap_max`, 160 000 by default, spec §6, §8).
//! Here the count is derived from what the data can constrain:
//!
//! 1. **Pixels.** A billboard whose footprint in the views that see it is below
//!    `A = TS²/4` pixels (8×8 at TS = 16) resolves less than a quarter of its texels: its texture
//!    is wasted and a Gaussian would do. A view of `P` pixels therefore constrains about `P/A`
//!    billboards per layer. Views around an object see roughly half of the surface each and
//!    splats overlap about twice along a ray, so the scene holds about `S = 2 × 2 = 4` views'
//!    worth of surface ([`COVERAGE`]); with fewer than 4 views, `S` is the number of views (a
//!    view only constrains what it sees). Pixel bound: `⌈S·P/A⌉` with `P` the median pixel count
//!    of the training views, clamped to `[`[`MIN_BUDGET`]`, `[`MAX_BUDGET`]`]` (the upper end
//!    is the reference default cap).
//! 2. **Points.** With `m` SfM points, `m + sky(m)` of the budget start on the points and the
//!    sky (`sky` = [`sky_point_count`]; farthest-point sampled when they are more), and the CLI's
//!    default initialisation puts the rest on a background shell
//!    ([`crate::init::scene_init`]): a capture's points sit where features matched, mostly on
//!    the object, while walls and far surfaces seen by a few views need billboards too (on
//!    beer_colmap +0.24 dB at 30 minutes against stopping at the point count, `docs/quality.md`).
//!    Growth during training ([`crate::train::grow`]) then adds billboards up to [`growth_cap`].
//!
//! So the budget is the pixel bound; the reason names the point count too. Figures for the test
//! scenes (TS 16): NeRF-synthetic lego at 400×400 (100 views, no points) → 10 000; the fox
//! (225×400 cropped by undistortion to a median 87 912 px, no points) → 5 495; beer_colmap
//! (median 87 074 px) with 4 414 points → 5 443, of which 1 029 on the shell; the demo scene
//! exported at the CLI defaults (35 train views at 96×96, 6 000 points) → 576. `bbsplat demo`
//! itself does not use the budget. See `docs/numerics-init-loss.md` §9.
//!
//! ```
//! use bbsplat::init::budget::{budget_for, BudgetInputs};
//! let lego = BudgetInputs { views: 100, pixels_per_view: 400 * 400, sfm_points: None, texture_size: 16 };
//! assert_eq!(budget_for(&lego).billboards, 10_000);
//! let beer = BudgetInputs { views: 62, pixels_per_view: 225 * 400, sfm_points: Some(4_414), texture_size: 16 };
//! assert_eq!(budget_for(&beer).billboards, 5_625);
//! ```

use crate::init::fibonacci::sky_point_count;
use crate::scene::Scene;

/// Surface "views' worth" a scene holds: half the surface visible per view, two layers.
pub const COVERAGE: u64 = 4;
/// Smallest pixel bound.
pub const MIN_BUDGET: usize = 256;
/// Largest budget (the reference default `--cap_max`).
pub const MAX_BUDGET: usize = 160_000;

/// A billboard count and why.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Budget {
    /// Number of billboards.
    pub billboards: usize,
    /// The rule and the numbers it used, for logs.
    pub reason: String,
}

/// What the budget rule looks at.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BudgetInputs {
    /// Number of training views.
    pub views: usize,
    /// Median pixel count (`width·height`) of a training view.
    pub pixels_per_view: u64,
    /// Number of finite SfM points, when the scene has a point cloud.
    pub sfm_points: Option<usize>,
    /// Texture side TS.
    pub texture_size: usize,
}

impl BudgetInputs {
    /// The inputs of a loaded scene, at texture side `texture_size`. An empty point cloud
    /// counts as none (initialisation then places random points).
    pub fn from_scene(scene: &Scene, texture_size: usize) -> Self {
        let mut pixels: Vec<u64> = scene
            .train
            .iter()
            .map(|v| v.camera.width as u64 * v.camera.height as u64)
            .collect();
        pixels.sort_unstable();
        let pixels_per_view = if pixels.is_empty() {
            0
        } else {
            pixels[(pixels.len() - 1) / 2]
        };
        let sfm_points = scene
            .points
            .as_ref()
            .map(|p| p.positions.iter().filter(|p| p.is_finite()).count())
            .filter(|&m| m > 0);
        BudgetInputs {
            views: scene.train.len(),
            pixels_per_view,
            sfm_points,
            texture_size,
        }
    }
}

/// The pixel bound of rule 1 and its explanation.
fn pixel_bound(inputs: &BudgetInputs) -> (usize, String) {
    let ts = inputs.texture_size.max(1) as u64;
    let footprint = (ts * ts).div_ceil(4).max(1);
    let coverage = (inputs.views as u64).min(COVERAGE);
    let raw = (coverage * inputs.pixels_per_view).div_ceil(footprint);
    let bound = (raw.min(MAX_BUDGET as u64) as usize).max(MIN_BUDGET);
    let reason = format!(
        "pixel bound {bound} = clamp(ceil({coverage} views' worth x {} px / {footprint} px per billboard), \
         {MIN_BUDGET}, {MAX_BUDGET})",
        inputs.pixels_per_view
    );
    (bound, reason)
}

/// Cap of growth over the pixel bound ([`growth_cap`]).
pub const GROWTH_CAP_FACTOR: usize = 2;

/// The growth cap of a scene (the count [`crate::train::grow`] grows toward): `min(`
/// [`MAX_BUDGET`]`, `[`GROWTH_CAP_FACTOR`]` × pixel bound)`, never below `initial`. The pixel
/// bound is what the views constrain at one layer per footprint; the factor 2 leaves room for
/// growth to add billboards where alpha says the scene needs them (the reference grows 60k-100k
/// initial billboards to caps of 60k-300k, spec §6). A provisional rule: it was not chosen by a
/// quality measurement yet (`docs/quality.md`).
///
/// ```
/// use bbsplat::init::budget::{growth_cap, BudgetInputs};
/// let beer = BudgetInputs { views: 62, pixels_per_view: 87_074, sfm_points: Some(4_414), texture_size: 16 };
/// assert_eq!(growth_cap(&beer, 4_414).billboards, 10_886);
/// ```
pub fn growth_cap(inputs: &BudgetInputs, initial: usize) -> Budget {
    let (bound, reason) = pixel_bound(inputs);
    let cap = (GROWTH_CAP_FACTOR * bound).min(MAX_BUDGET).max(initial);
    Budget {
        billboards: cap,
        reason: format!("cap {cap} = max(initial {initial}, min({MAX_BUDGET}, {GROWTH_CAP_FACTOR} x {reason}))"),
    }
}

/// The budget rule of the [module documentation](self).
pub fn budget_for(inputs: &BudgetInputs) -> Budget {
    let (pixel_bound, mut reason) = pixel_bound(inputs);
    match inputs.sfm_points {
        Some(m) => {
            let sky = sky_point_count(m.min(pixel_bound));
            let on_points = m.min(pixel_bound - sky) + sky;
            reason.push_str(&format!(
                "; {on_points} on {m} SfM points and {sky} sky, {} on a background shell",
                pixel_bound - on_points
            ));
        }
        None => reason.push_str("; no SfM points"),
    }
    let billboards = pixel_bound;
    Budget {
        billboards,
        reason: format!("{billboards} billboards: {reason}"),
    }
}

/// The default budget of a loaded scene at TS 16 ([`budget_for`] of
/// [`BudgetInputs::from_scene`]).
pub fn default_budget(scene: &Scene) -> Budget {
    budget_for(&BudgetInputs::from_scene(scene, 16))
}
