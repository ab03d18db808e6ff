//! The initial point set of a scene (spec §8, supplement §6.3): SfM points reduced by farthest
//! point sampling plus a Fibonacci sky sphere, or uniform random points in a box when the
//! scene has no points.
//!
//! # Rules
//!
//! - **With SfM points** (`m ≥ 1` finite points; non-finite ones are dropped and counted):
//!   - sky points `s = sky_point_count(min(m, N))` (supplement: none below 10 000 points,
//!     2 000 up to 20 000, else 10 000), where `min(m, N)` is the number of SfM points the run
//!     would use without a sky;
//!   - SfM points `min(m, N − s)`, chosen by [`farthest_point_sampling`] (start at index 0;
//!     all of them when `m ≤ N − s`, in file order; so the total `min(m, N − s) + s` is below
//!     `N` only when the cloud is small);
//!   - sky on the sphere around the world origin of radius [`sky_radius`] of **all** finite SfM
//!     points (before sampling: FPS picks outliers first, so the sampled set has a larger
//!     outlier fraction). That radius is robust: `min(1.1 × the 99th percentile of the points'
//!     L∞ norms, the largest L∞ norm)`, so up to 1 % far outliers do not blow the sky up
//!     (the reference uses the largest L∞ norm, also reported);
//!   - sky colour white `(1, 1, 1)`, SfM colours as read; sky points first (reference order);
//!   - with [`PointlessInit::Auto`] (the CLI default), a budget beyond the SfM and sky points
//!     is filled by a background shell of the remaining `N − min(m, N − s) − s` points, as the
//!     one of a scene without points below (the SfM points of a capture sit where features
//!     matched, mostly on the object; walls and far surfaces seen by a few views get none).
//!     On beer_colmap (4 414 points, budget 5 443) this gave +0.24 dB at 30 minutes and
//!     +0.27 dB at 5 minutes (`docs/quality.md`). The other variants keep the reference's
//!     SfM + sky only.
//! - **Without points** (NeRF-synthetic, instant-ngp): the scene box comes from the training
//!   cameras for every format ([`camera_box`]): the centre is the least-squares point nearest
//!   to all optical axes (what the cameras look at), the half side is the median over cameras
//!   of `distance to the centre × sin(half the smaller field of view)`: the cube around the
//!   largest sphere the median camera sees whole. (On lego, 400×400 with fx = 555.6 px and
//!   cameras 4.03 from the origin, this rule gives a half side of 1.37 around the origin, close
//!   to the spec's fixed `[−1.3, 1.3]³`, which an unseen scene whose cameras sit far from the
//!   origin would miss entirely.) What goes in it ([`PointlessInit`]):
//!   - [`PointlessInit::Random`]: `N` points uniform in the box, colour
//!     `0.5 + C0·U[0, 1/255]` per channel (the reference's `SH2RGB(U[0, 1/255])`, grey), seeded;
//!   - [`PointlessInit::Hull`]: the visual hull of the alpha masks ([`crate::init::hull`]);
//!   - [`PointlessInit::Auto`] (the CLI default): the hull when any training view has an alpha
//!     mask (the background is then a uniform colour and needs no billboards); otherwise
//!     `N − ⌊N·`[`SHELL_FRACTION`]`⌋` random points in the box and a background shell of
//!     `⌊N·SHELL_FRACTION⌋` points on a Fibonacci sphere around the box centre of radius
//!     [`SHELL_RADIUS_FACTOR`] × the largest camera distance from it (beyond every camera,
//!     like the reference's sky sphere: floors, walls and sky far from the object have
//!     billboards to start from), grey as the random points.

use crate::init::fibonacci::{fibonacci_sphere, sky_point_count, sky_radius, sky_radius_reference};
use crate::init::fps::farthest_point_sampling;
use crate::init::hull::{HullConfig, HullError, visual_hull_points};
use crate::model::RawBillboards;
use crate::rng::Rng;
use crate::scene::Scene;
use crate::stages::sh::SH_C0;
use glam::{DVec3, Vec3};
use thiserror::Error;

/// Half side of the reference's NeRF-synthetic random box (spec §8), for comparison: the box
/// now comes from the cameras ([`camera_box`]) for every format.
pub const BLENDER_HALF_SIDE: f32 = 1.3;
/// Fraction of the budget on the background shell of [`PointlessInit::Auto`] without masks.
pub const SHELL_FRACTION: f64 = 0.25;
/// Radius of the background shell over the largest camera distance from the box centre.
pub const SHELL_RADIUS_FACTOR: f32 = 2.0;
/// Colour of sky points.
pub const SKY_COLOUR: [f32; 3] = [1.0, 1.0, 1.0];

/// What [`init_points`] did.
#[derive(Clone, Debug, PartialEq)]
pub struct InitReport {
    /// The budget asked for.
    pub budget: usize,
    /// Finite SfM points in the scene (0 without a point cloud).
    pub sfm_available: usize,
    /// Non-finite SfM points dropped.
    pub sfm_dropped: usize,
    /// SfM points kept.
    pub sfm: usize,
    /// Sky points added.
    pub sky: usize,
    /// Random points added.
    pub random: usize,
    /// Points on the background shell ([`PointlessInit::Auto`] without masks, or filling an
    /// SfM scene's budget beyond its points).
    pub shell: usize,
    /// Radius of the background shell, 0 without.
    pub shell_radius: f32,
    /// Points on the visual hull's surface ([`PointlessInit::Hull`]).
    pub hull: usize,
    /// Surface voxels the hull points were sampled from (0 without a hull).
    pub hull_candidates: usize,
    /// Sky radius used (robust rule), 0 without sky.
    pub sky_radius: f32,
    /// The reference's sky radius (largest L∞ norm) for comparison, 0 without sky.
    pub sky_radius_reference: f32,
    /// The box of the random points `(min, max)`, when random points were placed.
    pub random_box: Option<(Vec3, Vec3)>,
    /// How the box was chosen.
    pub box_rule: String,
}

impl InitReport {
    /// Total points.
    pub fn total(&self) -> usize {
        self.sfm + self.sky + self.random + self.hull + self.shell
    }
}

impl std::fmt::Display for InitReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} points for a budget of {}: {} SfM (of {}), {} sky, {} random",
            self.total(),
            self.budget,
            self.sfm,
            self.sfm_available,
            self.sky,
            self.random
        )?;
        if self.hull > 0 {
            write!(
                f,
                ", {} on the visual hull (farthest points of {} surface voxels)",
                self.hull, self.hull_candidates
            )?;
        }
        if self.shell > 0 {
            write!(
                f,
                ", {} on a background shell of radius {:.3}",
                self.shell, self.shell_radius
            )?;
        }
        if self.sky > 0 {
            write!(
                f,
                "; sky radius {:.3} (reference rule {:.3})",
                self.sky_radius, self.sky_radius_reference
            )?;
        }
        if let Some((lo, hi)) = self.random_box {
            write!(f, "; box {lo:.3} to {hi:.3} ({})", self.box_rule)?;
        }
        Ok(())
    }
}

/// Initial points, their colours and the report.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneInit {
    /// Positions (sky first, then SfM; or the random points).
    pub points: Vec<Vec3>,
    /// RGB in `[0, 1]`, one per point.
    pub colours: Vec<[f32; 3]>,
    /// What was done.
    pub report: InitReport,
}

/// Errors of [`init_points`].
#[derive(Debug, Error, PartialEq)]
#[non_exhaustive]
pub enum InitError {
    /// A budget of zero billboards.
    #[error("the billboard budget is 0")]
    ZeroBudget,
    /// The visual hull could not be built.
    #[error("visual-hull initialisation: {0}")]
    Hull(#[from] HullError),
}

/// Where billboards go in a scene without SfM points (and, for [`PointlessInit::Auto`], the
/// budget an SfM scene's points leave unfilled).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub enum PointlessInit {
    /// Uniform random points in the scene box (the reference, spec §8).
    #[default]
    Random,
    /// Farthest points of the surface of the visual hull carved from the training views'
    /// alpha masks, in the scene box ([`crate::init::hull`]); needs RGBA images. Topped up with
    /// random points when the surface has fewer voxels than the budget.
    Hull(HullConfig),
    /// [`PointlessInit::Hull`] when any training view has an alpha mask, else random points in
    /// the camera box plus a background shell (module rules). With SfM points: the points and
    /// the sky, and a background shell for the rest of the budget.
    Auto(HullConfig),
}

impl PointlessInit {
    /// What `self` does on `scene` (without SfM points): [`PointlessInit::Auto`] resolved to
    /// `Hull` or kept as `Auto` (random + shell); the others unchanged.
    pub fn resolve(&self, scene: &Scene) -> PointlessInit {
        match *self {
            PointlessInit::Auto(config) if scene.train.iter().any(|v| v.coverage.is_some()) => {
                PointlessInit::Hull(config)
            }
            other => other,
        }
    }
}

/// The initial points of `scene` for a budget of `budget` billboards (rules in the [module
/// documentation](self)); `seed` drives the random points only (FPS and the sky are
/// deterministic).
///
/// # Errors
///
/// [`InitError::ZeroBudget`] when `budget` is 0.
pub fn init_points(scene: &Scene, budget: usize, seed: u64) -> Result<SceneInit, InitError> {
    init_points_with(scene, budget, seed, &PointlessInit::Random)
}

/// [`init_points`], with `pointless` choosing what happens when the scene has no SfM points.
///
/// # Errors
///
/// [`InitError::ZeroBudget`] when `budget` is 0; [`InitError::Hull`] when the visual hull was
/// asked for and cannot be built (no masks, empty hull).
pub fn init_points_with(
    scene: &Scene,
    budget: usize,
    seed: u64,
    pointless: &PointlessInit,
) -> Result<SceneInit, InitError> {
    if budget == 0 {
        return Err(InitError::ZeroBudget);
    }
    let (mut positions, mut colours, mut dropped) = (Vec::new(), Vec::new(), 0usize);
    if let Some(cloud) = &scene.points {
        for (p, c) in cloud.positions.iter().zip(&cloud.colours) {
            if p.is_finite() {
                positions.push(*p);
                colours.push(*c);
            } else {
                dropped += 1;
            }
        }
    }
    let m = positions.len();
    let mut report = InitReport {
        budget,
        sfm_available: m,
        sfm_dropped: dropped,
        sfm: 0,
        sky: 0,
        random: 0,
        shell: 0,
        shell_radius: 0.0,
        hull: 0,
        hull_candidates: 0,
        sky_radius: 0.0,
        sky_radius_reference: 0.0,
        random_box: None,
        box_rule: String::new(),
    };
    if m == 0 {
        let cams: Vec<_> = scene.train.iter().map(|v| v.camera).collect();
        let (c, h) = camera_box(&cams);
        let (lo, hi) = (c - Vec3::splat(h), c + Vec3::splat(h));
        report.random_box = Some((lo, hi));
        report.box_rule =
            "from the training cameras (centre nearest the optical axes, half side median d*sin(fov/2))".to_string();
        let pointless = pointless.resolve(scene);
        if let PointlessInit::Hull(config) = pointless {
            let (surface, surface_colours) = visual_hull_points(&scene.train, lo, hi, &config, seed)?;
            let keep = farthest_point_sampling(&surface, budget.min(surface.len())).expect("hull points are finite");
            let mut points: Vec<Vec3> = keep.iter().map(|&i| surface[i]).collect();
            let mut cols: Vec<[f32; 3]> = keep.iter().map(|&i| surface_colours[i]).collect();
            report.hull = points.len();
            report.hull_candidates = surface.len();
            let (extra, extra_cols) = random_points(budget - points.len(), lo, hi, seed);
            report.random = extra.len();
            points.extend(extra);
            cols.extend(extra_cols);
            return Ok(SceneInit {
                points,
                colours: cols,
                report,
            });
        }
        if let PointlessInit::Auto(_) = pointless {
            let shell = (budget as f64 * SHELL_FRACTION).floor() as usize;
            let (mut points, mut cols) = random_points(budget - shell, lo, hi, seed);
            let (shell_points, shell_cols, radius) = background_shell(&cams, shell, seed);
            points.extend(shell_points);
            cols.extend(shell_cols);
            report.random = budget - shell;
            report.shell = shell;
            report.shell_radius = radius;
            return Ok(SceneInit {
                points,
                colours: cols,
                report,
            });
        }
        let (points, cols) = random_points(budget, lo, hi, seed);
        report.random = budget;
        return Ok(SceneInit {
            points,
            colours: cols,
            report,
        });
    }
    let sky = sky_point_count(m.min(budget)).min(budget);
    let keep_count = m.min(budget - sky);
    let keep = farthest_point_sampling(&positions, keep_count).expect("non-finite points were dropped");
    let radius = if sky > 0 { sky_radius(&positions) } else { 0.0 };
    let mut points = fibonacci_sphere(sky, radius, Vec3::ZERO);
    let mut cols = vec![SKY_COLOUR; sky];
    points.extend(keep.iter().map(|&i| positions[i]));
    cols.extend(keep.iter().map(|&i| colours[i]));
    report.sfm = keep_count;
    report.sky = sky;
    if sky > 0 {
        report.sky_radius = radius;
        report.sky_radius_reference = sky_radius_reference(&positions);
    }
    if let PointlessInit::Auto(_) = pointless {
        let cams: Vec<_> = scene.train.iter().map(|v| v.camera).collect();
        let shell = budget - points.len();
        let (shell_points, shell_cols, radius) = background_shell(&cams, shell, seed);
        points.extend(shell_points);
        cols.extend(shell_cols);
        report.shell = shell;
        report.shell_radius = radius;
    }
    Ok(SceneInit {
        points,
        colours: cols,
        report,
    })
}

/// `count` points on the background shell of the module rules: a Fibonacci sphere around the
/// centre of the cameras' box ([`camera_box`]) of radius [`SHELL_RADIUS_FACTOR`] × the largest
/// camera distance from that centre (at least the box's half side), grey as the random points
/// (seeded by `seed`); returns the points, their colours and the radius (0 when `count` is 0).
fn background_shell(cams: &[crate::camera::Camera], count: usize, seed: u64) -> (Vec<Vec3>, Vec<[f32; 3]>, f32) {
    if count == 0 {
        return (Vec::new(), Vec::new(), 0.0);
    }
    let (c, h) = camera_box(cams);
    let far = cams
        .iter()
        .map(|cam| (cam.centre() - c).length())
        .filter(|d| d.is_finite())
        .fold(h, f32::max);
    let radius = SHELL_RADIUS_FACTOR * far;
    let (lo, hi) = (c - Vec3::splat(h), c + Vec3::splat(h));
    let (_, colours) = random_points(count, lo, hi, seed ^ 0x0053_4845_4c4c);
    (fibonacci_sphere(count, radius, c), colours, radius)
}

/// [`init_points`] then [`RawBillboards::from_points`] with the same seed.
///
/// # Errors
///
/// As [`init_points`].
pub fn init_model(
    scene: &Scene,
    budget: usize,
    texture_size: usize,
    seed: u64,
) -> Result<(RawBillboards, InitReport), InitError> {
    init_model_with(scene, budget, texture_size, seed, &PointlessInit::Random)
}

/// [`init_points_with`] then [`RawBillboards::from_points`] with the same seed.
///
/// # Errors
///
/// As [`init_points_with`].
pub fn init_model_with(
    scene: &Scene,
    budget: usize,
    texture_size: usize,
    seed: u64,
    pointless: &PointlessInit,
) -> Result<(RawBillboards, InitReport), InitError> {
    let init = init_points_with(scene, budget, seed, pointless)?;
    Ok((
        RawBillboards::from_points(&init.points, &init.colours, texture_size, seed),
        init.report,
    ))
}

/// `n` points uniform in the box `[lo, hi]` with the reference's near-grey colours.
pub fn random_points(n: usize, lo: Vec3, hi: Vec3, seed: u64) -> (Vec<Vec3>, Vec<[f32; 3]>) {
    let mut rng = Rng::new(seed);
    let points = (0..n)
        .map(|_| Vec3::new(rng.range(lo.x, hi.x), rng.range(lo.y, hi.y), rng.range(lo.z, hi.z)))
        .collect();
    let colours = (0..n)
        .map(|_| std::array::from_fn(|_| 0.5 + SH_C0 * rng.range(0.0, 1.0 / 255.0)))
        .collect();
    (points, colours)
}

/// The box the cameras look at, as `(centre, half side)`: the centre is the least-squares
/// point nearest to the optical axes (falls back to the mean camera centre when the axes are
/// (nearly) parallel), the half side is `median_i(|o_i − c|·sin θ_i)` with `θ_i` half the
/// smaller field of view of camera `i` (the cube around the largest sphere centred at `c` that
/// the median camera sees whole). Empty input gives the unit box at the origin.
pub fn camera_box(cameras: &[crate::camera::Camera]) -> (Vec3, f32) {
    if cameras.is_empty() {
        return (Vec3::ZERO, 1.0);
    }
    let mean = cameras.iter().map(|c| c.centre().as_dvec3()).sum::<DVec3>() / cameras.len() as f64;
    // Well conditioned when the axes span at least two directions.
    let centre = crate::camera::nearest_to_lines(
        cameras
            .iter()
            .map(|c| (c.centre().as_dvec3(), c.rotation.row(2).as_dvec3().normalize_or_zero())),
    )
    .unwrap_or(mean);
    let mut radii: Vec<f64> = cameras
        .iter()
        .map(|cam| {
            let tan_half = (cam.width as f64 / (2.0 * cam.fx as f64)).min(cam.height as f64 / (2.0 * cam.fy as f64));
            let sin_half = tan_half / (1.0 + tan_half * tan_half).sqrt();
            (cam.centre().as_dvec3() - centre).length() * sin_half
        })
        .filter(|r| r.is_finite())
        .collect();
    radii.sort_by(f64::total_cmp);
    let half = if radii.is_empty() {
        1.0
    } else {
        radii[(radii.len() - 1) / 2]
    };
    let half = if half > 0.0 && half.is_finite() {
        half as f32
    } else {
        1.0
    };
    (centre.as_vec3(), half)
}
