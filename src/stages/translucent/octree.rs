//! Octree over point-like items with extents: the spatial hierarchy of wang2018 Sec. 3.4 over the
//! volume samples (light-ray intervals) and the surface samples, stored as in Sec. 4.2 and traversed as
//! in Sec. 4.3.
//!
//! **Input → output.** Items (a position deciding the cell, an axis-aligned box bounding the item's
//! extent) → a flat array of nodes whose children are contiguous and whose items form one contiguous
//! range of [`Octree::items`] (items are stored in leaf order), with per node the octree cell, the union
//! of the items' boxes, depth and height. Queries: per-node aggregates ([`Octree::bottom_up`]), ray
//! traversal over node boxes (single scattering, [`Octree::ray_items`]), the first step of the two-step
//! traversal of a ray bundle ([`Octree::ray_frontier`]) and tree cuts (Algorithm 1, [`Octree::cut`]).
//!
//! Every traversal is iterative with an explicit stack, so deep trees cannot overflow the call stack.
//! The ray–box test is the slab test evaluated with the same floating-point operations for every box:
//! the result is monotone under box containment (a ray that hits a box hits every box containing it),
//! which is what makes a traversal from a frontier visit exactly the items a traversal from the root
//! visits.

use std::collections::VecDeque;

use glam::DVec3;

/// One item to index.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Item {
    /// Decides the octree cell the item falls in.
    pub position: DVec3,
    /// Axis-aligned box (min, max) of the item's extent, unioned into the node boxes used for culling.
    pub bounds: (DVec3, DVec3),
}

/// One octree node.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Node {
    /// The octree cell (min, max).
    pub cell: (DVec3, DVec3),
    /// Union of the boxes of the items below (min, max).
    pub bounds: (DVec3, DVec3),
    /// Index of the first child in [`Octree::nodes`], `u32::MAX` for a leaf.
    pub first_child: u32,
    /// Number of (non-empty) children, stored contiguously from `first_child`.
    pub child_count: u8,
    /// First entry of this node's range in [`Octree::items`].
    pub first_item: u32,
    /// Length of that range (all items below the node).
    pub item_count: u32,
    /// Depth, 0 at the root.
    pub depth: u8,
    /// 0 for a leaf, 1 + the largest child height otherwise.
    pub height: u8,
}

impl Node {
    /// Whether the node has no children.
    pub fn is_leaf(&self) -> bool {
        self.first_child == u32::MAX
    }

    /// Indices of the children.
    pub fn children(&self) -> std::ops::Range<u32> {
        if self.is_leaf() { 0..0 } else { self.first_child..self.first_child + u32::from(self.child_count) }
    }
}

/// The octree: nodes (root at index 0, children after their parent) and item indices in leaf order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Octree {
    /// Nodes; empty when no item was indexed.
    pub nodes: Vec<Node>,
    /// Indices into the `items` slice given to [`Octree::build`], in leaf order.
    pub items: Vec<u32>,
}

/// One entry of a tree cut.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CutEntry {
    /// A node taken as a whole (index into [`Octree::nodes`]).
    Node(u32),
    /// A single item of a leaf that still wanted refinement (index into the built items).
    Item(u32),
}

/// Slab test of the segment `origin + t·dir`, `t ∈ [0, t_max]`, against the box `(lo, hi)`.
/// `inv` holds `1/dir` per axis (unused where `dir` is 0). Monotone under box containment.
#[inline]
fn segment_hits_box(origin: DVec3, dir: DVec3, inv: DVec3, t_max: f64, b: &(DVec3, DVec3)) -> bool {
    let mut t0 = 0.0f64;
    let mut t1 = t_max;
    for a in 0..3 {
        let (o, d, lo, hi) = (origin[a], dir[a], b.0[a], b.1[a]);
        if d == 0.0 {
            if !(o >= lo && o <= hi) {
                return false;
            }
        } else {
            let (mut n, mut f) = ((lo - o) * inv[a], (hi - o) * inv[a]);
            if n > f {
                std::mem::swap(&mut n, &mut f);
            }
            t0 = t0.max(n);
            t1 = t1.min(f);
            // t0 and t1 are never NaN: f64::max/min drop a NaN operand.
            if t0 > t1 {
                return false;
            }
        }
    }
    true
}

/// Whether a ray is usable: finite origin and direction, `t_max ≥ 0` (may be `+∞`).
fn ray_ok(origin: DVec3, dir: DVec3, t_max: f64) -> bool {
    origin.is_finite() && dir.is_finite() && t_max >= 0.0
}

fn inverse(dir: DVec3) -> DVec3 {
    DVec3::new(1.0 / dir.x, 1.0 / dir.y, 1.0 / dir.z)
}

fn union(a: (DVec3, DVec3), b: (DVec3, DVec3)) -> (DVec3, DVec3) {
    (a.0.min(b.0), a.1.max(b.1))
}

const EMPTY_BOX: (DVec3, DVec3) = (DVec3::INFINITY, DVec3::NEG_INFINITY);

impl Octree {
    /// Builds the octree top-down from the bounding cube of the items' positions. A node becomes a leaf
    /// when it holds at most `max_leaf` items (8 in the paper; 0 is treated as 1), when it is at depth
    /// `max_depth`, or when all its positions coincide. Items with a non-finite position or bounds are
    /// left out (they appear in no node). No items → no nodes.
    pub fn build(items: &[Item], max_leaf: usize, max_depth: u8) -> Octree {
        let max_leaf = max_leaf.max(1);
        let mut work: Vec<u32> = (0..items.len().min(u32::MAX as usize) as u32)
            .filter(|&i| {
                let it = &items[i as usize];
                it.position.is_finite() && it.bounds.0.is_finite() && it.bounds.1.is_finite()
            })
            .collect();
        if work.is_empty() {
            return Octree::default();
        }
        let pos = |i: u32| items[i as usize].position;
        let (lo, hi) = work.iter().fold(EMPTY_BOX, |b, &i| (b.0.min(pos(i)), b.1.max(pos(i))));
        let side = (hi - lo).max_element();
        let root_cell = (lo, lo + DVec3::splat(side));
        let mut nodes = vec![Node {
            cell: root_cell,
            bounds: EMPTY_BOX,
            first_child: u32::MAX,
            child_count: 0,
            first_item: 0,
            item_count: work.len() as u32,
            depth: 0,
            height: 0,
        }];
        // Breadth-first: children of a node are appended together, so they are contiguous and come
        // after their parent. Each node's items are a range of `work`, partitioned in place by octant.
        let mut queue = VecDeque::from([0u32]);
        let mut keyed: Vec<(u8, u32)> = Vec::new();
        while let Some(ni) = queue.pop_front() {
            let node = nodes[ni as usize];
            let range = node.first_item as usize..(node.first_item + node.item_count) as usize;
            if range.len() <= max_leaf || node.depth >= max_depth {
                continue;
            }
            let slice = &mut work[range.clone()];
            let first = pos(slice[0]);
            if slice.iter().all(|&i| pos(i) == first) {
                continue;
            }
            let (clo, chi) = node.cell;
            let mid = 0.5 * (clo + chi);
            let octant = |p: DVec3| u8::from(p.x >= mid.x) | u8::from(p.y >= mid.y) << 1 | u8::from(p.z >= mid.z) << 2;
            keyed.clear();
            keyed.extend(slice.iter().map(|&i| (octant(pos(i)), i)));
            // Stable: items keep their relative order within an octant (deterministic output).
            keyed.sort_by_key(|&(k, _)| k);
            for (dst, &(_, i)) in slice.iter_mut().zip(&keyed) {
                *dst = i;
            }
            let first_child = nodes.len() as u32;
            let mut start = 0usize;
            let mut count = 0u8;
            while start < keyed.len() {
                let k = keyed[start].0;
                let end = start + keyed[start..].iter().take_while(|&&(kk, _)| kk == k).count();
                let pick = |bit: u8, a: f64, b: f64, m: f64| if k & bit != 0 { (m, b) } else { (a, m) };
                let (x0, x1) = pick(1, clo.x, chi.x, mid.x);
                let (y0, y1) = pick(2, clo.y, chi.y, mid.y);
                let (z0, z1) = pick(4, clo.z, chi.z, mid.z);
                nodes.push(Node {
                    cell: (DVec3::new(x0, y0, z0), DVec3::new(x1, y1, z1)),
                    bounds: EMPTY_BOX,
                    first_child: u32::MAX,
                    child_count: 0,
                    first_item: node.first_item + start as u32,
                    item_count: (end - start) as u32,
                    depth: node.depth + 1,
                    height: 0,
                });
                queue.push_back(nodes.len() as u32 - 1);
                count += 1;
                start = end;
            }
            let n = &mut nodes[ni as usize];
            n.first_child = first_child;
            n.child_count = count;
        }
        // Children follow their parents: one reverse sweep fills bounds and heights.
        for ni in (0..nodes.len()).rev() {
            let n = nodes[ni];
            let (bounds, height) = if n.is_leaf() {
                let r = n.first_item as usize..(n.first_item + n.item_count) as usize;
                (work[r].iter().fold(EMPTY_BOX, |b, &i| union(b, items[i as usize].bounds)), 0)
            } else {
                n.children().fold((EMPTY_BOX, 0u8), |(b, h), c| {
                    let c = &nodes[c as usize];
                    (union(b, c.bounds), h.max(c.height.saturating_add(1)))
                })
            };
            nodes[ni].bounds = bounds;
            nodes[ni].height = height;
        }
        Octree { nodes, items: work }
    }

    /// The item indices below `node` (empty for an out-of-range index).
    pub fn node_items(&self, node: u32) -> &[u32] {
        match self.nodes.get(node as usize) {
            Some(n) => &self.items[n.first_item as usize..(n.first_item + n.item_count) as usize],
            None => &[],
        }
    }

    /// Per node aggregate: `leaf(items)` at a leaf, `merge(children's aggregates, in child order)` above.
    pub fn bottom_up<A: Clone>(&self, leaf: impl Fn(&[u32]) -> A, merge: impl Fn(&[A]) -> A) -> Vec<A> {
        let mut out: Vec<Option<A>> = vec![None; self.nodes.len()];
        let mut kids: Vec<A> = Vec::new();
        for ni in (0..self.nodes.len()).rev() {
            let n = &self.nodes[ni];
            let a = if n.is_leaf() {
                leaf(self.node_items(ni as u32))
            } else {
                kids.clear();
                kids.extend(n.children().filter_map(|c| out[c as usize].clone()));
                merge(&kids)
            };
            out[ni] = Some(a);
        }
        out.into_iter().flatten().collect()
    }

    /// Ray traversal: calls `visit` for every item of every leaf whose node box (and every ancestor's
    /// box up to one of `roots`) the segment `origin + t·dir`, `t ∈ [0, t_max]`, intersects, descending
    /// from `roots` (`&[0]` for the whole tree; out-of-range roots are ignored). `dir` need not be unit.
    /// Returns the number of nodes tested. A non-finite origin or direction or a negative or NaN
    /// `t_max` visits nothing.
    pub fn ray_items(&self, roots: &[u32], origin: DVec3, dir: DVec3, t_max: f64, mut visit: impl FnMut(u32)) -> usize {
        if !ray_ok(origin, dir, t_max) {
            return 0;
        }
        let inv = inverse(dir);
        let mut stack: Vec<u32> = roots.iter().rev().copied().filter(|&r| (r as usize) < self.nodes.len()).collect();
        let mut tested = 0usize;
        while let Some(ni) = stack.pop() {
            let n = &self.nodes[ni as usize];
            tested += 1;
            if !segment_hits_box(origin, dir, inv, t_max, &n.bounds) {
                continue;
            }
            if n.is_leaf() {
                self.node_items(ni).iter().for_each(|&i| visit(i));
            } else {
                stack.extend(n.children().rev());
            }
        }
        tested
    }

    /// First step of the two-step traversal (Sec. 4.3): appends to `out` the nodes of height
    /// `stop_height` (or leaves above that height) whose boxes at least one of `rays`
    /// (`(origin, dir, t_max)`) intersects, descending from the root only through nodes some ray hits.
    /// Used as `roots` of [`Octree::ray_items`] for each ray of the bundle it gives exactly the items a
    /// traversal from the root gives. Returns the number of node tests (node × ray pairs evaluated).
    pub fn ray_frontier(&self, rays: &[(DVec3, DVec3, f64)], stop_height: u8, out: &mut Vec<u32>) -> usize {
        let rays: Vec<(DVec3, DVec3, DVec3, f64)> =
            rays.iter().filter(|r| ray_ok(r.0, r.1, r.2)).map(|&(o, d, t)| (o, d, inverse(d), t)).collect();
        if self.nodes.is_empty() || rays.is_empty() {
            return 0;
        }
        let mut stack = vec![0u32];
        let mut tested = 0usize;
        while let Some(ni) = stack.pop() {
            let n = &self.nodes[ni as usize];
            let mut any = false;
            for &(o, d, inv, t) in &rays {
                tested += 1;
                if segment_hits_box(o, d, inv, t, &n.bounds) {
                    any = true;
                    break;
                }
            }
            if !any {
                continue;
            }
            if n.is_leaf() || n.height <= stop_height {
                out.push(ni);
            } else {
                stack.extend(n.children().rev());
            }
        }
        tested
    }

    /// Tree cut (Algorithm 1): from `roots` (out-of-range ones ignored), a node for which
    /// `refine(node)` is false is emitted as [`CutEntry::Node`]; otherwise its children are visited; a
    /// leaf that still wants refinement emits its items as [`CutEntry::Item`]. Entries come in
    /// depth-first order. Returns the number of nodes visited.
    pub fn cut(&self, roots: &[u32], mut refine: impl FnMut(u32) -> bool, out: &mut Vec<CutEntry>) -> usize {
        let mut stack: Vec<u32> = roots.iter().rev().copied().filter(|&r| (r as usize) < self.nodes.len()).collect();
        let mut visited = 0usize;
        while let Some(ni) = stack.pop() {
            visited += 1;
            let n = &self.nodes[ni as usize];
            if !refine(ni) {
                out.push(CutEntry::Node(ni));
            } else if n.is_leaf() {
                out.extend(self.node_items(ni).iter().map(|&i| CutEntry::Item(i)));
            } else {
                stack.extend(n.children().rev());
            }
        }
        visited
    }
}

#[cfg(test)]
mod tests;
