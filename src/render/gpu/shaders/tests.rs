use super::*;

/// Every technique's shader list.
const ALL: &[&[Shader]] =
    &[crate::stages::god_rays::shaders::ALL, crate::stages::image_fog::shaders::ALL, crate::stages::pop::shaders::ALL];

#[test]
fn every_shader_file_is_listed_and_validates() {
    // A file under src/stages/*/shaders that ALL forgets would never be validated.
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files: Vec<String> = Vec::new();
    for stage in std::fs::read_dir(root.join("src/stages")).expect("stages folder").filter_map(Result::ok) {
        let Ok(dir) = std::fs::read_dir(stage.path().join("shaders")) else { continue };
        for e in dir.filter_map(Result::ok) {
            let name = e.file_name().to_string_lossy().into_owned();
            if name.ends_with(".wgsl") {
                files.push(format!("src/stages/{}/shaders/{name}", stage.file_name().to_string_lossy()));
            }
        }
    }
    files.sort();
    let mut listed: Vec<String> = ALL.iter().flat_map(|l| l.iter()).map(|s| format!("{}/{}", s.dir, s.name)).collect();
    listed.sort();
    assert_eq!(files, listed);
    assert_eq!(files.len(), 13, "god rays 6, image fog 4, POP 3");
    for s in ALL.iter().flat_map(|l| l.iter()) {
        if let Err(e) = s.validate() {
            panic!("{e}");
        }
    }
}

#[test]
fn a_broken_shader_is_reported_with_its_file_and_line() {
    let broken = Shader {
        dir: "src/stages/test/shaders",
        name: "broken.wgsl",
        source: "@compute @workgroup_size(64)\nfn main() {\n  let x: f32 = 1u;\n}\n",
    };
    let e = broken.validate().unwrap_err();
    assert!(e.contains("src/stages/test/shaders/broken.wgsl:3:"), "{e}");
}
