//! A 3×4 projection matrix `P = K·[R | t]` taken apart into intrinsics and pose.
//!
//! `P` is defined up to a non-zero scale, its sign included. The left 3×3 block `M = K·R` is
//! factored by an RQ decomposition (Gram-Schmidt on the rows of `M`, from the last row up) into
//! an upper-triangular `K` with a **positive diagonal** and a rotation `R`; a `P` with
//! `det M < 0` is negated first, so that `R` is a proper rotation (`det R = +1`) and every
//! point that `P` maps with a positive third coordinate lies in front of the camera. `K` is then
//! divided by `K[2][2]`, and `t = K⁻¹·p₄` (`p₄` the fourth column, of the same scaled `P`).
//! The pose is world-to-camera with the axes of `P`'s image: x along increasing columns, y along
//! increasing rows, z forward (OpenCV's, the crate's). Computed in f64.
//!
//! ```
//! use bbsplat::scene::projection::decompose_projection;
//! // K = [[100, 0, 50], [0, 120, 40], [0, 0, 1]], R = I, t = (1, 2, 3), scaled by -2.
//! let p = [[-200.0, 0.0, -100.0, -500.0], [0.0, -240.0, -80.0, -720.0], [0.0, 0.0, -2.0, -6.0]];
//! let d = decompose_projection(&p).unwrap();
//! assert!((d.k[0][0] - 100.0).abs() < 1e-9 && (d.k[1][2] - 40.0).abs() < 1e-9);
//! assert!((d.translation[2] - 3.0).abs() < 1e-9);
//! assert!((d.rotation[0][0] - 1.0).abs() < 1e-12);
//! ```

use glam::{DMat3, DVec3};

/// Intrinsics and pose of a projection matrix (rows as arrays, f64).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Decomposed {
    /// Upper-triangular intrinsics, positive diagonal, `k[2][2] = 1`; `k[0][1]` is the skew.
    pub k: [[f64; 3]; 3],
    /// World-to-camera rotation, rows are the camera axes in world coordinates, `det = +1`.
    pub rotation: [[f64; 3]; 3],
    /// World-to-camera translation.
    pub translation: [f64; 3],
}

/// Decomposes the 3×4 projection `p` (rows). See the module documentation.
///
/// # Errors
/// A message when `p` is not finite or its 3×3 block is singular or nearly so
/// (`|det M| < 1e-6 · |m₁|·|m₂|·|m₃|`, the rows `mᵢ`; a real camera's ratio is near 1), or when
/// rounding left the rotation's rows off orthonormal by more than 1e-9.
pub fn decompose_projection(p: &[[f64; 4]; 3]) -> Result<Decomposed, String> {
    if p.iter().flatten().any(|v| !v.is_finite()) {
        return Err("the projection matrix is not finite".into());
    }
    let row = |r: &[f64; 4]| DVec3::new(r[0], r[1], r[2]);
    let (mut m1, mut m2, mut m3) = (row(&p[0]), row(&p[1]), row(&p[2]));
    let mut p4 = DVec3::new(p[0][3], p[1][3], p[2][3]);
    let det = m1.dot(m2.cross(m3));
    let size = m1.length() * m2.length() * m3.length();
    if det.is_nan() || size.is_nan() || det.abs() <= 1e-6 * size {
        return Err(format!(
            "the 3x3 block of the projection matrix is singular or nearly so (determinant {det:e}, \
             {:.1e} of the product of its row lengths)",
            det.abs() / size
        ));
    }
    if det < 0.0 {
        (m1, m2, m3, p4) = (-m1, -m2, -m3, -p4);
    }
    // M = K·R, rows: m3 = k33·r3; m2 = k22·r2 + k23·r3; m1 = k11·r1 + k12·r2 + k13·r3.
    let k33 = m3.length();
    let r3 = m3 / k33;
    let k23 = m2.dot(r3);
    let rest2 = m2 - k23 * r3;
    let k22 = rest2.length();
    let r2 = rest2 / k22;
    let (k13, k12) = (m1.dot(r3), m1.dot(r2));
    let rest1 = m1 - k12 * r2 - k13 * r3;
    let k11 = rest1.length();
    let r1 = rest1 / k11;
    let k_full = DMat3::from_cols(
        DVec3::new(k11, 0.0, 0.0),
        DVec3::new(k12, k22, 0.0),
        DVec3::new(k13, k23, k33),
    );
    let t = k_full.inverse() * p4;
    let k = [
        [k11 / k33, k12 / k33, k13 / k33],
        [0.0, k22 / k33, k23 / k33],
        [0.0, 0.0, 1.0],
    ];
    let out = Decomposed {
        k,
        rotation: [r1.to_array(), r2.to_array(), r3.to_array()],
        translation: t.to_array(),
    };
    if out
        .k
        .iter()
        .flatten()
        .chain(out.translation.iter())
        .any(|v| !v.is_finite())
    {
        return Err("the projection matrix does not decompose into finite intrinsics".into());
    }
    let r = DMat3::from_cols(r1, r2, r3);
    let off = (r.transpose() * r - DMat3::IDENTITY).to_cols_array();
    if off.iter().any(|v| v.is_nan() || v.abs() > 1e-9) {
        return Err("the projection matrix is too ill-conditioned to decompose into a rotation".into());
    }
    Ok(out)
}
