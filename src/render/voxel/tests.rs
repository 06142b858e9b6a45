use super::*;

#[test]
fn exr_slices_read_as_the_volume_they_store() {
    let dir = std::env::temp_dir().join(format!("voltab-slices-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    // density(x, y, z) = x + 10 y + 100 z on a 3 × 2 × 4 volume; rows run top (y = 1) to bottom.
    let (w, h, d) = (3usize, 2usize, 4usize);
    for z in 0..d {
        let px: Vec<[f32; 3]> = (0..w * h)
            .map(|i| {
                let (x, row) = (i % w, i / w);
                let y = h - 1 - row;
                let v = (x + 10 * y + 100 * z) as f32;
                [v, 0.0, 0.0]
            })
            .collect();
        crate::image_io::write_exr_rgb(&dir.join(format!("s{z:03}.exr")), w, h, &px, &[]).unwrap();
    }
    std::fs::write(dir.join("notes.txt"), b"ignored").unwrap();
    let (dims, vals) = read_exr_slices(&dir).unwrap();
    assert_eq!(dims, [3, 2, 4]);
    for z in 0..d {
        for y in 0..h {
            for x in 0..w {
                assert_eq!(vals[x + w * (y + h * z)], (x + 10 * y + 100 * z) as f32);
            }
        }
    }
    // A slice of another size, a negative density and an empty folder are refused, naming the file.
    crate::image_io::write_exr_rgb(&dir.join("s999.exr"), 2, 2, &[[1.0, 0.0, 0.0]; 4], &[]).unwrap();
    let e = read_exr_slices(&dir).unwrap_err();
    let e = e.to_string();
    assert!(e.contains("s999.exr") && e.contains("same size"), "{e}");
    std::fs::remove_file(dir.join("s999.exr")).unwrap();
    let mut bad = vec![[1.0f32, 0.0, 0.0]; w * h];
    bad[4] = [-2.0, 0.0, 0.0];
    crate::image_io::write_exr_rgb(&dir.join("s002.exr"), w, h, &bad, &[]).unwrap();
    let e = read_exr_slices(&dir).unwrap_err().to_string();
    assert!(e.contains("s002.exr") && e.contains("pixel (1, 1)") && e.contains("-2"), "{e}");
    let empty = dir.join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    assert!(read_exr_slices(&empty).unwrap_err().to_string().contains("no .exr slices"));
    assert!(read_exr_slices(&dir.join("missing")).unwrap_err().to_string().contains("cannot read the slice folder"));
    std::fs::remove_dir_all(&dir).unwrap();
}

fn coeffs() -> RgbMedium {
    RgbMedium::grey(4.0, 0.0, 0.7)
}

#[test]
fn voxel_lookup_and_errors() {
    let m = VoxelMedium::new(DVec3::ZERO, DVec3::new(2.0, 1.0, 1.0), [2, 1, 1], vec![1.0, 3.0], coeffs()).unwrap();
    assert_eq!(m.density_at(DVec3::new(0.5, 0.5, 0.5)), 1.0);
    assert_eq!(m.density_at(DVec3::new(1.5, 0.5, 0.5)), 3.0);
    assert_eq!(m.density_at(DVec3::new(2.0, 1.0, 1.0)), 3.0);
    assert_eq!(m.density_at(DVec3::new(2.1, 0.5, 0.5)), 0.0);
    assert_eq!(m.max_density(), 3.0);
    assert!(
        VoxelMedium::new(DVec3::ZERO, DVec3::ONE, [2, 1, 1], vec![1.0], coeffs())
            .unwrap_err()
            .to_string()
            .contains("needs 2")
    );
    assert!(VoxelMedium::new(DVec3::ZERO, DVec3::ONE, [1, 1, 1], vec![-1.0], coeffs()).is_err());
    assert!(VoxelMedium::new(DVec3::ZERO, DVec3::ONE, [1, 1, 1], vec![f32::NAN], coeffs()).is_err());
    assert!(VoxelMedium::homogeneous(DVec3::ONE, DVec3::ZERO, coeffs()).is_err());
    assert!(VoxelMedium::homogeneous(DVec3::ZERO, DVec3::ONE, RgbMedium::grey(1.0, 0.0, -0.1)).is_err());
    assert!(VoxelMedium::new(DVec3::ZERO, DVec3::ONE, [0, 1, 1], vec![], coeffs()).is_err());
}

#[test]
fn raw_volume_round_trip_and_size_check() {
    let dir = std::env::temp_dir().join(format!("voltab-raw-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("d.raw");
    let vals = [0.0_f32, 1.5, 2.0, 4.25];
    std::fs::write(&p, vals.iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>()).unwrap();
    assert_eq!(read_raw_density(&p, [2, 2, 1]).unwrap(), vals.to_vec());
    let e = read_raw_density(&p, [2, 2, 2]).unwrap_err();
    let e = e.to_string();
    assert!(e.contains("d.raw") && e.contains("32"), "{e}");
    assert!(read_raw_density(&dir.join("missing.raw"), [1, 1, 1]).unwrap_err().to_string().contains("missing.raw"));
    // Declared sizes beyond memory, a folder and a device are refused before anything is read.
    let e = read_raw_density(&p, [usize::MAX; 3]).unwrap_err();
    assert!(matches!(e, VoxelError::RawSize { bytes: 16, .. }), "{e}");
    assert!(matches!(read_raw_density(&dir, [1, 1, 1]), Err(VoxelError::NotAFile(_))));
    assert!(matches!(read_raw_density(Path::new("/dev/zero"), [1, 1, 1]), Err(VoxelError::NotAFile(_))));
    let e = VoxelMedium::new(DVec3::ZERO, DVec3::ONE, [usize::MAX; 3], vec![1.0], coeffs()).unwrap_err();
    assert!(matches!(e, VoxelError::Count { got: 1, .. }), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}
