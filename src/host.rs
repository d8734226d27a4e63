//! What the machine says about itself: its memory, and this process's
//! memory high-water mark and CPU time. A leaf: it imports nothing of the
//! crate, so every layer may ask it.

use std::path::Path;

/// Half the memory this process may have (at least 1 GiB): the smaller of
/// the machine's and its control group's limit (a container's, a Slurm
/// job's: cgroup v2 `memory.max`, v1 `memory.limit_in_bytes`), or 8 GiB
/// where neither can be read.
pub fn default_max_memory() -> u64 {
    let machine = std::fs::read_to_string("/proc/meminfo").ok().and_then(|m| {
        m.lines()
            .find(|l| l.starts_with("MemTotal:"))
            .and_then(|l| l.split_whitespace().nth(1)?.parse::<u64>().ok())
            .map(|kb| kb * 1024)
    });
    let cgroup = std::fs::read_to_string("/proc/self/cgroup")
        .ok()
        .and_then(|c| cgroup_limit(Path::new("/sys/fs/cgroup"), &c));
    let total = match (machine, cgroup) {
        (Some(m), Some(c)) => Some(m.min(c)),
        (m, c) => m.or(c),
    };
    total.map_or(8 << 30, |b| (b / 2).max(1 << 30))
}

/// The memory limit of the control group `proc_cgroup` names (the text of
/// `/proc/self/cgroup`) under the hierarchy mounted at `root`: the least
/// of its own and its parents' (a limit binds the groups below it), `None`
/// where none is set. cgroup v2 (`0::/path`, `memory.max`, `max` for none)
/// first, else v1 (`N:memory:/path` under `root/memory`,
/// `memory.limit_in_bytes`). A container often sees its own group as the
/// root: then the root's file holds the limit. A hybrid system lists
/// both; its memory controller is v1's.
pub fn cgroup_limit(root: &Path, proc_cgroup: &str) -> Option<u64> {
    let v2 = proc_cgroup.lines().find_map(|l| l.strip_prefix("0::"));
    let v1 = proc_cgroup.lines().find_map(|l| {
        let mut parts = l.splitn(3, ':');
        let (_, controllers, path) = (parts.next()?, parts.next()?, parts.next()?);
        controllers
            .split(',')
            .any(|c| c == "memory")
            .then_some(path)
    });
    // A hybrid system lists both: its memory controller is v1's.
    let (base, path, file) = match (v1, v2) {
        (Some(p), _) => (root.join("memory"), p, "memory.limit_in_bytes"),
        (None, Some(p)) => (root.to_path_buf(), p, "memory.max"),
        (None, None) => return None,
    };
    let mut dir = base.join(path.trim_start_matches('/'));
    let mut least: Option<u64> = None;
    loop {
        let limit = std::fs::read_to_string(dir.join(file))
            .ok()
            .and_then(|t| t.trim().parse::<u64>().ok());
        if let Some(l) = limit {
            least = Some(least.map_or(l, |m| m.min(l)));
        }
        if dir == base || !dir.pop() || !dir.starts_with(&base) {
            break;
        }
    }
    least
}

/// A `/proc/self/status` figure in KiB.
fn status_kib(key: &str) -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with(key))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

/// Peak resident set size of this process in bytes (`VmHWM`), where the
/// platform tells it.
pub fn peak_rss_bytes() -> Option<u64> {
    status_kib("VmHWM:").map(|kb| kb * 1024)
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A fake cgroup hierarchy: `files` (path under the root, contents).
    fn hierarchy(files: &[(&str, &str)]) -> tempfile::TempDir {
        let dir = tempfile::tempdir().unwrap();
        for (path, text) in files {
            let p = dir.path().join(path);
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            std::fs::write(p, text).unwrap();
        }
        dir
    }

    #[test]
    fn a_cgroup_limit_is_read_from_either_version_and_its_parents() {
        // v2: the job's own group under a parent with a tighter limit.
        let d = hierarchy(&[
            ("memory.max", "max\n"),
            ("job/memory.max", "4294967296\n"),
            ("job/step/memory.max", "max\n"),
        ]);
        assert_eq!(cgroup_limit(d.path(), "0::/job/step\n"), Some(4 << 30));
        // A container: its group is the root.
        let d = hierarchy(&[("memory.max", "2147483648\n")]);
        assert_eq!(cgroup_limit(d.path(), "0::/\n"), Some(2 << 30));
        // None set.
        let d = hierarchy(&[("memory.max", "max\n")]);
        assert_eq!(cgroup_limit(d.path(), "0::/\n"), None);
        // v1: the memory controller's line.
        let d = hierarchy(&[("memory/slurm/memory.limit_in_bytes", "1073741824\n")]);
        let v1 = "5:cpu,cpuacct:/slurm\n4:memory:/slurm\n";
        assert_eq!(cgroup_limit(d.path(), v1), Some(1 << 30));
        assert_eq!(cgroup_limit(d.path(), ""), None);
    }
}
