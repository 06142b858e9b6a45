//! The output folder as a content-addressed cache.
//!
//! Input: a table's content key and encoded bytes. Output: `<out>/<id>.vtab` plus its JSON sidecar,
//! backed by `<out>/.voltab-cache/<key>.vtab` so reverting a definition restores instantly.
//! Invariants:
//! - keys are hashes of (canonical definition, kind schema version, generator version, container
//!   major) — never paths or modification times;
//! - every file appears atomically (temp file in the same folder, fsync, rename): a run killed at any
//!   moment leaves either the old file or the new one, never a partial one; leftover temp files are
//!   removed by the next run;
//! - one run at a time per folder (an exclusive lock on `<out>/.voltab.lock`); a second run waits;
//! - an existing file counts as up to date only if its header carries the key *and* every chunk
//!   verifies, so a corrupted output is rebuilt rather than trusted (no poisoned cache).

pub mod bounded;

use std::fs::{self, File};
use std::io::Write;
use std::path::{Path, PathBuf};

use crate::container::VtabReader;

/// Prefix of temporary files (removed on the next run if a run was killed).
const TMP_PREFIX: &str = ".tmp-voltab-";
/// Cache sub-folder.
pub const CACHE_DIR: &str = ".voltab-cache";

/// Lower-case hex of a key.
pub fn hex(key: &[u8; 32]) -> String {
    key.iter().map(|b| format!("{b:02x}")).collect()
}

/// Problems with the output folder.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CacheError {
    /// The folder cannot be created or written.
    #[error(
        "output folder {path} is not usable: {source}\n  = help: choose a writable folder with --out DIR, or fix its permissions"
    )]
    NotWritable {
        /// Folder.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// A file operation failed.
    #[error("cannot write {path}: {source}")]
    Io {
        /// File.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
}

/// An output folder, locked for this run.
#[derive(Debug)]
pub struct OutputDir {
    dir: PathBuf,
    _lock: File,
    /// Stale temporary files removed when the folder was opened (from killed runs).
    pub stale_removed: usize,
}

impl OutputDir {
    /// Creates (if needed) and locks `dir`; `waiting` is called once if another run holds the lock.
    pub fn open(dir: &Path, waiting: impl FnOnce()) -> Result<Self, CacheError> {
        let not_writable = |source| CacheError::NotWritable { path: dir.to_path_buf(), source };
        fs::create_dir_all(dir.join(CACHE_DIR)).map_err(not_writable)?;
        let lock = fs::OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .open(dir.join(".voltab.lock"))
            .map_err(not_writable)?;
        match lock.try_lock() {
            Ok(()) => {}
            Err(fs::TryLockError::WouldBlock) => {
                waiting();
                lock.lock().map_err(not_writable)?;
            }
            Err(fs::TryLockError::Error(e)) => return Err(not_writable(e)),
        }
        // Probe that we can really create files here (a read-only mount passes create_dir_all).
        let probe = tempfile::Builder::new().prefix(TMP_PREFIX).tempfile_in(dir).map_err(not_writable)?;
        drop(probe);
        let mut stale_removed = 0;
        for d in [dir.to_path_buf(), dir.join(CACHE_DIR)] {
            if let Ok(entries) = fs::read_dir(&d) {
                for e in entries.flatten() {
                    if e.file_name().to_string_lossy().starts_with(TMP_PREFIX) && fs::remove_file(e.path()).is_ok() {
                        stale_removed += 1;
                    }
                }
            }
        }
        Ok(Self { dir: dir.to_path_buf(), _lock: lock, stale_removed })
    }

    /// The folder.
    pub fn path(&self) -> &Path {
        &self.dir
    }

    /// `<out>/<id>.vtab`.
    pub fn table_path(&self, id: &str) -> PathBuf {
        self.dir.join(format!("{id}.vtab"))
    }

    /// `<out>/<id>.vtab.json`.
    pub fn sidecar_path(&self, id: &str) -> PathBuf {
        self.dir.join(format!("{id}.vtab.json"))
    }

    fn cached(&self, key: &[u8; 32], ext: &str) -> PathBuf {
        self.dir.join(CACHE_DIR).join(format!("{}.{ext}", hex(key)))
    }

    /// True if `<out>/<id>.vtab` holds `key`, verifies completely, and has its sidecar.
    ///
    /// A file is not read again while its fingerprint — size, inode, modification and status-change
    /// times (any write or re-link changes the last) — matches the one recorded when it was written
    /// by [`OutputDir::store`] or last verified completely, and its header still carries `key`. A
    /// fingerprint recorded by a verification within [`RACY_NS`] of the file's last change is not
    /// trusted (a write in the same clock tick could go unseen). One recorded by the writer is: the
    /// file is a fresh inode, filled under a private temporary name and renamed into place, so only an
    /// in-place rewrite of the same size in the filesystem's timestamp granule after the rename could
    /// hide — the assumption make, ninja and cargo make of every output (and on Linux ≥ 6.13, ext4,
    /// xfs, btrfs and tmpfs stamp a change after a `stat` with a fine-grained time, which closes even
    /// that). `voltab verify` always reads every chunk.
    pub fn is_up_to_date(&self, id: &str, key: &[u8; 32]) -> bool {
        if !self.sidecar_path(id).is_file() {
            return false;
        }
        let path = self.table_path(id);
        let fp_path = self.cached(key, "fp");
        if let (Some(now), Some(stored)) = (Fingerprint::of(&path), Fingerprint::read(&fp_path))
            && stored.trusted_for(&now)
        {
            return VtabReader::open(&path).is_ok_and(|r| r.header().content_key == *key);
        }
        let ok = file_holds(&path, key);
        if ok {
            self.record_fingerprint(&path, key, Origin::Verified);
        }
        ok
    }

    /// Writes `.voltab-cache/<key>.fp` for `path` (best effort: without it the next check verifies).
    fn record_fingerprint(&self, path: &Path, key: &[u8; 32], origin: Origin) {
        if let Some(mut fp) = Fingerprint::of(path) {
            fp.verified_ns = now_ns();
            fp.origin = origin;
            let _ = write_atomic(&self.cached(key, "fp"), fp.to_line().as_bytes());
        }
    }

    /// If the cache holds a verified table for `key`, makes it `<out>/<id>.vtab` (with its sidecar)
    /// and returns true.
    pub fn restore(&self, id: &str, key: &[u8; 32]) -> Result<bool, CacheError> {
        let (vtab, json) = (self.cached(key, "vtab"), self.cached(key, "json"));
        if !json.is_file() || !file_holds(&vtab, key) {
            return Ok(false);
        }
        self.link_atomic(&vtab, &self.table_path(id))?;
        self.link_atomic(&json, &self.sidecar_path(id))?;
        Ok(true)
    }

    /// Stores a freshly compiled table and sidecar in the cache and publishes them as `<id>`.
    pub fn store(&self, id: &str, key: &[u8; 32], vtab: &[u8], sidecar: &[u8]) -> Result<(), CacheError> {
        let (cv, cj) = (self.cached(key, "vtab"), self.cached(key, "json"));
        write_atomic(&cv, vtab)?;
        write_atomic(&cj, sidecar)?;
        self.link_atomic(&cv, &self.table_path(id))?;
        self.link_atomic(&cj, &self.sidecar_path(id))?;
        // After the last link (a link changes the inode's status-change time).
        self.record_fingerprint(&self.table_path(id), key, Origin::Written);
        Ok(())
    }

    /// Publishes `src` at `dst` atomically: hard link (or copy) to a temp name, then rename.
    fn link_atomic(&self, src: &Path, dst: &Path) -> Result<(), CacheError> {
        let io = |source| CacheError::Io { path: dst.to_path_buf(), source };
        static COUNTER: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
        let n = COUNTER.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let tmp = self.dir.join(format!("{TMP_PREFIX}{}-{n}", std::process::id()));
        let _ = fs::remove_file(&tmp);
        if fs::hard_link(src, &tmp).is_err() {
            fs::copy(src, &tmp).map_err(io)?;
        }
        fs::rename(&tmp, dst).map_err(io)?;
        sync_dir(&self.dir);
        Ok(())
    }
}

/// A fingerprint younger than this after the file's last change is not trusted \[ns\].
pub const RACY_NS: u128 = 2_000_000_000;

fn now_ns() -> u128 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos())
}

/// Who vouched for a fingerprinted file's content.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Origin {
    /// [`OutputDir::store`] wrote it (a fresh inode renamed into place).
    Written,
    /// A complete verification read it.
    Verified,
}

/// What `is_up_to_date` remembers of a file it may trust (one line in `.voltab-cache/<key>.fp`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Fingerprint {
    len: u64,
    ino: u64,
    dev: u64,
    mtime_ns: u128,
    ctime_ns: u128,
    /// When the file was written or verified completely.
    verified_ns: u128,
    origin: Origin,
}

impl Fingerprint {
    #[cfg(unix)]
    fn of(path: &Path) -> Option<Self> {
        use std::os::unix::fs::MetadataExt;
        let m = fs::metadata(path).ok()?;
        if !m.is_file() {
            return None;
        }
        let ns = |s: i64, n: i64| u128::try_from(i128::from(s) * 1_000_000_000 + i128::from(n)).ok();
        Some(Self {
            len: m.len(),
            ino: m.ino(),
            dev: m.dev(),
            mtime_ns: ns(m.mtime(), m.mtime_nsec())?,
            ctime_ns: ns(m.ctime(), m.ctime_nsec())?,
            verified_ns: 0,
            origin: Origin::Verified,
        })
    }

    #[cfg(not(unix))]
    fn of(_path: &Path) -> Option<Self> {
        None
    }

    fn to_line(self) -> String {
        let origin = match self.origin {
            Origin::Written => "written",
            Origin::Verified => "verified",
        };
        format!(
            "voltab-fp 2 {} {} {} {} {} {} {origin}\n",
            self.len, self.ino, self.dev, self.mtime_ns, self.ctime_ns, self.verified_ns
        )
    }

    fn read(path: &Path) -> Option<Self> {
        let bytes = bounded::read_regular(path, 4096).ok()?;
        let text = std::str::from_utf8(&bytes).ok()?;
        let f: Vec<&str> = text.split_whitespace().collect();
        if f.len() != 9 || f[0] != "voltab-fp" || f[1] != "2" {
            return None;
        }
        let origin = match f[8] {
            "written" => Origin::Written,
            "verified" => Origin::Verified,
            _ => return None,
        };
        Some(Self {
            len: f[2].parse().ok()?,
            ino: f[3].parse().ok()?,
            dev: f[4].parse().ok()?,
            mtime_ns: f[5].parse().ok()?,
            ctime_ns: f[6].parse().ok()?,
            verified_ns: f[7].parse().ok()?,
            origin,
        })
    }

    /// The file is the one written or verified, and a verification came clearly after its last change.
    fn trusted_for(&self, now: &Fingerprint) -> bool {
        self.len == now.len
            && self.ino == now.ino
            && self.dev == now.dev
            && self.mtime_ns == now.mtime_ns
            && self.ctime_ns == now.ctime_ns
            && (self.origin == Origin::Written
                || self.verified_ns > self.mtime_ns.max(self.ctime_ns).saturating_add(RACY_NS))
    }
}

/// True if `path` is a complete, verified `.vtab` whose header carries `key`.
fn file_holds(path: &Path, key: &[u8; 32]) -> bool {
    match VtabReader::open(path) {
        Ok(mut r) => r.header().content_key == *key && r.verify().is_ok(),
        Err(_) => false,
    }
}

/// Writes `bytes` to `path` atomically (temp file in the same folder, fsync, rename).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), CacheError> {
    let io = |source| CacheError::Io { path: path.to_path_buf(), source };
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let mut tmp = tempfile::Builder::new().prefix(TMP_PREFIX).tempfile_in(dir).map_err(io)?;
    tmp.write_all(bytes).map_err(io)?;
    // tempfile creates 0600 files; outputs are ordinary shared build artefacts.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        tmp.as_file().set_permissions(fs::Permissions::from_mode(0o644)).map_err(io)?;
    }
    tmp.as_file().sync_all().map_err(io)?;
    tmp.persist(path).map_err(|e| io(e.error))?;
    sync_dir(dir);
    Ok(())
}

/// Makes a rename durable (best effort: not every platform can fsync a folder).
fn sync_dir(dir: &Path) {
    if let Ok(d) = File::open(dir) {
        let _ = d.sync_all();
    }
}
