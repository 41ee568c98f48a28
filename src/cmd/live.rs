//! Live control of a running graph: `skinflow run --watch` applies edits of the graph file,
//! and `--control SOCKET` serves JSON lines on a Unix domain socket.
//!
//! Watch: an edit that changes nodes' kinds or parameters swaps those nodes (unchanged nodes
//! keep running with their state; queues are kept, so `block` edges lose nothing; a swapped
//! node's replacement takes over its learned state, e.g. the EIT reference, P0 and noise
//! estimates, see `skinflow_core::runtime::GraphHandle`). An invalid edit, or one that adds,
//! removes or rewires nodes and edges, is rejected with its error and the running graph goes on.
//!
//! Control socket, one JSON object per line, one reply per line (`{"ok": true, ...}` or
//! `{"ok": false, "error": "..."}`; `tare` and `control` wait for the node's answer, so a
//! command the node rejects gives its error). The socket path must not exist or be a stale
//! socket; any other file there is refused, never replaced:
//! `{"cmd": "stats"}`, `{"cmd": "tare", "node": "sync"}`,
//! `{"cmd": "control", "node": "recon", "command": "tare"}`,
//! `{"cmd": "swap", "node": "split", "kind": "splitter", "params": {"strategy": "proportional"}}`.

use std::io::{BufRead, BufReader, Write};
use std::os::unix::fs::FileTypeExt;
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, SystemTime};

use anyhow::{Context as _, Result, bail};
use serde_json::{Value, json};
use skinflow_core::graph::{EdgeSpec, SourceFile};
use skinflow_core::{GraphHandle, GraphSpec, Params, Registry};

/// What a node is, for diffing two versions of a graph file.
fn node_key(spec: &GraphSpec) -> Vec<(String, String, toml::Table)> {
    spec.nodes.iter().map(|n| (n.id.clone(), n.kind.clone(), n.params.table().clone())).collect()
}

fn edge_key(e: &EdgeSpec) -> (String, String, usize, String) {
    (e.from.clone(), e.to.clone(), e.capacity, format!("{:?}", e.policy))
}

/// Applies one edit: validates, checks the structure is unchanged, swaps changed nodes.
/// Returns the ids swapped.
pub fn apply_edit(old: &GraphSpec, new: &GraphSpec, handle: &GraphHandle) -> Result<Vec<String>, String> {
    let (a, b) = (node_key(old), node_key(new));
    let ids = |k: &[(String, String, toml::Table)]| k.iter().map(|n| n.0.clone()).collect::<Vec<_>>();
    if ids(&a) != ids(&b) {
        return Err("nodes were added, removed or reordered: that needs a restart".into());
    }
    let (ea, eb): (Vec<_>, Vec<_>) =
        (old.edges.iter().map(edge_key).collect(), new.edges.iter().map(edge_key).collect());
    if ea != eb {
        return Err("edges were added, removed or changed: that needs a restart".into());
    }
    for (o, n) in old.nodes.iter().zip(&new.nodes) {
        if o.trigger != n.trigger || o.thread != n.thread || o.cpu != n.cpu || o.rt_priority != n.rt_priority {
            return Err(format!("node \"{}\": trigger or thread options changed: that needs a restart", n.id));
        }
    }
    let mut swapped = Vec::new();
    for ((old_n, new_n), (ka, kb)) in old.nodes.iter().zip(&new.nodes).zip(a.iter().zip(&b)) {
        if ka != kb {
            handle.swap(&new_n.id, new_n.factory.clone(), new_n.params.clone()).map_err(|e| e.to_string())?;
            tracing::info!(node = %new_n.id, from = %old_n.kind, to = %new_n.kind, "node replaced after an edit");
            swapped.push(new_n.id.clone());
        }
    }
    Ok(swapped)
}

fn mtime(p: &Path) -> Option<SystemTime> {
    std::fs::metadata(p).and_then(|m| m.modified()).ok()
}

/// Watches the graph file until `done`; applies valid edits, reports rejected ones.
pub fn watch(path: PathBuf, registry: Registry, mut current: GraphSpec, handle: GraphHandle, done: Arc<AtomicBool>) {
    let mut seen = mtime(&path);
    while !done.load(Ordering::SeqCst) {
        std::thread::sleep(Duration::from_millis(200));
        let now = mtime(&path);
        if now == seen {
            continue;
        }
        seen = now;
        let src = match SourceFile::read(&path) {
            Ok(s) => s,
            Err(e) => {
                eprintln!("{}: edit rejected: cannot read: {e}", path.display());
                continue;
            }
        };
        match GraphSpec::parse(src, &registry) {
            Err(errs) => {
                for e in &errs.0 {
                    eprintln!("edit rejected: {e}");
                }
            }
            Ok(new) => match apply_edit(&current, &new, &handle) {
                Ok(swapped) if swapped.is_empty() => eprintln!("{}: edit applied: no node changed", path.display()),
                Ok(swapped) => {
                    eprintln!("{}: edit applied: swapped {}", path.display(), swapped.join(", "));
                    current = new;
                }
                Err(e) => eprintln!("{}: edit rejected: {e}", path.display()),
            },
        }
    }
}

/// Longest a `tare` or `control` request waits for the node to run the command.
const CONTROL_REPLY_TIMEOUT: Duration = Duration::from_secs(10);

fn reply(handle: &GraphHandle, registry: &Registry, line: &str) -> Value {
    let req: Value = match serde_json::from_str(line) {
        Ok(v) => v,
        Err(e) => return json!({"ok": false, "error": format!("not JSON: {e}")}),
    };
    let s = |k: &str| req.get(k).and_then(Value::as_str);
    let result: Result<Value, String> = match s("cmd") {
        Some("stats") => serde_json::to_value(handle.stats()).map_err(|e| e.to_string()),
        Some("tare") => match s("node") {
            Some(n) => {
                handle.control_wait(n, "tare", CONTROL_REPLY_TIMEOUT).map(|()| json!({})).map_err(|e| e.to_string())
            }
            None => Err("\"tare\" needs \"node\"".into()),
        },
        Some("control") => match (s("node"), s("command")) {
            (Some(n), Some(c)) => {
                handle.control_wait(n, c, CONTROL_REPLY_TIMEOUT).map(|()| json!({})).map_err(|e| e.to_string())
            }
            _ => Err("\"control\" needs \"node\" and \"command\"".into()),
        },
        Some("swap") => match (s("node"), s("kind")) {
            (Some(n), Some(k)) => match registry.get(k) {
                None => Err(format!("unknown kind \"{k}\"")),
                Some(f) => {
                    let params = req.get("params").cloned().unwrap_or(json!({}));
                    match toml::Table::try_from(params) {
                        Ok(t) => handle
                            .swap(n, f.clone(), Params::from_table(t))
                            .map(|()| json!({}))
                            .map_err(|e| e.to_string()),
                        Err(e) => Err(format!("params: {e}")),
                    }
                }
            },
            _ => Err("\"swap\" needs \"node\" and \"kind\"".into()),
        },
        Some(other) => Err(format!("unknown cmd \"{other}\" (known: stats, tare, control, swap)")),
        None => Err("missing \"cmd\"".into()),
    };
    match result {
        Ok(Value::Object(mut m)) if !m.contains_key("nodes") => {
            m.insert("ok".into(), json!(true));
            Value::Object(m)
        }
        Ok(v) => json!({"ok": true, "stats": v}),
        Err(e) => json!({"ok": false, "error": e}),
    }
}

fn serve(stream: UnixStream, handle: GraphHandle, registry: Registry) {
    let Ok(mut out) = stream.try_clone() else { return };
    for line in BufReader::new(stream).lines() {
        let Ok(line) = line else { return };
        if line.trim().is_empty() {
            continue;
        }
        let r = reply(&handle, &registry, &line);
        if writeln!(out, "{r}").is_err() {
            return;
        }
    }
}

/// Binds the control socket. An existing socket at `path` (left by an earlier run) is
/// replaced; any other existing file is refused and left alone.
pub fn bind_control_socket(path: &Path) -> Result<UnixListener> {
    match std::fs::symlink_metadata(path) {
        Ok(m) if m.file_type().is_socket() => {
            std::fs::remove_file(path).with_context(|| format!("{}: cannot replace the old socket", path.display()))?;
        }
        Ok(m) => bail!(
            "{}: --control: exists and is not a socket ({}); refusing to replace it: remove it or choose another path",
            path.display(),
            if m.is_dir() {
                "a directory"
            } else if m.file_type().is_symlink() {
                "a symbolic link"
            } else {
                "a file"
            }
        ),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => bail!("{}: --control: cannot inspect the path: {e}", path.display()),
    }
    let listener =
        UnixListener::bind(path).with_context(|| format!("{}: cannot bind the control socket", path.display()))?;
    listener.set_nonblocking(true).with_context(|| format!("{}: control socket", path.display()))?;
    Ok(listener)
}

/// Serves the control socket until `done`; removes the socket file at the end.
pub fn control_socket(
    listener: UnixListener,
    path: &Path,
    registry: Registry,
    handle: GraphHandle,
    done: Arc<AtomicBool>,
) -> std::thread::JoinHandle<()> {
    let path = path.to_path_buf();
    std::thread::spawn(move || {
        while !done.load(Ordering::SeqCst) {
            match listener.accept() {
                Ok((s, _)) => {
                    let _ = s.set_nonblocking(false);
                    let (h, r) = (handle.clone(), registry.clone());
                    std::thread::spawn(move || serve(s, h, r));
                }
                Err(_) => std::thread::sleep(Duration::from_millis(50)),
            }
        }
        let _ = std::fs::remove_file(&path);
    })
}
