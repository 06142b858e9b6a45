//! One acceleration structure (an obvhs CWBVH over a triangle list) and its traversal loop.
//!
//! **Input → output.** Triangles (f32, world space) → a compressed wide BVH whose leaves hold
//! triangles in slot order; a prepared ray and a visitor → the visitor called on every triangle slot
//! whose leaf box the ray may touch.
//!
//! **Conservative node test.** obvhs's own box test clamps the entry distance to 1e-4 and replaces the
//! inverse of small direction components by ±1/ε_f32, which can cull boxes that a ray starting close to
//! them, or running almost parallel to a face, does touch. The test below widens every slab by a bound
//! on its rounding error (32 ulp of the coordinates involved), treats an exactly zero direction
//! component as the slope 2⁻⁶⁴, and has no entry clamp, so a box is never culled when the ray touches
//! it. Culling errs only towards visiting a few more nodes; which triangles are hit is decided by the
//! triangle test alone, so results do not depend on the tree's shape (which the parallel build may
//! vary with the thread count).
//!
//! The traversal order follows obvhs's `traverse!` macro (Ylitie et al. 2017 hit masks); the stack
//! spills to the heap instead of overwriting its last entry, so no depth loses a subtree.

use std::time::Duration;

use glam::Vec3A;
use obvhs::BvhBuildParams;
use obvhs::cwbvh::CwBvh;
use obvhs::cwbvh::builder::build_cwbvh_from_tris;
use obvhs::cwbvh::node::{CwBvhNode, extract_byte64};

use super::triangle::{PreparedRay, Tri};

/// Relative widening of each slab in the node test (2⁻¹⁸: 32 ulp of f32).
const SLAB_PAD: f32 = 1.0 / (1u32 << 18) as f32;

/// Stand-in inverse of an exactly zero direction component (larger than any real one, which the
/// flushing of components below 2⁻⁶⁰ bounds by 2⁶⁰).
const ZERO_COMPONENT_INV: f32 = 18_446_744_073_709_551_616.0; // 2^64

/// Triangles and the BVH over them.
#[derive(Debug, Clone, Default)]
pub(super) struct Accel {
    /// `None` when there are no triangles.
    bvh: Option<CwBvh>,
    /// Triangles in BVH slot order.
    pub tris: Vec<Tri>,
}

/// What the box test needs of a ray.
#[derive(Debug, Clone, Copy)]
pub(super) struct NodeRay {
    o: [f32; 3],
    inv: [f32; 3],
    oct_inv4: u32,
    t_min: f32,
}

impl NodeRay {
    /// From a prepared ray; `t_min` in internal units.
    pub fn new(r: &PreparedRay, t_min: f32) -> Self {
        let inv = r.d.map(|x| if x == 0.0 { ZERO_COMPONENT_INV } else { 1.0 / x });
        // The octant bits of obvhs's ray_get_octant_inv4 (traversal order of the children).
        let oct_inv4 = (if r.d[0] < 0.0 { 0 } else { 0x0404_0404 })
            | (if r.d[1] < 0.0 { 0 } else { 0x0202_0202 })
            | (if r.d[2] < 0.0 { 0 } else { 0x0101_0101 });
        NodeRay { o: r.o, inv, oct_inv4, t_min }
    }
}

impl Accel {
    /// Builds the BVH (obvhs medium-quality PLOC build on the current rayon pool) and stores the
    /// triangles in slot order.
    pub fn build(tris: Vec<Tri>) -> Self {
        if tris.is_empty() {
            return Accel::default();
        }
        let shapes: Vec<obvhs::triangle::Triangle> = tris
            .iter()
            .map(|t| obvhs::triangle::Triangle {
                v0: Vec3A::from_array(t.v[0]),
                v1: Vec3A::from_array(t.v[1]),
                v2: Vec3A::from_array(t.v[2]),
            })
            .collect();
        // medium_build has no spatial pre-splits: every triangle sits in exactly one leaf slot.
        let bvh = build_cwbvh_from_tris(&shapes, BvhBuildParams::medium_build(), &mut Duration::default());
        let slots = bvh.primitive_indices.iter().map(|&i| tris[i as usize]).collect();
        Accel { bvh: Some(bvh), tris: slots }
    }

    /// Number of BVH nodes.
    pub fn nodes(&self) -> usize {
        self.bvh.as_ref().map_or(0, |b| b.nodes.len())
    }

    /// Calls `visit(slot, &mut t_max)` for each triangle slot in a leaf whose (widened) box the ray
    /// touches within `[t_min, t_max]`. The visitor may lower `t_max` (closest hit) and returns
    /// `true` to stop the traversal (any hit).
    #[inline]
    pub fn traverse(&self, ray: &NodeRay, mut t_max: f32, mut visit: impl FnMut(usize, &mut f32) -> bool) {
        let Some(bvh) = &self.bvh else { return };
        let mut stack = Stack::default();
        // (base index, mask): hit children in the high byte, imask in the low byte.
        let mut group: (u32, u32) = (0, 0x8000_0000);
        let mut prims: (u32, u32) = (0, 0);
        loop {
            while prims.1 != 0 {
                let local = 31 - prims.1.leading_zeros();
                prims.1 &= !(1u32 << local);
                if visit((prims.0 + local) as usize, &mut t_max) {
                    return;
                }
            }
            if group.1 & 0xff00_0000 != 0 {
                let hits = group.1;
                let offset = 31 - hits.leading_zeros();
                group.1 &= !(1u32 << offset);
                if group.1 & 0xff00_0000 != 0 {
                    stack.push(group);
                }
                let slot = (offset - 24) ^ (ray.oct_inv4 & 0xff);
                let relative = (hits & !(u32::MAX << slot)).count_ones();
                let node = &bvh.nodes[(group.0 + relative) as usize];
                let mask = node_hits(node, ray, t_max);
                group = (node.child_base_idx, (mask & 0xff00_0000) | u32::from(node.imask));
                prims = (node.primitive_base_idx, mask & 0x00ff_ffff);
            } else {
                group = (0, 0);
            }
            if prims.1 == 0 && group.1 & 0xff00_0000 == 0 {
                match stack.pop() {
                    Some(g) => group = g,
                    None => return,
                }
            }
        }
    }
}

/// The children of `node` whose widened boxes the ray touches within `[ray.t_min, t_max]`, as an
/// obvhs hit mask (internal children in the high byte by traversal priority, leaf primitives below).
#[inline(always)]
fn node_hits(node: &CwBvhNode, ray: &NodeRay, t_max: f32) -> u32 {
    let ext = node.compute_extent();
    let ext = [ext.x, ext.y, ext.z];
    let p = [node.p.x, node.p.y, node.p.z];
    let planes = [
        (&node.child_min_x, &node.child_max_x),
        (&node.child_min_y, &node.child_max_y),
        (&node.child_min_z, &node.child_max_z),
    ];
    let mut enter = [ray.t_min; 8];
    let mut exit = [t_max; 8];
    for a in 0..3 {
        let scale = ext[a] * ray.inv[a];
        let base = (p[a] - ray.o[a]) * ray.inv[a];
        // Bounds the rounding of the dequantised planes and of the slab distances (module doc).
        let pad = SLAB_PAD * (255.0 * ext[a] + 2.0 * p[a].abs() + ray.o[a].abs()) * ray.inv[a].abs();
        // The plane the ray reaches first (the low one for a positive direction component).
        let (near, far) = if ray.inv[a] < 0.0 { (planes[a].1, planes[a].0) } else { planes[a] };
        let (near_base, far_base) = (base - pad, base + pad);
        for c in 0..8 {
            // Comparisons rather than f32::min/max: plain SIMD min/max, and a NaN slab is ignored.
            let t_near = f32::from(near[c]) * scale + near_base;
            let t_far = f32::from(far[c]) * scale + far_base;
            enter[c] = if t_near > enter[c] { t_near } else { enter[c] };
            exit[c] = if t_far < exit[c] { t_far } else { exit[c] };
        }
    }
    let mut touched = 0u32;
    for c in 0..8 {
        touched |= u32::from(enter[c] <= exit[c]) << c;
    }
    if touched == 0 {
        return 0;
    }
    let (child_bits8, bit_index8) = node.get_child_and_index_bits(ray.oct_inv4);
    let mut mask = 0u32;
    while touched != 0 {
        let c = touched.trailing_zeros() as usize;
        touched &= touched - 1;
        mask |= extract_byte64(child_bits8, c) << extract_byte64(bit_index8, c);
    }
    mask
}

/// Traversal stack: 64 entries inline (a CWBVH of any practical size is far shallower), then the heap.
struct Stack {
    inline: [(u32, u32); 64],
    len: usize,
    spill: Vec<(u32, u32)>,
}

impl Default for Stack {
    fn default() -> Self {
        Stack { inline: [(0, 0); 64], len: 0, spill: Vec::new() }
    }
}

impl Stack {
    #[inline(always)]
    fn push(&mut self, g: (u32, u32)) {
        if self.len < self.inline.len() {
            self.inline[self.len] = g;
            self.len += 1;
        } else {
            self.spill.push(g);
        }
    }

    #[inline(always)]
    fn pop(&mut self) -> Option<(u32, u32)> {
        if let Some(g) = self.spill.pop() {
            return Some(g);
        }
        if self.len == 0 {
            return None;
        }
        self.len -= 1;
        Some(self.inline[self.len])
    }
}
