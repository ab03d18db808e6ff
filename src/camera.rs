//! Pinhole camera with a world-to-camera pose.
//!
//! Conventions (see `docs/numerics.md`):
//! - World-to-camera pose `p_view = R · p_world + t` with OpenCV/COLMAP camera axes:
//!   x right, y down, z forward (the camera looks along +z).
//! - Intrinsics in pixels: a view-space point (X, Y, Z) projects to pixel coordinates
//!   `(fx·X/Z + cx, fy·Y/Z + cy)`. Pixel `(i, j)` (column i, row j) covers
//!   `[i, i+1) × [j, j+1)` and is evaluated at its centre `(i + 0.5, j + 0.5)`.
//! - The principal point is honoured (the reference implementation forces `(W/2, H/2)`).

use glam::{Mat3, Vec3};

/// A pinhole camera: world-to-camera rotation and translation, intrinsics and image size.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Rotation part `R` of the world-to-camera transform (rows are the camera axes in world
    /// coordinates).
    pub rotation: Mat3,
    /// Translation part `t` of the world-to-camera transform.
    pub translation: Vec3,
    /// Focal length along x, in pixels.
    pub fx: f32,
    /// Focal length along y, in pixels.
    pub fy: f32,
    /// Principal point x, in pixels (from the left image edge).
    pub cx: f32,
    /// Principal point y, in pixels (from the top image edge).
    pub cy: f32,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
}

impl Camera {
    /// The identity-pose camera: centre at the world origin, axes the world axes (looking along
    /// +z, y down), `width × height` pixels, `fx = fy = width` (a 53° horizontal field of
    /// view), principal point at the image centre.
    ///
    /// ```
    /// use bbsplat::camera::Camera;
    /// use glam::Vec3;
    /// let cam = Camera::identity(64, 48);
    /// assert_eq!(cam.project(Vec3::new(0.0, 0.0, 2.0)), Some((32.0, 24.0)));
    /// ```
    pub fn identity(width: u32, height: u32) -> Self {
        Self {
            rotation: Mat3::IDENTITY,
            translation: Vec3::ZERO,
            fx: width as f32,
            fy: width as f32,
            cx: width as f32 * 0.5,
            cy: height as f32 * 0.5,
            width,
            height,
        }
    }

    /// A camera at `eye` looking at `target`, with `up` pointing roughly to the top of the
    /// image, principal point at the image centre.
    ///
    /// ```
    /// use bbsplat::camera::Camera;
    /// use glam::Vec3;
    /// let cam = Camera::look_at(Vec3::new(0.0, 0.0, -4.0), Vec3::ZERO, Vec3::Y, 100.0, 100.0, 64, 48);
    /// let v = cam.world_to_view(Vec3::ZERO);
    /// assert!((v - Vec3::new(0.0, 0.0, 4.0)).length() < 1e-6);
    /// let (x, y) = cam.project(Vec3::ZERO).unwrap();
    /// assert!((x - 32.0).abs() < 1e-4 && (y - 24.0).abs() < 1e-4);
    /// ```
    pub fn look_at(eye: Vec3, target: Vec3, up: Vec3, fx: f32, fy: f32, width: u32, height: u32) -> Self {
        let z = (target - eye).normalize();
        // OpenCV: y points down in the image, so the camera y axis is -up projected.
        let x = z.cross(up).normalize();
        let y = z.cross(x);
        // Rows of R are the camera axes expressed in world coordinates.
        let rotation = Mat3::from_cols(x, y, z).transpose();
        let translation = -(rotation * eye);
        Self {
            rotation,
            translation,
            fx,
            fy,
            cx: width as f32 * 0.5,
            cy: height as f32 * 0.5,
            width,
            height,
        }
    }

    /// Builds a camera from a camera-to-world matrix in OpenGL/Blender axes (x right, y up,
    /// camera looking along -z), as stored in NeRF `transforms.json` files. The y and z axes are
    /// flipped to OpenCV axes and the matrix is inverted.
    ///
    /// `c2w` is given as rows of the 4×4 matrix (only the upper 3×4 block is read).
    #[allow(clippy::too_many_arguments)]
    pub fn from_c2w_opengl(
        c2w_rows: [[f32; 4]; 4],
        fx: f32,
        fy: f32,
        cx: f32,
        cy: f32,
        width: u32,
        height: u32,
    ) -> Self {
        let col = |j: usize| Vec3::new(c2w_rows[0][j], c2w_rows[1][j], c2w_rows[2][j]);
        // OpenGL -> OpenCV: negate the camera y and z axes (columns 1 and 2 of c2w).
        let r_c2w = Mat3::from_cols(col(0), -col(1), -col(2));
        let centre = col(3);
        let rotation = r_c2w.transpose();
        let translation = -(rotation * centre);
        Self {
            rotation,
            translation,
            fx,
            fy,
            cx,
            cy,
            width,
            height,
        }
    }

    /// This camera turned by `rotation` (`ω`, radians, camera axes) about its own centre, its
    /// view frame then shifted by `translation` (`δ`, camera axes, world units), and its focal
    /// lengths multiplied by `focal_scale`: `R_cw → exp([ω]×)·R_cw`, `t → exp([ω]×)·t + δ`
    /// (composed in f64, rounded once). The camera centre moves by `−R'ᵀ·δ`; the principal
    /// point and image size are kept. At `ω = δ = 0` the gradient of a render with respect to
    /// `ω` and `δ` is [`crate::raster::backward::CameraGradient`].
    ///
    /// ```
    /// use bbsplat::camera::Camera;
    /// use glam::Vec3;
    /// let cam = Camera::look_at(Vec3::new(0.0, 0.0, -4.0), Vec3::ZERO, Vec3::Y, 100.0, 100.0, 64, 48);
    /// // Turning about the view axis keeps the centre and the image of the target.
    /// let turned = cam.adjusted(Vec3::new(0.0, 0.0, 0.3), Vec3::ZERO, 1.0);
    /// assert!((turned.centre() - cam.centre()).length() < 1e-5);
    /// assert!(turned.world_to_view(Vec3::ZERO).abs_diff_eq(cam.world_to_view(Vec3::ZERO), 1e-5));
    /// // δ shifts every view point by δ.
    /// let moved = cam.adjusted(Vec3::ZERO, Vec3::new(0.5, 0.0, 0.0), 2.0);
    /// assert!((moved.world_to_view(Vec3::ZERO) - Vec3::new(0.5, 0.0, 4.0)).length() < 1e-6);
    /// assert_eq!(moved.fx, 200.0);
    /// ```
    pub fn adjusted(&self, rotation: Vec3, translation: Vec3, focal_scale: f32) -> Camera {
        let omega = rotation.as_dvec3();
        let angle = omega.length();
        let turn = if angle > 0.0 {
            glam::DMat3::from_axis_angle(omega / angle, angle)
        } else {
            glam::DMat3::IDENTITY
        };
        Camera {
            rotation: (turn * self.rotation.as_dmat3()).as_mat3(),
            translation: (turn * self.translation.as_dvec3() + translation.as_dvec3()).as_vec3(),
            fx: self.fx * focal_scale,
            fy: self.fy * focal_scale,
            ..*self
        }
    }

    /// World point to view (camera) space.
    #[inline]
    pub fn world_to_view(&self, p: Vec3) -> Vec3 {
        self.rotation * p + self.translation
    }

    /// Camera centre in world coordinates, `-Rᵀ t`.
    #[inline]
    pub fn centre(&self) -> Vec3 {
        -(self.rotation.transpose() * self.translation)
    }

    /// `position − centre`, the vector from the camera centre to `position` in the world frame
    /// (the SH view direction before normalisation), computed in f64 and rounded once.
    ///
    /// In f32, a camera centre near 1e4 units is itself rounded by up to 5e-4 and the
    /// subtraction cancels, so a billboard a few units away would see its direction off by about
    /// 1e-4 rad; here the centre `−Rᵀt` and the difference are taken in f64, leaving only the
    /// final rounding of the offset.
    ///
    /// ```
    /// use bbsplat::camera::Camera;
    /// use glam::Vec3;
    /// let eye = Vec3::new(1.0e4, -2.0e4, 3.0e4);
    /// let cam = Camera::look_at(eye, eye + Vec3::new(1.0, 2.0, 3.0), Vec3::Y, 100.0, 100.0, 64, 48);
    /// let p = cam.centre() + Vec3::new(0.25, 0.5, 1.0);
    /// // The camera centre −Rᵀt in f64, and the offset to `p` rounded once.
    /// let centre = -(cam.rotation.as_dmat3().transpose() * cam.translation.as_dvec3());
    /// assert_eq!(cam.view_offset(p), (p.as_dvec3() - centre).as_vec3());
    /// // The f32 subtraction is off by about 1e-3 here.
    /// assert!(((p - cam.centre()).as_dvec3() - (p.as_dvec3() - centre)).length() > 1e-4);
    /// ```
    #[inline]
    pub fn view_offset(&self, position: Vec3) -> Vec3 {
        offset_from(self.centre_f64(), position)
    }

    /// The camera centre `−Rᵀt` in f64 (what [`Camera::view_offset`] subtracts); a caller with
    /// many positions takes it once and calls [`offset_from`].
    #[inline]
    pub fn centre_f64(&self) -> glam::DVec3 {
        -(self.rotation.as_dmat3().transpose() * self.translation.as_dvec3())
    }

    /// Projects a world point to continuous pixel coordinates; `None` when the point is not in
    /// front of the camera (view z ≤ 0).
    pub fn project(&self, p: Vec3) -> Option<(f32, f32)> {
        let v = self.world_to_view(p);
        if v.z <= 0.0 {
            return None;
        }
        Some((self.fx * v.x / v.z + self.cx, self.fy * v.y / v.z + self.cy))
    }

    /// Number of pixels, `width · height`.
    #[inline]
    pub fn pixel_count(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// The same camera for an image scaled by `factor` (e.g. 0.5 for half resolution):
    /// focal lengths and principal point scale exactly, sizes are `round(size · factor)`.
    pub fn scaled(&self, factor: f32) -> Self {
        let w = ((self.width as f32) * factor).round().max(1.0) as u32;
        let h = ((self.height as f32) * factor).round().max(1.0) as u32;
        // Scale by the actual size ratio so that the image edges stay where they were.
        let sx = w as f32 / self.width as f32;
        let sy = h as f32 / self.height as f32;
        Self {
            fx: self.fx * sx,
            fy: self.fy * sy,
            cx: self.cx * sx,
            cy: self.cy * sy,
            width: w,
            height: h,
            ..*self
        }
    }
}

/// `position − centre` in f64, rounded once: [`Camera::view_offset`] with the f64 centre
/// ([`Camera::centre_f64`]) taken once for many positions.
#[inline]
pub fn offset_from(centre: glam::DVec3, position: Vec3) -> Vec3 {
    (position.as_dvec3() - centre).as_vec3()
}

/// The least-squares point nearest to the lines `o + t·d` given as `(o, d)` with unit `d`: the
/// solution of `Σ(I − ddᵀ)·x = Σ(I − ddᵀ)·o`, in f64. `None` when the lines are (nearly)
/// parallel (the system's determinant at most `1e-6·n³` for `n` lines) or there are none. With
/// optical axes (camera centre, viewing direction) it is what the cameras look at.
///
/// ```
/// use glam::DVec3;
/// let lines = [(DVec3::new(-1.0, 0.0, 0.0), DVec3::X), (DVec3::new(0.0, 5.0, 1.0), DVec3::NEG_Y)];
/// let p = bbsplat::camera::nearest_to_lines(lines).unwrap();
/// assert!((p - DVec3::new(0.0, 0.0, 0.5)).length() < 1e-12);
/// ```
pub fn nearest_to_lines(lines: impl IntoIterator<Item = (glam::DVec3, glam::DVec3)>) -> Option<glam::DVec3> {
    use glam::{DMat3, DVec3};
    let (mut a, mut b, mut n) = (DMat3::ZERO, DVec3::ZERO, 0usize);
    for (o, d) in lines {
        let proj = DMat3::IDENTITY - DMat3::from_cols(d * d.x, d * d.y, d * d.z);
        a += proj;
        b += proj * o;
        n += 1;
    }
    (n > 0 && a.determinant().abs() > 1e-6 * n.pow(3) as f64).then(|| a.inverse() * b)
}
