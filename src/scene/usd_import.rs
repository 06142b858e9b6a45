//! Placeholder until the importer lands (replaced in this change).
use std::path::Path;

use super::{Scene, SceneError};

/// Reads a scene.
pub fn import(path: &Path) -> Result<Scene, SceneError> {
    Err(SceneError::file(path, "importer not built yet", ""))
}
