//! Proptest strategies shared by the crate's property tests and usable by other crates.
//!
//! Every strategy generates *well-conditioned* inputs: away from the discontinuities of the
//! method (near plane, grazing rays, texel borders, alpha cut-offs) unless its name says
//! otherwise. Hard cases have their own named tests.
//!
//! ```
//! use bbsplat::strategies;
//! use proptest::prelude::*;
//! use proptest::strategy::ValueTree;
//! use proptest::test_runner::TestRunner;
//! let mut runner = TestRunner::deterministic();
//! let q = strategies::unit_quaternion().new_tree(&mut runner).unwrap().current();
//! let n: f32 = q.iter().map(|c| c * c).sum();
//! assert!((n - 1.0).abs() < 1e-5);
//! ```

use crate::camera::Camera;
use glam::{Vec2, Vec3};
use proptest::prelude::*;

/// The seed every property test of the crate starts from unless `PROPTEST_RNG_SEED` is set.
pub const DEFAULT_PROPTEST_SEED: u64 = 0x00bb_5a1a7;

/// A proptest configuration with `cases` cases and a fixed seed, so that a run is reproducible:
/// the seed is [`DEFAULT_PROPTEST_SEED`], or the value of the environment variable
/// `PROPTEST_RNG_SEED` when set (to explore further seeds). Failure persistence files are not
/// written; a failing case is printed with its inputs and is reproduced by the same seed.
pub fn seeded_config(cases: u32) -> ProptestConfig {
    let seed = std::env::var("PROPTEST_RNG_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(DEFAULT_PROPTEST_SEED);
    ProptestConfig {
        cases,
        rng_seed: proptest::test_runner::RngSeed::Fixed(seed),
        failure_persistence: None,
        ..ProptestConfig::default()
    }
}

/// Position, log-scales and raw quaternion (w, x, y, z) of one billboard.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BillboardPose {
    /// Centre in world coordinates.
    pub position: Vec3,
    /// Natural logarithms of the half side lengths along the two tangent axes.
    pub log_scales: Vec2,
    /// Raw (not necessarily unit) quaternion, order w, x, y, z.
    pub quaternion: [f32; 4],
}

/// Quaternion with norm in `[0.5, 2]` (raw storage is not unit), order w, x, y, z.
pub fn quaternion() -> impl Strategy<Value = [f32; 4]> {
    (unit_quaternion(), 0.5f32..2.0).prop_map(|(q, s)| q.map(|c| c * s))
}

/// Unit quaternion, order w, x, y, z, uniform on the 3-sphere (normalised Gaussian 4-vector).
pub fn unit_quaternion() -> impl Strategy<Value = [f32; 4]> {
    proptest::array::uniform4(-1.0f32..1.0)
        .prop_filter("quaternion too short to normalise", |q| {
            q.iter().map(|c| c * c).sum::<f32>() > 0.05
        })
        .prop_map(|q| {
            let n = q.iter().map(|c| c * c).sum::<f32>().sqrt();
            q.map(|c| c / n)
        })
}

/// Unit direction vector.
pub fn direction() -> impl Strategy<Value = Vec3> {
    proptest::array::uniform3(-1.0f32..1.0)
        .prop_filter("direction too short to normalise", |d| {
            d.iter().map(|c| c * c).sum::<f32>() > 0.05
        })
        .prop_map(|d| Vec3::from_array(d).normalize())
}

/// Texture values strictly inside (0, 1): `ts·ts·channels` texels, layout
/// `[channel][row][column]`.
pub fn texture(ts: usize, channels: usize) -> impl Strategy<Value = Vec<f32>> {
    proptest::collection::vec(0.02f32..0.98, ts * ts * channels)
}

/// Texture-space coordinates `(u, v)` inside the billboard square, at least `margin` (in texel
/// units) away from every texel border, for a texture of size `ts`.
pub fn uv_off_texel_borders(ts: usize, margin: f32) -> impl Strategy<Value = Vec2> {
    let cells = (ts - 1) as u32;
    (0..cells, 0..cells, margin..1.0 - margin, margin..1.0 - margin).prop_map(move |(cx, cy, fx, fy)| {
        let to_uv = |c: u32, f: f32| 2.0 * (c as f32 + f) / (ts - 1) as f32 - 1.0;
        Vec2::new(to_uv(cx, fx), to_uv(cy, fy))
    })
}

/// A camera at a random pose looking at the origin from distance 3-6, 64×48 pixels with
/// `fx = fy = 60`, principal point slightly off-centre (to exercise it).
pub fn camera() -> impl Strategy<Value = Camera> {
    (direction(), 3.0f32..6.0, -2.0f32..2.0, -2.0f32..2.0).prop_filter_map(
        "degenerate up vector",
        |(dir, dist, dcx, dcy)| {
            let up = if dir.y.abs() > 0.9 { Vec3::X } else { Vec3::Y };
            let mut cam = Camera::look_at(dir * dist, Vec3::ZERO, up, 60.0, 60.0, 64, 48);
            cam.cx += dcx;
            cam.cy += dcy;
            Some(cam)
        },
    )
}

/// `n` seeded points uniform in the box `[−half, half]` per axis (a zero half width gives a
/// flat or linear cloud): the test and benchmark point cloud of the initialisation checks.
/// Draws x, y, z of each point in turn from [`crate::rng::Rng::new`]`(seed)`.
pub fn box_cloud(n: usize, seed: u64, half: [f32; 3]) -> Vec<Vec3> {
    let mut rng = crate::rng::Rng::new(seed);
    (0..n)
        .map(|_| {
            Vec3::new(
                rng.range(-half[0], half[0]),
                rng.range(-half[1], half[1]),
                rng.range(-half[2], half[2]),
            )
        })
        .collect()
}

/// The identity-pose test camera: at the origin looking along +z, `width × height` pixels,
/// `fx = fy = width`, principal point at the image centre ([`Camera::identity`]).
pub fn identity_camera(width: u32, height: u32) -> Camera {
    Camera::identity(width, height)
}

/// A billboard in front of `camera`: centre at view depth 2-6 projecting inside the image,
/// half sides 0.05-0.5, and its normal at least 30° away from edge-on as seen from the camera
/// centre (|cos| ≥ 0.5 between the normal and the viewing ray).
pub fn billboard_in_front(camera: Camera) -> impl Strategy<Value = BillboardPose> {
    (
        0.1f32..0.9,
        0.1f32..0.9,
        2.0f32..6.0,
        -3.0f32..-0.7,
        -3.0f32..-0.7,
        quaternion(),
    )
        .prop_filter_map("billboard too close to edge-on", move |(fx, fy, depth, ls0, ls1, q)| {
            let px = fx * camera.width as f32;
            let py = fy * camera.height as f32;
            let view = Vec3::new(
                (px - camera.cx) / camera.fx * depth,
                (py - camera.cy) / camera.fy * depth,
                depth,
            );
            let position = camera.rotation.transpose() * (view - camera.translation);
            let pose = BillboardPose {
                position,
                log_scales: Vec2::new(ls0, ls1),
                quaternion: q,
            };
            let normal = normal_of(q);
            let ray = (position - camera.centre()).normalize();
            (normal.dot(ray).abs() >= 0.5).then_some(pose)
        })
}

/// The third column of the rotation matrix of quaternion `q` (w, x, y, z), i.e. the billboard
/// normal in world coordinates. Used to filter strategies; not a differentiable stage.
fn normal_of(q: [f32; 4]) -> Vec3 {
    let n = q.iter().map(|c| c * c).sum::<f32>().sqrt();
    let [w, x, y, z] = q.map(|c| c / n);
    Vec3::new(
        2.0 * (x * z + w * y),
        2.0 * (y * z - w * x),
        1.0 - 2.0 * (x * x + y * y),
    )
}

/// A point cloud of `n` points with coordinates in `[-scale, scale]`.
pub fn point_cloud(n: std::ops::Range<usize>, scale: f32) -> impl Strategy<Value = Vec<Vec3>> {
    proptest::collection::vec(proptest::array::uniform3(-scale..scale).prop_map(Vec3::from_array), n)
}

/// Alpha values for compositing, kept away from the cut-offs: in `[0.02, 0.95]`.
pub fn alpha() -> impl Strategy<Value = f32> {
    0.02f32..0.95
}

/// Texture-space coordinates `(u, v)` anywhere in the zero-padded support of a bilinear texture
/// of size `ts`: texel coordinates in `(−1, ts)`, i.e. the billboard square plus the one-texel
/// fade band around it, at least `margin` (in texel units) away from every texel border.
pub fn uv_in_support_off_texel_borders(ts: usize, margin: f32) -> impl Strategy<Value = Vec2> {
    // Cells [−1, 0), [0, 1), …, [ts − 1, ts).
    let cells = ts as u32 + 1;
    (0..cells, 0..cells, margin..1.0 - margin, margin..1.0 - margin).prop_map(move |(cx, cy, fx, fy)| {
        let to_uv = |c: u32, f: f32| 2.0 * (c as f32 - 1.0 + f) / (ts - 1) as f32 - 1.0;
        Vec2::new(to_uv(cx, fx), to_uv(cy, fy))
    })
}

/// SH coefficients for all 16 basis functions (`[coeff][rgb]`, 48 values): degree-0 values
/// that put the colour in about `[0.2, 0.8]`, higher bands in `[-0.3, 0.3]`.
pub fn sh_coefficients() -> impl Strategy<Value = Vec<f32>> {
    (
        proptest::collection::vec(-1.0f32..1.0, 3),
        proptest::collection::vec(-0.3f32..0.3, 45),
    )
        .prop_map(|(dc, rest)| dc.into_iter().chain(rest).collect())
}
