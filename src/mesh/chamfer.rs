//! Distance between two surfaces given as point samples with normals: Chamfer distance (both
//! directions, mean and percentiles) and normal consistency.
//!
//! Conventions: for samples `a` (e.g. of an extracted mesh) and `b` (e.g. of the true surface),
//! `a_to_b` holds, for each point of `a`, the distance to the nearest point of `b` (the DTU
//! evaluation's *accuracy* when `a` is the mesh), `b_to_a` the other way (*completeness*). The
//! Chamfer distance is the mean of the two means, as DTU's "overall". Distances are point to
//! point, so they include the sampling spacing: with `n` samples on a surface of area `A`, a
//! nearest sample lies about `0.5·√(A/n)` away even on the same surface; sample densely. Normal
//! consistency is the mean over both directions of `|n_p · n_q|` for each point `p` and its
//! nearest neighbour `q` (Occupancy Networks' definition: unsigned, 1 for aligned surfaces).
//! Nearest neighbours come from the crate's k-d tree ([`crate::kdtree`]) over f64 coordinates
//! (of several equally near samples, the first one's normal is used); sums run in sample
//! order, so results do not depend on the thread count.

use super::{MeshError, TriangleMesh};
use crate::kdtree::KdTree;
use crate::rng::Rng;
use glam::Vec3;
use rayon::prelude::*;

/// Points on a surface with their unit normals.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SurfaceSamples {
    /// Positions (world units).
    pub points: Vec<Vec3>,
    /// Unit normals, one per point.
    pub normals: Vec<Vec3>,
}

/// `count` points drawn uniformly by area on `mesh` (triangle chosen with probability
/// proportional to its area, then a uniform point in it), each with its triangle's unit normal;
/// seeded, deterministic.
///
/// # Errors
///
/// [`MeshError::EmptyMesh`] when no triangle has a positive area.
pub fn sample_mesh(mesh: &TriangleMesh, count: usize, seed: u64) -> Result<SurfaceSamples, MeshError> {
    let mut cumulative = Vec::with_capacity(mesh.triangles.len());
    let mut total = 0.0f64;
    for t in 0..mesh.triangles.len() {
        total += mesh.triangle_area(t) as f64;
        cumulative.push(total);
    }
    if !(total > 0.0 && total.is_finite()) {
        return Err(MeshError::EmptyMesh);
    }
    let mut rng = Rng::new(seed);
    let mut samples = SurfaceSamples::default();
    for _ in 0..count {
        let target = rng.uniform_f64() * total;
        let t = cumulative.partition_point(|&c| c <= target).min(cumulative.len() - 1);
        let [a, b, c] = mesh.triangles[t].map(|i| mesh.positions[i as usize]);
        let (r1, r2) = (rng.uniform().sqrt(), rng.uniform());
        samples
            .points
            .push(a * (1.0 - r1) + b * (r1 * (1.0 - r2)) + c * (r1 * r2));
        samples.normals.push((b - a).cross(c - a).normalize_or_zero());
    }
    Ok(samples)
}

/// Mean and percentiles of a set of distances.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DistanceStats {
    /// Mean.
    pub mean: f64,
    /// 50th percentile (nearest rank).
    pub median: f64,
    /// 90th percentile (nearest rank).
    pub p90: f64,
}

impl DistanceStats {
    fn of(mut d: Vec<f64>) -> Self {
        let mean = d.iter().sum::<f64>() / d.len() as f64;
        d.sort_unstable_by(f64::total_cmp);
        let rank = |q: f64| d[((d.len() as f64 * q).ceil() as usize).clamp(1, d.len()) - 1];
        Self {
            mean,
            median: rank(0.5),
            p90: rank(0.9),
        }
    }
}

/// The comparison of two sampled surfaces ([module documentation](self)).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChamferReport {
    /// From each point of the first set to the nearest of the second.
    pub a_to_b: DistanceStats,
    /// From each point of the second set to the nearest of the first.
    pub b_to_a: DistanceStats,
    /// `(a_to_b.mean + b_to_a.mean) / 2`.
    pub chamfer: f64,
    /// Mean `|n_p · n_q|` over both directions (each point weighted alike).
    pub normal_consistency: f64,
}

/// Per point of `from`: distance to the nearest point of `to` and `|n·n'|` with its normal.
fn nearest(from: &SurfaceSamples, to: &SurfaceSamples) -> Vec<(f64, f64)> {
    let coords: Vec<[f64; 3]> = to.points.iter().map(|p| p.as_dvec3().to_array()).collect();
    let tree = KdTree::new(&coords);
    from.points
        .par_iter()
        .zip(&from.normals)
        .map(|(p, n)| {
            let q = p.as_dvec3().to_array();
            let (distance, item) = tree.nearest::<1>(q, None).as_slice()[0];
            let other = to.normals[item];
            (distance.sqrt(), n.dot(other).abs() as f64)
        })
        .collect()
}

/// Compares two sampled surfaces ([module documentation](self)).
///
/// # Errors
///
/// [`MeshError::InvalidParameter`] when a set is empty, its normals do not match its points,
/// or a point is not finite.
pub fn chamfer(a: &SurfaceSamples, b: &SurfaceSamples) -> Result<ChamferReport, MeshError> {
    for (name, s) in [("first samples", a), ("second samples", b)] {
        let finite = s.points.iter().all(|p| p.is_finite());
        if s.points.is_empty() || s.points.len() != s.normals.len() || !finite {
            return Err(MeshError::InvalidParameter {
                name,
                value: s.points.len() as f64,
                reason: "need at least one finite point and one normal per point",
            });
        }
    }
    let ab = nearest(a, b);
    let ba = nearest(b, a);
    let normal_sum: f64 = ab.iter().chain(&ba).map(|x| x.1).sum();
    let a_to_b = DistanceStats::of(ab.iter().map(|x| x.0).collect());
    let b_to_a = DistanceStats::of(ba.iter().map(|x| x.0).collect());
    Ok(ChamferReport {
        a_to_b,
        b_to_a,
        chamfer: 0.5 * (a_to_b.mean + b_to_a.mean),
        normal_consistency: normal_sum / (ab.len() + ba.len()) as f64,
    })
}

/// Keeps the samples inside the box `[lo, hi]`.
pub fn inside_box(s: &SurfaceSamples, lo: Vec3, hi: Vec3) -> SurfaceSamples {
    let keep: Vec<usize> = (0..s.points.len())
        .filter(|&i| s.points[i].cmpge(lo).all() && s.points[i].cmple(hi).all())
        .collect();
    SurfaceSamples {
        points: keep.iter().map(|&i| s.points[i]).collect(),
        normals: keep.iter().map(|&i| s.normals[i]).collect(),
    }
}
