//! Ray-plane intersection of a pixel's ray with a billboard (2DGS Eq. 8-10), and its backward pass
//! to the ray-splat transform `T`.
//!
//! Conventions (see `docs/numerics-geometry.md`): the caller passes the pixel *centre*
//! `(i + 0.5, j + 0.5)`; `T` is the [`SplatTransform`] of [`crate::stages::splat_transform`], mapping
//! `(u, v, 1)` to homogeneous pixels. For pixel `(x, y)`, `k = x·Tw − Tu` and `l = y·Tw − Tv` are
//! the homogeneous lines of the billboard plane that project onto the image column `x` and row `y`;
//! their intersection `p = k × l` is the hit in homogeneous plane coordinates, so
//! `(u, v) = (p.x/p.z, p.y/p.z)` and the hit's view depth is `Tw·(u, v, 1)`.
//!
//! [`intersect`] computes that depth from `T` alone; the rasterizer calls [`intersect_with`]
//! (the same guards, plane coordinates and near-plane test) with the depth by the plane equation
//! of [`ViewPlane`], which does not cancel when a plane is seen obliquely or far from its centre.

use crate::camera::Camera;
use crate::stages::splat_transform::{NEAR_PLANE, SplatTransform};
use glam::Vec3;

/// Grazing-ray guard on the accuracy of `p.z`: a hit is rejected unless
/// `|p.z| > GRAZING_EPS·(|k.x·l.y| + |k.y·l.x|)`.
///
/// `p.z = k.x·l.y − k.y·l.x` is a 2×2 determinant; `ρ = |p.z| / (|k.x·l.y| + |k.y·l.x|) ∈ [0, 1]` is
/// its componentwise condition number, so the f32 rounding error of `p.z` (and hence the relative
/// error of `u`, `v` and of the `1/p.z` in the gradients) is at most about `2ε/ρ`
/// (`ε = 2⁻²⁴`): `≤ 1.2e-3` at the guard, and far smaller for the hits that matter.
///
/// Geometric meaning: `p.z = fx·fy·s_u·s_v·(n_view·r)` with `r = ((x − cx)/fx, (y − cy)/fy, 1)` the
/// pixel's ray, and the denominator is at most `fx·fy·s_u·s_v·√(1 + r_x²)·√(1 + r_y²)`, so
/// `ρ ≥ 0.87·|cos θ_pixel|` inside a 90° field of view, where `θ_pixel` is the angle between the
/// ray and the normal. The guard therefore rejects rays within about `1.15e-4` rad (0.0066°) of
/// the plane, and nothing else: `ρ` does not depend on the scales, their ratio, the in-plane
/// rotation or the focal lengths. Such a billboard is seen so close to edge-on that it is
/// thinner than a pixel unless it spans more than ~10⁴ pixels.
///
/// Why not `|p.z| ≤ G·|k|·|l|`: `|p.z|/(|k||l|) = sin φ/√(1 + u² + v²)` (φ the angle between `k`
/// and `l`), and `sin φ ≈ 2·s_v/s_u` for an elongated billboard rotated in its plane, so that
/// guard rejects the centre of visible needles (anisotropy `≳ 1/G`) although `p.z` is computed
/// without cancellation there; see the named test `elongated_billboards_are_not_rejected`.
///
/// The reference skips only `p.z == 0` exactly, which lets `(u, v)` grow without bound (up to
/// `±inf`/NaN) for nearly parallel rays; [`UV_LIMIT`] bounds them.
pub const GRAZING_EPS: f32 = 1e-4;

/// Bound on the hit's plane coordinates: a hit is rejected unless `max(|p.x|, |p.y|) <
/// UV_LIMIT·|p.z|`, i.e. `|u|, |v| < 1e4`.
///
/// [`GRAZING_EPS`] bounds the rounding error of `p.z` but not `|p.z|` itself: a ray parallel to
/// the billboard's `t_u` axis has `p.z → 0` with `ρ` of order 1, and `u → ∞`. Texture samples are
/// zero outside `|u|, |v| ≤ 1 + 2/(TS − 1)` (1.134 for TS = 16), so `1e4` loses nothing the
/// rasterizer could use while keeping `u`, `v`, the depth and the gradients (which scale with
/// `1 + |u| + |v|`) finite. Both comparisons are free of squares and square roots, so they
/// neither overflow for huge billboards nor cost much.
pub const UV_LIMIT: f32 = 1e4;

/// A ray-billboard hit: plane coordinates and view depth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlaneHit {
    /// Plane coordinate along `s_u·t_u` (`±1` at the square's edges).
    pub u: f32,
    /// Plane coordinate along `s_v·t_v`.
    pub v: f32,
    /// View depth of the hit point, `u·Tw.x + v·Tw.y + Tw.z` (≥ [`NEAR_PLANE`]).
    pub depth: f32,
}

/// `k`, `l` and `p = k × l` for pixel `(px, py)`, or `None` when the guards reject the hit:
/// [`GRAZING_EPS`] (which also rejects `p.z == 0` and NaN), [`UV_LIMIT`], and `|p.z|` below the
/// smallest normal f32 (so that `1/p.z` is finite).
#[inline(always)]
fn guarded_lines(t: &SplatTransform, px: f32, py: f32) -> Option<(Vec3, Vec3, Vec3)> {
    let k = px * t.tw - t.tu;
    let l = py * t.tw - t.tv;
    let (m, n) = (k.x * l.y, k.y * l.x);
    let p = Vec3::new(k.y * l.z - k.z * l.y, k.z * l.x - k.x * l.z, m - n);
    let apz = p.z.abs();
    // Every comparison is false for NaN, so NaN is rejected (`max` ignores NaN, hence it is only
    // used where a NaN operand also makes `p.z` NaN).
    let accurate = apz > (GRAZING_EPS * (m.abs() + n.abs())).max(f32::MIN_POSITIVE);
    let limit = UV_LIMIT * apz;
    let bounded = p.x.abs() < limit && p.y.abs() < limit;
    (accurate && bounded).then_some((k, l, p))
}

/// Intersects the ray of pixel centre `(px, py)` with the billboard plane of `t`.
///
/// Returns `None` for grazing rays (see [`GRAZING_EPS`] and [`UV_LIMIT`]), for hits with
/// `depth < ` [`NEAR_PLANE`] (behind or too close to the camera) and for non-finite inputs or
/// results. The hit is *not* restricted to the billboard square: `|u|, |v|` may be up to
/// [`UV_LIMIT`].
///
/// ```
/// use bbsplat::stages::ray_plane::intersect;
/// use bbsplat::stages::splat_transform::SplatTransform;
/// use glam::Vec3;
/// // Face-on square at depth 2, fx = fy = 10, principal point (5, 5).
/// let t = SplatTransform { tu: Vec3::new(10.0, 0.0, 10.0), tv: Vec3::new(0.0, 10.0, 10.0), tw: Vec3::new(0.0, 0.0, 2.0) };
/// let hit = intersect(&t, 7.5, 5.0).unwrap();
/// assert!((hit.u - 0.5).abs() < 1e-6 && hit.v.abs() < 1e-6 && (hit.depth - 2.0).abs() < 1e-6);
/// ```
#[inline]
pub fn intersect(t: &SplatTransform, px: f32, py: f32) -> Option<PlaneHit> {
    intersect_with(t, px, py, |u, v| expanded_depth(t, u, v))
}

/// The hit depth `u·Tw.x + v·Tw.y + Tw.z` from the transform alone ([`intersect`]'s depth).
#[inline(always)]
fn expanded_depth(t: &SplatTransform, u: f32, v: f32) -> f32 {
    u * t.tw.x + v * t.tw.y + t.tw.z
}

/// [`intersect`] with the hit's view depth given by `depth(u, v)` instead of the expanded form:
/// the same guards, plane coordinates and near-plane test. The rasterizer passes the plane
/// equation ([`ViewPlane::depth`]), which keeps its accuracy where the expanded form cancels.
#[inline(always)]
pub fn intersect_with(t: &SplatTransform, px: f32, py: f32, depth: impl FnOnce(f32, f32) -> f32) -> Option<PlaneHit> {
    let (_, _, p) = guarded_lines(t, px, py)?;
    let inv = 1.0 / p.z;
    let (u, v) = (p.x * inv, p.y * inv);
    let depth = depth(u, v);
    // Written so that NaN and +inf depths are rejected too.
    (NEAR_PLANE..f32::INFINITY)
        .contains(&depth)
        .then_some(PlaneHit { u, v, depth })
}

/// A billboard's plane in view space, for hit depths by the plane equation: with `n` the plane's
/// unit normal facing the camera and `offset = n·p_view` (`p_view` the centre in view space), the
/// ray of pixel `(x, y)`, `r = ((x − cx)/fx, (y − cy)/fy, 1)`, meets the plane at view depth
/// `offset / (n·r)`.
///
/// Why: the expanded form `u·Tw.x + v·Tw.y + Tw.z` adds terms of size `|u·Tw.x|` that cancel when
/// a plane is seen obliquely or far from its centre (a large plane whose centre is 500 units
/// away and which passes 0.06 from the camera loses 1e-3 of a hit depth of 0.2, enough to move
/// hits across the near plane). Here `offset` is taken in f64 from the raw parameters
/// ([`crate::stages::splat_transform::view_plane`]), so it keeps its accuracy however far the
/// centre is, and `n·r` is a three-term dot product that cancels only for rays grazing the
/// plane, which the grazing guard rejects. Measured in `tests/suite/stage_ray_plane.rs`
/// (`plane_equation_depth_is_more_accurate`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ViewPlane {
    /// Unit normal in view space, facing the camera.
    pub normal: Vec3,
    /// `normal · p_view` (negative for a plane in front of the camera that faces it).
    pub offset: f32,
}

impl ViewPlane {
    /// View depth where the pixel ray `ray` ([`pixel_ray`]) meets the plane.
    #[inline(always)]
    pub fn depth(&self, ray: Vec3) -> f32 {
        self.offset / self.normal.dot(ray)
    }
}

/// The ray of pixel centre `(px, py)` scaled to view depth 1: `((px − cx)/fx, (py − cy)/fy, 1)`.
#[inline(always)]
pub fn pixel_ray(camera: &Camera, px: f32, py: f32) -> Vec3 {
    Vec3::new((px - camera.cx) / camera.fx, (py - camera.cy) / camera.fy, 1.0)
}

/// Backward pass of [`intersect`]: given `∂L/∂u`, `∂L/∂v`, `∂L/∂depth` at the hit of pixel
/// `(px, py)`, returns `∂L/∂T` (rows, same layout as [`SplatTransform`]). The pixel is a constant.
/// Recomputes `k`, `l`, `p` internally; returns zero when [`intersect`] returns `None`.
///
/// Chain (2DGS): with `G_u = ∂L/∂u + ∂L/∂depth·Tw.x`, `G_v = ∂L/∂v + ∂L/∂depth·Tw.y`,
/// `∂L/∂p = (G_u, G_v, −(G_u·u + G_v·v)) / p.z`, `∂L/∂k = l × ∂L/∂p`, `∂L/∂l = ∂L/∂p × k`;
/// `∂L/∂Tu = −∂L/∂k`, `∂L/∂Tv = −∂L/∂l`, `∂L/∂Tw = x·∂L/∂k + y·∂L/∂l + ∂L/∂depth·(u, v, 1)`.
///
/// ```
/// use bbsplat::stages::ray_plane::intersect_vjp;
/// use bbsplat::stages::splat_transform::SplatTransform;
/// use glam::Vec3;
/// let t = SplatTransform { tu: Vec3::new(10.0, 0.0, 10.0), tv: Vec3::new(0.0, 10.0, 10.0), tw: Vec3::new(0.0, 0.0, 2.0) };
/// // depth = Tw.z at the centre pixel: ∂depth/∂Tw.z = 1.
/// let g = intersect_vjp(&t, 5.0, 5.0, 0.0, 0.0, 1.0);
/// assert!((g.tw.z - 1.0).abs() < 1e-6);
/// ```
#[inline]
pub fn intersect_vjp(t: &SplatTransform, px: f32, py: f32, d_u: f32, d_v: f32, d_depth: f32) -> SplatTransform {
    intersect_vjp_with(t, px, py, |u, v| expanded_depth(t, u, v), d_u, d_v, d_depth)
}

/// [`intersect_vjp`] for a forward made with [`intersect_with`] and the same `depth`: the
/// near-plane decision uses `depth`, as the forward did. The gradient is that of the exact
/// depth as a function of `T` (every depth formula computes the same exact value, so the
/// derivative does not depend on the formula).
#[inline(always)]
pub fn intersect_vjp_with(
    t: &SplatTransform,
    px: f32,
    py: f32,
    depth: impl FnOnce(f32, f32) -> f32,
    d_u: f32,
    d_v: f32,
    d_depth: f32,
) -> SplatTransform {
    let Some((k, l, p)) = guarded_lines(t, px, py) else {
        return SplatTransform::default();
    };
    let inv = 1.0 / p.z;
    let (u, v) = (p.x * inv, p.y * inv);
    if !(NEAR_PLANE..f32::INFINITY).contains(&depth(u, v)) {
        return SplatTransform::default();
    }
    let gu = d_u + d_depth * t.tw.x;
    let gv = d_v + d_depth * t.tw.y;
    let dp = Vec3::new(gu, gv, -(gu * u + gv * v)) * inv;
    let dk = l.cross(dp);
    let dl = dp.cross(k);
    SplatTransform {
        tu: -dk,
        tv: -dl,
        tw: px * dk + py * dl + d_depth * Vec3::new(u, v, 1.0),
    }
}

/// Pixels per call of [`intersect_lanes`] (and of the other row-wise stage functions).
pub const LANES: usize = 8;

/// The centres `(first + l) as f32 + 0.5` of the [`LANES`] pixels `first..first + LANES` of a
/// row or column, bit for bit. Below 2²³ − [`LANES`] they are computed as one broadcast and one
/// vector add of the lane offsets (every value there is a multiple of ½ below 2²³, so each
/// operation is exact and both forms give the exact centre); the integer conversion per lane
/// is kept above it, where `f32` rounds. Tested against the per-lane form in
/// `tests/suite/stage_lanes.rs`.
#[inline(always)]
pub fn row_centres(first: u32) -> [f32; LANES] {
    if first < (1 << 23) - LANES as u32 {
        let base = first as f32 + 0.5;
        std::array::from_fn(|l| base + l as f32)
    } else {
        std::array::from_fn(|l| first.wrapping_add(l as u32) as f32 + 0.5)
    }
}

/// The hits of [`LANES`] pixel centres with one billboard ([`intersect_lanes`]): lane `l` holds what [`intersect_with`] gives for pixel `l`, with the
/// depth by the plane equation; `valid[l]` is false where it gives `None` (`u`, `v` and `depth`
/// of such a lane are unspecified).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RowHits {
    /// Plane coordinate `u` per lane.
    pub u: [f32; LANES],
    /// Plane coordinate `v` per lane.
    pub v: [f32; LANES],
    /// View depth per lane.
    pub depth: [f32; LANES],
    /// The lane's ray hits the plane (every guard of [`intersect_with`] passed).
    pub valid: [bool; LANES],
}

/// [`intersect_with`] with the plane-equation depth ([`ViewPlane::depth`] of the pixel's
/// [`pixel_ray`]) for the pixel centres `(px[l], py[l])`, `l < LANES`, computed lane by lane with
/// no branch, so that the compiler can run the lanes side by side in vector registers.
///
/// Every lane does exactly the operations of the scalar functions, in the same order (no fused
/// multiply-add, which Rust never introduces by itself), so each valid lane equals
/// `intersect_with(t, px[l], py[l], |_, _| plane.depth(pixel_ray(camera, px[l], py[l])))` bit
/// for bit, and `valid[l]` is true exactly where that returns `Some` (tested on random and
/// degenerate inputs in `tests/suite/stage_lanes.rs`). The rasterizer's forward and backward
/// tile loops call this form; the scalar form is its reference and carries the gradient proofs.
#[inline(always)]
pub fn intersect_lanes(
    t: &SplatTransform,
    plane: &ViewPlane,
    camera: &Camera,
    px: &[f32; LANES],
    py: &[f32; LANES],
) -> RowHits {
    let mut hits = RowHits {
        u: [0.0; LANES],
        v: [0.0; LANES],
        depth: [0.0; LANES],
        valid: [false; LANES],
    };
    for lane in 0..LANES {
        let (x, y) = (px[lane], py[lane]);
        // `guarded_lines`, lane-wise: k = x·Tw − Tu, l = y·Tw − Tv, p = k × l.
        let (kx, ky, kz) = (x * t.tw.x - t.tu.x, x * t.tw.y - t.tu.y, x * t.tw.z - t.tu.z);
        let (lx, ly, lz) = (y * t.tw.x - t.tv.x, y * t.tw.y - t.tv.y, y * t.tw.z - t.tv.z);
        let (m, n) = (kx * ly, ky * lx);
        let (pxh, pyh, pzh) = (ky * lz - kz * ly, kz * lx - kx * lz, m - n);
        let apz = pzh.abs();
        let accurate = apz > (GRAZING_EPS * (m.abs() + n.abs())).max(f32::MIN_POSITIVE);
        let limit = UV_LIMIT * apz;
        let bounded = pxh.abs() < limit && pyh.abs() < limit;
        let inv = 1.0 / pzh;
        let (u, v) = (pxh * inv, pyh * inv);
        // `ViewPlane::depth` of `pixel_ray`: offset / (n · ((x − cx)/fx, (y − cy)/fy, 1)).
        let (ray_x, ray_y) = ((x - camera.cx) / camera.fx, (y - camera.cy) / camera.fy);
        let depth = plane.offset / (plane.normal.x * ray_x + plane.normal.y * ray_y + plane.normal.z * 1.0);
        hits.u[lane] = u;
        hits.v[lane] = v;
        hits.depth[lane] = depth;
        hits.valid[lane] = accurate & bounded & (NEAR_PLANE..f32::INFINITY).contains(&depth);
    }
    hits
}

/// [`LANES`] transform gradients, one per lane ([`intersect_vjp_lanes`]), in
/// structure-of-arrays form: `tu[c][l]` is component `c` of lane `l`'s `∂L/∂Tu`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LaneTransforms {
    /// `∂L/∂Tu` per component and lane.
    pub tu: [[f32; LANES]; 3],
    /// `∂L/∂Tv` per component and lane.
    pub tv: [[f32; LANES]; 3],
    /// `∂L/∂Tw` per component and lane.
    pub tw: [[f32; LANES]; 3],
}

impl LaneTransforms {
    /// Lane `lane`'s gradient.
    #[inline(always)]
    pub fn lane(&self, lane: usize) -> SplatTransform {
        let at = |rows: &[[f32; LANES]; 3]| Vec3::new(rows[0][lane], rows[1][lane], rows[2][lane]);
        SplatTransform {
            tu: at(&self.tu),
            tv: at(&self.tv),
            tw: at(&self.tw),
        }
    }
}

/// [`intersect_vjp_with`] with the plane-equation depth for the pixel centres `(px[l], py[l])`
/// and upstream gradients `(d_u[l], d_v[l], d_depth[l])`, lane by lane with no branch, given
/// the forward's `hits` = [`intersect_lanes`]`(t, plane, camera, px, py)` (whose `u`, `v` and
/// validity the scalar form recomputes; lanes marked invalid get zero, as the scalar form
/// returns). Each lane equals the scalar form bit for bit (same operations, same order; tested
/// in `tests/suite/stage_lanes.rs`); the scalar form carries the finite-difference proofs.
#[inline(always)]
pub fn intersect_vjp_lanes(
    t: &SplatTransform,
    hits: &RowHits,
    (px, py): (&[f32; LANES], &[f32; LANES]),
    (d_u, d_v, d_depth): (&[f32; LANES], &[f32; LANES], &[f32; LANES]),
) -> LaneTransforms {
    let mut out = LaneTransforms {
        tu: [[0.0; LANES]; 3],
        tv: [[0.0; LANES]; 3],
        tw: [[0.0; LANES]; 3],
    };
    for lane in 0..LANES {
        let (x, y) = (px[lane], py[lane]);
        let k = x * t.tw - t.tu;
        let l = y * t.tw - t.tv;
        let inv = 1.0 / (k.x * l.y - k.y * l.x);
        let (u, v) = (hits.u[lane], hits.v[lane]);
        let dd = d_depth[lane];
        let gu = d_u[lane] + dd * t.tw.x;
        let gv = d_v[lane] + dd * t.tw.y;
        let dp = Vec3::new(gu, gv, -(gu * u + gv * v)) * inv;
        let dk = l.cross(dp);
        let dl = dp.cross(k);
        let tw = x * dk + y * dl + dd * Vec3::new(u, v, 1.0);
        let keep = hits.valid[lane];
        let pick = |g: f32| if keep { g } else { 0.0 };
        for (c, (a, b, w)) in [(-dk.x, -dl.x, tw.x), (-dk.y, -dl.y, tw.y), (-dk.z, -dl.z, tw.z)]
            .into_iter()
            .enumerate()
        {
            out.tu[c][lane] = pick(a);
            out.tv[c][lane] = pick(b);
            out.tw[c][lane] = pick(w);
        }
    }
    out
}
