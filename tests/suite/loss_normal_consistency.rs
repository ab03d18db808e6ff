//! The normal-consistency loss (2DGS) and the depth-distortion loss: the depth-to-normal VJP and
//! the loss's VJP into the depth, alpha and normal maps against central finite differences in
//! f64, a plane's normals, the detached alpha, and checks that a wrong gradient fails.

use bbsplat::camera::Camera;
use bbsplat::gradcheck::{GradReport, GradTolerance, compare, random_weights};
use bbsplat::loss::LossError;
use bbsplat::loss::distortion::distortion_loss;
use bbsplat::loss::normal_consistency::{
    expected_depth, normal_consistency, normal_consistency_weighted, surface_normals, surface_normals_vjp,
};
use bbsplat::rng::Rng;
use glam::{DVec3, Vec3};

/// A camera of `w × h` pixels looking along +z, focal length ~ the width.
fn camera(w: u32, h: u32, rng: &mut Rng) -> Camera {
    let mut cam = Camera::identity(w, h);
    cam.fx = w as f32 * rng.range(0.8, 1.2);
    cam.fy = w as f32 * rng.range(0.8, 1.2);
    cam.cx += rng.range(-2.0, 2.0);
    cam.cy += rng.range(-2.0, 2.0);
    cam
}

/// A smooth positive expected-depth map: a tilted plane plus low-frequency bumps (depth 2-4),
/// far from the degenerate `|a × b| = 0`.
fn smooth_depth(w: usize, h: usize, rng: &mut Rng) -> Vec<f64> {
    let (gx, gy) = (rng.range(-0.02, 0.02) as f64, rng.range(-0.02, 0.02) as f64);
    let (f1, f2, p1, p2) = (
        rng.range(0.1, 0.4) as f64,
        rng.range(0.1, 0.4) as f64,
        rng.range(0.0, 6.0) as f64,
        rng.range(0.0, 6.0) as f64,
    );
    (0..h)
        .flat_map(|j| (0..w).map(move |i| (i as f64, j as f64)))
        .map(|(x, y)| 3.0 + gx * x + gy * y + 0.1 * (f1 * x + p1).sin() * (f2 * y + p2).cos())
        .collect()
}

/// `Σ w·n` over the surface normals: the scalar whose gradient the depth-to-normal VJP gives.
fn weighted_normals(cam: &Camera, depth: &[f64], w: &[DVec3]) -> f64 {
    surface_normals(cam, depth).iter().zip(w).map(|(n, w)| n.dot(*w)).sum()
}

/// Central differences in f64 of `f` at `x`, every element, step `h·(1 + |x|)`.
fn central_f64(f: impl Fn(&[f64]) -> f64, x: &[f64], h: f64) -> Vec<f64> {
    (0..x.len())
        .map(|i| {
            let step = h * (1.0 + x[i].abs());
            let mut p = x.to_vec();
            p[i] = x[i] + step;
            let plus = f(&p);
            p[i] = x[i] - step;
            (plus - f(&p)) / (2.0 * step)
        })
        .collect()
}

/// The depth-to-normal VJP against f64 central differences on one random case; the analytic
/// gradient is multiplied by `scale` (1 for the check, 1.01 for the catch test).
fn depth_to_normal_report(seed: u64, scale: f64) -> GradReport {
    let mut rng = Rng::new(seed);
    let (w, h) = (4 + rng.below(9) as usize, 4 + rng.below(9) as usize);
    let cam = camera(w as u32, h as u32, &mut rng);
    let depth = smooth_depth(w, h, &mut rng);
    let r = random_weights(3 * w * h, seed + 1);
    let d_normals: Vec<DVec3> = r.chunks(3).map(|c| DVec3::new(c[0], c[1], c[2])).collect();
    let analytic: Vec<f64> = surface_normals_vjp(&cam, &depth, &d_normals)
        .iter()
        .map(|g| g * scale)
        .collect();
    let numeric = central_f64(|d| weighted_normals(&cam, d, &d_normals), &depth, 1e-6);
    compare(&analytic, &numeric, &DEPTH_TO_NORMAL_TOLERANCE)
}

/// Tolerance of the depth-to-normal check (f64 throughout). Measured over 200 seeds
/// (`cargo test --features testing --test suite loss_normal_consistency::measure -- --ignored
/// --nocapture`): worst relative L2 1.7e-10, |bias| 4.7e-11, 1 − cos 7.8e-16, largest
/// |difference| 6.4e-10. Bounds 10× those (relative L2 1.7e-9, bias 4.7e-10, 1 − cos 7.8e-15);
/// elementwise atol 1e-9 + rtol 1e-7 (the worst element measured at 0.12 of it). A 1 % scale
/// error (relative L2 1e-2) fails: `depth_to_normal_check_catches_a_one_percent_error`.
const DEPTH_TO_NORMAL_TOLERANCE: GradTolerance = GradTolerance {
    atol: 1e-9,
    rtol: 1e-7,
    max_rel_l2: 1.7e-9,
    min_cosine: 1.0 - 7.8e-15,
    max_bias: 4.7e-10,
};

#[test]
fn depth_to_normal_vjp_matches_f64_finite_differences() {
    for seed in 0..40 {
        let r = depth_to_normal_report(seed, 1.0);
        assert!(r.passed(), "seed {seed}: {r}");
    }
}

#[test]
fn depth_to_normal_check_catches_a_one_percent_error() {
    for seed in 0..40 {
        let r = depth_to_normal_report(seed, 1.01);
        assert!(!r.passed(), "seed {seed}: a 1 % error passed: {r}");
    }
}

/// Maps of a render: depth `D = A·e`, alpha `A`, and a unit-ish rendered normal `N` times `A`,
/// all f32, smooth, alpha in [0.3, 1].
struct Maps {
    cam: Camera,
    depth: Vec<f32>,
    alpha: Vec<f32>,
    normal: Vec<f32>,
}

fn maps(seed: u64) -> Maps {
    let mut rng = Rng::new(seed);
    let (w, h) = (4 + rng.below(9) as usize, 4 + rng.below(9) as usize);
    let cam = camera(w as u32, h as u32, &mut rng);
    let e = smooth_depth(w, h, &mut rng);
    let alpha: Vec<f32> = (0..w * h).map(|_| rng.range(0.3, 1.0)).collect();
    let depth: Vec<f32> = e.iter().zip(&alpha).map(|(&e, &a)| e as f32 * a).collect();
    let normal: Vec<f32> = alpha
        .iter()
        .flat_map(|&a| {
            let n = Vec3::new(rng.range(-0.4, 0.4), rng.range(-0.4, 0.4), -1.0).normalize() * a;
            n.to_array()
        })
        .collect();
    Maps {
        cam,
        depth,
        alpha,
        normal,
    }
}

/// Which map a check differentiates.
#[derive(Clone, Copy, Debug)]
enum Map {
    Depth,
    Alpha,
    Normal,
}

/// The loss's gradient with respect to one map against central differences (f32 inputs moved
/// by exactly representable steps, the loss evaluated in f64, the detached alpha weighting the
/// surface normals held at the base alpha); analytic gradient times `scale`.
fn loss_report(seed: u64, map: Map, scale: f64) -> GradReport {
    let m = maps(seed);
    let d_loss = 1.7;
    let out = normal_consistency(&m.cam, &m.depth, &m.alpha, &m.normal, d_loss).unwrap();
    let (x, grad) = match map {
        Map::Depth => (&m.depth, &out.d_depth),
        Map::Alpha => (&m.alpha, &out.d_alpha),
        Map::Normal => (&m.normal, &out.d_normal),
    };
    let analytic: Vec<f64> = grad.iter().map(|&g| f64::from(g) * scale).collect();
    let eval = |p: &[f32]| {
        let (mut depth, mut alpha, mut normal) = (m.depth.clone(), m.alpha.clone(), m.normal.clone());
        match map {
            Map::Depth => depth = p.to_vec(),
            Map::Alpha => alpha = p.to_vec(),
            Map::Normal => normal = p.to_vec(),
        }
        d_loss
            * normal_consistency_weighted(&m.cam, &depth, &alpha, &m.alpha, &normal, 1.0)
                .unwrap()
                .value
    };
    let numeric: Vec<f64> = (0..x.len())
        .map(|i| {
            let at = |step: f64| {
                let mut p = x.clone();
                p[i] = (f64::from(x[i]) + step) as f32;
                (eval(&p), f64::from(p[i]) - f64::from(x[i]))
            };
            let h = 1e-5 * (1.0 + f64::from(x[i]).abs());
            let ((plus, hp), (minus, hm)) = (at(h), at(-h));
            (plus - minus) / (hp - hm)
        })
        .collect();
    compare(&analytic, &numeric, &LOSS_TOLERANCE)
}

/// Tolerance of the loss checks against the f32 maps (step 1e-5·(1 + |x|); the loss in f64, the
/// gradients rounded to f32). Measured over 200 seeds × 3 maps (`measure`): worst relative L2
/// 2.4e-7 (alpha; depth 3.9e-8, normal 3.6e-8), |bias| 3.3e-8, 1 − cos 2.7e-14, largest
/// |difference| 7.7e-8. Bounds 10× those (relative L2 2.4e-6, bias 3.3e-7, 1 − cos 2.7e-13);
/// elementwise atol 1e-8 + rtol 1e-5 (the worst element at about 0.3 of it). A 1 % scale error
/// fails: `normal_consistency_check_catches_a_one_percent_error`.
const LOSS_TOLERANCE: GradTolerance = GradTolerance {
    atol: 1e-8,
    rtol: 1e-5,
    max_rel_l2: 2.4e-6,
    min_cosine: 1.0 - 2.7e-13,
    max_bias: 3.3e-7,
};

#[test]
fn normal_consistency_vjp_matches_finite_differences() {
    for seed in 0..30 {
        for map in [Map::Depth, Map::Alpha, Map::Normal] {
            let r = loss_report(seed, map, 1.0);
            assert!(r.passed(), "seed {seed}, {map:?}: {r}");
        }
    }
}

#[test]
fn normal_consistency_check_catches_a_one_percent_error() {
    for seed in 0..30 {
        for map in [Map::Depth, Map::Alpha, Map::Normal] {
            let r = loss_report(seed, map, 1.01);
            assert!(!r.passed(), "seed {seed}, {map:?}: a 1 % error passed: {r}");
        }
    }
}

/// The alpha that multiplies the surface normal is detached: the alpha gradient is exactly the
/// one through `e = D/A`, so with a depth map that makes `e` constant in alpha (D scaled with
/// A) it does not see the `N · n_s · A` product. Checked by moving alpha and depth together
/// (e fixed): the loss then changes only through the detached factor, which the gradient
/// ignores, so `∂L/∂A + e·∂L/∂D` (the derivative along that move) is zero.
#[test]
fn the_alpha_multiplying_the_surface_normal_is_detached() {
    for seed in 0..10 {
        let m = maps(seed);
        let out = normal_consistency(&m.cam, &m.depth, &m.alpha, &m.normal, 1.0).unwrap();
        let e = expected_depth(&m.depth, &m.alpha);
        for p in 0..m.alpha.len() {
            let along = f64::from(out.d_alpha[p]) + e[p] * f64::from(out.d_depth[p]);
            assert!(
                along.abs() <= 1e-6 * (f64::from(out.d_alpha[p]).abs() + 1e-9),
                "seed {seed} pixel {p}: {along}"
            );
        }
    }
}

/// On a plane, the surface normals of interior pixels are the plane's normal facing the camera
/// (whatever its tilt), and the border is 0.
#[test]
fn a_plane_gives_its_normal_facing_the_camera() {
    let mut rng = Rng::new(5);
    for _ in 0..20 {
        let (w, h) = (9usize, 7usize);
        let cam = camera(w as u32, h as u32, &mut rng);
        // Plane n·P = d in view space, in front of the camera.
        let n = DVec3::new(rng.range(-0.5, 0.5).into(), rng.range(-0.5, 0.5).into(), 1.0).normalize();
        let d = 3.0;
        let depth: Vec<f64> = (0..h)
            .flat_map(|j| (0..w).map(move |i| (i, j)))
            .map(|(i, j)| {
                let r = bbsplat::stages::ray_plane::pixel_ray(&cam, i as f32 + 0.5, j as f32 + 0.5).as_dvec3();
                d / n.dot(r)
            })
            .collect();
        let normals = surface_normals(&cam, &depth);
        for j in 0..h {
            for i in 0..w {
                let s = normals[j * w + i];
                if i == 0 || j == 0 || i == w - 1 || j == h - 1 {
                    assert_eq!(s, DVec3::ZERO);
                } else {
                    // Facing the camera: opposite to the plane normal pointing away (n·P = d > 0).
                    assert!((s + n).length() < 1e-6, "{s} vs {}", -n);
                }
            }
        }
    }
}

/// Where alpha is 0 the expected depth is 0 (not NaN) and receives no gradient.
#[test]
fn empty_pixels_give_zero_depth_and_no_gradient() {
    let mut m = maps(3);
    m.alpha[5] = 0.0;
    m.depth[5] = 0.0;
    let e = expected_depth(&m.depth, &m.alpha);
    assert_eq!(e[5], 0.0);
    let out = normal_consistency(&m.cam, &m.depth, &m.alpha, &m.normal, 1.0).unwrap();
    assert!(out.value.is_finite());
    assert_eq!((out.d_depth[5], out.d_alpha[5]), (0.0, 0.0));
    assert!(
        out.d_depth
            .iter()
            .chain(&out.d_alpha)
            .chain(&out.d_normal)
            .all(|g| g.is_finite())
    );
}

#[test]
fn maps_of_the_wrong_size_are_refused() {
    let m = maps(1);
    let err = normal_consistency(&m.cam, &m.depth[1..], &m.alpha, &m.normal, 1.0).unwrap_err();
    assert!(matches!(err, LossError::BadLength { which: "depth", .. }), "{err}");
    let err = normal_consistency(&m.cam, &m.depth, &m.alpha, &m.normal[3..], 1.0).unwrap_err();
    assert!(matches!(err, LossError::BadLength { which: "normal", .. }), "{err}");
    assert!(matches!(distortion_loss(&[], 1.0), Err(LossError::Empty { .. })));
}

/// Prints the worst errors of the checks over many seeds (the figures next to the tolerances).
#[test]
#[ignore]
fn measure() {
    let mut worst = bbsplat::gradcheck::WorstObserved::default();
    for seed in 0..200 {
        worst.add(&depth_to_normal_report(seed, 1.0));
    }
    eprintln!("depth to normal: {worst:?}");
    for map in [Map::Depth, Map::Alpha, Map::Normal] {
        let mut worst = bbsplat::gradcheck::WorstObserved::default();
        for seed in 0..200 {
            worst.add(&loss_report(seed, map, 1.0));
        }
        eprintln!("loss, {map:?}: {worst:?}");
    }
}
