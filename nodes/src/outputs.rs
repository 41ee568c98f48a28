//! The files a graph writes, against the files it reads, and the force strategies its loggers
//! list, against those that can reach them: for `skinflow check`, for `skinflow run` before
//! any node starts (after `GraphSpec::check_files` and `sensors::check_graph`), and for hot
//! swaps ([`check_graph`]; [`check_files`] and [`check_strategies`] apart).
//!
//! [`check_files`] refuses an output file of a node (an `hdf5_logger`'s `path`, a `compare`'s
//! `json`, a `collect`'s `path`, a plugin kind's `output-path`-typed param) that is the same
//! file as
//!
//! - the graph file itself, or a `[[plugin]]` library it loads;
//! - a file a node reads: a `replay` recording, a `sim` scene, a `corrector`'s or `splitter`'s
//!   calibration, a `reconstructor`'s or `hdf5_logger`'s sensor file, a serial device, a plugin
//!   kind's `input-path`- or `sensor`-typed param, and any `path`-typed param of a plugin kind (which may
//!   read or write it: an output over it loses either way);
//! - another node's output file (a plugin's `output-path` included).
//!
//! Whether `overwrite` is set or not: the run would replace an input, or two writers would
//! replace each other's rows. Paths are resolved against the graph file's directory (as the
//! nodes resolve them) and compared as files: an existing one canonicalized (links followed,
//! and on Unix a hard link to the same file is the same file), one that does not exist yet by
//! its canonicalized existing directory and the rest of its path normalized (`.` and `..`).
//! A logger that rotates (`rotate_mb` / `rotate_s`) writes `name-0001.h5`, `name-0002.h5`, ...
//! beside `name.h5` as given (in its directory, canonicalized: not beside the file a link
//! `name.h5` leads to): a file of that pattern there counts as its output too (one that exists
//! as a link is replaced, not written through). Each conflict is an error located at the writer's param (the
//! later writer's, for two writers), naming both nodes and files. A plugin param's type (`skinflow_plugin_sdk::export::PARAM_TYPES`) says what the
//! kind does with its file: `output-path` writes it, `input-path` reads it, `path` may do
//! either (not known here), so two `path` params, or a `path` and an `input-path`, naming one
//! file are not refused (two readers are fine); an array of one of them (`[output-path]`)
//! names a file with each string. A reconstructor's `cache_dir` is a directory of cache files
//! and is not compared.
//!
//! [`check_extra_output`] refuses an output file given outside the graph (a command-line
//! option such as `skinflow run --stats-json`) that is the same file as any file the graph
//! names (read, written, or either), the graph file and its plugin libraries included.
//!
//! [`check_strategies`] refuses a name in an `hdf5_logger`'s `strategies` that no node
//! upstream of its `forces` input produces (a typo logs nothing of the strategy meant). The
//! names are derived as the `corrector` node names its output: its `name`, else its strategy,
//! suffixed with `-<splitter strategy>` for a pneumatic strategy fed by a splitter that is not
//! `proportional`. When a `forces` edge comes from anything else than a built-in corrector (a
//! plugin corrector), or a corrector's `split` edge from anything else than a built-in
//! splitter (a plugin splitter, whose strategy name is its own), the names that arrive are not
//! known here and the logger's list is not checked.

use std::collections::BTreeSet;
use std::ops::Range;
use std::path::{Component, Path, PathBuf};

use skinflow_contact::StrategyKind;
use skinflow_core::BuildContext;
use skinflow_core::graph::{GraphError, GraphErrors, GraphSpec, plugin_paths};
use skinflow_plugin_sdk::export::{INPUT_PATH, OUTPUT_PATH, PATH, SENSOR};

use crate::correct::{CorrectorParams, name_follows_split, output_name};
use crate::log::LoggerParams;
use crate::sensors::param_error_at;
use crate::split::{SplitStrategy, SplitterParams};

/// [`check_files`] and [`check_strategies`]: every error of both, in file order.
pub fn check_graph(spec: &GraphSpec) -> Result<(), GraphErrors> {
    let mut errs = Vec::new();
    for r in [check_files(spec), check_strategies(spec)] {
        if let Err(GraphErrors(e)) = r {
            errs.extend(e);
        }
    }
    finish(errs)
}

fn finish(mut errs: Vec<GraphError>) -> Result<(), GraphErrors> {
    if errs.is_empty() {
        return Ok(());
    }
    errs.sort_by_key(|e| (e.line, e.col)); // stable: one place keeps the order found
    Err(GraphErrors(errs))
}

/// What a node does with the file a `path`-, `input-path`- or `output-path`-typed param names.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Use {
    /// Writes it (replacing what is there, or appending to it).
    Writes,
    /// Reads it.
    Reads,
    /// A plugin's `path`: reads or writes it, not known here.
    Names,
    /// A directory of its own files (a reconstructor's `cache_dir`): not compared.
    Directory,
}

/// What a built-in kind does with its `path`-typed param; `None` for a kind or param not
/// listed (a plugin's).
fn builtin_use(kind: &str, param: &str) -> Option<Use> {
    Some(match (kind, param) {
        ("hdf5_logger", "path") | ("compare", "json") | ("collect", "path") => Use::Writes,
        ("replay", "path")
        | ("sim", "scene")
        | ("corrector" | "splitter", "calibration")
        | ("reconstructor" | "hdf5_logger", "sensor")
        | ("serial_eit" | "serial_pressure" | "serial_loadcell", "port") => Use::Reads,
        ("reconstructor", "cache_dir") => Use::Directory,
        _ => return None,
    })
}

/// What a node of kind `kind` does with the file its param `param` of type `ty` names: a
/// built-in kind's as [`builtin_use`] lists it, else as the type says (`output-path` writes,
/// `input-path` and `sensor` read, `path` either; an array `[T]` as `T`); `None` for a param
/// that names no file.
fn param_use(kind: &str, param: &str, ty: &str) -> Option<Use> {
    let scalar = ty.strip_prefix('[').and_then(|t| t.strip_suffix(']')).unwrap_or(ty);
    let by_type = match scalar {
        OUTPUT_PATH => Use::Writes,
        INPUT_PATH | SENSOR => Use::Reads,
        PATH => Use::Names,
        _ => return None,
    };
    Some(builtin_use(kind, param).unwrap_or(by_type))
}

/// The file names a param of type `ty` holds in `value`: a string, or for an array type
/// (`[output-path]`) the strings of an array; empty ones left out (unset).
fn file_names<'a>(ty: &str, value: &'a toml::Value) -> Vec<&'a str> {
    let names = match value {
        toml::Value::String(s) => vec![s.as_str()],
        toml::Value::Array(a) if ty.starts_with('[') => a.iter().filter_map(toml::Value::as_str).collect(),
        _ => Vec::new(),
    };
    names.into_iter().filter(|s| !s.is_empty()).collect()
}

/// What the kind of a file a node reads is called in an error.
fn what_is_read(kind: &str, param: &str) -> &'static str {
    match (kind, param) {
        ("replay", _) => "recording",
        ("sim", _) => "scene",
        (_, "calibration") => "calibration",
        (_, "sensor") => "sensor file",
        (_, "port") => "serial device",
        _ => "file",
    }
}

/// One file a graph names, as the node resolves it and as a file identity.
struct Named {
    /// The node (`None`: the graph file or a plugin library).
    node: Option<usize>,
    param: String,
    resolved: PathBuf,
    id: FileId,
    use_: Use,
    /// A logger that rotates: the parts it writes (beside `resolved`, as given).
    parts: Option<Parts>,
}

/// A file's identity: its normalized absolute path (see [`file_id`]) and, for an existing
/// file on Unix, its device and inode.
#[derive(Debug, Clone, PartialEq, Eq)]
struct FileId {
    path: PathBuf,
    inode: Option<(u64, u64)>,
}

impl FileId {
    fn same(&self, other: &FileId) -> bool {
        self.path == other.path || (self.inode.is_some() && self.inode == other.inode)
    }
}

/// The rotated parts a logger writes, `stem-NNNN.ext` (at least four digits), as
/// `skinflow_record::rotate::part_path` makes them: beside its path as given, named after the
/// given file name. A link there is not followed (if `rec.h5` leads to `other/x.h5`, the parts
/// are `rec-0001.h5`, ... beside the link, not `other/x-0001.h5`); the directory is
/// canonicalized as [`file_id`] does.
#[derive(Debug)]
struct Parts {
    /// The given path's directory, as [`file_id`] identifies it.
    dir: PathBuf,
    /// The given file name's stem and extension (converted as `part_path` converts them).
    stem: String,
    ext: Option<String>,
}

impl Parts {
    /// The parts a logger rotating over `given` writes; `None` for a path naming no file
    /// (ending in `..`, or a root).
    fn of(given: &Path) -> Option<Parts> {
        let abs = std::path::absolute(given).unwrap_or_else(|_| given.to_path_buf());
        let name = Path::new(abs.file_name()?);
        let dir = file_id(abs.parent()?).path;
        let stem = name.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        let ext = name.extension().map(|e| e.to_string_lossy().into_owned());
        Some(Parts { dir, stem, ext })
    }

    /// Whether `f` is one of the parts: a file of the pattern in [`Parts::dir`]. A part that
    /// exists as a link is replaced, never written through (the writer renames its finished
    /// file over the name, or refuses without `overwrite`), so where it leads is no part.
    fn includes(&self, f: &FileId) -> bool {
        self.is_part_name(&f.path)
    }

    /// Whether `p` is `dir/stem-NNNN.ext` (at least four digits).
    fn is_part_name(&self, p: &Path) -> bool {
        let (Some(dir), Some(name)) = (p.parent(), p.file_name().and_then(|n| n.to_str())) else {
            return false;
        };
        if dir != self.dir {
            return false;
        }
        let rest = match &self.ext {
            Some(ext) => name.strip_suffix(ext.as_str()).and_then(|n| n.strip_suffix('.')),
            None => Some(name),
        };
        let digits = rest.and_then(|r| r.strip_prefix(self.stem.as_str())).and_then(|r| r.strip_prefix('-'));
        digits.is_some_and(|d| d.len() >= 4 && d.bytes().all(|b| b.is_ascii_digit()))
    }
}

/// The identity of `p`: absolute, with each existing prefix canonicalized (links followed) and
/// the part that does not exist yet normalized lexically (`.` dropped, `..` taking off the
/// component before it). A link leading where nothing is yet (a dangling one) is followed too:
/// its target, relative to the link's directory, is where a writer through it creates the file.
fn file_id(p: &Path) -> FileId {
    let abs = std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
    let path = resolved(&abs, MAX_LINKS);
    FileId { inode: inode(&path), path }
}

/// Dangling links [`file_id`] follows in a row, at most (as the kernel's limit on links in a
/// path): beyond, a loop of links say, the rest is normalized lexically.
const MAX_LINKS: usize = 40;

/// `abs` (absolute) as [`file_id`] identifies it, following at most `links` dangling links.
fn resolved(abs: &Path, links: usize) -> PathBuf {
    let mut path = PathBuf::new();
    let mut components = abs.components();
    while let Some(c) = components.next() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                path.pop();
            }
            c => {
                path.push(c);
                if let Ok(canonical) = std::fs::canonicalize(&path) {
                    path = canonical;
                } else if links > 0
                    && let Ok(target) = std::fs::read_link(&path)
                {
                    // A link to nothing (yet): its target, from the link's directory (already
                    // canonical), then the components after the link.
                    path.pop();
                    let mut next = path.join(target);
                    let rest = components.as_path();
                    if !rest.as_os_str().is_empty() {
                        next.push(rest);
                    }
                    return resolved(&next, links - 1);
                }
            }
        }
    }
    path
}

#[cfg(unix)]
fn inode(p: &Path) -> Option<(u64, u64)> {
    use std::os::unix::fs::MetadataExt;
    std::fs::metadata(p).ok().map(|m| (m.dev(), m.ino()))
}

#[cfg(not(unix))]
fn inode(_p: &Path) -> Option<(u64, u64)> {
    None
}

/// Every file the graph names: the graph file, its plugin libraries, then each node's params
/// naming a file ([`param_use`]) that are set, in node and param order.
fn named_files(spec: &GraphSpec) -> Vec<Named> {
    let base_dir = spec.source.base_dir();
    let mut files = vec![Named {
        node: None,
        param: "graph".into(),
        resolved: spec.source.path.clone(),
        id: file_id(&spec.source.path),
        use_: Use::Reads,
        parts: None,
    }];
    // Resolved against the graph's directory by `plugin_paths`.
    for lib in plugin_paths(&spec.source).unwrap_or_default() {
        files.push(Named {
            node: None,
            param: "plugin".into(),
            id: file_id(&lib),
            resolved: lib,
            use_: Use::Reads,
            parts: None,
        });
    }
    for (i, node) in spec.nodes.iter().enumerate() {
        let ctx = BuildContext::new(base_dir.clone(), spec.mode, node.id.clone());
        let table = node.params.table();
        let rotates = node.kind == "hdf5_logger" && (table.contains_key("rotate_mb") || table.contains_key("rotate_s"));
        for doc in node.factory.info().params.iter() {
            let Some(use_) = param_use(&node.kind, &doc.name, &doc.ty) else { continue };
            let Some(value) = table.get(doc.name.as_ref()) else { continue };
            if use_ == Use::Directory {
                continue;
            }
            for name in file_names(&doc.ty, value) {
                let resolved = ctx.resolve(Path::new(name));
                files.push(Named {
                    node: Some(i),
                    param: doc.name.to_string(),
                    id: file_id(&resolved),
                    parts: if rotates && use_ == Use::Writes { Parts::of(&resolved) } else { None },
                    resolved,
                    use_,
                });
            }
        }
    }
    files
}

/// Whether writer `w` writes over file `f` (its file, or a rotated part of it).
fn writes_over(w: &Named, f: &FileId) -> bool {
    w.id.same(f) || w.parts.as_ref().is_some_and(|p| p.includes(f))
}

/// Refuses every output file of a node that is the graph file, a plugin library, a file a
/// node reads or another node's output file (see the module docs); each error is located at
/// the writer's param and names both nodes and files.
pub fn check_files(spec: &GraphSpec) -> Result<(), GraphErrors> {
    let files = named_files(spec);
    let mut node_spans: Option<Vec<Range<usize>>> = None;
    let mut errs = Vec::new();
    for (wi, w) in files.iter().enumerate() {
        let (Use::Writes, Some(n)) = (w.use_, w.node) else { continue };
        let writes = format!("writes {}", w.resolved.display());
        // Said only to a kind that has the param (a plugin's sink may have none).
        let ow = if spec.nodes[n].factory.info().params.iter().any(|p| p.name == "overwrite") {
            ", whatever `overwrite` says"
        } else {
            ""
        };
        let same = |f: &Named| {
            if f.resolved.as_os_str() == w.resolved.as_os_str() { "" } else { ", the same file" }
        };
        // A directory takes no file of this name: the node would fail to start (a plugin sink
        // only once `run` builds it, after `check` said ok).
        if w.resolved.is_dir() {
            let problem = format!("{writes}, which is a directory; give `{}` a file path", w.param);
            errs.push(param_error_at(spec, n, &w.param, problem, &mut node_spans));
            continue;
        }
        for (fi, f) in files.iter().enumerate() {
            if fi == wi {
                continue;
            }
            let problem = match (f.use_, f.node) {
                (Use::Directory, _) => continue,
                // Two writers: reported once, at the later one.
                (Use::Writes, Some(o)) => {
                    if fi > wi || !(writes_over(w, &f.id) || writes_over(f, &w.id)) {
                        continue;
                    }
                    let other = &spec.nodes[o];
                    // The same node: two files of an array param (`[output-path]`).
                    let whose =
                        if o == n { "this node".to_owned() } else { format!("{} \"{}\"", other.kind, other.id) };
                    format!(
                        "{writes}, which {whose} writes too (its `{}` {}{}): each would replace the other's \
                         output{ow}; give each node its own file",
                        f.param,
                        f.resolved.display(),
                        same(f)
                    )
                }
                _ if !writes_over(w, &f.id) => continue,
                (_, None) if f.param == "graph" => format!(
                    "{writes}, which is this graph's own file {}{}: the run would replace the graph with its \
                     output{ow}; give `{}` another file",
                    f.resolved.display(),
                    same(f),
                    w.param
                ),
                (_, None) => format!(
                    "{writes}, which is the plugin library {} this graph loads (`[[plugin]] path`){}: the run \
                     would replace it{ow}; give `{}` another file",
                    f.resolved.display(),
                    same(f),
                    w.param
                ),
                (Use::Reads, Some(o)) => {
                    let other = &spec.nodes[o];
                    let whose =
                        if o == n { "this node".to_owned() } else { format!("{} \"{}\"", other.kind, other.id) };
                    format!(
                        "{writes}, the {} {whose} reads (its `{}` {}{}): the run would overwrite that input{ow}, \
                         and what it holds would be lost; give `{}` another file",
                        what_is_read(&other.kind, &f.param),
                        f.param,
                        f.resolved.display(),
                        same(f),
                        w.param
                    )
                }
                (_, Some(o)) => {
                    let other = &spec.nodes[o];
                    format!(
                        "{writes}, which {} \"{}\" (a plugin kind) names in its `{}` {}{}: whether it reads or \
                         writes that file, the run would replace it or have it replaced{ow}; \
                         give `{}` another file",
                        other.kind,
                        other.id,
                        f.param,
                        f.resolved.display(),
                        same(f),
                        w.param
                    )
                }
            };
            errs.push(param_error_at(spec, n, &w.param, problem, &mut node_spans));
        }
    }
    finish(errs)
}

/// Refuses what would stop a node at start and is known before any runs, so `check` reports
/// it too (located at the param): a logger's file whose directory is missing or takes no file
/// ([`crate::output::unwritable`]), or that is no recording while `overwrite` is set
/// ([`crate::output::not_a_recording`]); and two serial sources on one device (files compared
/// as in [`check_files`]). A logger's existing file without `overwrite` is refused at start
/// only ([`crate::log::existing_file_refusal`]): the file may be moved by then, and `check` of
/// a session graph stays independent of the last session's output. Not part of [`check_files`], which a live edit's graph is checked with
/// too: by then the running logger has made its file.
pub fn check_start(spec: &GraphSpec) -> Result<(), GraphErrors> {
    let base_dir = spec.source.base_dir();
    let mut node_spans: Option<Vec<Range<usize>>> = None;
    let mut errs = Vec::new();
    let mut ports: Vec<(usize, PathBuf, FileId)> = Vec::new();
    for (n, node) in spec.nodes.iter().enumerate() {
        let ctx = BuildContext::new(base_dir.clone(), spec.mode, node.id.clone());
        match node.kind.as_str() {
            "hdf5_logger" => {
                let Ok(p) = node.params.parse::<LoggerParams>() else { continue };
                let path = ctx.resolve(&p.path);
                // A directory there is `check_files`'s error.
                if p.path.as_os_str().is_empty() || path.is_dir() {
                    continue;
                }
                // An existing file without `overwrite` is left to the start: a session graph
                // (`graphs/record-calibration.toml`) checks fine again once its file is moved.
                let problem = crate::output::unwritable(&path)
                    .or_else(|| crate::output::not_a_file(&path))
                    .or_else(|| p.overwrite.then(|| crate::output::not_a_recording(&path)).flatten());
                if let Some(why) = problem {
                    let problem = format!("{}: {why}", path.display());
                    errs.push(param_error_at(spec, n, "path", problem, &mut node_spans));
                }
            }
            "serial_eit" | "serial_pressure" | "serial_loadcell" => {
                let Some(port) = node.params.table().get("port").and_then(toml::Value::as_str) else { continue };
                let resolved = ctx.resolve(Path::new(port));
                let id = file_id(&resolved);
                if let Some((o, other, _)) = ports.iter().find(|(_, _, i)| i.same(&id)) {
                    let other_node = &spec.nodes[*o];
                    let spelt = if other == &resolved { String::new() } else { format!(" ({})", other.display()) };
                    let problem = format!(
                        "{} is also the port of {} \"{}\"{spelt}: a device is read by one node, and this one \
                         would fail to open it",
                        resolved.display(),
                        other_node.kind,
                        other_node.id,
                    );
                    errs.push(param_error_at(spec, n, "port", problem, &mut node_spans));
                }
                ports.push((n, resolved, id));
            }
            _ => {}
        }
    }
    finish(errs)
}

/// Refuses an output file given outside the graph, `path` (as given: relative to the current
/// directory, not to the graph file), named `what` in the error (e.g. `--stats-json`), that is
/// the same file as one the graph names: the graph file, a plugin library, a file a node reads
/// or writes (or, for a plugin's `path`, either), or a rotated part of a logger's recording.
/// The error names each such node, its param and its file; files are compared as in
/// [`check_files`] (links followed, `.` and `..` normalized). A reconstructor's `cache_dir` is
/// not compared.
pub fn check_extra_output(spec: &GraphSpec, what: &str, path: &Path) -> Result<(), String> {
    let found = output_clashes(spec, path);
    if found.is_empty() {
        return Ok(());
    }
    Err(format!(
        "{what} {} is {}: writing it would replace that file, or the graph would write over it; give {what} \
         another file",
        path.display(),
        found.join(", and ")
    ))
}

/// What of `spec` the file `path` is (compared as [`check_extra_output`] does), each said as
/// "the calibration correct \"c\" reads (its `calibration` c.toml)"; empty when none.
pub fn output_clashes(spec: &GraphSpec, path: &Path) -> Vec<String> {
    let id = file_id(path);
    let same = |f: &Named| if f.resolved.as_os_str() == path.as_os_str() { "" } else { ", the same file" };
    let mut found = Vec::new();
    for f in named_files(spec) {
        if f.use_ == Use::Directory {
            continue;
        }
        let part = !f.id.same(&id) && f.parts.as_ref().is_some_and(|p| p.includes(&id));
        if !f.id.same(&id) && !part {
            continue;
        }
        let file = f.resolved.display();
        found.push(match (f.use_, f.node) {
            (_, None) if f.param == "graph" => format!("this graph's own file {file}{}", same(&f)),
            (_, None) => format!("the plugin library {file} this graph loads (`[[plugin]] path`{})", same(&f)),
            (use_, Some(o)) => {
                let node = &spec.nodes[o];
                let (kind, nid, param) = (&node.kind, &node.id, &f.param);
                match use_ {
                    Use::Reads => format!(
                        "the {} {kind} \"{nid}\" reads (its `{param}` {file}{})",
                        what_is_read(kind, param),
                        same(&f)
                    ),
                    Use::Writes if part => {
                        format!("a rotated part of the recording {kind} \"{nid}\" writes (its `{param}` {file})")
                    }
                    Use::Writes => format!("the file {kind} \"{nid}\" writes (its `{param}` {file}{})", same(&f)),
                    Use::Names | Use::Directory => format!(
                        "the file {kind} \"{nid}\" (a plugin kind) reads or writes (its `{param}` {file}{})",
                        same(&f)
                    ),
                }
            }
        });
    }
    found
}

/// The strategy names that can arrive, each with the node that names it (`None`: not known
/// here: a plugin upstream).
type Arriving = Option<Vec<(String, usize)>>;

/// The edges into node `to`'s input `port`.
fn edges_into<'a>(spec: &'a GraphSpec, to: usize, port: &str) -> impl Iterator<Item = usize> + 'a {
    let p = spec.nodes[to].factory.info().inputs.iter().position(|s| s.name == port);
    spec.edges.iter().filter(move |e| e.to_node == to && Some(e.to_port) == p).map(|e| e.from_node)
}

/// The names the forces of node `c` can carry, when it is a built-in corrector whose splits
/// come from built-in splitters (named as `Corrector::process` names them: `output_name`);
/// `None` otherwise.
fn corrector_names(spec: &GraphSpec, c: usize) -> Option<Vec<String>> {
    let node = &spec.nodes[c];
    if node.kind != "corrector" {
        return None; // a plugin's forces: their names are its own
    }
    let p = node.params.parse::<CorrectorParams>().ok()?;
    let kind = StrategyKind::from_name(&p.strategy)?;
    let named = |split: &str| {
        let mut n = String::new();
        output_name(&mut n, p.name.as_deref(), kind, split);
        n
    };
    if !name_follows_split(p.name.as_deref(), kind) {
        return Some(vec![named(SplitStrategy::Proportional.name())]);
    }
    let mut names = Vec::new();
    for s in edges_into(spec, c, "split") {
        let splitter = &spec.nodes[s];
        if splitter.kind != "splitter" {
            return None; // a plugin splitter names its own strategy
        }
        names.push(named(splitter.params.parse::<SplitterParams>().ok()?.strategy.name()));
    }
    Some(names)
}

/// The strategy names that can reach logger `l`'s `forces` input (see [`Arriving`]).
fn arriving(spec: &GraphSpec, l: usize) -> Arriving {
    let mut names = Vec::new();
    for f in edges_into(spec, l, "forces") {
        names.extend(corrector_names(spec, f)?.into_iter().map(|n| (n, f)));
    }
    Some(names)
}

/// Refuses a name in an `hdf5_logger`'s `strategies` that no corrector upstream of its
/// `forces` input produces, naming the param and the names that do arrive (see the module
/// docs; not checked when a plugin produces some of the forces).
pub fn check_strategies(spec: &GraphSpec) -> Result<(), GraphErrors> {
    let mut node_spans = None;
    let mut errs = Vec::new();
    for (l, node) in spec.nodes.iter().enumerate() {
        if node.kind != "hdf5_logger" || edges_into(spec, l, "forces").next().is_none() {
            continue;
        }
        let Ok(params) = node.params.parse::<LoggerParams>() else { continue };
        // A forces producer whose names are not known here (a plugin): nothing to refuse.
        let Some(arriving) = arriving(spec, l) else { continue };
        let known: BTreeSet<&str> = arriving.iter().map(|(n, _)| n.as_str()).collect();
        let missing: Vec<String> =
            params.strategies.iter().filter(|s| !known.contains(s.as_str())).map(|s| format!("{s:?}")).collect();
        if missing.is_empty() {
            continue;
        }
        let (these, are) = if missing.len() == 1 { ("strategy", "is") } else { ("strategies", "are") };
        let names = if arriving.is_empty() {
            "none (no corrector's forces reach it)".to_owned()
        } else {
            let mut seen = BTreeSet::new();
            arriving
                .iter()
                .filter(|(n, _)| seen.insert(n.clone()))
                .map(|(n, c)| format!("\"{n}\" (corrector \"{}\")", spec.nodes[*c].id))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let problem = format!(
            "{these} {} {are} not produced by any corrector connected to `forces`, so nothing would be logged \
             under {}; the names that arrive: {names} (a corrector's `name`, else its strategy, suffixed \
             with -<splitter strategy> for a pneumatic one after a splitter other than proportional)",
            missing.join(", "),
            if missing.len() == 1 { "it" } else { "them" },
        );
        errs.push(param_error_at(spec, l, "strategies", problem, &mut node_spans));
    }
    finish(errs)
}

#[cfg(test)]
mod tests {
    use super::*;

    use serde::Deserialize;
    use skinflow_core::graph::SourceFile;
    use skinflow_core::{KindInfo, NodeError, NodeImpl, NodeParams, ParamDoc, PortSpec, Registry, Role, typed};

    use crate::payload::{Forces, Split};

    /// Params of `p-files`, standing in for a plugin kind: one file of each type, and an array
    /// of files it writes.
    #[derive(Debug, Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)] // only parsed: never built
    struct FileParams {
        out: Option<String>,
        outs: Option<Vec<String>>,
        #[serde(rename = "in")]
        input: Option<String>,
        either: Option<String>,
        sensor: Option<String>,
    }

    impl NodeParams for FileParams {}

    /// The built-in kinds, plus stand-ins for plugin kinds (never built): `p-files` (forces, and
    /// an `output-path`, a `[output-path]`, an `input-path` and a `path` param) and `p-split`.
    fn registry() -> Registry {
        let mut r = crate::registry();
        r.register(typed(
            KindInfo::new("p-files", Role::Source, "a plugin's files")
                .output(PortSpec::output::<Forces>("forces", "forces"))
                .param(ParamDoc::new("out", OUTPUT_PATH, "none", "a file it writes"))
                .param(ParamDoc::new("outs", "[output-path]", "[]", "files it writes"))
                .param(ParamDoc::new("in", INPUT_PATH, "none", "a file it reads"))
                .param(ParamDoc::new("either", PATH, "none", "a file it reads or writes"))
                .param(ParamDoc::new("sensor", SENSOR, "none", "the sensor its frames come from")),
            |_: FileParams, _: &BuildContext| -> Result<NodeImpl, NodeError> { Err(NodeError::msg("not built")) },
        ))
        .unwrap();
        r.register(typed(
            KindInfo::new("p-split", Role::Source, "a plugin's splits")
                .output(PortSpec::output::<Split>("split", "splits")),
            |_: FileParams, _: &BuildContext| -> Result<NodeImpl, NodeError> { Err(NodeError::msg("not built")) },
        ))
        .unwrap();
        r
    }

    /// The directory the graph "is in": it does not exist (paths compared normalized).
    fn base() -> PathBuf {
        std::env::temp_dir().join("skinflow-outputs-unit-nonexistent")
    }

    fn spec(text: &str) -> GraphSpec {
        GraphSpec::parse(SourceFile::new(base().join("g.toml"), text.to_owned()), &registry()).expect("a valid graph")
    }

    /// The errors of `check_files` on `text` (as `base()/g.toml`), one per line, `base()`
    /// written `DIR`; empty: accepted.
    fn errors(text: &str) -> String {
        match check_files(&spec(text)) {
            Ok(()) => String::new(),
            Err(e) => e.to_string().replace(&base().display().to_string(), "DIR"),
        }
    }

    fn files(id: &str, params: &str) -> String {
        format!("[[node]]\nid = \"{id}\"\nkind = \"p-files\"\nparams = {{ {params} }}\n")
    }

    const REPLAY: &str = "[[node]]\nid = \"replay\"\nkind = \"replay\"\nparams = { path = \"rec.h5\" }\n";

    #[test]
    fn two_plugin_outputs_on_one_file_are_refused_at_the_later() {
        let text = files("a", "out = \"x.csv\"") + &files("b", "out = \"sub/../x.csv\"");
        assert_eq!(
            errors(&text),
            "DIR/g.toml:8:12: node \"b\": param \"out\": writes DIR/sub/../x.csv, which p-files \"a\" writes too \
             (its `out` DIR/x.csv, the same file): each would replace the other's output; \
             give each node its own file"
        );
        // One of an array's files, and one file twice in one array.
        let text = files("a", "out = \"x.csv\"") + &files("b", "outs = [\"y.csv\", \"x.csv\"]");
        assert!(
            errors(&text).starts_with(
                "DIR/g.toml:8:12: node \"b\": param \"outs\": writes DIR/x.csv, which p-files \"a\" writes too (its \
                 `out` DIR/x.csv)"
            ),
            "{}",
            errors(&text)
        );
        let text = files("a", "outs = [\"y.csv\", \"./y.csv\"]");
        assert!(
            errors(&text).starts_with(
                "DIR/g.toml:4:12: node \"a\": param \"outs\": writes DIR/./y.csv, which this node writes too (its \
                 `outs` DIR/y.csv, the same file)"
            ),
            "{}",
            errors(&text)
        );
        // Different files: accepted.
        let text = files("a", "out = \"x.csv\", outs = [\"y.csv\"]") + &files("b", "out = \"z.csv\"");
        assert_eq!(errors(&text), "");
    }

    #[test]
    fn a_plugin_output_over_a_file_any_node_reads_or_writes_is_refused() {
        // A recording replayed.
        let text = format!("{REPLAY}{}", files("csv", "out = \"rec.h5\""));
        assert_eq!(
            errors(&text),
            "DIR/g.toml:8:12: node \"csv\": param \"out\": writes DIR/rec.h5, the recording replay \"replay\" \
             reads (its `path` DIR/rec.h5): the run would overwrite that input, and what \
             it holds would be lost; give `out` another file"
        );
        // The graph file; a plugin's input-path; a plugin's path (read or written).
        let text = files("csv", "out = \"g.toml\"");
        assert!(errors(&text).contains("writes DIR/g.toml, which is this graph's own file"), "{}", errors(&text));
        let text = files("r", "in = \"p.csv\"") + &files("w", "out = \"p.csv\"");
        assert!(
            errors(&text).starts_with(
                "DIR/g.toml:8:12: node \"w\": param \"out\": writes DIR/p.csv, the file p-files \"r\" reads (its `in` \
                 DIR/p.csv)"
            ),
            "{}",
            errors(&text)
        );
        let text = files("r", "sensor = \"s.toml\"") + &files("w", "out = \"s.toml\"");
        assert!(
            errors(&text).starts_with(
                "DIR/g.toml:8:12: node \"w\": param \"out\": writes DIR/s.toml, the sensor file p-files \"r\" reads \
                 (its `sensor` DIR/s.toml)"
            ),
            "{}",
            errors(&text)
        );
        let text = files("w", "out = \"p.csv\"") + &files("e", "either = \"p.csv\"");
        assert!(
            errors(&text).starts_with(
                "DIR/g.toml:4:12: node \"w\": param \"out\": writes DIR/p.csv, which p-files \"e\" (a plugin kind) \
                 names in its `either` DIR/p.csv"
            ),
            "{}",
            errors(&text)
        );
        // A logger over a plugin's output, and over a file a plugin reads.
        for param in ["out", "in"] {
            let text = format!(
                "{REPLAY}{}[[node]]\nid = \"log\"\nkind = \"hdf5_logger\"\nparams = {{ path = \"p.h5\" }}\n\
                 [[edge]]\nfrom = \"replay.eit\"\nto = \"log.eit\"\n",
                files("p", &format!("{param} = \"p.h5\""))
            );
            assert!(
                errors(&text).starts_with("DIR/g.toml:12:12: node \"log\": param \"path\": writes DIR/p.h5"),
                "{param}"
            );
        }
        // A file a plugin reads (input-path or path) may be read by any number of nodes.
        let text = files("a", "in = \"p.csv\"")
            + &files("b", "in = \"p.csv\", either = \"q.csv\"")
            + &files("c", "either = \"p.csv\"");
        assert_eq!(errors(&text), "");
    }

    #[test]
    fn param_types_say_what_a_plugin_does_with_its_file() {
        assert_eq!(param_use("p", "f", "output-path"), Some(Use::Writes));
        assert_eq!(param_use("p", "f", "[output-path]"), Some(Use::Writes));
        assert_eq!(param_use("p", "f", "input-path"), Some(Use::Reads));
        assert_eq!(param_use("p", "f", "sensor"), Some(Use::Reads));
        assert_eq!(param_use("p", "f", "path"), Some(Use::Names));
        assert_eq!(param_use("p", "f", "string"), None);
        // A built-in kind's, as listed (its type is `path`).
        assert_eq!(param_use("hdf5_logger", "path", "path"), Some(Use::Writes));
        assert_eq!(param_use("replay", "path", "path"), Some(Use::Reads));
        assert_eq!(param_use("reconstructor", "cache_dir", "path"), Some(Use::Directory));
    }

    #[test]
    fn an_extra_output_over_any_file_of_the_graph_is_refused_naming_node_param_and_file() {
        let text = format!(
            "{REPLAY}\
             [[node]]\nid = \"log\"\nkind = \"hdf5_logger\"\nparams = {{ path = \"out.h5\", rotate_s = 60.0 }}\n\
             [[node]]\nid = \"split\"\nkind = \"p-split\"\n\
             [[node]]\nid = \"force\"\nkind = \"corrector\"\nparams = {{ calibration = \"calib.toml\" }}\n\
             {}{}\
             [[edge]]\nfrom = \"replay.eit\"\nto = \"log.eit\"\n\
             [[edge]]\nfrom = \"split.split\"\nto = \"force.split\"\n",
            files("csv", "out = \"f.csv\", either = \"e.csv\""),
            files("csv2", "in = \"calib.toml\"")
        );
        let spec = spec(&text);
        assert_eq!(check_files(&spec), Ok(()), "the graph itself is fine");
        let check = |p: &str| {
            check_extra_output(&spec, "--stats-json", &base().join(p))
                .map_err(|e| e.replace(&base().display().to_string(), "DIR"))
        };
        let tail = ": writing it would replace that file, or the graph would write over it; give --stats-json another \
                    file";
        assert_eq!(
            check("rec.h5").unwrap_err(),
            format!("--stats-json DIR/rec.h5 is the recording replay \"replay\" reads (its `path` DIR/rec.h5){tail}")
        );
        assert_eq!(
            check("sub/../calib.toml").unwrap_err(),
            format!(
                "--stats-json DIR/sub/../calib.toml is the calibration corrector \"force\" reads (its `calibration` \
                 DIR/calib.toml, the same file), and the file p-files \"csv2\" reads (its `in` DIR/calib.toml, the \
                 same file){tail}"
            )
        );
        assert_eq!(
            check("g.toml").unwrap_err(),
            format!("--stats-json DIR/g.toml is this graph's own file DIR/g.toml{tail}")
        );
        assert_eq!(
            check("out.h5").unwrap_err(),
            format!("--stats-json DIR/out.h5 is the file hdf5_logger \"log\" writes (its `path` DIR/out.h5){tail}")
        );
        assert_eq!(
            check("out-0002.h5").unwrap_err(),
            format!(
                "--stats-json DIR/out-0002.h5 is a rotated part of the recording hdf5_logger \"log\" writes (its \
                 `path` DIR/out.h5){tail}"
            )
        );
        assert_eq!(
            check("f.csv").unwrap_err(),
            format!("--stats-json DIR/f.csv is the file p-files \"csv\" writes (its `out` DIR/f.csv){tail}")
        );
        assert_eq!(
            check("e.csv").unwrap_err(),
            format!(
                "--stats-json DIR/e.csv is the file p-files \"csv\" (a plugin kind) reads or writes (its `either` \
                 DIR/e.csv){tail}"
            )
        );
        // Another file, and a name relative to the current directory, not the graph's.
        check("stats.json").unwrap();
        check_extra_output(&spec, "--stats-json", Path::new("rec.h5")).unwrap();
    }

    #[test]
    fn rotated_parts_and_normalized_paths() {
        let parts = Parts::of(Path::new("/nonexistent-skinflow/d/rec.h5")).unwrap();
        let id = |p: &str| file_id(Path::new(p));
        assert!(parts.includes(&id("/nonexistent-skinflow/d/rec-0001.h5")));
        assert!(parts.includes(&id("/nonexistent-skinflow/d/rec-12345.h5")));
        assert!(!parts.includes(&id("/nonexistent-skinflow/d/rec-001.h5")));
        assert!(!parts.includes(&id("/nonexistent-skinflow/e/rec-0001.h5")));
        assert!(!parts.includes(&id("/nonexistent-skinflow/d/rec-0001.hdf5")));
        assert!(!parts.includes(&id("/nonexistent-skinflow/d/rec.h5")), "the base is no part");
        assert!(parts.includes(&id("/nonexistent-skinflow/d/x/../rec-0002.h5")));
        assert!(id("/nonexistent-skinflow/d/./x/../rec.h5").same(&id("/nonexistent-skinflow/d/rec.h5")));
        let bare = Parts::of(Path::new("/nonexistent-skinflow/d/rec")).unwrap();
        assert!(bare.includes(&id("/nonexistent-skinflow/d/rec-0003")));
        // The given path, normalized: its directory as `file_id` identifies it.
        let dotted = Parts::of(Path::new("/nonexistent-skinflow/d/x/../rec.h5")).unwrap();
        assert!(dotted.includes(&id("/nonexistent-skinflow/d/rec-0004.h5")));
        assert!(Parts::of(Path::new("/nonexistent-skinflow/d/..")).is_none());
    }

    #[cfg(unix)]
    #[test]
    fn links_are_the_file_they_lead_to() {
        let d = std::env::temp_dir().join(format!("skinflow-outputs-links-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(d.join("sub")).unwrap();
        std::fs::write(d.join("a.h5"), "x").unwrap();
        std::os::unix::fs::symlink(d.join("a.h5"), d.join("link.h5")).unwrap();
        std::fs::hard_link(d.join("a.h5"), d.join("hard.h5")).unwrap();
        std::os::unix::fs::symlink(d.join("sub"), d.join("dirlink")).unwrap();
        let a = file_id(&d.join("a.h5"));
        assert!(file_id(&d.join("link.h5")).same(&a));
        assert!(file_id(&d.join("hard.h5")).same(&a));
        assert!(file_id(&d.join("sub/../a.h5")).same(&a));
        // Not there yet: the existing directory canonicalized, through the link.
        assert!(file_id(&d.join("dirlink/new.h5")).same(&file_id(&d.join("sub/new.h5"))));
        let _ = std::fs::remove_dir_all(&d);
    }

    /// A rotating logger's parts are written beside its path as given (`part_path` on it), not
    /// beside the file a link there leads to: a writer on `dir/rec-0001.h5` is refused for a
    /// logger on `dir/rec.h5 -> other/x.h5`, one on `other/x-0001.h5` is not; the base file is
    /// still compared through the link, and an existing part that is a link is replaced, so the
    /// file it leads to is no output.
    #[cfg(unix)]
    #[test]
    fn rotated_parts_are_beside_the_path_given_not_beside_a_links_target() {
        use std::os::unix::fs::symlink;
        let d = std::env::temp_dir().join(format!("skinflow-outputs-rotated-link-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(d.join("dir")).unwrap();
        std::fs::create_dir_all(d.join("other")).unwrap();
        std::fs::write(d.join("other/x.h5"), "x").unwrap();
        symlink(d.join("other/x.h5"), d.join("dir/rec.h5")).unwrap();
        // An existing part that is a link elsewhere: the logger replaces the link.
        symlink(d.join("other/y.h5"), d.join("dir/rec-0002.h5")).unwrap();
        let path = |p: &str| d.join(p).to_str().unwrap().to_owned();
        let logger = format!(
            "{REPLAY}[[node]]\nid = \"log\"\nkind = \"hdf5_logger\"\nparams = {{ path = {:?}, rotate_s = 60.0 }}\n\
             [[edge]]\nfrom = \"replay.eit\"\nto = \"log.eit\"\n",
            path("dir/rec.h5")
        );
        let with = |p: &str| format!("{logger}{}", files("w", &format!("out = {:?}", path(p))));
        let refused = "which hdf5_logger \"log\" writes too";
        for p in ["dir/rec-0001.h5", "dir/./rec-0003.h5", "other/../dir/rec-0004.h5", "other/x.h5"] {
            let e = errors(&with(p));
            assert!(e.contains(refused) && e.contains("node \"w\": param \"out\""), "{p}: {e:?}");
        }
        for p in ["other/x-0001.h5", "other/rec-0001.h5", "dir/x-0001.h5", "dir/rec-01.h5", "other/y.h5"] {
            assert_eq!(errors(&with(p)), "", "{p}");
        }
        // An output given outside the graph, likewise.
        let spec = spec(&logger);
        let extra = |p: &str| check_extra_output(&spec, "--stats-json", &d.join(p));
        let e = extra("dir/rec-0001.h5").unwrap_err();
        assert!(e.contains("is a rotated part of the recording hdf5_logger \"log\" writes"), "{e}");
        extra("other/x-0001.h5").unwrap();
        assert!(extra("other/x.h5").unwrap_err().contains("the file hdf5_logger \"log\" writes"));
        let _ = std::fs::remove_dir_all(&d);
    }

    /// A link leading where no file is yet is the file a writer through it creates: its target,
    /// relative to the link's directory, through links to links and dangling directory links;
    /// a loop of links ends. Two writers, through the link and at its target, are refused.
    #[cfg(unix)]
    #[test]
    fn dangling_links_are_the_file_they_lead_to() {
        use std::os::unix::fs::symlink;
        let d = std::env::temp_dir().join(format!("skinflow-outputs-dangling-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(d.join("realdir")).unwrap();
        symlink("realdir/nonexist.csv", d.join("dangling.csv")).unwrap();
        symlink(d.join("dangling.csv"), d.join("link-to-link.csv")).unwrap();
        symlink("realdir/newsub", d.join("dirdangle")).unwrap();
        symlink("loop2", d.join("loop1")).unwrap();
        symlink("loop1", d.join("loop2")).unwrap();
        let target = file_id(&d.join("realdir/nonexist.csv"));
        assert!(file_id(&d.join("dangling.csv")).same(&target));
        assert!(file_id(&d.join("link-to-link.csv")).same(&target));
        assert!(file_id(&d.join("./realdir/../dangling.csv")).same(&target));
        assert!(file_id(&d.join("dirdangle/x.csv")).same(&file_id(&d.join("realdir/newsub/x.csv"))));
        assert!(!file_id(&d.join("loop1")).same(&file_id(&d.join("loop2"))));
        assert!(!file_id(&d.join("realdir/other.csv")).same(&target));

        let out = |p: &str| format!("out = {:?}", d.join(p).to_str().unwrap());
        let text = format!("{}{}", files("a", &out("dangling.csv")), files("b", &out("realdir/nonexist.csv")));
        let e = errors(&text);
        assert!(e.contains("nonexist.csv"), "{e}");
        assert_eq!(errors(&files("a", &out("dangling.csv"))), "");
        let _ = std::fs::remove_dir_all(&d);
    }
}
