//! The embedded demo scene: a small analytic world rendered by an independent ray tracer.
//!
//! The scene needs no data folder, so the crate's main job can run on a fresh machine. It is
//! deliberately *not* rendered with billboards: the images come from exact ray-object
//! intersections (a checkered floor disc, textured spheres and a box, Lambert shading with one
//! directional light plus ambient), so a trained billboard model is judged against an
//! independent ground truth.
//!
//! Conventions: world y is up; the objects sit on the floor `y = 0` around the origin; cameras
//! are on a ring of radius ≈ 4 at height ≈ 1.2-2.2 looking at `(0, 0.5, 0)`, in the crate's
//! OpenCV camera frame (see [`crate::camera`]). Colours are linear RGB in `[0, 1]`.

use crate::camera::Camera;
use crate::rng::Rng;
use glam::Vec3;

pub mod street;
pub mod surface;

/// One rendered view of the demo scene.
#[derive(Clone, Debug)]
pub struct DemoView {
    /// The pinhole camera (no distortion).
    pub camera: Camera,
    /// Interleaved RGB, row-major, `width · height · 3` values in `[0, 1]`.
    pub rgb: Vec<f32>,
}

/// The demo data set: train and test views, a surface point cloud with colours (standing in for
/// structure-from-motion points), and the background colour seen by rays that hit nothing.
#[derive(Clone, Debug)]
pub struct DemoScene {
    /// Views to train on.
    pub train: Vec<DemoView>,
    /// Held-out views (interleaved on the same ring, never trained on).
    pub test: Vec<DemoView>,
    /// Points sampled on the visible surfaces.
    pub points: Vec<Vec3>,
    /// Shaded colour of each point as seen from above (linear RGB, `[0, 1]`).
    pub colours: Vec<[f32; 3]>,
    /// Colour of rays that miss every object.
    pub background: [f32; 3],
}

/// Settings of the demo generator.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DemoConfig {
    /// Image width and height in pixels (square images).
    pub resolution: u32,
    /// Number of training views.
    pub train_views: usize,
    /// Number of test views.
    pub test_views: usize,
    /// Number of surface points in the point cloud.
    pub points: usize,
    /// Seed for the camera jitter and the point sampling.
    pub seed: u64,
}

impl Default for DemoConfig {
    fn default() -> Self {
        Self {
            resolution: 96,
            train_views: 32,
            test_views: 8,
            points: 3000,
            seed: 0,
        }
    }
}

/// Background colour of the demo world (a pale sky grey).
pub const DEMO_BACKGROUND: [f32; 3] = [0.85, 0.88, 0.92];

const FLOOR_RADIUS: f32 = 2.6;
const LOOK_AT: Vec3 = Vec3::new(0.0, 0.5, 0.0);

/// What the ground is: the demo's disc, or the street's strip.
#[derive(Clone, Copy, Debug)]
enum Floor {
    /// `x² + z² ≤ radius²`.
    Disc { radius: f32 },
    /// `x₀ ≤ x ≤ x₁`, `z₀ ≤ z ≤ z₁`.
    Strip { x: [f32; 2], z: [f32; 2] },
}

impl Floor {
    fn contains(&self, p: Vec3) -> bool {
        match *self {
            Floor::Disc { radius } => p.x * p.x + p.z * p.z <= radius * radius,
            Floor::Strip { x, z } => (x[0]..=x[1]).contains(&p.x) && (z[0]..=z[1]).contains(&p.z),
        }
    }
}

/// A world to ray-trace: a floor on `y = 0` and objects on it.
#[derive(Clone, Debug)]
struct World {
    floor: Floor,
    objects: Vec<Object>,
}

/// The demo world: the floor disc, two spheres and a box around the origin.
fn demo_world() -> World {
    World {
        floor: Floor::Disc { radius: FLOOR_RADIUS },
        objects: OBJECTS.to_vec(),
    }
}

#[derive(Clone, Copy, Debug)]
enum Object {
    Floor,
    Sphere {
        centre: Vec3,
        radius: f32,
        base: Vec3,
        stripe: Vec3,
        bands: f32,
    },
    Box {
        min: Vec3,
        max: Vec3,
    },
}

const OBJECTS: [Object; 4] = [
    Object::Floor,
    Object::Sphere {
        centre: Vec3::new(-0.7, 0.55, 0.2),
        radius: 0.55,
        base: Vec3::new(0.85, 0.25, 0.2),
        stripe: Vec3::new(0.95, 0.85, 0.3),
        bands: 6.0,
    },
    Object::Sphere {
        centre: Vec3::new(0.75, 0.35, -0.45),
        radius: 0.35,
        base: Vec3::new(0.2, 0.45, 0.85),
        stripe: Vec3::new(0.9, 0.9, 0.95),
        bands: 4.0,
    },
    Object::Box {
        min: Vec3::new(0.15, 0.0, 0.35),
        max: Vec3::new(0.85, 0.8, 1.05),
    },
];

struct Hit {
    t: f32,
    point: Vec3,
    normal: Vec3,
    object: usize,
}

fn intersect_object(object: &Object, floor: &Floor, origin: Vec3, dir: Vec3) -> Option<(f32, Vec3)> {
    const T_MIN: f32 = 1e-4;
    match *object {
        Object::Floor => {
            if dir.y.abs() < 1e-8 {
                return None;
            }
            let t = -origin.y / dir.y;
            let p = origin + t * dir;
            (t > T_MIN && floor.contains(p)).then_some((t, Vec3::Y))
        }
        Object::Sphere { centre, radius, .. } => {
            let oc = origin - centre;
            let b = oc.dot(dir);
            let c = oc.length_squared() - radius * radius;
            let disc = b * b - c;
            if disc < 0.0 {
                return None;
            }
            let s = disc.sqrt();
            let t = if -b - s > T_MIN { -b - s } else { -b + s };
            (t > T_MIN).then(|| (t, (origin + t * dir - centre) / radius))
        }
        Object::Box { min, max } => {
            let inv = dir.recip();
            let t0 = (min - origin) * inv;
            let t1 = (max - origin) * inv;
            let tmin = t0.min(t1);
            let tmax = t0.max(t1);
            let near = tmin.max_element();
            let far = tmax.min_element();
            if near > far || far < T_MIN {
                return None;
            }
            let t = if near > T_MIN { near } else { far };
            let p = origin + t * dir;
            // The face whose slab bound equals t gives the normal.
            let centre = (min + max) * 0.5;
            let half = (max - min) * 0.5;
            let local = (p - centre) / half;
            let a = local.abs();
            let normal = if a.x >= a.y && a.x >= a.z {
                Vec3::new(local.x.signum(), 0.0, 0.0)
            } else if a.y >= a.z {
                Vec3::new(0.0, local.y.signum(), 0.0)
            } else {
                Vec3::new(0.0, 0.0, local.z.signum())
            };
            Some((t, normal))
        }
    }
}

fn trace(world: &World, origin: Vec3, dir: Vec3) -> Option<Hit> {
    let mut best: Option<Hit> = None;
    for (i, object) in world.objects.iter().enumerate() {
        if let Some((t, normal)) = intersect_object(object, &world.floor, origin, dir)
            && best.as_ref().is_none_or(|b| t < b.t)
        {
            best = Some(Hit {
                t,
                point: origin + t * dir,
                normal,
                object: i,
            });
        }
    }
    best
}

fn albedo(world: &World, hit: &Hit) -> Vec3 {
    let p = hit.point;
    match world.objects[hit.object] {
        Object::Floor => {
            let check = ((p.x * 2.5).floor() + (p.z * 2.5).floor()) as i64 & 1;
            let ring = ((p.x * p.x + p.z * p.z).sqrt() * 1.5).fract() < 0.08;
            if ring {
                Vec3::new(0.3, 0.3, 0.3)
            } else if check == 0 {
                Vec3::new(0.82, 0.78, 0.7)
            } else {
                Vec3::new(0.35, 0.5, 0.35)
            }
        }
        Object::Sphere {
            centre,
            base,
            stripe,
            bands,
            ..
        } => {
            let d = (p - centre).normalize();
            let lon = d.z.atan2(d.x);
            let s = (lon * bands).sin() * (d.y * bands).cos();
            if s > 0.2 { stripe } else { base }
        }
        Object::Box { min, max } => {
            let local = (p - min) / (max - min);
            let n = hit.normal;
            // Each face gets its own colour and a grid of lines.
            let face = if n.x.abs() > 0.5 {
                Vec3::new(0.9, 0.6, 0.2)
            } else if n.y.abs() > 0.5 {
                Vec3::new(0.95, 0.95, 0.9)
            } else {
                Vec3::new(0.55, 0.3, 0.65)
            };
            let grid = |c: f32| ((c * 4.0).fract() - 0.5).abs() > 0.44;
            let (a, b) = if n.x.abs() > 0.5 {
                (local.y, local.z)
            } else if n.y.abs() > 0.5 {
                (local.x, local.z)
            } else {
                (local.x, local.y)
            };
            if grid(a) || grid(b) { face * 0.35 } else { face }
        }
    }
}

fn light_direction() -> Vec3 {
    Vec3::new(0.5, 1.0, 0.3).normalize()
}

fn shade(world: &World, hit: &Hit) -> Vec3 {
    let l = light_direction();
    let lambert = hit.normal.dot(l).max(0.0);
    // Hard shadow towards the light.
    let shadowed = trace(world, hit.point + hit.normal * 1e-3, l).is_some();
    let direct = if shadowed { 0.0 } else { lambert };
    (albedo(world, hit) * (0.35 + 0.65 * direct)).clamp(Vec3::ZERO, Vec3::ONE)
}

/// Renders one view of the demo world with one ray through every pixel centre (no
/// anti-aliasing).
pub fn render_view(camera: &Camera) -> Vec<f32> {
    render_world(&demo_world(), camera)
}

/// Renders one view of `world` (as [`render_view`]).
fn render_world(world: &World, camera: &Camera) -> Vec<f32> {
    let (w, h) = (camera.width as usize, camera.height as usize);
    let r_c2w = camera.rotation.transpose();
    let origin = camera.centre();
    let mut rgb = vec![0.0f32; w * h * 3];
    for j in 0..h {
        for i in 0..w {
            let x = (i as f32 + 0.5 - camera.cx) / camera.fx;
            let y = (j as f32 + 0.5 - camera.cy) / camera.fy;
            let dir = (r_c2w * Vec3::new(x, y, 1.0)).normalize();
            let c = trace(world, origin, dir).map_or(Vec3::from_array(DEMO_BACKGROUND), |hit| shade(world, &hit));
            rgb[(j * w + i) * 3..(j * w + i) * 3 + 3].copy_from_slice(&c.to_array());
        }
    }
    rgb
}

fn ring_camera(index: usize, count: usize, offset: f32, rng: &mut Rng, resolution: u32) -> Camera {
    let angle = std::f32::consts::TAU * (index as f32 + offset) / count as f32 + rng.range(-0.05, 0.05);
    let radius = 4.0 + rng.range(-0.3, 0.3);
    let height = 1.2 + rng.range(0.0, 1.0);
    let eye = Vec3::new(radius * angle.cos(), height, radius * angle.sin());
    let focal = resolution as f32 * 1.1;
    Camera::look_at(eye, LOOK_AT, Vec3::Y, focal, focal, resolution, resolution)
}

/// Samples `n` points on the surfaces, uniformly per object area (approximately), with the
/// shaded colour seen from straight above the point's normal.
fn surface_points(n: usize, rng: &mut Rng) -> (Vec<Vec3>, Vec<[f32; 3]>) {
    surface_points_of(&demo_world(), Vec3::ZERO, 0.0, n, rng)
}

/// [`surface_points`] of `world`, the rays shot from around `centre + (s, 0, 0)`, `s` uniform
/// in `±spread` (the street's length).
fn surface_points_of(world: &World, centre: Vec3, spread: f32, n: usize, rng: &mut Rng) -> (Vec<Vec3>, Vec<[f32; 3]>) {
    let mut points = Vec::with_capacity(n);
    let mut colours = Vec::with_capacity(n);
    while points.len() < n {
        // Shoot random rays from a random point on a sphere of radius 5 towards the scene: the
        // first hit is a visible surface point, as a structure-from-motion point would be.
        // No draw without a spread: the demo's own points stay those of its sequence.
        let along = if spread > 0.0 { rng.range(-spread, spread) } else { 0.0 };
        let shift = centre + Vec3::new(along, 0.0, 0.0);
        let theta = rng.range(0.0, std::f32::consts::TAU);
        let y = rng.range(0.15, 1.0);
        let r = (1.0 - y * y).sqrt();
        let eye = shift + Vec3::new(r * theta.cos(), y, r * theta.sin()) * 5.0;
        let target = shift + Vec3::new(rng.range(-2.0, 2.0), rng.range(0.0, 1.0), rng.range(-2.0, 2.0));
        if let Some(hit) = trace(world, eye, (target - eye).normalize()) {
            colours.push(shade(world, &hit).to_array());
            points.push(hit.point);
        }
    }
    (points, colours)
}

/// Generates the demo data set. Deterministic for a given config.
///
/// ```
/// use bbsplat::demo::{generate, DemoConfig};
/// let scene = generate(&DemoConfig { resolution: 16, train_views: 3, test_views: 1, points: 10, seed: 1 });
/// assert_eq!(scene.train.len(), 3);
/// assert_eq!(scene.train[0].rgb.len(), 16 * 16 * 3);
/// assert_eq!(scene.points.len(), 10);
/// ```
pub fn generate(config: &DemoConfig) -> DemoScene {
    let mut rng = Rng::new(config.seed);
    let total = config.train_views + config.test_views;
    // Interleave test views on the ring: every k-th slot is a test view.
    let mut train = Vec::with_capacity(config.train_views);
    let mut test = Vec::with_capacity(config.test_views);
    let stride = if config.test_views == 0 {
        usize::MAX
    } else {
        total.div_ceil(config.test_views)
    };
    for i in 0..total {
        let camera = ring_camera(i, total, 0.0, &mut rng, config.resolution);
        let view = DemoView {
            camera,
            rgb: Vec::new(),
        };
        if i % stride == stride / 2 && test.len() < config.test_views {
            test.push(view);
        } else if train.len() < config.train_views {
            train.push(view);
        } else {
            test.push(view);
        }
    }
    use rayon::prelude::*;
    train
        .par_iter_mut()
        .chain(test.par_iter_mut())
        .for_each(|v| v.rgb = render_view(&v.camera));
    let (points, colours) = surface_points(config.points, &mut rng);
    DemoScene {
        train,
        test,
        points,
        colours,
        background: DEMO_BACKGROUND,
    }
}

/// Writes the demo scene as a COLMAP dataset: `dir/sparse/0/{cameras,images,points3D}.bin`
/// (one PINHOLE camera per view, w2c poses, the surface points with 8-bit colours) and
/// `dir/images/view_NNN.png` (8-bit). Views are written in ring order, train and test together,
/// so a loader's own split (every 8th view by default) decides which are held out.
///
/// # Errors
///
/// [`SceneError`](crate::scene::SceneError) when a file cannot be written.
pub fn export_colmap(scene: &DemoScene, dir: &std::path::Path) -> Result<(), crate::scene::SceneError> {
    let mut views: Vec<&DemoView> = scene.train.iter().chain(&scene.test).collect();
    // Ring order: sort by the camera's azimuth so names follow the ring.
    views.sort_by(|a, b| {
        let az = |v: &DemoView| {
            let c = v.camera.centre();
            c.z.atan2(c.x)
        };
        az(a).total_cmp(&az(b))
    });
    write_colmap_views(dir, &views, &scene.points, &scene.colours)
}

/// Writes `views` in their order as `dir/images/view_NNN.png` and the COLMAP model of them and
/// of the points ([`write_colmap_model`]).
fn write_colmap_views(
    dir: &std::path::Path,
    views: &[&DemoView],
    points: &[Vec3],
    colours: &[[f32; 3]],
) -> Result<(), crate::scene::SceneError> {
    use crate::scene::SceneError;
    let images_dir = dir.join("images");
    std::fs::create_dir_all(&images_dir).map_err(|e| SceneError::io(&images_dir, e))?;
    let mut named = Vec::with_capacity(views.len());
    for (i, v) in views.iter().enumerate() {
        let c = &v.camera;
        let name = format!("view_{i:03}.png");
        let bytes: Vec<u8> = v.rgb.iter().map(|&x| crate::loss::psnr::quantize_u8(x)).collect();
        let path = images_dir.join(&name);
        image::save_buffer(&path, &bytes, c.width, c.height, image::ColorType::Rgb8)
            .map_err(|e| SceneError::io(&path, std::io::Error::other(e)))?;
        named.push((name, *c));
    }
    write_colmap_model(dir, &named, points, colours)
}

/// Writes `dir/sparse/0/{cameras,images,points3D}.bin`: one PINHOLE camera per named view (w2c
/// pose), and the points with their colours quantised to 8 bits.
fn write_colmap_model(
    dir: &std::path::Path,
    views: &[(String, Camera)],
    points: &[Vec3],
    colours: &[[f32; 3]],
) -> Result<(), crate::scene::SceneError> {
    use crate::scene::SceneError;
    use crate::scene::colmap::{CameraModel, ColmapCamera, ColmapImage, ColmapModel, ColmapPoint3D};
    let mut model = ColmapModel {
        cameras: Vec::new(),
        images: Vec::new(),
        points: Vec::new(),
    };
    for (i, (name, c)) in views.iter().enumerate() {
        model.cameras.push(ColmapCamera {
            id: i as u32 + 1,
            model: CameraModel::Pinhole,
            width: c.width as u64,
            height: c.height as u64,
            params: vec![c.fx as f64, c.fy as f64, c.cx as f64, c.cy as f64],
        });
        let q = glam::Quat::from_mat3(&c.rotation).normalize();
        model.images.push(ColmapImage {
            id: i as u32 + 1,
            qvec: [q.w as f64, q.x as f64, q.y as f64, q.z as f64],
            tvec: c.translation.to_array().map(f64::from),
            camera_id: i as u32 + 1,
            name: name.clone(),
            points2d: Vec::new(),
        });
    }
    for (i, (p, col)) in points.iter().zip(colours).enumerate() {
        model.points.push(ColmapPoint3D {
            id: i as u64 + 1,
            xyz: p.to_array().map(f64::from),
            rgb: col.map(crate::loss::psnr::quantize_u8),
            error: 0.0,
            track: Vec::new(),
        });
    }
    let sparse = dir.join("sparse/0");
    std::fs::create_dir_all(&sparse).map_err(|e| SceneError::io(&sparse, e))?;
    crate::scene::colmap_binary::write_model(&model, &sparse)
}

/// Camera `i` of `n` on a dome: a spiral over heights 0.6 to 3 at radius 3.5 to 4.5, looking at
/// the demo's objects (the golden angle apart: no two photos alike).
fn dome_camera(i: usize, n: usize, width: u32, height: u32) -> Camera {
    let t = (i as f32 + 0.5) / n as f32;
    let angle = i as f32 * 2.399_963;
    let radius = 3.5 + ((i * 7919) % 101) as f32 / 100.0;
    let eye = Vec3::new(radius * angle.cos(), 0.6 + 2.4 * t, radius * angle.sin());
    let focal = width as f32 * 0.9;
    Camera::look_at(eye, Vec3::new(0.0, 0.4, 0.0), Vec3::Y, focal, focal, width, height)
}

/// Writes a capture of the demo world as large as a user's, to measure memory and loading at
/// the sizes of real captures (docs/scene.md, "Large captures"): `count` JPEG photographs
/// (quality 90) of `width × height` named `images/photo_NNNNN.jpg` on a dome of cameras
/// ([`render_view`]), a COLMAP model in `sparse/0` (one PINHOLE camera per photo) and 20 000 of
/// the demo's surface points. Each photo is rendered, encoded and dropped in turn (in
/// parallel), so the memory taken is a few photos'.
///
/// # Errors
///
/// [`SceneError`](crate::scene::SceneError) when a file cannot be written.
pub fn export_capture(
    dir: &std::path::Path,
    count: usize,
    width: u32,
    height: u32,
) -> Result<(), crate::scene::SceneError> {
    use crate::scene::SceneError;
    use rayon::prelude::*;
    let images = dir.join("images");
    std::fs::create_dir_all(&images).map_err(|e| SceneError::io(&images, e))?;
    let names: Vec<String> = (0..count).map(|i| format!("photo_{i:05}.jpg")).collect();
    names.par_iter().enumerate().try_for_each(|(i, name)| {
        let camera = dome_camera(i, count, width, height);
        let bytes: Vec<u8> = render_view(&camera)
            .iter()
            .map(|&c| crate::loss::psnr::quantize_u8(c))
            .collect();
        let path = images.join(name);
        let file = std::fs::File::create(&path).map_err(|e| SceneError::io(&path, e))?;
        image::codecs::jpeg::JpegEncoder::new_with_quality(std::io::BufWriter::new(file), 90)
            .encode(&bytes, width, height, image::ExtendedColorType::Rgb8)
            .map_err(|e| SceneError::io(&path, std::io::Error::other(e)))
    })?;
    let (points, colours) = surface_points(20_000, &mut Rng::new(0));
    let named: Vec<(String, Camera)> = names
        .into_iter()
        .enumerate()
        .map(|(i, name)| (name, dome_camera(i, count, width, height)))
        .collect();
    write_colmap_model(dir, &named, &points, &colours)
}
