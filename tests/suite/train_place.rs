//! Billboards placed on a view's error (`bbsplat::train::place`).

use bbsplat::camera::Camera;
use bbsplat::raster::SH_FLOATS;
use bbsplat::rng::Rng;
use bbsplat::stages::rotation::quat_to_rotation;
use bbsplat::stages::sh::rgb_to_sh;
use bbsplat::train::place::{HALF_SIDE_PX, ViewError, place_on_error};
use glam::Vec3;

const TS: usize = 8;

fn camera() -> Camera {
    Camera::look_at(
        Vec3::new(0.3, -2.0, -6.0),
        Vec3::new(0.0, 0.2, 0.0),
        Vec3::Y,
        55.0,
        50.0,
        40,
        30,
    )
}

/// A render equal to its target (RGB from the pixel index) except in `blocks`, each
/// `(x0, y0, size, error)`: every channel of those pixels off by `error`. Median depth 5 on the
/// left half of the image, 0 (none) on the right.
fn view_with_errors(cam: &Camera, blocks: &[(usize, usize, usize, f32)]) -> (Vec<f32>, Vec<f32>, Vec<f32>) {
    let (w, h) = (cam.width as usize, cam.height as usize);
    let target: Vec<f32> = (0..3 * w * h).map(|i| ((i * 7) % 11) as f32 / 10.0).collect();
    let mut rendered = target.clone();
    for &(x0, y0, size, e) in blocks {
        for y in y0..y0 + size {
            for x in x0..x0 + size {
                for c in 0..3 {
                    rendered[3 * (y * w + x) + c] += e;
                }
            }
        }
    }
    let depth = (0..w * h).map(|p| if p % w < w / 2 { 5.0 } else { 0.0 }).collect();
    (rendered, target, depth)
}

fn view_of<'a>(rendered: &'a [f32], target: &'a [f32], median_depth: &'a [f32]) -> ViewError<'a> {
    ViewError {
        rendered,
        target,
        median_depth,
    }
}

/// Each placed billboard lies inside an erroneous pixel's ray at the rendered depth, faces the
/// camera, has the half side of `HALF_SIDE_PX` pixels there and the pixel's target colour.
#[test]
fn placed_on_the_bad_pixels_at_the_rendered_depth_facing_the_camera() {
    let cam = camera();
    let (rendered, target, depth) = view_with_errors(&cam, &[(5, 7, 3, 0.3)]);
    let view = view_of(&rendered, &target, &depth);
    let placed = place_on_error(&view, &cam, 40, TS, &mut Rng::new(3), |_, _, z| z);
    assert_eq!(placed.len(), 40);
    assert_eq!(placed.texture_size, TS);
    let forward = cam.rotation.row(2);
    for i in 0..placed.len() {
        let p = placed.positions[i];
        let (x, y) = cam.project(p).expect("in front of the camera");
        assert!(
            (5.0..8.0).contains(&x) && (7.0..10.0).contains(&y),
            "({x}, {y}) outside the block"
        );
        let z = cam.world_to_view(p).z;
        assert!((z - 5.0).abs() < 1e-4, "view depth {z}");
        let r = quat_to_rotation(placed.quaternions[i]);
        assert!(r.z_axis.dot(forward) > 1.0 - 1e-5, "faces the camera");
        assert!(r.x_axis.dot(cam.rotation.row(0)) > 1.0 - 1e-5, "u along the image's x");
        let s = placed.log_scales[i].exp();
        let want = HALF_SIDE_PX * 5.0 / cam.fx.max(cam.fy);
        assert!((s.x - want).abs() < 1e-5 * want && (s.y - want).abs() < 1e-5 * want);
        let (px, py) = (x as usize, y as usize);
        let k = 3 * (py * cam.width as usize + px);
        for c in 0..3 {
            assert_eq!(placed.sh[i * SH_FLOATS + c], rgb_to_sh(target[k + c]) - 0.1);
        }
    }
}

/// Where the render has no depth, the view's median depth (5 here) is used.
#[test]
fn pixels_without_depth_take_the_views_median_depth() {
    let cam = camera();
    let (rendered, target, depth) = view_with_errors(&cam, &[(30, 10, 2, 0.5)]);
    let view = view_of(&rendered, &target, &depth);
    let placed = place_on_error(&view, &cam, 10, TS, &mut Rng::new(1), |_, _, z| z);
    assert_eq!(placed.len(), 10);
    for p in &placed.positions {
        let (x, _) = cam.project(*p).unwrap();
        assert!((30.0..32.0).contains(&x));
        assert!((cam.world_to_view(*p).z - 5.0).abs() < 1e-4);
    }
}

/// Pixels are drawn ∝ squared error: blocks of equal size with errors 0.1 and 0.2 get draws in
/// the ratio 1 : 4 (4000 draws: standard deviation of the ratio about 0.16; measured 4.01 with
/// this seed, 3.61-4.31 over seeds 0-11, mean 4.01; bound 3.4-4.7, about ±4 standard
/// deviations), and the same RNG state gives the same placements.
#[test]
fn draws_follow_the_squared_error_and_are_seeded() {
    let cam = camera();
    let (rendered, target, depth) = view_with_errors(&cam, &[(2, 2, 4, 0.1), (10, 15, 4, 0.2)]);
    let view = view_of(&rendered, &target, &depth);
    let placed = place_on_error(&view, &cam, 4000, TS, &mut Rng::new(0), |_, _, z| z);
    let (mut small, mut large) = (0usize, 0usize);
    for p in &placed.positions {
        let (x, _) = cam.project(*p).unwrap();
        if x < 6.0 {
            small += 1;
        } else {
            large += 1;
        }
    }
    assert_eq!(small + large, 4000);
    let ratio = large as f64 / small as f64;
    println!("draws {small} : {large}, ratio {ratio:.2}");
    assert!((3.4..4.7).contains(&ratio), "ratio {ratio}");
    let again = place_on_error(&view, &cam, 4000, TS, &mut Rng::new(0), |_, _, z| z);
    assert_eq!(again, placed);
}

/// Nothing is placed for no draws, a perfect render, or a render without depth anywhere; NaN
/// pixels are never drawn.
#[test]
fn nothing_to_place() {
    let cam = camera();
    let (rendered, target, depth) = view_with_errors(&cam, &[]);
    let view = view_of(&rendered, &target, &depth);
    assert_eq!(
        place_on_error(&view, &cam, 10, TS, &mut Rng::new(0), |_, _, z| z).len(),
        0
    );
    let (rendered, target, _) = view_with_errors(&cam, &[(1, 1, 2, 0.4)]);
    let no_depth = vec![0.0; depth.len()];
    let view = view_of(&rendered, &target, &no_depth);
    assert_eq!(
        place_on_error(&view, &cam, 10, TS, &mut Rng::new(0), |_, _, z| z).len(),
        0
    );
    let view = view_of(&rendered, &target, &depth);
    assert_eq!(
        place_on_error(&view, &cam, 0, TS, &mut Rng::new(0), |_, _, z| z).len(),
        0
    );
    let mut nan = rendered.clone();
    nan[3 * (20 * 40 + 3)] = f32::NAN;
    let view = view_of(&nan, &target, &depth);
    for p in &place_on_error(&view, &cam, 200, TS, &mut Rng::new(2), |_, _, z| z).positions {
        let (x, y) = cam.project(*p).unwrap();
        assert!(x < 3.0 && y < 3.0, "only the erroneous block is drawn");
    }
}

/// `refine_depth` moves each placement along its pixel's ray to the depth it returns (the
/// half side follows), is asked once a draw with the pixel and the rendered depth, and a depth
/// that is not positive and finite keeps the rendered one.
#[test]
fn a_refined_depth_moves_the_placement_along_its_ray() {
    let cam = camera();
    let (rendered, target, depth) = view_with_errors(&cam, &[(5, 7, 3, 0.3)]);
    let view = view_of(&rendered, &target, &depth);
    let asked = std::cell::RefCell::new(Vec::new());
    let placed = place_on_error(&view, &cam, 12, TS, &mut Rng::new(3), |x, y, z| {
        asked.borrow_mut().push((x, y, z));
        7.5
    });
    let plain = place_on_error(&view, &cam, 12, TS, &mut Rng::new(3), |_, _, z| z);
    assert_eq!(asked.borrow().len(), 12);
    for (i, &(x, y, z)) in asked.borrow().iter().enumerate() {
        assert!(
            (5..8).contains(&x) && (7..10).contains(&y) && z == 5.0,
            "({x}, {y}, {z})"
        );
        let p = placed.positions[i];
        assert!((cam.world_to_view(p).z - 7.5).abs() < 1e-4);
        // The same pixel as without refinement, farther along the same ray.
        let (a, b) = (cam.project(p).unwrap(), cam.project(plain.positions[i]).unwrap());
        assert!(
            (a.0 - b.0).abs() < 1e-3 && (a.1 - b.1).abs() < 1e-3,
            "{a:?} against {b:?}"
        );
        let want = HALF_SIDE_PX * 7.5 / cam.fx.max(cam.fy);
        assert!((placed.log_scales[i].exp().x - want).abs() < 1e-5 * want);
    }
    for bad in [0.0, -1.0, f32::NAN, f32::INFINITY] {
        let kept = place_on_error(&view, &cam, 12, TS, &mut Rng::new(3), |_, _, _| bad);
        assert_eq!(kept.positions, plain.positions, "refined depth {bad}");
    }
}
