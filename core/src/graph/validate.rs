//! Static checks of a graph file: syntax and schema, kinds and params, wiring, types, cycles.
//! Every error found is reported, each located in the file. Nothing here touches files or
//! devices named in params: input files are opened by [`GraphSpec::check_files`] and when
//! nodes are built, devices only when nodes are built.

use std::collections::HashMap;
use std::ops::Range;
use std::path::PathBuf;
use std::time::Duration;

use toml::Spanned;

use super::error::{GraphError, GraphErrorKind as K, GraphErrors};
use super::file::{
    AlignBy, GraphFile, LooseFile, LooseSections, LooseTable, NodeEntry, SECTIONS, ThreadMode, TriggerKind,
};
use super::source::SourceFile;
use super::{DEFAULT_CAPACITY, EdgeSpec, GraphSpec, MAX_CAPACITY, MAX_WORKERS, NodeSpec, Trigger, connected_inputs};
use crate::node::Mode;
use crate::params::Params;
use crate::registry::Wiring;
use crate::registry::{Registry, Role};

/// Most schema errors one file reports (each found by setting the sections at fault aside).
const MAX_SCHEMA_ERRORS: usize = 20;

/// The file read into its schema; or every schema error in it, in file order: after an
/// error, the section that holds it (a `[[node]]`, `[[edge]]`, `[graph]` or `[[plugin]]`
/// table, or a top-level key) is blanked out, keeping every other byte where it was, and the
/// rest of the file is read again. A file that is not TOML reports its first syntax error.
fn parse_file(src: &SourceFile) -> Result<GraphFile, GraphErrors> {
    let mut errors = Vec::new();
    let mut masked = src.clone();
    loop {
        let e = match skinflow_toml::from_str::<GraphFile>(&masked.text) {
            Ok(file) if errors.is_empty() => return Ok(file),
            Ok(_) => break,
            Err(e) => e,
        };
        errors.push(schema_error(&masked, &e));
        if errors.len() >= MAX_SCHEMA_ERRORS {
            break;
        }
        let Some(at) = e.span().map(|s| s.start) else { break };
        let Some(text) = blank_section_at(&masked.text, at) else { break };
        masked = SourceFile::new(src.path.clone(), text);
    }
    errors.sort_by_key(|e| (e.line, e.col));
    Err(GraphErrors(errors))
}

/// `text` with the section holding byte `at` turned into spaces (line ends kept, so every
/// other line and column stays where it was); `None` when `text` is not TOML, no section
/// holds `at`, or the result would not be TOML (then what follows could not be trusted).
fn blank_section_at(text: &str, at: usize) -> Option<String> {
    let file: LooseSections = toml::from_str(text).ok()?;
    let tables = file.graph.iter().chain(&file.plugin).chain(&file.node).chain(&file.edge);
    let mut range = tables.map(extent).find(|r| r.contains(&at));
    if range.is_none() {
        let top: LooseTable = toml::from_str(text).ok()?;
        range = top
            .iter()
            .filter(|(k, _)| !SECTIONS.contains(&k.get_ref().as_str()))
            .map(|(k, v)| k.span().start..v.span().end)
            .find(|r| r.contains(&at));
    }
    let range = range?;
    let mut out = String::with_capacity(text.len());
    for (i, c) in text.char_indices() {
        if range.contains(&i) && c != '\n' && c != '\r' {
            out.extend(std::iter::repeat_n(' ', c.len_utf8()));
        } else {
            out.push(c);
        }
    }
    toml::from_str::<toml::Table>(&out).ok().map(|_| out)
}

/// The error for a file that is not TOML or does not fit the schema. One inside a `[[node]]`
/// table names the node (or says why its id cannot) and the key whose value is wrong.
fn schema_error(src: &SourceFile, e: &toml::de::Error) -> GraphError {
    let cause = skinflow_toml::message(e).trim().to_owned();
    let span = e.span();
    let Some(at) = span.as_ref().map(|s| s.start) else {
        return GraphError::at(src, span, None, K::Syntax(cause));
    };
    let Some(table) = node_table_at(src, at) else {
        // Not TOML at all: name the `[[node]]` section the error is in from the text, and the
        // key a "duplicate key" error points at.
        let key = (cause == "duplicate key").then(|| key_at(&src.text, at)).flatten();
        // A value the loose reading refuses too (an integer beyond 64 bits) still has its key
        // path from the root: name it below the node.
        let (cause, named) = within_node(&cause);
        let key = if named { None } else { key };
        return match node_section_by_text(&src.text, at) {
            None => GraphError::at(src, span, None, K::Syntax(cause)),
            Some(Ok(id)) => GraphError::at(src, span, Some(&id), K::NodeField { key, cause }),
            Some(Err(problem)) => GraphError::at(src, span, None, K::UnnamedNode { problem, key, cause }),
        };
    };
    // skinflow-toml names the key path from the file's root (`node[1].cpu: ...`); the node is
    // named by its id here, so its `node[N]` goes, and a path left names the key itself.
    let (cause, named) = within_node(&cause);
    let key =
        if named { None } else { table.iter().find(|(_, v)| v.span().contains(&at)).map(|(k, _)| k.get_ref().clone()) };
    match node_name(&table) {
        Ok(id) => GraphError::at(src, span, Some(&id), K::NodeField { key, cause }),
        Err(problem) => GraphError::at(src, span, None, K::UnnamedNode { problem, key, cause }),
    }
}

/// `cause` without the `node[N]` that begins skinflow-toml's key path of an error in a
/// `[[node]]` table (and without `params.` before a param, named by its key alone as the
/// node's own param errors name it), and whether what is left of the path (`cpu: ...`,
/// `trigger.kind: ...`, `count: ...`) names the key.
fn within_node(cause: &str) -> (String, bool) {
    match skinflow_toml::split_path(cause) {
        (Some(path), rest) if path.starts_with("node[") => {
            let below = path.split_once(']').map_or("", |(_, below)| below).trim_start_matches('.');
            // A param is named by its key alone, as the node's own param errors name it.
            let below = below.strip_prefix("params.").unwrap_or(below);
            if below.is_empty() { (rest.to_owned(), false) } else { (format!("{below}: {rest}"), true) }
        }
        _ => (cause.to_owned(), false),
    }
}

/// The `[[node]]` table holding byte `at` of the file, if the file is valid TOML.
fn node_table_at(src: &SourceFile, at: usize) -> Option<LooseTable> {
    let file: LooseFile = toml::from_str(&src.text).ok()?;
    file.node.into_iter().find(|n| extent(n).contains(&at)).map(Spanned::into_inner)
}

/// The bytes a `[[node]]` table covers: its header (the span of the table itself) to its
/// last key or value.
fn extent(node: &Spanned<LooseTable>) -> Range<usize> {
    let parts = node.get_ref().iter().flat_map(|(k, v)| [k.span(), v.span()]);
    parts.fold(node.span(), |all, s| all.start.min(s.start)..all.end.max(s.end))
}

/// For a file that is not valid TOML: the id of the `[[node]]` section holding byte `at`, read
/// from the section's `id = "..."` line (or why it cannot name it); `None` outside a node.
fn node_section_by_text(text: &str, at: usize) -> Option<Result<String, String>> {
    let header = |line: &str| line.trim_start().starts_with('[');
    let before = &text[..at.min(text.len())];
    let start =
        before.rfind("[[node]]").filter(|&h| before[..h].rsplit('\n').next().is_some_and(|l| l.trim().is_empty()))?;
    let section = &text[start + "[[node]]".len()..];
    let section_end = section.find('\n').map_or(section.len(), |first| {
        let body = &section[first + 1..];
        first + 1 + body.split_inclusive('\n').take_while(|l| !header(l)).map(str::len).sum::<usize>()
    });
    // Another table header between the node's and `at`: the error is not in this node.
    if at > start + "[[node]]".len() + section_end {
        return None;
    }
    let id_line = section[..section_end].lines().find(|l| {
        let l = l.trim_start();
        l.strip_prefix("id").is_some_and(|rest| rest.trim_start().starts_with('='))
    });
    let Some(line) = id_line else { return Some(Err("without an id".into())) };
    let id = toml::from_str::<toml::Table>(line).ok().and_then(|t| t.get("id").cloned());
    Some(match id {
        Some(toml::Value::String(id)) if valid_id(&id) => Ok(id),
        Some(toml::Value::String(id)) => Err(format!("with an invalid id \"{id}\"")),
        _ => Err("whose id line cannot be read".into()),
    })
}

/// The bare or quoted key starting at byte `at`, if there is one.
fn key_at(text: &str, at: usize) -> Option<String> {
    let rest = text.get(at..)?;
    let key: String = match rest.strip_prefix('"') {
        Some(quoted) => quoted.split('"').next()?.to_owned(),
        None => rest.chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_' || *c == '-').collect(),
    };
    (!key.is_empty()).then_some(key)
}

/// The id that names a `[[node]]` table, or why it cannot.
fn node_name(table: &LooseTable) -> Result<String, String> {
    match table.iter().find(|(k, _)| k.get_ref() == "id").map(|(_, v)| v.get_ref()) {
        None => Err("without an id".into()),
        Some(toml::Value::String(id)) if valid_id(id) => Ok(id.clone()),
        Some(toml::Value::String(id)) => Err(format!("with an invalid id \"{id}\"")),
        Some(other) => Err(format!("with an id that is not a string ({other})")),
    }
}

/// The byte span of each `[[node]]` table, in file order (empty if the file is not TOML).
pub(super) fn node_spans(src: &SourceFile) -> Vec<Range<usize>> {
    toml::from_str::<LooseFile>(&src.text).map_or_else(|_| Vec::new(), |f| f.node.iter().map(Spanned::span).collect())
}

pub(super) fn plugin_paths(src: &SourceFile) -> Result<Vec<PathBuf>, GraphErrors> {
    Ok(plugin_entries(src)?.into_iter().map(|(path, _)| path).collect())
}

/// Each `[[plugin]] path`, resolved against the graph file's directory, with the byte span of
/// its value.
pub(super) fn plugin_entries(src: &SourceFile) -> Result<Vec<(PathBuf, Range<usize>)>, GraphErrors> {
    let file = parse_file(src)?;
    let base = src.base_dir();
    Ok(file.plugin.iter().map(|p| (base.join(p.path.get_ref()), p.path.span())).collect())
}

/// A node id is a bare TOML key: letters, digits, `_` and `-`.
fn valid_id(id: &str) -> bool {
    skinflow_toml::is_bare_key(id)
}

pub(super) fn validate(src: SourceFile, registry: &Registry) -> Result<GraphSpec, GraphErrors> {
    let file = parse_file(&src)?;
    let mut errs: Vec<GraphError> = Vec::new();
    let mut err =
        |span: Option<Range<usize>>, node: Option<&str>, kind: K| errs.push(GraphError::at(&src, span, node, kind));

    // Nodes: ids, kinds, params, trigger options.
    let mut nodes: Vec<Option<NodeSpec>> = Vec::with_capacity(file.node.len());
    // Per `[[node]]` table, in order: whether its kind is known and its params passed its check.
    let mut params_ok: Vec<bool> = Vec::with_capacity(file.node.len());
    let mut by_id: HashMap<String, usize> = HashMap::new();
    for (i, entry) in file.node.iter().enumerate() {
        let n: &NodeEntry = entry.get_ref();
        let id = n.id.get_ref().clone();
        if !valid_id(&id) {
            err(Some(n.id.span()), None, K::BadId(id.clone()));
        } else if let Some(&first) = by_id.get(&id) {
            let (line, _) = src.line_col(file.node[first].get_ref().id.span().start);
            err(Some(n.id.span()), None, K::DuplicateId(id.clone(), line));
        } else {
            by_id.insert(id.clone(), i);
        }
        let Some(factory) = registry.get(n.kind.get_ref()) else {
            let known = registry.names().collect::<Vec<_>>().join(", ");
            err(Some(n.kind.span()), Some(&id), K::UnknownKind { kind: n.kind.get_ref().clone(), known });
            nodes.push(None);
            params_ok.push(false);
            continue;
        };
        let params = Params::in_graph(src.text.clone(), i, n.params.clone().unwrap_or_default());
        let checked = factory.check(&params).and_then(|()| params.locate(factory.info().no_empty_paths(&params)));
        if let Err(e) = &checked {
            err(e.span.clone().or(Some(entry.span())), Some(&id), K::Param(e.to_string()));
        }
        params_ok.push(checked.is_ok());
        let role = factory.info().role;
        let trigger = match trigger_of(n) {
            Ok(t) => t,
            Err((span, msg)) => {
                err(span.or(Some(entry.span())), Some(&id), K::Option(msg));
                Trigger::Any
            }
        };
        if role == Role::Source && n.trigger != TriggerKind::Any {
            err(Some(entry.span()), Some(&id), K::Option("a source has no trigger: it runs on its own thread".into()));
        }
        let placement = match file.graph.mode {
            Mode::Lockstep => lockstep_errors(n),
            Mode::Realtime => placement_error(n, role).into_iter().collect(),
        };
        for (span, msg) in option_errors(n).into_iter().chain(placement) {
            err(Some(span), Some(&id), K::Option(msg));
        }
        nodes.push(Some(NodeSpec {
            id,
            kind: n.kind.get_ref().clone(),
            factory: factory.clone(),
            params,
            trigger,
            deadline_us: n.deadline_us.as_ref().map(|d| *d.get_ref()),
            cpu: n.cpu.as_ref().map(|c| *c.get_ref()),
            rt_priority: n.rt_priority.as_ref().map(|p| *p.get_ref()),
            restart: n.restart,
            thread: n.thread.as_ref().map_or_else(ThreadMode::default, |t| *t.get_ref()),
        }));
    }

    // Edges: endpoints, ports, types, capacities, single inputs.
    let mut edges: Vec<EdgeSpec> = Vec::new();
    // Where each of `edges` is written: the span of its `from`.
    let mut edge_spans: Vec<Range<usize>> = Vec::new();
    let mut first_into: HashMap<(usize, usize), String> = HashMap::new();
    let mut attempted: Vec<(usize, String)> = Vec::new();
    for e in &file.edge {
        let ed = e.get_ref();
        let from = resolve(&ed.from, "from", &by_id, &nodes, &mut err);
        let to = resolve(&ed.to, "to", &by_id, &nodes, &mut err);
        let (from_ok, to_ok) = (from.as_ref().map(|_| ()), to.clone());
        let capacity = ed.capacity.as_ref().map_or(DEFAULT_CAPACITY, |c| *c.get_ref());
        if capacity == 0 {
            let span = ed.capacity.as_ref().map(|c| c.span());
            err(span, None, K::Option("edge capacity must be >= 1 (got 0)".into()));
        } else if capacity > MAX_CAPACITY {
            let span = ed.capacity.as_ref().map(|c| c.span());
            err(
                span,
                None,
                K::Option(format!(
                    "edge capacity must be <= {MAX_CAPACITY} messages (got {capacity}): every slot is allocated \
                     when the graph starts"
                )),
            );
        }
        let (Some((fnode, fport_name)), Some((tnode, tport_name))) = (from, to) else {
            // An input whose edge failed for another reason (reported above) is not also
            // "unconnected": one mistake, one error.
            if let (None, Some((tnode, tport))) = (from_ok, &to_ok) {
                attempted.push((*tnode, tport.clone()));
            }
            continue;
        };
        let (Some(fspec), Some(tspec)) = (&nodes[fnode], &nodes[tnode]) else { continue };
        let finfo = fspec.factory.info();
        let tinfo = tspec.factory.info();
        let fport = finfo.output_index(&fport_name);
        let tport = tinfo.input_index(&tport_name);
        if fport.is_none() {
            let known = finfo.outputs.iter().map(|p| p.name.as_ref()).collect::<Vec<_>>().join(", ");
            err(
                Some(ed.from.span()),
                None,
                K::UnknownPort {
                    node: fspec.id.clone(),
                    kind: fspec.kind.clone(),
                    dir: "output",
                    port: fport_name.clone(),
                    known: if known.is_empty() { "none".into() } else { known },
                },
            );
        }
        if tport.is_none() {
            let known = tinfo.inputs.iter().map(|p| p.name.as_ref()).collect::<Vec<_>>().join(", ");
            err(
                Some(ed.to.span()),
                None,
                K::UnknownPort {
                    node: tspec.id.clone(),
                    kind: tspec.kind.clone(),
                    dir: "input",
                    port: tport_name.clone(),
                    known: if known.is_empty() { "none".into() } else { known },
                },
            );
        }
        let (Some(fport), Some(tport)) = (fport, tport) else { continue };
        if let Some(first) =
            edges.iter().position(|x| (x.from_node, x.from_port, x.to_node, x.to_port) == (fnode, fport, tnode, tport))
        {
            // One mistake, one error: the copy is neither type-checked nor a second edge.
            let (first_line, _) = src.line_col(edge_spans[first].start);
            let (line, _) = src.line_col(ed.from.span().start);
            let (from, to) = (ed.from.get_ref().clone(), ed.to.get_ref().clone());
            err(Some(ed.from.span()), None, K::DuplicateEdge { from, to, first_line, line });
            continue;
        }
        let (fp, tp) = (&finfo.outputs[fport], &tinfo.inputs[tport]);
        if !tp.accepts(&fp.ty) {
            err(
                Some(ed.to.span()),
                None,
                K::TypeMismatch {
                    from: ed.from.get_ref().clone(),
                    from_ty: fp.ty.to_string(),
                    to: ed.to.get_ref().clone(),
                    to_ty: tp.ty.to_string(),
                },
            );
        }
        if !tp.multi {
            if let Some(first) = first_into.get(&(tnode, tport)) {
                err(
                    Some(ed.to.span()),
                    None,
                    K::SecondEdge {
                        to: ed.to.get_ref().clone(),
                        from: ed.from.get_ref().clone(),
                        first: first.clone(),
                    },
                );
            } else {
                first_into.insert((tnode, tport), ed.from.get_ref().clone());
            }
        }
        edges.push(EdgeSpec {
            from_node: fnode,
            from_port: fport,
            to_node: tnode,
            to_port: tport,
            capacity: capacity.max(1),
            policy: ed.policy,
            from: ed.from.get_ref().clone(),
            to: ed.to.get_ref().clone(),
        });
        edge_spans.push(ed.from.span());
    }

    // Required inputs.
    for (i, n) in nodes.iter().enumerate() {
        let Some(n) = n else { continue };
        for (p, port) in n.factory.info().inputs.iter().enumerate() {
            let tried = attempted.iter().any(|(t, name)| *t == i && *name == port.name);
            if port.required && !tried && !edges.iter().any(|e| e.to_node == i && e.to_port == p) {
                err(
                    Some(file.node[i].get_ref().id.span()),
                    Some(&n.id),
                    K::Unconnected(format!("{}.{}", n.id, port.name)),
                );
            }
        }
    }

    // Params that depend on which inputs are connected (once the params themselves passed).
    for (i, n) in nodes.iter().enumerate() {
        let Some(n) = n else { continue };
        let connected = connected_inputs(&n.factory.info().inputs, i, &edges);
        if params_ok[i]
            && let Err(e) = n.factory.check_wiring(&n.params, &Wiring::new(&connected))
        {
            err(e.span.clone().or(Some(file.node[i].span())), Some(&n.id), K::Param(e.to_string()));
        }
    }

    // Cycles: Kahn's algorithm (ties broken by file order so `topo` is deterministic) leaves
    // the nodes on or downstream of a cycle; one cycle among them is reported.
    let topo = topo_order(nodes.len(), &edges);
    if topo.len() < nodes.len() {
        let cycle = find_cycle(nodes.len(), &edges).expect("Kahn's algorithm stopped, so there is a cycle");
        let last = *cycle.last().expect("a cycle has an edge");
        let mut path: Vec<&str> =
            cycle.iter().map(|&k| file.node[edges[k].from_node].get_ref().id.get_ref().as_str()).collect();
        path.push(path[0]);
        let (from, to) = (edges[last].from.clone(), edges[last].to.clone());
        err(Some(edge_spans[last].clone()), None, K::Cycle { path: path.join(" -> "), from, to });
    }

    if file.node.is_empty() {
        err(None, None, K::NoNodes);
    }
    if let (Mode::Lockstep, Some(w)) = (file.graph.mode, &file.graph.workers) {
        err(Some(w.span()), None, K::Option(lockstep_ignores("workers")));
    } else if let Some(w) = file.graph.workers.as_ref().filter(|w| *w.get_ref() > MAX_WORKERS) {
        err(
            Some(w.span()),
            None,
            K::Option(format!("[graph] workers must be <= {MAX_WORKERS} (got {}); 0 is one per core", w.get_ref())),
        );
    }

    if !errs.is_empty() {
        errs.sort_by_key(|e| (e.line, e.col)); // stable: same place keeps discovery order
        return Err(GraphErrors(errs));
    }
    let base = src.base_dir();
    Ok(GraphSpec {
        name: file
            .graph
            .name
            .clone()
            .unwrap_or_else(|| src.path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default()),
        mode: file.graph.mode,
        workers: file.graph.workers.as_ref().map_or(0, |w| *w.get_ref()),
        plugins: file.plugin.iter().map(|p| base.join(p.path.get_ref())).collect(),
        nodes: nodes.into_iter().map(|n| n.expect("errors were reported for missing nodes")).collect(),
        edges,
        topo,
        source: src,
    })
}

/// Range errors of `deadline_us` and `rt_priority`.
fn option_errors(n: &NodeEntry) -> Vec<(Range<usize>, String)> {
    let mut out = Vec::new();
    if let Some(d) = &n.deadline_us
        && !(d.get_ref().is_finite() && *d.get_ref() > 0.0)
    {
        out.push((d.span(), format!("deadline_us must be finite and > 0 (got {})", d.get_ref())));
    }
    if let Some(p) = &n.rt_priority
        && !(1..=99).contains(p.get_ref())
    {
        out.push((p.span(), format!("rt_priority must be in 1..=99 (got {})", p.get_ref())));
    }
    out
}

/// `thread = "pool"` on a source, or on a processor or sink that also sets `rt_priority` or
/// `cpu`: the runtime gives such a node a thread of its own anyway (a source always; see
/// `RunningGraph::start`), so the pool request would be silently ignored.
fn placement_error(n: &NodeEntry, role: Role) -> Option<(Range<usize>, String)> {
    let thread = n.thread.as_ref().filter(|t| *t.get_ref() == ThreadMode::Pool)?;
    if role == Role::Source {
        return Some((
            thread.span(),
            "a source always runs on a thread of its own (it waits on its device or clock), not on \
             the shared pool: leave thread out, or set thread = \"dedicated\""
                .to_owned(),
        ));
    }
    let option = if n.rt_priority.is_some() {
        "rt_priority"
    } else if n.cpu.is_some() {
        "cpu"
    } else {
        return None;
    };
    Some((
        thread.span(),
        format!(
            "{option} applies only to a thread of its own, not to the shared pool: \
             set thread = \"dedicated\" (or leave thread out), or remove {option}"
        ),
    ))
}

/// `cpu`, `rt_priority` or `thread` in a `mode = "lockstep"` graph: lockstep runs every node
/// on the calling thread, so they would be silently ignored.
fn lockstep_errors(n: &NodeEntry) -> Vec<(Range<usize>, String)> {
    let mut out = Vec::new();
    if let Some(c) = &n.cpu {
        out.push((c.span(), lockstep_ignores("cpu")));
    }
    if let Some(p) = &n.rt_priority {
        out.push((p.span(), lockstep_ignores("rt_priority")));
    }
    if let Some(t) = &n.thread {
        out.push((t.span(), lockstep_ignores("thread")));
    }
    out
}

fn lockstep_ignores(option: &str) -> String {
    format!(
        "{option} is ignored in mode = \"lockstep\" (every node runs on the calling thread): \
         remove it, or set mode = \"realtime\" in [graph]"
    )
}

fn trigger_of(n: &NodeEntry) -> Result<Trigger, (Option<Range<usize>>, String)> {
    let misplaced = |what: &str, span: Range<usize>, t: &str| {
        Err((Some(span), format!("{what} applies only to trigger = \"{t}\"")))
    };
    match n.trigger {
        TriggerKind::Any => {
            if let Some(a) = &n.align {
                return misplaced("align", a.span(), "aligned");
            }
            if let Some(w) = &n.align_window_us {
                return misplaced("align_window_us", w.span(), "aligned");
            }
            if let Some(p) = &n.period_ms {
                return misplaced("period_ms", p.span(), "periodic");
            }
            Ok(Trigger::Any)
        }
        TriggerKind::Aligned => {
            if let Some(p) = &n.period_ms {
                return misplaced("period_ms", p.span(), "periodic");
            }
            match (
                n.align
                    .as_ref()
                    .map_or(if n.align_window_us.is_some() { AlignBy::Time } else { AlignBy::Seq }, |a| *a.get_ref()),
                &n.align_window_us,
            ) {
                (AlignBy::Seq, None) => Ok(Trigger::AlignedSeq),
                (AlignBy::Seq, Some(w)) => Err((Some(w.span()), "align_window_us needs align = \"time\"".into())),
                (AlignBy::Time, None) => Err((None, "align = \"time\" needs align_window_us".into())),
                (AlignBy::Time, Some(w)) => {
                    let us = *w.get_ref();
                    if us.is_finite() && us >= 0.0 {
                        Ok(Trigger::AlignedWindow { window_ns: (us * 1e3) as u64 })
                    } else {
                        Err((Some(w.span()), format!("align_window_us must be finite and >= 0 (got {us})")))
                    }
                }
            }
        }
        TriggerKind::Periodic => {
            if let Some(a) = &n.align {
                return misplaced("align", a.span(), "aligned");
            }
            if let Some(w) = &n.align_window_us {
                return misplaced("align_window_us", w.span(), "aligned");
            }
            match &n.period_ms {
                None => Err((None, "trigger = \"periodic\" needs period_ms".into())),
                Some(p) if (super::MIN_PERIOD_MS..=super::MAX_PERIOD_MS).contains(p.get_ref()) => {
                    Ok(Trigger::Periodic { period: Duration::from_secs_f64(*p.get_ref() / 1e3) })
                }
                Some(p) => Err((
                    Some(p.span()),
                    format!(
                        "period_ms must be at least {} ms (the shortest period the timer keeps) and at most {} ms \
                         (one day); got {}",
                        super::MIN_PERIOD_MS,
                        super::MAX_PERIOD_MS,
                        // Huge values in exponent form, not 300 digits.
                        if p.get_ref().abs() >= 1e15 { format!("{:e}", p.get_ref()) } else { p.get_ref().to_string() }
                    ),
                )),
            }
        }
    }
}

fn resolve(
    r: &toml::Spanned<String>,
    end: &'static str,
    by_id: &HashMap<String, usize>,
    nodes: &[Option<NodeSpec>],
    err: &mut impl FnMut(Option<Range<usize>>, Option<&str>, K),
) -> Option<(usize, String)> {
    let Some((node, port)) = r.get_ref().split_once('.') else {
        err(Some(r.span()), None, K::BadPortRef(r.get_ref().clone()));
        return None;
    };
    if port.is_empty() || node.is_empty() {
        err(Some(r.span()), None, K::BadPortRef(r.get_ref().clone()));
        return None;
    }
    match by_id.get(node) {
        Some(&i) if nodes[i].is_some() => Some((i, port.to_owned())),
        Some(_) => None, // the node's own error (unknown kind) was reported
        None => {
            err(Some(r.span()), None, K::UnknownNode { end, node: node.to_owned() });
            None
        }
    }
}

/// The edges (indices into `edges`) of one cycle, in order, the closing edge last: the first
/// back edge of a depth-first search that visits nodes and their out-edges in file order.
fn find_cycle(n: usize, edges: &[EdgeSpec]) -> Option<Vec<usize>> {
    #[derive(Clone, Copy, PartialEq)]
    enum Mark {
        New,
        OnPath,
        Done,
    }
    // A node's out-edges, last first, so that popping follows them in file order.
    let out = |node: usize| -> Vec<usize> { (0..edges.len()).rev().filter(|&k| edges[k].from_node == node).collect() };
    let mut mark = vec![Mark::New; n];
    for root in 0..n {
        if mark[root] != Mark::New {
            continue;
        }
        // The path from `root`: per node on it, the edge it was entered by (none for `root`)
        // and its out-edges still to follow.
        mark[root] = Mark::OnPath;
        let mut path: Vec<(Option<usize>, Vec<usize>)> = vec![(None, out(root))];
        while let Some((_, todo)) = path.last_mut() {
            let Some(k) = todo.pop() else {
                let (into, _) = path.pop().expect("the path is not empty");
                let node = into.map_or(root, |k| edges[k].to_node);
                mark[node] = Mark::Done;
                continue;
            };
            let next = edges[k].to_node;
            match mark[next] {
                Mark::Done => {}
                Mark::New => {
                    mark[next] = Mark::OnPath;
                    path.push((Some(k), out(next)));
                }
                Mark::OnPath => {
                    // The cycle runs from `next` along the path back to this edge.
                    let on_path: Vec<usize> = path.iter().filter_map(|(into, _)| *into).collect();
                    let start = on_path.iter().position(|&e| edges[e].from_node == next).unwrap_or(on_path.len());
                    let mut cycle = on_path[start..].to_vec();
                    cycle.push(k);
                    return Some(cycle);
                }
            }
        }
    }
    None
}

/// Kahn's algorithm; among ready nodes the lowest index goes first.
pub(crate) fn topo_order(n: usize, edges: &[EdgeSpec]) -> Vec<usize> {
    let mut indeg = vec![0usize; n];
    for e in edges {
        indeg[e.to_node] += 1;
    }
    let mut out = Vec::with_capacity(n);
    let mut done = vec![false; n];
    while let Some(next) = (0..n).find(|&i| !done[i] && indeg[i] == 0) {
        done[next] = true;
        out.push(next);
        for e in edges.iter().filter(|e| e.from_node == next) {
            indeg[e.to_node] -= 1;
        }
    }
    out
}
