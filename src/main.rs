//! The `skinflow` command line: run, check, describe and render graphs (CONTRACTS.md section 3).

mod cmd;

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::{Context as _, Result, bail};
use clap::{Parser, Subcommand};
use skinflow_core::{GraphSpec, Registry, RunOptions, RunningGraph};

#[derive(Parser)]
#[command(
    name = "skinflow",
    version,
    about = "Dataflow engine and toolkit for dual-channel (EIT + pneumatic) robot skins"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Run a graph until its sources end, Ctrl-C, or the time is up; print per-node statistics.
    Run {
        graph: PathBuf,
        /// Stop after this many seconds.
        #[arg(long = "for", value_name = "SECONDS")]
        for_s: Option<f64>,
        /// Also write the statistics as JSON.
        #[arg(long, value_name = "FILE")]
        stats_json: Option<PathBuf>,
        /// Apply edits of the graph file to the running graph (changed nodes are swapped).
        #[arg(long)]
        watch: bool,
        /// Serve a control socket (Unix domain, JSON lines): stats, tare, control, swap.
        #[arg(long, value_name = "SOCKET")]
        control: Option<PathBuf>,
    },
    /// Validate a graph and open the input files its params name (read-only), without running
    /// it; errors name file, line and column.
    Check { graph: PathBuf },
    /// List every node kind with its ports, parameters and docs.
    Nodes {
        /// Also load this plugin library (repeatable).
        #[arg(long = "plugin", value_name = "LIB")]
        plugins: Vec<PathBuf>,
    },
    /// Run a graph's variants on one recording; write a speed-against-error table and Pareto plot.
    Bench {
        graph: PathBuf,
        /// Recording replayed by the graph's `replay` node.
        #[arg(long)]
        replay: PathBuf,
        /// NODE.PARAM=V1,V2,... (repeatable; every combination runs).
        #[arg(long = "vary", value_name = "NODE.PARAM=V1,V2")]
        vary: Vec<cmd::bench::Vary>,
        /// Output directory (bench.md, bench.json, pareto.png).
        #[arg(long, default_value = "out/bench")]
        out: PathBuf,
    },
    /// Send requests (JSON lines) to a graph run with `--control SOCKET`; print the replies.
    Send {
        socket: PathBuf,
        /// e.g. '{"cmd":"control","node":"loadcell","command":"at 12.5 -25"}' (one or more).
        #[arg(required = true, value_name = "JSON")]
        requests: Vec<String>,
    },
    /// Print a graph as Graphviz dot.
    Dot { graph: PathBuf },
    /// Simulate a scene and write it as a recording.
    Simulate {
        scene: PathBuf,
        #[arg(long)]
        out: PathBuf,
        /// Seed of the noise and drift.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Replace an existing output file.
        #[arg(long)]
        overwrite: bool,
    },
    /// Emulate the EIT board, pressure board and load cell on pseudo-terminals from a scene.
    Emulate {
        scene: PathBuf,
        #[command(flatten)]
        options: cmd::emulate::EmulateArgs,
    },
    /// Reproduce the paper's experiments on the simulated skin and write a Markdown report.
    Reproduce {
        /// Output directory (recordings, calibration, JSON, report.md).
        #[arg(long, default_value = "out/reproduce")]
        out: PathBuf,
        /// Directory of the scene files.
        #[arg(long, default_value = cmd::reproduce::DEFAULT_SCENES)]
        scenes: PathBuf,
        #[arg(long, default_value_t = 1)]
        seed: u64,
        #[command(flatten)]
        fit: cmd::calibrate::FitArgs,
        #[command(flatten)]
        pipeline: cmd::pipeline::PipelineArgs,
    },
    /// Summarise a recording: streams, counts, duration, rates, gaps, truth coverage.
    Inspect {
        recording: PathBuf,
        /// Print only the TOML of the graph that wrote the recording (its `graph` attribute)
        #[arg(long)]
        graph: bool,
    },
    /// Copy a recording whose last write was cut short (disk full, power loss, a killed logger),
    /// each table cut to the rows all its datasets hold; the input is never modified.
    Repair {
        recording: PathBuf,
        #[arg(long)]
        out: PathBuf,
        /// Replace an existing output file.
        #[arg(long)]
        overwrite: bool,
    },
    /// Fit the force calibration from single-contact recordings with ground truth (several are
    /// pooled, each reconstructed against its own no-load reference).
    Calibrate {
        #[arg(required = true, value_name = "RECORDING")]
        recordings: Vec<PathBuf>,
        #[arg(long)]
        out: PathBuf,
        #[command(flatten)]
        fit: cmd::calibrate::FitArgs,
        #[command(flatten)]
        pipeline: cmd::pipeline::PipelineArgs,
    },
    /// Run every force strategy on recordings with ground truth and print the comparison.
    Eval {
        /// Recordings with ground truth; several are pooled into one report.
        #[arg(required = true, value_name = "RECORDING")]
        recordings: Vec<PathBuf>,
        #[arg(long)]
        calib: PathBuf,
        /// Write the CONTRACTS.md JSON report here.
        #[arg(long)]
        json: Option<PathBuf>,
        /// Write PNG plots into this directory.
        #[arg(long)]
        plots: Option<PathBuf>,
        /// Write one CSV row per matched, missed or spurious contact (truth, EIT features, every strategy's force).
        #[arg(long, value_name = "CSV")]
        contacts_csv: Option<PathBuf>,
        #[command(flatten)]
        pipeline: cmd::pipeline::PipelineArgs,
        #[command(flatten)]
        lanes: cmd::eval::LaneArgs,
    },
}

fn main() -> ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        )
        .with_writer(std::io::stderr)
        // A log line that cannot be written (stderr a closed pipe: `2>&1 | head`) is dropped;
        // reporting that on the same stderr would panic, and the command has files to write.
        .log_internal_errors(false)
        // Colour codes only for a terminal, not in redirected logs.
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .init();
    let cli = Cli::parse();
    if cli.cmd.only_prints() {
        default_sigpipe();
    }
    match dispatch(cli.cmd) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(if e.is::<cmd::InvalidGraph>() { 2 } else { 1 })
        }
    }
}

impl Cmd {
    /// Commands whose only pipes are standard output and error: no user graph (whose nodes may
    /// write to sockets or devices), no control socket, no emulated device; and whose files, if
    /// any (`simulate`, `repair`), are written before anything is printed. `calibrate`, `eval`
    /// and `reproduce` print before or between their files: they print with
    /// [`cmd::print_or_warn`], so a closed output (`| head`) loses only the printed text.
    fn only_prints(&self) -> bool {
        matches!(
            self,
            Cmd::Check { .. }
                | Cmd::Nodes { .. }
                | Cmd::Dot { .. }
                | Cmd::Simulate { .. }
                | Cmd::Inspect { .. }
                | Cmd::Repair { .. }
        )
    }
}

/// Restores the default action of SIGPIPE, which Rust's runtime ignores: a closed standard
/// output (`skinflow eval ... | head -1`) then ends the process quietly, as it ends `cat`,
/// instead of a panic in `println!`. Not for commands that run user graphs or serve sockets:
/// there a peer that hangs up must be an error of one write, not the end of the process.
fn default_sigpipe() {
    // SAFETY: `signal` with SIG_DFL installs no handler code; it is called once, from `main`,
    // before any thread of this process is started, so no other thread observes the change.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

fn dispatch(cmd: Cmd) -> Result<ExitCode> {
    match cmd {
        Cmd::Run { graph, for_s, stats_json, watch, control } => {
            run(&graph, for_s, stats_json.as_deref(), watch, control.as_deref())
        }
        Cmd::Check { graph } => {
            let spec = load(&graph, InputFiles::Check)?;
            match spec {
                Ok(spec) => {
                    println!("{}: ok ({} nodes, {} edges)", graph.display(), spec.nodes.len(), spec.edges.len());
                    Ok(ExitCode::SUCCESS)
                }
                Err(code) => Ok(code),
            }
        }
        Cmd::Nodes { plugins } => {
            let mut reg = registry();
            skinflow_nodes::codec::load_plugins(&plugins, &mut reg)?;
            print_nodes(&reg);
            Ok(ExitCode::SUCCESS)
        }
        Cmd::Bench { graph, replay, vary, out } => {
            cmd::bench::run(&graph, &replay, &vary, &out).map(|()| ExitCode::SUCCESS)
        }
        Cmd::Simulate { scene, out, seed, overwrite } => {
            cmd::simulate::run(&scene, &out, seed, overwrite).map(|()| ExitCode::SUCCESS)
        }
        Cmd::Emulate { scene, options } => {
            cmd::emulate::run(&scene, options, interrupt_flag("closing the emulated devices")?)
                .map(|()| ExitCode::SUCCESS)
        }
        Cmd::Reproduce { out, scenes, seed, fit, pipeline } => {
            cmd::reproduce::run(&scenes, &out, seed, &fit.fit, &pipeline).map(|()| ExitCode::SUCCESS)
        }
        Cmd::Inspect { recording, graph } => cmd::inspect::run(&recording, graph).map(|()| ExitCode::SUCCESS),
        Cmd::Send { socket, requests } => cmd::send::run(&socket, &requests).map(|()| ExitCode::SUCCESS),
        Cmd::Repair { recording, out, overwrite } => {
            cmd::repair::run(&recording, &out, overwrite).map(|()| ExitCode::SUCCESS)
        }
        Cmd::Calibrate { recordings, out, fit, pipeline } => {
            cmd::calibrate::run(&recordings, &out, &fit.fit, &pipeline).map(|()| ExitCode::SUCCESS)
        }
        Cmd::Eval { recordings, calib, json, plots, contacts_csv, pipeline, lanes } => cmd::eval::run(
            &recordings,
            &calib,
            json.as_deref(),
            plots.as_deref(),
            contacts_csv.as_deref(),
            &pipeline,
            &lanes,
        )
        .map(|()| ExitCode::SUCCESS),
        // Drawing needs the graph only, not the files it reads.
        Cmd::Dot { graph } => match load(&graph, InputFiles::Skip)? {
            Ok(spec) => {
                print!("{}", skinflow_core::graph::dot::to_dot(&spec));
                Ok(ExitCode::SUCCESS)
            }
            Err(code) => Ok(code),
        },
    }
}

fn registry() -> Registry {
    skinflow_nodes::registry()
}

/// The built-in kinds plus the graph's `[[plugin]]` libraries. Err(code): plugin entries
/// that do not parse (printed). An unreadable graph file is reported by `GraphSpec::load`.
fn registry_for(path: &Path) -> Result<Result<Registry, ExitCode>> {
    let mut reg = registry();
    if let Ok(src) = skinflow_core::graph::SourceFile::read(path) {
        // Located at the library's `[[plugin]] path` line.
        match skinflow_core::graph::plugin_paths(&src) {
            Ok(plugins) => {
                // A graph naming a library that does not load cannot be validated: exit 2,
                // with the graph named (the library may just not be built yet).
                if let Err(e) = skinflow_nodes::codec::load_plugins(&plugins, &mut reg) {
                    let hint = if plugins.iter().any(|p| !p.exists()) {
                        " (a [[plugin]] path is relative to the graph file; not built yet? `cargo build --workspace` \
                         builds this workspace's plugins into target/debug/)"
                    } else {
                        ""
                    };
                    eprintln!("{}", skinflow_core::graph::plugin_error(&src, e.path(), format!("{e}{hint}")));
                    return Ok(Err(ExitCode::from(2)));
                }
            }
            Err(errs) => {
                for e in &errs.0 {
                    eprintln!("{e}");
                }
                return Ok(Err(ExitCode::from(2)));
            }
        }
    }
    Ok(Ok(reg))
}

/// Whether [`load`] also opens the input files the graph's params name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum InputFiles {
    /// Read-only, as their nodes read them when built (`GraphSpec::check_files`): `check` and
    /// `run` report a missing or invalid scene, calibration or recording the same way, and
    /// `run` before any node starts.
    Check,
    Skip,
}

/// Loads and validates (and with [`InputFiles::Check`] checks the input files once the graph is
/// valid); errors are printed one per line and give exit code 2.
fn load(path: &Path, inputs: InputFiles) -> Result<Result<GraphSpec, ExitCode>> {
    let reg = match registry_for(path)? {
        Ok(r) => r,
        Err(code) => return Ok(Err(code)),
    };
    let checked = GraphSpec::load(path, &reg).and_then(|spec| match inputs {
        // The files the nodes read, the sensors they name, and the files the nodes write
        // (`skinflow_nodes::check_graph_files`). Last, a warning for each calibration applied on another image scale than it was
        // fitted on (`skinflow_nodes::scale`), and for each corrector whose force map does not rise.
        InputFiles::Check => skinflow_nodes::check_graph_files(&spec).map(|()| {
            for w in skinflow_nodes::scale::check_graph(&spec) {
                eprintln!("warning: {}: {w}", path.display());
            }
            for w in skinflow_nodes::correct::flat_map_warnings(&spec) {
                eprintln!("warning: {}: {w}", path.display());
            }
            spec
        }),
        InputFiles::Skip => Ok(spec),
    });
    match checked {
        Ok(spec) => Ok(Ok(spec)),
        Err(errs) => {
            for e in &errs.0 {
                eprintln!("{e}");
            }
            Ok(Err(ExitCode::from(2)))
        }
    }
}

fn run(
    path: &Path,
    for_s: Option<f64>,
    stats_json: Option<&Path>,
    watch: bool,
    control: Option<&Path>,
) -> Result<ExitCode> {
    let spec = match load(path, InputFiles::Check)? {
        Ok(s) => s,
        Err(code) => return Ok(code),
    };
    let duration = match for_s {
        Some(s) if s.is_finite() && s > 0.0 => match Duration::try_from_secs_f64(s) {
            Ok(d) => Some(d),
            Err(_) => bail!("--for {s}: too long for a duration (at most {:e} s)", Duration::MAX.as_secs_f64()),
        },
        Some(s) => bail!("--for must be a positive number of seconds (got {s})"),
        None => None,
    };
    // Before the graph starts: a bad --stats-json or --control path fails without any data flowing.
    // Neither may be a file the graph reads or writes (a calibration, a logger's recording).
    if let Some(stats) = stats_json {
        skinflow_nodes::outputs::check_extra_output(&spec, "--stats-json", stats).map_err(anyhow::Error::msg)?;
        cmd::paths::check_outputs(&[("graph", path)], &[("--stats-json", stats)])?;
    }
    if let Some(sock) = control {
        skinflow_nodes::outputs::check_extra_output(&spec, "--control", sock).map_err(anyhow::Error::msg)?;
        if let Some(stats) = stats_json.filter(|s| {
            let abs = |p: &Path| std::path::absolute(p).ok();
            abs(s) == abs(sock) || cmd::paths::same_file(s, sock)
        }) {
            bail!("--stats-json {} and --control {} name the same file", stats.display(), sock.display());
        }
    }
    // A hot swap may not point a node at either (checked with every edit and swap).
    let extra_outputs: Vec<(&'static str, PathBuf)> = [("--stats-json", stats_json), ("--control", control)]
        .into_iter()
        .filter_map(|(what, p)| Some((what, p?.to_path_buf())))
        .collect();
    let stop = interrupt_flag("stopping sources, draining queues")?;
    // The kinds live swaps can use: the graph's plugins loaded again (fresh copies, so a
    // rebuilt library is told apart later); they loaded a moment ago for validation.
    let kinds = if watch || control.is_some() {
        Some(cmd::live::Kinds::load(&spec.plugins, &spec.source).map_err(|e| anyhow::anyhow!(e))?)
    } else {
        None
    };
    let listener = control.map(cmd::live::bind_control_socket).transpose()?;
    let running = match RunningGraph::start(&spec) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("{}: {e}", path.display());
            if let (Some(sock), Some(_)) = (control, &listener) {
                let _ = std::fs::remove_file(sock); // the socket bound above
            }
            return Ok(ExitCode::from(1));
        }
    };
    let done = Arc::new(AtomicBool::new(false));
    let mut helpers = Vec::new();
    let live = kinds.map(|k| cmd::live::Live::new(&spec, k, running.handle(), extra_outputs.clone()));
    if let (true, Some(live)) = (watch, &live) {
        let (p, live, d) = (path.to_path_buf(), Arc::clone(live), done.clone());
        helpers.push(std::thread::spawn(move || cmd::live::watch(p, live, d)));
        eprintln!("watching {} and its plugins for edits", path.display());
    }
    if let (Some(sock), Some(listener), Some(live)) = (control, listener, &live) {
        helpers.push(cmd::live::control_socket(listener, sock, Arc::clone(live), done.clone()));
        eprintln!("control socket at {}", sock.display());
    }
    let report = running.wait(&RunOptions { duration, stop: Some(stop) });
    done.store(true, Ordering::SeqCst);
    for h in helpers {
        let _ = h.join();
    }
    // The file first: a closed standard output loses the printed table only.
    if let Some(p) = stats_json {
        let json = serde_json::to_string_pretty(&report.stats)? + "\n";
        std::fs::write(p, json).with_context(|| format!("writing {}", p.display()))?;
    }
    cmd::print_or_warn(&format!("{}\n", report.stats), "the statistics table");
    if report.failures.is_empty() {
        Ok(ExitCode::SUCCESS)
    } else {
        for f in &report.failures {
            eprintln!("{}: {f}", path.display());
        }
        Ok(ExitCode::from(1))
    }
}

/// A flag set by the first Ctrl-C (or SIGTERM), which prints `doing`; a second one exits at once.
fn interrupt_flag(doing: &'static str) -> Result<Arc<AtomicBool>> {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    ctrlc::set_handler(move || {
        if flag.swap(true, Ordering::SeqCst) {
            eprintln!("second interrupt: exiting without draining");
            std::process::exit(130);
        }
        eprintln!("interrupt: {doing} (Ctrl-C again to abort)");
    })
    .context("installing the Ctrl-C handler")?;
    Ok(stop)
}

fn print_nodes(reg: &Registry) {
    for f in reg.iter() {
        let k = f.info();
        println!("{} ({:?}, {}): {}", k.name, k.role, k.origin, k.doc);
        for p in &k.inputs {
            let opt = if p.required { "" } else { ", optional" };
            let multi = if p.multi { ", multi" } else { "" };
            println!("  in  {}: {}{opt}{multi}  {}", p.name, p.ty, p.doc);
        }
        for p in &k.outputs {
            println!("  out {}: {}  {}", p.name, p.ty, p.doc);
        }
        for p in &k.params {
            let d = if p.default.is_empty() { "required".to_string() } else { format!("default {}", p.default) };
            println!("  param {}: {} ({d})  {}", p.name, p.ty, p.doc);
        }
    }
}
