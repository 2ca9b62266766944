//! What is kept with one map for every later call: the tiles drawn of a vector map ([`crate::tiles`]) and a scene
//! model's features of the map ([`crate::kept`]). A bounded store shared by the threads that use it, the least
//! recently used tile leaving first.

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

/// Which tile of a scene model's features (contract 12's `map.scene.tile_px`): the model that computed it (its
/// [`crate::runtime::Predictor`]'s own number) and its place on the world's tile grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct FeatureKey {
    /// The predictor's number ([`crate::runtime::Predictor::id`]).
    pub model: u64,
    /// Tile column (east).
    pub i: i64,
    /// Tile row (south).
    pub j: i64,
}

/// Tiles kept with one map, at most [`Store::CAPACITY`] of them: a new one beyond it replaces the one least recently
/// used (a service following agents across a city map keeps the tiles around them). A clone of the map starts with
/// none. Shared by the threads that draw or read them.
pub struct Store<K, T: ?Sized> {
    inner: Mutex<Tiles<K, T>>,
}

/// The pixels drawn of a vector map, by tile.
pub type TileStore = Store<TileKey, [u8]>;
/// A scene model's features of a map (`(tile_features², channels)` rows each), by model and tile.
pub type FeatureStore = Store<FeatureKey, [f32]>;

/// The kept tiles, each with the tick of its last use.
struct Tiles<K, T: ?Sized> {
    tiles: HashMap<K, (Arc<T>, u64)>,
    tick: u64,
}

impl<K, T: ?Sized> Default for Store<K, T> {
    fn default() -> Self {
        Self { inner: Mutex::new(Tiles { tiles: HashMap::new(), tick: 0 }) }
    }
}

impl<K: Copy + Eq + std::hash::Hash, T: ?Sized> Store<K, T> {
    /// The most tiles kept per map (of 128² RGB pixels: 24 MiB; of a scene model's features, 16² rows of 16
    /// channels: 8 MiB).
    pub const CAPACITY: usize = 512;

    fn lock(&self) -> std::sync::MutexGuard<'_, Tiles<K, T>> {
        // A thread that panicked while holding the lock left the tiles whole (each change is one call).
        self.inner.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// A tile drawn before, if kept (marked used).
    pub fn get(&self, key: &K) -> Option<Arc<T>> {
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
    pub fn insert(&self, key: K, tile: Arc<T>) -> Arc<T> {
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
    pub fn contains(&self, key: &K) -> bool {
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

impl<K, T: ?Sized> Clone for Store<K, T> {
    fn clone(&self) -> Self {
        Self::default()
    }
}

impl<K: Copy + Eq + std::hash::Hash, T: ?Sized> std::fmt::Debug for Store<K, T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Store({} tiles)", self.len())
    }
}
