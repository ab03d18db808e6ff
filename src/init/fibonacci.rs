//! The sky sphere (spec §8.2, supplement §6.3): points spread evenly on a large sphere around
//! the scene by the Fibonacci (golden-angle) spiral, to represent the sky and far-away objects.
//!
//! # Conventions
//!
//! - **Lattice** ([`fibonacci_sphere`]): for `i in 0..n`, `y = 1 − 2i/(n−1)`,
//!   `r = √(1 − y²)`, `θ = i·π(√5 − 1)` (the golden angle), unit point `(cos θ·r, y, sin θ·r)`,
//!   then scaled by `radius` and shifted by `centre`. Point 0 is the north pole `+y` and point
//!   `n − 1` the south pole `−y`. Computed in f64 and rounded once to f32; `θ` is reduced modulo
//!   2π exactly (as `2π·frac(i·(√5−1)/2)`) so large `i` loses no accuracy.
//!   `n = 0` gives no point, `n = 1` the north pole alone (the formula divides by `n − 1`),
//!   `n = 2` the two poles.
//! - **Spacing**: each point covers an area `4π/n` of the unit sphere, so neighbours are about
//!   `√(4π/n)` apart. The closest pair is the pole and its neighbour, at `≈ 2/√n`, i.e.
//!   `≈ 0.56·√(4π/n)`; the tests check `≥ 0.55·√(4π/n)·radius` for `n ≤ 300` and sizes up to 4096.
//! - **How many sky points** ([`sky_point_count`]), the supplement's rule for small budgets:
//!   none below 10 000 initial points, 2 000 from 10 000 up to and including 20 000, and the
//!   default 10 000 above 20 000. "Initial points" is the number of primitives the run starts
//!   from without the sky (the SfM points after sampling). The released code always uses
//!   10 000 (`--sphere_point`) whenever `--add_sky_box` is given.
//! - **Radius and centre**: the reference centres the sphere at the **world origin** and uses
//!   the largest L∞ norm `max(|x|, |y|, |z|)` over the SfM points ([`SkyRadius::Reference`]).
//!   (The supplement says "the distance to the furthest point", i.e. the L2 norm, which is
//!   what actually encloses every point: [`SkyRadius::Enclosing`].) One far outlier blows
//!   both up, and with them the sky, so the default ([`sky_radius`]) is
//!   [`SkyRadius::Robust`]: a high quantile of the L∞ norms times a margin, never more than the
//!   reference radius. See [`SkyRadius`] for the exact rules.
//!
//! ```
//! use bbsplat::init::fibonacci::{fibonacci_sphere, sky_point_count};
//! use glam::Vec3;
//! let pts = fibonacci_sphere(100, 2.0, Vec3::new(1.0, 0.0, 0.0));
//! assert_eq!(pts.len(), 100);
//! assert!(pts.iter().all(|p| ((*p - Vec3::X).length() - 2.0).abs() < 1e-5));
//! assert_eq!(pts[0], Vec3::new(1.0, 2.0, 0.0)); // the north pole
//! assert_eq!(sky_point_count(150_000), 10_000);
//! assert_eq!(sky_point_count(20_000), 2_000);
//! assert_eq!(sky_point_count(9_999), 0);
//! ```

use glam::Vec3;

/// Sky points added for budgets above [`SMALL_BUDGET_MAX`] (reference `--sphere_point`).
pub const SKY_POINTS: usize = 10_000;
/// Sky points added for budgets from [`NO_SKY_BELOW`] to [`SMALL_BUDGET_MAX`] inclusive.
pub const SKY_POINTS_SMALL: usize = 2_000;
/// Largest initial point count that gets the small sky ([`SKY_POINTS_SMALL`]).
pub const SMALL_BUDGET_MAX: usize = 20_000;
/// Initial point counts below this get no sky at all.
pub const NO_SKY_BELOW: usize = 10_000;

/// `(√5 − 1)/2`: the golden angle is `2π` times this, modulo `2π`.
const GOLDEN_FRACTION: f64 = 0.618_033_988_749_894_8;

/// `n` points of the Fibonacci lattice on the sphere of `radius` around `centre` (order and
/// formula in the [module documentation](self)).
///
/// A negative `radius` mirrors the lattice through the centre; a zero radius puts every point
/// on the centre.
pub fn fibonacci_sphere(n: usize, radius: f32, centre: Vec3) -> Vec<Vec3> {
    let (r, c) = (radius as f64, centre.as_dvec3());
    (0..n)
        .map(|i| {
            let u = unit_point(i, n);
            Vec3::new(
                (c.x + r * u[0]) as f32,
                (c.y + r * u[1]) as f32,
                (c.z + r * u[2]) as f32,
            )
        })
        .collect()
}

/// Point `i` of the `n`-point unit lattice, in f64.
fn unit_point(i: usize, n: usize) -> [f64; 3] {
    if n == 1 {
        return [0.0, 1.0, 0.0];
    }
    let y = 1.0 - 2.0 * i as f64 / (n - 1) as f64;
    let r = (1.0 - y * y).max(0.0).sqrt();
    let theta = std::f64::consts::TAU * (i as f64 * GOLDEN_FRACTION).fract();
    [theta.cos() * r, y, theta.sin() * r]
}

/// Number of sky points for a run starting from `initial_points` points (supplement §6.3):
/// `0` if `initial_points < 10 000`, `2 000` if `10 000 ≤ initial_points ≤ 20 000`, otherwise
/// `10 000`.
pub fn sky_point_count(initial_points: usize) -> usize {
    if initial_points < NO_SKY_BELOW {
        0
    } else if initial_points <= SMALL_BUDGET_MAX {
        SKY_POINTS_SMALL
    } else {
        SKY_POINTS
    }
}

/// How the sky radius is derived from the scene's points (all norms are about the world
/// origin, the sphere's centre in the reference). Non-finite points are ignored; with no
/// finite point every rule gives 0.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SkyRadius {
    /// The released code: the largest L∞ norm `max(|x|, |y|, |z|)`. Encloses the axis-aligned
    /// cube around the origin that holds the cloud, but not necessarily the cloud itself (a
    /// point at `(1, 1, 1)` has L∞ norm 1 and distance √3).
    Reference,
    /// The supplement's wording: the largest Euclidean norm, so every point is inside.
    Enclosing,
    /// A high quantile of the L∞ norms times a margin, capped at the [`SkyRadius::Reference`]
    /// value: `min(margin · Q_q, max L∞)`, where `Q_q` is the nearest-rank quantile (the
    /// `⌈q·N⌉`-th smallest L∞ norm, `q` clamped to `[0, 1]`). Up to a fraction `1 − q` of the
    /// points can be arbitrarily far without changing the radius. On a cloud without a far
    /// tail the cap makes it equal to the reference.
    Robust {
        /// The quantile `q` of the L∞ norms.
        quantile: f32,
        /// The factor applied to the quantile.
        margin: f32,
    },
}

impl SkyRadius {
    /// The default robust rule: the 99th percentile of the L∞ norms times 1.1 (capped at the
    /// reference radius). For points uniform in a cube the 99th percentile is `0.9967` of the
    /// half side, so the margin puts the sphere just beyond the cube (where the cap then
    /// returns the reference value); a cloud with up to 1 % far outliers keeps the radius of
    /// its inliers.
    pub const DEFAULT_ROBUST: SkyRadius = SkyRadius::Robust {
        quantile: 0.99,
        margin: 1.1,
    };

    /// The radius of the sky sphere for `points` under this rule.
    pub fn radius(&self, points: &[Vec3]) -> f32 {
        let finite = points.iter().filter(|p| p.is_finite());
        match *self {
            SkyRadius::Reference => finite.map(|p| p.abs().max_element()).fold(0.0, f32::max),
            SkyRadius::Enclosing => finite.map(|p| p.length()).fold(0.0, f32::max),
            SkyRadius::Robust { quantile, margin } => {
                let mut norms: Vec<f32> = finite.map(|p| p.abs().max_element()).collect();
                if norms.is_empty() {
                    return 0.0;
                }
                let max = norms.iter().copied().fold(0.0, f32::max);
                let q = if quantile.is_nan() {
                    1.0
                } else {
                    quantile.clamp(0.0, 1.0)
                };
                let rank = ((q as f64 * norms.len() as f64).ceil() as usize).clamp(1, norms.len());
                let (_, &mut value, _) = norms.select_nth_unstable_by(rank - 1, f32::total_cmp);
                (margin * value).min(max)
            }
        }
    }
}

/// The default (robust) sky radius: [`SkyRadius::DEFAULT_ROBUST`], i.e.
/// `min(1.1 · (99th percentile of the L∞ norms), max L∞ norm)`.
///
/// ```
/// use bbsplat::init::fibonacci::{sky_radius, sky_radius_reference};
/// use glam::Vec3;
/// let mut cloud: Vec<Vec3> = (0..1000).map(|i| Vec3::splat((i as f32 / 999.0) * 2.0 - 1.0)).collect();
/// assert_eq!(sky_radius(&cloud), sky_radius_reference(&cloud)); // no far tail: the same
/// cloud.push(Vec3::new(1.0e6, 0.0, 0.0)); // one outlier
/// assert_eq!(sky_radius_reference(&cloud), 1.0e6);
/// assert!(sky_radius(&cloud) <= 1.1);
/// ```
pub fn sky_radius(points: &[Vec3]) -> f32 {
    SkyRadius::DEFAULT_ROBUST.radius(points)
}

/// The released code's sky radius: the largest L∞ norm of the points ([`SkyRadius::Reference`]).
pub fn sky_radius_reference(points: &[Vec3]) -> f32 {
    SkyRadius::Reference.radius(points)
}

/// The sky for an initial cloud: [`sky_point_count`]`(points.len())` Fibonacci points on the
/// sphere of radius `rule.radius(points)` around the world origin (as the reference). Prepend
/// them to the cloud (the reference order) and colour them white.
pub fn sky_sphere(points: &[Vec3], rule: SkyRadius) -> Vec<Vec3> {
    let n = sky_point_count(points.len());
    if n == 0 {
        return Vec::new();
    }
    fibonacci_sphere(n, rule.radius(points), Vec3::ZERO)
}
