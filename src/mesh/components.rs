//! Connected components of a triangle mesh and the reference's rule for keeping the largest.
//!
//! Two triangles are connected when they share an edge (two vertex indices), as Open3D's
//! `cluster_connected_triangles` used by the reference. Components are numbered by their
//! smallest triangle index, so the result does not depend on the thread count or on hashing.
//!
//! The rule (2DGS `post_process_mesh`, spec §10.4): with `n_k` the triangle count of the k-th
//! largest component (`keep` = k, the reference's `num_cluster`: 1000 by default, 1 in its DTU
//! script), keep every component with at least `max(n_k, min_triangles)` triangles
//! (`min_triangles` 50 in the reference). Components tied with the k-th are all kept. When the
//! mesh has fewer than k components, `n_k` is the smallest one's count (the reference would fail
//! with an index error there). Unreferenced vertices are then dropped.

use super::TriangleMesh;

/// Per triangle, the id of its component, and the triangle count of each component. Component
/// ids are `0..count`, numbered in order of each component's first triangle.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Components {
    /// Component id of each triangle.
    pub of_triangle: Vec<u32>,
    /// Triangles per component.
    pub sizes: Vec<u32>,
}

fn find(parent: &mut [u32], mut i: u32) -> u32 {
    while parent[i as usize] != i {
        let up = parent[parent[i as usize] as usize];
        parent[i as usize] = up;
        i = up;
    }
    i
}

/// The edge-connected components of `mesh`'s triangles.
pub fn connected_components(mesh: &TriangleMesh) -> Components {
    let n = mesh.triangles.len();
    // (undirected edge key, triangle), sorted: triangles sharing an edge become neighbours.
    let mut edges: Vec<(u64, u32)> = Vec::with_capacity(3 * n);
    for (t, tri) in mesh.triangles.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            let key = ((a.min(b) as u64) << 32) | a.max(b) as u64;
            edges.push((key, t as u32));
        }
    }
    edges.sort_unstable();
    let mut parent: Vec<u32> = (0..n as u32).collect();
    for pair in edges.windows(2) {
        if pair[0].0 == pair[1].0 {
            let (a, b) = (find(&mut parent, pair[0].1), find(&mut parent, pair[1].1));
            // The smaller index becomes the root: roots are each component's first triangle.
            let (low, high) = (a.min(b), a.max(b));
            parent[high as usize] = low;
        }
    }
    let mut id_of_root = vec![u32::MAX; n];
    let mut of_triangle = vec![0u32; n];
    let mut sizes = Vec::new();
    for t in 0..n as u32 {
        let root = find(&mut parent, t) as usize;
        if id_of_root[root] == u32::MAX {
            id_of_root[root] = sizes.len() as u32;
            sizes.push(0);
        }
        of_triangle[t as usize] = id_of_root[root];
        sizes[id_of_root[root] as usize] += 1;
    }
    Components { of_triangle, sizes }
}

/// What [`keep_largest`] kept.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct KeptComponents {
    /// Components before.
    pub components: usize,
    /// Components kept.
    pub kept: usize,
    /// The triangle count a component needed to be kept.
    pub threshold: u32,
}

/// Keeps the largest components of `mesh` by the reference's rule ([module
/// documentation](self)), drops unreferenced vertices (order of the rest kept) and returns what
/// it kept. `keep` = 0 keeps nothing but components of at least `min_triangles`.
pub fn keep_largest(mesh: &mut TriangleMesh, keep: usize, min_triangles: u32) -> KeptComponents {
    let comps = connected_components(mesh);
    let mut sorted = comps.sizes.clone();
    sorted.sort_unstable_by(|a, b| b.cmp(a));
    let kth = match keep {
        0 => 0,
        k => sorted.get(k - 1).or(sorted.last()).copied().unwrap_or(0),
    };
    let threshold = kth.max(min_triangles);
    let kept_component: Vec<bool> = comps.sizes.iter().map(|&s| s >= threshold).collect();
    let triangles: Vec<[u32; 3]> = mesh
        .triangles
        .iter()
        .zip(&comps.of_triangle)
        .filter(|(_, c)| kept_component[**c as usize])
        .map(|(t, _)| *t)
        .collect();
    let mut new_index = vec![u32::MAX; mesh.positions.len()];
    for tri in &triangles {
        for &v in tri {
            new_index[v as usize] = 0;
        }
    }
    for (next, slot) in new_index.iter_mut().filter(|s| **s == 0).enumerate() {
        *slot = next as u32;
    }
    let keep_vertex = |i: &usize| new_index[*i] != u32::MAX;
    let pick = |v: &[glam::Vec3]| (0..v.len()).filter(keep_vertex).map(|i| v[i]).collect::<Vec<_>>();
    mesh.positions = pick(&mesh.positions);
    mesh.normals = pick(&mesh.normals);
    mesh.colours = (0..mesh.colours.len())
        .filter(keep_vertex)
        .map(|i| mesh.colours[i])
        .collect();
    mesh.triangles = triangles
        .into_iter()
        .map(|t| t.map(|v| new_index[v as usize]))
        .collect();
    KeptComponents {
        components: comps.sizes.len(),
        kept: kept_component.iter().filter(|k| **k).count(),
        threshold,
    }
}
