//! What the machine says about itself: its memory, and this process's
//! memory high-water mark and CPU time. A leaf: it imports nothing of the
//! crate, so every layer may ask it.

/// Half the machine's memory (at least 1 GiB), or 8 GiB where it cannot be read.
pub fn default_max_memory() -> u64 {
    let total = std::fs::read_to_string("/proc/meminfo").ok().and_then(|m| {
        m.lines()
            .find(|l| l.starts_with("MemTotal:"))
            .and_then(|l| l.split_whitespace().nth(1)?.parse::<u64>().ok())
    });
    total.map_or(8 << 30, |kb| (kb * 1024 / 2).max(1 << 30))
}

/// Peak resident set size of this process in bytes (`VmHWM`), where the
/// platform tells it.
pub fn peak_rss_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// CPU time (user + system) this process has used so far, in seconds, where
/// the platform tells it.
pub fn cpu_seconds() -> Option<f64> {
    #[cfg(unix)]
    {
        let mut u = std::mem::MaybeUninit::<libc::rusage>::zeroed();
        // SAFETY: getrusage writes a whole rusage into the pointer it is
        // given, which points to one, and reads nothing from it.
        #[allow(unsafe_code)]
        let rc = unsafe { libc::getrusage(libc::RUSAGE_SELF, u.as_mut_ptr()) };
        if rc != 0 {
            return None;
        }
        // SAFETY: getrusage returned 0, so it filled the struct.
        #[allow(unsafe_code)]
        let u = unsafe { u.assume_init() };
        let t = |v: libc::timeval| v.tv_sec as f64 + v.tv_usec as f64 * 1e-6;
        Some(t(u.ru_utime) + t(u.ru_stime))
    }
    #[cfg(not(unix))]
    None
}

/// How much lower than the filter's threads the decoding and compressing
/// threads run (a `nice` increment: at 10 the scheduler gives a busy thread
/// of the filter about ten times the time of one of them).
pub const IO_NICE: i32 = 10;

/// Lower the calling thread's scheduling priority by [`IO_NICE`] (Linux,
/// where each thread has its own `nice`; elsewhere nothing). Lowering needs
/// no privilege; a failure leaves the priority as it was.
pub fn lower_this_threads_priority() {
    #[cfg(target_os = "linux")]
    {
        // SAFETY: gettid takes nothing and returns this thread's id;
        // setpriority reads only its three integer arguments.
        #[allow(unsafe_code)]
        unsafe {
            let tid = libc::syscall(libc::SYS_gettid) as libc::id_t;
            let now = libc::getpriority(libc::PRIO_PROCESS, tid);
            libc::setpriority(libc::PRIO_PROCESS, tid, (now + IO_NICE).min(19));
        }
    }
}

/// The calling thread's `nice` (Linux; elsewhere `None`).
pub fn this_threads_nice() -> Option<i32> {
    #[cfg(target_os = "linux")]
    {
        // SAFETY: as in `lower_this_threads_priority`.
        #[allow(unsafe_code)]
        let nice = unsafe {
            let tid = libc::syscall(libc::SYS_gettid) as libc::id_t;
            libc::getpriority(libc::PRIO_PROCESS, tid)
        };
        Some(nice)
    }
    #[cfg(not(target_os = "linux"))]
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[cfg(target_os = "linux")]
    #[test]
    fn lowering_moves_only_the_calling_thread() {
        let before = this_threads_nice();
        let (was, now) = std::thread::spawn(|| {
            let was = this_threads_nice().unwrap();
            lower_this_threads_priority();
            (was, this_threads_nice().unwrap())
        })
        .join()
        .unwrap();
        assert_eq!(now, (was + IO_NICE).min(19));
        assert_eq!(this_threads_nice(), before, "the caller keeps its priority");
    }
}
