//! The run-time hooks (ABI version 4) between the host and the SDK's export code, on tables
//! built in this binary (the same bytes a plugin's entry point returns): control commands
//! (applied, refused with the node and kind named, not supported), a hot swap's state as bytes
//! (the same kind of a library loaded again from another path takes it byte for byte; another
//! kind's, another plugin's, another format's or a built-in node's state starts afresh with the
//! reason; a replacement may refuse the swap; a panic taking a state over is the replacement's
//! panic), a table without the hooks, and, through the engine, a processor's held messages
//! emitted by its replacement with their provenance. Built libraries (the example plugins, a
//! swap between two loads of one library) are run in the workspace's tests/plugins.rs.

use crate::common;

use std::collections::VecDeque;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::SeqCst};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};

use serde::Deserialize;
use skinflow_core::graph::SourceFile;
use skinflow_core::{
    BuildContext, Context, GraphSpec, Mode, NodeError, NodeFactory, NodeImpl, NodeParams, NodeState, Outputs, Params,
    RunOptions, RunningGraph, Source, SourcePoll, StateRefused, typed,
};
use skinflow_plugin_sdk::abi::SfPlugin;
use skinflow_plugin_sdk::export::{KindEntry, Table, entry, kind, sink};
use skinflow_plugin_sdk::host::{Codecs, PluginFactory, PluginState, read_table, register_kinds};
use skinflow_plugin_sdk::{
    Columns, Flush, ImportOutcome, KindSpec, Outputs as PluginOutputs, PluginNode, PluginSink, StateReader, StateWriter,
};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct NoParams {}

/// `t-tally`: passes its input through plus a tally set by control commands (`add N`); hands
/// the tally over (one u64, format 1).
struct Tally(u64);

fn read_u64(bytes: &[u8]) -> Result<u64, String> {
    let mut r = StateReader::new(bytes);
    let v = r.u64()?;
    r.finish()?;
    Ok(v)
}

impl PluginNode for Tally {
    type Params = NoParams;

    fn spec() -> KindSpec {
        KindSpec::new("t-tally", "value + tally; `add N` adds to the tally").input("in", "count", "a count").output(
            "out",
            "count",
            "value + tally",
        )
    }

    fn new(_: NoParams, _: &Path) -> Result<Self, String> {
        Ok(Tally(0))
    }

    fn process(&mut self, inputs: &[Columns<'_>], out: &mut PluginOutputs) -> Result<(), String> {
        out.port(0).scalar("value", inputs[0].scalar("value")? + self.0 as f64);
        Ok(())
    }

    fn control(&mut self, cmd: &str) -> Result<(), String> {
        match cmd.split_whitespace().collect::<Vec<_>>()[..] {
            ["add", n] => {
                self.0 += n.parse::<u64>().map_err(|_| format!("add: \"{n}\" is not a count"))?;
                Ok(())
            }
            ["boom"] => panic!("boom on command"),
            _ => Err(format!("unknown command \"{cmd}\" (t-tally takes: add N)")),
        }
    }

    fn export_state(&mut self) -> Option<Vec<u8>> {
        Some(StateWriter::new().u64(self.0).finish())
    }

    fn import_state(&mut self, bytes: &[u8]) -> ImportOutcome {
        match read_u64(bytes) {
            Ok(v) => {
                self.0 = v;
                ImportOutcome::Accepted
            }
            Err(e) => ImportOutcome::StartAfresh(format!("not a tally: {e}")),
        }
    }
}

/// `t-tally` as a later build writes it: another state format.
struct TallyV2(Tally);

impl PluginNode for TallyV2 {
    type Params = NoParams;
    const STATE_FORMAT: u32 = 2;

    fn spec() -> KindSpec {
        Tally::spec()
    }

    fn new(p: NoParams, base_dir: &Path) -> Result<Self, String> {
        Tally::new(p, base_dir).map(TallyV2)
    }

    fn process(&mut self, inputs: &[Columns<'_>], out: &mut PluginOutputs) -> Result<(), String> {
        self.0.process(inputs, out)
    }

    fn export_state(&mut self) -> Option<Vec<u8>> {
        self.0.export_state()
    }

    fn import_state(&mut self, bytes: &[u8]) -> ImportOutcome {
        self.0.import_state(bytes)
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct OtherParams {
    /// What `import_state` does: "accept", "refuse" (the swap) or "panic".
    on_import: String,
}

/// `t-other`: a pass-through with a state in `t-tally`'s encoding (one u64, format 1); no
/// control command.
struct Other {
    on_import: String,
    v: u64,
}

impl PluginNode for Other {
    type Params = OtherParams;

    fn spec() -> KindSpec {
        KindSpec::new("t-other", "value").input("in", "count", "a count").output("out", "count", "the count")
    }

    fn new(p: OtherParams, _: &Path) -> Result<Self, String> {
        Ok(Other { on_import: p.on_import, v: 41 })
    }

    fn process(&mut self, inputs: &[Columns<'_>], out: &mut PluginOutputs) -> Result<(), String> {
        out.port(0).scalar("value", inputs[0].scalar("value")?);
        Ok(())
    }

    fn export_state(&mut self) -> Option<Vec<u8>> {
        Some(StateWriter::new().u64(self.v).finish())
    }

    fn import_state(&mut self, bytes: &[u8]) -> ImportOutcome {
        match self.on_import.as_str() {
            "refuse" => ImportOutcome::RefuseSwap("t-other cannot go on from another instance".into()),
            "panic" => panic!("t-other import panic"),
            _ => {
                self.v = read_u64(bytes).unwrap_or(0);
                ImportOutcome::Accepted
            }
        }
    }
}

/// A table of plugin `name`, built once in `cell`.
fn table(cell: &'static OnceLock<Table>, name: &'static str, kinds: fn() -> Vec<KindEntry>) -> &'static SfPlugin {
    // SAFETY: `entry` returned a pointer into `cell`'s table, which lives for the program
    // (non-null: building it did not panic).
    unsafe { &*entry(cell, name, "0", kinds) }
}

fn hooks() -> &'static SfPlugin {
    static T: OnceLock<Table> = OnceLock::new();
    table(&T, "hooks", || vec![kind::<Tally>(), kind::<Other>()])
}

/// Kind `kind` of `table`, as loaded from library file `lib`.
fn factory(table: &SfPlugin, lib: &str, kind: &str) -> PluginFactory {
    let kinds = read_table(Path::new(lib), table, &Codecs::new()).expect("a valid table");
    PluginFactory(Arc::new(kinds.into_iter().find(|k| k.info.name == kind).expect("the kind")))
}

/// A node `id` of `kind` of `table` loaded from `lib`, with `params`.
fn node(table: &SfPlugin, lib: &str, kind: &str, params: &str) -> NodeImpl {
    let ctx = BuildContext::new(".", Mode::Lockstep, "n");
    factory(table, lib, kind).build(&Params::from_toml(params).unwrap(), &ctx).expect("builds")
}

fn ctx() -> Context {
    Context::detached("n", Mode::Lockstep)
}

fn control(n: &mut NodeImpl, cmd: &str) -> Result<(), String> {
    let ctx = &mut ctx();
    match n {
        NodeImpl::Processor(p) => p.control(ctx, cmd),
        NodeImpl::Source(s) => s.control(ctx, cmd),
        NodeImpl::Sink(s) => s.control(ctx, cmd),
    }
    .map_err(|e| e.to_string())
}

fn export(n: &mut NodeImpl) -> Option<NodeState> {
    let ctx = &mut ctx();
    match n {
        NodeImpl::Processor(p) => p.export_state(ctx),
        NodeImpl::Source(s) => s.export_state(ctx),
        NodeImpl::Sink(s) => s.export_state(ctx),
    }
}

fn import(n: &mut NodeImpl, state: NodeState) -> Result<(), StateRefused> {
    let ctx = &mut ctx();
    match n {
        NodeImpl::Processor(p) => p.import_state(ctx, state),
        NodeImpl::Source(s) => s.import_state(ctx, state),
        NodeImpl::Sink(s) => s.import_state(ctx, state),
    }
}

/// The tally a `t-tally` node hands over.
fn tally_of(n: &mut NodeImpl) -> u64 {
    let state = export(n).expect("t-tally exports its tally");
    read_u64(state.downcast_ref::<PluginState>().expect("a plugin state").bytes()).unwrap()
}

#[test]
fn a_command_is_applied_and_a_bad_one_is_refused_naming_node_and_kind() {
    let mut n = node(hooks(), "liba.so", "t-tally", "");
    control(&mut n, "add 5").unwrap();
    control(&mut n, "add 7").unwrap();
    assert_eq!(tally_of(&mut n), 12);
    assert_eq!(
        control(&mut n, "add x").unwrap_err(),
        "plugin kind \"t-tally\" (liba.so): node \"n\": add: \"x\" is not a count"
    );
    assert_eq!(
        control(&mut n, "reset").unwrap_err(),
        "plugin kind \"t-tally\" (liba.so): node \"n\": unknown command \"reset\" (t-tally takes: add N)"
    );
    assert_eq!(tally_of(&mut n), 12, "a refused command changes nothing");
    // A kind that does not implement `control` refuses every command (the SDK's default).
    let mut other = node(hooks(), "liba.so", "t-other", "on_import = \"accept\"");
    assert_eq!(
        control(&mut other, "add 1").unwrap_err(),
        "plugin kind \"t-other\" (liba.so): node \"n\": control command \"add 1\" is not supported: this kind takes no control commands"
    );
}

#[test]
fn a_panic_in_a_command_is_its_error_and_the_instance_is_unusable_after_it() {
    let mut n = node(hooks(), "liba.so", "t-tally", "");
    let e = control(&mut n, "boom").unwrap_err();
    assert!(e.starts_with("plugin kind \"t-tally\" (liba.so): node \"n\": control: panicked: boom on command"), "{e}");
    assert!(e.ends_with("(the instance is unusable: its next call fails as the node's panic)"), "{e}");
    let e = control(&mut n, "add 1").unwrap_err();
    assert!(e.contains("an earlier call panicked: the instance is unusable"), "{e}");
    assert!(export(&mut n).is_none(), "the state of a panicked instance is not handed over");
}

#[test]
fn the_same_kind_of_a_library_loaded_again_takes_the_state_byte_for_byte() {
    let mut old = node(hooks(), "liba.so", "t-tally", "");
    control(&mut old, "add 12").unwrap();
    let state = export(&mut old).unwrap();
    let s = state.downcast_ref::<PluginState>().unwrap();
    assert_eq!((s.plugin(), s.kind(), s.origin(), s.format()), ("hooks", "t-tally", "liba.so", 1));
    assert_eq!(s.bytes(), StateWriter::new().u64(12).finish());
    // Loaded again from another file (a rebuilt library): the same plugin and kind.
    let mut new = node(hooks(), "rebuilt/liba.so", "t-tally", "");
    import(&mut new, state).unwrap();
    assert_eq!(tally_of(&mut new), 12);
}

#[test]
fn another_kinds_plugins_or_formats_state_starts_afresh_with_the_reason() {
    let mut tally = node(hooks(), "liba.so", "t-tally", "");
    control(&mut tally, "add 3").unwrap();

    // Another kind of the same plugin, whose import would read this encoding.
    let mut other = node(hooks(), "liba.so", "t-other", "on_import = \"accept\"");
    let refused = import(&mut other, export(&mut tally).unwrap()).unwrap_err();
    assert!(!refused.swap_refused);
    assert_eq!(
        refused.reason,
        "plugin kind \"t-other\" (liba.so): the state is of kind \"t-tally\" of plugin \"hooks\" (liba.so), this node is of kind \"t-other\" of plugin \"hooks\": a node takes over only its own kind's state"
    );
    assert_eq!(tally_of(&mut other), 41, "t-other kept its own state");
    // The refused state goes back whole: the running instance takes it back.
    import(&mut tally, refused.state).unwrap();
    assert_eq!(tally_of(&mut tally), 3);

    // The same kind name in another plugin.
    static ELSEWHERE: OnceLock<Table> = OnceLock::new();
    let mut elsewhere = node(table(&ELSEWHERE, "elsewhere", || vec![kind::<Tally>()]), "libe.so", "t-tally", "");
    let refused = import(&mut elsewhere, export(&mut tally).unwrap()).unwrap_err();
    assert!(!refused.swap_refused);
    assert!(
        refused
            .reason
            .contains("of plugin \"hooks\" (liba.so), this node is of kind \"t-tally\" of plugin \"elsewhere\"")
    );
    assert_eq!(tally_of(&mut elsewhere), 0);

    // The same kind, a build with another state format.
    static V2: OnceLock<Table> = OnceLock::new();
    let mut v2 = node(table(&V2, "hooks", || vec![kind::<TallyV2>()]), "libv2.so", "t-tally", "");
    let refused = import(&mut v2, export(&mut tally).unwrap()).unwrap_err();
    assert!(!refused.swap_refused);
    assert_eq!(
        refused.reason,
        "plugin kind \"t-tally\" (libv2.so): the state is in format 1, this build of the kind reads format 2"
    );
    assert_eq!(tally_of(&mut v2), 0);

    // A built-in node's state.
    let refused = import(&mut tally, Box::new(7u32)).unwrap_err();
    assert!(!refused.swap_refused);
    assert_eq!(
        refused.reason,
        "plugin kind \"t-tally\" (liba.so): the state is not a plugin node's (a built-in kind's)"
    );
    assert_eq!(refused.state.downcast_ref::<u32>(), Some(&7), "given back as it came");
}

#[test]
fn a_replacement_may_refuse_the_swap_and_a_panic_taking_a_state_over_is_its_panic() {
    let mut running = node(hooks(), "liba.so", "t-other", "on_import = \"accept\"");
    let mut refusing = node(hooks(), "libb.so", "t-other", "on_import = \"refuse\"");
    let refused = import(&mut refusing, export(&mut running).unwrap()).unwrap_err();
    assert!(refused.swap_refused);
    assert_eq!(refused.reason, "plugin kind \"t-other\" (libb.so): t-other cannot go on from another instance");
    import(&mut running, refused.state).expect("the running instance takes its own state back");

    let mut panicking = node(hooks(), "libb.so", "t-other", "on_import = \"panic\"");
    let state = export(&mut running).unwrap();
    let p = catch_unwind(AssertUnwindSafe(|| import(&mut panicking, state))).expect_err("re-raised in the host");
    let msg = p.downcast_ref::<String>().expect("a message");
    assert_eq!(msg, "plugin kind \"t-other\" (libb.so): import_state: panicked: t-other import panic");
}

#[test]
fn a_kind_without_the_hooks_refuses_commands_and_hands_nothing_over() {
    static BARE: OnceLock<Table> = OnceLock::new();
    let bare = table(&BARE, "hooks", || vec![kind::<Tally>().without_hooks()]);
    let mut n = node(bare, "libbare.so", "t-tally", "");
    assert_eq!(
        control(&mut n, "add 1").unwrap_err(),
        "plugin kind \"t-tally\" (libbare.so): node \"n\": control command \"add 1\" is not supported: the kind has no control function (it takes no commands)"
    );
    assert!(export(&mut n).is_none());
    let mut with_hooks = node(hooks(), "liba.so", "t-tally", "");
    let refused = import(&mut n, export(&mut with_hooks).unwrap()).unwrap_err();
    assert!(!refused.swap_refused);
    assert_eq!(
        refused.reason,
        "plugin kind \"t-tally\" (libbare.so): the kind has no import_state function (it takes over no state)"
    );
}

#[test]
fn a_kind_that_exports_state_it_cannot_import_is_refused_at_load() {
    let mut t = *hooks();
    // SAFETY: the table's kinds array holds `n_kinds` kinds, static in this binary.
    let mut k = unsafe { *t.kinds };
    k.import_state = None;
    t.kinds = &k;
    t.n_kinds = 1;
    let e = read_table(Path::new("libhalf.so"), &t, &Codecs::new()).err().expect("refused").to_string();
    assert_eq!(
        e,
        "plugin libhalf.so: kind \"t-tally\": a processor with an export_state function needs an import_state function (when a hot swap is refused, the running instance takes its own state back)"
    );
}

// Through the engine: a processor holding derived messages is swapped mid-stream; its
// replacement (the same kind, loaded again) emits them at flush with their inputs' provenance.

/// `t-keep`: holds every input's header and emits them all at flush, as derived messages (the
/// host attaches each to its input); hands the held headers over.
struct Keep {
    held: VecDeque<(u64, u64)>,
}

impl PluginNode for Keep {
    type Params = NoParams;

    fn spec() -> KindSpec {
        KindSpec::new("t-keep", "holds every input; emits them at flush").input("in", "count", "a count").output(
            "out",
            "derived",
            "each input, at flush",
        )
    }

    fn new(_: NoParams, _: &Path) -> Result<Self, String> {
        Ok(Keep { held: VecDeque::new() })
    }

    fn process(&mut self, inputs: &[Columns<'_>], _: &mut PluginOutputs) -> Result<(), String> {
        self.held.push_back((inputs[0].seq(), inputs[0].t_ns()));
        Ok(())
    }

    fn flush(&mut self, out: &mut PluginOutputs) -> Result<Flush, String> {
        if let Some((seq, t_ns)) = self.held.pop_front() {
            out.port(0).header(seq, t_ns);
            out.port(0).scalar("from", 0.0); // the host takes the value from the provenance
        }
        Ok(if self.held.is_empty() { Flush::Done } else { Flush::More })
    }

    fn held(&self) -> u64 {
        self.held.len() as u64
    }

    fn export_state(&mut self) -> Option<Vec<u8>> {
        let mut w = StateWriter::new().u64(self.held.len() as u64);
        for (seq, t_ns) in std::mem::take(&mut self.held) {
            w = w.u64(seq).u64(t_ns);
        }
        Some(w.finish())
    }

    fn import_state(&mut self, bytes: &[u8]) -> ImportOutcome {
        let read = || -> Result<VecDeque<(u64, u64)>, String> {
            let mut r = StateReader::new(bytes);
            let n = r.u64()?;
            let held = (0..n).map(|_| Ok((r.u64()?, r.u64()?))).collect::<Result<_, String>>()?;
            r.finish()?;
            Ok(held)
        };
        match read() {
            Ok(held) => {
                self.held = held;
                ImportOutcome::Accepted
            }
            Err(e) => ImportOutcome::StartAfresh(format!("not a t-keep state: {e}")),
        }
    }
}

/// `t-seen`: records the provenance (`from`) of every derived message.
struct Seen;

fn seen() -> &'static Mutex<Vec<u64>> {
    static SEEN: Mutex<Vec<u64>> = Mutex::new(Vec::new());
    &SEEN
}

impl PluginSink for Seen {
    type Params = NoParams;

    fn spec() -> KindSpec {
        KindSpec::new("t-seen", "records derived messages").input("in", "derived", "messages")
    }

    fn new(_: NoParams, _: &Path) -> Result<Self, String> {
        Ok(Seen)
    }

    fn consume(&mut self, inputs: &[Columns<'_>]) -> Result<(), String> {
        seen().lock().unwrap().push(inputs[0].scalar("from")? as u64);
        Ok(())
    }
}

/// Holds a source once it has sent `limit` messages, until `open`.
#[derive(Default)]
struct Gate {
    limit: AtomicU64,
    open: AtomicBool,
    sent: AtomicU64,
    /// Polls answered while held.
    held: AtomicU64,
}

struct Gated {
    inner: Box<dyn Source>,
    gate: Arc<Gate>,
}

impl Source for Gated {
    fn poll(&mut self, ctx: &mut Context, out: &mut Outputs) -> Result<SourcePoll, NodeError> {
        let g = &self.gate;
        if !g.open.load(SeqCst) && g.sent.load(SeqCst) >= g.limit.load(SeqCst) {
            g.held.fetch_add(1, SeqCst);
            std::thread::yield_now();
            return Ok(SourcePoll::Idle);
        }
        let r = self.inner.poll(ctx, out)?;
        if r == SourcePoll::Emitted {
            g.sent.fetch_add(1, SeqCst);
        }
        Ok(r)
    }
}

#[derive(Deserialize)]
struct Pass {
    #[serde(flatten)]
    table: toml::Table,
}
impl NodeParams for Pass {}

#[test]
fn held_messages_handed_over_are_emitted_by_the_replacement_with_their_provenance() {
    static KEEP: OnceLock<Table> = OnceLock::new();
    let kinds = || vec![kind::<Keep>(), sink::<Seen>()];
    let mut reg = common::registry(&KEEP, "keep", "libkeep.so", kinds);
    let gate = Arc::new(Gate { limit: AtomicU64::new(6), ..Gate::default() });
    let counter = reg.get("counter").unwrap().clone();
    let mut info = counter.info().clone();
    info.name = "gated".into();
    let g = gate.clone();
    reg.register(typed(info, move |p: Pass, ctx: &BuildContext| {
        match counter.build(&Params::from_table(p.table), ctx)? {
            NodeImpl::Source(inner) => Ok(NodeImpl::Source(Box::new(Gated { inner, gate: g.clone() }))),
            _ => unreachable!("a source kind"),
        }
    }))
    .unwrap();
    // The same table loaded again, from another file: the replacement's kind.
    let mut again = skinflow_core::Registry::new();
    let mut codecs = Codecs::new();
    codecs.register("derived", common::Derived::codec);
    let rebuilt = read_table(Path::new("rebuilt/libkeep.so"), table(&KEEP, "keep", kinds), &codecs).unwrap();
    register_kinds(Path::new("rebuilt/libkeep.so"), rebuilt, &mut again).unwrap();

    let graph = "[graph]\nmode = \"lockstep\"\n\
        [[node]]\nid = \"src\"\nkind = \"gated\"\nparams = { count = 10, start = 1 }\n\
        [[node]]\nid = \"keep\"\nkind = \"t-keep\"\n[[node]]\nid = \"seen\"\nkind = \"t-seen\"\n\
        [[edge]]\nfrom = \"src.out\"\nto = \"keep.in\"\n[[edge]]\nfrom = \"keep.out\"\nto = \"seen.in\"\n";
    let spec = GraphSpec::parse(SourceFile::new("<keep>", graph.to_owned()), &reg).unwrap();
    let running = RunningGraph::start(&spec).unwrap();
    let handle = running.handle();
    let runner = std::thread::spawn(move || running.wait(&RunOptions::default()));
    // Held twice: the first six values went through (a lockstep pass drains).
    let t0 = Instant::now();
    while gate.held.load(SeqCst) < 2 {
        assert!(t0.elapsed() < Duration::from_secs(300), "the source was never held");
        std::thread::sleep(Duration::from_millis(5));
    }
    let factory = again.get("t-keep").unwrap().clone();
    handle.swap_wait("keep", factory, Params::default(), Duration::from_secs(300)).expect("installed");
    gate.open.store(true, SeqCst);
    let report = runner.join().unwrap();
    assert!(report.failures.is_empty(), "{:?}", report.failures);
    let keep = report.stats.nodes.iter().find(|n| n.id == "keep").unwrap();
    assert_eq!((keep.swaps, keep.errors, keep.discarded), (1, 0, 0), "{keep:?}");
    assert_eq!(*seen().lock().unwrap(), (1..=10).collect::<Vec<u64>>(), "every input once, with its own value");
}
