//! `eval --plugin LIB --lane SPEC`: lanes after the built-in nine, each a splitter and a
//! corrector given as a built-in strategy or a node kind (a plugin's), resolved against the
//! registry before any graph is built, so a lane that cannot run is refused naming its
//! `--lane`.

use std::path::{Path, PathBuf};

use anyhow::{Result, anyhow, bail};
use serde::Deserialize;
use skinflow_contact::StrategyKind;
use skinflow_core::Registry;
use skinflow_nodes::pipeline::{Lane, PipelineSpec, Stage};
use skinflow_nodes::split::SplitStrategy;

use super::LANES;

/// `--plugin` and `--lane`: lanes evaluated after the built-in nine.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct LaneArgs {
    /// Load this plugin library (repeatable; relative to the current directory), for --lane.
    #[arg(long = "plugin", value_name = "LIB")]
    pub plugins: Vec<PathBuf>,
    /// Add a lane after the built-in ones (repeatable), as inline TOML, e.g. 'name = "fused",
    /// correct = "fused-corrector", correct_params = { weight_pneumatic = 0.8 }'. Keys: name,
    /// split (a splitter strategy or node kind; default "proportional"), split_params, correct
    /// (a corrector strategy or node kind; default "pneumatic-locaware"), correct_params, label.
    #[arg(long = "lane", value_name = "TOML")]
    pub lanes: Vec<String>,
}

/// One `--lane`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct LaneArg {
    /// The lane's key in the JSON and its CSV column (`<name>_n`).
    name: String,
    /// A splitter strategy, or a node kind with a `contacts` input and a `split` output.
    #[serde(default = "default_split")]
    split: String,
    #[serde(default)]
    split_params: toml::Table,
    /// A corrector strategy, or a node kind with a `split` input and a `forces` output.
    #[serde(default = "default_correct")]
    correct: String,
    #[serde(default)]
    correct_params: toml::Table,
    /// Row label of the printed table (default: the name, with " (plugin)" for a plugin kind).
    label: Option<String>,
}

fn default_split() -> String {
    SplitStrategy::Proportional.name().to_owned()
}

fn default_correct() -> String {
    StrategyKind::PneumaticLocAware.name().to_owned()
}

/// The `--lane` text as a TOML document (`lane = { ... }`).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct LaneDoc {
    lane: LaneArg,
}

/// A `--lane`, resolved against the registry.
#[derive(Debug, Clone)]
struct ExtraLane {
    /// As given on the command line.
    text: String,
    lane: Lane,
    label: String,
    /// The files its nodes' params name (a calibration, a plugin's `path`-typed params), as
    /// (`split_params.x` or `correct_params.x`, path relative to the current directory).
    files: Vec<(String, PathBuf)>,
}

/// The lanes after the built-in nine, and the plugin libraries their kinds come from.
#[derive(Debug, Clone, Default)]
pub struct ExtraLanes {
    plugins: Vec<PathBuf>,
    lanes: Vec<ExtraLane>,
}

/// Which node of a lane a stage is.
#[derive(Clone, Copy)]
enum Role {
    Split,
    Correct,
}

impl Role {
    /// The key of `--lane` naming it.
    fn key(self) -> &'static str {
        match self {
            Role::Split => "split",
            Role::Correct => "correct",
        }
    }

    /// (its built-in kind, what it is, its input type, its output type).
    fn shape(self) -> (&'static str, &'static str, &'static str, &'static str) {
        match self {
            Role::Split => ("splitter", "a splitter", "contacts", "split"),
            Role::Correct => ("corrector", "a corrector", "split", "forces"),
        }
    }

    /// The built-in kind's `strategy` values.
    fn strategies(self) -> Vec<&'static str> {
        match self {
            Role::Split => SplitStrategy::ALL.iter().map(|s| s.name()).collect(),
            Role::Correct => StrategyKind::ALL.iter().map(|k| k.name()).collect(),
        }
    }
}

impl ExtraLanes {
    /// Loads the `--plugin` libraries and resolves every `--lane` (refused, naming it, when its
    /// TOML, its name, a kind or a kind's ports do not fit). `calib` is passed to a kind that
    /// declares a `calibration` param the lane does not set.
    pub fn resolve(args: &LaneArgs, calib: &Path) -> Result<ExtraLanes> {
        let mut registry = skinflow_nodes::registry();
        if let Err(e) = skinflow_nodes::codec::load_plugins(&args.plugins, &mut registry) {
            let hint = if args.plugins.iter().any(|p| !p.exists()) {
                " (relative to the current directory; not built yet? `cargo build --workspace` builds this workspace's \
                 plugins into target/debug/)"
            } else {
                ""
            };
            bail!("--plugin: {e}{hint}");
        }
        let mut lanes: Vec<ExtraLane> = Vec::with_capacity(args.lanes.len());
        for text in &args.lanes {
            let lane = resolve_lane(text, &registry, calib, &lanes).map_err(|e| anyhow!("--lane '{text}': {e}"))?;
            lanes.push(lane);
        }
        Ok(ExtraLanes { plugins: args.plugins.clone(), lanes })
    }

    /// Every lane's (name, label): the built-in nine, then these.
    pub(super) fn labels(&self) -> Vec<(&str, &str)> {
        let builtin = LANES.iter().map(|(n, _, _, l)| (*n, *l));
        builtin.chain(self.lanes.iter().map(|l| (l.lane.name.as_str(), l.label.as_str()))).collect()
    }

    /// The pipeline's lanes and plugins (the calibration is set apart).
    pub(super) fn configure(&self, spec: &mut PipelineSpec) {
        spec.lanes = LANES.iter().map(|(n, s, c, _)| Lane::strategies(n, s, c)).collect();
        spec.lanes.extend(self.lanes.iter().map(|l| l.lane.clone()));
        spec.plugins = self.plugins.clone();
    }

    /// The files these lanes read (or name): the `--plugin` libraries and the files their
    /// nodes' params name, each with what it is for an error (`the --plugin library`, `file
    /// correct_params.calibration of --lane "x"`). Outputs of `eval` must be none of them.
    pub(super) fn files(&self) -> Vec<(String, &Path)> {
        let plugins = self.plugins.iter().map(|p| ("--plugin library".to_owned(), p.as_path()));
        let params = self.lanes.iter().flat_map(|l| {
            l.files.iter().map(move |(param, p)| (format!("file {param} of --lane \"{}\"", l.lane.name), p.as_path()))
        });
        plugins.chain(params).collect()
    }

    /// The calibrations lanes set themselves (a `calibration` param other than `--calib`), with
    /// the `--lane` text that sets each.
    pub(super) fn calibrations<'a>(&'a self, calib: &'a Path) -> Vec<(&'a str, &'a Path)> {
        let mut out: Vec<(&str, &Path)> = Vec::new();
        for l in &self.lanes {
            for (param, p) in &l.files {
                let own = param.ends_with(".calibration") && !super::super::paths::same_file(p, calib);
                if own && !out.iter().any(|(_, q)| super::super::paths::same_file(p, q)) {
                    out.push((l.text.as_str(), p.as_path()));
                }
            }
        }
        out
    }

    /// `--lane '<text>'` of the first of these lanes node `id` of `spec` is part of.
    pub(super) fn origin(&self, spec: &PipelineSpec, id: &str) -> Option<String> {
        let names = spec.lanes_of(id);
        let lane = self.lanes.iter().find(|l| names.contains(&l.lane.name.as_str()))?;
        Some(format!("--lane '{}'", lane.text))
    }
}

/// Whether `name` can be a lane's: a node id part and a JSON key and CSV column name.
fn valid_name(name: &str) -> bool {
    skinflow_toml::is_bare_key(name)
}

/// One `--lane` (errors without the `--lane '<text>'` prefix); `earlier` are the lanes before it.
fn resolve_lane(text: &str, registry: &Registry, calib: &Path, earlier: &[ExtraLane]) -> Result<ExtraLane> {
    // Syntax first (the text is the body of an inline table), then the keys.
    let doc = format!("lane = {{ {text} }}");
    let one_line = |m: &str| m.trim().replace('\n', "; ");
    let table: toml::Table =
        skinflow_toml::from_str(&doc).map_err(|e| anyhow!("not a TOML table body: {}", one_line(e.message())))?;
    if table.len() != 1 {
        bail!("not a TOML table body (key = value, ...)");
    }
    let LaneDoc { lane: arg } = skinflow_toml::deserialize(toml::Value::Table(table)).map_err(|e| {
        let m = one_line(e.message());
        let field = m.strip_prefix("lane: ").or_else(|| m.strip_prefix("lane.")).unwrap_or(&m);
        anyhow!("{field}")
    })?;
    let name = arg.name;
    if !valid_name(&name) {
        bail!("name \"{name}\": use ASCII letters, digits, '_' and '-'");
    }
    if LANES.iter().any(|(n, ..)| *n == name) {
        let builtin: Vec<&str> = LANES.iter().map(|(n, ..)| *n).collect();
        bail!("name \"{name}\" is a built-in lane's (built-in: {}); choose another", builtin.join(", "));
    }
    if let Some(other) = earlier.iter().find(|l| l.lane.name == name) {
        bail!("name \"{name}\" is also the name of --lane '{}'", other.text);
    }
    let mut files = Vec::new();
    let (split, split_plugin) = stage(Role::Split, &arg.split, arg.split_params, registry, calib, &name, &mut files)?;
    let (correct, correct_plugin) =
        stage(Role::Correct, &arg.correct, arg.correct_params, registry, calib, &name, &mut files)?;
    let label = arg
        .label
        .unwrap_or_else(|| if split_plugin || correct_plugin { format!("{name} (plugin)") } else { name.clone() });
    // Rows and plot panels are told apart by their labels.
    if label.trim().is_empty() {
        bail!("label is empty: rows of the table and panels of the plots are told apart by it");
    }
    if let Some((n, ..)) = LANES.iter().find(|(.., l)| *l == label) {
        bail!("label \"{label}\" is the built-in lane {n}'s; choose another");
    }
    if let Some(other) = earlier.iter().find(|l| l.label == label) {
        bail!("label \"{label}\" is also the label of --lane '{}'", other.text);
    }
    Ok(ExtraLane { text: text.to_owned(), lane: Lane { name, split, correct }, label, files })
}

/// Whether a param of type `ty` names files (`path`, `input-path`, `output-path`, `sensor`, or
/// an array of one of them).
fn names_files(ty: &str) -> bool {
    use skinflow_plugin_sdk::export::{INPUT_PATH, OUTPUT_PATH, PATH, SENSOR};
    let scalar = ty.strip_prefix('[').and_then(|t| t.strip_suffix(']')).unwrap_or(ty);
    [PATH, INPUT_PATH, OUTPUT_PATH, SENSOR].contains(&scalar)
}

/// A lane's splitter or corrector: a built-in strategy (`params` empty), else a node kind
/// whose ports fit, with `params` completed (`calibration`: `calib`; a corrector's `name`: the
/// lane's, when the kind declares them and the lane does not set them). Also whether the kind
/// is a plugin's.
fn stage(
    role: Role,
    what: &str,
    mut params: toml::Table,
    registry: &Registry,
    calib: &Path,
    lane: &str,
    files: &mut Vec<(String, PathBuf)>,
) -> Result<(Stage, bool)> {
    let (builtin_kind, a_role, in_ty, out_ty) = role.shape();
    let key = role.key();
    let strategies = role.strategies();
    let kind = if strategies.contains(&what) {
        if params.is_empty() {
            return Ok((Stage::Strategy(what.to_owned()), false));
        }
        if params.contains_key("strategy") {
            bail!("{key}_params sets \"strategy\": name the strategy with {key} = \"...\" instead");
        }
        // The built-in kind with that strategy and these params.
        params.insert("strategy".into(), toml::Value::String(what.to_owned()));
        builtin_kind
    } else {
        what
    };
    let Some(factory) = registry.get(kind) else {
        let plugin_kinds: Vec<&str> =
            registry.iter().map(|f| f.info()).filter(|k| k.origin != "built-in").map(|k| k.name.as_ref()).collect();
        let plugins = if plugin_kinds.is_empty() {
            "no plugin is loaded (load a library with --plugin LIB)".to_owned()
        } else {
            format!("plugin kinds: {} (another library: --plugin LIB)", plugin_kinds.join(", "))
        };
        bail!(
            "{key} \"{what}\": unknown: neither a {builtin_kind} strategy ({}) nor a node kind; {plugins}",
            strategies.join(", ")
        );
    };
    let info = factory.info();
    let plugin = info.origin != "built-in";
    let of = if plugin { format!(" (plugin {})", info.origin) } else { " (built-in)".to_owned() };
    let ports = |ports: &[skinflow_core::PortSpec]| -> String {
        if ports.is_empty() {
            "none".to_owned()
        } else {
            ports.iter().map(|p| format!("{} ({})", p.name, p.ty)).collect::<Vec<_>>().join(", ")
        }
    };
    let input = info.inputs.iter().find(|p| p.ty == in_ty);
    let output = info.outputs.iter().find(|p| p.ty == out_ty);
    let unfed = info.inputs.iter().find(|p| p.required && input.is_none_or(|i| i.name != p.name));
    let (Some(input), Some(output), None) = (input, output, unfed) else {
        bail!(
            "{key} \"{kind}\"{of} does not fit as {a_role}: {a_role} needs an input of type \"{in_ty}\" (and no other \
             required input) and an output of type \"{out_ty}\"; its inputs: {}; its outputs: {}",
            ports(&info.inputs),
            ports(&info.outputs)
        );
    };
    let declares = |param: &str| info.params.iter().any(|p| p.name == param);
    if declares("calibration") && !params.contains_key("calibration") {
        params.insert("calibration".into(), toml::Value::String(calib.to_string_lossy().into_owned()));
    }
    if matches!(role, Role::Correct) && declares("name") && !params.contains_key("name") {
        params.insert("name".into(), toml::Value::String(lane.to_owned()));
    }
    for doc in info.params.iter().filter(|d| names_files(&d.ty)) {
        let named: Vec<&str> = match params.get(doc.name.as_ref()) {
            Some(toml::Value::String(one)) => vec![one.as_str()],
            Some(toml::Value::Array(many)) => many.iter().filter_map(toml::Value::as_str).collect(),
            _ => Vec::new(),
        };
        let param = format!("{key}_params.{}", doc.name);
        files.extend(named.into_iter().filter(|f| !f.is_empty()).map(|f| (param.clone(), PathBuf::from(f))));
    }
    let stage =
        Stage::Node { kind: kind.to_owned(), params, input: input.name.to_string(), output: output.name.to_string() };
    Ok((stage, plugin))
}
