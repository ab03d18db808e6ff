//! A circular camera path around a scene, placed from its dataset cameras (for `bbsplat render
//! --orbit`).
//!
//! - Target: the point nearest, in least squares, to every camera's optical axis (the point the
//!   cameras look at); the mean camera centre if the axes are all parallel.
//! - Up: the mean of the cameras' up vectors (−y of the OpenCV camera axes).
//! - The circle lies in the plane perpendicular to up, at the cameras' mean height above the
//!   target and their mean horizontal distance from it, starting at the first camera's azimuth
//!   and turning counter-clockwise about up. Intrinsics are the first camera's, with the
//!   principal point at the image centre.

use super::ExportError;
use crate::camera::Camera;
use glam::{DMat3, DVec3, Vec3};

/// The target point of `cameras` (see the module documentation).
pub fn look_target(cameras: &[Camera]) -> Option<Vec3> {
    let mut a = DMat3::ZERO;
    let mut b = DVec3::ZERO;
    for cam in cameras {
        let d = cam.rotation.row(2).as_dvec3().normalize();
        let c = cam.centre_f64();
        let p = DMat3::IDENTITY - DMat3::from_cols(d * d.x, d * d.y, d * d.z);
        a += p;
        b += p * c;
    }
    if cameras.is_empty() {
        return None;
    }
    // Parallel axes leave `a` singular (rank 2): fall back to the mean centre.
    let det = a.determinant();
    let scale = a.x_axis.length() * a.y_axis.length() * a.z_axis.length();
    if det.abs() > 1e-9 * scale.max(f64::MIN_POSITIVE) {
        Some((a.inverse() * b).as_vec3())
    } else {
        let mean = cameras.iter().map(|c| c.centre_f64()).sum::<DVec3>() / cameras.len() as f64;
        Some(mean.as_vec3())
    }
}

/// `frames` cameras on the orbit of `cameras` (see the module documentation).
///
/// ```
/// use bbsplat::camera::Camera;
/// use bbsplat::export::orbit::orbit_cameras;
/// use glam::Vec3;
/// // Four cameras on a circle of radius 4 around the origin, looking at it, z up.
/// let cams: Vec<Camera> = (0..4)
///     .map(|k| {
///         let a = k as f32 * std::f32::consts::FRAC_PI_2;
///         Camera::look_at(Vec3::new(4.0 * a.cos(), 4.0 * a.sin(), 1.0), Vec3::ZERO, Vec3::Z, 50.0, 50.0, 64, 48)
///     })
///     .collect();
/// let orbit = orbit_cameras(&cams, 8).unwrap();
/// assert_eq!(orbit.len(), 8);
/// assert!((orbit[0].centre() - cams[0].centre()).length() < 1e-3);
/// assert!((orbit[2].centre() - cams[1].centre()).length() < 1e-3);
/// ```
pub fn orbit_cameras(cameras: &[Camera], frames: usize) -> Result<Vec<Camera>, ExportError> {
    let first = cameras.first().ok_or(ExportError::NoOrbitCamera)?;
    if frames == 0 {
        return Err(ExportError::NoOrbitCamera);
    }
    let target = look_target(cameras).ok_or(ExportError::NoOrbitCamera)?;
    let up_sum: Vec3 = cameras.iter().map(|c| -c.rotation.row(1)).sum();
    let up = up_sum.try_normalize().unwrap_or(-first.rotation.row(1));
    let n = cameras.len() as f32;
    let offsets: Vec<Vec3> = cameras.iter().map(|c| c.centre() - target).collect();
    let height = offsets.iter().map(|o| o.dot(up)).sum::<f32>() / n;
    let radius = offsets.iter().map(|o| (*o - o.dot(up) * up).length()).sum::<f32>() / n;
    // Azimuth basis: e1 towards the first camera (or any direction perpendicular to up).
    let towards_first = offsets[0] - offsets[0].dot(up) * up;
    let e1 = towards_first
        .try_normalize()
        .unwrap_or_else(|| up.any_orthonormal_vector());
    let e2 = up.cross(e1);
    Ok((0..frames)
        .map(|k| {
            let angle = std::f32::consts::TAU * k as f32 / frames as f32;
            let eye = target + height * up + radius * (angle.cos() * e1 + angle.sin() * e2);
            Camera::look_at(eye, target, up, first.fx, first.fy, first.width, first.height)
        })
        .collect())
}
