//! Farm bakes (`voltab run --shard`): a prepared bake → the estimates of one tile of texels of one
//! mode, the work unit `shard::bake` hands out; every texel draws from its own stream, so the tiles
//! together are the bake's estimates to the bit.

use super::*;

/// A bake prepared for its tiles ([`BakeLightmaps::tile_baker`]).
pub struct TileBaker<'a> {
    pub(super) stage: &'a BakeLightmaps,
    pub(super) id: String,
    pub(super) prepared: Prepared,
}

impl TileBaker<'_> {
    /// Texels of the atlas.
    pub fn texels(&self) -> usize {
        self.prepared.points.len()
    }

    /// The estimates of tile `tile` (texels `tile × TILE_TEXELS …`, in atlas order) of mode
    /// `modes[mode]`: a work unit of a farm bake. Every texel draws from its own stream (keyed by its
    /// atlas pixel), so the tiles of all texels are the bake's estimates to the bit.
    pub fn bake(&self, mode: usize, tile: usize) -> Result<Vec<transport::Estimate>, StageError> {
        let fail =
            |message: String, help: &str| StageError::Input { stage: self.id.clone(), message, help: help.into() };
        let Some(&m) = self.stage.modes.get(mode) else {
            return Err(fail(
                format!("mode {mode} out of range ({} modes)", self.stage.modes.len()),
                "report this bug",
            ));
        };
        let p = &self.prepared;
        let start = tile.saturating_mul(TILE_TEXELS).min(p.points.len());
        let end = (start + TILE_TEXELS).min(p.points.len());
        let tr = Transport::new(&p.scene, &p.bvh, p.table.as_ref(), self.stage.transport_options(m))
            .map_err(|e| fail(e.to_string(), "check the table"))?;
        bake_points(&tr, &p.points[start..end], false, "")
            .map_err(|e| fail(e.to_string(), "check the table's g range against the scene's media"))
    }
}

/// Texels per work unit of a farm bake (`voltab run --shard`).
pub const TILE_TEXELS: usize = 1024;
