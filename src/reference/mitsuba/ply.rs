//! Binary little-endian PLY meshes as Mitsuba's `ply` shape reads them: per vertex `x y z nx ny nz`
//! (float32), per face a `uchar` count (3) and three `int` indices. World space, metres.

/// Encodes `positions`/`normals` (same length) and `triangles` as PLY bytes. With `flip`, every triangle's
/// winding and every normal are reversed (a closed boundary oriented inward, written outward).
pub fn encode(positions: &[[f32; 3]], normals: &[[f32; 3]], triangles: &[[u32; 3]], flip: bool) -> Vec<u8> {
    let header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment written by voltab export mitsuba\n\
         element vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
         property float nx\nproperty float ny\nproperty float nz\n\
         element face {}\nproperty list uchar int vertex_indices\nend_header\n",
        positions.len(),
        triangles.len()
    );
    let mut out = Vec::with_capacity(header.len() + positions.len() * 24 + triangles.len() * 13);
    out.extend_from_slice(header.as_bytes());
    let sign = if flip { -1.0f32 } else { 1.0 };
    for (p, n) in positions.iter().zip(normals) {
        for v in p {
            out.extend_from_slice(&v.to_le_bytes());
        }
        for v in n {
            out.extend_from_slice(&(sign * v).to_le_bytes());
        }
    }
    for t in triangles {
        out.push(3);
        let order = if flip { [t[0], t[2], t[1]] } else { *t };
        for i in order {
            // Indices were validated against the vertex count on import (< 2^31 for any loadable mesh).
            out.extend_from_slice(&(i as i32).to_le_bytes());
        }
    }
    out
}

#[cfg(test)]
mod tests;
