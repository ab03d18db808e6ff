//! OpenCV radial-tangential lens distortion and its iterative inverse.
//!
//! The model acts on *normalised* image coordinates `(x, y) = (X/Z, Y/Z)` of a camera-space
//! point (OpenCV axes: x right, y down, z forward). With `r² = x² + y²`:
//!
//! ```text
//! radial = 1 + k1·r² + k2·r⁴ + k3·r⁶
//! x_d = x·radial + 2·p1·x·y + p2·(r² + 2x²)
//! y_d = y·radial + p1·(r² + 2y²) + 2·p2·x·y
//! ```
//!
//! and the distorted pixel is `(fx·x_d + cx, fy·y_d + cy)`. COLMAP's SIMPLE_RADIAL (`k`),
//! RADIAL (`k1 k2`) and OPENCV (`k1 k2 p1 p2`) models and instant-ngp/nerfstudio's `k1 k2 k3 p1
//! p2` are all this model with the missing coefficients zero.
//!
//! [`Distortion::undistort`] inverts it by Newton's method on the 2×2 system with the analytic
//! Jacobian, started at the distorted point, with step halving when a step does not reduce the
//! residual. It answers `None` when it does not converge to a residual below
//! `1e-12·(1 + |p_d|)` (normalised units) or when the solution lies beyond the invertible part of
//! the model: the radial factor `1 + k1 r² + ...` or the slope of the radial profile
//! `d(r·radial)/dr` is not positive, or the Jacobian determinant is not positive.
//!
//! ```
//! use bbsplat::scene::distortion::Distortion;
//! let d = Distortion { k1: -0.2, k2: 0.05, k3: 0.0, p1: 0.001, p2: -0.002 };
//! let p = d.undistort([0.4, -0.3]).unwrap();
//! let q = d.distort(p);
//! assert!((q[0] - 0.4).abs() < 1e-12 && (q[1] + 0.3).abs() < 1e-12);
//! ```

/// OpenCV radial-tangential distortion coefficients (dimensionless, on normalised coordinates).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Distortion {
    /// Radial coefficient of r².
    pub k1: f64,
    /// Radial coefficient of r⁴.
    pub k2: f64,
    /// Radial coefficient of r⁶.
    pub k3: f64,
    /// First tangential coefficient.
    pub p1: f64,
    /// Second tangential coefficient.
    pub p2: f64,
}

/// Residual (normalised units, relative to `1 + |p_d|`) below which Newton's iteration stops.
const TOLERANCE: f64 = 1e-12;

impl Distortion {
    /// No distortion.
    pub const NONE: Distortion = Distortion {
        k1: 0.0,
        k2: 0.0,
        k3: 0.0,
        p1: 0.0,
        p2: 0.0,
    };

    /// True when every coefficient is zero (a pinhole camera).
    pub fn is_none(&self) -> bool {
        *self == Self::NONE
    }

    /// True when every coefficient is finite.
    pub fn is_finite(&self) -> bool {
        [self.k1, self.k2, self.k3, self.p1, self.p2]
            .iter()
            .all(|v| v.is_finite())
    }

    /// Applies the distortion to normalised coordinates `[x, y]`.
    pub fn distort(&self, p: [f64; 2]) -> [f64; 2] {
        let [x, y] = p;
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        [
            x * radial + 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x),
            y * radial + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y,
        ]
    }

    /// Jacobian `∂(x_d, y_d)/∂(x, y)` as rows.
    pub fn jacobian(&self, p: [f64; 2]) -> [[f64; 2]; 2] {
        let [x, y] = p;
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        // d(radial)/d(r²)
        let g = self.k1 + r2 * (2.0 * self.k2 + 3.0 * self.k3 * r2);
        let cross = 2.0 * x * y * g + 2.0 * self.p1 * x + 2.0 * self.p2 * y;
        [
            [radial + 2.0 * x * x * g + 2.0 * self.p1 * y + 6.0 * self.p2 * x, cross],
            [cross, radial + 2.0 * y * y * g + 6.0 * self.p1 * y + 2.0 * self.p2 * x],
        ]
    }

    /// The undistorted normalised point whose distortion is `pd`, by Newton's method; `None`
    /// when there is no such point on the invertible part of the model.
    pub fn undistort(&self, pd: [f64; 2]) -> Option<[f64; 2]> {
        if !pd[0].is_finite() || !pd[1].is_finite() {
            return None;
        }
        if self.is_none() {
            return Some(pd);
        }
        let residual = |p: [f64; 2]| {
            let d = self.distort(p);
            [d[0] - pd[0], d[1] - pd[1]]
        };
        let norm = |r: [f64; 2]| r[0].hypot(r[1]);
        let tolerance = TOLERANCE * (1.0 + norm(pd));
        let mut p = pd;
        let mut r = residual(p);
        for _ in 0..100 {
            if norm(r) < tolerance {
                break;
            }
            let [[a, b], [c, d]] = self.jacobian(p);
            let det = a * d - b * c;
            if det.is_nan() || det.abs() <= 1e-12 {
                return None;
            }
            let step = [(d * r[0] - b * r[1]) / det, (a * r[1] - c * r[0]) / det];
            // Backtracking: halve the step until the residual decreases.
            let mut t = 1.0;
            loop {
                let q = [p[0] - t * step[0], p[1] - t * step[1]];
                let rq = residual(q);
                if norm(rq) < norm(r) || t < 1e-6 {
                    p = q;
                    r = rq;
                    break;
                }
                t *= 0.5;
            }
            if !p[0].is_finite() || !p[1].is_finite() {
                return None;
            }
        }
        let [[a, b], [c, d]] = self.jacobian(p);
        // On the invertible branch: the radial factor and the radial profile's slope are
        // positive, and the map preserves orientation.
        let r2 = p[0] * p[0] + p[1] * p[1];
        let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        let slope = radial + 2.0 * r2 * (self.k1 + r2 * (2.0 * self.k2 + 3.0 * self.k3 * r2));
        (norm(r) < tolerance && a * d - b * c > 0.0 && radial > 0.0 && slope > 0.0).then_some(p)
    }
}
