//! Visual hull initialisation: carving a ball from its masks, typed errors, mask dilation.

use bbsplat::camera::Camera;
use bbsplat::init::hull::{HullConfig, HullError, carve, visual_hull_points};
use bbsplat::scene::Image;
use bbsplat::scene::View;
use bbsplat::testing_internals::hull::dilate_mask;
use glam::Vec3;
use std::path::PathBuf;

/// Views of a ball of radius 0.5 at the origin from 12 directions, with exact masks.
fn ball_views(size: u32) -> Vec<View> {
    (0..12)
        .map(|i| {
            let a = i as f32 * std::f32::consts::TAU / 12.0;
            let eye = Vec3::new(3.0 * a.cos(), 1.0 + 0.3 * (i % 3) as f32, 3.0 * a.sin());
            let f = size as f32;
            let camera = Camera::look_at(eye, Vec3::ZERO, Vec3::Y, f, f, size, size);
            let mut coverage = vec![0u8; (size * size) as usize];
            let mut rgb = vec![255u8; (size * size * 3) as usize];
            let d = eye.length();
            let angular = (0.5 / d).asin();
            for y in 0..size {
                for x in 0..size {
                    let dir = Vec3::new((x as f32 + 0.5 - f / 2.0) / f, (y as f32 + 0.5 - f / 2.0) / f, 1.0);
                    let off = (dir.x * dir.x + dir.y * dir.y).sqrt().atan();
                    if off < angular {
                        let k = (y * size + x) as usize;
                        coverage[k] = 255;
                        rgb[3 * k..3 * k + 3].copy_from_slice(&[200, 40, 40]);
                    }
                }
            }
            View {
                name: format!("{i}"),
                path: PathBuf::from(format!("{i}.png")),
                camera,
                image: Image::new(size, size, rgb).unwrap().into(),
                coverage: Some(coverage),
                mask: None,
            }
        })
        .collect()
}

#[test]
fn the_hull_of_a_ball_contains_it_and_is_close_to_it() {
    let views = ball_views(64);
    let config = HullConfig {
        resolution: 48,
        ..HullConfig::default()
    };
    let (lo, hi) = (Vec3::splat(-1.0), Vec3::splat(1.0));
    let occupied = carve(&views, lo, hi, &config).unwrap();
    let r = config.resolution;
    let step = 2.0 / r as f32;
    let mut inside_kept = true;
    let mut far_kept = 0;
    for z in 0..r {
        for y in 0..r {
            for x in 0..r {
                let p = lo + step * Vec3::new(x as f32 + 0.5, y as f32 + 0.5, z as f32 + 0.5);
                let kept = occupied[(z * r + y) * r + x];
                if p.length() < 0.5 && !kept {
                    inside_kept = false;
                }
                if p.length() > 0.8 && kept {
                    far_kept += 1;
                }
            }
        }
    }
    assert!(inside_kept, "a voxel of the ball was carved");
    // 12 views around the ball carve everything well outside it (the hull of a ball seen
    // from a ring is a bit larger than the ball near the poles).
    assert!(far_kept < 40, "{far_kept} voxels beyond radius 0.8 survived");
    let (points, colours) = visual_hull_points(&views, lo, hi, &config, 3).unwrap();
    let radii: Vec<f32> = points.iter().map(|p| p.length()).collect();
    let mean = radii.iter().sum::<f32>() / radii.len() as f32;
    assert!((0.45..0.7).contains(&mean), "mean surface radius {mean}");
    // Points seen by some view take the ball's colour.
    let red = colours.iter().filter(|c| c[0] > 0.7 && c[1] < 0.25).count();
    assert!(red * 10 > colours.len() * 9, "{red} of {} red", colours.len());
}

#[test]
fn no_masks_empty_hull_and_bad_resolution_are_typed_errors() {
    let mut views = ball_views(16);
    let (lo, hi) = (Vec3::splat(-1.0), Vec3::splat(1.0));
    assert_eq!(
        carve(
            &views,
            lo,
            hi,
            &HullConfig {
                resolution: 1,
                ..HullConfig::default()
            }
        ),
        Err(HullError::Resolution(1))
    );
    for v in &mut views {
        v.coverage.as_mut().unwrap().fill(0);
    }
    assert_eq!(
        visual_hull_points(&views, lo, hi, &HullConfig::default(), 0),
        Err(HullError::Empty)
    );
    for v in &mut views {
        v.coverage = None;
    }
    assert_eq!(carve(&views, lo, hi, &HullConfig::default()), Err(HullError::NoMasks));
}

#[test]
fn dilation_is_a_square_max_filter() {
    let mut m = vec![0u8; 25];
    m[12] = 9;
    let d = dilate_mask(&m, 5, 5, 1);
    for y in 0..5 {
        for x in 0..5 {
            let inside = (1..=3).contains(&x) && (1..=3).contains(&y);
            assert_eq!(d[y * 5 + x], if inside { 9 } else { 0 }, "({x}, {y})");
        }
    }
}
