//! Seeded scenes for the f64 reference tests: a rotated, translated camera and billboards placed
//! in its view, built with this module's own f64 geometry (no crate helper).

use super::renderer::{V3, rotation_columns};
use bbsplat::billboards::ActivatedBillboards;
use bbsplat::camera::Camera;
use bbsplat::raster::RenderSettings;
use bbsplat::rng::Rng;
use bbsplat::stages::composite::CompositeParams;
use glam::{Mat3, Vec2, Vec3};

/// Hamilton product of quaternions `[w, x, y, z]`.
pub fn qmul(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    [
        a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
        a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
        a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
        a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
    ]
}

fn normalise(q: [f64; 4]) -> [f64; 4] {
    let n = q.iter().map(|c| c * c).sum::<f64>().sqrt();
    q.map(|c| c / n)
}

/// A camera whose world-to-view rotation is the rotation of quaternion `q` (normalised) and
/// whose centre is `eye`; intrinsics `f`, principal point at the image centre.
pub fn camera(q: [f64; 4], eye: V3, f: f32, width: u32, height: u32) -> Camera {
    let cols = rotation_columns(q);
    let rot = Mat3::from_cols(
        Vec3::from_array(cols[0].map(|x| x as f32)),
        Vec3::from_array(cols[1].map(|x| x as f32)),
        Vec3::from_array(cols[2].map(|x| x as f32)),
    );
    // t = −R·eye, with R read back from its f32 entries, accumulated in f64.
    let r = rot.to_cols_array_2d();
    let t: [f32; 3] = std::array::from_fn(|i| -(0..3).map(|k| r[k][i] as f64 * eye[k]).sum::<f64>() as f32);
    Camera {
        rotation: rot,
        translation: Vec3::from_array(t),
        fx: f,
        fy: f,
        cx: width as f32 * 0.5,
        cy: height as f32 * 0.5,
        width,
        height,
    }
}

/// How billboards are oriented relative to the camera.
#[derive(Clone, Copy, Debug)]
pub enum Facing {
    /// Uniformly random rotations (some seen nearly edge-on).
    Uniform,
    /// Normals within about `tilt` (quaternion x, y components up to `tilt`) of the view axis,
    /// any in-plane rotation.
    Towards(f64),
}

/// Parameters of [`scene`].
#[derive(Clone, Copy, Debug)]
pub struct Spec {
    pub n: usize,
    pub width: u32,
    pub height: u32,
    pub ts: usize,
    /// Side of a billboard seen face-on, in pixels.
    pub footprint: f64,
    /// View depths of the centres, drawn uniformly.
    pub depth: (f64, f64),
    /// Alpha texels drawn uniformly in this range.
    pub alpha: (f32, f32),
    pub facing: Facing,
    pub sh_degree: u32,
    pub seed: u64,
    /// The camera's world position (large values place the whole scene far from the origin).
    pub eye: V3,
}

impl Spec {
    pub fn new(n: usize, size: u32, ts: usize, seed: u64) -> Self {
        Self {
            n,
            width: size,
            height: size,
            ts,
            footprint: size as f64 / 4.0,
            depth: (2.0, 8.0),
            alpha: (0.0, 1.0),
            facing: Facing::Uniform,
            sh_degree: 3,
            seed,
            eye: [0.4, -0.3, -1.0],
        }
    }
}

/// The camera of a [`Spec`]: rotated by a fixed non-trivial quaternion, focal length the image
/// width.
pub fn spec_camera(spec: &Spec) -> Camera {
    camera(
        [0.9, 0.15, -0.3, 0.2],
        spec.eye,
        spec.width as f32,
        spec.width,
        spec.height,
    )
}

/// Random billboards in the view of [`spec_camera`] and the render settings (training
/// thresholds, a seeded background, the spec's SH degree).
pub fn scene(spec: &Spec) -> (ActivatedBillboards, Camera, RenderSettings) {
    let cam = spec_camera(spec);
    let mut rng = Rng::new(spec.seed);
    let r = cam.rotation.to_cols_array_2d(); // r[col][row]
    let eye = spec.eye;
    // Quaternion of the camera rotation, for composing view-space orientations.
    let q_cam = normalise([0.9, 0.15, -0.3, 0.2]);
    let q_cam_inv = [q_cam[0], -q_cam[1], -q_cam[2], -q_cam[3]];
    let ts = spec.ts;
    let mut b = ActivatedBillboards::empty(ts);
    for _ in 0..spec.n {
        let x = rng.uniform_f64() * spec.width as f64;
        let y = rng.uniform_f64() * spec.height as f64;
        let z = spec.depth.0 + (spec.depth.1 - spec.depth.0) * rng.uniform_f64();
        let f = cam.fx as f64;
        let view = [(x - cam.cx as f64) / f * z, (y - cam.cy as f64) / cam.fy as f64 * z, z];
        // world = Rᵀ·view + eye.
        let world: [f64; 3] = std::array::from_fn(|k| (0..3).map(|i| r[k][i] as f64 * view[i]).sum::<f64>() + eye[k]);
        b.positions.push(Vec3::from_array(world.map(|c| c as f32)));
        let q_view = match spec.facing {
            Facing::Uniform => [rng.normal(), rng.normal(), rng.normal(), rng.normal()].map(f64::from),
            Facing::Towards(tilt) => {
                let a = rng.range(-1.0, 1.0) as f64;
                [
                    1.0,
                    tilt * rng.range(-1.0, 1.0) as f64,
                    tilt * rng.range(-1.0, 1.0) as f64,
                    a,
                ]
            }
        };
        // A billboard with rotation R_view in view space has R_world = R_camᵀ·R_view.
        let q = qmul(q_cam_inv, normalise(q_view));
        b.quaternions.push(q.map(|c| c as f32));
        let s = spec.footprint * z / (2.0 * f);
        let jitter = [rng.range(-0.2, 0.2), rng.range(-0.2, 0.2)];
        b.log_scales
            .push(Vec2::new(s.ln() as f32 + jitter[0], s.ln() as f32 + jitter[1]));
        for k in 0..48 {
            b.sh.push(if k < 3 {
                rng.range(-0.5, 0.5)
            } else {
                rng.range(-0.15, 0.15)
            });
        }
        for _ in 0..ts * ts {
            b.textures.push([
                rng.uniform(),
                rng.uniform(),
                rng.uniform(),
                rng.range(spec.alpha.0, spec.alpha.1),
            ]);
        }
    }
    let background = Vec3::new(rng.uniform(), rng.uniform(), rng.uniform());
    let settings = RenderSettings {
        background,
        sh_degree: spec.sh_degree,
        composite: CompositeParams::default(),
        distortion: false,
        ..RenderSettings::default()
    };
    (b, cam, settings)
}

/// Quaternion of the rotation by `angle` about the unit `axis`.
pub fn axis_angle(axis: V3, angle: f64) -> [f64; 4] {
    let (s, c) = (0.5 * angle).sin_cos();
    [c, s * axis[0], s * axis[1], s * axis[2]]
}

/// Places billboards given in view space of a [`spec_camera`]-style camera.
pub struct Placer {
    r: [[f32; 3]; 3],
    eye: V3,
    q_cam_inv: [f64; 4],
}

impl Placer {
    /// For a camera built by [`camera`] with quaternion `q` and centre `eye`.
    pub fn new(cam: &Camera, q: [f64; 4], eye: V3) -> Self {
        let q = normalise(q);
        Self {
            r: cam.rotation.to_cols_array_2d(),
            eye,
            q_cam_inv: [q[0], -q[1], -q[2], -q[3]],
        }
    }

    /// World position and quaternion of a billboard with view-space centre `view` and
    /// view-space rotation `q_view`.
    pub fn place(&self, view: V3, q_view: [f64; 4]) -> (Vec3, [f32; 4]) {
        let world: [f64; 3] =
            std::array::from_fn(|k| (0..3).map(|i| self.r[k][i] as f64 * view[i]).sum::<f64>() + self.eye[k]);
        let q = qmul(self.q_cam_inv, normalise(q_view));
        (Vec3::from_array(world.map(|c| c as f32)), q.map(|c| c as f32))
    }
}

/// Appends one billboard with seeded random SH and textures (alpha texels in `alpha`).
pub fn push_random(
    b: &mut ActivatedBillboards,
    pos: Vec3,
    q: [f32; 4],
    log_scales: Vec2,
    alpha: (f32, f32),
    rng: &mut Rng,
) {
    b.positions.push(pos);
    b.quaternions.push(q);
    b.log_scales.push(log_scales);
    for k in 0..48 {
        b.sh.push(if k < 3 {
            rng.range(-0.5, 0.5)
        } else {
            rng.range(-0.15, 0.15)
        });
    }
    for _ in 0..b.texture_size * b.texture_size {
        b.textures
            .push([rng.uniform(), rng.uniform(), rng.uniform(), rng.range(alpha.0, alpha.1)]);
    }
}
