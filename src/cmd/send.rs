//! `skinflow send SOCKET REQUEST...`: a client of `skinflow run --control SOCKET` for scripts
//! (a calibration session moving the indenter, a tare before a trial). Sends each request as
//! one JSON line, prints each reply line, and fails on the first reply that is not `"ok": true`.

use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixStream;
use std::path::Path;
use std::time::Duration;

use anyhow::{Context as _, Result, bail};

/// Longer than the server's own wait for a node to run a command (10 s).
const REPLY_TIMEOUT: Duration = Duration::from_secs(30);

pub fn run(socket: &Path, requests: &[String]) -> Result<()> {
    let s = socket.display();
    let stream = UnixStream::connect(socket)
        .with_context(|| format!("{s}: cannot connect (is `skinflow run GRAPH --control {s}` running?)"))?;
    stream.set_read_timeout(Some(REPLY_TIMEOUT)).with_context(|| format!("{s}: setting the reply timeout"))?;
    let mut writer = stream.try_clone().with_context(|| format!("{s}: cannot use the connection"))?;
    let mut replies = BufReader::new(stream).lines();
    for request in requests {
        let line = request.trim();
        if line.contains('\n') || line.is_empty() {
            bail!("request {request:?}: must be one non-empty line of JSON");
        }
        writeln!(writer, "{line}").with_context(|| format!("{s}: sending {line}"))?;
        let reply = match replies.next() {
            Some(Err(e)) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {
                bail!("{s}: no reply to {line} within {} s", REPLY_TIMEOUT.as_secs())
            }
            Some(Err(e)) if e.kind() == std::io::ErrorKind::InvalidData => {
                bail!("{s}: the reply to {line} is not UTF-8 text ({e}): is this a skinflow control socket?")
            }
            // A reset is the graph's end (or its socket's) while the request was in flight.
            Some(Err(e)) => bail!(
                "{s}: the connection ended before a reply to {line} ({e}): the graph ended or closed its socket; \
                 whether the request was applied is not known (ask {{\"cmd\": \"stats\"}} of a graph still running)"
            ),
            Some(Ok(r)) => r,
            None => bail!("{s}: the graph closed the connection before replying to {line}"),
        };
        // A closed standard output (`skinflow send ... | head -c 300`) ends the session quietly:
        // the requests after this one are not sent. (SIGPIPE stays ignored: this command also
        // writes to a socket, whose peer hanging up must be an error, not the end of the process.)
        // The reply's status still decides the exit code.
        let printed = match writeln!(std::io::stdout(), "{reply}") {
            Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => false,
            r => r.map(|()| true).context("writing the reply to standard output")?,
        };
        let value: serde_json::Value =
            serde_json::from_str(&reply).with_context(|| format!("{s}: reply to {line} is not JSON"))?;
        if value.get("ok") != Some(&serde_json::Value::Bool(true)) {
            let error = value.get("error").and_then(|e| e.as_str()).unwrap_or("no error given");
            bail!("{s}: {line}: {}", error.trim_end());
        }
        if !printed {
            return Ok(());
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use std::io::{Read, Write};
    use std::os::unix::net::UnixListener;

    use super::*;

    /// A peer answering one request with `reply`, on a socket in a fresh directory.
    fn peer(name: &str, reply: &'static [u8]) -> (std::path::PathBuf, std::thread::JoinHandle<()>) {
        let dir = std::env::temp_dir().join(format!("skinflow-send-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("c.sock");
        let listener = UnixListener::bind(&path).unwrap();
        let server = std::thread::spawn(move || {
            let (mut conn, _) = listener.accept().unwrap();
            let mut byte = [0u8; 1];
            while conn.read(&mut byte).unwrap() == 1 && byte[0] != b'\n' {}
            conn.write_all(reply).unwrap();
        });
        (path, server)
    }

    #[test]
    fn a_reply_that_is_not_utf8_is_said_so_not_taken_for_the_connection_ending() {
        let (path, server) = peer("not-utf8", b"\xff\xfe ok\n");
        let e = run(&path, &["{\"cmd\":\"stats\"}".into()]).unwrap_err().to_string();
        server.join().unwrap();
        assert!(e.contains("the reply to {\"cmd\":\"stats\"} is not UTF-8 text"), "{e}");
        assert!(!e.contains("connection ended"), "{e}");
    }

    #[test]
    fn an_ok_reply_passes_and_an_error_reply_fails_naming_it() {
        let (path, server) = peer("ok", b"{\"ok\": true}\n");
        run(&path, &["{\"cmd\":\"stats\"}".into()]).unwrap();
        server.join().unwrap();
        let (path, server) = peer("err", b"{\"ok\": false, \"error\": \"no node \\\"x\\\"\"}\n");
        let e = run(&path, &["{\"cmd\":\"tare\"}".into()]).unwrap_err().to_string();
        server.join().unwrap();
        assert!(e.ends_with(": {\"cmd\":\"tare\"}: no node \"x\""), "{e}");
    }
}
