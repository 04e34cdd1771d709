//! An eight-wide BVH of our own, over a binary tree of a triangle a leaf
//! (`build.rs`, then obvhs's reinsertion): the wide tree of least cost by the
//! surface area heuristic that the binary one holds, found by dynamic
//! programming as Ylitie, Karras and Laine (2017) find their compressed
//! wide trees ([`Plan`]), with leaves of up to four blocks of four
//! triangles (`leaf.rs`). A node's eight children have their float bounds
//! in SIMD lanes, as Wald, Benthin and Boulos (2008) and Embree's BVH8 lay
//! them out; the children a ray enters are visited nearest first, farther
//! ones kept on a stack with their entry distance so that those beyond a
//! closer hit are dropped. A child pushed is prefetched, as Embree's
//! traversal does: on a mesh too large for the caches the wait for its
//! memory overlaps the work on its nearer siblings (closest hits on a
//! 1M-triangle mesh 1.1x as fast).
//!
//! The node test is written once over eight lanes ([`enter`]) and once in
//! AVX2 (`avx2.rs`), with the same operations in the same order (a
//! difference then a product, maxima and minima with the ray's own range
//! second): both find the same children, hence the same hits.

use core::mem::MaybeUninit;

use glam::Vec3A;
use obvhs::bvh2::Bvh2;

use super::leaf::{Block, LANES};

/// A child slot that holds nothing.
const EMPTY: u32 = u32::MAX;
/// A child slot that holds a leaf: this bit, its count of blocks of
/// [`LANES`] triangles less one in the next two bits, its first block (of
/// the tree's own) in the rest.
const LEAF: u32 = 1 << 31;
const COUNT_SHIFT: u32 = 29;
const FIRST_MASK: u32 = (1 << COUNT_SHIFT) - 1;

/// The most triangles one tree holds (2^29: the most blocks a leaf's first
/// index encodes, each of at least one triangle); larger scenes are split
/// into several trees.
pub(super) const MAX_TRIANGLES: usize = 1 << COUNT_SHIFT;

/// The factor a child's exit distance is widened by before it is compared
/// with the entry (in the product that makes it: the inverse direction is
/// multiplied by it first): `1 + 2^-20`, a few ulps, more than the rounding
/// of the slab distances, of that product and of the triangle test's `t`
/// together (Ize 2013 widens by `1 + 2γ_3`). Without it a flat box (an axis-aligned wall's) could be
/// passed by where its triangle is hit an ulp closer than a neighbour's.
pub(super) const WIDEN: f32 = 1.0 + 1.0 / (1 << 20) as f32;

/// Slots of a traversal's stack kept on the thread's stack, uninitialized
/// (filling them cost 3 % of a path's instructions): enough for trees 36
/// levels deep (a 1M-triangle mesh's is 15, veach-ajar's 15); a deeper
/// tree's stack is on the heap, allocated per ray.
const INLINE_STACK: usize = 256;

/// The most blocks a leaf holds (what its two bits of count encode).
const LEAF_BLOCKS: usize = 4;

/// The most triangles a leaf holds.
const LEAF_SIZE: u32 = (LEAF_BLOCKS * LANES) as u32;

/// Eight children: their bounds, axis by axis, and what each holds.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
pub(super) struct Node {
    /// `[min x, max x, min y, max y, min z, max z]`, a lane per child; an
    /// empty slot's box is inverted (min +inf, max -inf) and never entered.
    pub(super) bounds: [[f32; 8]; 6],
    /// An inner node's index, a leaf ([`LEAF`]), or [`EMPTY`].
    child: [u32; 8],
}

/// What a traversal needs of a ray, computed once.
#[derive(Clone, Copy, Debug)]
pub(super) struct Query {
    pub(super) origin: Vec3A,
    pub(super) inv_direction: Vec3A,
    /// `inv_direction` times [`WIDEN`]: the exit distances are widened in
    /// the product that makes them, off the node test's longest chain.
    pub(super) inv_direction_far: Vec3A,
    /// For each axis, the row of [`Node::bounds`] a ray enters the slab
    /// through (the minimum for a positive direction) and leaves it by.
    pub(super) near: [usize; 3],
    pub(super) far: [usize; 3],
    pub(super) t_min: f32,
}

impl Query {
    pub(super) fn new(ray: &obvhs::ray::Ray) -> Self {
        let d = ray.inv_direction;
        let near = |axis: usize, inv: f32| 2 * axis + (inv < 0.0) as usize;
        let near = [near(0, d.x), near(1, d.y), near(2, d.z)];
        Query {
            origin: ray.origin,
            inv_direction: d,
            inv_direction_far: d * WIDEN,
            near,
            far: near.map(|n| n ^ 1),
            t_min: ray.tmin,
        }
    }
}

/// `maxps`: `b` unless `a` is greater (so `b` where either is NaN).
#[inline(always)]
fn max_ps(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
}

/// `minps`: `b` unless `a` is less (so `b` where either is NaN).
#[inline(always)]
fn min_ps(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

/// The children of `node` that a ray (`query`, with its current farthest
/// distance `t_max`) enters: a bit per child, and the distances it enters
/// them at. The lane-by-lane twin of `avx2::enter`.
///
/// A slab's distances are `(bound - origin) * inverse direction`, the exit
/// ones widened by [`WIDEN`] in that product. The entry is the greatest of
/// the three entry distances and `t_min`, the exit the least of the three
/// exit distances and `t_max` widened, each taken as a tree of two levels
/// (a chain of three was the longest path of the node test, whose latency
/// is most of a closest hit's on a large mesh). A slab distance is NaN only
/// where the ray runs in the slab's plane; a NaN drops one operand of a
/// maximum or minimum, which can only lower the entry or raise the exit: a
/// child is then entered more readily, never missed.
pub(super) fn enter(node: &Node, query: &Query, t_max: f32) -> (u32, [f32; 8]) {
    let o = query.origin.to_array();
    let inv = query.inv_direction.to_array();
    let inv_far = query.inv_direction_far.to_array();
    let t_far = t_max * WIDEN;
    let mut mask = 0;
    let mut entry = [0.0; 8];
    for (lane, entered) in entry.iter_mut().enumerate() {
        let slab = |axis: usize, row: usize, inv: &[f32; 3]| {
            (node.bounds[row][lane] - o[axis]) * inv[axis]
        };
        let [nx, ny, nz] = [0, 1, 2].map(|a| slab(a, query.near[a], &inv));
        let [fx, fy, fz] = [0, 1, 2].map(|a| slab(a, query.far[a], &inv_far));
        let t0 = max_ps(max_ps(nx, ny), max_ps(nz, query.t_min));
        let t1 = min_ps(min_ps(fx, fy), min_ps(fz, t_far));
        *entered = t0;
        mask |= ((t0 <= t1) as u32) << lane;
    }
    (mask, entry)
}

/// The tree: its nodes, over blocks of triangles from `base` on in the
/// intersector's list.
pub(super) struct Wide {
    nodes: Vec<Node>,
    /// The root: node 0, or a leaf where all the triangles are cheaper
    /// tested together (a scene of a few, as a ground plane's two), with
    /// no node at all.
    root: u32,
    /// Where the tree's blocks start in the intersector's list.
    base: usize,
    /// The deepest path from the root, in nodes: the traversal's stack
    /// holds at most seven children a level.
    depth: usize,
}

/// A leaf's blocks: `first..first + count` of the tree's.
fn leaf(child: u32) -> (usize, usize) {
    let first = (child & FIRST_MASK) as usize;
    let count = ((child & !LEAF) >> COUNT_SHIFT) as usize + 1;
    (first, count)
}

/// The costs the surface area heuristic weighs a wide tree's shape by: an
/// eight-wide node test, and a test of a block of [`LANES`] triangles (as
/// much: paths a second changed by under 3 % on every scene from 0.75 to 3).
const NODE_COST: f32 = 1.0;
const BLOCK_COST: f32 = 1.0;

/// What the best way to hold a binary node's subtree in `i + 1` slots of a
/// wide node is (its entry `i` of [`Plan::choice`]).
const AS_LEAF: u8 = 0;
const AS_NODE: u8 = 1;
/// In `i` slots (`i + 1 > 1`): as it is held in one slot fewer.
const IN_FEWER: u8 = 2;
/// In `i + 1 > 1` slots: its left child's subtree in `k` of them, its
/// right's in the rest, for `SPLIT + k`.
const SPLIT: u8 = 16;

/// The cheapest wide tree over a binary one, by dynamic programming over
/// the binary tree (Ylitie, Karras and Laine 2017, their conversion of a
/// binary BVH to a wide one: the least SAH cost of each subtree held in one
/// to eight slots of a wide node, children before parents). It keeps ~10
/// bytes a binary node (~20 a triangle); the costs live only while the
/// walk needs them, on a stack as deep as the tree.
struct Plan {
    /// For each binary node and `i` in `0..8`: how its subtree is best held
    /// in at most `i + 1` slots.
    choice: Vec<[u8; 8]>,
    /// For each binary node held as a wide node of its own: how many of the
    /// eight slots its left child's subtree takes.
    left_slots: Vec<u8>,
}

impl Plan {
    /// The plan, and the least cost it finds (the root held in one slot).
    fn new(bvh: &Bvh2) -> (Self, f32) {
        let n = bvh.nodes.len();
        let mut plan = Plan {
            choice: vec![[AS_LEAF; 8]; n],
            left_slots: vec![0; n],
        };
        let leaf_cost = |area: f32, count: u32| {
            if count <= LEAF_SIZE {
                area * BLOCK_COST * count.div_ceil(LANES as u32) as f32
            } else {
                f32::INFINITY
            }
        };
        // A walk in post-order (a left subtree, the right one, their
        // parent): `todo` holds the nodes to visit, each with whether its
        // children are done; `done` the subtrees finished and not yet taken
        // by their parents, each as its least costs in one to eight slots
        // and its triangles. (A binary leaf costs the same in every number
        // of slots, and keeps its choice, as a leaf.)
        let mut todo = vec![(0usize, false)];
        let mut done: Vec<([f32; 8], u32)> = Vec::new();
        while let Some((i, children_done)) = todo.pop() {
            let node = &bvh.nodes[i];
            if node.is_leaf() {
                let cost = leaf_cost(node.aabb.half_area(), node.prim_count);
                done.push(([cost; 8], node.prim_count));
                continue;
            }
            let left = node.first_index as usize;
            if !children_done {
                todo.extend([(i, true), (left + 1, false), (left, false)]);
                continue;
            }
            let (Some((right, right_count)), Some((left, left_count))) = (done.pop(), done.pop())
            else {
                unreachable!("both subtrees of a node are done before it");
            };
            let count = left_count + right_count;
            let area = node.aabb.half_area();
            // The two subtrees spread over 2 to 8 slots, the left one's
            // share of the cheapest.
            // (A split of one slot to the left stands where no cost
            // compares, as NaN ones from NaN coordinates do not.)
            let mut spread = [(f32::INFINITY, 1u8); 9];
            for (slots, best) in spread.iter_mut().enumerate().skip(2) {
                for k in 1..slots {
                    let cost = left[k - 1] + right[slots - k - 1];
                    if cost < best.0 {
                        *best = (cost, k as u8);
                    }
                }
            }
            plan.left_slots[i] = spread[8].1;
            let as_leaf = leaf_cost(area, count);
            let as_node = area * NODE_COST + spread[8].0;
            let mut cost = [0.0; 8];
            let choice = &mut plan.choice[i];
            (cost[0], choice[0]) = if count <= LEAF_SIZE && as_leaf <= as_node {
                (as_leaf, AS_LEAF)
            } else {
                (as_node, AS_NODE)
            };
            for slots in 2..=8 {
                let (spread, k) = spread[slots];
                (cost[slots - 1], choice[slots - 1]) = if spread < cost[slots - 2] {
                    (spread, SPLIT + k)
                } else {
                    (cost[slots - 2], IN_FEWER)
                };
            }
            done.push((cost, count));
        }
        let root_cost = done.pop().map_or(0.0, |(cost, _)| cost[0]);
        (plan, root_cost)
    }

    /// The binary nodes that take the slots a wide node made of binary
    /// node `i` has.
    fn children(&self, bvh: &Bvh2, i: usize) -> Vec<usize> {
        let mut children = Vec::with_capacity(8);
        let node = &bvh.nodes[i];
        if node.is_leaf() || self.choice[i][0] == AS_LEAF {
            children.push(i);
        } else {
            let k = self.left_slots[i] as usize;
            self.held_in(bvh, node.first_index as usize, k, &mut children);
            self.held_in(bvh, node.first_index as usize + 1, 8 - k, &mut children);
        }
        children
    }

    /// Adds the binary nodes that hold `i`'s subtree in `slots` slots.
    fn held_in(&self, bvh: &Bvh2, i: usize, slots: usize, out: &mut Vec<usize>) {
        match self.choice[i][slots - 1] {
            IN_FEWER => self.held_in(bvh, i, slots - 1, out),
            c if c >= SPLIT && slots > 1 && !bvh.nodes[i].is_leaf() => {
                let (k, first) = ((c - SPLIT) as usize, bvh.nodes[i].first_index as usize);
                self.held_in(bvh, first, k, out);
                self.held_in(bvh, first + 1, slots - k, out);
            }
            _ => out.push(i),
        }
    }

    /// Whether binary node `i`, in a slot of its own, is a leaf.
    fn is_leaf(&self, bvh: &Bvh2, i: usize) -> bool {
        bvh.nodes[i].is_leaf() || self.choice[i][0] == AS_LEAF
    }
}

/// The primitives of binary node `i`'s subtree, into `out` (`todo`: room
/// for the walk).
fn primitives(bvh: &Bvh2, i: usize, todo: &mut Vec<usize>, out: &mut Vec<u32>) {
    todo.push(i);
    while let Some(i) = todo.pop() {
        let node = &bvh.nodes[i];
        if node.is_leaf() {
            let first = node.first_index as usize;
            out.extend_from_slice(&bvh.primitive_indices[first..first + node.prim_count as usize]);
        } else {
            todo.extend([node.first_index as usize + 1, node.first_index as usize]);
        }
    }
}

/// Asks the processor to bring the four cache lines from the one `at` is
/// in into its cache (x86_64; elsewhere nothing): a node's (224 bytes at
/// 32-byte alignment) or a block's (208 at 16).
#[inline(always)]
fn prefetch(at: *const u8) {
    #[cfg(target_arch = "x86_64")]
    {
        use core::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        const LINE: usize = 64;
        let first = at.wrapping_sub(at as usize % LINE).cast::<i8>();
        for line in 0..4 {
            // SAFETY: a prefetch is a hint: it reads nothing and never
            // faults, whatever the address.
            #[allow(unsafe_code)]
            unsafe {
                _mm_prefetch::<_MM_HINT_T0>(first.wrapping_add(line * LINE));
            }
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = at;
}

/// A lane of a block without a triangle.
pub(super) const NO_TRIANGLE: u32 = u32::MAX;

impl Wide {
    /// The wide tree of least cost by the surface area heuristic over the
    /// binary tree `bvh` (of at most [`MAX_TRIANGLES`] primitives), chosen
    /// by [`Plan`]: each wide node's children are binary nodes below it,
    /// a leaf holding every primitive of its binary subtree (at most
    /// [`LEAF_SIZE`]).
    /// Its blocks start at `base` of the intersector's list; it returns
    /// them, each as the primitives of `bvh` in its lanes (or
    /// [`NO_TRIANGLE`]).
    pub(super) fn collapse(bvh: &Bvh2, base: usize) -> (Self, Vec<[u32; LANES]>) {
        let empty = Node {
            bounds: [
                [f32::INFINITY; 8],
                [f32::NEG_INFINITY; 8],
                [f32::INFINITY; 8],
                [f32::NEG_INFINITY; 8],
                [f32::INFINITY; 8],
                [f32::NEG_INFINITY; 8],
            ],
            child: [EMPTY; 8],
        };
        let (plan, _) = Plan::new(bvh);
        let (mut blocks, mut primitives_of, mut walk) = (Vec::new(), Vec::new(), Vec::new());
        // A leaf of binary node `c`'s primitives, its blocks added.
        let mut leaf_of = |c: usize, blocks: &mut Vec<[u32; LANES]>| {
            primitives_of.clear();
            primitives(bvh, c, &mut walk, &mut primitives_of);
            debug_assert!(primitives_of.len() <= LEAF_SIZE as usize);
            let first = blocks.len() as u32;
            debug_assert!(first <= FIRST_MASK);
            for lanes in primitives_of.chunks(LANES) {
                blocks.push(core::array::from_fn(|l| {
                    lanes.get(l).copied().unwrap_or(NO_TRIANGLE)
                }));
            }
            let size = blocks.len() as u32 - first;
            LEAF | ((size - 1) << COUNT_SHIFT) | first
        };
        if plan.is_leaf(bvh, 0) {
            let root = leaf_of(0, &mut blocks);
            let (nodes, depth) = (Vec::new(), 0);
            return (
                Wide {
                    nodes,
                    root,
                    base,
                    depth,
                },
                blocks,
            );
        }
        let mut nodes = vec![empty];
        let mut depth = 1;
        // (the binary node a wide node is made from, the wide node, its depth)
        let mut todo = vec![(0usize, 0usize, 1usize)];
        while let Some((binary, wide, level)) = todo.pop() {
            depth = depth.max(level);
            for (lane, c) in plan.children(bvh, binary).into_iter().enumerate() {
                let node = &bvh.nodes[c];
                let (lo, hi) = (node.aabb.min, node.aabb.max);
                let bounds = &mut nodes[wide].bounds;
                for axis in 0..3 {
                    bounds[2 * axis][lane] = lo[axis];
                    bounds[2 * axis + 1][lane] = hi[axis];
                }
                nodes[wide].child[lane] = if plan.is_leaf(bvh, c) {
                    leaf_of(c, &mut blocks)
                } else {
                    nodes.push(empty);
                    let index = nodes.len() - 1;
                    todo.push((c, index, level + 1));
                    index as u32
                };
            }
        }
        // The nodes moved to memory in huge pages (the vector grew by
        // pushes, the count unknown until now).
        let mut tree = Vec::new();
        super::huge_pages::reserve(&mut tree, nodes.len());
        tree.extend_from_slice(&nodes);
        let nodes = tree;
        (
            Wide {
                nodes,
                root: 0,
                base,
                depth,
            },
            blocks,
        )
    }

    /// Asks the processor to fetch child `child` (a node, or a leaf's
    /// first block of `blocks`) into its cache while the traversal works
    /// elsewhere, as Embree does for every child a ray enters: a child
    /// that waits on the stack arrives before it is popped. The address is
    /// selected, not branched to (a leaf or a node is a coin toss).
    #[inline(always)]
    fn prefetch(&self, child: u32, blocks: &[Block]) {
        let node = self.nodes.as_ptr().wrapping_add(child as usize);
        let block = blocks.as_ptr().wrapping_add(self.base + leaf(child).0);
        let (node, block) = (node.cast(), block.cast());
        prefetch(if child & LEAF != 0 { block } else { node });
    }

    /// How many nodes the tree has.
    #[cfg(test)]
    pub(super) fn nodes(&self) -> usize {
        self.nodes.len()
    }

    /// Room for the traversal's stack.
    fn stack_room(&self) -> usize {
        7 * self.depth + 1
    }

    /// The closest of the triangles `hit(first, count, t_max)` finds in
    /// the blocks `first..first + count` of the intersector's list (it
    /// returns the nearest it hits closer than `t_max`), children found
    /// by `enter`.
    #[inline(always)]
    pub(super) fn closest(
        &self,
        query: &Query,
        t_max: f32,
        enter: impl Fn(&Node, &Query, f32) -> (u32, [f32; 8]),
        mut hit: impl FnMut(usize, usize, f32) -> Option<f32>,
        blocks: &[Block],
    ) -> f32 {
        let (mut inline, mut heap) = ([MaybeUninit::uninit(); INLINE_STACK], Vec::new());
        let stack: &mut [MaybeUninit<(u32, f32)>] = match self.stack_room() {
            room if room <= INLINE_STACK => &mut inline,
            room => {
                heap.resize(room, MaybeUninit::uninit());
                &mut heap
            }
        };
        let mut top = 0;
        let mut t_max = t_max;
        let mut current = self.root;
        loop {
            if current & LEAF != 0 {
                let (first, count) = leaf(current);
                if let Some(t) = hit(self.base + first, count, t_max) {
                    t_max = t;
                }
            } else {
                let node = &self.nodes[current as usize];
                let (mask, entry) = enter(node, query, t_max);
                if mask != 0 {
                    let lane = mask.trailing_zeros() as usize;
                    let mut rest = mask & (mask - 1);
                    current = node.child[lane];
                    if rest == 0 {
                        continue;
                    }
                    // Two or more entered: each pushed into place among
                    // this node's (an insertion sort on the stack, the
                    // nearest on top, of equal distances the first lane),
                    // then the nearest popped to be visited next.
                    let base = top;
                    self.prefetch(current, blocks);
                    stack[top] = MaybeUninit::new((current, entry[lane]));
                    top += 1;
                    while rest != 0 {
                        let lane = rest.trailing_zeros() as usize;
                        rest &= rest - 1;
                        let item = (node.child[lane], entry[lane]);
                        self.prefetch(item.0, blocks);
                        let mut at = top;
                        // SAFETY: the slots from `base` to `top` were
                        // written above.
                        #[allow(unsafe_code)]
                        while at > base && unsafe { stack[at - 1].assume_init().1 } <= item.1 {
                            stack[at] = stack[at - 1];
                            at -= 1;
                        }
                        stack[at] = MaybeUninit::new(item);
                        top += 1;
                    }
                    top -= 1;
                    // SAFETY: written above.
                    #[allow(unsafe_code)]
                    {
                        current = unsafe { stack[top].assume_init().0 };
                    }
                    continue;
                }
            }
            // The nearest child left on the stack that is not beyond the
            // closest hit found.
            current = loop {
                if top == 0 {
                    return t_max;
                }
                top -= 1;
                // SAFETY: the slots below `top` were written by pushes.
                #[allow(unsafe_code)]
                let (c, t) = unsafe { stack[top].assume_init() };
                if t <= t_max * WIDEN {
                    break c;
                }
            };
        }
    }

    /// Whether `hit(first, count)` finds any triangle along the ray (it
    /// returns whether one of the blocks `first..first + count` of the
    /// intersector's list is hit).
    #[inline(always)]
    pub(super) fn any(
        &self,
        query: &Query,
        t_max: f32,
        enter: impl Fn(&Node, &Query, f32) -> (u32, [f32; 8]),
        mut hit: impl FnMut(usize, usize) -> bool,
        blocks: &[Block],
    ) -> bool {
        let (mut inline, mut heap) = ([MaybeUninit::uninit(); INLINE_STACK], Vec::new());
        let stack: &mut [MaybeUninit<u32>] = match self.stack_room() {
            room if room <= INLINE_STACK => &mut inline,
            room => {
                heap.resize(room, MaybeUninit::uninit());
                &mut heap
            }
        };
        let (mut top, mut current) = (0, self.root);
        loop {
            if current & LEAF != 0 {
                let (first, count) = leaf(current);
                if hit(self.base + first, count) {
                    return true;
                }
            } else {
                let node = &self.nodes[current as usize];
                let (mut mask, _) = enter(node, query, t_max);
                if mask != 0 {
                    // The first child entered next, without the stack; the
                    // others pushed (and prefetched).
                    current = node.child[mask.trailing_zeros() as usize];
                    mask &= mask - 1;
                    while mask != 0 {
                        let lane = mask.trailing_zeros() as usize;
                        mask &= mask - 1;
                        self.prefetch(node.child[lane], blocks);
                        stack[top] = MaybeUninit::new(node.child[lane]);
                        top += 1;
                    }
                    continue;
                }
            }
            if top == 0 {
                return false;
            }
            top -= 1;
            // SAFETY: the slots below `top` were written by pushes.
            #[allow(unsafe_code)]
            {
                current = unsafe { stack[top].assume_init() };
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use obvhs::BvhBuildParams;
    use obvhs::bvh2::builder::build_bvh2_from_tris;
    use obvhs::triangle::Triangle;

    /// Small triangles scattered in a box, with a few long slivers across
    /// it (so that some subtrees are cheaper as leaves and some as nodes).
    fn binary_tree() -> Bvh2 {
        let mut rnd = crate::bvh::test_uniforms(7);
        let triangles: Vec<Triangle> = (0..3000)
            .map(|k| {
                let size = if k % 100 == 0 { 3.0 } else { 0.05 };
                let p = Vec3A::new(rnd(), rnd(), rnd()) * 4.0;
                let mut corner = || p + Vec3A::new(rnd(), rnd(), rnd()) * size;
                Triangle {
                    v0: p,
                    v1: corner(),
                    v2: corner(),
                }
            })
            .collect();
        let params = BvhBuildParams {
            max_prims_per_leaf: 1,
            ..BvhBuildParams::medium_build()
        };
        build_bvh2_from_tris(&triangles, params, &mut core::time::Duration::default())
    }

    /// The tree built holds every triangle once, in leaves of at most
    /// [`LEAF_SIZE`], and costs what [`Plan`] found least: its nodes'
    /// and leaves' areas, weighed by the heuristic's costs, add up to the
    /// plan's cost of the root (rounding aside).
    #[test]
    fn the_tree_holds_every_triangle_once_at_the_plans_cost() {
        let bvh = binary_tree();
        let (_, planned) = Plan::new(&bvh);
        let (tree, blocks) = Wide::collapse(&bvh, 0);
        let mut held: Vec<u32> = blocks
            .iter()
            .flatten()
            .copied()
            .filter(|&t| t != NO_TRIANGLE)
            .collect();
        held.sort_unstable();
        assert_eq!(held, (0..3000).collect::<Vec<u32>>());
        let half_area = |node: &Node, lane: usize| {
            let d = [0, 1, 2].map(|a| node.bounds[2 * a + 1][lane] - node.bounds[2 * a][lane]);
            ((d[0] + d[1]) * d[2] + d[0] * d[1]) as f64
        };
        let mut cost = bvh.nodes[0].aabb.half_area() as f64 * NODE_COST as f64;
        let (mut leaves, mut inner) = (0, 0);
        for node in &tree.nodes {
            for (lane, &child) in node.child.iter().enumerate() {
                if child == EMPTY {
                    continue;
                }
                let weight = if child & LEAF != 0 {
                    let (_, count) = leaf(child);
                    leaves += 1;
                    count as f32 * BLOCK_COST
                } else {
                    inner += 1;
                    NODE_COST
                };
                cost += half_area(node, lane) * weight as f64;
            }
        }
        let planned = planned as f64;
        assert!(
            (cost - planned).abs() < 1e-4 * planned,
            "{cost} against {planned}"
        );
        // Both kinds of children are common, and nodes are nearly full.
        assert_eq!(inner + 1, tree.nodes.len());
        assert!(leaves > 200 && inner > 20, "{leaves} leaves, {inner} nodes");
        assert!(leaves + inner > 6 * tree.nodes.len(), "{leaves} {inner}");
    }
}
