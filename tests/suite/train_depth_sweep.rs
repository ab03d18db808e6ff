//! The plane sweep of `train::depth_sweep`: the depth of a textured plane found within one
//! depth step, no distinct depth on an even surface, the neighbour rule, and degenerate input.

use bbsplat::camera::Camera;
use bbsplat::scene::Image;
use bbsplat::train::depth_sweep::{SweepConfig, SweepImage, nearest_views, sweep_pixel};
use glam::Vec3;

/// A camera and its image, as a sweep reads them.
struct View {
    camera: Camera,
    image: Image,
}

impl SweepImage for View {
    fn camera(&self) -> &Camera {
        &self.camera
    }
    fn rgb(&self, x: u32, y: u32) -> [f32; 3] {
        self.image.pixel_f32(x, y)
    }
}

/// The camera centres of `views`.
fn centres(views: &[View]) -> Vec<Vec3> {
    views.iter().map(|v| v.camera.centre()).collect()
}

const W: u32 = 96;
const H: u32 = 72;
const F: f32 = 80.0;

/// The ground plane `y = 0`'s colour at `(x, z)`: smooth, not periodic at the patch scale.
fn ground(x: f32, z: f32) -> [f32; 3] {
    [
        0.5 + 0.25 * (5.3 * x + 1.1).sin() * (3.7 * z).cos() + 0.2 * (4.5 * (x + 0.7 * z)).sin(),
        0.5 + 0.3 * (7.9 * z - 0.4 * x).sin() * (2.3 * x).cos() + 0.15 * (4.0 * (z - 0.3 * x)).cos(),
        0.5 + 0.2 * (4.1 * (x - z)).sin() + 0.25 * (3.0 * x * z).sin(),
    ]
}

/// Sky colour: one even colour.
const SKY: [f32; 3] = [0.3, 0.5, 0.9];

/// A camera's view of the plane (or of an even `fill` colour everywhere when given).
fn render(cam: &Camera, fill: Option<[f32; 3]>) -> Image {
    let to_world = cam.rotation.transpose();
    let centre = cam.centre();
    let mut bytes = Vec::with_capacity((W * H * 3) as usize);
    for y in 0..H {
        for x in 0..W {
            let d = to_world
                * Vec3::new(
                    (x as f32 + 0.5 - cam.cx) / cam.fx,
                    (y as f32 + 0.5 - cam.cy) / cam.fy,
                    1.0,
                );
            let rgb = fill.unwrap_or_else(|| {
                if d.y < -1e-3 {
                    let t = -centre.y / d.y;
                    let p = centre + d * t;
                    ground(p.x, p.z)
                } else {
                    SKY
                }
            });
            bytes.extend(rgb.map(|c| (c.clamp(0.0, 1.0) * 255.0).round() as u8));
        }
    }
    Image::new(W, H, bytes).unwrap()
}

/// `n` cameras on an arc of radius 4 at height 2.5 looking at the origin.
fn views(n: usize, fill: Option<[f32; 3]>) -> Vec<View> {
    (0..n)
        .map(|i| {
            let a = 0.25 * i as f32;
            let eye = Vec3::new(4.0 * a.cos(), 2.5, 4.0 * a.sin());
            let camera = Camera::look_at(eye, Vec3::ZERO, Vec3::Y, F, F, W, H);
            View {
                image: render(&camera, fill),
                camera,
            }
        })
        .collect()
}

/// View depth of the plane at pixel `(x, y)` of `cam` (the ray through the pixel centre).
fn plane_depth(cam: &Camera, x: u32, y: u32) -> f32 {
    let d = cam.rotation.transpose() * Vec3::new((x as f32 + 0.5 - cam.cx) / F, (y as f32 + 0.5 - cam.cy) / F, 1.0);
    let t = -cam.centre().y / d.y;
    cam.world_to_view(cam.centre() + d * t).z
}

#[test]
fn a_pixel_sweep_finds_the_plane_depth_within_a_step() {
    let views = views(8, None);
    let config = SweepConfig::default();
    let neighbours = nearest_views(&centres(&views), 3, config.neighbours);
    // Views 2 and 4 are one arc step away, 1 and 5 two (equal up to rounding).
    let mut near_pair = neighbours[..2].to_vec();
    near_pair.sort();
    let mut far_pair = neighbours[2..].to_vec();
    far_pair.sort();
    assert_eq!((near_pair, far_pair), (vec![2, 4], vec![1, 5]), "{neighbours:?}");
    let cam = &views[3].camera;
    for &(x, y) in &[(48u32, 50u32), (30, 60), (70, 45), (20, 40), (60, 66)] {
        let truth = plane_depth(cam, x, y);
        // A wrong guess 30 % too far, searched over [guess / 2, guess * 2] as placement does.
        let guess = 1.3 * truth;
        let (near, far) = (guess / 2.0, guess * 2.0);
        let step = (far / near).powf(1.0 / (config.depths - 1) as f32);
        let sweep = sweep_pixel(&views, 3, &neighbours, x, y, near, far, &config).unwrap();
        assert!(sweep.distinct(), "pixel ({x}, {y}): {sweep:?}");
        // Measured: within 0.5 of a step (the grid point nearest the truth) at every pixel here.
        let ratio = (sweep.depth / truth).max(truth / sweep.depth);
        assert!(
            ratio <= step,
            "pixel ({x}, {y}): depth {} against {truth} (step {step})",
            sweep.depth
        );
        assert!((cam.world_to_view(sweep.point).z - sweep.depth).abs() < 1e-4 * sweep.depth);
    }
}

#[test]
fn an_even_surface_or_the_sky_has_no_distinct_depth() {
    let config = SweepConfig::default();
    let even = views(8, Some([0.6, 0.6, 0.6]));
    let neighbours = nearest_views(&centres(&even), 3, config.neighbours);
    let sweep = sweep_pixel(&even, 3, &neighbours, 48, 50, 2.0, 8.0, &config).unwrap();
    assert!(!sweep.distinct(), "{sweep:?}");
    assert_eq!(sweep.cost, 0.0);
    // The sky of the textured scene: its top rows.
    let views = views(8, None);
    let sweep = sweep_pixel(&views, 3, &neighbours, 48, 3, 2.0, 8.0, &config).unwrap();
    assert!(!sweep.distinct(), "{sweep:?}");
}

#[test]
fn degenerate_sweeps_find_nothing() {
    let views = views(4, None);
    let config = SweepConfig::default();
    let all = [0, 2, 3];
    // The patch does not fit in the image.
    assert_eq!(sweep_pixel(&views, 1, &all, 1, 30, 2.0, 8.0, &config), None);
    assert_eq!(sweep_pixel(&views, 1, &all, 40, H - 2, 2.0, 8.0, &config), None);
    // Not a positive range.
    assert_eq!(sweep_pixel(&views, 1, &all, 48, 50, 0.0, 8.0, &config), None);
    assert_eq!(sweep_pixel(&views, 1, &all, 48, 50, 8.0, 2.0, &config), None);
    assert_eq!(sweep_pixel(&views, 1, &all, 48, 50, 2.0, f32::INFINITY, &config), None);
    // Fewer than two neighbours can never agree.
    assert_eq!(sweep_pixel(&views, 1, &[0], 48, 50, 2.0, 8.0, &config), None);
    // No depths.
    let none = SweepConfig { depths: 0, ..config };
    assert_eq!(sweep_pixel(&views, 1, &all, 48, 50, 2.0, 8.0, &none), None);
    // One depth: the geometric mean of the range.
    let one = SweepConfig { depths: 1, ..config };
    let sweep = sweep_pixel(&views, 1, &all, 48, 50, 2.0, 8.0, &one).unwrap();
    assert!((sweep.depth - 4.0).abs() < 1e-5, "{}", sweep.depth);
}

#[test]
fn neighbours_are_the_nearest_camera_centres() {
    let views = views(6, None);
    // An arc: from an end, the others in order of index distance.
    assert_eq!(nearest_views(&centres(&views), 0, 3), vec![1, 2, 3]);
    assert_eq!(nearest_views(&centres(&views), 5, 10), vec![4, 3, 2, 1, 0]);
    assert_eq!(nearest_views(&centres(&views), 2, 0), Vec::<usize>::new());
}
