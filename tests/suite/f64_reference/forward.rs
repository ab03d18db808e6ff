//! Forward: the crate's `raster::render` against the f64 reference, relative L2 per image.
//!
//! Each tolerance is written next to the worst error measured on this test's cases
//! (`cargo test --test suite f64_reference::forward -- --nocapture` prints them); tolerances are
//! at most 10× the measured worst.

use super::renderer::{Cam64, Scene64, V3, cross, dot, rotation_columns};
use super::scenes::{Facing, Placer, Spec, axis_angle, camera, push_random, qmul, scene};
use super::{ImageErrors, both, image_errors};
use bbsplat::billboards::ActivatedBillboards;
use bbsplat::camera::Camera;
use bbsplat::raster::RenderSettings;
use bbsplat::rng::Rng;
use bbsplat::stages::composite::CompositeParams;
use glam::{Mat3, Vec2, Vec3};

/// Renders with both renderers, prints the errors and returns them.
fn errors_of(name: &str, b: &ActivatedBillboards, cam: &Camera, s: &RenderSettings) -> ImageErrors {
    let (out, img) = both(b, cam, s);
    let e = image_errors(&out, &img);
    eprintln!(
        "f64_reference {name}: rel L2 rgb {:.2e} alpha {:.2e} depth {:.2e}",
        e.rgb, e.alpha, e.depth
    );
    e
}

/// Random scenes: 20-500 billboards, texture sizes 2-16, SH degrees 0-3, random backgrounds,
/// uniformly random rotations and alpha texels over `[0, 1]` (so the clamp, the cut-off and the
/// stop all occur), images 24-64 px, rotated camera.
///
/// Tolerance 1.5e-5 on each image; measured worst over the 12 scenes 3.0e-6 (scene 9, 150
/// billboards, TS 16; most scenes 1e-7 to 6e-7).
#[test]
fn random_scenes_match() {
    const TOL: f64 = 1.5e-5;
    let counts = [20, 45, 80, 150, 300, 500];
    let sizes = [24, 32, 40, 48, 56, 64];
    let texture_sizes = [2, 3, 4, 8, 16];
    let mut worst = 0.0f64;
    for k in 0..12usize {
        let mut spec = Spec::new(counts[k % 6], sizes[(k * 5) % 6], texture_sizes[k % 5], 1000 + k as u64);
        spec.sh_degree = (k % 4) as u32;
        spec.footprint = spec.width as f64 * [0.15, 0.3, 0.6][k % 3];
        let (b, cam, s) = scene(&spec);
        let e = errors_of(&format!("random scene {k} ({spec:?})"), &b, &cam, &s);
        worst = worst.max(e.max());
        assert!(e.max() <= TOL, "scene {k}: {e:?}");
    }
    eprintln!("f64_reference random scenes: worst rel L2 {worst:.2e}");
}

/// The camera quaternion and eye of the hard cases.
const Q_CAM: [f64; 4] = [0.9, 0.15, -0.3, 0.2];
const EYE: V3 = [0.4, -0.3, -1.0];

fn normalised(v: V3) -> V3 {
    let n = dot(v, v).sqrt();
    v.map(|c| c / n)
}

/// The view-space rotation whose normal (third column) is `n` (unit), spun by `spin` about it.
pub(super) fn rotation_with_normal(n: V3, spin: f64) -> [f64; 4] {
    let z = [0.0, 0.0, 1.0];
    let axis = cross(z, n);
    let s = dot(axis, axis).sqrt();
    let align = if s < 1e-12 {
        [1.0, 0.0, 0.0, 0.0]
    } else {
        axis_angle(axis.map(|c| c / s), n[2].clamp(-1.0, 1.0).acos())
    };
    qmul(align, axis_angle(z, spin))
}

fn hard_settings(rng: &mut Rng) -> RenderSettings {
    RenderSettings {
        background: Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()),
        sh_degree: 3,
        composite: CompositeParams::default(),
        distortion: false,
        ..RenderSettings::default()
    }
}

/// Grazing planes: billboards whose normal makes 80° to 89.99° with the ray through their
/// centre (seen nearly edge-on, thin slivers a few pixels long), on top of a few face-on ones.
///
/// Tolerance 1e-4; measured worst 2.6e-5 (rgb; the f32 hit of rays within a fraction of a
/// degree of the plane).
#[test]
fn hard_case_grazing_planes() {
    const TOL: f64 = 1e-4;
    let (w, h) = (48, 40);
    let cam = camera(Q_CAM, EYE, 48.0, w, h);
    let placer = Placer::new(&cam, Q_CAM, EYE);
    let mut rng = Rng::new(7);
    let mut b = ActivatedBillboards::empty(8);
    let margins_deg: [f64; 8] = [10.0, 5.0, 2.0, 1.0, 0.5, 0.1, 0.01, 0.001];
    for (k, m) in margins_deg.iter().enumerate() {
        for rep in 0..3 {
            let z = 2.5 + 0.37 * k as f64 + 0.11 * rep as f64;
            let p = [
                (rng.uniform_f64() - 0.5) * 0.7 * z,
                (rng.uniform_f64() - 0.5) * 0.6 * z,
                z,
            ];
            let d = normalised(p);
            let e = normalised(cross(d, [rng.uniform_f64() - 0.5, 1.0, rng.uniform_f64() - 0.5]));
            let theta = (90.0 - m).to_radians();
            let n: V3 = std::array::from_fn(|i| theta.cos() * d[i] + theta.sin() * e[i]);
            let (pos, q) = placer.place(p, rotation_with_normal(n, rng.uniform_f64() * 6.0));
            let s = (0.4 * z).ln() as f32;
            push_random(&mut b, pos, q, Vec2::new(s, s - 0.5), (0.2, 1.0), &mut rng);
        }
    }
    // A few face-on billboards behind them.
    for k in 0..4 {
        let p = [-0.8 + 0.5 * k as f64, 0.2 * k as f64 - 0.3, 9.0 + k as f64];
        let (pos, q) = placer.place(p, [1.0, 0.05, -0.03, 0.3 * k as f64]);
        push_random(&mut b, pos, q, Vec2::splat(0.9f32.ln()), (0.3, 1.0), &mut rng);
    }
    let s = hard_settings(&mut rng);
    let e = errors_of("grazing planes", &b, &cam, &s);
    assert!(e.max() <= TOL, "{e:?}");
}

/// Edge-on: the camera centre lies exactly in the plane of two billboards (culled by both: the
/// crate culls `cos θ = 0`, which the exact permutation quaternion and identity camera make
/// exact in f32), a large plane 0.05 above the camera seen at 0.5°-10° (a floor), and
/// face-on billboards so the image is not empty.
///
/// Tolerance 2.5e-6; measured worst 4.7e-7.
#[test]
fn hard_case_edge_on_and_floor() {
    const TOL: f64 = 2.5e-6;
    let (w, h) = (40, 32);
    let cam = Camera {
        rotation: Mat3::IDENTITY,
        translation: Vec3::ZERO,
        fx: 32.0,
        fy: 32.0,
        cx: 20.0,
        cy: 16.0,
        width: w,
        height: h,
    };
    let mut rng = Rng::new(11);
    let mut b = ActivatedBillboards::empty(4);
    // Normal (0, 1, 0), t_u = (0, 0, 1), t_v = (1, 0, 0): exactly representable.
    let floor_q = [0.5, -0.5, -0.5, -0.5];
    push_random(
        &mut b,
        Vec3::new(0.0, 0.0, 3.0),
        floor_q,
        Vec2::ZERO,
        (0.5, 1.0),
        &mut rng,
    );
    push_random(
        &mut b,
        Vec3::new(0.7, 0.0, 5.0),
        floor_q,
        Vec2::ZERO,
        (0.5, 1.0),
        &mut rng,
    );
    // The floor: plane y = 0.05, half sides 3 (depth) and 2 (width), centre at depth 4.
    push_random(
        &mut b,
        Vec3::new(0.0, 0.05, 4.0),
        floor_q,
        Vec2::new(3.0f32.ln(), 2.0f32.ln()),
        (0.2, 1.0),
        &mut rng,
    );
    for k in 0..3 {
        let pos = Vec3::new(-1.0 + 0.9 * k as f32, -0.4, 6.0 + k as f32);
        push_random(
            &mut b,
            pos,
            [1.0, 0.0, 0.0, 0.2],
            Vec2::splat(0.7f32.ln()),
            (0.3, 1.0),
            &mut rng,
        );
    }
    let s = hard_settings(&mut rng);
    let (out, img) = both(&b, &cam, &s);
    assert!(
        !out.visible[0] && !out.visible[1],
        "camera-in-plane billboards must be culled"
    );
    let e = errors_of("edge-on and floor", &b, &cam, &s);
    assert!(e.max() <= TOL, "{e:?}");
    // The floor is seen: some pixel below the horizon has its depth.
    assert!(
        img.alpha
            .iter()
            .skip(w as usize * (h as usize / 2 + 1))
            .any(|&a| a > 0.1)
    );
}

/// Billboards crossing the camera plane: half sides 2-6 world units, centres at view depth
/// 0.6-2.5, normals 50°-85° from the view axis, so parts of the squares lie behind the camera
/// and the near plane cuts them.
///
/// Tolerance 1e-6; measured worst 2.1e-7.
#[test]
fn hard_case_crossing_the_camera_plane() {
    const TOL: f64 = 1e-6;
    let (w, h) = (40, 40);
    let cam = camera(Q_CAM, EYE, 36.0, w, h);
    let placer = Placer::new(&cam, Q_CAM, EYE);
    let mut rng = Rng::new(13);
    let mut b = ActivatedBillboards::empty(6);
    for k in 0..10 {
        let z = 0.6 + 0.19 * k as f64;
        let p = [(rng.uniform_f64() - 0.5) * z, (rng.uniform_f64() - 0.5) * z, z];
        let tilt = (50.0 + 3.5 * k as f64).to_radians();
        let phi = rng.uniform_f64() * std::f64::consts::TAU;
        let n = [tilt.sin() * phi.cos(), tilt.sin() * phi.sin(), tilt.cos()];
        let (pos, q) = placer.place(p, rotation_with_normal(n, rng.uniform_f64() * 6.0));
        let s = (2.0 + 0.45 * k as f64).ln() as f32;
        push_random(&mut b, pos, q, Vec2::new(s, s - 0.3), (0.05, 0.6), &mut rng);
    }
    // The case is what it says: some support squares reach behind the camera.
    let (scene64, cam64) = (Scene64::of(&b, &RenderSettings::default()), Cam64::of(&cam));
    let behind = (0..b.len())
        .filter(|&i| {
            let [tu, tv, _] = rotation_columns(scene64.quat[i]);
            let (a, bb) = (cam64.rotate(tu), cam64.rotate(tv));
            let c = cam64.rotate(scene64.pos[i])[2] + cam64.t[2];
            let (su, sv) = (scene64.log_scale[i][0].exp(), scene64.log_scale[i][1].exp());
            [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
                .iter()
                .any(|(u, v)| c + u * su * a[2] + v * sv * bb[2] < 0.0)
        })
        .count();
    assert!(behind >= 5, "only {behind} billboards cross the camera plane");
    let s = hard_settings(&mut rng);
    let e = errors_of("crossing the camera plane", &b, &cam, &s);
    assert!(e.max() <= TOL, "{e:?}");
}

/// Stacks of 20, 50 and 100 near-opaque layers (alpha texels in [0.9, 1], so many clamped at
/// 0.99 and most pixels stopped by the transmittance threshold) and one stack of 60 layers with
/// alpha in [0.2, 0.5] (the stop reached after ~20-40 layers), all covering the image.
///
/// Tolerance 1e-6; measured worst 1.4e-7.
#[test]
fn hard_case_stacked_layers() {
    const TOL: f64 = 1e-6;
    for (k, (n, alpha)) in [(20, (0.9, 1.0)), (50, (0.9, 1.0)), (100, (0.9, 1.0)), (60, (0.2, 0.5))]
        .into_iter()
        .enumerate()
    {
        let mut spec = Spec::new(n, 32, 4, 300 + k as u64);
        spec.alpha = alpha;
        spec.facing = Facing::Towards(0.15);
        spec.footprint = 80.0;
        spec.depth = (2.0, 6.0);
        let (b, cam, s) = scene(&spec);
        let e = errors_of(&format!("{n} stacked layers, alpha {alpha:?}"), &b, &cam, &s);
        assert!(e.max() <= TOL, "{n} layers: {e:?}");
    }
}

/// Positions near 1e3 and 1e4 with a rotated camera (the scene a few units in front of it).
/// The crate takes the SH view direction in f32 (`position − camera.centre()` with the centre
/// rebuilt from `R`, `t` in f32), which is a float32 effect of ~1e-4 in colour at 1e4 (see
/// `float32_effects`); the f64 reference reads the same f32 inputs.
///
/// Tolerance 1e-4; measured worst 1.9e-5 (rgb at 1e4, the SH view direction; 1.6e-6 at 1e3;
/// alpha and depth 7e-7).
#[test]
fn hard_case_far_from_the_origin() {
    const TOL: f64 = 1e-4;
    for (k, eye) in [[1.2e3, -8.0e2, 5.0e2], [8.0e3, 6.0e3, -1.0e4]].into_iter().enumerate() {
        let mut spec = Spec::new(60, 40, 8, 500 + k as u64);
        spec.eye = eye;
        spec.footprint = 12.0;
        let (b, cam, s) = scene(&spec);
        let e = errors_of(&format!("eye {eye:?}"), &b, &cam, &s);
        assert!(e.max() <= TOL, "eye {eye:?}: {e:?}");
    }
}

/// Sub-pixel billboards (footprints 0.3-1 px, many missed by every pixel centre) and
/// screen-filling ones (3-6× the image).
///
/// Tolerances: sub-pixel 6e-5, measured worst 1.4e-5 (alpha: the sampled alphas of
/// sub-pixel billboards are often within f32 rounding of the 1/255 cut-off); screen-filling
/// 2e-6, measured worst 3.4e-7.
#[test]
fn hard_case_sub_pixel_and_screen_filling() {
    for (name, n, footprint, tol) in [("sub-pixel", 400, 0.6, 6e-5), ("screen-filling", 12, 150.0, 2e-6)] {
        let mut spec = Spec::new(n, 32, 8, 700);
        spec.footprint = footprint;
        let (b, cam, s) = scene(&spec);
        let e = errors_of(name, &b, &cam, &s);
        assert!(e.max() <= tol, "{name}: {e:?}");
    }
}
