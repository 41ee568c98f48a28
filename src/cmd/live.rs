//! Live control of a running graph: `skinflow run --watch` applies edits of the graph file,
//! and `--control SOCKET` serves JSON lines on a Unix domain socket.
//!
//! Watch: an edit that changes nodes' kinds or parameters swaps those nodes (unchanged nodes
//! keep running with their state; queues are kept, so `block` edges lose nothing; a swapped
//! node's replacement takes over its learned state, e.g. the EIT reference, P0 and noise
//! estimates, see `skinflow_core::runtime::GraphHandle`); a node's `deadline_us` and `restart`
//! are applied to the running node. An invalid edit, or one that adds, removes or rewires nodes
//! and edges, or changes what only a restart can (`[graph]` keys, a node's `trigger`, `thread`,
//! `cpu`, `rt_priority`: `needs a restart: <key> of node "x" changed`), is rejected with its
//! error and the running graph goes on. A swap is reported applied (by the socket's `ok` too)
//! only once the node runs its replacement; one the replacement refuses (a source asked to
//! continue another recording or scene, a logger asked to write the file it is writing) or that
//! its node never gets to within 10 s is reported with the reason, and the node runs as before.
//! An edit is compared with what runs now (swaps made through the socket included), and when one
//! of its swaps fails (a node that cannot build), the swaps before it stay and the message names
//! them. A plugin library whose file changes (rebuilt) is loaded again as a fresh copy, and every
//! running node of its kinds is swapped to the new code with its params, once the graph with the
//! new kinds passes an edit's checks (sensors, files: the new code may declare other params);
//! refused, every node keeps the previous code.
//!
//! Control socket, one JSON object per line, one reply per line (`{"ok": true, ...}` or
//! `{"ok": false, "error": "..."}`; `tare` and `control` wait for the node's answer, so a
//! command the node rejects gives its error). The socket path must not exist or be a stale
//! socket; any other file there is refused, never replaced:
//! `{"cmd": "stats"}` (or one node's: `{"cmd": "stats", "node": "recon"}`), `{"cmd": "tare", "node": "sync"}`,
//! `{"cmd": "control", "node": "recon", "command": "tare"}`,
//! `{"cmd": "swap", "node": "split", "kind": "splitter", "params": {"strategy": "proportional"}}`.

use std::io::{BufRead, BufReader, Write};
use std::os::unix::fs::FileTypeExt;
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, SystemTime};

use anyhow::{Context as _, Result, bail};
use serde_json::{Value, json};
use skinflow_core::graph::{EdgeSpec, NodeSpec, Restart, SourceFile};
use skinflow_core::registry::NodeFactory;
use skinflow_core::{GraphHandle, GraphSpec, Params, Registry};

/// What a node runs: (id, kind, params).
type NodeNow = (String, String, Params);

/// A node's per-call deadline (`deadline_us`) and restart policy, as running.
type Policy = (Option<f64>, Restart);

/// Longest a swap waits for its node to install it (a source paced to its next message, the
/// graph ending); after that it is cancelled and reported, and the node runs as before.
const SWAP_TIMEOUT: Duration = Duration::from_secs(10);

fn node_key(spec: &GraphSpec) -> Vec<NodeNow> {
    spec.nodes.iter().map(|n| (n.id.clone(), n.kind.clone(), n.params.clone())).collect()
}

fn policy(n: &NodeSpec) -> Policy {
    (n.deadline_us, n.restart)
}

/// The first key of an edit that only a restart can apply: `[graph]` keys, then per node the
/// placement and trigger (the nodes' ids and edges are compared apart).
fn needs_restart(old: &GraphSpec, new: &GraphSpec) -> Option<String> {
    let graph =
        [("name", old.name != new.name), ("mode", old.mode != new.mode), ("workers", old.workers != new.workers)];
    if let Some((key, _)) = graph.iter().find(|(_, changed)| *changed) {
        return Some(format!("needs a restart: [graph] {key} changed"));
    }
    for (o, n) in old.nodes.iter().zip(&new.nodes) {
        let keys = [
            ("trigger", o.trigger != n.trigger),
            ("thread", o.thread != n.thread),
            ("cpu", o.cpu != n.cpu),
            ("rt_priority", o.rt_priority != n.rt_priority),
        ];
        if let Some((key, _)) = keys.iter().find(|(_, changed)| *changed) {
            return Some(format!("needs a restart: {key} of node \"{}\" changed", n.id));
        }
    }
    None
}

/// What an edit changed in the running graph.
#[derive(Debug, Default)]
pub struct Applied {
    /// Nodes whose deadline or restart policy changed, as `deadline_us of node "x"` etc.
    pub policies: Vec<String>,
    /// Nodes swapped.
    pub swapped: Vec<String>,
}

impl Applied {
    /// Nothing changed.
    pub fn is_empty(&self) -> bool {
        self.policies.is_empty() && self.swapped.is_empty()
    }
}

impl std::fmt::Display for Applied {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mut parts = Vec::new();
        if !self.policies.is_empty() {
            parts.push(format!("set {}", self.policies.join(", ")));
        }
        if !self.swapped.is_empty() {
            parts.push(format!("swapped {}", self.swapped.join(", ")));
        }
        if self.is_empty() {
            return write!(f, "no node changed");
        }
        write!(f, "{}", parts.join("; "))
    }
}

fn edge_key(e: &EdgeSpec) -> (String, String, usize, String) {
    (e.from.clone(), e.to.clone(), e.capacity, format!("{:?}", e.policy))
}

/// A plugin library as last loaded.
struct Library {
    path: PathBuf,
    mtime: Option<SystemTime>,
    kinds: Vec<String>,
}

/// The kinds a running graph can swap in: the built-ins and the graph's `[[plugin]]` libraries.
/// When a library file changes (a rebuilt plugin), every library is loaded again as a fresh
/// copy, so the next swap, from an edit or the socket, builds from the new code.
pub struct Kinds {
    registry: Registry,
    libraries: Vec<Library>,
    /// The graph file text that named the libraries: a reload's error is located there.
    source: SourceFile,
}

impl Kinds {
    /// Loads `plugins`, the `[[plugin]]` paths of graph file `src`: an error is located at the
    /// failing library's entry there (`file:line:col: plugin PATH: cause`).
    pub fn load(plugins: &[PathBuf], src: &SourceFile) -> Result<Kinds, String> {
        let mut registry = skinflow_nodes::registry();
        let loaded = skinflow_nodes::codec::load_plugins(plugins, &mut registry)
            .map_err(|e| skinflow_core::graph::plugin_error(src, e.path(), e.to_string()).to_string())?;
        let libraries = plugins
            .iter()
            .zip(loaded)
            .map(|(path, l)| Library { path: path.clone(), mtime: mtime(path), kinds: l.kinds })
            .collect();
        Ok(Kinds { registry, libraries, source: src.clone() })
    }

    /// The libraries whose file changed since they were loaded.
    fn changed(&self) -> Vec<&Library> {
        self.libraries.iter().filter(|l| mtime(&l.path) != l.mtime).collect()
    }

    fn paths(&self) -> Vec<PathBuf> {
        self.libraries.iter().map(|l| l.path.clone()).collect()
    }
}

/// The live graph as the watcher and the control socket see it: its structure as started, what
/// each node runs now (updated by every swap, whether from an edit or the socket, so an edit is
/// compared with the running graph, not with the last file read) and the kinds it can swap in.
pub struct Live {
    handle: GraphHandle,
    started: GraphSpec,
    nodes: Mutex<Vec<NodeNow>>,
    policies: Mutex<Vec<Policy>>,
    kinds: Mutex<Kinds>,
    /// Files the command writes beside the graph (`--stats-json`, `--control`), as (option,
    /// path): no swap may point a node at one of them.
    extra_outputs: Vec<(&'static str, PathBuf)>,
}

/// An edit that could not be applied whole: the deadlines and restart policies it changed are
/// set, and the nodes swapped before the failure keep their new kind and params (the running
/// graph now differs from the file in the failed node only).
#[derive(Debug)]
pub struct EditError {
    /// What the edit changed before it failed.
    pub done: Applied,
    pub error: String,
}

impl std::fmt::Display for EditError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.done.is_empty() {
            write!(f, "edit rejected: {}", self.error)
        } else {
            write!(f, "edit partly applied: {} (that node runs as before the edit)", self.partly())
        }
    }
}

impl EditError {
    fn rejected(error: String) -> EditError {
        EditError { done: Applied::default(), error }
    }

    /// `set deadline_us of node "x"; swapped a, b; then <error>`, or the error alone when
    /// nothing was applied.
    fn partly(&self) -> String {
        if self.done.is_empty() { self.error.clone() } else { format!("{}; then {}", self.done, self.error) }
    }
}

impl Live {
    /// `spec` is the graph as started, `kinds` its plugins loaded for swaps (`Kinds::load`).
    /// `extra_outputs`: the files the command writes beside the graph, as (option, path).
    pub fn new(
        spec: &GraphSpec,
        kinds: Kinds,
        handle: GraphHandle,
        extra_outputs: Vec<(&'static str, PathBuf)>,
    ) -> Arc<Live> {
        Arc::new(Live {
            handle,
            started: spec.clone(),
            nodes: Mutex::new(node_key(spec)),
            policies: Mutex::new(spec.nodes.iter().map(policy).collect()),
            kinds: Mutex::new(kinds),
            extra_outputs,
        })
    }

    fn lock_nodes(&self) -> std::sync::MutexGuard<'_, Vec<NodeNow>> {
        self.nodes.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    fn lock_kinds(&self) -> std::sync::MutexGuard<'_, Kinds> {
        self.kinds.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Swaps `node` to `kind` with `params`, once the node runs the replacement, and records it.
    fn swap(&self, node: &str, factory: Arc<dyn NodeFactory>, kind: &str, params: Params) -> Result<(), String> {
        self.handle.swap_wait(node, factory, params.clone(), SWAP_TIMEOUT).map_err(|e| e.to_string())?;
        if let Some(n) = self.lock_nodes().iter_mut().find(|n| n.0 == node) {
            (n.1, n.2) = (kind.to_owned(), params);
        }
        Ok(())
    }

    /// Refuses a swap of `node` to `kind` with `params` after which the graph's sensors would
    /// disagree or a node would write over an input or another's output
    /// ([`check_swapped_graph`]), checked on the graph as it runs now with that one change.
    fn check_swap(
        &self,
        node: &str,
        factory: &Arc<dyn NodeFactory>,
        kind: &str,
        params: &Params,
    ) -> Result<(), String> {
        let running = self.lock_nodes().clone();
        let kinds = self.lock_kinds();
        let spec = graph_now(&self.started, &running, &kinds.registry, &[], Some((node, factory, kind, params)));
        drop(kinds);
        check_swapped_graph(&spec, &self.extra_outputs)
    }

    /// Refuses a load cell's `at X Y [D]` that the graph's checks would refuse as the rig's
    /// params (`x_mm`, `y_mm`, `diameter_mm`): a position off the sensor of the logger that
    /// records its truth, an indenter wider than it. Checked as a swap to those params is
    /// ([`Live::check_swap`]). Other commands, and an `at` the node cannot parse (it says
    /// why), go to the node.
    fn check_control(&self, node: &str, command: &str) -> Result<(), String> {
        let Some((_, kind, params)) = self.lock_nodes().iter().find(|n| n.0 == node).cloned() else { return Ok(()) };
        if kind != "serial_loadcell" {
            return Ok(());
        }
        let Ok(rig) = params.parse::<skinflow_nodes::serial::LoadcellParams>() else { return Ok(()) };
        let Ok((x, y, d)) = skinflow_nodes::serial::parse_at(command, rig.diameter_mm) else { return Ok(()) };
        let mut table = params.table().clone();
        for (key, value) in [("x_mm", x), ("y_mm", y), ("diameter_mm", d)] {
            table.insert(key.into(), value.into());
        }
        let Some(factory) = self.lock_kinds().registry.get(&kind).cloned() else { return Ok(()) };
        self.check_swap(node, &factory, &kind, &Params::from_table(table))
            .map_err(|e| format!("control command \"{command}\" refused: {e}"))
    }

    /// Applies one validated edit: checks the structure and what only a restart can change are
    /// unchanged, sets the deadlines and restart policies that changed, and swaps the nodes
    /// whose kind or params differ from what runs now.
    pub fn apply_edit(&self, new: &GraphSpec) -> Result<Applied, EditError> {
        let rejected = EditError::rejected;
        let old = &self.started;
        let ids = |s: &GraphSpec| s.nodes.iter().map(|n| n.id.clone()).collect::<Vec<_>>();
        let (was, now) = (ids(old), ids(new));
        if was != now {
            let added: Vec<_> = now.iter().filter(|i| !was.contains(i)).map(|i| format!("\"{i}\"")).collect();
            let removed: Vec<_> = was.iter().filter(|i| !now.contains(i)).map(|i| format!("\"{i}\"")).collect();
            let what = match (added.is_empty(), removed.is_empty()) {
                (false, false) => format!("nodes {} added and {} removed", added.join(", "), removed.join(", ")),
                (false, true) => format!("nodes {} added", added.join(", ")),
                (true, false) => format!("nodes {} removed", removed.join(", ")),
                (true, true) => "nodes reordered".to_owned(),
            };
            return Err(rejected(format!("{what}: that needs a restart")));
        }
        let (ea, eb): (Vec<_>, Vec<_>) =
            (old.edges.iter().map(edge_key).collect(), new.edges.iter().map(edge_key).collect());
        if ea != eb {
            return Err(rejected("edges were added, removed or changed: that needs a restart".into()));
        }
        if let Some(why) = needs_restart(old, new) {
            return Err(rejected(why));
        }
        check_swapped_graph(new, &self.extra_outputs).map_err(rejected)?;
        let mut applied = Applied::default();
        {
            let mut policies = self.policies.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
            for (running, n) in policies.iter_mut().zip(&new.nodes) {
                let want = policy(n);
                if *running == want {
                    continue;
                }
                if let Err(e) = self.handle.set_policy(&n.id, want.0, want.1) {
                    return Err(rejected(e.to_string()));
                }
                if running.0 != want.0 {
                    applied.policies.push(format!("deadline_us of node \"{}\"", n.id));
                }
                if running.1 != want.1 {
                    applied.policies.push(format!("restart of node \"{}\"", n.id));
                }
                *running = want;
            }
        }
        // Replacements record the edited file as their graph (a logger's `graph` attribute).
        self.handle.set_graph_text(new.source.text.clone());
        let now = self.lock_nodes().clone();
        for (running, new_n) in now.iter().zip(&new.nodes) {
            if (&running.1, running.2.table()) != (&new_n.kind, new_n.params.table()) {
                if let Err(error) = self.swap(&new_n.id, new_n.factory.clone(), &new_n.kind, new_n.params.clone()) {
                    return Err(EditError { done: applied, error });
                }
                tracing::info!(node = %new_n.id, from = %running.1, to = %new_n.kind, "node replaced after an edit");
                applied.swapped.push(new_n.id.clone());
            }
        }
        Ok(applied)
    }

    /// Loads the plugin libraries again when one of their files changed, and swaps every node of
    /// a kind from a changed library to the new code (same params). `None` when nothing changed.
    fn reload_changed_plugins(&self) -> Option<Result<Vec<String>, String>> {
        let mut kinds = self.lock_kinds();
        let changed: Vec<(PathBuf, Vec<String>)> =
            kinds.changed().into_iter().map(|l| (l.path.clone(), l.kinds.clone())).collect();
        if changed.is_empty() {
            return None;
        }
        let names = changed.iter().map(|(p, _)| p.display().to_string()).collect::<Vec<_>>().join(", ");
        // Located in the text that named the libraries (an edit may have changed them since
        // the graph started).
        let fresh = match Kinds::load(&kinds.paths(), &kinds.source) {
            Ok(k) => k,
            Err(e) => {
                // Not swapped: the running nodes keep the old code. The file's time is taken as
                // seen, so a half-written library is tried again only when it changes again.
                for l in kinds.libraries.iter_mut() {
                    l.mtime = mtime(&l.path);
                }
                // `e` is located at the library's `[[plugin]]` entry (file:line:col).
                return Some(Err(format!(
                    "{e}; the library changed but was not reloaded (running nodes keep its previous code)"
                )));
            }
        };
        let graph = self.started.source.path.display();
        let stale: Vec<&String> = changed.iter().flat_map(|(_, k)| k).collect();
        let now = self.lock_nodes().clone();
        // Checked as an edit's swaps are, before any node is swapped: the new code's kinds may
        // declare other params (a sensor, a file it writes) than the running ones did.
        if let Err(e) =
            check_swapped_graph(&graph_now(&self.started, &now, &fresh.registry, &stale, None), &self.extra_outputs)
        {
            for l in kinds.libraries.iter_mut() {
                l.mtime = mtime(&l.path);
            }
            return Some(Err(format!(
                "{graph}: plugin {names} changed but was not reloaded (running nodes keep its previous code): {e}"
            )));
        }
        *kinds = fresh;
        let mut swapped: Vec<String> = Vec::new();
        let failed = |swapped: Vec<String>, error: String| {
            let e = EditError { done: Applied { policies: Vec::new(), swapped }, error };
            Some(Err(format!("{graph}: plugin {names} reloaded: {} (that node runs its previous code)", e.partly())))
        };
        for (id, kind, params) in now.iter().filter(|n| stale.contains(&&n.1)) {
            // A node that runs no more (a source whose stream ended) has nothing to swap; the
            // others of the library still get the new code.
            if self.handle.node_ended(id).unwrap_or(false) {
                tracing::info!(node = %id, "plugin reloaded: node not swapped, it runs no more");
                continue;
            }
            let Some(factory) = kinds.registry.get(kind).cloned() else {
                return failed(swapped, format!("node \"{id}\": kind \"{kind}\" is no longer in the library"));
            };
            if let Err(e) = self.swap(id, factory, kind, params.clone()) {
                return failed(swapped, e);
            }
            swapped.push(id.clone());
        }
        Some(Ok(swapped))
    }
}

fn mtime(p: &Path) -> Option<SystemTime> {
    std::fs::metadata(p).and_then(|m| m.modified()).ok()
}

/// Watches the graph file and its plugin libraries until `done`: applies valid edits and
/// rebuilt plugins, reports rejected ones.
pub fn watch(path: PathBuf, live: Arc<Live>, done: Arc<AtomicBool>) {
    let mut seen = mtime(&path);
    while !done.load(Ordering::SeqCst) {
        std::thread::sleep(Duration::from_millis(200));
        match live.reload_changed_plugins() {
            None => {}
            Some(Ok(swapped)) if swapped.is_empty() => {
                eprintln!("{}: plugin rebuilt and reloaded: no running node uses it", path.display())
            }
            Some(Ok(swapped)) => {
                eprintln!("{}: plugin rebuilt and reloaded: swapped {}", path.display(), swapped.join(", "))
            }
            // Each names the graph file (and the `[[plugin]]` entry, when a library failed to load).
            Some(Err(e)) => eprintln!("{e}"),
        }
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
        // An edit may name other libraries: they are loaded (fresh copies) for this edit.
        let plugins = match skinflow_core::graph::plugin_paths(&src) {
            Ok(p) => p,
            Err(errs) => {
                for e in &errs.0 {
                    eprintln!("edit rejected: {e}");
                }
                continue;
            }
        };
        let parsed = {
            let mut kinds = live.lock_kinds();
            if plugins != kinds.paths() {
                match Kinds::load(&plugins, &src) {
                    Ok(k) => *kinds = k,
                    Err(e) => {
                        eprintln!("edit rejected: {e}");
                        continue;
                    }
                }
            }
            GraphSpec::parse(src, &kinds.registry)
        };
        match parsed {
            Err(errs) => {
                for e in &errs.0 {
                    eprintln!("edit rejected: {e}");
                }
            }
            Ok(new) => match live.apply_edit(&new) {
                Ok(applied) => eprintln!("{}: edit applied: {applied}", path.display()),
                Err(e) => eprintln!("{}: {e}", path.display()),
            },
        }
    }
}

/// The sensors of the graph agree (`skinflow_nodes::sensors::check_graph`), and no node writes
/// a file the graph reads or another node writes (`skinflow_nodes::outputs::check_files`), as
/// `check` and `run` check before starting: an edit or a swap that would image frames on
/// another sensor than theirs, apply a calibration of another sensor, or record over an input,
/// is refused, and the graph runs on. (A logger's `strategies` are not checked here: a swap may
/// rename a corrector's output, whose frames the logger then counts as discarded.)
/// The command's own output files (`extra`: `--stats-json`, `--control`) are checked against
/// the swapped graph's files too (`skinflow_nodes::outputs::check_extra_output`).
/// The graph as it runs now: `started` with each node's kind and params from `running`, and its
/// factory (the kind's ports and params, which the checks read) from `registry` when its kind
/// changed since the start or is one of `reloaded` (the kinds of a library loaded again); then
/// `swap` (node, factory, kind, params) applied, if any.
fn graph_now(
    started: &GraphSpec,
    running: &[NodeNow],
    registry: &Registry,
    reloaded: &[&String],
    swap: Option<(&str, &Arc<dyn NodeFactory>, &str, &Params)>,
) -> GraphSpec {
    let mut spec = started.clone();
    for (n, (id, kind, params)) in spec.nodes.iter_mut().zip(running) {
        if let Some((_, factory, kind, params)) = swap.filter(|(node, ..)| node == id) {
            n.factory = factory.clone();
            (n.kind, n.params) = (kind.to_owned(), params.clone());
            continue;
        }
        if (*kind != n.kind || reloaded.contains(&kind))
            && let Some(f) = registry.get(kind)
        {
            n.factory = f.clone();
        }
        (n.kind, n.params) = (kind.clone(), params.clone());
    }
    spec
}

fn check_swapped_graph(spec: &GraphSpec, extra: &[(&'static str, PathBuf)]) -> Result<(), String> {
    skinflow_nodes::sensors::check_graph(spec)
        .and_then(|()| skinflow_nodes::outputs::check_files(spec))
        .map_err(|errs| errs.0.iter().map(ToString::to_string).collect::<Vec<_>>().join("; "))?;
    for (what, path) in extra {
        skinflow_nodes::outputs::check_extra_output(spec, what, path)?;
    }
    Ok(())
}

/// Longest a `tare` or `control` request waits for the node to run the command.
const CONTROL_REPLY_TIMEOUT: Duration = Duration::from_secs(10);

fn reply(live: &Live, line: &str) -> Value {
    let handle = &live.handle;
    let req: Value = match serde_json::from_str(line) {
        Ok(v) => v,
        Err(e) => return json!({"ok": false, "error": format!("not JSON: {e}")}),
    };
    if let Err(e) = check_request(&req) {
        return json!({"ok": false, "error": e});
    }
    let s = |k: &str| req.get(k).and_then(Value::as_str);
    let result: Result<Value, String> = match s("cmd") {
        Some("stats") => match s("node") {
            None => serde_json::to_value(handle.stats()).map_err(|e| e.to_string()),
            Some(n) => match handle.stats().nodes.into_iter().find(|x| x.id == n) {
                Some(one) => serde_json::to_value(one).map(|v| json!({ "node": v })).map_err(|e| e.to_string()),
                None => Err(format!("no node \"{n}\" (nodes: {})", handle.node_ids().join(", "))),
            },
        },
        Some("tare") => match s("node") {
            Some(n) => {
                handle.control_wait(n, "tare", CONTROL_REPLY_TIMEOUT).map(|()| json!({})).map_err(|e| e.to_string())
            }
            None => Err("\"tare\" needs \"node\"".into()),
        },
        Some("control") => match (s("node"), s("command")) {
            (Some(n), Some(c)) => live.check_control(n, c).and_then(|()| {
                handle.control_wait(n, c, CONTROL_REPLY_TIMEOUT).map(|()| json!({})).map_err(|e| e.to_string())
            }),
            _ => Err("\"control\" needs \"node\" and \"command\"".into()),
        },
        Some("swap") => match (s("node"), s("kind")) {
            (Some(n), Some(k)) => {
                let factory = live.lock_kinds().registry.get(k).cloned();
                match factory {
                    None => Err(format!(
                        "unknown kind \"{k}\" (a plugin's kinds are those of the libraries the graph file names; \
                         `skinflow nodes --plugin LIB` lists a library's)"
                    )),
                    Some(f) => match swap_params(req.get("params")) {
                        Ok(t) => {
                            let params = Params::from_table(t);
                            live.check_swap(n, &f, k, &params)
                                .and_then(|()| live.swap(n, f, k, params))
                                .map(|()| json!({}))
                        }
                        Err(e) => Err(format!("params: {e}")),
                    },
                }
            }
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
        // One line: a params error from the TOML parser spans several (`in `factor``).
        Err(e) => {
            json!({"ok": false, "error": e.lines().map(str::trim).filter(|l| !l.is_empty()).collect::<Vec<_>>().join(" ")})
        }
    }
}

fn serve(stream: UnixStream, live: Arc<Live>) {
    let Ok(mut out) = stream.try_clone() else { return };
    for line in BufReader::new(stream).split(b'\n') {
        let Ok(bytes) = line else { return };
        // A line that is not UTF-8 gets its reply too, and the connection goes on.
        let r = match std::str::from_utf8(&bytes) {
            Ok(line) if line.trim().is_empty() => continue,
            Ok(line) => reply(&live, line),
            Err(e) => json!({"ok": false, "error": format!("not UTF-8 text: {e}")}),
        };
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
            // Replaced only when stale: a socket something still listens on is another run's,
            // whose commands (a stage script's `at` and `tare`) would come here instead.
            // Only a refused connection says nobody listens; any other failure (no permission)
            // leaves the socket alone.
            match UnixStream::connect(path) {
                Err(e) if e.kind() == std::io::ErrorKind::ConnectionRefused => {}
                Err(e) => bail!(
                    "{}: --control: cannot tell whether another process serves this socket ({e}); choose another path",
                    path.display()
                ),
                Ok(_) => bail!(
                    "{}: --control: another process serves this socket (a running graph's --control?); \
                     choose another path, or stop that run first",
                    path.display()
                ),
            }
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
    live: Arc<Live>,
    done: Arc<AtomicBool>,
) -> std::thread::JoinHandle<()> {
    let path = path.to_path_buf();
    std::thread::spawn(move || {
        while !done.load(Ordering::SeqCst) {
            match listener.accept() {
                Ok((s, _)) => {
                    let _ = s.set_nonblocking(false);
                    let live = Arc::clone(&live);
                    std::thread::spawn(move || serve(s, live));
                }
                Err(_) => std::thread::sleep(Duration::from_millis(50)),
            }
        }
        let _ = std::fs::remove_file(&path);
    })
}

/// The keys each command takes (`cmd` first); `params` is the only one that is no string.
const REQUEST_KEYS: [(&str, &[&str]); 4] = [
    ("stats", &["cmd", "node"]),
    ("tare", &["cmd", "node"]),
    ("control", &["cmd", "node", "command"]),
    ("swap", &["cmd", "node", "kind", "params"]),
];

/// Refuses a request that is no object, whose `cmd` is no string, or that has a key its command
/// does not take or a string key of another type: a misspelt `"parms"` had swapped a node to
/// its default params with `{"ok": true}`, and `"node": 123` had answered the whole graph's
/// statistics. An unknown `cmd` is left to the caller (which lists the commands).
fn check_request(req: &Value) -> Result<(), String> {
    let Some(obj) = req.as_object() else {
        return Err(format!("a request is a JSON object, e.g. {{\"cmd\": \"stats\"}} (got {req})"));
    };
    let cmd = match obj.get("cmd") {
        None => return Err("missing \"cmd\"".into()),
        Some(Value::String(c)) => c.as_str(),
        Some(other) => {
            return Err(format!("\"cmd\" must be a string, one of stats, tare, control, swap (got {other})"));
        }
    };
    let Some((_, keys)) = REQUEST_KEYS.iter().find(|(c, _)| *c == cmd) else { return Ok(()) };
    for (k, v) in obj {
        if !keys.contains(&k.as_str()) {
            return Err(format!("unknown key \"{k}\" (known for {cmd}: {})", keys.join(", ")));
        }
        if k != "params" && !v.is_string() {
            return Err(format!("\"{k}\" must be a string (got {v})"));
        }
    }
    Ok(())
}

/// A swap request's `params` as the TOML table a node's params are: a JSON object (absent:
/// none). What TOML cannot hold is named with where it is: a value that is not an object, a
/// `null` anywhere in it (TOML has no null: leave the key out for its default), or an integer
/// above TOML's largest (`i64::MAX`).
fn swap_params(params: Option<&Value>) -> Result<toml::Table, String> {
    fn unholdable(v: &Value, path: &str) -> Option<String> {
        match v {
            Value::Null => Some(format!("{path} is null, which TOML cannot hold: leave the key out for its default")),
            Value::Number(n) if n.as_u64().is_some_and(|u| u > i64::MAX as u64) => {
                Some(format!("{path} is {n}, above the largest integer TOML holds ({})", i64::MAX))
            }
            Value::Array(a) => a.iter().enumerate().find_map(|(i, x)| unholdable(x, &format!("{path}[{i}]"))),
            Value::Object(o) => o.iter().find_map(|(k, x)| unholdable(x, &format!("{path}.{k}"))),
            _ => None,
        }
    }
    let Some(params) = params else { return Ok(toml::Table::new()) };
    let kind = match params {
        Value::Object(_) => None,
        Value::Null => Some("null"),
        Value::Bool(_) => Some("a boolean"),
        Value::Number(_) => Some("a number"),
        Value::String(_) => Some("a string"),
        Value::Array(_) => Some("an array"),
    };
    if let Some(kind) = kind {
        return Err(format!("must be a JSON object of the kind's params, e.g. {{\"lambda\": 0.05}} (got {kind})"));
    }
    if let Some(problem) = unholdable(params, "params") {
        return Err(problem);
    }
    toml::Table::try_from(params.clone()).map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use serde::Deserialize;
    use skinflow_core::{BuildContext, KindInfo, NodeError, NodeImpl, NodeParams, ParamDoc, PortSpec, Role, typed};
    use skinflow_nodes::payload::Forces;
    use skinflow_plugin_sdk::export::OUTPUT_PATH;

    use super::*;

    #[derive(Deserialize)]
    struct OutParams {
        #[allow(dead_code)] // read by the graph checks through the params table
        out: Option<String>,
    }

    impl NodeParams for OutParams {}

    /// The built-in kinds and `p-out`, a stand-in plugin kind (never built) whose param `out`
    /// has type `out_type`.
    fn registry(out_type: &'static str) -> Registry {
        let mut r = skinflow_nodes::registry();
        r.register(typed(
            KindInfo::new("p-out", Role::Source, "a plugin's file")
                .output(PortSpec::output::<Forces>("forces", "forces"))
                .param(ParamDoc::new("out", out_type, "none", "a file")),
            |_: OutParams, _: &BuildContext| -> Result<NodeImpl, NodeError> { Err(NodeError::msg("not built")) },
        ))
        .unwrap();
        r
    }

    /// A socket a process listens on is another run's: refused; once nobody listens, stale.
    #[test]
    fn a_socket_another_process_serves_is_not_taken_over_and_a_stale_one_is_replaced() {
        let d = std::env::temp_dir().join(format!("skinflow-live-sock-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        let sock = d.join("c.sock");
        let serving = UnixListener::bind(&sock).unwrap();
        let e = bind_control_socket(&sock).unwrap_err().to_string();
        assert!(e.ends_with("--control: another process serves this socket (a running graph's --control?); choose another path, or stop that run first"), "{e}");
        assert!(UnixStream::connect(&sock).is_ok(), "still the first one's");
        drop(serving); // the file stays, nobody listens: stale
        let _mine = bind_control_socket(&sock).unwrap();
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn requests_with_unknown_keys_or_mistyped_ones_are_refused() {
        let refused = |v: Value| check_request(&v).unwrap_err();
        assert_eq!(
            refused(json!({"cmd": "swap", "node": "d", "kind": "scale", "parms": {"factor": 5}})),
            "unknown key \"parms\" (known for swap: cmd, node, kind, params)"
        );
        assert_eq!(
            refused(json!({"cmd": "tare", "node": "d", "comand": "x"})),
            "unknown key \"comand\" (known for tare: cmd, node)"
        );
        assert_eq!(refused(json!({"cmd": "stats", "node": 123})), "\"node\" must be a string (got 123)");
        assert_eq!(
            refused(json!({"cmd": 123})),
            "\"cmd\" must be a string, one of stats, tare, control, swap (got 123)"
        );
        assert_eq!(refused(json!([])), "a request is a JSON object, e.g. {\"cmd\": \"stats\"} (got [])");
        assert_eq!(refused(json!({})), "missing \"cmd\"");
        for ok in [
            json!({"cmd": "stats"}),
            json!({"cmd": "control", "node": "cell", "command": "at 1 2"}),
            json!({"cmd": "swap", "node": "d", "kind": "scale", "params": {"factor": 5}}),
            json!({"cmd": "reload"}),
        ] {
            assert_eq!(check_request(&ok), Ok(()), "{ok}");
        }
    }

    #[test]
    fn swap_params_name_what_toml_cannot_hold() {
        assert_eq!(swap_params(None).unwrap(), toml::Table::new());
        let t = swap_params(Some(&json!({"lambda": 0.05, "mesh": {"elements": 3000}}))).unwrap();
        assert_eq!(t["mesh"]["elements"].as_integer(), Some(3000));
        for (v, want) in [
            (json!(5), "must be a JSON object of the kind's params, e.g. {\"lambda\": 0.05} (got a number)"),
            (
                json!("lambda = 0.05"),
                "must be a JSON object of the kind's params, e.g. {\"lambda\": 0.05} (got a string)",
            ),
            (json!([1, 2]), "must be a JSON object of the kind's params, e.g. {\"lambda\": 0.05} (got an array)"),
            (
                json!({"mesh": {"elements": null}}),
                "params.mesh.elements is null, which TOML cannot hold: leave the key out for its default",
            ),
            (json!({"a": [1, null]}), "params.a[1] is null, which TOML cannot hold: leave the key out for its default"),
            (
                json!({"toy": {"by": u64::MAX}}),
                "params.toy.by is 18446744073709551615, above the largest integer TOML holds (9223372036854775807)",
            ),
        ] {
            assert_eq!(swap_params(Some(&v)).unwrap_err(), want, "{v}");
        }
    }

    /// A rebuilt library's kinds are checked with what they declare now: a param that was a
    /// string and now names a file the kind writes (here the graph's own file) is refused before
    /// any node is swapped; a kind of a library not reloaded keeps what it started with.
    #[test]
    fn a_reloaded_librarys_kinds_are_checked_with_their_new_params() {
        let base = std::env::temp_dir().join("skinflow-live-unit-nonexistent");
        let text = "[[node]]\nid = \"w\"\nkind = \"p-out\"\nparams = { out = \"g.toml\" }\n";
        let old = registry("string");
        let started = GraphSpec::parse(SourceFile::new(base.join("g.toml"), text.to_owned()), &old).unwrap();
        let running: Vec<NodeNow> =
            started.nodes.iter().map(|n| (n.id.clone(), n.kind.clone(), n.params.clone())).collect();
        check_swapped_graph(&graph_now(&started, &running, &old, &[], None), &[]).unwrap();
        let new = registry(OUTPUT_PATH);
        let kind = "p-out".to_owned();
        let e = check_swapped_graph(&graph_now(&started, &running, &new, &[&kind], None), &[]).unwrap_err();
        assert!(e.contains("node \"w\": param \"out\": writes ") && e.contains("this graph's own file"), "{e}");
        check_swapped_graph(&graph_now(&started, &running, &new, &[], None), &[]).unwrap();
    }
}
