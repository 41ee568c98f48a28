//! Loading a plugin library into a [`Registry`]: copy the file to a unique temporary path (so a
//! rebuilt file is a new library to the dynamic loader, and the build may overwrite it while we
//! run), `dlopen` the copy, call the entry point, check the ABI version and every struct size,
//! copy the kind descriptions out, and register one factory per kind. Nothing is registered
//! unless every kind of the library can be. The library stays mapped while any factory or node
//! from it exists (they hold an `Arc<PluginLibrary>`).

use std::borrow::Cow;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use skinflow_core::{KindInfo, ParamDoc, PortSpec, Registry, Role};

use super::codec::{Codecs, MakeCodec};
use super::node::{KindFns, PluginFactory, PluginKind};
use crate::abi::{ABI_VERSION, ENTRY_SYMBOL, EntryFn, SfKind, SfPlugin, SfPort, SfRole, SfStr, sizes};
use crate::export::{PARAM_TYPES, SENSOR, is_param_type};

/// Why a plugin could not be loaded. Every message names the library's path.
#[derive(Debug, thiserror::Error)]
pub enum PluginError {
    /// `what`: "file not found", "is a directory", "is not a regular file (a device, a FIFO)".
    #[error("plugin {}: {what}", path.display())]
    Missing { path: PathBuf, what: &'static str },
    #[error("plugin {}: cannot copy it to {}: {source}", path.display(), to.display())]
    Copy { path: PathBuf, to: PathBuf, source: std::io::Error },
    #[error("plugin {}: not a loadable library: {cause}", path.display())]
    Open { path: PathBuf, cause: String },
    #[error("plugin {}: not a skinflow plugin (no symbol \"skinflow_plugin_entry\"; export kinds with skinflow_plugin_sdk::export_plugin!)", path.display())]
    NotAPlugin { path: PathBuf },
    #[error("plugin {}: its entry point failed (it panicked while describing its kinds)", path.display())]
    Entry { path: PathBuf },
    #[error("plugin {}: built for plugin ABI version {found}, this skinflow loads version {expected} (rebuild it against this skinflow-plugin-sdk)", path.display())]
    AbiVersion { path: PathBuf, found: u32, expected: u32 },
    #[error("plugin {}: struct {what} is {found} bytes in the plugin but {expected} in the host (ABI mismatch; rebuild the plugin)", path.display())]
    StructSize { path: PathBuf, what: &'static str, found: u32, expected: u32 },
    #[error("plugin {}: {problem}", path.display())]
    Invalid { path: PathBuf, problem: String },
    #[error("plugin {}: kind \"{kind}\" {port}: no codec for payload type \"{ty}\" (known: {known})", path.display())]
    NoCodec { path: PathBuf, kind: String, port: String, ty: String, known: String },
    #[error("plugin {}: kind \"{kind}\": {problem}", path.display())]
    Kind { path: PathBuf, kind: String, problem: String },
    #[error("plugin {}: kind \"{kind}\" is already defined by {existing}", path.display())]
    DuplicateKind { path: PathBuf, kind: String, existing: String },
    #[error("plugin {}: given twice (also as {}); load each library once", path.display(), first.display())]
    Twice { path: PathBuf, first: PathBuf },
}

impl PluginError {
    /// The library the error is about, as the caller named it.
    pub fn path(&self) -> &Path {
        match self {
            PluginError::Missing { path, .. }
            | PluginError::Copy { path, .. }
            | PluginError::Open { path, .. }
            | PluginError::NotAPlugin { path }
            | PluginError::Entry { path }
            | PluginError::AbiVersion { path, .. }
            | PluginError::StructSize { path, .. }
            | PluginError::Invalid { path, .. }
            | PluginError::NoCodec { path, .. }
            | PluginError::Kind { path, .. }
            | PluginError::DuplicateKind { path, .. }
            | PluginError::Twice { path, .. } => path,
        }
    }
}

/// A mapped plugin library.
pub struct PluginLibrary {
    /// The path the user named.
    pub path: PathBuf,
    pub name: String,
    pub version: String,
    // Dropped last, after every node and factory that could call into it.
    _lib: libloading::Library,
}

impl std::fmt::Debug for PluginLibrary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PluginLibrary").field("path", &self.path).field("name", &self.name).finish()
    }
}

/// What a load added.
#[derive(Debug, Clone)]
pub struct Loaded {
    pub library: Arc<PluginLibrary>,
    pub kinds: Vec<String>,
}

static COPIES: AtomicU64 = AtomicU64::new(0);

/// Copies `path` to a fresh temporary file and opens that copy.
fn open_copy(path: &Path) -> Result<libloading::Library, PluginError> {
    let dir = std::env::temp_dir().join("skinflow-plugins");
    let file = path.file_name().map_or_else(|| "plugin".into(), |f| f.to_string_lossy().into_owned());
    let to = dir.join(format!("{}-{}-{file}", std::process::id(), COPIES.fetch_add(1, Ordering::Relaxed)));
    std::fs::create_dir_all(&dir).and_then(|()| std::fs::copy(path, &to)).map_err(|source| PluginError::Copy {
        path: path.to_path_buf(),
        to: to.clone(),
        source,
    })?;
    if let Err(problem) = check_complete(&to) {
        let _ = std::fs::remove_file(&to);
        return Err(PluginError::Open { path: path.to_path_buf(), cause: problem });
    }
    // SAFETY: loading a library runs its initialisers; the user named this plugin in a graph or
    // on the command line, which is the trust decision. The copy is ours alone, and
    // `check_complete` found every segment the loader maps within it.
    let lib = unsafe { libloading::Library::new(&to) };
    // The mapping outlives the file: removing the copy now leaves nothing behind.
    let _ = std::fs::remove_file(&to);
    lib.map_err(|e| {
        // libloading says "dlopen failed" and keeps the loader's reason (an invalid ELF header,
        // a missing dependency) as the error's source.
        let cause = match std::error::Error::source(&e) {
            Some(reason) => format!("{e}: {reason}"),
            None => e.to_string(),
        };
        PluginError::Open {
            path: path.to_path_buf(),
            cause: cause.replace(&*to.to_string_lossy(), &path.to_string_lossy()),
        }
    })
}

/// Refuses a library file that is cut short: an ELF file whose headers, or a segment the
/// loader maps, reach past its end. `dlopen` maps such a file and the process dies of SIGBUS
/// when it touches the missing pages (a rebuild caught half way under `run --watch`). Files
/// that are not 64-bit ELF are left to `dlopen`, which names what is wrong with them.
fn check_complete(copy: &Path) -> Result<(), String> {
    use object::read::elf::{ElfFile64, FileHeader, ProgramHeader};
    let data = std::fs::read(copy).map_err(|e| format!("cannot read it: {e}"))?;
    let incomplete = |what: &str| {
        format!(
            "the file is incomplete: {what}, but it has {} bytes; is it still being written (a build in progress)?",
            data.len()
        )
    };
    if !data.starts_with(b"\x7fELF") || data.get(4) != Some(&2) {
        return Ok(());
    }
    let elf = match ElfFile64::<object::Endianness>::parse(&*data) {
        Ok(elf) => elf,
        Err(e) => return Err(incomplete(&format!("its ELF headers do not read ({e})"))),
    };
    let (header, endian) = (elf.elf_header(), elf.endian());
    let segments =
        header.program_headers(endian, &*data).map_err(|_| incomplete("its program headers reach past its end"))?;
    for (k, segment) in segments.iter().enumerate() {
        let (offset, size) = (segment.p_offset(endian), segment.p_filesz(endian));
        if offset.checked_add(size).is_none_or(|end| end > data.len() as u64) {
            return Err(incomplete(&format!("segment {k} ends at byte {}", offset.saturating_add(size))));
        }
    }
    Ok(())
}

fn text(path: &Path, what: &str, s: SfStr) -> Result<String, PluginError> {
    // SAFETY: the table passed the ABI checks; its strings are static in the library, which
    // stays mapped while we read.
    unsafe { s.to_str() }
        .map(str::to_owned)
        .map_err(|e| PluginError::Invalid { path: path.to_path_buf(), problem: format!("{what} is not UTF-8: {e}") })
}

/// `n` items at `p` (empty when `n == 0`, whatever `p` is).
///
/// # Safety
/// When `n > 0`, `p` must point at `n` valid items that live as long as the library.
unsafe fn items<'a, T>(p: *const T, n: usize) -> &'a [T] {
    if n == 0 || p.is_null() {
        return &[];
    }
    // SAFETY: forwarded from the caller.
    unsafe { std::slice::from_raw_parts(p, n) }
}

/// Checks the version and struct sizes before anything else of the table is read.
fn check_abi(path: &Path, t: &SfPlugin) -> Result<(), PluginError> {
    if t.abi_version != ABI_VERSION {
        return Err(PluginError::AbiVersion { path: path.to_path_buf(), found: t.abi_version, expected: ABI_VERSION });
    }
    for ((what, expected), found) in sizes().into_iter().zip(t.declared_sizes()) {
        if found != expected {
            return Err(PluginError::StructSize { path: path.to_path_buf(), what, found, expected });
        }
    }
    Ok(())
}

fn port_spec(path: &Path, kind: &str, p: &SfPort, input: bool) -> Result<PortSpec, PluginError> {
    let name = text(path, &format!("kind \"{kind}\" port name"), p.name)?;
    Ok(PortSpec {
        ty: Cow::Owned(text(path, &format!("kind \"{kind}\" port \"{name}\" type"), p.type_name)?),
        doc: Cow::Owned(text(path, &format!("kind \"{kind}\" port \"{name}\" doc"), p.doc)?),
        name: Cow::Owned(name),
        required: input && p.optional == 0,
        multi: !input,
    })
}

/// The kind's role, checked against its functions and ports.
fn role(path: &Path, name: &str, k: &SfKind) -> Result<Role, PluginError> {
    let bad = |problem: String| PluginError::Kind { path: path.to_path_buf(), kind: name.to_owned(), problem };
    let (role, word) = match k.role {
        SfRole::PROCESSOR => (Role::Processor, "processor"),
        SfRole::SOURCE => (Role::Source, "source"),
        SfRole::SINK => (Role::Sink, "sink"),
        SfRole(r) => return Err(bad(format!("unknown role {r} (0 processor, 1 source, 2 sink)"))),
    };
    let needs_poll = role == Role::Source;
    if needs_poll != k.poll.is_some() || needs_poll == k.process.is_some() {
        let want = if needs_poll { "a poll function and no process" } else { "a process function and no poll" };
        return Err(bad(format!("a {word} has {want}")));
    }
    if role != Role::Processor && k.flush.is_some() {
        return Err(bad(format!("a {word} has no flush function (only processors are flushed at end of stream)")));
    }
    if role == Role::Source && k.n_inputs != 0 {
        return Err(bad(format!("a source has no inputs (it declares {})", k.n_inputs)));
    }
    if role == Role::Source && k.n_outputs == 0 {
        return Err(bad("a source needs at least one output".into()));
    }
    if role == Role::Sink && k.n_outputs != 0 {
        return Err(bad(format!("a sink has no outputs (it declares {})", k.n_outputs)));
    }
    if role == Role::Sink && k.n_inputs == 0 {
        return Err(bad("a sink needs at least one input".into()));
    }
    if k.export_state.is_some() && k.import_state.is_none() {
        return Err(bad(format!(
            "a {word} with an export_state function needs an import_state function (when a hot swap is refused, the running instance takes its own state back)"
        )));
    }
    Ok(role)
}

/// Reads one kind's description and finds codecs for its ports; `plugin` is the library's name.
fn read_kind(path: &Path, origin: &str, plugin: &str, k: &SfKind, codecs: &Codecs) -> Result<PluginKind, PluginError> {
    let name = text(path, "a kind name", k.name)?;
    let role = role(path, &name, k)?;
    let mut info = KindInfo {
        name: Cow::Owned(name.clone()),
        doc: Cow::Owned(text(path, &format!("kind \"{name}\" doc"), k.doc)?),
        role,
        inputs: Vec::new(),
        outputs: Vec::new(),
        params: Vec::new(),
        origin: Cow::Owned(origin.to_owned()),
    };
    // SAFETY (three calls): arrays in the checked table, static in the mapped library.
    for p in unsafe { items(k.inputs, k.n_inputs) } {
        info.inputs.push(port_spec(path, &name, p, true)?);
    }
    for p in unsafe { items(k.outputs, k.n_outputs) } {
        info.outputs.push(port_spec(path, &name, p, false)?);
    }
    for p in unsafe { items(k.params, k.n_params) } {
        let pname = text(path, &format!("kind \"{name}\" param name"), p.name)?;
        let what = |f: &str| format!("kind \"{name}\" param \"{pname}\" {f}");
        let ty = text(path, &what("type"), p.ty)?;
        let refused = |problem: String| PluginError::Kind { path: path.to_path_buf(), kind: name.clone(), problem };
        if ty == format!("[{SENSOR}]") {
            return Err(refused(format!(
                "param \"{pname}\": type \"{ty}\" is not allowed: a node's frames come from one sensor (declare \"{SENSOR}\")"
            )));
        }
        if !is_param_type(&ty) {
            return Err(refused(format!(
                "param \"{pname}\": unknown type \"{ty}\" (known: {}, or an array of one, e.g. [string])",
                PARAM_TYPES.join(", ")
            )));
        }
        if ty == SENSOR
            && let Some(first) = info.params.iter().find(|d| d.ty == SENSOR)
        {
            return Err(refused(format!(
                "param \"{pname}\": a second param of type \"{SENSOR}\" (\"{}\" is one): a node's frames come from one sensor",
                first.name
            )));
        }
        info.params.push(ParamDoc {
            ty: Cow::Owned(ty),
            default: Cow::Owned(text(path, &what("default"), p.default)?),
            doc: Cow::Owned(text(path, &what("doc"), p.doc)?),
            name: Cow::Owned(pname),
        });
    }
    let codec = |port: &PortSpec, dir: &str| {
        codecs.get(&port.ty).ok_or_else(|| PluginError::NoCodec {
            path: path.to_path_buf(),
            kind: name.clone(),
            port: format!("{dir} \"{}\"", port.name),
            ty: port.ty.to_string(),
            known: codecs.names().collect::<Vec<_>>().join(", "),
        })
    };
    let in_codecs = info.inputs.iter().map(|p| codec(p, "input")).collect::<Result<_, _>>()?;
    let out_codecs: Vec<MakeCodec> = info.outputs.iter().map(|p| codec(p, "output")).collect::<Result<_, _>>()?;
    if role == Role::Source {
        // A source has no inputs to take provenance from: each output must decode from its
        // columns alone.
        for (p, make) in info.outputs.iter().zip(&out_codecs) {
            if make().needs_provenance() {
                let standalone: Vec<&str> =
                    codecs.names().filter(|t| !codecs.get(t).is_some_and(|m| m().needs_provenance())).collect();
                return Err(PluginError::Kind {
                    path: path.to_path_buf(),
                    kind: name.clone(),
                    problem: format!(
                        "output \"{}\": a source cannot emit \"{}\" (its payload is derived from inputs a source does not have; a source can emit: {})",
                        p.name,
                        p.ty,
                        standalone.join(", ")
                    ),
                });
            }
        }
    }
    let fns = KindFns {
        check: k.check,
        create: k.create,
        process: k.process,
        poll: k.poll,
        flush: k.flush,
        stop: k.stop,
        destroy: k.destroy,
        control: k.control,
        export_state: k.export_state,
        import_state: k.import_state,
    };
    Ok(PluginKind { info, fns, in_codecs, out_codecs, plugin: plugin.to_owned(), library: None })
}

/// Reads a table into kinds: checks the ABI, copies the descriptions, finds the codecs.
/// `table` must be a plugin entry point's result (or an in-binary `export::Table`'s).
pub fn read_table(path: &Path, table: &SfPlugin, codecs: &Codecs) -> Result<Vec<PluginKind>, PluginError> {
    check_abi(path, table)?;
    let origin = path.display().to_string();
    let plugin = text(path, "the plugin name", table.name)?;
    // SAFETY: the kinds array of the checked table.
    let raw_kinds = unsafe { items(table.kinds, table.n_kinds) };
    if raw_kinds.is_empty() {
        return Err(PluginError::Invalid { path: path.to_path_buf(), problem: "it exports no kinds".into() });
    }
    let mut kinds: Vec<PluginKind> = Vec::with_capacity(raw_kinds.len());
    for k in raw_kinds {
        let kind = read_kind(path, &origin, &plugin, k, codecs)?;
        if kinds.iter().any(|o| o.info.name == kind.info.name) {
            return Err(PluginError::DuplicateKind {
                path: path.to_path_buf(),
                kind: kind.info.name.to_string(),
                existing: origin,
            });
        }
        kinds.push(kind);
    }
    Ok(kinds)
}

/// Registers kinds read from `path` (all or none); returns their names.
pub fn register_kinds(
    path: &Path,
    kinds: Vec<PluginKind>,
    registry: &mut Registry,
) -> Result<Vec<String>, PluginError> {
    for k in &kinds {
        if let Some(f) = registry.get(&k.info.name) {
            let existing = f.info().origin.to_string();
            return Err(PluginError::DuplicateKind {
                path: path.to_path_buf(),
                kind: k.info.name.to_string(),
                existing,
            });
        }
    }
    let names: Vec<String> = kinds.iter().map(|k| k.info.name.to_string()).collect();
    for k in kinds {
        registry.register(Arc::new(PluginFactory(Arc::new(k)))).map_err(|d| PluginError::DuplicateKind {
            path: path.to_path_buf(),
            kind: d.kind,
            existing: d.existing_origin,
        })?;
    }
    Ok(names)
}

/// The table an entry point returned, as a reference once its two leading fields say it has
/// this host's layout: the ABI version (`head[0]`) and its own size (`head[1]`, the plugin's
/// `size_of::<SfPlugin>()`). Those two fields never move between ABI versions; nothing else of
/// the table is read before both match, and a table of the same version but another size (a
/// smaller one would end before the reference's last byte) is refused, not read.
///
/// # Safety
/// `table` must be non-null and point at an entry point's table (at least its two leading
/// `u32`s readable, all of the `plugin_size` bytes it declares readable) that stays valid for
/// `'a`.
unsafe fn table_ref<'a>(path: &Path, table: *const SfPlugin) -> Result<&'a SfPlugin, PluginError> {
    if !table.is_aligned() {
        return Err(PluginError::Invalid {
            path: path.to_path_buf(),
            problem: format!("its table at {table:p} is not aligned to {} bytes", align_of::<SfPlugin>()),
        });
    }
    // SAFETY: non-null and aligned (so aligned for `u32`), and the caller guarantees the two
    // leading fields are readable.
    let head = unsafe { std::ptr::read(table.cast::<[u32; 2]>()) };
    if head[0] != ABI_VERSION {
        return Err(PluginError::AbiVersion { path: path.to_path_buf(), found: head[0], expected: ABI_VERSION });
    }
    let (what, expected) = sizes()[0];
    if head[1] != expected {
        return Err(PluginError::StructSize { path: path.to_path_buf(), what, found: head[1], expected });
    }
    // SAFETY: aligned, and the plugin declares `size_of::<SfPlugin>()` readable bytes, laid out
    // as this version's `SfPlugin` (its other sizes and fields are checked by `read_table`),
    // valid for `'a` (the caller's guarantee).
    Ok(unsafe { &*table })
}

/// Loads the plugin at `path` and registers its kinds (all or none).
pub fn load(path: &Path, registry: &mut Registry, codecs: &Codecs) -> Result<Loaded, PluginError> {
    if !path.is_file() {
        let what = match std::fs::metadata(path) {
            Err(_) => "file not found",
            Ok(m) if m.is_dir() => "is a directory, not a library",
            Ok(_) => "is not a regular file (a device or a FIFO), not a library",
        };
        return Err(PluginError::Missing { path: path.to_path_buf(), what });
    }
    let lib = open_copy(path)?;
    // SAFETY: the symbol, when present, is the SDK's entry point with this signature (the
    // name is reserved for it); a library exporting it otherwise is not a skinflow plugin and
    // the ABI checks below reject what they can.
    let entry: EntryFn = match unsafe { lib.get::<EntryFn>(ENTRY_SYMBOL) } {
        Ok(sym) => *sym,
        Err(_) => {
            return Err(PluginError::NotAPlugin { path: path.to_path_buf() });
        }
    };
    // SAFETY: the entry point never unwinds (it catches panics) and returns a pointer to a
    // table that lives as long as the library, or null.
    let table = unsafe { entry() };
    if table.is_null() {
        return Err(PluginError::Entry { path: path.to_path_buf() });
    }
    // SAFETY: non-null (checked above), and the entry point's result is a table static in
    // the library (all the bytes its `plugin_size` declares: the export macro writes it), which
    // stays mapped while `lib` lives (all of this function).
    let t = unsafe { table_ref(path, table) }?;
    let mut kinds = read_table(path, t, codecs)?;
    let library = Arc::new(PluginLibrary {
        path: path.to_path_buf(),
        name: text(path, "the plugin name", t.name)?,
        version: text(path, "the plugin version", t.version)?,
        _lib: lib,
    });
    for k in &mut kinds {
        k.library = Some(library.clone());
    }
    let names = register_kinds(path, kinds, registry)?;
    tracing::info!(plugin = %library.name, version = %library.version, path = %path.display(), kinds = ?names, "plugin loaded");
    Ok(Loaded { library, kinds: names })
}

/// Loads every plugin in order; stops at the first failure.
pub fn load_all(paths: &[PathBuf], registry: &mut Registry, codecs: &Codecs) -> Result<Vec<Loaded>, PluginError> {
    // One library named twice (under any spelling) would define each of its kinds twice.
    let same = |a: &Path, b: &Path| match (a.canonicalize(), b.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => a == b,
    };
    for (k, path) in paths.iter().enumerate() {
        if let Some(first) = paths[..k].iter().find(|p| same(p, path)) {
            return Err(PluginError::Twice { path: path.clone(), first: first.clone() });
        }
    }
    paths.iter().map(|p| load(p, registry, codecs)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The two leading fields alone, aligned as a table: what a same-version plugin with a
    /// smaller table would return.
    #[repr(C)]
    struct Head {
        _align: [SfPlugin; 0],
        abi_version: u32,
        plugin_size: u32,
    }

    fn table(abi_version: u32, plugin_size: u32) -> SfPlugin {
        let [_, kind_size, port_size, param_size, message_size, column_size, poll_size, state_size] =
            sizes().map(|(_, n)| n);
        SfPlugin {
            abi_version,
            plugin_size,
            kind_size,
            port_size,
            param_size,
            message_size,
            column_size,
            poll_size,
            state_size,
            name: SfStr::new("test"),
            version: SfStr::new("0"),
            kinds: std::ptr::null(),
            n_kinds: 0,
        }
    }

    #[test]
    fn a_table_smaller_than_this_versions_is_refused_before_a_reference_to_it_is_formed() {
        let path = Path::new("short.so");
        let head = Head { _align: [], abi_version: ABI_VERSION, plugin_size: size_of::<Head>() as u32 };
        assert_eq!(size_of::<Head>(), 8);
        // SAFETY: the two leading fields are readable and nothing past them is read when the
        // declared size differs from this host's (what this test checks).
        let e = unsafe { table_ref(path, std::ptr::from_ref(&head).cast()) }.unwrap_err();
        let expected = size_of::<SfPlugin>() as u32;
        assert!(
            matches!(e, PluginError::StructSize { what: "SfPlugin", found: 8, expected: x, .. } if x == expected),
            "{e:?}"
        );
        assert!(
            e.to_string().contains(&format!("struct SfPlugin is 8 bytes in the plugin but {expected} in the host"))
        );

        // The version is checked first: a table of another version is never measured.
        let old = Head { _align: [], abi_version: ABI_VERSION - 1, plugin_size: 8 };
        // SAFETY: as above.
        let e = unsafe { table_ref(path, std::ptr::from_ref(&old).cast()) }.unwrap_err();
        assert!(matches!(e, PluginError::AbiVersion { found, .. } if found == ABI_VERSION - 1), "{e:?}");

        // A whole table of this version and size is read.
        let whole = table(ABI_VERSION, expected);
        // SAFETY: a whole table, alive for the call.
        let t = unsafe { table_ref(path, &raw const whole) }.unwrap();
        assert_eq!((t.abi_version, t.plugin_size, t.n_kinds), (ABI_VERSION, expected, 0));
    }

    /// A processor whose params are `sensor`-typed as `SENSORS` says: 1, one `sensor`; 2, two;
    /// 3, one `[sensor]`.
    struct Board<const SENSORS: u8>;

    impl<const SENSORS: u8> crate::PluginNode for Board<SENSORS> {
        type Params = toml::Table;

        fn spec() -> crate::KindSpec {
            let k = crate::KindSpec::new("test-board", "frames of a sensor")
                .input("in", "count", "a count")
                .output("out", "count", "the count")
                .param("rate", "float", "1", "not a sensor");
            match SENSORS {
                1 => k.param("sensor", SENSOR, "none", "the sensor"),
                2 => k.param("sensor", SENSOR, "none", "the sensor").param("other", SENSOR, "none", "another"),
                _ => k.param("sensors", "[sensor]", "[]", "sensors"),
            }
        }

        fn new(_: toml::Table, _: &Path) -> Result<Self, String> {
            Ok(Board)
        }

        fn process(&mut self, _: &[crate::Columns<'_>], _: &mut crate::Outputs) -> Result<(), String> {
            Ok(())
        }
    }

    /// What the host makes of the table of the one kind `Board<SENSORS>`.
    fn read_board<const SENSORS: u8>() -> Result<Vec<PluginKind>, PluginError> {
        static TABLES: [std::sync::OnceLock<crate::export::Table>; 3] =
            [std::sync::OnceLock::new(), std::sync::OnceLock::new(), std::sync::OnceLock::new()];
        let cell = &TABLES[usize::from(SENSORS) - 1];
        // SAFETY: `entry` points at the static table in `cell`.
        let table =
            unsafe { &*crate::export::entry(cell, "test", "0", || vec![crate::export::kind::<Board<SENSORS>>()]) };
        read_table(Path::new("libtest.so"), table, &Codecs::new())
    }

    #[test]
    fn one_sensor_param_is_read_and_a_second_or_an_array_of_them_refused() {
        let kinds = read_board::<1>().expect("one sensor param loads");
        let params: Vec<(&str, &str)> = kinds[0].info.params.iter().map(|p| (p.name.as_ref(), p.ty.as_ref())).collect();
        assert_eq!(params, [("rate", "float"), ("sensor", "sensor")]);

        let e = read_board::<2>().err().expect("two sensor params are refused").to_string();
        assert_eq!(
            e,
            "plugin libtest.so: kind \"test-board\": param \"other\": a second param of type \"sensor\" (\"sensor\" \
             is one): a node's frames come from one sensor"
        );
        let e = read_board::<3>().err().expect("an array of sensors is refused").to_string();
        assert_eq!(
            e,
            "plugin libtest.so: kind \"test-board\": param \"sensors\": type \"[sensor]\" is not allowed: a node's \
             frames come from one sensor (declare \"sensor\")"
        );
    }

    #[test]
    fn a_misaligned_table_is_refused_unread() {
        let whole = [table(ABI_VERSION, size_of::<SfPlugin>() as u32), table(ABI_VERSION, 0)];
        // Four bytes into the first table: readable, but not where a table can start.
        let p = std::ptr::from_ref(&whole).cast::<u8>().wrapping_add(4).cast::<SfPlugin>();
        // SAFETY: more than a table's bytes are readable from `p`; it is refused before any read.
        let e = unsafe { table_ref(Path::new("odd.so"), p) }.unwrap_err();
        assert!(e.to_string().contains("is not aligned"), "{e}");
    }
}
