//! `scene::registration`: the sharp turns between consecutive frames that a folded registration
//! leaves, and when they are worth a warning.

use bbsplat::camera::Camera;
use bbsplat::scene::registration::{MAX_SHARP_SHARE, folded_registration_warning, sharp_turns, turn_degrees};
use glam::{Mat3, Vec3};

/// Frame `i` of an orbit about the y axis, `step` degrees a frame, looking at the origin from 5
/// units, tilted down by 20 degrees; frames in `folded` turned by 180 degrees about the axis.
fn orbit(frames: usize, step: f32, folded: std::ops::Range<usize>) -> Vec<Camera> {
    (0..frames)
        .map(|i| {
            let fold = if folded.contains(&i) { 180.0 } else { 0.0 };
            let angle = (i as f32 * step + fold).to_radians();
            let eye = Vec3::new(5.0 * angle.sin(), -1.8, 5.0 * angle.cos());
            Camera::look_at(eye, Vec3::ZERO, Vec3::NEG_Y, 100.0, 100.0, 64, 48)
        })
        .collect()
}

fn names(n: usize) -> Vec<String> {
    (0..n).map(|i| format!("{i:04}.jpg")).collect()
}

#[test]
fn the_turn_between_two_cameras_is_the_angle_of_their_relative_rotation() {
    let a = Camera::identity(8, 8);
    for degrees in [0.0f32, 1.0, 45.0, 90.0, 135.0, 179.0] {
        let b = Camera {
            rotation: Mat3::from_axis_angle(Vec3::new(1.0, 2.0, 2.0) / 3.0, degrees.to_radians()),
            ..a
        };
        // f32 rotations: measured worst 1.5e-4 deg (at 1 and 179, where acos is steep); bound 10x.
        let err = (turn_degrees(&a, &b) - degrees as f64).abs();
        assert!(err < 1.5e-3, "{degrees}: {err}");
    }
}

#[test]
fn a_smooth_orbit_has_no_sharp_turn_and_a_folded_one_has_one_per_fold_boundary() {
    let smooth = orbit(60, 9.0, 0..0);
    assert!(sharp_turns(&smooth).is_empty());
    let n = names(60);
    let n: Vec<&str> = n.iter().map(String::as_str).collect();
    assert_eq!(folded_registration_warning(&n, &smooth), None);
    // Frames 20..40 folded: sharp turns at 19 -> 20 and 39 -> 40, each 180 - 9 degrees.
    let folded = orbit(60, 9.0, 20..40);
    let turns = sharp_turns(&folded);
    assert_eq!(turns.iter().map(|t| t.index).collect::<Vec<_>>(), vec![19, 39]);
    for t in &turns {
        assert!((t.degrees - 171.0).abs() < 0.01, "{}", t.degrees);
    }
    let w = folded_registration_warning(&n, &folded).expect("a warning");
    assert!(w.starts_with("2 of 59 consecutive image pairs"), "{w}");
    assert!(
        w.contains("0019.jpg -> 0020.jpg by 171 deg, 0039.jpg -> 0040.jpg by 171 deg"),
        "{w}"
    );
}

#[test]
fn photographs_in_no_order_get_no_warning() {
    // Every other frame from the far side: half the pairs turn sharply, so these are not frames
    // of one video in order, and the check stays silent.
    let cams: Vec<Camera> = orbit(40, 9.0, 0..0)
        .into_iter()
        .enumerate()
        .map(|(i, c)| if i % 2 == 1 { orbit(1, 0.0, 0..1)[0] } else { c })
        .collect();
    let n = names(40);
    let n: Vec<&str> = n.iter().map(String::as_str).collect();
    assert!(sharp_turns(&cams).len() * MAX_SHARP_SHARE > 39);
    assert_eq!(folded_registration_warning(&n, &cams), None);
    // One sharp turn among few frames still speaks (the share is counted over at least ten).
    let few = orbit(6, 9.0, 3..6);
    let n = names(6);
    let n: Vec<&str> = n.iter().map(String::as_str).collect();
    assert!(folded_registration_warning(&n, &few).is_some());
}
