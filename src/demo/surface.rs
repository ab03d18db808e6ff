//! The demo world's true surface as samples with normals, for measuring extracted meshes
//! ([`crate::mesh::chamfer`]).
//!
//! [`sample_true_surface`] draws points uniformly by area over every object of the demo (the
//! floor disc of radius 2.6, the two spheres, all six faces of the box), with their outward
//! normals; [`visible_from`] keeps those that at least one camera sees: in front of it, inside
//! its image, facing it, and not hidden by another object (the demo's own ray tracer, as the
//! images were made). Together they give the surface the training views show, which is what a
//! mesh fused from those views can recover.

use super::{FLOOR_RADIUS, OBJECTS, Object, demo_world, trace};
use crate::camera::Camera;
use crate::mesh::chamfer::SurfaceSamples;
use crate::rng::Rng;
use glam::Vec3;
use rayon::prelude::*;

/// One flat or round patch of the demo world to sample.
#[derive(Clone, Copy, Debug)]
enum Patch {
    Floor,
    Sphere(Vec3, f32),
    /// A box face: a corner, its two edge vectors and its outward normal.
    Face(Vec3, Vec3, Vec3, Vec3),
}

fn patches() -> Vec<(Patch, f32)> {
    let mut out = Vec::new();
    for object in OBJECTS {
        match object {
            Object::Floor => out.push((Patch::Floor, std::f32::consts::PI * FLOOR_RADIUS * FLOOR_RADIUS)),
            Object::Sphere { centre, radius, .. } => out.push((
                Patch::Sphere(centre, radius),
                4.0 * std::f32::consts::PI * radius * radius,
            )),
            Object::Box { min, max } => {
                let size = max - min;
                for axis in 0..3 {
                    let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
                    let (mut eu, mut ev) = (Vec3::ZERO, Vec3::ZERO);
                    eu[u] = size[u];
                    ev[v] = size[v];
                    for side in 0..2 {
                        let mut corner = min;
                        let mut normal = Vec3::ZERO;
                        corner[axis] = if side == 0 { min[axis] } else { max[axis] };
                        normal[axis] = if side == 0 { -1.0 } else { 1.0 };
                        out.push((Patch::Face(corner, eu, ev, normal), size[u] * size[v]));
                    }
                }
            }
        }
    }
    out
}

/// `count` points drawn uniformly by area over the whole demo world with their outward unit
/// normals (seeded, deterministic). Hidden parts (the floor under the objects, the box's
/// bottom) are included: [`visible_from`] removes them.
pub fn sample_true_surface(count: usize, seed: u64) -> SurfaceSamples {
    let patches = patches();
    let total: f32 = patches.iter().map(|p| p.1).sum();
    let mut rng = Rng::new(seed);
    let mut samples = SurfaceSamples::default();
    for _ in 0..count {
        let mut pick = rng.uniform() * total;
        let mut patch = patches[patches.len() - 1].0;
        for &(p, area) in &patches {
            if pick < area {
                patch = p;
                break;
            }
            pick -= area;
        }
        let (point, normal) = match patch {
            Patch::Floor => {
                let r = FLOOR_RADIUS * rng.uniform().sqrt();
                let theta = rng.range(0.0, std::f32::consts::TAU);
                (Vec3::new(r * theta.cos(), 0.0, r * theta.sin()), Vec3::Y)
            }
            Patch::Sphere(centre, radius) => {
                let z = rng.range(-1.0, 1.0);
                let phi = rng.range(0.0, std::f32::consts::TAU);
                let s = (1.0 - z * z).max(0.0).sqrt();
                let n = Vec3::new(s * phi.cos(), z, s * phi.sin());
                (centre + radius * n, n)
            }
            Patch::Face(corner, eu, ev, normal) => (corner + rng.uniform() * eu + rng.uniform() * ev, normal),
        };
        samples.points.push(point);
        samples.normals.push(normal);
    }
    samples
}

/// Whether `camera` sees the surface point `p` with outward normal `n`.
fn sees(camera: &Camera, p: Vec3, n: Vec3) -> bool {
    let eye = camera.centre();
    let to_eye = eye - p;
    if n.dot(to_eye) <= 0.0 || camera.world_to_view(p).z <= 0.0 {
        return false;
    }
    let Some((u, v)) = camera.project(p) else {
        return false;
    };
    if !(u >= 0.0 && v >= 0.0 && u < camera.width as f32 && v < camera.height as f32) {
        return false;
    }
    let distance = to_eye.length();
    // The first hit along the ray from the eye must be the point itself.
    trace(&demo_world(), eye, -to_eye / distance).is_some_and(|hit| hit.t >= distance - 1e-3 * distance.max(1.0))
}

/// The samples of `s` that at least one of `cameras` sees (in front, inside the image, facing
/// it, not occluded), in their original order.
pub fn visible_from(s: &SurfaceSamples, cameras: &[Camera]) -> SurfaceSamples {
    let keep: Vec<bool> = s
        .points
        .par_iter()
        .zip(&s.normals)
        .map(|(&p, &n)| cameras.iter().any(|c| sees(c, p, n)))
        .collect();
    let index = (0..s.points.len()).filter(|&i| keep[i]);
    SurfaceSamples {
        points: index.clone().map(|i| s.points[i]).collect(),
        normals: index.map(|i| s.normals[i]).collect(),
    }
}
