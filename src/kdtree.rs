//! A static k-d tree over 3-D points in f64: the `K` nearest items of a query point, exactly.
//!
//! # Conventions
//!
//! - **Distance**: [`sq_dist`], `dx·dx + dy·dy + dz·dz` in f64, in that order. The tree ranks
//!   items by this expression and nothing else, so a query returns exactly what a brute-force scan
//!   computing [`sq_dist`] to every item would: the `K` smallest `(distance, item)` pairs in
//!   lexicographic order (ties in distance go to the smaller item index).
//! - **Why pruning is exact**: a subtree on the far side of a split plane is skipped only when
//!   the squared distance `d²` from the query to the plane (along the split axis, computed in
//!   the same f64 operations) is *strictly* greater than the current `K`-th distance. Rounded
//!   subtraction and addition of non-negative terms are monotone, so every item beyond the plane
//!   has `sq_dist ≥ d²`: none of them could enter the list, not even on a tie.
//! - **Items** are the positions in the slice given to [`KdTree::new`]; points must be finite
//!   (callers filter non-finite points out, with their own convention for them).
//! - **Determinism**: the build and a query are sequential and depend on nothing but the input,
//!   so queries run from any number of threads give the same answers.
//!
//! Building is `O(N log N)` (median splits on the axis of largest extent, leaves of at most
//! [`LEAF`] points); a query visits `O(log N)` nodes on well-spread points.
//!
//! ```
//! use bbsplat::kdtree::KdTree;
//! let points = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [5.0, 5.0, 5.0]];
//! let tree = KdTree::new(&points);
//! let near = tree.nearest::<2>([0.1, 0.0, 0.0], None);
//! assert_eq!(near.items(), vec![0, 1]);
//! // The query point's own item can be left out (a point's neighbours other than itself).
//! assert_eq!(tree.nearest::<1>(points[0], Some(0)).items(), vec![1]);
//! ```

/// Largest number of points in a leaf, scanned without further splits.
pub const LEAF: usize = 8;

/// The squared Euclidean distance, `dx·dx + dy·dy + dz·dz` in that order: the one expression
/// the tree ranks by.
#[inline]
pub fn sq_dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    let (dx, dy, dz) = (a[0] - b[0], a[1] - b[1], a[2] - b[2]);
    dx * dx + dy * dy + dz * dz
}

/// One point of the tree: its coordinates, its item (index in the input) and, when it is the
/// median of a split range, the axis of that split.
#[derive(Clone, Copy, Debug)]
struct Node {
    point: [f64; 3],
    item: usize,
    axis: u8,
}

/// A k-d tree built once over a set of points ([module documentation](self)).
#[derive(Clone, Debug)]
pub struct KdTree {
    /// The points reordered so that every range `[lo, hi)` longer than [`LEAF`] has its split
    /// point at `lo + (hi − lo) / 2`, the points before it not above it on its axis and the points
    /// after it not below.
    nodes: Vec<Node>,
}

/// The nearest items found by [`KdTree::nearest`], closest first.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Neighbours<const K: usize> {
    found: [(f64, usize); K],
    len: usize,
}

impl<const K: usize> Neighbours<K> {
    fn empty() -> Self {
        Self {
            found: [(f64::INFINITY, usize::MAX); K],
            len: 0,
        }
    }

    /// `(squared distance, item)` pairs, closest first (ties: smaller item first). Fewer than `K`
    /// when the tree holds fewer eligible items.
    pub fn as_slice(&self) -> &[(f64, usize)] {
        &self.found[..self.len]
    }

    /// The items, closest first.
    pub fn items(&self) -> Vec<usize> {
        self.as_slice().iter().map(|&(_, i)| i).collect()
    }

    /// The squared distances, in increasing order.
    pub fn distances(&self) -> Vec<f64> {
        self.as_slice().iter().map(|&(d, _)| d).collect()
    }

    /// The distance an item must not exceed to enter the list (∞ while it is not full).
    fn bound(&self) -> f64 {
        if self.len < K {
            f64::INFINITY
        } else {
            self.found[K - 1].0
        }
    }

    /// Inserts `(d, item)` if it ranks among the `K` smallest so far.
    fn offer(&mut self, d: f64, item: usize) {
        let key = (d, item);
        let ranks_before = |a: (f64, usize), b: (f64, usize)| a.0 < b.0 || (a.0 == b.0 && a.1 < b.1);
        if self.len == K && !ranks_before(key, self.found[K - 1]) {
            return;
        }
        let mut at = self.len.min(K - 1);
        while at > 0 && ranks_before(key, self.found[at - 1]) {
            self.found[at] = self.found[at - 1];
            at -= 1;
        }
        self.found[at] = key;
        self.len = (self.len + 1).min(K);
    }
}

impl KdTree {
    /// Builds the tree over `points` (finite coordinates; item `i` is `points[i]`).
    pub fn new(points: &[[f64; 3]]) -> Self {
        debug_assert!(
            points.iter().flatten().all(|c| c.is_finite()),
            "the k-d tree needs finite points"
        );
        let mut nodes: Vec<Node> = points
            .iter()
            .enumerate()
            .map(|(item, &point)| Node { point, item, axis: 0 })
            .collect();
        build(&mut nodes);
        Self { nodes }
    }

    /// Number of points in the tree.
    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    /// Whether the tree holds no point.
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// The `K` nearest items to `query` by [`sq_dist`], closest first, leaving out item `skip`
    /// when given. `K` must be at least 1.
    pub fn nearest<const K: usize>(&self, query: [f64; 3], skip: Option<usize>) -> Neighbours<K> {
        assert!(K > 0, "a query asks for at least one neighbour");
        let mut best = Neighbours::empty();
        self.search(&self.nodes, query, skip, &mut best);
        best
    }

    fn search<const K: usize>(&self, range: &[Node], query: [f64; 3], skip: Option<usize>, best: &mut Neighbours<K>) {
        if range.len() <= LEAF {
            for node in range {
                if Some(node.item) != skip {
                    best.offer(sq_dist(query, node.point), node.item);
                }
            }
            return;
        }
        let mid = range.len() / 2;
        let split = range[mid];
        let axis = split.axis as usize;
        if Some(split.item) != skip {
            best.offer(sq_dist(query, split.point), split.item);
        }
        let to_plane = query[axis] - split.point[axis];
        let (below, above) = (&range[..mid], &range[mid + 1..]);
        let (near, far) = if to_plane < 0.0 { (below, above) } else { (above, below) };
        self.search(near, query, skip, best);
        if to_plane * to_plane <= best.bound() {
            self.search(far, query, skip, best);
        }
    }
}

/// Orders `nodes` into the tree layout of [`KdTree::nodes`]: the median on the axis of largest
/// extent, ties broken by item so that the layout depends only on the input. Halves of large
/// ranges are built in parallel (disjoint slices: the same layout for any number of threads).
fn build(nodes: &mut [Node]) {
    if nodes.len() <= LEAF {
        return;
    }
    let axis = widest_axis(nodes);
    let mid = nodes.len() / 2;
    nodes.select_nth_unstable_by(mid, |a, b| {
        a.point[axis].total_cmp(&b.point[axis]).then(a.item.cmp(&b.item))
    });
    nodes[mid].axis = axis as u8;
    let (below, rest) = nodes.split_at_mut(mid);
    let above = &mut rest[1..];
    if below.len() > 4096 {
        rayon::join(|| build(below), || build(above));
    } else {
        build(below);
        build(above);
    }
}

/// The axis along which `nodes` spread the most.
fn widest_axis(nodes: &[Node]) -> usize {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for n in nodes {
        for a in 0..3 {
            lo[a] = lo[a].min(n.point[a]);
            hi[a] = hi[a].max(n.point[a]);
        }
    }
    let extent = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
    (0..3).fold(0, |w, a| if extent[a] > extent[w] { a } else { w })
}
