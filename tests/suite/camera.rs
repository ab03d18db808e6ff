//! Cameras: the look-at constructor's OpenCV axes and the OpenGL camera-to-world import.

use bbsplat::camera::Camera;
use glam::Vec3;

#[test]
fn look_at_axes_are_opencv() {
    let cam = Camera::look_at(Vec3::new(0.0, 0.0, -5.0), Vec3::ZERO, Vec3::Y, 50.0, 50.0, 100, 100);
    // A point above the target (world +y) appears in the upper half of the image (smaller y).
    let (_, y) = cam.project(Vec3::new(0.0, 1.0, 0.0)).unwrap();
    assert!(y < 50.0);
    // A point to the camera's right appears at larger x.
    let right = cam.rotation.row(0);
    let (x, _) = cam.project(right).unwrap();
    assert!(x > 50.0);
    assert!((cam.centre() - Vec3::new(0.0, 0.0, -5.0)).length() < 1e-6);
}

#[test]
fn opengl_c2w_round_trip() {
    // Camera at (0, 0, 4) looking at the origin along -z in OpenGL axes: identity rotation.
    let c2w = [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 4.0],
        [0.0, 0.0, 0.0, 1.0],
    ];
    let cam = Camera::from_c2w_opengl(c2w, 100.0, 100.0, 50.0, 50.0, 100, 100);
    assert!((cam.centre() - Vec3::new(0.0, 0.0, 4.0)).length() < 1e-6);
    let v = cam.world_to_view(Vec3::ZERO);
    assert!((v - Vec3::new(0.0, 0.0, 4.0)).length() < 1e-6);
    // World +y (up) maps to image up (smaller pixel y).
    let (_, y) = cam.project(Vec3::new(0.0, 0.5, 0.0)).unwrap();
    assert!(y < 50.0);
}
