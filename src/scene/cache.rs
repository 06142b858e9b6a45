//! Imported scenes shared within one run: a scene path → its [`Scene`], imported ([`Scene::load`]) once
//! however many readers ask for it — the planner that prunes the pipeline and every stage that renders
//! or bakes the same file.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};

use super::{Scene, SceneError};

/// Scenes by canonical path, each imported at most once. Failures are not kept: a broken scene is
/// read again, and reported, by every reader.
#[derive(Debug, Default)]
pub struct SceneCache {
    scenes: Mutex<HashMap<PathBuf, Arc<Scene>>>,
}

impl SceneCache {
    /// The scene at `path`, imported on first use; later calls for the same file (by canonical path,
    /// however it is spelt) share it.
    pub fn load(&self, path: &Path) -> Result<Arc<Scene>, SceneError> {
        let key = path.canonicalize().unwrap_or_else(|_| path.to_path_buf());
        if let Some(scene) = self.lock().get(&key) {
            return Ok(Arc::clone(scene));
        }
        // Imported without the lock held: another thread asking for another scene is not kept waiting.
        let scene = Arc::new(Scene::load(path)?);
        Ok(Arc::clone(self.lock().entry(key).or_insert(scene)))
    }

    /// How many scenes have been imported.
    pub fn len(&self) -> usize {
        self.lock().len()
    }

    /// Whether no scene has been imported yet.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    fn lock(&self) -> MutexGuard<'_, HashMap<PathBuf, Arc<Scene>>> {
        // A panic elsewhere while holding the lock leaves the map whole (inserts are single calls).
        self.scenes.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

#[cfg(test)]
mod tests;
