//! Peak-heap accounting for the fuzz targets: every input runs inside a window that measures how far
//! the heap grew above its level at the start, and fails (a libFuzzer crash with the input saved) when
//! the growth exceeds `4 × declared + ALLOWANCE` — issue 37's "peak memory ≤ 4× the declared data size
//! on every input". `declared` is what the input itself says must be held: its own bytes plus the raw
//! sizes it declares (a `.vtab`'s chunks, a glTF's buffers). Each target states its own.
//!
//! Only Rust allocations are counted (libFuzzer's own C++ heap is not voltab's). The largest growth
//! and the largest growth-to-declared ratio seen are written to `mem/<target>.txt` when they change,
//! so a long run leaves its worst case behind (`run.sh` clears the file when a run starts; a forked
//! child starts from the worst its predecessors wrote).

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering::Relaxed};

/// Fixed structures any input may allocate regardless of its size (parser state, a scene's default
/// camera and lights, error strings, thread-pool start-up): 1 MiB.
pub const ALLOWANCE: u64 = 1 << 20;

/// The allocator every target installs.
pub struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

fn grew(by: usize) {
    let now = LIVE.fetch_add(by, Relaxed) + by;
    PEAK.fetch_max(now, Relaxed);
}

// SAFETY: every call forwards to `System` with the caller's arguments unchanged; the counters are
// plain atomics updated only after a successful (non-null) allocation.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            grew(layout.size());
        }
        p
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc_zeroed(layout) };
        if !p.is_null() {
            grew(layout.size());
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) };
        LIVE.fetch_sub(layout.size(), Relaxed);
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let q = unsafe { System.realloc(ptr, layout, new_size) };
        if !q.is_null() {
            if new_size >= layout.size() {
                grew(new_size - layout.size());
            } else {
                LIVE.fetch_sub(layout.size() - new_size, Relaxed);
            }
        }
        q
    }
}

/// One input's measurement window.
pub struct Window {
    base: usize,
}

/// Opens a window: the peak is reset to the current live heap.
pub fn start() -> Window {
    let base = LIVE.load(Relaxed);
    PEAK.store(base, Relaxed);
    Window { base }
}

static WORST_BYTES: AtomicU64 = AtomicU64::new(0);
static WORST_RATIO_MILLI: AtomicU64 = AtomicU64::new(0);

impl Window {
    /// Closes the window: panics (a libFuzzer crash) when the heap grew beyond
    /// `4 × declared + ALLOWANCE`, and records a new worst case in `mem/<target>.txt`.
    pub fn check(self, target: &str, declared: u64) {
        static LOADED: std::sync::Once = std::sync::Once::new();
        LOADED.call_once(|| load_worst(target));
        let growth = (PEAK.load(Relaxed).saturating_sub(self.base)) as u64;
        let limit = declared.saturating_mul(4).saturating_add(ALLOWANCE);
        assert!(
            growth <= limit,
            "{target}: the heap grew by {growth} bytes for {declared} declared bytes (limit {limit})"
        );
        let ratio_milli = growth.saturating_mul(1000) / declared.max(1);
        let worse_bytes = WORST_BYTES.fetch_max(growth, Relaxed) < growth;
        // The ratio only means something once the declared size dominates the allowance.
        let worse_ratio = declared >= ALLOWANCE && WORST_RATIO_MILLI.fetch_max(ratio_milli, Relaxed) < ratio_milli;
        if worse_bytes || worse_ratio {
            let text = format!(
                "target {target}\nlargest growth: {} bytes\nlargest growth / declared (declared ≥ 1 MiB): {:.3}\n\
                 last new worst: growth {growth} bytes for {declared} declared\n",
                WORST_BYTES.load(Relaxed),
                WORST_RATIO_MILLI.load(Relaxed) as f64 / 1000.0,
            );
            let _ = std::fs::create_dir_all("mem");
            let _ = std::fs::write(format!("mem/{target}.txt"), text);
        }
    }
}

/// Starts from the worst case an earlier process of this run wrote (fork mode).
fn load_worst(target: &str) {
    let Ok(text) = std::fs::read_to_string(format!("mem/{target}.txt")) else { return };
    for line in text.lines() {
        if let Some(v) = line.strip_prefix("largest growth: ").and_then(|r| r.strip_suffix(" bytes")) {
            WORST_BYTES.store(v.parse().unwrap_or(0), Relaxed);
        }
        if let Some(v) = line.strip_prefix("largest growth / declared (declared ≥ 1 MiB): ") {
            WORST_RATIO_MILLI.store((v.parse::<f64>().unwrap_or(0.0) * 1000.0) as u64, Relaxed);
        }
    }
}
