//! The ground frame of a capture: the up direction its cameras agree on, and the two horizontal
//! axes along which their centres spread most (`along`) and least (`across`).
//!
//! Up is the mean of the cameras' up vectors (minus each camera's y axis: the crate's cameras
//! are OpenCV's, y down), normalised; when those cancel out (a mean shorter than 0.1, cameras
//! rolled every way), world +y. Cameras pitched alike tilt it by their pitch (one track of
//! cameras looking down 14° gives an up 14° off); cameras facing each other, or level ones,
//! do not. `along` is the principal axis of the camera centres projected
//! onto the plane perpendicular to up (the eigenvector of the larger eigenvalue of their 2×2
//! covariance, in f64), signed so that its largest component is positive; `across = up × along`.
//! The origin is the mean camera centre. A point's ground coordinates are its offsets from the
//! origin along `along` and `across`.
//!
//! ```
//! use bbsplat::blocks::GroundFrame;
//! use bbsplat::camera::Camera;
//! use glam::Vec3;
//! // Cameras on a track along x at height 1, looking at -z.
//! let cams: Vec<Camera> = (0..5)
//!     .map(|i| {
//!         let eye = Vec3::new(i as f32, 1.0, 3.0);
//!         Camera::look_at(eye, eye - Vec3::Z, Vec3::Y, 50.0, 50.0, 8, 8)
//!     })
//!     .collect();
//! let frame = GroundFrame::from_cameras(&cams).unwrap();
//! assert!((frame.up - Vec3::Y).length() < 1e-5);
//! assert!((frame.along - Vec3::X).length() < 1e-5);
//! let q = frame.project(Vec3::new(4.0, 7.0, 3.0));
//! assert!((q.x - 2.0).abs() < 1e-5 && q.y.abs() < 1e-5);
//! ```

use crate::camera::Camera;
use glam::{DVec3, Vec2, Vec3};
use serde::{Deserialize, Serialize};

/// The frame (module docs). Unit vectors, `along ⟂ up`, `across = up × along`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct GroundFrame {
    /// The mean camera centre (world).
    pub origin: Vec3,
    /// Up (world).
    pub up: Vec3,
    /// The horizontal axis the camera centres spread most along.
    pub along: Vec3,
    /// `up × along`.
    pub across: Vec3,
}

impl GroundFrame {
    /// The frame of `cameras` (module docs); `None` when there is none.
    pub fn from_cameras<'a>(cameras: impl IntoIterator<Item = &'a Camera>) -> Option<Self> {
        let cameras: Vec<&Camera> = cameras.into_iter().collect();
        if cameras.is_empty() {
            return None;
        }
        let n = cameras.len() as f64;
        let mean_up: DVec3 = cameras.iter().map(|c| -c.rotation.row(1).as_dvec3()).sum::<DVec3>() / n;
        let up = if mean_up.length() > 0.1 {
            mean_up.normalize()
        } else {
            DVec3::Y
        };
        let origin: DVec3 = cameras.iter().map(|c| c.centre_f64()).sum::<DVec3>() / n;
        // Two unit vectors spanning the plane perpendicular to up.
        let u = up.any_orthonormal_vector();
        let v = up.cross(u);
        let (mut cuu, mut cuv, mut cvv) = (0.0, 0.0, 0.0);
        for c in &cameras {
            let d = c.centre_f64() - origin;
            let (a, b) = (d.dot(u), d.dot(v));
            cuu += a * a;
            cuv += a * b;
            cvv += b * b;
        }
        // The principal axis of [[cuu, cuv], [cuv, cvv]].
        let theta = 0.5 * (2.0 * cuv).atan2(cuu - cvv);
        let mut along = u * theta.cos() + v * theta.sin();
        let largest = along.abs().max_element();
        let sign = if along.x.abs() == largest {
            along.x
        } else if along.y.abs() == largest {
            along.y
        } else {
            along.z
        };
        if sign < 0.0 {
            along = -along;
        }
        let across = up.cross(along);
        Some(Self {
            origin: origin.as_vec3(),
            up: up.as_vec3(),
            along: along.as_vec3(),
            across: across.as_vec3(),
        })
    }

    /// The frame with its ground axes turned by `degrees` about up (counter-clockwise seen from
    /// above: `along` turns towards `across`), for a grid that the cameras' main spread does not
    /// align well (`bbsplat blocks split --turn`). Computed in f64; `up` and the origin are kept.
    ///
    /// ```
    /// use bbsplat::blocks::GroundFrame;
    /// use glam::Vec3;
    /// let frame = GroundFrame { origin: Vec3::ZERO, up: Vec3::Y, along: Vec3::X, across: Vec3::NEG_Z };
    /// let turned = frame.turned(90.0);
    /// assert!((turned.along - Vec3::NEG_Z).length() < 1e-6 && (turned.across - Vec3::NEG_X).length() < 1e-6);
    /// ```
    pub fn turned(&self, degrees: f32) -> Self {
        let (sin, cos) = (degrees as f64).to_radians().sin_cos();
        let (up, along, across) = (self.up.as_dvec3(), self.along.as_dvec3(), self.across.as_dvec3());
        let turned = (along * cos + across * sin).normalize();
        Self {
            along: turned.as_vec3(),
            across: up.cross(turned).as_vec3(),
            ..*self
        }
    }

    /// Ground coordinates of `p`: its offsets from the origin along `along` and `across`.
    pub fn project(&self, p: Vec3) -> Vec2 {
        let d = p - self.origin;
        Vec2::new(d.dot(self.along), d.dot(self.across))
    }
}
