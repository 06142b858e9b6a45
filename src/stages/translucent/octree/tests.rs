use super::*;
use crate::physics::rng::StreamKey;

fn rnd(key: StreamKey, i: u64, d: u32) -> f64 {
    key.uniform(i, d)
}

/// Random small boxes around random positions in [0, 1]³.
fn random_items(n: usize, seed: u64) -> Vec<Item> {
    let k = StreamKey { table: seed, cell: 0 };
    (0..n as u64)
        .map(|i| {
            let p = DVec3::new(rnd(k, i, 0), rnd(k, i, 1), rnd(k, i, 2));
            let h = DVec3::new(rnd(k, i, 3), rnd(k, i, 4), rnd(k, i, 5)) * 0.05;
            Item { position: p, bounds: (p - h, p + h * 0.5) }
        })
        .collect()
}

fn check_structure(t: &Octree, items: &[Item], max_leaf: usize, max_depth: u8) {
    let valid: Vec<u32> = (0..items.len() as u32)
        .filter(|&i| {
            let it = &items[i as usize];
            it.position.is_finite() && it.bounds.0.is_finite() && it.bounds.1.is_finite()
        })
        .collect();
    // Each valid item in exactly one leaf.
    let mut seen = vec![0u32; items.len()];
    for (ni, n) in t.nodes.iter().enumerate() {
        if n.is_leaf() {
            for &i in t.node_items(ni as u32) {
                seen[i as usize] += 1;
                assert!(items[i as usize].position.cmpge(n.cell.0).all());
                assert!(items[i as usize].position.cmple(n.cell.1).all());
            }
            let items_here = t.node_items(ni as u32);
            let coincide =
                items_here.iter().all(|&i| items[i as usize].position == items[items_here[0] as usize].position);
            assert!(items_here.len() <= max_leaf || n.depth >= max_depth || coincide, "leaf of {}", items_here.len());
            assert_eq!(n.height, 0);
        } else {
            // Children ranges tile the parent's range, in order.
            let mut next = n.first_item;
            let mut h = 0;
            for c in n.children() {
                let c = &t.nodes[c as usize];
                assert_eq!(c.first_item, next);
                assert!(c.item_count > 0);
                assert_eq!(c.depth, n.depth + 1);
                next += c.item_count;
                h = h.max(c.height + 1);
                assert!(c.bounds.0.cmpge(n.bounds.0).all() && c.bounds.1.cmple(n.bounds.1).all());
            }
            assert_eq!(next, n.first_item + n.item_count);
            assert_eq!(n.height, h);
        }
    }
    for (i, &count) in seen.iter().enumerate() {
        assert_eq!(count, u32::from(valid.contains(&(i as u32))), "item {i}");
    }
    if !valid.is_empty() {
        assert_eq!(t.nodes[0].item_count as usize, valid.len());
    }
}

#[test]
fn build_partitions_items_into_leaves() {
    let items = random_items(3000, 7);
    let t = Octree::build(&items, 8, 20);
    check_structure(&t, &items, 8, 20);
    assert!(t.nodes.len() > 3000 / 8);
    // Depth-limited tree: leaves may be larger but the partition still holds.
    let t2 = Octree::build(&items, 8, 2);
    check_structure(&t2, &items, 8, 2);
    assert!(t2.nodes.iter().all(|n| n.depth <= 2));
}

#[test]
fn bottom_up_sum_equals_total() {
    let items = random_items(1000, 3);
    let t = Octree::build(&items, 8, 20);
    let w = |i: u32| (i as f64 + 1.0).sqrt();
    let agg = t.bottom_up(|its| its.iter().map(|&i| w(i)).sum::<f64>(), |k| k.iter().sum());
    let total: f64 = (0..1000u32).map(w).sum();
    assert!((agg[0] - total).abs() < 1e-9 * total);
    // Every node's aggregate equals the direct sum over its item range.
    for (ni, a) in agg.iter().enumerate() {
        let direct: f64 = t.node_items(ni as u32).iter().map(|&i| w(i)).sum();
        assert!((a - direct).abs() < 1e-9 * direct.max(1.0));
    }
    let counts = t.bottom_up(|its| its.len(), |k| k.iter().sum());
    assert_eq!(counts[0], 1000);
}

fn brute_hits(items: &[Item], o: DVec3, d: DVec3, tm: f64) -> Vec<u32> {
    let inv = inverse(d);
    (0..items.len() as u32).filter(|&i| segment_hits_box(o, d, inv, tm, &items[i as usize].bounds)).collect()
}

#[test]
fn ray_traversal_is_conservative_and_frontier_is_exact() {
    let items = random_items(2000, 11);
    let t = Octree::build(&items, 8, 20);
    let k = StreamKey { table: 99, cell: 1 };
    for r in 0..200u64 {
        let o = DVec3::new(rnd(k, r, 0), rnd(k, r, 1), rnd(k, r, 2)) * 3.0 - 1.0;
        let mut d = DVec3::new(rnd(k, r, 3), rnd(k, r, 4), rnd(k, r, 5)) * 2.0 - 1.0;
        // Axis-parallel rays exercise the zero-direction branch.
        if r % 5 == 0 {
            d = DVec3::new(d.x, 0.0, 0.0);
        }
        let tm = if r % 3 == 0 { f64::INFINITY } else { 0.2 + 2.0 * rnd(k, r, 6) };
        let mut from_root = Vec::new();
        t.ray_items(&[0], o, d, tm, |i| from_root.push(i));
        from_root.sort_unstable();
        let brute = brute_hits(&items, o, d, tm);
        for i in &brute {
            assert!(from_root.binary_search(i).is_ok(), "ray {r}: item {i} missed");
        }
        // A 2×2 bundle around this ray: the frontier gives the identical set per ray.
        let bundle: Vec<(DVec3, DVec3, f64)> = (0..4)
            .map(|j| {
                let off = DVec3::new(0.02 * (j & 1) as f64, 0.02 * (j >> 1) as f64, 0.0);
                (o + off, d, tm)
            })
            .collect();
        for h in [0u8, 1, 2, 5] {
            let mut frontier = Vec::new();
            t.ray_frontier(&bundle, h, &mut frontier);
            assert!(frontier.iter().all(|&f| t.nodes[f as usize].height <= h || t.nodes[f as usize].is_leaf()));
            for &(bo, bd, bt) in &bundle {
                let mut a = Vec::new();
                let mut b = Vec::new();
                t.ray_items(&[0], bo, bd, bt, |i| a.push(i));
                t.ray_items(&frontier, bo, bd, bt, |i| b.push(i));
                a.sort_unstable();
                b.sort_unstable();
                assert_eq!(a, b, "ray {r}, stop height {h}");
            }
        }
    }
}

#[test]
fn slab_test_on_hand_built_cases() {
    let b = (DVec3::ZERO, DVec3::ONE);
    let hit = |o: DVec3, d: DVec3, t: f64| segment_hits_box(o, d, inverse(d), t, &b);
    assert!(hit(DVec3::new(-1.0, 0.5, 0.5), DVec3::X, 1.0)); // reaches x = 0 exactly at t = 1
    assert!(!hit(DVec3::new(-1.0, 0.5, 0.5), DVec3::X, 0.999));
    assert!(!hit(DVec3::new(-1.0, 1.5, 0.5), DVec3::X, 10.0)); // parallel, outside in y
    assert!(hit(DVec3::new(0.5, 0.5, 0.5), -DVec3::Y, 0.0)); // starts inside
    assert!(!hit(DVec3::new(2.0, 0.5, 0.5), DVec3::X, f64::INFINITY)); // box behind
    assert!(hit(DVec3::new(-1.0, -1.0, 0.5), DVec3::new(1.0, 1.0, 0.0), 1.0)); // touches the corner
}

#[test]
fn cuts_partition_items() {
    let items = random_items(1500, 5);
    let t = Octree::build(&items, 8, 20);
    let mut out = Vec::new();
    t.cut(&[0], |_| true, &mut out);
    let mut all: Vec<u32> = out.iter().map(|e| if let CutEntry::Item(i) = e { *i } else { panic!("{e:?}") }).collect();
    all.sort_unstable();
    assert_eq!(all, (0..1500).collect::<Vec<u32>>());
    out.clear();
    assert_eq!(t.cut(&[0], |_| false, &mut out), 1);
    assert_eq!(out, vec![CutEntry::Node(0)]);
    // A distance-driven cut (Algorithm 1 style): refine nodes large relative to their distance.
    for (q, ratio) in [(DVec3::splat(0.3), 0.5), (DVec3::new(2.0, 0.0, 0.5), 0.2), (DVec3::splat(0.9), 2.0)] {
        out.clear();
        t.cut(
            &[0],
            |n| {
                let n = &t.nodes[n as usize];
                let size = (n.bounds.1 - n.bounds.0).length();
                let dist = q.clamp(n.bounds.0, n.bounds.1).distance(q);
                size > ratio * dist
            },
            &mut out,
        );
        let mut count = vec![0u32; 1500];
        for e in &out {
            match *e {
                CutEntry::Node(n) => t.node_items(n).iter().for_each(|&i| count[i as usize] += 1),
                CutEntry::Item(i) => count[i as usize] += 1,
            }
        }
        assert!(count.iter().all(|&c| c == 1));
    }
}

#[test]
fn degenerate_inputs_do_not_panic() {
    let t = Octree::build(&[], 8, 20);
    assert!(t.nodes.is_empty());
    let mut v = Vec::new();
    assert_eq!(t.ray_items(&[0], DVec3::ZERO, DVec3::X, 1.0, |_| panic!()), 0);
    assert_eq!(t.ray_frontier(&[(DVec3::ZERO, DVec3::X, 1.0)], 1, &mut v), 0);
    assert_eq!(t.cut(&[0], |_| true, &mut Vec::new()), 0);
    assert!(t.bottom_up(|i| i.len(), |k| k.len()).is_empty());
    assert!(t.node_items(0).is_empty());

    let one = [Item { position: DVec3::ONE, bounds: (DVec3::ONE, DVec3::ONE) }];
    let t = Octree::build(&one, 8, 20);
    assert_eq!(t.nodes.len(), 1);
    assert_eq!(t.items, vec![0]);
    let mut got = Vec::new();
    t.ray_items(&[0], DVec3::ZERO, DVec3::ONE, 2.0, |i| got.push(i));
    assert_eq!(got, vec![0]);

    let same: Vec<Item> =
        (0..1000).map(|_| Item { position: DVec3::splat(0.25), bounds: (DVec3::ZERO, DVec3::splat(0.5)) }).collect();
    let t = Octree::build(&same, 8, 255);
    check_structure(&t, &same, 8, 255);
    assert_eq!(t.nodes.len(), 1);

    let mut mixed = random_items(50, 1);
    mixed[3].position = DVec3::new(f64::NAN, 0.0, 0.0);
    mixed[7].bounds.1 = DVec3::splat(f64::INFINITY);
    let t = Octree::build(&mixed, 4, 255);
    check_structure(&t, &mixed, 4, 255);
    assert_eq!(t.items.len(), 48);
    // Two positions one ulp apart with max_depth 255 terminate.
    let close = [
        Item { position: DVec3::splat(1.0), bounds: (DVec3::ONE, DVec3::ONE) },
        Item { position: DVec3::splat(1.0 + f64::EPSILON), bounds: (DVec3::ONE, DVec3::ONE) },
    ];
    let t = Octree::build(&close, 1, 255);
    check_structure(&t, &close, 1, 255);
    // Bad rays visit nothing.
    let t = Octree::build(&random_items(100, 2), 8, 20);
    assert_eq!(t.ray_items(&[0], DVec3::NAN, DVec3::X, 1.0, |_| panic!()), 0);
    assert_eq!(t.ray_items(&[0], DVec3::ZERO, DVec3::X, f64::NAN, |_| panic!()), 0);
    assert_eq!(t.ray_items(&[7_000_000], DVec3::ZERO, DVec3::X, 1.0, |_| panic!()), 0);
}
