//! An eight-wide BVH of our own: obvhs's binary tree (PLOC with
//! reinsertion, leaves of at most four triangles) collapsed into nodes of
//! eight children whose float bounds lie in SIMD lanes, as Wald, Benthin
//! and Boulos (2008) and Embree's BVH8 lay them out; the children a ray
//! enters are visited nearest first, farther ones kept on a stack with
//! their entry distance so that those beyond a closer hit are dropped.
//!
//! The node test is written once over eight lanes ([`enter`]) and once in
//! AVX2 (`avx2.rs`), with the same operations in the same order (a
//! difference then a product, maxima and minima with the ray's own range
//! second): both find the same children, hence the same hits.

use core::mem::MaybeUninit;

use glam::Vec3A;
use obvhs::bvh2::Bvh2;

/// A child slot that holds nothing.
const EMPTY: u32 = u32::MAX;
/// A child slot that holds a leaf: this bit, the triangle count less one in
/// the next two bits, the first triangle (of the tree's own) in the rest.
const LEAF: u32 = 1 << 31;
const COUNT_SHIFT: u32 = 29;
const FIRST_MASK: u32 = (1 << COUNT_SHIFT) - 1;

/// The most triangles one tree holds (2^29: what a leaf's first index
/// encodes); larger scenes are split into several trees.
pub(super) const MAX_TRIANGLES: usize = 1 << COUNT_SHIFT;

/// The factor a child's exit distance is widened by before it is compared
/// with the entry: `1 + 2^-20`, a few ulps, more than the rounding of the
/// slab distances and of the triangle test's `t` together (Ize 2013 widens
/// by `1 + 2γ_3`). Without it a flat box (an axis-aligned wall's) could be
/// passed by where its triangle is hit an ulp closer than a neighbour's.
pub(super) const WIDEN: f32 = 1.0 + 1.0 / (1 << 20) as f32;

/// Slots of a traversal's stack kept on the thread's stack, uninitialized
/// (filling them cost 3 % of a path's instructions): enough for trees 36
/// levels deep (a 5M-triangle mesh's is 22); a deeper tree's stack is on
/// the heap, allocated per ray (which a 96-slot stack did for every mesh of
/// 1M triangles or more, 18 levels and deeper).
const INLINE_STACK: usize = 256;

/// The most triangles a leaf holds (the binary tree's leaves are collapsed
/// to at most four, what the encoding holds).
pub(super) const LEAF_SIZE: u32 = 4;

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
            near,
            far: near.map(|n| n ^ 1),
            t_min: ray.tmin,
        }
    }
}

/// The children of `node` that a ray (`query`, with its current farthest
/// distance `t_max`) enters: a bit per child, and the distances it enters
/// them at. The lane-by-lane twin of `avx2::enter`.
pub(super) fn enter(node: &Node, query: &Query, t_max: f32) -> (u32, [f32; 8]) {
    let o = query.origin.to_array();
    let inv = query.inv_direction.to_array();
    let mut mask = 0;
    let mut entry = [0.0; 8];
    for (lane, entered) in entry.iter_mut().enumerate() {
        let slab = |axis: usize, row: usize| (node.bounds[row][lane] - o[axis]) * inv[axis];
        let [nx, ny, nz] = [0, 1, 2].map(|a| slab(a, query.near[a]));
        let [fx, fy, fz] = [0, 1, 2].map(|a| slab(a, query.far[a]));
        // f32::max and min keep the operand that is not NaN, as maxps and
        // minps do when the NaN is first; the second is never NaN here.
        let t0 = nx.max(ny.max(nz.max(query.t_min)));
        let t1 = fx.min(fy.min(fz.min(t_max))) * WIDEN;
        *entered = t0;
        mask |= ((t0 <= t1) as u32) << lane;
    }
    (mask, entry)
}

/// The tree: its nodes, the root first, over triangles in the order of the
/// binary tree's primitive indices, from `base` on in the intersector's.
pub(super) struct Wide {
    nodes: Vec<Node>,
    /// Where the tree's triangles start in the intersector's order.
    base: usize,
    /// The deepest path from the root, in nodes: the traversal's stack
    /// holds at most seven children a level.
    depth: usize,
}

/// A leaf's triangles: `first..first + count` of the tree's order.
fn leaf(child: u32) -> (usize, usize) {
    let first = (child & FIRST_MASK) as usize;
    let count = ((child & !LEAF) >> COUNT_SHIFT) as usize + 1;
    (first, count)
}

impl Wide {
    /// The binary tree `bvh` (leaves of at most [`LEAF_SIZE`] primitives,
    /// at most [`MAX_TRIANGLES`] of them) collapsed: each node takes its children's
    /// children, the largest in surface area first, until it has eight
    /// or only leaves (Wald et al. 2008's collapse).
    /// Its triangles start at `base` of the intersector's order.
    pub(super) fn collapse(bvh: &Bvh2, base: usize) -> Self {
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
        let mut nodes = vec![empty];
        let mut depth = 1;
        // (the binary node a wide node is made from, the wide node, its depth)
        let mut todo = vec![(0usize, 0usize, 1usize)];
        while let Some((binary, wide, level)) = todo.pop() {
            depth = depth.max(level);
            let root = &bvh.nodes[binary];
            let mut children = if root.is_leaf() {
                vec![binary]
            } else {
                let first = root.first_index as usize;
                vec![first, first + 1]
            };
            while children.len() < 8 {
                let widest = children
                    .iter()
                    .enumerate()
                    .filter(|(_, c)| !bvh.nodes[**c].is_leaf())
                    .max_by(|a, b| {
                        let area = |i: &usize| bvh.nodes[*i].aabb.half_area();
                        area(a.1).total_cmp(&area(b.1))
                    })
                    .map(|(slot, _)| slot);
                let Some(slot) = widest else { break };
                let first = bvh.nodes[children[slot]].first_index as usize;
                children[slot] = first;
                children.push(first + 1);
            }
            for (lane, &c) in children.iter().enumerate() {
                let node = &bvh.nodes[c];
                let (lo, hi) = (node.aabb.min, node.aabb.max);
                let bounds = &mut nodes[wide].bounds;
                for axis in 0..3 {
                    bounds[2 * axis][lane] = lo[axis];
                    bounds[2 * axis + 1][lane] = hi[axis];
                }
                nodes[wide].child[lane] = if node.is_leaf() {
                    debug_assert!(node.prim_count <= LEAF_SIZE && node.first_index <= FIRST_MASK);
                    LEAF | ((node.prim_count - 1) << COUNT_SHIFT) | node.first_index
                } else {
                    nodes.push(empty);
                    let index = nodes.len() - 1;
                    todo.push((c, index, level + 1));
                    index as u32
                };
            }
        }
        Wide { nodes, base, depth }
    }

    /// Room for the traversal's stack.
    fn stack_room(&self) -> usize {
        7 * self.depth + 1
    }

    /// The closest of the triangles `hit(first, count, t_max)` finds
    /// along the ray (which returns the nearest it hits closer than
    /// `t_max`), children found by `enter`.
    #[inline(always)]
    pub(super) fn closest(
        &self,
        query: &Query,
        t_max: f32,
        enter: impl Fn(&Node, &Query, f32) -> (u32, [f32; 8]),
        mut hit: impl FnMut(usize, usize, f32) -> Option<f32>,
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
        let mut next = Some(0u32);
        loop {
            let current = match next.take() {
                Some(c) => c,
                None => loop {
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
                },
            };
            if current & LEAF != 0 {
                let (first, count) = leaf(current);
                if let Some(t) = hit(self.base + first, count, t_max) {
                    t_max = t;
                }
                continue;
            }
            let node = &self.nodes[current as usize];
            let (mut mask, entry) = enter(node, query, t_max);
            if mask == 0 {
                continue;
            }
            // The entered children, nearest first (an insertion sort of at
            // most eight); the nearest is visited next, the others pushed
            // farthest first.
            let mut order = [(0u32, 0f32); 8];
            let mut n = 0;
            while mask != 0 {
                let lane = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                let item = (node.child[lane], entry[lane]);
                let mut at = n;
                while at > 0 && order[at - 1].1 > item.1 {
                    order[at] = order[at - 1];
                    at -= 1;
                }
                order[at] = item;
                n += 1;
            }
            for &item in order[1..n].iter().rev() {
                stack[top] = MaybeUninit::new(item);
                top += 1;
            }
            next = Some(order[0].0);
        }
    }

    /// Whether `hit(first, count, t_max)` finds any triangle along the ray
    /// (it returns whether one of its triangles is hit).
    #[inline(always)]
    pub(super) fn any(
        &self,
        query: &Query,
        t_max: f32,
        enter: impl Fn(&Node, &Query, f32) -> (u32, [f32; 8]),
        mut hit: impl FnMut(usize, usize) -> bool,
    ) -> bool {
        let (mut inline, mut heap) = ([MaybeUninit::uninit(); INLINE_STACK], Vec::new());
        let stack: &mut [MaybeUninit<u32>] = match self.stack_room() {
            room if room <= INLINE_STACK => &mut inline,
            room => {
                heap.resize(room, MaybeUninit::uninit());
                &mut heap
            }
        };
        stack[0] = MaybeUninit::new(0);
        let mut top = 1;
        while top > 0 {
            top -= 1;
            // SAFETY: the slots below `top` were written by pushes.
            #[allow(unsafe_code)]
            let current = unsafe { stack[top].assume_init() };
            if current & LEAF != 0 {
                let (first, count) = leaf(current);
                if hit(self.base + first, count) {
                    return true;
                }
                continue;
            }
            let node = &self.nodes[current as usize];
            let (mut mask, _) = enter(node, query, t_max);
            while mask != 0 {
                let lane = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                stack[top] = MaybeUninit::new(node.child[lane]);
                top += 1;
            }
        }
        false
    }
}
