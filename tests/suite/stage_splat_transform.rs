//! Splat transform `T`, camera-facing normal and screen bounds: FD gradient property, projection
//! invariants, broken backwards and the named hard cases.
//!
//! Tolerances were measured with `cargo test --test suite stage_splat_transform:: -- --ignored --nocapture
//! measure` (worst case over 40 seeds × 256 cases); the numbers are in
//! `docs/numerics-geometry.md` and next to each constant.

use bbsplat::camera::Camera;
use bbsplat::gradcheck::{GradReport, GradTolerance, StepRule, check_vjp};
use bbsplat::stages::bilinear;
use bbsplat::stages::ray_plane::intersect;
use bbsplat::stages::rotation::quat_to_rotation;
use bbsplat::stages::splat_transform::{
    NEAR_PLANE, ProjectedSplat, ScreenBounds, SplatGrads, SplatTransform, project_splat, project_splat_vjp,
    project_splat_vjp_visible, splat_frame, square_screen_bounds, support_half_side, support_quad,
};
use bbsplat::strategies::{BillboardPose, billboard_in_front, camera, identity_camera, seeded_config};
use glam::{DMat3, DVec2, DVec3, Mat3, Vec2, Vec3};
use proptest::prelude::*;
use proptest::strategy::ValueTree;
use proptest::test_runner::{RngSeed, TestRunner};

/// Texture support half side for TS = 16.
fn support() -> f32 {
    support_half_side(16)
}

/// FD tolerance for `project_splat_vjp` on `camera()` × `billboard_in_front()` with the default
/// step, outputs `(Tu/fx, Tv/fy, Tw, normal)`. Measured worst over 40 seeds × 256 cases
/// (`measure_tolerances`): elementwise ratio 0.41 of this tolerance, rel L2 5.0e-4, 1 − cos
/// 1.25e-7, |bias| 2.9e-4. Chosen: atol 1e-3, rtol 5e-3 (elementwise 2.5× the worst observed),
/// rel L2 2e-3 (4×), 1 − cos 1e-6 (8×), bias 1.5e-3 (5×).
const SPLAT_TOL: GradTolerance = GradTolerance {
    atol: 1e-3,
    rtol: 5e-3,
    max_rel_l2: 2e-3,
    min_cosine: 1.0 - 1e-6,
    max_bias: 1.5e-3,
};

/// FD step: `1e-3·max(1, |x|)` (the checker's default).
const SPLAT_STEP: StepRule = StepRule {
    base: 1e-3,
    relative: true,
};

fn pose_to_x(b: &BillboardPose) -> Vec<f32> {
    let (p, s, q) = (b.position, b.log_scales, b.quaternion);
    vec![p.x, p.y, p.z, s.x, s.y, q[0], q[1], q[2], q[3]]
}

fn unpack(x: &[f32]) -> (Vec3, Vec2, [f32; 4]) {
    (
        Vec3::new(x[0], x[1], x[2]),
        Vec2::new(x[3], x[4]),
        [x[5], x[6], x[7], x[8]],
    )
}

/// Forward outputs for the checker: the rows of `T` with `Tu`, `Tv` divided by the focal lengths
/// (a fixed linear map, so that every output is O(1) and the normal's share of the loss is not
/// drowned in the pixel-sized entries of `T`), then the normal.
fn forward(cam: Camera) -> impl Fn(&[f32]) -> Vec<f32> {
    move |x| {
        let (p, s, q) = unpack(x);
        let ps = project_splat(p, s, q, &cam).expect("strategies keep billboards visible");
        let t = ps.transform;
        let (tu, tv, n) = (t.tu / cam.fx, t.tv / cam.fy, ps.normal_view);
        vec![
            tu.x, tu.y, tu.z, tv.x, tv.y, tv.z, t.tw.x, t.tw.y, t.tw.z, n.x, n.y, n.z,
        ]
    }
}

fn grads_to_vec(g: SplatGrads) -> Vec<f32> {
    let (p, s, q) = (g.d_position, g.d_log_scales, g.d_quaternion);
    vec![p.x, p.y, p.z, s.x, s.y, q[0], q[1], q[2], q[3]]
}

/// Cotangent of the outputs of [`forward`] → `(∂L/∂T, ∂L/∂normal)`.
fn cotangent(cam: &Camera, w: &[f32]) -> (SplatTransform, Vec3) {
    let d_t = SplatTransform {
        tu: Vec3::new(w[0], w[1], w[2]) / cam.fx,
        tv: Vec3::new(w[3], w[4], w[5]) / cam.fy,
        tw: Vec3::new(w[6], w[7], w[8]),
    };
    (d_t, Vec3::new(w[9], w[10], w[11]))
}

fn vjp(cam: Camera) -> impl Fn(&[f32], &[f32]) -> Vec<f32> + Copy {
    move |x, w| {
        let (p, s, q) = unpack(x);
        let (d_t, d_n) = cotangent(&cam, w);
        grads_to_vec(project_splat_vjp(p, s, q, &cam, &d_t, d_n))
    }
}

fn check(cam: Camera, b: &BillboardPose, seed: u64, backward: impl Fn(&[f32], &[f32]) -> Vec<f32>) -> GradReport {
    check_vjp(&pose_to_x(b), forward(cam), backward, seed, SPLAT_STEP, &SPLAT_TOL)
}

fn scene() -> impl Strategy<Value = (Camera, BillboardPose)> {
    camera().prop_flat_map(|cam| (Just(cam), billboard_in_front(cam)))
}

/// World point of plane coordinates `(u, v)`.
fn world_point(b: &BillboardPose, u: f32, v: f32) -> Vec3 {
    let r = quat_to_rotation(b.quaternion);
    let s = Vec2::new(b.log_scales.x.exp(), b.log_scales.y.exp());
    b.position + u * s.x * r.x_axis + v * s.y * r.y_axis
}

/// Worst errors of the round trip "(u, v) → world point → camera pixel → intersect".
#[derive(Default, Debug)]
struct RoundTrip {
    uv: f32,
    depth_rel: f32,
    pixel: f32,
}

fn round_trip(cam: &Camera, b: &BillboardPose, ps: &ProjectedSplat, u: f32, v: f32) -> Option<RoundTrip> {
    let x = world_point(b, u, v);
    let (px, py) = cam.project(x)?;
    let z = cam.world_to_view(x).z;
    let hit = intersect(&ps.transform, px, py)?;
    let (pix, depth) = ps.transform.project_uv(u, v);
    Some(RoundTrip {
        uv: (hit.u - u).abs().max((hit.v - v).abs()),
        depth_rel: ((hit.depth - z) / z).abs().max(((depth - z) / z).abs()),
        pixel: (pix - Vec2::new(px, py)).abs().max_element(),
    })
}

/// Round-trip budgets on `camera()` × `billboard_in_front()`, `(u, v) ∈ [−1.2, 1.2]²`. Measured
/// worst over 40 seeds × 256 cases (`measure_tolerances`): (u, v) 1.5e-5, relative depth 3.2e-7,
/// pixel 1.5e-5 (2 ulps at 64 px). Chosen ≈ 3×.
const ROUND_TRIP_UV: f32 = 5e-5;
const ROUND_TRIP_DEPTH_REL: f32 = 1e-6;
const ROUND_TRIP_PIXEL: f32 = 5e-5;

proptest! {
    #![proptest_config(seeded_config(256))]

    #[test]
    fn gradient_matches_finite_differences((cam, b) in scene(), seed in any::<u64>()) {
        let r = check(cam, &b, seed, vjp(cam));
        prop_assert!(r.passed(), "{b:?}: {r}");
    }

    #[test]
    fn transform_reproduces_the_camera_projection((cam, b) in scene(), u in -1.2f32..1.2, v in -1.2f32..1.2) {
        let ps = project_splat(b.position, b.log_scales, b.quaternion, &cam).unwrap();
        let e = round_trip(&cam, &b, &ps, u, v).expect("the hit is in front and not grazing");
        prop_assert!(e.uv <= ROUND_TRIP_UV, "{e:?}");
        prop_assert!(e.depth_rel <= ROUND_TRIP_DEPTH_REL, "{e:?}");
        prop_assert!(e.pixel <= ROUND_TRIP_PIXEL, "{e:?}");
    }

    #[test]
    fn normal_faces_the_camera((cam, b) in scene()) {
        let ps = project_splat(b.position, b.log_scales, b.quaternion, &cam).unwrap();
        let p_view = cam.world_to_view(b.position);
        prop_assert!(ps.normal_view.dot(p_view) < 0.0);
        prop_assert!((ps.normal_view.length() - 1.0).abs() < 1e-5);
        let n = cam.rotation * quat_to_rotation(b.quaternion).z_axis;
        prop_assert!((ps.normal_view - ps.normal_sign * n).length() < 1e-6);
        prop_assert!((ps.view_depth - p_view.z).abs() <= 1e-6 * p_view.z);
    }

    #[test]
    fn principal_point_is_honoured((cam, b) in scene(), dx in -5.0f32..5.0, dy in -5.0f32..5.0) {
        let moved = Camera { cx: cam.cx + dx, cy: cam.cy + dy, ..cam };
        let a = project_splat(b.position, b.log_scales, b.quaternion, &cam).unwrap();
        let m = project_splat(b.position, b.log_scales, b.quaternion, &moved).unwrap();
        for (u, v) in [(0.0, 0.0), (1.0, -1.0), (-0.3, 0.8)] {
            let shift = m.transform.project_uv(u, v).0 - a.transform.project_uv(u, v).0;
            prop_assert!((shift - Vec2::new(dx, dy)).abs().max_element() < 1e-4, "{shift}");
        }
        prop_assert!((m.centre - a.centre - Vec2::new(dx, dy)).abs().max_element() < 1e-3);
    }

    #[test]
    fn unit_disk_box_matches_sampled_circle((cam, b) in scene()) {
        // The 2DGS closed form against the box of 2000 projected circle points.
        let ps = project_splat(b.position, b.log_scales, b.quaternion, &cam).unwrap();
        let (mut lo, mut hi) = (Vec2::splat(f32::INFINITY), Vec2::splat(f32::NEG_INFINITY));
        for i in 0..2000 {
            let a = i as f32 / 2000.0 * std::f32::consts::TAU;
            let (px, py) = cam.project(world_point(&b, a.cos(), a.sin())).unwrap();
            lo = lo.min(Vec2::new(px, py));
            hi = hi.max(Vec2::new(px, py));
        }
        let (c, h) = ((lo + hi) * 0.5, (hi - lo) * 0.5);
        // Sampling misses the extreme by at most R·(1 − cos(π/2000)) ≈ 1.2e-6·R; plus rounding.
        let tol = 1e-3 + 1e-5 * h.max_element();
        prop_assert!((ps.centre - c).abs().max_element() <= tol, "{} vs {c}", ps.centre);
        prop_assert!((ps.half_extent - h).abs().max_element() <= tol, "{} vs {h}", ps.half_extent);
    }
}

/// Every pixel centre whose ray hits the support square (with a margin of `1e-4` in uv, below the
/// last texel's alpha fade of `Δ/255 ≈ 5e-4`) lies in the bounds; returns the box of those pixels.
fn scan_hits(cam: &Camera, t: &SplatTransform, bounds: Option<ScreenBounds>) -> Option<ScreenBounds> {
    let l = support() - 1e-4;
    let mut hit_box: Option<ScreenBounds> = None;
    for j in 0..cam.height {
        for i in 0..cam.width {
            let p = Vec2::new(i as f32 + 0.5, j as f32 + 0.5);
            let Some(h) = intersect(t, p.x, p.y) else { continue };
            if h.u.abs() > l || h.v.abs() > l {
                continue;
            }
            let b = bounds.unwrap_or_else(|| panic!("pixel {p} hits ({}, {}) but there are no bounds", h.u, h.v));
            assert!(b.contains(p), "pixel {p} hits ({}, {}) outside {b:?}", h.u, h.v);
            let hb = hit_box.get_or_insert(ScreenBounds { min: p, max: p });
            hb.min = hb.min.min(p);
            hb.max = hb.max.max(p);
        }
    }
    hit_box
}

proptest! {
    #![proptest_config(seeded_config(64))]

    #[test]
    fn bounds_contain_every_hit_pixel((cam, b) in scene()) {
        let ps = project_splat(b.position, b.log_scales, b.quaternion, &cam).unwrap();
        let bounds = square_screen_bounds(&ps.transform, support());
        scan_hits(&cam, &ps.transform, bounds);
    }
}

proptest! {
    #![proptest_config(seeded_config(256))]

    #[test]
    fn bounds_are_the_box_of_the_camera_projected_corners((cam, b) in scene()) {
        // Tight: equal (up to rounding) to the box of the 4 world corners projected by the camera.
        let ps = project_splat(b.position, b.log_scales, b.quaternion, &cam).unwrap();
        let l = support();
        let bounds = square_screen_bounds(&ps.transform, l).unwrap();
        let (mut lo, mut hi) = (Vec2::splat(f32::INFINITY), Vec2::splat(f32::NEG_INFINITY));
        for (u, v) in [(-l, -l), (l, -l), (l, l), (-l, l)] {
            let (px, py) = cam.project(world_point(&b, u, v)).unwrap();
            lo = lo.min(Vec2::new(px, py));
            hi = hi.max(Vec2::new(px, py));
        }
        prop_assert!((bounds.min - lo).abs().max_element() < 1e-3, "{bounds:?} vs {lo} {hi}");
        prop_assert!((bounds.max - hi).abs().max_element() < 1e-3, "{bounds:?} vs {lo} {hi}");
    }
}

// ---------------------------------------------------------------------------------------------
// Broken backwards must fail.

fn failure_rate(make: impl Fn(Camera) -> Box<dyn Fn(&[f32], &[f32]) -> Vec<f32>>, cases: u32) -> f64 {
    let mut runner = TestRunner::new(seeded_config(cases));
    let failed = (0..cases)
        .filter(|&i| {
            let (cam, b) = scene().new_tree(&mut runner).unwrap().current();
            !check(cam, &b, i as u64, make(cam)).passed()
        })
        .count();
    failed as f64 / cases as f64
}

#[test]
fn broken_backward_sign_flip_fails() {
    // The position gradient's z component with the wrong sign.
    let rate = failure_rate(
        |cam| {
            Box::new(move |x, w| {
                let mut g = vjp(cam)(x, w);
                g[2] = -g[2];
                g
            })
        },
        64,
    );
    assert!(rate >= 0.95, "caught in only {:.0}% of cases", rate * 100.0);
}

#[test]
fn broken_backward_ignoring_the_normal_flip_fails() {
    // Forgets that the normal was flipped: wrong whenever the flip is −1.
    let mut runner = TestRunner::new(seeded_config(64));
    let (mut flipped, mut caught) = (0, 0);
    for i in 0..64 {
        let (cam, b) = scene().new_tree(&mut runner).unwrap().current();
        let ps = project_splat(b.position, b.log_scales, b.quaternion, &cam).unwrap();
        if ps.normal_sign > 0.0 {
            continue;
        }
        flipped += 1;
        let broken = move |x: &[f32], w: &[f32]| {
            let mut w = w.to_vec();
            w[9..12].iter_mut().for_each(|c| *c = -*c);
            vjp(cam)(x, &w)
        };
        caught += usize::from(!check(cam, &b, i, broken).passed());
    }
    assert!(flipped >= 16, "too few flipped normals: {flipped}");
    assert_eq!(caught, flipped);
}

#[test]
fn broken_backward_missing_principal_point_term_fails() {
    // Backward computed as if cx = cy = 0 (drops the K·[…] principal-point term).
    let rate = failure_rate(
        |cam| {
            Box::new(move |x, w| {
                let (p, s, q) = unpack(x);
                let (d_t, d_n) = cotangent(&cam, w);
                let no_pp = Camera {
                    cx: 0.0,
                    cy: 0.0,
                    ..cam
                };
                grads_to_vec(project_splat_vjp(p, s, q, &no_pp, &d_t, d_n))
            })
        },
        64,
    );
    assert!(rate >= 0.95, "caught in only {:.0}% of cases", rate * 100.0);
}

#[test]
fn broken_backward_missing_exp_chain_fails() {
    // ∂L/∂s returned as ∂L/∂log s (forgets the factor s of the exp).
    let rate = failure_rate(
        |cam| {
            Box::new(move |x, w| {
                let mut g = vjp(cam)(x, w);
                g[3] /= x[3].exp();
                g[4] /= x[4].exp();
                g
            })
        },
        64,
    );
    assert!(rate >= 0.95, "caught in only {:.0}% of cases", rate * 100.0);
}

#[test]
fn broken_backward_one_percent_scale_fails() {
    let rate = failure_rate(
        |cam| Box::new(move |x, w| vjp(cam)(x, w).into_iter().map(|g| g * 1.01).collect()),
        64,
    );
    assert_eq!(rate, 1.0, "a 1% scale error must always fail");
}

// ---------------------------------------------------------------------------------------------
// Named hard cases.

const FACE_ON: [f32; 4] = [1.0, 0.0, 0.0, 0.0];

#[test]
fn near_plane_cull_of_the_centre() {
    let cam = identity_camera(64, 48);
    let at = |z: f32| project_splat(Vec3::new(0.0, 0.0, z), Vec2::splat(-2.0), FACE_ON, &cam);
    assert!(at(NEAR_PLANE).is_none(), "depth exactly at the near plane is culled");
    assert!(at(NEAR_PLANE - 1e-3).is_none());
    assert!(at(-1.0).is_none(), "behind the camera");
    let just = at(NEAR_PLANE + 1e-3).expect("just in front is kept");
    assert!(just.view_depth > NEAR_PLANE);
    // Culled billboards get zero gradients.
    let d_t = SplatTransform {
        tu: Vec3::ONE,
        tv: Vec3::ONE,
        tw: Vec3::ONE,
    };
    let g = project_splat_vjp(Vec3::new(0.0, 0.0, 0.1), Vec2::ZERO, FACE_ON, &cam, &d_t, Vec3::ONE);
    assert_eq!(g, SplatGrads::default());
}

#[test]
fn camera_lying_in_the_billboard_plane() {
    let cam = identity_camera(64, 48);
    // q = (1, 1, 1, 1)/2 (120° about (1, 1, 1)) is exact in f32: t_u = +y, t_v = +z, n = +x, so
    // the plane x = position.x contains the camera iff position.x = 0.
    let q = [1.0, 1.0, 1.0, 1.0];
    assert_eq!(quat_to_rotation(q), Mat3::from_cols(Vec3::Y, Vec3::Z, Vec3::X));
    let exactly = project_splat(Vec3::new(0.0, 0.0, 3.0), Vec2::splat(-1.0), q, &cam);
    assert!(exactly.is_none(), "cos θ == 0: T is singular, culled");
    let d_t = SplatTransform {
        tu: Vec3::ONE,
        tv: Vec3::ONE,
        tw: Vec3::ONE,
    };
    let g = project_splat_vjp(Vec3::new(0.0, 0.0, 3.0), Vec2::ZERO, q, &cam, &d_t, Vec3::ONE);
    assert_eq!(g, SplatGrads::default());
    // Nearly in the plane: kept, every result finite, nothing visible except near-plane-rejected
    // or grazing rays; gradients finite.
    for offset in [1e-6f32, 1e-4, 1e-2, -1e-3] {
        let ps = project_splat(Vec3::new(offset, 0.0, 3.0), Vec2::splat(-1.0), q, &cam).expect("not exactly edge-on");
        let t = ps.transform;
        let mut accepted = 0;
        for j in 0..cam.height {
            for i in 0..cam.width {
                let (px, py) = (i as f32 + 0.5, j as f32 + 0.5);
                if let Some(hit) = intersect(&t, px, py) {
                    assert!(hit.u.is_finite() && hit.v.is_finite() && hit.depth >= NEAR_PLANE);
                    // Seen within atan(offset/3) of edge-on, the square is < 1 px wide:
                    // accepted hits lie far outside it or are grazing-rejected.
                    if hit.u.abs() <= support() && hit.v.abs() <= support() {
                        accepted += 1;
                    }
                }
                let g = bbsplat::stages::ray_plane::intersect_vjp(&t, px, py, 0.3, -0.7, 0.2);
                assert!(g.tu.is_finite() && g.tv.is_finite() && g.tw.is_finite());
            }
        }
        assert!(accepted <= 48, "offset {offset}: {accepted} pixels inside the square");
        let b = square_screen_bounds(&t, support()).unwrap();
        assert!(b.min.is_finite() && b.max.is_finite());
        assert!(b.max.x - b.min.x < 1.0, "edge-on square spans < 1 px in x: {b:?}");
        let d_t = SplatTransform {
            tu: Vec3::ONE,
            tv: Vec3::ONE,
            tw: Vec3::ONE,
        };
        let g = project_splat_vjp(Vec3::new(offset, 0.0, 3.0), Vec2::splat(-1.0), q, &cam, &d_t, Vec3::ONE);
        assert!(g.d_position.is_finite() && g.d_log_scales.is_finite() && g.d_quaternion.iter().all(|v| v.is_finite()));
    }
}

#[test]
fn billboard_crossing_the_near_plane() {
    let cam = identity_camera(64, 48);
    // Centre at depth 0.6, tilted 60° about x, half sides 1: the square spans depths
    // 0.6 ± 0.87·1.13, i.e. crosses both the near plane and the camera plane.
    let a = 60f32.to_radians() * 0.5;
    let q = [a.cos(), a.sin(), 0.0, 0.0];
    let ps = project_splat(Vec3::new(0.1, -0.05, 0.6), Vec2::ZERO, q, &cam).expect("centre in front");
    let t = ps.transform;
    let l = support();
    let behind = [(-l, -l), (l, -l), (l, l), (-l, l)]
        .iter()
        .filter(|&&(u, v)| t.project_uv(u, v).1 < NEAR_PLANE)
        .count();
    assert_eq!(behind, 2, "two corners behind the near plane");
    let bounds = square_screen_bounds(&t, l).expect("part of it is visible");
    assert!(bounds.min.is_finite() && bounds.max.is_finite());
    // Every visible pixel is inside the clipped bounds, and the bounds are tight in y (the near
    // plane cuts the square along image rows here).
    let hits = scan_hits(&cam, &t, Some(bounds)).expect("visible pixels");
    assert!(bounds.pixel_rect(cam.width, cam.height).is_some());
    assert!(hits.min.y - bounds.min.y.max(0.0) <= 1.0 + 1e-3 || bounds.min.y < 0.0);
    // The reference's centre-only cull: a centre behind the near plane is culled even though
    // part of the square is in front.
    assert!(project_splat(Vec3::new(0.1, -0.05, 0.15), Vec2::ZERO, q, &cam).is_none());
    // Entirely behind the near plane: no bounds.
    let far_behind = SplatTransform {
        tw: Vec3::new(0.01, 0.01, 0.1),
        ..t
    };
    assert!(square_screen_bounds(&far_behind, l).is_none());
}

#[test]
fn degenerate_tiny_scales() {
    let mut runner = TestRunner::new(seeded_config(64));
    for _ in 0..64 {
        let (cam, b) = scene().new_tree(&mut runner).unwrap().current();
        for ls in [Vec2::splat(-20.0), Vec2::new(-20.0, -1.0), Vec2::new(-1.0, -30.0)] {
            let ps = project_splat(b.position, ls, b.quaternion, &cam).expect("a point-sized billboard is kept");
            assert!(ps.half_extent.is_finite() && ps.centre.is_finite());
            let (px, py) = cam.project(b.position).unwrap();
            if ls.max_element() < -10.0 {
                // Point-sized: the disk box degenerates to the projected centre.
                assert!(
                    (ps.centre - Vec2::new(px, py)).abs().max_element() < 1e-3,
                    "{} vs {px} {py}",
                    ps.centre
                );
                assert!(ps.half_extent.max_element() < 1e-3);
            }
            let bounds = square_screen_bounds(&ps.transform, support()).unwrap();
            assert!(bounds.min.is_finite() && bounds.max.is_finite());
            assert!(bounds.contains(Vec2::new(px, py)) || (bounds.max - bounds.min).max_element() < 1e-2);
            // Rays: finite results or None, never NaN.
            for (dx, dy) in [(0.0, 0.0), (0.3, -0.2), (5.0, 5.0)] {
                if let Some(h) = intersect(&ps.transform, px + dx, py + dy) {
                    assert!(h.u.is_finite() && h.v.is_finite() && h.depth.is_finite());
                }
            }
            let d_t = SplatTransform {
                tu: Vec3::ONE,
                tv: -Vec3::ONE,
                tw: Vec3::ONE,
            };
            let g = project_splat_vjp(b.position, ls, b.quaternion, &cam, &d_t, Vec3::ONE);
            assert!(g.d_position.is_finite() && g.d_log_scales.is_finite());
            assert!(g.d_quaternion.iter().all(|v| v.is_finite()));
            // d/d log s = s·d/ds → ~0 for s = e^-20.
            assert!(g.d_log_scales.abs().min_element() < 1e-4);
        }
    }
}

#[test]
fn degenerate_huge_scales() {
    let mut runner = TestRunner::new(seeded_config(64));
    for _ in 0..64 {
        let (cam, b) = scene().new_tree(&mut runner).unwrap().current();
        for ls in [Vec2::splat(10.0), Vec2::new(15.0, -1.0), Vec2::splat(20.0)] {
            let ps = project_splat(b.position, ls, b.quaternion, &cam).expect("huge billboards are kept");
            assert!(ps.transform.to_array().iter().all(|v| v.is_finite()));
            // The square covers the whole screen side of its plane: the centre pixel of the
            // billboard sees (u, v) ≈ (0, 0).
            let (px, py) = cam.project(b.position).unwrap();
            let hit = intersect(&ps.transform, px, py).expect("centre pixel hits");
            let tol = 1e-5 * (-ls.min_element()).exp() * 1e3;
            assert!(hit.u.abs() < tol && hit.v.abs() < tol, "{hit:?}");
            let bounds = square_screen_bounds(&ps.transform, support()).expect("visible");
            assert!(bounds.contains(Vec2::new(px, py)));
            let rect = bounds.pixel_rect(cam.width, cam.height).unwrap();
            assert!(rect.x_max > rect.x_min && rect.y_max > rect.y_min);
            let d_t = SplatTransform {
                tu: Vec3::ONE,
                tv: -Vec3::ONE,
                tw: Vec3::ONE,
            };
            let g = project_splat_vjp(b.position, ls, b.quaternion, &cam, &d_t, Vec3::ONE);
            assert!(g.d_position.is_finite() && g.d_log_scales.is_finite());
            assert!(g.d_quaternion.iter().all(|v| v.is_finite()));
        }
    }
    // exp overflow (log-scale > 88.7): culled, not NaN.
    let cam = identity_camera(64, 48);
    assert!(project_splat(Vec3::new(0.0, 0.0, 3.0), Vec2::splat(100.0), FACE_ON, &cam).is_none());
}

#[test]
fn nan_and_infinite_inputs_never_panic() {
    let cam = identity_camera(64, 48);
    let p = Vec3::new(0.0, 0.0, 3.0);
    let (nan, inf) = (f32::NAN, f32::INFINITY);
    let d_t = SplatTransform {
        tu: Vec3::ONE,
        tv: Vec3::ONE,
        tw: Vec3::ONE,
    };
    let culled = [
        (Vec3::new(nan, 0.0, 3.0), Vec2::ZERO, FACE_ON),
        (Vec3::new(0.0, 0.0, nan), Vec2::ZERO, FACE_ON),
        (Vec3::new(inf, 0.0, 3.0), Vec2::ZERO, FACE_ON),
        (p, Vec2::new(nan, 0.0), FACE_ON),
        (p, Vec2::new(0.0, inf), FACE_ON),
        (p, Vec2::new(f32::NEG_INFINITY, 0.0), FACE_ON),
        // A NaN or infinite quaternion is culled: the identity fallback of degenerate (finite)
        // quaternions would render it as an ordinary billboard.
        (p, Vec2::ZERO, [nan, 1.0, 0.0, 0.0]),
        (p, Vec2::ZERO, [1.0, 0.0, inf, 0.0]),
    ];
    for (pos, ls, q) in culled {
        assert!(project_splat(pos, ls, q, &cam).is_none(), "{pos} {ls} {q:?}");
        assert!(splat_frame(pos, ls, q, &cam).is_none(), "{pos} {ls} {q:?}");
        assert_eq!(
            project_splat_vjp(pos, ls, q, &cam, &d_t, Vec3::ONE),
            SplatGrads::default()
        );
    }
    // A NaN camera culls everything.
    let bad = Camera {
        rotation: Mat3::from_cols_array(&[nan; 9]),
        ..cam
    };
    assert!(project_splat(p, Vec2::ZERO, FACE_ON, &bad).is_none());
    let bad = Camera { fx: nan, ..cam };
    assert!(project_splat(p, Vec2::ZERO, FACE_ON, &bad).is_none());
    // Bounds of a NaN transform.
    let t = SplatTransform {
        tu: Vec3::new(nan, 0.0, 0.0),
        ..d_t
    };
    assert!(square_screen_bounds(&t, support()).is_none());
    assert!(square_screen_bounds(&d_t, nan).is_none());
}

// ---------------------------------------------------------------------------------------------
// Far-away coordinates: f32 against an f64 reference.

/// The f64 reference of `project_splat`'s transform and of `intersect`, in plain f64 code.
struct Reference {
    tu: DVec3,
    tv: DVec3,
    tw: DVec3,
}

impl Reference {
    fn new(b: &BillboardPose, cam: &Camera) -> Self {
        let q: Vec<f64> = b.quaternion.iter().map(|&c| c as f64).collect();
        let n = q.iter().map(|c| c * c).sum::<f64>().sqrt();
        let (w, x, y, z) = (q[0] / n, q[1] / n, q[2] / n, q[3] / n);
        let tu = DVec3::new(
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y + w * z),
            2.0 * (x * z - w * y),
        );
        let tv = DVec3::new(
            2.0 * (x * y - w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z + w * x),
        );
        let rcw = DMat3::from_cols_array(&cam.rotation.to_cols_array().map(|v| v as f64));
        let (su, sv) = ((b.log_scales.x as f64).exp(), (b.log_scales.y as f64).exp());
        let a = rcw * tu * su;
        let bb = rcw * tv * sv;
        let c = rcw * b.position.as_dvec3() + cam.translation.as_dvec3();
        let tw = DVec3::new(a.z, bb.z, c.z);
        let (fx, fy, cx, cy) = (cam.fx as f64, cam.fy as f64, cam.cx as f64, cam.cy as f64);
        Self {
            tu: fx * DVec3::new(a.x, bb.x, c.x) + cx * tw,
            tv: fy * DVec3::new(a.y, bb.y, c.y) + cy * tw,
            tw,
        }
    }

    fn pixel(&self, u: f64, v: f64) -> DVec2 {
        let x = DVec3::new(u, v, 1.0);
        DVec2::new(self.tu.dot(x), self.tv.dot(x)) / self.tw.dot(x)
    }

    fn intersect(&self, px: f64, py: f64) -> (f64, f64, f64) {
        let k = px * self.tw - self.tu;
        let l = py * self.tw - self.tv;
        let p = k.cross(l);
        let (u, v) = (p.x / p.z, p.y / p.z);
        (u, v, u * self.tw.x + v * self.tw.y + self.tw.z)
    }

    fn max_abs(&self) -> f64 {
        self.tu
            .abs()
            .max_element()
            .max(self.tv.abs().max_element())
            .max(self.tw.abs().max_element())
    }
}

/// Worst f32-vs-f64 errors in one configuration family.
#[derive(Default, Debug, Clone, Copy)]
struct FarErrors {
    /// max |T32 − T64| / max |T64|.
    t_rel: f64,
    /// max |(u, v)32 − (u, v)64| at pixels of in-square points (whole pipeline in f32).
    uv: f64,
    /// max relative depth error at those pixels.
    depth_rel: f64,
    /// max |(u, v)| error of `intersect` alone (same T, f32 vs f64).
    uv_intersect_only: f64,
    /// max relative depth error of `intersect` alone.
    depth_rel_intersect_only: f64,
}

impl FarErrors {
    fn max(self, o: Self) -> Self {
        Self {
            t_rel: self.t_rel.max(o.t_rel),
            uv: self.uv.max(o.uv),
            depth_rel: self.depth_rel.max(o.depth_rel),
            uv_intersect_only: self.uv_intersect_only.max(o.uv_intersect_only),
            depth_rel_intersect_only: self.depth_rel_intersect_only.max(o.depth_rel_intersect_only),
        }
    }
}

/// Compares f32 against f64 for a billboard; pixels are chosen (in f64) at in-square points.
fn far_errors(cam: &Camera, b: &BillboardPose, uvs: &[(f64, f64)]) -> FarErrors {
    let ps = project_splat(b.position, b.log_scales, b.quaternion, cam).expect("visible");
    let r = Reference::new(b, cam);
    let t64 = [r.tu, r.tv, r.tw];
    let t32 = [ps.transform.tu, ps.transform.tv, ps.transform.tw];
    let mut e = FarErrors::default();
    for (a, b) in t32.iter().zip(&t64) {
        e.t_rel = e.t_rel.max((a.as_dvec3() - *b).abs().max_element() / r.max_abs());
    }
    let t_same = Reference {
        tu: ps.transform.tu.as_dvec3(),
        tv: ps.transform.tv.as_dvec3(),
        tw: ps.transform.tw.as_dvec3(),
    };
    for &(u, v) in uvs {
        let pix = r.pixel(u, v);
        let (px, py) = (pix.x as f32, pix.y as f32);
        let (u64_, v64, d64) = r.intersect(px as f64, py as f64);
        let hit = intersect(&ps.transform, px, py).expect("in-square hit");
        e.uv = e.uv.max((hit.u as f64 - u64_).abs().max((hit.v as f64 - v64).abs()));
        e.depth_rel = e.depth_rel.max(((hit.depth as f64 - d64) / d64).abs());
        let (us, vs, ds) = t_same.intersect(px as f64, py as f64);
        e.uv_intersect_only = e
            .uv_intersect_only
            .max((hit.u as f64 - us).abs().max((hit.v as f64 - vs).abs()));
        e.depth_rel_intersect_only = e.depth_rel_intersect_only.max(((hit.depth as f64 - ds) / ds).abs());
    }
    e
}

const FAR_UVS: [(f64, f64); 5] = [(0.0, 0.0), (0.9, 0.9), (-0.9, 0.5), (0.3, -1.0), (-1.1, -1.1)];

/// Family A: world coordinates around 1e4 units, camera 3-6 units from the billboard (a large
/// scene seen from inside): `p_view = R·x + t` cancels two ~1e4 terms.
fn translated_scene(seed: u64) -> impl Iterator<Item = (Camera, BillboardPose)> {
    let mut cfg = seeded_config(1);
    cfg.rng_seed = RngSeed::Fixed(seed);
    let mut runner = TestRunner::new(cfg);
    let mut rng = bbsplat::rng::Rng::new(seed);
    std::iter::repeat_with(move || {
        let (cam, b) = scene().new_tree(&mut runner).unwrap().current();
        let offset = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)) * 1e4;
        let centre = cam.centre() + offset;
        let moved_cam = Camera {
            translation: -(cam.rotation * centre),
            ..cam
        };
        let moved = BillboardPose {
            position: b.position + offset,
            ..b
        };
        (moved_cam, moved)
    })
}

/// Family B: billboard far from the camera: the strategy's scene scaled by 2000-3000 about the
/// camera centre (view depth 4e3-1.8e4, half sides 100-1500, same angular size), fx = fy = 600.
fn distant_scene(seed: u64) -> impl Iterator<Item = (Camera, BillboardPose)> {
    let mut cfg = seeded_config(1);
    cfg.rng_seed = RngSeed::Fixed(seed);
    let mut runner = TestRunner::new(cfg);
    let mut rng = bbsplat::rng::Rng::new(seed ^ 0xfa5);
    std::iter::repeat_with(move || {
        let (cam, b) = scene().new_tree(&mut runner).unwrap().current();
        let cam = Camera {
            fx: 600.0,
            fy: 600.0,
            ..cam
        };
        let scale = 2500.0 * rng.range(0.8, 1.2);
        let c = cam.centre();
        let moved = BillboardPose {
            position: c + (b.position - c) * scale,
            log_scales: b.log_scales + Vec2::splat(scale.ln()),
            ..b
        };
        (cam, moved)
    })
}

/// Stated bounds for f32 vs f64 at 1e4 units, family A (world coordinates ~1e4). Measured worst
/// over 40 seeds × 256 billboards (`measure_tolerances`): T 4.8e-7 of max|T|, (u, v) 1.5e-5,
/// relative depth 2.3e-7; `intersect` alone 7.4e-6 and 1.2e-7. Chosen ≈ 3×. (Before `p_view` was
/// accumulated in f64 the same run measured T 2.2e-3, (u, v) 3.3e-2, depth 7.0e-4.)
const FAR_A: FarErrors = FarErrors {
    t_rel: 1.5e-6,
    uv: 5e-5,
    depth_rel: 1e-6,
    uv_intersect_only: 2.5e-5,
    depth_rel_intersect_only: 5e-7,
};
/// Family B (billboard 1e4 away). Measured worst: T 5.5e-7, (u, v) 6.5e-6, relative depth 1.5e-7;
/// `intersect` alone 2.8e-6 and 8.6e-8. Chosen ≈ 3×.
const FAR_B: FarErrors = FarErrors {
    t_rel: 1.5e-6,
    uv: 2e-5,
    depth_rel: 5e-7,
    uv_intersect_only: 1e-5,
    depth_rel_intersect_only: 3e-7,
};

/// FD step for the far-away gradient check: absolute `4e-3`, i.e. 4 f32 spacings at 1e4 (the
/// checker's floor) for the positions and small enough for the other inputs.
const FAR_STEP: StepRule = StepRule {
    base: 4e-3,
    relative: false,
};

#[test]
fn far_away_gradient_matches_finite_differences() {
    // World coordinates ~1e4: the position FD perturbs by whole f32 spacings of 1e4; p_view is
    // accumulated in f64 so the forward stays smooth at that scale.
    for (i, (cam, b)) in translated_scene(21).take(64).enumerate() {
        let r = check_vjp(&pose_to_x(&b), forward(cam), vjp(cam), i as u64, FAR_STEP, &SPLAT_TOL);
        assert!(r.passed(), "{b:?}: {r}");
    }
}

fn assert_within(e: FarErrors, bound: FarErrors, what: &str) {
    assert!(e.t_rel <= bound.t_rel, "{what}: T {e:?}");
    assert!(e.uv <= bound.uv, "{what}: uv {e:?}");
    assert!(e.depth_rel <= bound.depth_rel, "{what}: depth {e:?}");
    assert!(e.uv_intersect_only <= bound.uv_intersect_only, "{what}: {e:?}");
    assert!(
        e.depth_rel_intersect_only <= bound.depth_rel_intersect_only,
        "{what}: {e:?}"
    );
}

#[test]
fn far_away_coordinates_match_f64_reference() {
    let a = translated_scene(11)
        .take(256)
        .fold(FarErrors::default(), |m, (c, b)| m.max(far_errors(&c, &b, &FAR_UVS)));
    assert_within(a, FAR_A, "world coordinates at 1e4");
    let b = distant_scene(12)
        .take(256)
        .fold(FarErrors::default(), |m, (c, b)| m.max(far_errors(&c, &b, &FAR_UVS)));
    assert_within(b, FAR_B, "billboard 1e4 away");
}

// ---------------------------------------------------------------------------------------------
// Measurement (for the docs).

#[test]
#[ignore = "measurement run, see docs/numerics-geometry.md"]
fn measure_tolerances() {
    let (seeds, cases) = (40u64, 256u32);
    let (mut ratio, mut l2, mut cos, mut bias) = (0f64, 0f64, 0f64, 0f64);
    let (mut fratio, mut fl2, mut fcos, mut fbias) = (0f64, 0f64, 0f64, 0f64);
    let mut rt = RoundTrip::default();
    let mut fa = FarErrors::default();
    let mut fb = FarErrors::default();
    for s in 0..seeds {
        let mut cfg = seeded_config(cases);
        cfg.rng_seed = RngSeed::Fixed(2000 + s);
        let mut runner = TestRunner::new(cfg);
        for i in 0..cases {
            let (cam, b) = scene().new_tree(&mut runner).unwrap().current();
            let r = check(cam, &b, s * 10_000 + i as u64, vjp(cam));
            ratio = ratio.max(r.worst_ratio);
            l2 = l2.max(r.rel_l2);
            cos = cos.max(1.0 - r.cosine);
            bias = bias.max(r.bias.abs());
            let ps = project_splat(b.position, b.log_scales, b.quaternion, &cam).unwrap();
            let (u, v) = (
                ((i % 16) as f32 / 15.0) * 2.4 - 1.2,
                ((i / 16) as f32 / 15.0) * 2.4 - 1.2,
            );
            let e = round_trip(&cam, &b, &ps, u, v).unwrap();
            rt.uv = rt.uv.max(e.uv);
            rt.depth_rel = rt.depth_rel.max(e.depth_rel);
            rt.pixel = rt.pixel.max(e.pixel);
        }
        for (i, (cam, b)) in translated_scene(5000 + s).take(64).enumerate() {
            let r = check_vjp(&pose_to_x(&b), forward(cam), vjp(cam), i as u64, FAR_STEP, &SPLAT_TOL);
            fratio = fratio.max(r.worst_ratio);
            fl2 = fl2.max(r.rel_l2);
            fcos = fcos.max(1.0 - r.cosine);
            fbias = fbias.max(r.bias.abs());
        }
        fa = translated_scene(3000 + s)
            .take(cases as usize)
            .fold(fa, |m, (c, b)| m.max(far_errors(&c, &b, &FAR_UVS)));
        fb = distant_scene(4000 + s)
            .take(cases as usize)
            .fold(fb, |m, (c, b)| m.max(far_errors(&c, &b, &FAR_UVS)));
    }
    println!(
        "splat transform FD: worst elementwise ratio {ratio:.3e}, rel L2 {l2:.3e}, 1-cos {cos:.3e}, |bias| {bias:.3e}"
    );
    println!(
        "far-away FD: worst elementwise ratio {fratio:.3e}, rel L2 {fl2:.3e}, 1-cos {fcos:.3e}, |bias| {fbias:.3e}"
    );
    println!("round trip: {rt:?}");
    println!("far A (coordinates 1e4): {fa:?}");
    println!("far B (distance 1e4): {fb:?}");
}

#[test]
fn unit_disk_touching_the_camera_plane() {
    // q = (1, 1, 1, 1)/2: t_u = +y, t_v = +z, n = +x, all exact. With s_v equal to the centre's
    // depth, d = tw.x² + tw.y² − tw.z² = s_v² − z² is exactly 0: the reference culls it.
    let cam = identity_camera(64, 48);
    let q = [1.0, 1.0, 1.0, 1.0];
    let ls = 1.5f32;
    let z = ls.exp();
    assert!(project_splat(Vec3::new(0.5, 0.0, z), Vec2::new(-1.0, ls), q, &cam).is_none());
    // One ulp larger scale: d tiny but not 0. Kept, with a finite (or +inf) box and never NaN.
    let ps = project_splat(Vec3::new(0.5, 0.0, z), Vec2::new(-1.0, ls.next_up()), q, &cam).expect("d ≠ 0");
    assert!(!ps.centre.is_nan() && !ps.half_extent.is_nan(), "{ps:?}");
    assert!(ps.reference_radius() >= 3.0);
    // The square crosses the near plane: its bounds still come out finite.
    let b = square_screen_bounds(&ps.transform, support()).unwrap();
    assert!(b.min.is_finite() && b.max.is_finite());
}

/// `pixel_rect` (truncating casts) equals the plain `ceil`/`floor` formula it replaces, on edge
/// values (integers, half-integers, around 0 and the image size, huge and infinite bounds) and
/// on random ones.
#[test]
fn pixel_rect_matches_the_libm_formula() {
    let libm = |b: &ScreenBounds, w: u32, h: u32| {
        let lo = |m: f32, n: u32| (m - 0.5).ceil().clamp(0.0, n as f32) as u32;
        let hi = |m: f32, n: u32| ((m - 0.5).floor() + 1.0).clamp(0.0, n as f32) as u32;
        let (x0, y0, x1, y1) = (lo(b.min.x, w), lo(b.min.y, h), hi(b.max.x, w), hi(b.max.y, h));
        (x0 < x1 && y0 < y1).then_some((x0, y0, x1, y1))
    };
    let mut values = vec![
        0.0,
        -0.0,
        0.5,
        -0.5,
        1.0,
        -1.0,
        -1.5,
        -2.5,
        2.5,
        15.5,
        16.0,
        16.5,
        17.0,
        1e30,
        -1e30,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::from_bits(0.5f32.to_bits() + 1),
        f32::from_bits(0.5f32.to_bits() - 1),
    ];
    let mut state = 0x853c49e6748fea9bu64;
    for _ in 0..400 {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        values.push(((state >> 40) as f32 / (1u64 << 24) as f32) * 40.0 - 12.0);
    }
    for (k, &a) in values.iter().enumerate() {
        let b = values[(k * 7 + 3) % values.len()];
        let bounds = ScreenBounds {
            min: Vec2::new(a.min(b), a),
            max: Vec2::new(a.max(b), b.max(a)),
        };
        let got = bounds.pixel_rect(16, 12).map(|r| (r.x_min, r.y_min, r.x_max, r.y_max));
        assert_eq!(got, libm(&bounds, 16, 12), "bounds {bounds:?}");
    }
}

proptest! {
    #![proptest_config(seeded_config(256))]

    /// Every point the rasterizer would accept (ray-plane hit and bilinear taps at TS = 16) lies
    /// inside its row's span of the support quad: pixel centres of the whole image, and points
    /// projected from a thin ring around the support square's border (where the margin matters).
    #[test]
    fn support_quad_spans_contain_every_accepted_point((cam, b) in scene(), ring in prop::collection::vec((0.0f32..1.0, -0.02f32..0.02), 200)) {
        let ps = project_splat(b.position, b.log_scales, b.quaternion, &cam).unwrap();
        let t = ps.transform;
        let h = support_half_side(16);
        let Some(quad) = support_quad(&t, h) else {
            return Ok(());
        };
        let accepted = |px: f32, py: f32| {
            intersect(&t, px, py).is_some_and(|hit| bilinear::taps(hit.u, hit.v, 16).is_some())
        };
        let check = |px: f32, py: f32| -> Result<(), TestCaseError> {
            if accepted(px, py) {
                let span = quad.row_span(py);
                prop_assert!(
                    span.is_some_and(|(lo, hi)| lo <= px && px <= hi),
                    "({px}, {py}) accepted but outside the span {span:?} of {quad:?}"
                );
            }
            Ok(())
        };
        for j in 0..cam.height {
            for i in 0..cam.width {
                check(i as f32 + 0.5, j as f32 + 0.5)?;
            }
        }
        // Points around the border: walk the square's perimeter, offset across it.
        let tw = t.tw.as_dvec3();
        for &(s, off) in &ring {
            let w = (4.0 * s as f64).fract() * 2.0 - 1.0;
            let e = (h + off) as f64;
            let (u, v) = match (4.0 * s) as u32 {
                0 => (w * e, -e),
                1 => (e, w * e),
                2 => (-w * e, e),
                _ => (-e, -w * e),
            };
            let x = DVec3::new(u, v, 1.0);
            let p = DVec2::new(t.tu.as_dvec3().dot(x), t.tv.as_dvec3().dot(x)) / tw.dot(x);
            check(p.x as f32, p.y as f32)?;
        }
    }
}

/// A square crossing or close to the near plane, or seen at a steep angle, has no quad (the
/// rasterizer falls back to its bounding box).
#[test]
fn support_quad_refuses_near_and_steep_squares() {
    let h = support_half_side(16);
    let face_on = |depth: f32| SplatTransform {
        tu: Vec3::new(10.0, 0.0, 10.0 * depth / 2.0),
        tv: Vec3::new(0.0, 10.0, 10.0 * depth / 2.0),
        tw: Vec3::new(0.0, 0.0, depth),
    };
    assert!(support_quad(&face_on(2.0), h).is_some());
    assert!(
        support_quad(&face_on(0.3), h).is_none(),
        "closer than twice the near plane"
    );
    // Tilted so that one edge is 19× deeper than the other (depths 0.5 and 9.5).
    let steep = SplatTransform {
        tu: Vec3::new(10.0, 0.0, 10.0),
        tv: Vec3::new(0.0, 10.0, 10.0),
        tw: Vec3::new(0.0, 4.5 / h, 5.0),
    };
    assert!(support_quad(&steep, h).is_none(), "depth ratio above 16");
    assert!(
        support_quad(
            &SplatTransform {
                tw: Vec3::new(f32::NAN, 0.0, 2.0),
                ..face_on(2.0)
            },
            h
        )
        .is_none()
    );
}

/// A camera and a billboard pose (position, log-scales, quaternion) anywhere in a 16-unit cube
/// around the origin: in front of the camera, behind it, edge-on, some culled.
fn pose_anywhere() -> impl Strategy<Value = (Camera, Vec3, Vec2, [f32; 4])> {
    (
        camera(),
        (-8.0f32..8.0, -8.0f32..8.0, -8.0f32..8.0),
        (-3.0f32..1.0, -3.0f32..1.0),
        bbsplat::strategies::quaternion(),
    )
        .prop_map(|(cam, p, s, q)| (cam, Vec3::new(p.0, p.1, p.2), Vec2::new(s.0, s.1), q))
}

proptest! {
    #![proptest_config(seeded_config(512))]

    /// `splat_frame` is `project_splat` without the unit-disk box: the same frame fields, and the
    /// same culling (behind the near plane, edge-on) on poses anywhere around the camera,
    /// including behind it.
    #[test]
    fn splat_frame_matches_project_splat((cam, p, s, q) in pose_anywhere()) {
        let frame = splat_frame(p, s, q, &cam);
        let projected = project_splat(p, s, q, &cam);
        prop_assert_eq!(frame.is_some(), projected.is_some());
        if let (Some(f), Some(ps)) = (frame, projected) {
            prop_assert_eq!(f.transform, ps.transform);
            prop_assert_eq!(f.normal_view, ps.normal_view);
            prop_assert_eq!(f.normal_sign, ps.normal_sign);
            prop_assert_eq!(f.view_depth, ps.view_depth);
            prop_assert_eq!(f.scales, ps.scales);
        }
    }
}

proptest! {
    #![proptest_config(seeded_config(512))]

    /// The rasterizer's backward calls `project_splat_vjp_visible` with the normal sign its
    /// forward kept: for every pose the frame accepts (anywhere around the camera, so some face
    /// away and some are culled) it gives `project_splat_vjp`'s bits, normal gradient included.
    #[test]
    fn visible_vjp_equals_the_full_vjp_bit_for_bit(
        (cam, p, s, q) in pose_anywhere(),
        w in proptest::collection::vec(-1.0f32..1.0, 12),
    ) {
        let (d_t, d_n) = cotangent(&cam, &w);
        if let Some(frame) = splat_frame(p, s, q, &cam) {
            let full = project_splat_vjp(p, s, q, &cam, &d_t, d_n);
            let visible = project_splat_vjp_visible(s, q, frame.normal_sign, &cam, &d_t, d_n);
            let bits = |g: SplatGrads| grads_to_vec(g).iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            prop_assert_eq!(bits(visible), bits(full));
        }
    }
}

/// `splat_frames_x4` (four billboards in the lanes of `Vec4`s) gives `splat_frame`'s frames bit
/// for bit: ordinary billboards in front, behind and around the near plane, degenerate, tiny and
/// non-finite quaternions, overflowing and non-finite log-scales, NaN and huge positions; two
/// cameras. Compared through `Debug`, which tells −0.0 from 0.0.
#[test]
fn splat_frames_x4_equal_splat_frame_bit_for_bit() {
    use bbsplat::rng::Rng;
    use bbsplat::stages::splat_transform::splat_frames_x4;
    let cams = [
        Camera::look_at(Vec3::new(0.3, -0.2, -4.0), Vec3::ZERO, Vec3::Y, 120.0, 110.0, 64, 48),
        Camera::look_at(
            Vec3::new(3.0, 1.0, 2.0),
            Vec3::new(0.1, 0.0, 0.2),
            Vec3::Y,
            500.0,
            500.0,
            400,
            300,
        ),
    ];
    let mut rng = Rng::new(0x5eed_f4a3);
    let special = |rng: &mut Rng, ordinary: f32| match rng.below(16) {
        0 => f32::NAN,
        1 => f32::INFINITY,
        2 => -f32::INFINITY,
        3 => 0.0,
        4 => -0.0,
        5 => 1e30,
        6 => 1e-30,
        _ => ordinary,
    };
    let (mut some, mut none) = (0, 0);
    for case in 0..20_000 {
        let cam = &cams[case % 2];
        let rare = case % 5 == 0;
        let pick = |rng: &mut Rng, v: f32| if rare { special(rng, v) } else { v };
        let position = |rng: &mut Rng| {
            let depth = if rng.below(4) == 0 {
                rng.range(-1.0, 0.5)
            } else {
                rng.range(0.5, 8.0)
            };
            let (right, up) = (rng.range(-2.0, 2.0), rng.range(-2.0, 2.0));
            let r = cam.rotation;
            let p = cam.centre() + depth * r.row(2) + right * r.row(0) + up * r.row(1);
            Vec3::new(pick(rng, p.x), pick(rng, p.y), pick(rng, p.z))
        };
        let scales = |rng: &mut Rng| {
            let (u, v) = (rng.range(-4.0, 1.0), rng.range(-4.0, 100.0));
            Vec2::new(pick(rng, u), pick(rng, v))
        };
        let quat = |rng: &mut Rng| {
            let q = [0; 4].map(|_| rng.range(-1.0, 1.0));
            let tiny = rng.below(8) == 0;
            q.map(|c| pick(rng, if tiny { c * 1e-5 } else { c }))
        };
        let p: [Vec3; 4] = std::array::from_fn(|_| position(&mut rng));
        let s: [Vec2; 4] = std::array::from_fn(|_| scales(&mut rng));
        let q: [[f32; 4]; 4] = std::array::from_fn(|_| quat(&mut rng));
        let want = std::array::from_fn::<_, 4, _>(|l| format!("{:?}", splat_frame(p[l], s[l], q[l], cam)));
        let got = splat_frames_x4(p, s, q, cam).map(|f| format!("{f:?}"));
        assert_eq!(got, want, "case {case}: p {p:?} s {s:?} q {q:?}");
        for f in &want {
            if f == "None" { none += 1 } else { some += 1 }
        }
    }
    assert!(some > 20_000 && none > 5_000, "{some} frames, {none} culled");
}
