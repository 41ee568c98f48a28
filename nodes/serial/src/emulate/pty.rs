//! A pseudo-terminal behind a stable path: `dir/eit -> /dev/pts/N`, recreated on replug.
//!
//! The kernel picks pty numbers, so the emulator publishes a symlink and replaces its target
//! atomically (link to a temporary name, then rename) when the device is replugged. Both ends are
//! raw (cfmakeraw), so binary frames pass unmangled. The emulator keeps its own slave descriptor
//! open: writes are buffered while no reader is attached, and a reader's close does not hang up
//! the master. The master is non-blocking so a writer can honour a stop request.

use std::io;
use std::os::fd::{AsFd, AsRawFd, OwnedFd};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use nix::errno::Errno;
use nix::fcntl::{FcntlArg, OFlag, fcntl};
use nix::poll::{PollFd, PollFlags, PollTimeout, poll};
use nix::pty::openpty;
use nix::sys::termios::{SetArg, cfmakeraw, tcgetattr, tcsetattr};

/// How often blocked writes and drains look at the stop flag.
const STOP_POLL: Duration = Duration::from_millis(20);
/// How long the slave's input queue must stay empty before bytes count as taken by a reader.
const DRAIN_SETTLE: Duration = Duration::from_millis(100);

nix::ioctl_read_bad!(bytes_queued, nix::libc::FIONREAD, nix::libc::c_int);

struct PtyPair {
    master: OwnedFd,
    slave: OwnedFd,
}

/// What a write achieved.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Written {
    /// Every byte went into the pty.
    All,
    /// The pty stayed full; the last `bytes` bytes were dropped.
    Dropped { bytes: usize },
    /// The emulator is stopping.
    Stopped,
}

/// A pty pair published at a stable symlink path.
pub(super) struct StablePty {
    link: PathBuf,
    pair: Option<PtyPair>,
}

fn raw(fd: impl AsFd) -> nix::Result<()> {
    let mut t = tcgetattr(&fd)?;
    cfmakeraw(&mut t);
    tcsetattr(&fd, SetArg::TCSANOW, &t)
}

fn open_pair(link: &Path) -> io::Result<PtyPair> {
    let pty = openpty(None, None)?;
    raw(&pty.slave)?;
    raw(&pty.master)?;
    let flags = OFlag::from_bits_truncate(fcntl(&pty.master, FcntlArg::F_GETFL)?);
    fcntl(&pty.master, FcntlArg::F_SETFL(flags | OFlag::O_NONBLOCK))?;
    let slave_path = nix::unistd::ttyname(&pty.slave)?;
    // Made aside under a name of this process's own (a user's `eit.new` is not ours to remove)
    // and renamed over the link, so a reader never finds the link missing.
    let name = link.file_name().map_or_else(Default::default, |n| n.to_string_lossy().into_owned());
    let tmp = link.with_file_name(format!(".{name}.{}.new", std::process::id()));
    let _ = std::fs::remove_file(&tmp);
    std::os::unix::fs::symlink(&slave_path, &tmp)?;
    std::fs::rename(&tmp, link)?;
    Ok(PtyPair { master: pty.master, slave: pty.slave })
}

impl StablePty {
    /// Opens a pty pair and publishes its slave at `link`; an old symlink there is replaced,
    /// anything else at that path is left alone and is an error.
    pub(super) fn create(link: PathBuf) -> io::Result<Self> {
        if let Ok(meta) = std::fs::symlink_metadata(&link)
            && !meta.file_type().is_symlink()
        {
            return Err(io::Error::new(
                io::ErrorKind::AlreadyExists,
                format!("{} exists and is not a symlink", link.display()),
            ));
        }
        let pair = open_pair(&link)?;
        Ok(Self { link, pair: Some(pair) })
    }

    /// The device disappears: the link is removed first (so a reader cannot reopen the dying
    /// pty), then both ends are closed, which hangs up any reader.
    pub(super) fn unplug(&mut self) -> io::Result<()> {
        match std::fs::remove_file(&self.link) {
            Err(e) if e.kind() != io::ErrorKind::NotFound => return Err(e),
            _ => {}
        }
        self.pair = None;
        Ok(())
    }

    /// The device returns at the same path, on a new pty.
    pub(super) fn replug(&mut self) -> io::Result<()> {
        self.pair = Some(open_pair(&self.link)?);
        Ok(())
    }

    /// Writes `bytes`, waiting for room while a reader is slow. With `give_up`, bytes the pty
    /// has not taken after that long are dropped, as a board's full transmit buffer drops them.
    pub(super) fn write(
        &mut self,
        mut bytes: &[u8],
        stop: &AtomicBool,
        give_up: Option<Duration>,
    ) -> io::Result<Written> {
        let pair = self.pair.as_ref().ok_or_else(|| io::Error::other("pty is unplugged"))?;
        let until = give_up.map(|d| Instant::now() + d);
        while !bytes.is_empty() {
            if stop.load(Ordering::Relaxed) {
                return Ok(Written::Stopped);
            }
            match nix::unistd::write(&pair.master, bytes) {
                Ok(n) => bytes = &bytes[n..],
                Err(Errno::EAGAIN | Errno::EINTR) => {
                    if until.is_some_and(|u| Instant::now() >= u) {
                        return Ok(Written::Dropped { bytes: bytes.len() });
                    }
                    let mut fds = [PollFd::new(pair.master.as_fd(), PollFlags::POLLOUT)];
                    poll(&mut fds, PollTimeout::try_from(STOP_POLL).unwrap_or(PollTimeout::NONE))?;
                }
                Err(e) => return Err(e.into()),
            }
        }
        Ok(Written::All)
    }

    /// Waits until a reader has taken every written byte, `timeout` (if any) passed, or `stop`
    /// was raised.
    ///
    /// The kernel moves written bytes into the slave's input queue asynchronously, so an empty
    /// queue right after a write proves nothing: the queue must stay empty for `DRAIN_SETTLE`.
    pub(super) fn wait_drained(&self, timeout: Option<Duration>, stop: &AtomicBool) -> io::Result<()> {
        let Some(pair) = self.pair.as_ref() else {
            return Ok(());
        };
        let until = timeout.map(|t| Instant::now() + t);
        let mut empty_since: Option<Instant> = None;
        loop {
            let mut queued: nix::libc::c_int = 0;
            // SAFETY: FIONREAD writes one c_int through the pointer, which points to a live local;
            // the descriptor is an open tty owned by `pair`.
            unsafe { bytes_queued(pair.slave.as_raw_fd(), &mut queued) }?;
            let now = Instant::now();
            if queued == 0 {
                if now.duration_since(*empty_since.get_or_insert(now)) >= DRAIN_SETTLE {
                    return Ok(());
                }
            } else {
                empty_since = None;
            }
            if until.is_some_and(|u| now >= u) || stop.load(Ordering::Relaxed) {
                return Ok(());
            }
            std::thread::sleep(STOP_POLL / 4);
        }
    }
}

impl Drop for StablePty {
    fn drop(&mut self) {
        // Best effort: the link may already be gone (unplugged, or removed by the user).
        let _ = std::fs::remove_file(&self.link);
    }
}

#[cfg(test)]
mod tests {
    use super::StablePty;

    /// The link is made aside under a name of the process's own: a user's `eit.new` beside it
    /// was removed before.
    #[test]
    fn publishing_a_link_leaves_a_users_file_named_like_its_temporary_alone() {
        let d = std::env::temp_dir().join(format!("skinflow-pty-new-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        std::fs::write(d.join("eit.new"), "notes").unwrap();
        let pty = StablePty::create(d.join("eit")).unwrap();
        assert!(std::fs::symlink_metadata(d.join("eit")).unwrap().file_type().is_symlink());
        assert_eq!(std::fs::read_to_string(d.join("eit.new")).unwrap(), "notes");
        let left: Vec<_> = std::fs::read_dir(&d).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(left.len(), 2, "no temporary left: {left:?}");
        drop(pty);
        std::fs::remove_dir_all(&d).unwrap();
    }
}
