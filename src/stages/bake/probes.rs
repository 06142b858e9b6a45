//! The bake's light probes (dubouchet2019 Sec. 5.2's volume-to-point transport at grid points): a
//! probe grid over the scene → per probe the incident radiance as real SH bands `l ≤ 2` per RGB
//! channel, written as `probes.vtab`.

use super::*;

impl BakeLightmaps {
    /// Bakes the probe grid (if any) into `probes.vtab`; returns the number of probes.
    pub(super) fn bake_probes(
        &self,
        id: &str,
        scene: &Scene,
        bvh: &SceneBvh,
        table: Option<&ZhResponseTable>,
        dir: &Path,
        outputs: &mut Vec<PathBuf>,
    ) -> Result<usize, StageError> {
        let [nx, ny, nz] = match self.probe_grid.as_slice() {
            [a, b, c] => [*a, *b, *c],
            _ => return Ok(0),
        };
        let Some((lo, hi)) = scene.bounds() else { return Ok(0) };
        let mode = *self.modes.last().unwrap_or(&BakeMode::Full);
        let tr = Transport::new(scene, bvh, table, self.transport_options(mode)).map_err(|e| StageError::Input {
            stage: id.into(),
            message: e.to_string(),
            help: "check the table".into(),
        })?;
        let counts = [nx, ny, nz];
        let mut positions = Vec::new();
        for k in 0..nz {
            for j in 0..ny {
                for i in 0..nx {
                    let idx = [i, j, k];
                    positions.push(
                        [0, 1, 2].map(|c| lo[c] + (hi[c] - lo[c]) * (f64::from(idx[c]) + 0.5) / f64::from(counts[c])),
                    );
                }
            }
        }
        let sh: Vec<[[f64; transport::PROBE_SH]; 3]> = positions
            .par_iter()
            .enumerate()
            .map(|(i, p)| tr.probe(*p, (1 << 40) + i as u64))
            .collect::<Result<_, _>>()
            .map_err(|e| StageError::Input {
                stage: id.into(),
                message: e.to_string(),
                help: "check the table".into(),
            })?;
        let path = dir.join("probes.vtab");
        let bytes = probe_container(&positions, &sh, &format!("{self:?}")).map_err(|e| StageError::Output {
            stage: id.into(),
            path: path.clone(),
            message: e,
        })?;
        crate::cache::write_atomic(&path, &bytes).map_err(|e| StageError::Output {
            stage: id.into(),
            path: path.clone(),
            message: e.to_string(),
        })?;
        outputs.push(path);
        Ok(positions.len())
    }
}

/// Probes as a `.vtab` container: `positions[n, 3]` \[m\] and `sh[n, 3, 9]` (channel, coefficient) \[W/(m²·sr)\].
fn probe_container(
    positions: &[[f64; 3]],
    sh: &[[[f64; transport::PROBE_SH]; 3]],
    definition: &str,
) -> Result<Vec<u8>, String> {
    use crate::container::{ArrayDesc, ArrayValues, Axis, ElementType, Header};
    let n = positions.len() as u64;
    let arrays = vec![
        ArrayDesc {
            name: "positions".into(),
            description: "probe positions (world space)".into(),
            unit: "m".into(),
            element: ElementType::F32,
            axes: vec![Axis::linear("probe", "", 0.0, (n.max(1) - 1) as f64, n), Axis::linear("xyz", "", 0.0, 2.0, 3)],
            quantization: None,
        },
        ArrayDesc {
            name: "sh".into(),
            description: "incident radiance, real SH bands l <= 2 (i = l(l+1)+m), per RGB channel".into(),
            unit: "W/(m^2 sr)".into(),
            element: ElementType::F32,
            axes: vec![
                Axis::linear("probe", "", 0.0, (n.max(1) - 1) as f64, n),
                Axis::linear("channel", "", 0.0, 2.0, 3),
                Axis::linear("coefficient", "", 0.0, 8.0, transport::PROBE_SH as u64),
            ],
            quantization: None,
        },
    ];
    let header = Header {
        kind: "LightProbes".into(),
        kind_schema_version: 1,
        generator_version: "bake_lightmaps/1".into(),
        definition_ron: definition.into(),
        content_key: *blake3::hash(definition.as_bytes()).as_bytes(),
        arrays,
    };
    let pos: Vec<f32> = positions.iter().flat_map(|p| p.map(|c| c as f32)).collect();
    let coef: Vec<f32> = sh.iter().flat_map(|p| p.iter().flat_map(|c| c.map(|v| v as f32))).collect();
    let values = vec![ArrayValues::F32(pos), ArrayValues::F32(coef)];
    crate::container::encode(&header, &values, &crate::container::EncodeOptions::default())
        .map(|e| e.bytes)
        .map_err(|e| e.to_string())
}
