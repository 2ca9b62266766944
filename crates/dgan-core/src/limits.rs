//! Bounds and tolerances shared by several modules (frames, maps, histories), kept here so that none of them
//! imports another for a constant.

/// The largest coordinate magnitude, metres, of a position or map vertex: far beyond any real scene (UTM northings
/// are below 10⁷ m), so that a value of 10³⁰ m is caught as the unit or data error it is.
pub const MAX_COORDINATE_M: f64 = 1e9;

/// Relative tolerance for "the same time": a detection within `dt_s · TIME_TOLERANCE` of a grid time is on it.
pub const TIME_TOLERANCE: f64 = 1e-6;

/// The machine's cores (1 when unknown): the most threads one call may use.
pub fn cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}
