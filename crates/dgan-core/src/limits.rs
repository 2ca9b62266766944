//! Bounds and tolerances shared by several modules (frames, maps, histories), kept here so that none of them
//! imports another for a constant.

/// The largest coordinate magnitude, metres, of a position or map vertex: far beyond any real scene (UTM northings
/// are below 10⁷ m), so that a value of 10³⁰ m is caught as the unit or data error it is.
pub const MAX_COORDINATE_M: f64 = 1e9;

/// Relative tolerance for "the same time": a detection within `dt_s · TIME_TOLERANCE` of a grid time is on it.
pub const TIME_TOLERANCE: f64 = 1e-6;

/// The machine's cores (1 when unknown): the most threads one call may use. Asked of the system once per process
/// (Linux answers from the affinity mask and the cgroup's CPU quota, files read on each call: about 60 µs, as long
/// as preprocessing a few agents).
pub fn cores() -> usize {
    static CORES: std::sync::OnceLock<usize> = std::sync::OnceLock::new();
    *CORES.get_or_init(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
}

/// `work` on each item concurrently: the first item on the calling thread, each other on a scoped thread of its own
/// (the threads end with the call, so that no idle pool worker competes with ONNX Runtime for the cores). The results
/// in the items' order; an item whose thread panicked gets `panicked()` instead, so no panic leaves the call.
pub fn on_threads<T: Send, R: Send>(items: Vec<T>, work: impl Fn(T) -> R + Sync, panicked: impl Fn() -> R) -> Vec<R> {
    let mut items = items.into_iter();
    let Some(first) = items.next() else { return vec![] };
    let work = &work;
    std::thread::scope(|scope| {
        let handles: Vec<_> = items.map(|item| scope.spawn(move || work(item))).collect();
        let here = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| work(first)));
        let mut out = vec![here.unwrap_or_else(|_| panicked())];
        out.extend(handles.into_iter().map(|h| h.join().unwrap_or_else(|_| panicked())));
        out
    })
}

/// `work` on every job on `threads` threads ([`on_threads`]: the calling one included), each thread taking the next
/// job as it finishes one, so that uneven jobs share out evenly (the crops of a scene's busy part beside blank ones,
/// which contiguous shares left on one thread). Once every thread has stopped, the first error in thread order is
/// returned (a thread's panic as `panicked()`); a thread stops at its first error, the others finish the queue.
pub fn share_jobs<T: Send, E: Send>(
    jobs: Vec<T>,
    threads: usize,
    work: impl Fn(T) -> Result<(), E> + Sync,
    panicked: impl Fn() -> E + Sync,
) -> Result<(), E> {
    // No more threads than jobs: a thread with nothing to take would only cost its start.
    let threads = threads.min(jobs.len()).max(1);
    let queue = std::sync::Mutex::new(jobs.into_iter());
    let next = || queue.lock().unwrap_or_else(std::sync::PoisonError::into_inner).next();
    let run = |_| -> Result<(), E> {
        while let Some(job) = next() {
            work(job)?;
        }
        Ok(())
    };
    on_threads((0..threads).collect(), run, || Err(panicked())).into_iter().collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn on_threads_keeps_the_order_and_catches_panics() {
        let out = on_threads(
            vec![1, 2, 3, 4, 5],
            |x| if x % 2 == 1 && x != 5 { panic!("odd") } else { Ok(x * 10) },
            || Err(()),
        );
        assert_eq!(out, vec![Err(()), Ok(20), Err(()), Ok(40), Ok(50)]);
        assert!(on_threads(Vec::<i32>::new(), |x| x, || 0).is_empty());
    }

    #[test]
    fn shared_jobs_run_once_each_whatever_the_threads() {
        use std::sync::atomic::{AtomicUsize, Ordering};
        for threads in [1, 2, 5] {
            let mut out = vec![0usize; 37];
            let runs = AtomicUsize::new(0);
            let jobs: Vec<(usize, &mut usize)> = out.iter_mut().enumerate().collect();
            let done = share_jobs(
                jobs,
                threads,
                |(i, slot): (usize, &mut usize)| {
                    runs.fetch_add(1, Ordering::Relaxed);
                    *slot = i * i;
                    Ok::<(), ()>(())
                },
                || (),
            );
            assert_eq!(done, Ok(()));
            assert_eq!(runs.load(Ordering::Relaxed), 37);
            assert!(out.iter().enumerate().all(|(i, v)| *v == i * i));
        }
        let failed = share_jobs((0..20).collect(), 3, |i: i32| if i == 7 { Err("seven") } else { Ok(()) }, || "panic");
        assert_eq!(failed, Err("seven"));
        let panicked =
            share_jobs((0..20).collect(), 3, |i: i32| if i == 7 { panic!("at 7") } else { Ok(()) }, || "panic");
        assert_eq!(panicked, Err("panic"));
    }
}
