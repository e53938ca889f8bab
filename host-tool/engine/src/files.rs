//! How every output file is written: whole or not at all, and one writer
//! at a time (docs/cli.md § Output files).
//!
//! - [`write`] / [`write_with`]: the new content goes to a temporary file
//!   in the same directory (`NAME.tmp-PID-N`), is flushed and `fsync`ed,
//!   and only then renamed over `NAME`. A failure at any point — a full
//!   disk, a killed writer closure, a rename refused because `NAME` is a
//!   directory — removes the temporary file and leaves the old `NAME` as it
//!   was. A reader never sees a half-written file: a cut write used to
//!   leave a 0-byte or truncated CSV that `fit` then accepted.
//! - [`write_all`]: several files that belong together (a model and its
//!   history) — all are written to temporary files first, then renamed.
//! - [`Lock`]: a lock file `NAME.lock` created with `create_new` (atomic on
//!   every file system the tool runs on), holding the writer's process id,
//!   removed when the lock is dropped. Two `fit -o m.json` at once used to
//!   read the same history, and the later rename lost the earlier's step.
//!   A lock left by a process that no longer runs (killed) is taken over.
//!
//! Every command of the CLI and the engine's own writers (MODEL.json and
//! its history) write through here; nothing else calls `std::fs::write`.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};

/// Writes `bytes` to `path` atomically (module doc); the parent directory
/// is created when missing.
pub fn write(path: &Path, bytes: &[u8]) -> Result<()> {
    write_with(path, |w| Ok(w.write_all(bytes)?))
}

/// Writes what `fill` writes to `path` atomically (module doc), streamed
/// through a buffer: a million-row CSV is never held in memory. An error
/// from `fill` is returned with the file named; the old file stays.
pub fn write_with(path: &Path, fill: impl FnOnce(&mut dyn Write) -> Result<()>) -> Result<()> {
    let target = destination(path);
    let tmp = stage(&target, fill).with_context(|| cannot_write(path))?;
    commit(&tmp, &target).with_context(|| cannot_write(path))
}

/// Writes each `(path, bytes)` atomically, all or none: every file goes to
/// its temporary file first, and only when all are written are they
/// renamed, in order. (A rename that fails after an earlier one succeeded
/// — the second file's name is a directory — leaves the first renamed:
/// renames of two files cannot be one step.)
pub fn write_all(files: &[(&Path, &[u8])]) -> Result<()> {
    let mut staged: Vec<(PathBuf, PathBuf)> = Vec::new();
    for (path, bytes) in files {
        let target = destination(path);
        match stage(&target, |w| Ok(w.write_all(bytes)?)) {
            Ok(tmp) => staged.push((tmp, target)),
            Err(e) => {
                for (tmp, _) in &staged {
                    let _ = std::fs::remove_file(tmp);
                }
                return Err(e.context(format!("{} — nothing was written", cannot_write(path))));
            }
        }
    }
    let mut staged = staged.into_iter().zip(files);
    while let Some(((tmp, target), (path, _))) = staged.next() {
        if let Err(e) = commit(&tmp, &target) {
            for ((tmp, _), _) in staged {
                let _ = std::fs::remove_file(tmp);
            }
            return Err(e.context(cannot_write(path)));
        }
    }
    Ok(())
}

fn cannot_write(path: &Path) -> String {
    format!("cannot write {}", path.display())
}

/// The file a write replaces: the target of a symbolic link (writing
/// through it, as `std::fs::write` did, instead of replacing the link by a
/// file), else `path` itself.
fn destination(path: &Path) -> PathBuf {
    let is_link = std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_symlink());
    if is_link {
        if let Ok(real) = std::fs::canonicalize(path) {
            return real;
        }
    }
    path.to_path_buf()
}

/// Temporary files made by this process so far: the `N` of `NAME.tmp-PID-N`
/// (two threads writing one name never share a temporary file).
static TEMPS: AtomicUsize = AtomicUsize::new(0);

/// `NAME.tmp-PID-N` beside `target`.
fn temp_path(target: &Path) -> PathBuf {
    let mut name = target.file_name().unwrap_or_default().to_os_string();
    name.push(format!(
        ".tmp-{}-{}",
        std::process::id(),
        TEMPS.fetch_add(1, Ordering::Relaxed)
    ));
    target.with_file_name(name)
}

/// Writes the temporary file of `target` (created new, filled, flushed,
/// synced; the permissions of the file it replaces) and returns its path;
/// on any error it is removed.
fn stage(target: &Path, fill: impl FnOnce(&mut dyn Write) -> Result<()>) -> Result<PathBuf> {
    if let Some(dir) = target.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create the directory {}", dir.display()))?;
    }
    let tmp = temp_path(target);
    let file = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&tmp)
        .with_context(|| format!("cannot create {}", tmp.display()))?;
    let filled = (|| -> Result<()> {
        let mut w = std::io::BufWriter::new(file);
        fill(&mut w)?;
        let file = w.into_inner().map_err(|e| e.into_error())?;
        if let Ok(old) = std::fs::metadata(target) {
            // Best effort: a file system without permissions still gets
            // the content.
            let _ = file.set_permissions(old.permissions());
        }
        file.sync_all()?;
        Ok(())
    })();
    match filled {
        Ok(()) => Ok(tmp),
        Err(e) => {
            let _ = std::fs::remove_file(&tmp);
            Err(e)
        }
    }
}

/// Renames `tmp` over `target` (removing `tmp` when that fails) and syncs
/// the directory, so the new name survives a power cut.
fn commit(tmp: &Path, target: &Path) -> Result<()> {
    if let Err(e) = std::fs::rename(tmp, target) {
        let _ = std::fs::remove_file(tmp);
        return Err(e.into());
    }
    let dir = match target.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    // Directories cannot be opened for syncing everywhere (Windows): the
    // rename stands either way.
    if let Ok(d) = std::fs::File::open(dir) {
        let _ = d.sync_all();
    }
    Ok(())
}

/// How long [`Lock::acquire`] waits for another writer before refusing: a
/// model and its history are written in milliseconds, so a lock held
/// longer belongs to a writer that is stuck (or to a lock file copied in).
pub const LOCK_WAIT: Duration = Duration::from_secs(5);

/// The lock of one output (module doc): `NAME.lock` exists while it is
/// held and holds the holder's process id. Dropping it removes the file.
#[derive(Debug)]
pub struct Lock {
    path: PathBuf,
}

impl Lock {
    /// The lock file of `path`: `NAME.lock` beside it.
    pub fn path_for(path: &Path) -> PathBuf {
        let mut name = path.file_name().unwrap_or_default().to_os_string();
        name.push(".lock");
        path.with_file_name(name)
    }

    /// Takes the lock of `path`, waiting up to `wait` for another writer
    /// to finish; a lock whose process no longer runs is taken over. Held
    /// longer than `wait`: refused, naming the lock file and its holder.
    pub fn acquire(path: &Path, wait: Duration) -> Result<Lock> {
        let lock = Lock::path_for(path);
        if let Some(dir) = lock.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("cannot create the directory {}", dir.display()))?;
        }
        let start = Instant::now();
        let mut pause = Duration::from_millis(2);
        loop {
            match std::fs::OpenOptions::new()
                .write(true)
                .create_new(true)
                .open(&lock)
            {
                Ok(mut f) => {
                    // The id is for people and for the take-over below; a
                    // lock file without it still locks.
                    let _ = write!(f, "{}", std::process::id());
                    return Ok(Lock { path: lock });
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
                Err(e) => {
                    return Err(anyhow::Error::new(e)
                        .context(format!("cannot create the lock file {}", lock.display())))
                }
            }
            let holder = std::fs::read_to_string(&lock)
                .ok()
                .and_then(|s| s.trim().parse::<u32>().ok());
            if let Some(pid) = holder.filter(|&p| !process_runs(p)) {
                // Taken over only if it still names the dead process (not
                // a lock another writer took meanwhile).
                if std::fs::read_to_string(&lock).is_ok_and(|s| s.trim() == pid.to_string()) {
                    let _ = std::fs::remove_file(&lock);
                }
                continue;
            }
            if start.elapsed() >= wait {
                bail!(
                    "{} is being written by another trueaxis ({}; lock file {}): wait for it to finish — if no trueaxis is running, remove the lock file; nothing was written",
                    path.display(),
                    holder.map_or("process unknown".to_string(), |p| format!("process {p}")),
                    lock.display()
                );
            }
            std::thread::sleep(pause);
            pause = (pause * 2).min(Duration::from_millis(50));
        }
    }
}

impl Drop for Lock {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

/// Whether process `pid` runs. Known on Linux (`/proc`); elsewhere every
/// holder is taken to run (a stale lock is then removed by hand, as the
/// refusal says).
fn process_runs(pid: u32) -> bool {
    let proc = Path::new("/proc");
    !proc.join("self").exists() || proc.join(pid.to_string()).exists()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("trueaxis-files-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// Every file in `d`, by name.
    fn names(d: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn a_failure_mid_write_leaves_the_old_file_and_no_temporary() {
        let d = dir("mid");
        let p = d.join("data.csv");
        write(&p, b"x_mm,ex_um\n0,1\n").unwrap();
        let e = write_with(&p, |w| {
            w.write_all(b"x_mm,ex_um\n0,")?;
            // Past the buffer: the half-written content is on disk now.
            w.write_all(&[b'9'; 100_000])?;
            bail!("the disk is full")
        })
        .unwrap_err();
        assert_eq!(
            format!("{e:#}"),
            format!("cannot write {}: the disk is full", p.display())
        );
        assert_eq!(std::fs::read(&p).unwrap(), b"x_mm,ex_um\n0,1\n");
        assert_eq!(names(&d), ["data.csv"]);
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_refused_rename_leaves_no_temporary() {
        // `fit -o DIR` used to leave `DIR.tmp-PID` behind.
        let d = dir("rename");
        let target = d.join("m.json");
        std::fs::create_dir(&target).unwrap();
        std::fs::write(target.join("inside"), "kept").unwrap();
        assert!(write(&target, b"{}").is_err());
        assert_eq!(names(&d), ["m.json"]);
        let other = d.join("h.json");
        assert!(write_all(&[(other.as_path(), &b"1"[..]), (target.as_path(), &b"2"[..])]).is_err());
        // The first is renamed before the second fails (see write_all).
        assert_eq!(names(&d), ["h.json", "m.json"]);
        assert_eq!(
            std::fs::read_to_string(target.join("inside")).unwrap(),
            "kept"
        );
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_new_file_and_its_directory_are_made_and_links_written_through() {
        let d = dir("new");
        let p = d.join("sub").join("t.bin");
        write(&p, b"abc").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"abc");
        #[cfg(unix)]
        {
            let link = d.join("link.bin");
            std::os::unix::fs::symlink(&p, &link).unwrap();
            write(&link, b"def").unwrap();
            assert!(std::fs::symlink_metadata(&link)
                .unwrap()
                .file_type()
                .is_symlink());
            assert_eq!(std::fs::read(&p).unwrap(), b"def");
        }
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_held_lock_is_waited_for_then_refused_and_a_dead_holders_taken_over() {
        let d = dir("lock");
        let p = d.join("m.json");
        let held = Lock::acquire(&p, LOCK_WAIT).unwrap();
        assert_eq!(
            std::fs::read_to_string(Lock::path_for(&p)).unwrap(),
            std::process::id().to_string()
        );
        let e = Lock::acquire(&p, Duration::from_millis(30)).unwrap_err();
        assert_eq!(
            e.to_string(),
            format!(
                "{} is being written by another trueaxis (process {}; lock file {}): wait for it to finish — if no trueaxis is running, remove the lock file; nothing was written",
                p.display(),
                std::process::id(),
                Lock::path_for(&p).display()
            )
        );
        drop(held);
        assert!(!Lock::path_for(&p).exists());
        // A holder that is gone (pid beyond Linux's pid_max).
        if Path::new("/proc/self").exists() {
            std::fs::write(Lock::path_for(&p), "4194305").unwrap();
            let l = Lock::acquire(&p, Duration::from_millis(30)).unwrap();
            drop(l);
        }
        assert_eq!(names(&d), Vec::<String>::new());
        std::fs::remove_dir_all(&d).unwrap();
    }
}
