//! The binary tree the wide one is collapsed from (`wide.rs`), built top
//! down: each node is split at the plane of least cost by the surface area
//! heuristic (MacDonald and Booth 1990) among the planes between bins of
//! its triangles' centroids on each axis (Wald 2007, "On fast construction
//! of SAH-based bounding volume hierarchies"), down to a triangle a leaf.
//! Subtrees are built on rayon's threads, and a large node's triangles are
//! binned on them too.
//!
//! On a 1M-triangle mesh the tree (after reinsertion, `bvh.rs`) costs 5 %
//! less by the heuristic than obvhs's PLOC with the same reinsertion, and
//! closest hits are found 1.15-1.25x as fast (docs/BENCHMARKS.md, "Against
//! Embree").
//!
//! The tree is the same whatever the number of threads: a node's bins are
//! unions of boxes and sums of counts, which no order changes.

use glam::Vec3A;
use obvhs::aabb::Aabb;
use obvhs::bvh2::Bvh2;
use obvhs::bvh2::node::Bvh2Node;
use rayon::prelude::*;

/// The most bins a node's centroids fall into, on each axis; a node of
/// `n` triangles has `4 + n / 20` if fewer, as Embree's binned builder
/// has (on a 1M-triangle mesh the binary tree builds 1.15x as fast so,
/// and costs 0.4 % more by the heuristic).
const BINS: usize = 16;

/// Nodes of more triangles than this are binned on rayon's threads, in
/// chunks of this many, and their two subtrees built on two threads.
const PARALLEL: usize = 1 << 13;

/// A triangle's bounding box and its index in the list given.
#[derive(Clone, Copy)]
struct Item {
    bounds: Aabb,
    index: u32,
}

impl Item {
    /// Twice the box's centre (what the bins are of: no halving needed).
    fn centroid2(&self) -> Vec3A {
        self.bounds.min + self.bounds.max
    }
}

/// The boxes of a node's items and of their centroids (doubled).
#[derive(Clone, Copy)]
struct Bounds {
    boxes: Aabb,
    centroids: Aabb,
}

impl Bounds {
    const EMPTY: Bounds = Bounds {
        boxes: Aabb::INVALID,
        centroids: Aabb::INVALID,
    };

    fn add(&mut self, item: &Item) {
        self.boxes = self.boxes.union(&item.bounds);
        self.centroids.extend(item.centroid2());
    }

    fn of(items: &[Item]) -> Self {
        let mut b = Self::EMPTY;
        items.iter().for_each(|item| b.add(item));
        b
    }
}

/// The bin of each centroid on each axis, over a node's centroid bounds.
#[derive(Clone, Copy)]
struct Binning {
    origin: Vec3A,
    scale: Vec3A,
    /// How many bins (at most [`BINS`]).
    count: usize,
}

impl Binning {
    fn new(centroids: &Aabb, items: usize) -> Self {
        let extent = centroids.diagonal();
        let count = (4 + items / 20).min(BINS);
        Self {
            count,
            origin: centroids.min,
            // A flat axis (or a NaN one) puts every centroid in bin 0.
            scale: Vec3A::select(
                extent.cmpgt(Vec3A::ZERO),
                count as f32 / extent,
                Vec3A::ZERO,
            ),
        }
    }

    /// `item`'s bin on `axis` (a NaN one's, from infinite bounds, is bin 0).
    #[inline(always)]
    fn bin(&self, item: &Item, axis: usize) -> usize {
        let at = (item.centroid2()[axis] - self.origin[axis]) * self.scale[axis];
        at.clamp(0.0, (self.count - 1) as f32) as usize
    }
}

/// A node's items sorted into bins on each axis: each bin's box and count.
#[derive(Clone, Copy)]
struct Bins {
    boxes: [[Aabb; BINS]; 3],
    counts: [[u32; BINS]; 3],
}

impl Bins {
    const EMPTY: Bins = Bins {
        boxes: [[Aabb::INVALID; BINS]; 3],
        counts: [[0; BINS]; 3],
    };

    fn of(items: &[Item], binning: &Binning) -> Self {
        let mut bins = Self::EMPTY;
        for item in items {
            for axis in 0..3 {
                let bin = binning.bin(item, axis);
                let b = &mut bins.boxes[axis][bin];
                *b = b.union(&item.bounds);
                bins.counts[axis][bin] += 1;
            }
        }
        bins
    }

    /// [`Bins::of`], on rayon's threads when `items` are many.
    fn on_threads(items: &[Item], binning: &Binning) -> Self {
        if items.len() > PARALLEL {
            items
                .par_chunks(PARALLEL)
                .map(|chunk| Bins::of(chunk, binning))
                .reduce(|| Bins::EMPTY, Bins::merge)
        } else {
            Bins::of(items, binning)
        }
    }

    fn merge(mut self, other: Self) -> Self {
        for axis in 0..3 {
            for bin in 0..BINS {
                self.boxes[axis][bin] = self.boxes[axis][bin].union(&other.boxes[axis][bin]);
                self.counts[axis][bin] += other.counts[axis][bin];
            }
        }
        self
    }

    /// The axis and first bin of the right side of the split of least
    /// cost (each side's half area times its count), if one leaves both
    /// sides some items.
    fn best_split(&self, count: usize) -> Option<(usize, usize)> {
        let mut best = (f32::INFINITY, None);
        for axis in 0..3 {
            let (boxes, counts) = (&self.boxes[axis], &self.counts[axis]);
            // The cost of the right side from each bin on.
            let mut right = [0.0; BINS];
            let (mut b, mut n) = (Aabb::INVALID, 0);
            for bin in (1..count).rev() {
                b = b.union(&boxes[bin]);
                n += counts[bin];
                right[bin] = b.half_area() * n as f32;
            }
            let (mut b, mut n) = (Aabb::INVALID, 0);
            let total: u32 = counts.iter().sum();
            for bin in 1..count {
                b = b.union(&boxes[bin - 1]);
                n += counts[bin - 1];
                let cost = b.half_area() * n as f32 + right[bin];
                if n > 0 && n < total && cost < best.0 {
                    best = (cost, Some((axis, bin)));
                }
            }
        }
        best.1
    }
}

/// The binary tree over `triangles`, a triangle a leaf (an empty list gives
/// a tree of one empty leaf). Its nodes' children are adjacent (a node's
/// `first_index` and the next), as obvhs lays them out.
pub(super) fn binary_tree(triangles: &[[glam::Vec3; 3]]) -> Bvh2 {
    let mut items: Vec<Item> = triangles
        .par_iter()
        .enumerate()
        .map(|(index, t)| {
            let [a, b, c] = t.map(Vec3A::from);
            let (min, max) = (a.min(b).min(c), a.max(b).max(c));
            // A triangle with a NaN or infinite coordinate (never hit) is
            // given a point's box at the origin: NaN bounds would make
            // unions depend on their order.
            let finite = min.is_finite() && max.is_finite();
            let (min, max) = if finite {
                (min, max)
            } else {
                (Vec3A::ZERO, Vec3A::ZERO)
            };
            Item {
                bounds: Aabb::new(min, max),
                index: index as u32,
            }
        })
        .collect();
    let empty = Bvh2Node {
        aabb: Aabb::empty(),
        prim_count: 0,
        first_index: 0,
        ..Default::default()
    };
    if items.is_empty() {
        return Bvh2 {
            nodes: vec![empty],
            ..Default::default()
        };
    }
    // A node and its descendants, 2n - 1 nodes for n triangles.
    let mut nodes = vec![empty; 2 * items.len() - 1];
    let bounds = Bounds::of(&items);
    let (root, below) = nodes.split_first_mut().expect("one node at least");
    build(&mut items, 0, bounds, root, below, 1);
    Bvh2 {
        nodes,
        primitive_indices: items.iter().map(|item| item.index).collect(),
        ..Default::default()
    }
}

/// Builds the subtree over `items` (the first at `first` of the tree's
/// order, their bounds `bounds`) into `node` and `below`, the room for its
/// descendants (`2 * items.len() - 2` nodes, the first at `at`).
fn build(
    items: &mut [Item],
    first: usize,
    bounds: Bounds,
    node: &mut Bvh2Node,
    below: &mut [Bvh2Node],
    at: usize,
) {
    node.aabb = bounds.boxes;
    if items.len() == 1 {
        node.prim_count = 1;
        node.first_index = first as u32;
        return;
    }
    let (left, right, split) = split(items, &bounds);
    node.first_index = at as u32;
    let parallel = items.len() > PARALLEL;
    let (pair, rest) = below.split_at_mut(2);
    let (left_node, right_node) = pair.split_at_mut(1);
    let (left_below, right_below) = rest.split_at_mut(2 * split - 2);
    let (left_items, right_items) = items.split_at_mut(split);
    let right_at = at + 2 + left_below.len();
    let mut left_job = || {
        build(
            left_items,
            first,
            left,
            &mut left_node[0],
            left_below,
            at + 2,
        )
    };
    let mut right_job = || {
        let first = first + split;
        build(
            right_items,
            first,
            right,
            &mut right_node[0],
            right_below,
            right_at,
        )
    };
    if parallel {
        rayon::join(left_job, right_job);
    } else {
        left_job();
        right_job();
    }
}

/// Splits `items` (their bounds `bounds`) in two: the first's bounds, the
/// second's, and how many the first holds.
fn split(items: &mut [Item], bounds: &Bounds) -> (Bounds, Bounds, usize) {
    if items.len() == 2 {
        return (Bounds::of(&items[..1]), Bounds::of(&items[1..]), 1);
    }
    let binning = Binning::new(&bounds.centroids, items.len());
    let bins = Bins::on_threads(items, &binning);
    match bins.best_split(binning.count) {
        Some((axis, bin)) => partition(items, |item| binning.bin(item, axis) < bin),
        // No plane leaves items on both sides (their centroids all in one
        // bin on every axis): the middle of the list.
        None => {
            let half = items.len() / 2;
            let (l, r) = items.split_at(half);
            (Bounds::of(l), Bounds::of(r), half)
        }
    }
}

/// Moves the items `left_of` holds for before the others: their bounds,
/// the others', and how many they are.
fn partition(items: &mut [Item], left_of: impl Fn(&Item) -> bool) -> (Bounds, Bounds, usize) {
    let (mut left, mut right) = (Bounds::EMPTY, Bounds::EMPTY);
    let (mut i, mut j) = (0, items.len());
    while i < j {
        if left_of(&items[i]) {
            left.add(&items[i]);
            i += 1;
        } else {
            j -= 1;
            items.swap(i, j);
            right.add(&items[j]);
        }
    }
    (left, right, i)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    /// `n` small triangles at random places in a box of side 10 (seed `seed`).
    fn scattered(n: usize, seed: u64) -> Vec<[Vec3; 3]> {
        let mut rnd = crate::bvh::test_uniforms(seed);
        (0..n)
            .map(|_| {
                let p = Vec3::new(rnd(), rnd(), rnd()) * 10.0;
                let mut corner = || p + Vec3::new(rnd(), rnd(), rnd()) * 0.1;
                [p, corner(), corner()]
            })
            .collect()
    }

    /// Every triangle is in one leaf of its own, under boxes that bound
    /// it: a leaf's is its triangle's, an inner node's the union of its two
    /// children's (adjacent, after it), and the tree has 2n - 1 nodes. Also
    /// with triangles of NaN and infinite coordinates among the others.
    #[test]
    fn each_triangle_is_in_one_leaf_under_boxes_that_bound_it() {
        let mut triangles = scattered(3000, 3);
        for (k, bad) in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY]
            .into_iter()
            .enumerate()
        {
            triangles[100 * k][1].x = bad;
            triangles[100 * k + 1] = [Vec3::splat(bad); 3];
        }
        for triangles in [
            &triangles[..],
            &triangles[..1],
            &triangles[..2],
            &triangles[..5],
        ] {
            let bvh = binary_tree(triangles);
            assert_eq!(bvh.nodes.len(), 2 * triangles.len() - 1);
            let mut seen = vec![false; triangles.len()];
            let bits = |b: &Aabb| [b.min, b.max].map(|v| v.to_array().map(f32::to_bits));
            for (i, node) in bvh.nodes.iter().enumerate() {
                if node.is_leaf() {
                    assert_eq!(node.prim_count, 1);
                    let t = bvh.primitive_indices[node.first_index as usize] as usize;
                    assert!(!seen[t], "triangle {t} twice");
                    seen[t] = true;
                    let [a, b, c] = triangles[t].map(Vec3A::from);
                    let own = Aabb::new(a.min(b).min(c), a.max(b).max(c));
                    let own = if own.min.is_finite() && own.max.is_finite() {
                        own
                    } else {
                        Aabb::new(Vec3A::ZERO, Vec3A::ZERO)
                    };
                    assert_eq!(bits(&node.aabb), bits(&own), "leaf {i}");
                } else {
                    let first = node.first_index as usize;
                    assert!(first > i, "node {i}");
                    let union = bvh.nodes[first].aabb.union(&bvh.nodes[first + 1].aabb);
                    assert_eq!(bits(&node.aabb), bits(&union), "node {i}");
                }
            }
            assert!(seen.iter().all(|&s| s));
        }
        assert_eq!(binary_tree(&[]).nodes.len(), 1);
    }

    /// Triangles no plane separates (the same triangle 1000 times) are
    /// split at the middle of the list: a tree of the least depth.
    #[test]
    fn triangles_no_plane_separates_are_split_in_halves() {
        let bvh = binary_tree(&[scattered(1, 13)[0]; 1000]);
        let mut depth = 0;
        let mut todo = vec![(0, 0)];
        while let Some((i, d)) = todo.pop() {
            let node = &bvh.nodes[i];
            depth = depth.max(d);
            if !node.is_leaf() {
                let first = node.first_index as usize;
                todo.extend([(first, d + 1), (first + 1, d + 1)]);
            }
        }
        assert_eq!(depth, 10);
    }

    /// The tree is the same, bit for bit, on one thread and on three
    /// (a list large enough to be binned and split on several).
    #[test]
    fn the_tree_is_the_same_on_any_number_of_threads() {
        let triangles = scattered(5 * PARALLEL, 5);
        let on = |threads| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| binary_tree(&triangles))
        };
        let (one, three) = (on(1), on(3));
        let nodes = |bvh: &Bvh2| -> Vec<_> {
            bvh.nodes
                .iter()
                .map(|n| {
                    (
                        n.aabb.min.to_array(),
                        n.aabb.max.to_array(),
                        n.first_index,
                        n.prim_count,
                    )
                })
                .map(|(a, b, f, c)| (a.map(f32::to_bits), b.map(f32::to_bits), f, c))
                .collect()
        };
        assert_eq!(nodes(&one), nodes(&three));
        assert_eq!(one.primitive_indices, three.primitive_indices);
    }

    /// Bins filled on several threads, each a chunk of the items, then
    /// merged, hold what bins filled on one do.
    #[test]
    fn bins_merged_from_threads_are_bins_filled_on_one() {
        let items: Vec<Item> = scattered(3 * PARALLEL + 5, 11)
            .iter()
            .enumerate()
            .map(|(index, t)| {
                let [a, b, c] = t.map(Vec3A::from);
                let (min, max) = (a.min(b).min(c), a.max(b).max(c));
                Item {
                    bounds: Aabb::new(min, max),
                    index: index as u32,
                }
            })
            .collect();
        let binning = Binning::new(&Bounds::of(&items).centroids, items.len());
        let (merged, one) = (
            Bins::on_threads(&items, &binning),
            Bins::of(&items, &binning),
        );
        let bits = |bins: &Bins| {
            let boxes = bins
                .boxes
                .map(|axis| axis.map(|b| [b.min, b.max].map(|v| v.to_array().map(f32::to_bits))));
            (boxes, bins.counts)
        };
        assert_eq!(bits(&merged), bits(&one));
        assert!(
            one.counts
                .iter()
                .all(|axis| axis.iter().filter(|&&n| n > 0).count() == BINS)
        );
    }

    /// Two clusters, of 30 and 70 triangles far apart, are split at the
    /// gap between them, where the heuristic's cost is least, not at the
    /// middle of the list.
    #[test]
    fn the_root_is_split_between_two_clusters() {
        let mut triangles = scattered(100, 9);
        for t in &mut triangles[30..] {
            *t = t.map(|v| v + Vec3::X * 100.0);
        }
        let bvh = binary_tree(&triangles);
        let first = bvh.nodes[0].first_index as usize;
        let side = |node: usize| {
            let mut todo = vec![node];
            let mut held = Vec::new();
            while let Some(i) = todo.pop() {
                let n = &bvh.nodes[i];
                if n.is_leaf() {
                    held.push(bvh.primitive_indices[n.first_index as usize]);
                } else {
                    todo.extend([n.first_index as usize, n.first_index as usize + 1]);
                }
            }
            held.sort_unstable();
            held
        };
        let mut sides = [side(first), side(first + 1)];
        sides.sort_by_key(|s| s.len());
        assert_eq!(sides, [(0..30).collect::<Vec<u32>>(), (30..100).collect()]);
    }
}
