//! The street: the demo's objects repeated along a line, seen from cameras on two tracks beside
//! it (8 apart: from 5 copies on, the street is longer than it is wide, as
//! [`crate::blocks::GroundFrame`] needs to find its direction), so that a camera sees about one copy and blocks of the street really see different views
//! (the test scene of block-wise training, [`crate::blocks`], docs/cluster.md).
//!
//! Copy `c` of the demo's two spheres and box stands `c · spacing` along +x, its spheres'
//! colours rotated by `c` so that no two copies look alike, on a floor strip from 2 before the
//! first copy to 2 past the last and 2.2 to either side. The cameras stand on the tracks
//! `z = ±4` at heights 1.2-1.8, evenly along the street from 1 before its first copy to 1 past
//! its last (jittered by the seed), each looking across the street at height 0.5; the focal
//! length is 1.1 × the image side, as the demo's, so a view spans about ±1.8 along the street.
//! Images are ray-traced as the demo's ([`super::render_view`]); the points are the visible
//! surfaces' as the demo samples them.
//!
//! ```
//! use bbsplat::demo::street::{StreetConfig, generate_street};
//! let street = generate_street(&StreetConfig { copies: 2, resolution: 16, views_per_copy: 2, points: 50, seed: 0 , ..StreetConfig::default() });
//! assert_eq!(street.train.len(), 2 * 2 * 2); // two tracks
//! assert!(street.train.iter().all(|v| v.rgb.len() == 16 * 16 * 3));
//! ```

use super::{DemoScene, DemoView, Floor, OBJECTS, Object, World, render_world, surface_points_of, write_colmap_views};
use crate::camera::Camera;
use crate::rng::Rng;
use glam::Vec3;

/// Settings of the street.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StreetConfig {
    /// Copies of the demo's objects along the street.
    pub copies: usize,
    /// Distance between two copies, world units.
    pub spacing: f32,
    /// Image side in pixels (square images).
    pub resolution: u32,
    /// Cameras per copy on each track.
    pub views_per_copy: usize,
    /// Surface points (the SfM points of the COLMAP export).
    pub points: usize,
    /// Seed of the cameras' jitter and of the points.
    pub seed: u64,
}

impl Default for StreetConfig {
    fn default() -> Self {
        Self {
            copies: 6,
            spacing: 3.0,
            resolution: 64,
            views_per_copy: 8,
            points: 4000,
            seed: 0,
        }
    }
}

fn street_world(config: &StreetConfig) -> World {
    let length = (config.copies.max(1) - 1) as f32 * config.spacing;
    let mut objects = vec![Object::Floor];
    let sphere_colours: Vec<(Vec3, Vec3)> = OBJECTS
        .iter()
        .filter_map(|o| match *o {
            Object::Sphere { base, stripe, .. } => Some((base, stripe)),
            _ => None,
        })
        .chain([(Vec3::new(0.3, 0.7, 0.3), Vec3::new(0.95, 0.9, 0.8))])
        .collect();
    for c in 0..config.copies {
        let d = Vec3::new(c as f32 * config.spacing, 0.0, 0.0);
        let mut sphere = 0;
        for object in OBJECTS {
            match object {
                Object::Floor => {}
                Object::Sphere {
                    centre, radius, bands, ..
                } => {
                    let (base, stripe) = sphere_colours[(sphere + c) % sphere_colours.len()];
                    sphere += 1;
                    objects.push(Object::Sphere {
                        centre: centre + d,
                        radius,
                        base,
                        stripe,
                        bands,
                    });
                }
                Object::Box { min, max } => objects.push(Object::Box {
                    min: min + d,
                    max: max + d,
                }),
            }
        }
    }
    World {
        floor: Floor::Strip {
            x: [-2.0, length + 2.0],
            z: [-2.2, 2.2],
        },
        objects,
    }
}

fn street_cameras(config: &StreetConfig) -> Vec<Camera> {
    let length = (config.copies.max(1) - 1) as f32 * config.spacing;
    let per_track = config.views_per_copy * config.copies;
    let mut rng = Rng::new(config.seed);
    let focal = config.resolution as f32 * 1.1;
    let mut cameras = Vec::with_capacity(2 * per_track);
    for side in [1.0f32, -1.0] {
        for i in 0..per_track {
            let t = (i as f32 + 0.5) / per_track as f32;
            let x = -1.0 + t * (length + 2.0) + rng.range(-0.05, 0.05);
            let eye = Vec3::new(x, 1.2 + rng.range(0.0, 0.6), side * 4.0);
            let target = Vec3::new(x + rng.range(-0.2, 0.2), 0.5, 0.0);
            cameras.push(Camera::look_at(
                eye,
                target,
                Vec3::Y,
                focal,
                focal,
                config.resolution,
                config.resolution,
            ));
        }
    }
    cameras
}

/// The street's views (all in `train`, `test` empty: a loader's split holds views out), points
/// and background. Deterministic for a given config.
pub fn generate_street(config: &StreetConfig) -> DemoScene {
    use rayon::prelude::*;
    let world = street_world(config);
    let train: Vec<DemoView> = street_cameras(config)
        .into_par_iter()
        .map(|camera| DemoView {
            rgb: render_world(&world, &camera),
            camera,
        })
        .collect();
    let length = (config.copies.max(1) - 1) as f32 * config.spacing;
    let mut rng = Rng::new(config.seed ^ 0x5eed);
    let (points, colours) = surface_points_of(
        &world,
        Vec3::new(0.5 * length, 0.0, 0.0),
        0.5 * length + 1.0,
        config.points,
        &mut rng,
    );
    DemoScene {
        train,
        test: Vec::new(),
        points,
        colours,
        background: super::DEMO_BACKGROUND,
    }
}

/// Writes the street as a COLMAP dataset (as [`super::export_colmap`]), its views in order
/// along the street (the two tracks' cameras mixed as their jittered positions fall), so that
/// the loader's every-8th split holds out views all along both tracks.
///
/// # Errors
///
/// [`SceneError`](crate::scene::SceneError) when a file cannot be written.
pub fn export_street(config: &StreetConfig, dir: &std::path::Path) -> Result<(), crate::scene::SceneError> {
    let street = generate_street(config);
    let mut views: Vec<&DemoView> = street.train.iter().collect();
    views.sort_by(|a, b| a.camera.centre().x.total_cmp(&b.camera.centre().x));
    write_colmap_views(dir, &views, &street.points, &street.colours)
}
