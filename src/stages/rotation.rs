//! Quaternion → rotation matrix, with the backward pass to the raw (non-unit) quaternion.
//!
//! Conventions (see `docs/numerics-geometry.md`):
//! - A quaternion is stored as `[w, x, y, z]` (scalar first, as in BBSplat and 2DGS) and is *not*
//!   unit in storage: it is normalised here before use, and the backward pass differentiates
//!   through that normalisation.
//! - The columns of the rotation matrix are the billboard's local axes in world coordinates:
//!   `t_u` (column 0), `t_v` (column 1) and the plane normal `n` (column 2).
//! - A quaternion whose squared norm is below [`QUAT_NORM_SQ_MIN`], or that is not finite, has no
//!   usable direction: the forward pass returns the identity and the backward pass a zero gradient.
//!   Nothing here returns NaN or panics.

use glam::{Mat3, Vec3};

/// Squared-norm threshold below which a quaternion is treated as degenerate (`|q|² < 1e-8`, i.e.
/// `|q| < 1e-4`): [`quat_to_rotation`] returns the identity and [`quat_to_rotation_vjp`] a zero
/// gradient.
///
/// Why this value: the rotation of `q` does not depend on `|q|`, but the gradient with respect to
/// the raw quaternion scales as `1/|q|`, so the threshold caps that amplification at `1e4`. It is
/// far below any quaternion training produces: the gradient of a function of `q/|q|` is orthogonal
/// to `q`, so gradient steps never shrink `|q|` to first order, and BBSplat initialises `|q|` near 1.
/// A quaternion this short is corrupted input, not a training state. Above the threshold the f32
/// normalisation is accurate to a few ulps (the squared norm is at least `1e-8`, far from the
/// subnormal range).
pub const QUAT_NORM_SQ_MIN: f32 = 1e-8;

/// `Some((q/|q|, 1/|q|))`, or `None` for a degenerate or non-finite quaternion.
#[inline]
fn normalise(q: [f32; 4]) -> Option<([f32; 4], f32)> {
    let n2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3];
    // Rejects NaN too; an infinite component (or an overflowing sum) gives n2 = inf.
    if !(QUAT_NORM_SQ_MIN..f32::INFINITY).contains(&n2) {
        return None;
    }
    let inv = 1.0 / n2.sqrt();
    Some((q.map(|c| c * inv), inv))
}

/// The third column of [`quat_to_rotation`] (the billboard's normal in world coordinates),
/// computed in f64 from the same raw quaternion: normalised in f64, with the same degenerate
/// rule (decided in f32, exactly as [`quat_to_rotation`] decides it). For quantities that must
/// not inherit the f32 rounding of the matrix, such as a plane's offset from a distant camera.
#[inline]
pub fn quat_normal_f64(q: [f32; 4]) -> glam::DVec3 {
    if normalise(q).is_none() {
        return glam::DVec3::Z;
    }
    let [w, x, y, z] = q.map(f64::from);
    let inv = 1.0 / (w * w + x * x + y * y + z * z);
    // R(q/|q|) e_z = (2(xz + wy), 2(yz − wx), 1 − 2(x² + y²)) / |q|² for the raw components.
    glam::DVec3::new(
        2.0 * (x * z + w * y) * inv,
        2.0 * (y * z - w * x) * inv,
        1.0 - 2.0 * (x * x + y * y) * inv,
    )
}

/// The rotation matrix of a unit quaternion `[w, x, y, z]` (no normalisation).
#[inline]
fn unit_quat_matrix([w, x, y, z]: [f32; 4]) -> Mat3 {
    let (xx, yy, zz) = (x * x, y * y, z * z);
    let (xy, xz, yz) = (x * y, x * z, y * z);
    let (wx, wy, wz) = (w * x, w * y, w * z);
    Mat3::from_cols(
        Vec3::new(1.0 - 2.0 * (yy + zz), 2.0 * (xy + wz), 2.0 * (xz - wy)),
        Vec3::new(2.0 * (xy - wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz + wx)),
        Vec3::new(2.0 * (xz + wy), 2.0 * (yz - wx), 1.0 - 2.0 * (xx + yy)),
    )
}

/// Rotation matrix of the quaternion `q = [w, x, y, z]`, normalised first.
///
/// The columns are the billboard axes `t_u`, `t_v` and the normal `n` in world coordinates. A
/// quaternion with `|q|² <` [`QUAT_NORM_SQ_MIN`] or a non-finite component gives the identity.
///
/// ```
/// use bbsplat::stages::rotation::quat_to_rotation;
/// use glam::Vec3;
/// // 90° about z, stored with norm 2: t_u = +y, t_v = −x, n = +z.
/// let h = std::f32::consts::FRAC_1_SQRT_2 * 2.0;
/// let r = quat_to_rotation([h, 0.0, 0.0, h]);
/// assert!((r.x_axis - Vec3::Y).length() < 1e-6);
/// assert!((r.y_axis + Vec3::X).length() < 1e-6);
/// assert!((r.z_axis - Vec3::Z).length() < 1e-6);
/// assert_eq!(quat_to_rotation([0.0; 4]), glam::Mat3::IDENTITY);
/// ```
#[inline]
pub fn quat_to_rotation(q: [f32; 4]) -> Mat3 {
    match normalise(q) {
        Some((u, _)) => unit_quat_matrix(u),
        None => Mat3::IDENTITY,
    }
}

/// Backward pass of [`quat_to_rotation`]: given `d_rotation = ∂L/∂R` (same layout as `R`:
/// `d_rotation.col(j)[i] = ∂L/∂R_ij`), returns `∂L/∂q` for the *raw* quaternion, i.e. through the
/// normalisation `q̂ = q/|q|`: `∂L/∂q = (g − q̂·(q̂·g)) / |q|` with `g = ∂L/∂q̂`. The result is
/// orthogonal to `q` (the rotation does not depend on `|q|`).
///
/// Degenerate or non-finite quaternions (see [`QUAT_NORM_SQ_MIN`]) get a zero gradient.
///
/// ```
/// use bbsplat::stages::rotation::quat_to_rotation_vjp;
/// use glam::Mat3;
/// let q = [0.9, 0.3, -0.2, 0.4];
/// let g = quat_to_rotation_vjp(q, Mat3::from_cols_array(&[1.0, 0.5, -0.3, 0.2, -1.0, 0.7, 0.1, 0.4, 0.9]));
/// // No radial component.
/// let radial: f32 = g.iter().zip(q).map(|(a, b)| a * b).sum();
/// assert!(radial.abs() < 1e-5);
/// assert_eq!(quat_to_rotation_vjp([0.0; 4], Mat3::IDENTITY), [0.0; 4]);
/// ```
#[inline]
pub fn quat_to_rotation_vjp(q: [f32; 4], d_rotation: Mat3) -> [f32; 4] {
    let Some((u, inv_norm)) = normalise(q) else {
        return [0.0; 4];
    };
    let [w, x, y, z] = u;
    // g_ij = ∂L/∂R_ij; glam stores columns, so R_ij is col j, component i.
    let (c0, c1, c2) = (d_rotation.x_axis, d_rotation.y_axis, d_rotation.z_axis);
    let (g00, g10, g20) = (c0.x, c0.y, c0.z);
    let (g01, g11, g21) = (c1.x, c1.y, c1.z);
    let (g02, g12, g22) = (c2.x, c2.y, c2.z);
    // ∂L/∂q̂ for R(q̂) as in `unit_quat_matrix`.
    let gw = 2.0 * (x * (g21 - g12) + y * (g02 - g20) + z * (g10 - g01));
    let gx = 2.0 * (y * (g01 + g10) + z * (g02 + g20) + w * (g21 - g12) - 2.0 * x * (g11 + g22));
    let gy = 2.0 * (x * (g01 + g10) + z * (g12 + g21) + w * (g02 - g20) - 2.0 * y * (g00 + g22));
    let gz = 2.0 * (x * (g02 + g20) + y * (g12 + g21) + w * (g10 - g01) - 2.0 * z * (g00 + g11));
    // Through the normalisation: project out the radial part and divide by |q|.
    let radial = w * gw + x * gx + y * gy + z * gz;
    [
        (gw - w * radial) * inv_norm,
        (gx - x * radial) * inv_norm,
        (gy - y * radial) * inv_norm,
        (gz - z * radial) * inv_norm,
    ]
}
