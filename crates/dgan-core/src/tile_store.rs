//! The tiles drawn of one vector map ([`crate::tiles`]), kept with it: a bounded store shared by the threads that draw
//! crops, the least recently used tile leaving first.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

/// Which tile of a map: its resolution (`f64::to_bits`) and its place on the world's tile grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct TileKey {
    /// Metres per tile pixel, as `f64::to_bits`.
    pub resolution_bits: u64,
    /// Tile column (east).
    pub i: i64,
    /// Tile row (south).
    pub j: i64,
}

/// The tiles drawn of one vector map, at most [`TileStore::CAPACITY`] of them: a new one beyond it replaces the one
/// least recently used (a service following agents across a city map keeps the tiles around them). A clone of the
/// map starts with none. Shared by the threads drawing crops.
#[derive(Default)]
pub struct TileStore {
    inner: Mutex<Tiles>,
}

/// The kept tiles, each with the tick of its last use.
#[derive(Default)]
struct Tiles {
    tiles: HashMap<TileKey, (Arc<[u8]>, u64)>,
    tick: u64,
}

impl TileStore {
    /// The most tiles kept per map (of 128² RGB pixels: 24 MiB).
    pub const CAPACITY: usize = 512;

    fn lock(&self) -> std::sync::MutexGuard<'_, Tiles> {
        // A thread that panicked while holding the lock left the tiles whole (each change is one call).
        self.inner.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// A tile drawn before, if kept (marked used).
    pub fn get(&self, key: &TileKey) -> Option<Arc<[u8]>> {
        let mut kept = self.lock();
        kept.tick += 1;
        let tick = kept.tick;
        kept.tiles.get_mut(key).map(|(tile, used)| {
            *used = tick;
            tile.clone()
        })
    }

    /// Keeps `tile` under `key` (or the one another thread kept first, which holds the same pixels) and returns it;
    /// at capacity the least recently used tile makes room.
    pub fn insert(&self, key: TileKey, tile: Arc<[u8]>) -> Arc<[u8]> {
        let mut kept = self.lock();
        kept.tick += 1;
        let tick = kept.tick;
        if kept.tiles.len() >= Self::CAPACITY && !kept.tiles.contains_key(&key) {
            if let Some(oldest) = kept.tiles.iter().min_by_key(|(_, (_, used))| *used).map(|(k, _)| *k) {
                kept.tiles.remove(&oldest);
            }
        }
        let entry = kept.tiles.entry(key).or_insert((tile, tick));
        entry.1 = tick;
        entry.0.clone()
    }

    /// Whether a tile is kept under `key` (without marking it used).
    pub fn contains(&self, key: &TileKey) -> bool {
        self.lock().tiles.contains_key(key)
    }

    /// How many tiles are kept.
    pub fn len(&self) -> usize {
        self.lock().tiles.len()
    }

    /// Whether no tile is kept.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

impl Clone for TileStore {
    fn clone(&self) -> Self {
        Self::default()
    }
}

impl std::fmt::Debug for TileStore {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "TileStore({} tiles)", self.len())
    }
}
