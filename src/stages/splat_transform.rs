//! The 2DGS ray-splat transform `T` of one billboard, its screen bounds, and the backward pass to
//! position, log-scales and quaternion.
//!
//! Conventions (see `docs/numerics-geometry.md`):
//! - World-to-camera `p_view = R_cw·p + t` with OpenCV axes (x right, y down, z forward); pixel
//!   coordinates are continuous, pixel `(i, j)` is evaluated at its centre `(i + 0.5, j + 0.5)`.
//! - The billboard is the square `(u, v) ∈ [−1, 1]²` of the plane through `position` spanned by
//!   `s_u·t_u` and `s_v·t_v`, with `s = exp(log_scales)` (half side lengths) and `t_u`, `t_v`, `n`
//!   the columns of the rotation of the quaternion `[w, x, y, z]`. World point of `(u, v)`:
//!   `position + u·s_u·t_u + v·s_v·t_v`.
//! - `T = K·[s_u·R_cw·t_u | s_v·R_cw·t_v | p_view]` with `K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`
//!   (the principal point is honoured; the reference forces it to the image centre). `T` maps
//!   `(u, v, 1)` to homogeneous pixel coordinates: pixel `x = Tu·X / Tw·X`, `y = Tv·X / Tw·X`
//!   with `X = (u, v, 1)`, and `Tw·X` is the view depth of the plane point. [`SplatTransform`]
//!   stores the three rows `Tu`, `Tv`, `Tw`.

use crate::camera::Camera;
use crate::stages::rotation::{quat_to_rotation, quat_to_rotation_vjp};
use glam::{DVec2, DVec3, Mat3, Vec2, Vec3};

/// Near plane in view depth (world units): a billboard whose *centre* has view depth
/// `p_view.z ≤ NEAR_PLANE` is culled by [`project_splat`], and a ray-plane hit with
/// `depth < NEAR_PLANE` is rejected by [`crate::stages::ray_plane::intersect`].
///
/// The value `0.2` is the reference rasterizer's `NEAR_PLANE`, kept so that renders compare. It
/// also bounds the perspective division: every accepted depth is at least 0.2, so pixel positions
/// are at most `5·|T|` and never divide by a depth close to zero.
pub const NEAR_PLANE: f32 = 0.2;

/// The reference rasterizer's minimum splat "radius" factor (`FilterSize = 1/√2` pixels), used only
/// by [`ProjectedSplat::reference_radius`].
pub const REFERENCE_FILTER_SIZE: f32 = std::f32::consts::FRAC_1_SQRT_2;

/// The ray-splat transform `T` as its three rows (see the module docs).
///
/// For a plane point `X = (u, v, 1)`: `tu·X = depth·x_pixel`, `tv·X = depth·y_pixel`,
/// `tw·X = depth`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SplatTransform {
    /// First row of `T`: `fx·(a.x, b.x, c.x) + cx·tw`.
    pub tu: Vec3,
    /// Second row of `T`: `fy·(a.y, b.y, c.y) + cy·tw`.
    pub tv: Vec3,
    /// Third row of `T`: `(a.z, b.z, c.z)`, the view-depth row.
    pub tw: Vec3,
}

impl SplatTransform {
    /// The nine entries row by row: `[tu.x, tu.y, tu.z, tv.x, …, tw.z]`.
    #[inline]
    pub fn to_array(&self) -> [f32; 9] {
        [
            self.tu.x, self.tu.y, self.tu.z, self.tv.x, self.tv.y, self.tv.z, self.tw.x, self.tw.y, self.tw.z,
        ]
    }

    /// Inverse of [`SplatTransform::to_array`].
    #[inline]
    pub fn from_array(a: [f32; 9]) -> Self {
        Self {
            tu: Vec3::new(a[0], a[1], a[2]),
            tv: Vec3::new(a[3], a[4], a[5]),
            tw: Vec3::new(a[6], a[7], a[8]),
        }
    }

    /// Pixel coordinates and view depth of the plane point `(u, v)`: `(Tu·X/Tw·X, Tv·X/Tw·X)` and
    /// `Tw·X` with `X = (u, v, 1)`. The pixel is meaningless when the depth is not positive.
    #[inline]
    pub fn project_uv(&self, u: f32, v: f32) -> (Vec2, f32) {
        let x = Vec3::new(u, v, 1.0);
        let depth = self.tw.dot(x);
        (Vec2::new(self.tu.dot(x), self.tv.dot(x)) / depth, depth)
    }
}

/// Forward result of [`project_splat`] for one billboard.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProjectedSplat {
    /// The ray-splat transform `T`.
    pub transform: SplatTransform,
    /// Plane normal in view space, `R_cw·n`, flipped to face the camera
    /// (`normal_view · p_view ≤ 0`).
    pub normal_view: Vec3,
    /// The flip applied to `R_cw·n`: `+1` or `−1` (the sign of `cos θ = −(R_cw·n)·p_view`). The
    /// backward pass treats it as a constant.
    pub normal_sign: f32,
    /// View depth of the billboard centre, `p_view.z` (the reference's per-tile sort key).
    pub view_depth: f32,
    /// Screen centre of the projected unit disk `u² + v² ≤ 1` (2DGS closed form), in pixels.
    /// Not the projection of the 3D centre. Only meaningful when the unit disk lies in front of
    /// the camera plane (`tw.x² + tw.y² < tw.z²`); otherwise the conic is a hyperbola and this is
    /// the reference's formula applied anyway.
    pub centre: Vec2,
    /// Half extent of the axis-aligned bounding box of the projected unit disk (same caveat as
    /// [`ProjectedSplat::centre`]; negative squared extents are clamped to 0 as in the reference).
    /// Equal to the reference's closed form in exact arithmetic but evaluated without its
    /// cancellation (see `docs/numerics-geometry.md`). `+inf` (with `centre` the projected 3D
    /// centre) when the box overflows f32 because the disk grazes the camera plane.
    pub half_extent: Vec2,
    /// `exp(log_scales)`: the half side lengths `(s_u, s_v)` in world units.
    pub scales: Vec2,
}

impl ProjectedSplat {
    /// The reference rasterizer's tiling radius in pixels, `ceil(3·max(h_x, h_y, 1/√2))` (at
    /// least 3). Provided for faithful comparisons; [`square_screen_bounds`] is the tight box.
    #[inline]
    pub fn reference_radius(&self) -> f32 {
        (3.0 * self.half_extent.x.max(self.half_extent.y).max(REFERENCE_FILTER_SIZE)).ceil()
    }
}

/// Gradients of a scalar loss with respect to one billboard's parameters.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SplatGrads {
    /// `∂L/∂position` (world units).
    pub d_position: Vec3,
    /// `∂L/∂log_scales` (through `s = exp(log_scale)`).
    pub d_log_scales: Vec2,
    /// `∂L/∂q` for the raw quaternion `[w, x, y, z]` (through the normalisation).
    pub d_quaternion: [f32; 4],
}

/// Everything the forward and backward passes share.
struct Geometry {
    rotation: Mat3,
    scales: Vec2,
    /// `a = s_u·R_cw·t_u`, `b = s_v·R_cw·t_v`, `c = p_view`.
    a: Vec3,
    b: Vec3,
    c: Vec3,
    normal_view: Vec3,
}

#[inline]
fn geometry(position: Vec3, log_scales: Vec2, quaternion: [f32; 4], camera: &Camera) -> Geometry {
    let rotation = quat_to_rotation(quaternion);
    let scales = Vec2::new(log_scales.x.exp(), log_scales.y.exp());
    let w = camera.rotation;
    Geometry {
        rotation,
        scales,
        a: w * rotation.x_axis * scales.x,
        b: w * rotation.y_axis * scales.y,
        c: view_point(camera, position),
        normal_view: w * rotation.z_axis,
    }
}

/// `p_view = R_cw·position + t`, accumulated in f64 and rounded once to f32.
///
/// In large scenes both terms can be ~1e4 while their sum (a view depth) is a few units; in f32
/// the four roundings at magnitude 1e4 cost up to ~2e-3 units of absolute error in `p_view`
/// (measured: 2.2e-3 of max|T| and 0.033 in (u, v) at 1e4 units, see
/// `docs/numerics-geometry.md`). In f64 the only error left is the final rounding of `p_view`. It
/// runs once per billboard and view, so the cost is negligible.
#[inline]
fn view_point(camera: &Camera, position: Vec3) -> Vec3 {
    (camera.rotation.as_dmat3() * position.as_dvec3() + camera.translation.as_dvec3()).as_vec3()
}

/// The billboard's plane for hit depths ([`crate::stages::ray_plane::ViewPlane`]): the unit
/// normal facing the camera (the normal times `normal_sign`, [`SplatFrame::normal_sign`]) and its
/// offset `n·p_view`.
///
/// The normal is the f64 normal of the raw quaternion ([`crate::stages::rotation::quat_normal_f64`]
/// rotated by the f64 `R_cw`) rounded once to f32, and the offset is taken in f64 with that
/// rounded normal and the f64 view point, then rounded once: the f32 plane passes exactly
/// through the billboard's centre (normal and offset describe the same plane, so the offset
/// does not cancel against a slightly different normal), and the normal carries half an ulp of
/// error instead of the few ulps of the f32 rotation chain.
///
/// Always inlined: called out of line by the rasterizer's preprocess, its pair came back through
/// the stack and was read with wider loads than the stores that wrote it, a stall of the store
/// forwarding per billboard (`docs/perf.md`).
#[inline(always)]
pub fn view_plane(position: Vec3, quaternion: [f32; 4], camera: &Camera, normal_sign: f32) -> (Vec3, f32) {
    let rcw = camera.rotation.as_dmat3();
    let normal = (f64::from(normal_sign) * (rcw * crate::stages::rotation::quat_normal_f64(quaternion))).as_vec3();
    let c = rcw * position.as_dvec3() + camera.translation.as_dvec3();
    (normal, normal.as_dvec3().dot(c) as f32)
}

/// `K·[a | b | c]` as rows.
#[inline]
fn transform_of(a: Vec3, b: Vec3, c: Vec3, camera: &Camera) -> SplatTransform {
    let tw = Vec3::new(a.z, b.z, c.z);
    SplatTransform {
        tu: camera.fx * Vec3::new(a.x, b.x, c.x) + camera.cx * tw,
        tv: camera.fy * Vec3::new(a.y, b.y, c.y) + camera.cy * tw,
        tw,
    }
}

/// Projects one billboard: the ray-splat transform `T`, the camera-facing normal, the centre depth
/// and the reference's unit-disk screen box.
///
/// All arithmetic is f32 except `p_view = R_cw·position + t`, which is accumulated in f64 and
/// rounded once (it cancels large terms when world coordinates are large).
///
/// `position` in world units, `log_scales` the natural logs of the half sides, `quaternion` raw
/// `[w, x, y, z]` (normalised here; a degenerate one gives the identity rotation, see
/// [`crate::stages::rotation::QUAT_NORM_SQ_MIN`]).
///
/// Returns `None` (culled) when
/// - the centre's view depth is `≤` [`NEAR_PLANE`] (or NaN),
/// - a quaternion or log-scale component is not finite,
/// - any entry of `T` or the normal is not finite (NaN or overflowing inputs, e.g. a log-scale
///   above 88.7),
/// - `cos θ = −(R_cw·n)·p_view` is exactly 0 (camera exactly in the billboard's plane: `T` is
///   singular),
/// - `d = tw.x² + tw.y² − tw.z²` is exactly 0 (the unit-disk box formula divides by it).
///
/// These are the reference's culls (§3.1, §3.5 of the spec) plus the finiteness check.
///
/// ```
/// use bbsplat::camera::Camera;
/// use bbsplat::stages::splat_transform::project_splat;
/// use glam::{Vec2, Vec3};
/// let cam = Camera::look_at(Vec3::new(0.0, 0.0, -4.0), Vec3::ZERO, Vec3::Y, 100.0, 100.0, 64, 48);
/// let s = project_splat(Vec3::ZERO, Vec2::splat(0.5f32.ln()), [1.0, 0.0, 0.0, 0.0], &cam).unwrap();
/// assert!((s.view_depth - 4.0).abs() < 1e-5);
/// // The centre (u, v) = (0, 0) projects to the principal point.
/// let (px, depth) = s.transform.project_uv(0.0, 0.0);
/// assert!((px - Vec2::new(32.0, 24.0)).length() < 1e-4 && (depth - 4.0).abs() < 1e-5);
/// // A face-on square of half side 0.5 at depth 4 spans ±100·0.5/4 = ±12.5 px.
/// assert!((s.half_extent - Vec2::splat(12.5)).length() < 1e-3);
/// ```
#[inline]
pub fn project_splat(
    position: Vec3,
    log_scales: Vec2,
    quaternion: [f32; 4],
    camera: &Camera,
) -> Option<ProjectedSplat> {
    project_with_geometry(position, log_scales, quaternion, camera).map(|(p, _)| p)
}

/// The ray-splat frame of a billboard: [`project_splat`] without the reference's unit-disk box,
/// which the rasterizer does not use (it bounds the texture support with
/// [`square_screen_bounds`]). Same culling as [`project_splat`] except the box's own
/// degenerate case (`tw.x² + tw.y² = tw.z²` exactly), where this still gives a frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SplatFrame {
    /// The ray-splat transform `T`.
    pub transform: SplatTransform,
    /// Plane normal in view space, flipped to face the camera (see [`ProjectedSplat`]).
    pub normal_view: Vec3,
    /// The flip applied to `R_cw·n`: `+1` or `−1`.
    pub normal_sign: f32,
    /// View depth of the billboard centre.
    pub view_depth: f32,
    /// `exp(log_scales)`.
    pub scales: Vec2,
}

/// The [`SplatFrame`] of a billboard, or `None` when it is culled: centre at or behind the
/// near plane, exactly edge-on (`cos θ = 0`), a non-finite quaternion or log-scale (a NaN
/// quaternion is not given the identity rotation of degenerate ones), or a non-finite frame.
///
/// ```
/// use bbsplat::camera::Camera;
/// use bbsplat::stages::splat_transform::{project_splat, splat_frame};
/// use glam::{Vec2, Vec3};
/// let cam = Camera::look_at(Vec3::new(0.0, 0.0, -4.0), Vec3::ZERO, Vec3::Y, 100.0, 100.0, 64, 48);
/// let (p, q) = (Vec3::new(0.2, 0.1, 0.0), [0.9, 0.1, 0.3, 0.2]);
/// let frame = splat_frame(p, Vec2::splat(-1.0), q, &cam).unwrap();
/// assert_eq!(frame.transform, project_splat(p, Vec2::splat(-1.0), q, &cam).unwrap().transform);
/// ```
#[inline]
pub fn splat_frame(position: Vec3, log_scales: Vec2, quaternion: [f32; 4], camera: &Camera) -> Option<SplatFrame> {
    frame_with_geometry(position, log_scales, quaternion, camera).map(|(f, _)| f)
}

/// [`splat_frame`] of four billboards at once, bit for bit the same frames.
///
/// The four billboards are the lanes of [`glam::Vec4`] values (SSE registers on x86-64) through
/// the quaternion's normalisation and matrix, `R_cw` times the axes and `K·[a | b | c]`: each
/// lane performs the scalar path's IEEE operations on the same operands in the same order (lane
/// arithmetic rounds exactly like scalar arithmetic, and nothing is fused), so the frames are
/// identical; the square roots, exponentials and the f64 view point are taken lane by lane with
/// the scalar functions. Degenerate quaternions give the identity rotation, as in
/// [`crate::stages::rotation::quat_to_rotation`].
///
/// ```
/// use bbsplat::camera::Camera;
/// use bbsplat::stages::splat_transform::{splat_frame, splat_frames_x4};
/// use glam::{Vec2, Vec3};
/// let cam = Camera::look_at(Vec3::new(0.0, 0.0, -4.0), Vec3::ZERO, Vec3::Y, 100.0, 100.0, 64, 48);
/// // The second billboard is behind the camera, the third has a degenerate quaternion.
/// let p = [Vec3::new(0.2, 0.1, 0.0), Vec3::new(0.0, 0.0, -5.0), Vec3::ZERO, Vec3::new(-0.3, 0.2, 1.0)];
/// let s = [Vec2::splat(-1.0); 4];
/// let q = [[0.9, 0.1, 0.3, 0.2], [1.0, 0.0, 0.0, 0.0], [0.0; 4], [0.1, 0.7, -0.2, 0.4]];
/// let frames = splat_frames_x4(p, s, q, &cam);
/// assert_eq!(frames, std::array::from_fn(|l| splat_frame(p[l], s[l], q[l], &cam)));
/// assert!(frames[1].is_none() && frames[2].is_some());
/// ```
pub fn splat_frames_x4(
    positions: [Vec3; 4],
    log_scales: [Vec2; 4],
    quaternions: [[f32; 4]; 4],
    camera: &Camera,
) -> [Option<SplatFrame>; 4] {
    use crate::stages::rotation::QUAT_NORM_SQ_MIN;
    use glam::Vec4;
    // Explicit lanes throughout: `array::map` and `array::from_fn` are not always inlined, and
    // their closures would cost more than the arithmetic they carry.
    let q = &quaternions;
    let component = |c: usize| Vec4::new(q[0][c], q[1][c], q[2][c], q[3][c]);
    let (qw, qx, qy, qz) = (component(0), component(1), component(2), component(3));
    // `quat_to_rotation`: normalise, then the unit quaternion's matrix, or the identity.
    let n2 = qw * qw + qx * qx + qy * qy + qz * qz;
    let unit = n2.cmpge(Vec4::splat(QUAT_NORM_SQ_MIN)) & n2.cmplt(Vec4::splat(f32::INFINITY));
    let inv = Vec4::ONE / Vec4::new(n2.x.sqrt(), n2.y.sqrt(), n2.z.sqrt(), n2.w.sqrt());
    let (w, x, y, z) = (qw * inv, qx * inv, qy * inv, qz * inv);
    let (xx, yy, zz) = (x * x, y * y, z * z);
    let (xy, xz, yz) = (x * y, x * z, y * z);
    let (wx, wy, wz) = (w * x, w * y, w * z);
    let two = Vec4::splat(2.0);
    let pick = |v: Vec4, identity: f32| Vec4::select(unit, v, Vec4::splat(identity));
    // Columns of the rotation, component by component.
    let col = [
        [
            pick(Vec4::ONE - two * (yy + zz), 1.0),
            pick(two * (xy + wz), 0.0),
            pick(two * (xz - wy), 0.0),
        ],
        [
            pick(two * (xy - wz), 0.0),
            pick(Vec4::ONE - two * (xx + zz), 1.0),
            pick(two * (yz + wx), 0.0),
        ],
        [
            pick(two * (xz + wy), 0.0),
            pick(two * (yz - wx), 0.0),
            pick(Vec4::ONE - two * (xx + yy), 1.0),
        ],
    ];
    let ls = &log_scales;
    let sx = Vec4::new(ls[0].x.exp(), ls[1].x.exp(), ls[2].x.exp(), ls[3].x.exp());
    let sy = Vec4::new(ls[0].y.exp(), ls[1].y.exp(), ls[2].y.exp(), ls[3].y.exp());
    // `R_cw · v` as glam's `Mat3 * Vec3` computes it: `(x_axis·v.x + y_axis·v.y) + z_axis·v.z`.
    let r = camera.rotation;
    let rotate = |v: &[Vec4; 3], i: usize| r.x_axis[i] * v[0] + r.y_axis[i] * v[1] + r.z_axis[i] * v[2];
    let a = [
        rotate(&col[0], 0) * sx,
        rotate(&col[0], 1) * sx,
        rotate(&col[0], 2) * sx,
    ];
    let b = [
        rotate(&col[1], 0) * sy,
        rotate(&col[1], 1) * sy,
        rotate(&col[1], 2) * sy,
    ];
    let n = [rotate(&col[2], 0), rotate(&col[2], 1), rotate(&col[2], 2)];
    let c = [
        view_point(camera, positions[0]),
        view_point(camera, positions[1]),
        view_point(camera, positions[2]),
        view_point(camera, positions[3]),
    ];
    let cx = Vec4::new(c[0].x, c[1].x, c[2].x, c[3].x);
    let cy = Vec4::new(c[0].y, c[1].y, c[2].y, c[3].y);
    let cz = Vec4::new(c[0].z, c[1].z, c[2].z, c[3].z);
    // `transform_of`: tu = fx·(a.x, b.x, c.x) + cx·tw, tv = fy·(a.y, b.y, c.y) + cy·tw.
    let tu = [
        camera.fx * a[0] + camera.cx * a[2],
        camera.fx * b[0] + camera.cx * b[2],
        camera.fx * cx + camera.cx * cz,
    ];
    let tv = [
        camera.fy * a[1] + camera.cy * a[2],
        camera.fy * b[1] + camera.cy * b[2],
        camera.fy * cy + camera.cy * cz,
    ];
    let lane = |v: &[Vec4; 3], l: usize| Vec3::new(v[0][l], v[1][l], v[2][l]);
    let frame = |l: usize| {
        let c = c[l];
        if !(q[l].iter().all(|x| x.is_finite()) && ls[l].is_finite()) || c.z.is_nan() || c.z <= NEAR_PLANE {
            return None;
        }
        let transform = SplatTransform {
            tu: lane(&tu, l),
            tv: lane(&tv, l),
            tw: Vec3::new(a[2][l], b[2][l], c.z),
        };
        checked_frame(transform, lane(&n, l), c, Vec2::new(sx[l], sy[l]))
    };
    [frame(0), frame(1), frame(2), frame(3)]
}

/// [`splat_frame`], also returning the intermediate geometry for the backward pass.
#[inline]
fn frame_with_geometry(
    position: Vec3,
    log_scales: Vec2,
    quaternion: [f32; 4],
    camera: &Camera,
) -> Option<(SplatFrame, Geometry)> {
    // A non-finite quaternion would otherwise fall back to the identity rotation (the rule for
    // degenerate but finite ones) and a log-scale of −∞ to a zero-size square: both would pass
    // for ordinary billboards.
    if !(quaternion.iter().all(|q| q.is_finite()) && log_scales.is_finite()) {
        return None;
    }
    let g = geometry(position, log_scales, quaternion, camera);
    if g.c.z.is_nan() || g.c.z <= NEAR_PLANE {
        return None;
    }
    let frame = checked_frame(transform_of(g.a, g.b, g.c, camera), g.normal_view, g.c, g.scales)?;
    Some((frame, g))
}

/// The frame of a billboard whose centre is in front of the near plane, from its transform,
/// `R_cw·n`, `p_view` and scales; `None` when the transform or the normal is not finite or
/// `cos θ = −(R_cw·n)·p_view` is exactly 0. Shared by [`splat_frame`] and [`splat_frames_x4`].
#[inline]
fn checked_frame(transform: SplatTransform, normal_view: Vec3, c: Vec3, scales: Vec2) -> Option<SplatFrame> {
    let SplatTransform { tu, tv, tw } = transform;
    if !(tu.is_finite() && tv.is_finite() && tw.is_finite() && normal_view.is_finite()) {
        return None;
    }
    let cos_theta = -normal_view.dot(c);
    if cos_theta == 0.0 {
        return None;
    }
    let normal_sign = if cos_theta > 0.0 { 1.0 } else { -1.0 };
    Some(SplatFrame {
        transform,
        normal_view: normal_view * normal_sign,
        normal_sign,
        view_depth: c.z,
        scales,
    })
}

/// [`project_splat`], also returning the intermediate geometry for the backward pass.
#[inline]
fn project_with_geometry(
    position: Vec3,
    log_scales: Vec2,
    quaternion: [f32; 4],
    camera: &Camera,
) -> Option<(ProjectedSplat, Geometry)> {
    let (f, g) = frame_with_geometry(position, log_scales, quaternion, camera)?;
    let (centre, half_extent) = unit_disk_box(&f.transform)?;
    let projected = ProjectedSplat {
        transform: f.transform,
        normal_view: f.normal_view,
        normal_sign: f.normal_sign,
        view_depth: f.view_depth,
        centre,
        half_extent,
        scales: f.scales,
    };
    Some((projected, g))
}

/// The reference's screen box of the projected unit disk (2DGS closed form), or `None` when
/// `d = tw.x² + tw.y² − tw.z²` is exactly 0.
///
/// Evaluated in f64 from the f32 entries of `T` (once per billboard and view) and rounded once:
/// - the reference's `h² = centre² − Σ f_k·Tu_k²` cancels catastrophically for small splats
///   (absolute error ~`√ε·|centre|`, i.e. ~0.01 px at 40 px from the origin in f32). By
///   Cauchy-Binet it equals `(m.x² + m.y² − m.z²)/d²` with `m = Tu × Tw`, whose terms do not
///   cancel; that form is used;
/// - when `d` is merely tiny (the unit disk grazes the camera plane) the box can overflow f32:
///   then the centre falls back to the projected 3D centre and the half extent to `+inf` (a
///   conservative box), never NaN.
#[inline]
fn unit_disk_box(t: &SplatTransform) -> Option<(Vec2, Vec2)> {
    let (tu, tv, tw) = (t.tu.as_dvec3(), t.tv.as_dvec3(), t.tw.as_dvec3());
    let d = tw.x * tw.x + tw.y * tw.y - tw.z * tw.z;
    if d == 0.0 {
        return None;
    }
    let f = DVec3::new(1.0, 1.0, -1.0) / d;
    let centre = DVec2::new((f * tu).dot(tw), (f * tv).dot(tw)).as_vec2();
    let extent = |m: DVec3| ((m.x * m.x + m.y * m.y - m.z * m.z).max(0.0).sqrt() / d.abs()) as f32;
    let half_extent = Vec2::new(extent(tu.cross(tw)), extent(tv.cross(tw)));
    if centre.is_finite() && half_extent.is_finite() {
        Some((centre, half_extent))
    } else {
        // tw.z is the centre's view depth (> NEAR_PLANE here).
        Some((Vec2::new(t.tu.z, t.tv.z) / t.tw.z, Vec2::splat(f32::INFINITY)))
    }
}

/// Backward pass of [`project_splat`]: gradients of a loss with respect to position, log-scales and
/// raw quaternion, given `∂L/∂T` (as rows, same layout as [`SplatTransform`]) and
/// `∂L/∂normal_view` (the flipped normal; the flip sign is treated as a constant).
///
/// The outputs `view_depth`, `centre` and `half_extent` are not differentiated (they only drive
/// sorting and tiling). A billboard culled by [`splat_frame`] gets zero gradients (the
/// unit-disk box is not needed here, so its own degenerate case is not a cull).
///
/// Chain: `∂L/∂[a|b|c] = Kᵀ·∂L/∂T`; `∂L/∂position = R_cwᵀ·∂L/∂c`;
/// `∂L/∂t_u = s_u·R_cwᵀ·∂L/∂a`, `∂L/∂s_u = t_u·R_cwᵀ·∂L/∂a` and `∂L/∂log s_u = s_u·∂L/∂s_u` (same
/// for v); `∂L/∂n = sign·R_cwᵀ·∂L/∂normal_view`; then the quaternion VJP of
/// [`crate::stages::rotation::quat_to_rotation_vjp`].
///
/// ```
/// use bbsplat::camera::Camera;
/// use bbsplat::stages::splat_transform::{project_splat_vjp, SplatTransform};
/// use glam::{Vec2, Vec3};
/// let cam = Camera::look_at(Vec3::new(0.0, 0.0, -4.0), Vec3::ZERO, Vec3::Y, 100.0, 100.0, 64, 48);
/// // L = Tw.z = view depth of the centre: ∂L/∂position is the camera's viewing axis.
/// let d_t = SplatTransform { tw: Vec3::Z, ..Default::default() };
/// let g = project_splat_vjp(Vec3::ZERO, Vec2::ZERO, [1.0, 0.0, 0.0, 0.0], &cam, &d_t, Vec3::ZERO);
/// assert!((g.d_position - Vec3::Z).length() < 1e-6);
/// assert_eq!(g.d_log_scales, Vec2::ZERO);
/// ```
#[inline]
pub fn project_splat_vjp(
    position: Vec3,
    log_scales: Vec2,
    quaternion: [f32; 4],
    camera: &Camera,
    d_transform: &SplatTransform,
    d_normal_view: Vec3,
) -> SplatGrads {
    let Some((frame, g)) = frame_with_geometry(position, log_scales, quaternion, camera) else {
        return SplatGrads::default();
    };
    axes_vjp(
        g.rotation,
        g.scales,
        quaternion,
        frame.normal_sign,
        camera,
        d_transform,
        d_normal_view,
    )
}

/// [`project_splat_vjp`] for a billboard already known to pass [`splat_frame`]'s culling (the
/// frame exists), given the frame's `normal_sign`: the same values bit for bit, without
/// recomputing the frame (view point, `T`, checks). The rasterizer's backward calls it for every
/// billboard that reached a pixel; what it skips is most of [`project_splat_vjp`]'s cost.
///
/// Its result is meaningless (not zero) for a billboard that [`splat_frame`] culls.
///
/// ```
/// use bbsplat::camera::Camera;
/// use bbsplat::stages::splat_transform::{project_splat_vjp, project_splat_vjp_visible, splat_frame, SplatTransform};
/// use glam::{Vec2, Vec3};
/// let cam = Camera::look_at(Vec3::new(0.0, 0.0, -4.0), Vec3::ZERO, Vec3::Y, 100.0, 100.0, 64, 48);
/// let (p, s, q) = (Vec3::new(0.1, 0.2, 0.3), Vec2::new(-1.0, -0.5), [0.9, 0.1, -0.3, 0.2]);
/// let frame = splat_frame(p, s, q, &cam).unwrap();
/// let d_t = SplatTransform { tu: Vec3::X, tv: Vec3::Y, tw: Vec3::ONE };
/// let full = project_splat_vjp(p, s, q, &cam, &d_t, Vec3::X);
/// assert_eq!(project_splat_vjp_visible(s, q, frame.normal_sign, &cam, &d_t, Vec3::X), full);
/// ```
#[inline]
pub fn project_splat_vjp_visible(
    log_scales: Vec2,
    quaternion: [f32; 4],
    normal_sign: f32,
    camera: &Camera,
    d_transform: &SplatTransform,
    d_normal_view: Vec3,
) -> SplatGrads {
    // The same calls as `geometry`, so the same bits.
    let rotation = quat_to_rotation(quaternion);
    let scales = Vec2::new(log_scales.x.exp(), log_scales.y.exp());
    axes_vjp(
        rotation,
        scales,
        quaternion,
        normal_sign,
        camera,
        d_transform,
        d_normal_view,
    )
}

/// The chain of [`project_splat_vjp`] from `∂L/∂T` and `∂L/∂normal_view` back to position,
/// log-scales and quaternion, given the forward's rotation and scales.
#[inline]
fn axes_vjp(
    rotation: Mat3,
    scales: Vec2,
    quaternion: [f32; 4],
    normal_sign: f32,
    camera: &Camera,
    d_transform: &SplatTransform,
    d_normal_view: Vec3,
) -> SplatGrads {
    let [da, db, dc] = view_columns_vjp(camera, d_transform);
    let wt = camera.rotation.transpose();
    let (da_world, db_world) = (wt * da, wt * db);
    let d_rotation = Mat3::from_cols(
        da_world * scales.x,
        db_world * scales.y,
        wt * d_normal_view * normal_sign,
    );
    let d_scales = Vec2::new(da_world.dot(rotation.x_axis), db_world.dot(rotation.y_axis));
    SplatGrads {
        d_position: wt * dc,
        d_log_scales: d_scales * scales,
        d_quaternion: quat_to_rotation_vjp(quaternion, d_rotation),
    }
}

/// `∂L/∂[a | b | c]`, the view-space columns of `M` in `T = K·M`, from `∂L/∂T`:
/// `∂L/∂M = Kᵀ·∂L/∂T`. Row 0 of `∂L/∂M` is `fx·du`, row 1 `fy·dv`, row 2 `cx·du + cy·dv + dw`.
#[inline]
fn view_columns_vjp(camera: &Camera, d_transform: &SplatTransform) -> [Vec3; 3] {
    let SplatTransform { tu: du, tv: dv, tw: dw } = *d_transform;
    let row2 = camera.cx * du + camera.cy * dv + dw;
    [
        Vec3::new(camera.fx * du.x, camera.fy * dv.x, row2.x),
        Vec3::new(camera.fx * du.y, camera.fy * dv.y, row2.y),
        Vec3::new(camera.fx * du.z, camera.fy * dv.z, row2.z),
    ]
}

/// Gradients of a loss with respect to a small change of the camera, through one billboard's
/// `T` and facing normal (see [`camera_vjp`] for the parametrisation).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CameraGrads {
    /// `∂L/∂ω`: the view frame turned by `ω` (radians, camera axes), `p_view → (I + [ω]×)·p_view`.
    pub rotation: Vec3,
    /// `∂L/∂δ`: the view frame shifted by `δ` (world units, camera axes), `p_view → p_view + δ`.
    pub translation: Vec3,
    /// `(∂L/∂fx, ∂L/∂fy)`.
    pub focal: Vec2,
    /// `(∂L/∂cx, ∂L/∂cy)`.
    pub principal: Vec2,
}

/// Backward pass of [`project_splat`] to the camera: what `∂L/∂T` and `∂L/∂normal_view` (the
/// flipped normal, as for [`project_splat_vjp`]) say about the camera's pose and intrinsics.
///
/// The pose change is applied on the camera side of the world-to-camera transform:
/// `p_view = (I + [ω]×)·(R_cw·p + t) + δ`, i.e. `R_cw → (I + [ω]×)·R_cw` and
/// `t → (I + [ω]×)·t + δ`, so that `ω` turns the camera about its own centre and `δ` moves
/// it (by `−R_cwᵀ·δ` in world units). Then `a → a + ω×a`, `b → b + ω×b`, `c → c + ω×c + δ` and
/// `normal_view → normal_view + ω×normal_view`, so with `g_a, g_b, g_c` the columns of
/// `Kᵀ·∂L/∂T`: `∂L/∂ω = a×g_a + b×g_b + c×g_c + n×∂L/∂n` and `∂L/∂δ = g_c`. The intrinsics enter
/// only `T`: `∂L/∂fx = du·(a.x, b.x, c.x)`, `∂L/∂cx = du·tw` (same for y).
///
/// The SH colour's view direction depends on the camera centre too; that path is not here (it
/// is `R_cw·∂L/∂position` of the SH VJP, added by the rasterizer's backward pass).
///
/// A billboard culled by [`splat_frame`] gets zero gradients.
///
/// ```
/// use bbsplat::camera::Camera;
/// use bbsplat::stages::splat_transform::{camera_vjp, SplatTransform};
/// use glam::{Vec2, Vec3};
/// let cam = Camera::look_at(Vec3::new(0.0, 0.0, -4.0), Vec3::ZERO, Vec3::Y, 100.0, 100.0, 64, 48);
/// // L = Tw.z = view depth of the centre: moving the view frame by δ adds δ.z to it.
/// let d_t = SplatTransform { tw: Vec3::Z, ..Default::default() };
/// let g = camera_vjp(Vec3::ZERO, Vec2::ZERO, [1.0, 0.0, 0.0, 0.0], &cam, &d_t, Vec3::ZERO);
/// assert!((g.translation - Vec3::Z).length() < 1e-6);
/// // Turning the camera about its centre does not change the depth of a point on its axis.
/// assert!(g.rotation.length() < 1e-6);
/// ```
pub fn camera_vjp(
    position: Vec3,
    log_scales: Vec2,
    quaternion: [f32; 4],
    camera: &Camera,
    d_transform: &SplatTransform,
    d_normal_view: Vec3,
) -> CameraGrads {
    let Some((frame, g)) = frame_with_geometry(position, log_scales, quaternion, camera) else {
        return CameraGrads::default();
    };
    let [da, db, dc] = view_columns_vjp(camera, d_transform);
    let SplatTransform { tu: du, tv: dv, .. } = *d_transform;
    let tw = frame.transform.tw;
    CameraGrads {
        rotation: g.a.cross(da) + g.b.cross(db) + g.c.cross(dc) + frame.normal_view.cross(d_normal_view),
        translation: dc,
        focal: Vec2::new(
            du.dot(Vec3::new(g.a.x, g.b.x, g.c.x)),
            dv.dot(Vec3::new(g.a.y, g.b.y, g.c.y)),
        ),
        principal: Vec2::new(du.dot(tw), dv.dot(tw)),
    }
}

/// Half side of the texture support square for a `texture_size × texture_size` texture:
/// `1 + 2/(TS − 1)` (1.1333 for TS = 16). With align-corners texel centres at `u = −1 … 1` and zero
/// padding, bilinear samples fade to exactly 0 one texel spacing outside `[−1, 1]²`.
///
/// ```
/// assert!((bbsplat::stages::splat_transform::support_half_side(16) - 1.0 - 2.0 / 15.0).abs() < 1e-7);
/// ```
#[inline]
pub fn support_half_side(texture_size: usize) -> f32 {
    1.0 + 2.0 / (texture_size.max(2) - 1) as f32
}

/// The projected texture support square of a billboard, for culling pixels row by row: a
/// pixel whose centre lies outside [`SupportQuad::row_span`] of its row cannot hit the support
/// (the bounding box alone lets in every pixel of the box's corners, about half of the pairs a
/// trained scene evaluates).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SupportQuad {
    /// Projected corners of `(u, v) = (−h, −h), (h, −h), (h, h), (−h, h)`, in pixels: a convex
    /// quadrilateral (the square lies entirely in front of the camera).
    pub corners: [Vec2; 4],
    /// Safety margin in pixels, covering the f32 rounding of the ray-plane intersection: at least
    /// 0.01 px and 1e-3 of the quad's extent. A pixel accepted by
    /// [`crate::stages::ray_plane::intersect`] and the bilinear support test lies within this
    /// distance of the quad (tested).
    pub margin: f32,
}

/// Largest ratio of the corner depths for which [`support_quad`] returns a quad: beyond it the
/// perspective stretches the intersection's rounding errors too far for the fixed margin.
pub const SUPPORT_QUAD_MAX_DEPTH_RATIO: f64 = 16.0;

/// The [`SupportQuad`] of the support square `|u|, |v| ≤ half_side` of a billboard with transform
/// `t`, or `None` (use the bounding box) when a corner lies closer than `2 ·` [`NEAR_PLANE`], the
/// corner depths differ by more than [`SUPPORT_QUAD_MAX_DEPTH_RATIO`], or the projection is not
/// finite or wider than 10⁶ px. Corners computed in f64.
///
/// ```
/// use bbsplat::stages::splat_transform::{support_quad, SplatTransform};
/// use glam::Vec3;
/// // Face-on square at depth 2, fx = fy = 10, principal point (5, 5), half sides 1.
/// let t = SplatTransform { tu: Vec3::new(10.0, 0.0, 10.0), tv: Vec3::new(0.0, 10.0, 10.0), tw: Vec3::new(0.0, 0.0, 2.0) };
/// let q = support_quad(&t, 1.0).unwrap();
/// let (lo, hi) = q.row_span(5.0).unwrap();
/// assert!(lo <= 0.0 && lo > -0.1 && hi >= 10.0 && hi < 10.1);
/// assert!(q.row_span(10.5).is_none());
/// ```
pub fn support_quad(t: &SplatTransform, half_side: f32) -> Option<SupportQuad> {
    if !(t.tu.is_finite() && t.tv.is_finite() && t.tw.is_finite() && half_side.is_finite()) {
        return None;
    }
    let (tu, tv, tw) = (t.tu.as_dvec3(), t.tv.as_dvec3(), t.tw.as_dvec3());
    let h = half_side.abs() as f64;
    let uv = [(-h, -h), (h, -h), (h, h), (-h, h)].map(|(u, v)| DVec3::new(u, v, 1.0));
    let depths = uv.map(|x| tw.dot(x));
    let (lo, hi) = depths
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &d| (a.min(d), b.max(d)));
    // Written positively: NaN fails.
    if !(lo >= 2.0 * NEAR_PLANE as f64 && hi <= SUPPORT_QUAD_MAX_DEPTH_RATIO * lo) {
        return None;
    }
    let corners: [Vec2; 4] = std::array::from_fn(|k| (DVec2::new(tu.dot(uv[k]), tv.dot(uv[k])) / depths[k]).as_vec2());
    let (min, max) = corners
        .iter()
        .fold((Vec2::INFINITY, Vec2::NEG_INFINITY), |(a, b), &c| (a.min(c), b.max(c)));
    let extent = (max - min).max_element();
    if extent.is_nan() || extent > 1e6 {
        return None;
    }
    Some(SupportQuad {
        corners,
        margin: (1e-3 * extent).max(0.01),
    })
}

impl SupportQuad {
    /// The x-range `[lo, hi]` (pixels) of the quad within the band `|y − py| ≤ margin`, widened
    /// by `margin` on both sides; `None` when the band misses the quad. Every pixel centre
    /// `(x, py)` accepted by the ray-plane intersection and the bilinear support test has
    /// `lo ≤ x ≤ hi`.
    #[inline]
    pub fn row_span(&self, py: f32) -> Option<(f32, f32)> {
        let m = self.margin;
        let (y_lo, y_hi) = (py - m, py + m);
        let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
        for k in 0..4 {
            let (a, b) = (self.corners[k], self.corners[(k + 1) % 4]);
            // The part of edge a → b inside the band, as parameters [t0, t1] of a + t·(b − a).
            let dy = b.y - a.y;
            let (mut t0, mut t1) = (0.0f32, 1.0f32);
            if dy == 0.0 {
                if !(a.y >= y_lo && a.y <= y_hi) {
                    continue;
                }
            } else {
                let (ta, tb) = ((y_lo - a.y) / dy, (y_hi - a.y) / dy);
                t0 = t0.max(ta.min(tb));
                t1 = t1.min(ta.max(tb));
                if t0.is_nan() || t1.is_nan() || t0 > t1 {
                    continue;
                }
            }
            let (x0, x1) = (a.x + (b.x - a.x) * t0, a.x + (b.x - a.x) * t1);
            lo = lo.min(x0.min(x1));
            hi = hi.max(x0.max(x1));
        }
        (lo <= hi).then_some((lo - m, hi + m))
    }

    /// [`SupportQuad::row_span`] of [`ROW_LANES`] rows at once: lane `l` is `row_span(py[l])`,
    /// bit for bit (the same operations in the same order, the skipped edges replaced by
    /// selects), written without branches on the lane so that the divisions of all rows run in
    /// vector registers. Tested against `row_span` in `tests/suite/stage_lanes.rs`.
    #[inline(always)]
    pub fn row_spans(&self, py: &[f32; ROW_LANES]) -> [Option<(f32, f32)>; ROW_LANES] {
        let m = self.margin;
        let y_lo: [f32; ROW_LANES] = std::array::from_fn(|l| py[l] - m);
        let y_hi: [f32; ROW_LANES] = std::array::from_fn(|l| py[l] + m);
        let (mut lo, mut hi) = ([f32::INFINITY; ROW_LANES], [f32::NEG_INFINITY; ROW_LANES]);
        for k in 0..4 {
            let (a, b) = (self.corners[k], self.corners[(k + 1) % 4]);
            let dy = b.y - a.y;
            // Both cases of `row_span` computed and the edge's own chosen by a select (a
            // horizontal edge's divisions give infinities or NaN, which are not chosen), and the
            // lanes written to new arrays, so that `lo`, `hi` stay in registers from edge to edge
            // (seen in the compiled `fill_rows_avx2`). Written with a branch on the edge and the
            // lanes updated in place, the compiler kept them on the stack and updated them with
            // a masked store, which the next edge reloaded at once: on AMD Zen such a reload
            // waits for the store (docs/perf-log.md, 2026-11-29).
            let flat = dy == 0.0;
            let mut next_lo = [0.0f32; ROW_LANES];
            let mut next_hi = [0.0f32; ROW_LANES];
            for l in 0..ROW_LANES {
                let (ta, tb) = ((y_lo[l] - a.y) / dy, (y_hi[l] - a.y) / dy);
                let (edge_t0, edge_t1) = (0.0f32.max(ta.min(tb)), 1.0f32.min(ta.max(tb)));
                let (t0, t1) = if flat { (0.0f32, 1.0f32) } else { (edge_t0, edge_t1) };
                let keep = if flat {
                    a.y >= y_lo[l] && a.y <= y_hi[l]
                } else {
                    !(t0.is_nan() || t1.is_nan() || t0 > t1)
                };
                let (x0, x1) = (a.x + (b.x - a.x) * t0, a.x + (b.x - a.x) * t1);
                let (new_lo, new_hi) = (lo[l].min(x0.min(x1)), hi[l].max(x0.max(x1)));
                next_lo[l] = if keep { new_lo } else { lo[l] };
                next_hi[l] = if keep { new_hi } else { hi[l] };
            }
            (lo, hi) = (next_lo, next_hi);
        }
        std::array::from_fn(|l| (lo[l] <= hi[l]).then_some((lo[l] - m, hi[l] + m)))
    }
}

/// Rows per call of [`SupportQuad::row_spans`].
pub const ROW_LANES: usize = 8;

/// An axis-aligned box in continuous pixel coordinates (pixel `(i, j)` has its centre at
/// `(i + 0.5, j + 0.5)`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScreenBounds {
    /// Smallest x and y covered.
    pub min: Vec2,
    /// Largest x and y covered.
    pub max: Vec2,
}

/// A rectangle of pixel indices: columns `x_min..x_max`, rows `y_min..y_max` (exclusive ends).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PixelRect {
    /// First column.
    pub x_min: u32,
    /// First row.
    pub y_min: u32,
    /// One past the last column.
    pub x_max: u32,
    /// One past the last row.
    pub y_max: u32,
}

impl ScreenBounds {
    /// True when the point lies in the closed box.
    #[inline]
    pub fn contains(&self, p: Vec2) -> bool {
        p.cmpge(self.min).all() && p.cmple(self.max).all()
    }

    /// The pixels of a `width × height` image whose centres lie in the box, or `None` if there are
    /// none.
    ///
    /// ```
    /// use bbsplat::stages::splat_transform::{PixelRect, ScreenBounds};
    /// use glam::Vec2;
    /// let b = ScreenBounds { min: Vec2::new(-3.0, 2.5), max: Vec2::new(4.49, 2.5) };
    /// assert_eq!(b.pixel_rect(10, 10), Some(PixelRect { x_min: 0, y_min: 2, x_max: 4, y_max: 3 }));
    /// assert_eq!(b.pixel_rect(10, 2), None);
    /// ```
    #[inline]
    pub fn pixel_rect(&self, width: u32, height: u32) -> Option<PixelRect> {
        let (x_min, x_max) = pixel_range(self.min.x, self.max.x, width);
        let (y_min, y_max) = pixel_range(self.min.y, self.max.y, height);
        (x_min < x_max && y_min < y_max).then_some(PixelRect {
            x_min,
            y_min,
            x_max,
            y_max,
        })
    }
}

/// The pixel indices `first..end` of a row or column of `n` pixels whose centres `i + 0.5` lie
/// in `[lo, hi]`: `first = clamp(⌈lo − 0.5⌉, 0, n)`, `end = clamp(⌊hi − 0.5⌋ + 1, 0, n)` (empty
/// when `first ≥ end`). Used by [`ScreenBounds::pixel_rect`] and the rasterizer's per-row
/// culling.
///
/// The arguments are clamped first (which changes no result: everything outside lands on 0 or
/// `n` anyway), so huge or infinite bounds are safe, and the rounding is a truncating cast plus a
/// correction instead of a libm call (baseline x86-64 has no rounding instruction).
///
/// ```
/// use bbsplat::stages::splat_transform::pixel_range;
/// assert_eq!(pixel_range(1.5, 4.49, 10), (1, 4)); // centres 1.5, 2.5, 3.5
/// assert_eq!(pixel_range(-1e30, f32::INFINITY, 10), (0, 10));
/// assert_eq!(pixel_range(3.6, 4.4, 10), (4, 4)); // no centre inside
/// ```
#[inline]
pub fn pixel_range(lo: f32, hi: f32, n: u32) -> (u32, u32) {
    let x = (lo - 0.5).clamp(-1.0, n as f32);
    let t = x as i64;
    let first = (if (t as f32) < x { t + 1 } else { t }).clamp(0, i64::from(n)) as u32;
    let x = (hi - 0.5).clamp(-2.0, n as f32);
    let t = x as i64;
    let end = (if (t as f32) > x { t - 1 } else { t } + 1).clamp(0, i64::from(n)) as u32;
    (first, end)
}

/// Tight screen-space bounding box of the texture support square `|u|, |v| ≤ half_side` (use
/// [`support_half_side`]) of a billboard with transform `t`, restricted to the part the rasterizer
/// can see: plane points with view depth `≥` [`NEAR_PLANE`], the same acceptance rule as
/// [`crate::stages::ray_plane::intersect`].
///
/// View depth is affine in `(u, v)` (`depth = tw·(u, v, 1)`), so the visible part of the square is
/// the square clipped by the half-plane `depth ≥ NEAR_PLANE`: a convex polygon of at most 5
/// vertices, all in front of the camera. A convex planar polygon in front of the camera projects
/// to the convex hull of its projected vertices, so the box of those vertices is exact. When all
/// 4 corners are in front this is just the box of the 4 projected corners. No conservative
/// fallback is needed.
///
/// Computed in f64 from the f32 entries of `t` (once per billboard and view): for a huge billboard
/// crossing the near plane the corner depths can be ~1e9 while the clip vertices must land at
/// depth 0.2, which f32 cannot resolve (a clip vertex could come out behind the camera and
/// project to the wrong side).
///
/// Returns `None` when the whole square is behind the near plane or an input is not finite. The
/// box is not clipped to the image; see [`ScreenBounds::pixel_rect`].
///
/// ```
/// use bbsplat::stages::splat_transform::{square_screen_bounds, SplatTransform};
/// use glam::{Vec2, Vec3};
/// // Face-on square at depth 2, fx = fy = 10, principal point (5, 5), half sides 1.
/// let t = SplatTransform { tu: Vec3::new(10.0, 0.0, 10.0), tv: Vec3::new(0.0, 10.0, 10.0), tw: Vec3::new(0.0, 0.0, 2.0) };
/// let b = square_screen_bounds(&t, 1.0).unwrap();
/// assert!((b.min - Vec2::splat(0.0)).length() < 1e-6 && (b.max - Vec2::splat(10.0)).length() < 1e-6);
/// ```
#[inline]
pub fn square_screen_bounds(t: &SplatTransform, half_side: f32) -> Option<ScreenBounds> {
    if !(t.tu.is_finite() && t.tv.is_finite() && t.tw.is_finite() && half_side.is_finite()) {
        return None;
    }
    let (tu, tv, tw) = (t.tu.as_dvec3(), t.tv.as_dvec3(), t.tw.as_dvec3());
    let h = half_side.abs() as f64;
    let near = NEAR_PLANE as f64;
    let corners = [
        DVec2::new(-h, -h),
        DVec2::new(h, -h),
        DVec2::new(h, h),
        DVec2::new(-h, h),
    ];
    let depths = corners.map(|p| tw.x * p.x + tw.y * p.y + tw.z);
    // Clip the square by depth ≥ NEAR_PLANE (one Sutherland-Hodgman pass, at most 5 vertices).
    let mut poly = [DVec2::ZERO; 5];
    let mut n = 0;
    for i in 0..4 {
        let j = (i + 1) % 4;
        let (p, q, dp, dq) = (corners[i], corners[j], depths[i], depths[j]);
        let p_in = dp >= near;
        if p_in {
            poly[n] = p;
            n += 1;
        }
        if p_in != (dq >= near) {
            // The edge crosses the near plane (so dp ≠ dq).
            poly[n] = p + (q - p) * ((near - dp) / (dq - dp));
            n += 1;
        }
    }
    if n == 0 {
        return None;
    }
    let mut min = DVec2::splat(f64::INFINITY);
    let mut max = DVec2::splat(f64::NEG_INFINITY);
    for &p in &poly[..n] {
        // Every vertex has depth ≥ NEAR_PLANE up to f64 rounding: the division is safe.
        let x = DVec3::new(p.x, p.y, 1.0);
        let pixel = DVec2::new(tu.dot(x), tv.dot(x)) / tw.dot(x);
        min = min.min(pixel);
        max = max.max(pixel);
    }
    let (min, max) = (min.as_vec2(), max.as_vec2());
    (min.is_finite() && max.is_finite()).then_some(ScreenBounds { min, max })
}
