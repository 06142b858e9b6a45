use super::*;

fn seg(pixel: u32, d_max: f64) -> SegmentShape {
    SegmentShape { pixel, primary: true, samples: 4, d_max, dir: DVec3::Z, normal: -DVec3::Z }
}

#[test]
fn anchors_are_direct_and_the_rest_interpolates_bilinearly() {
    // 9 × 5 pixels, one segment each, stride 4: anchor columns 0, 4, 8 and rows 0, 4.
    let (w, h) = (9, 5);
    let segs: Vec<SegmentShape> = (0..w * h).map(|p| seg(p as u32, 1.0)).collect();
    let plan = plan(w, h, 4, &segs);
    let direct: Vec<usize> = (0..w * h).filter(|&i| plan[i] == Plan::Direct).collect();
    assert_eq!(direct, vec![0, 4, 8, 36, 40, 44]);
    // Pixel (1, 2): weights (3/4·1/2, 1/4·1/2, 3/4·1/2, 1/4·1/2) on pixels 0, 4, 36, 40.
    let Plan::Interp(t) = plan[1 + 2 * w] else { panic!("not interpolated") };
    assert_eq!(t, [(0, 0.375), (4, 0.125), (36, 0.375), (40, 0.125)]);
    // A pixel on an anchor row uses two taps; weights always sum to 1.
    let Plan::Interp(t) = plan[6] else { panic!() };
    assert_eq!(t[0], (4, 0.5));
    assert_eq!(t[1], (8, 0.5));
    for p in &plan {
        if let Plan::Interp(t) = p {
            assert!((t.iter().map(|x| x.1).sum::<f64>() - 1.0).abs() < 1e-15);
        }
    }
}

#[test]
fn edges_fall_back_to_direct() {
    let (w, h) = (5, 5);
    let mut segs: Vec<SegmentShape> = (0..w * h).map(|p| seg(p as u32, 1.0)).collect();
    // Anchor pixel 4 (x = 4, y = 0) is three times as long: its cell's pixels on row 0..4 near it fall back.
    segs[4].d_max = 3.0;
    // Anchor 20 (x = 0, y = 4) looks elsewhere.
    segs[20].dir = DVec3::X;
    let plan = plan(w, h, 4, &segs);
    assert_eq!(plan[2], Plan::Direct); // row 0 between anchors 0 and 4
    assert_eq!(plan[10], Plan::Direct); // column 0 between anchors 0 and 20
    assert_eq!(plan[5 + 2], Plan::Direct); // inside the cell: all four corners needed
    // Stride 1 and a missing anchor segment: everything that lacks a partner is direct.
    assert!(super::plan(w, h, 1, &segs).iter().all(|p| *p == Plan::Direct));
    let sparse: Vec<SegmentShape> = segs.iter().copied().filter(|s| s.pixel != 0).collect();
    let p = super::plan(w, h, 4, &sparse);
    assert_eq!(p[0], Plan::Direct); // pixel 1 needs pixel 0's segment
}
