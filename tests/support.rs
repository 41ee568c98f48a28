//! Helpers shared by the whole-binary tests: the binary, the repository, fixtures, a fresh
//! work directory per test, and one run of the binary.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Output, Stdio};
use std::sync::{PoisonError, RwLock};

/// The `skinflow` binary under test.
pub fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_skinflow")
}

/// The repository root.
pub fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// A file of `tests/fixtures`.
pub fn fixture(name: &str) -> PathBuf {
    root().join("tests/fixtures").join(name)
}

/// A fresh, empty directory under the system temp dir, unique per module, process and test.
pub fn workdir(module: &str, test: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("skinflow-{module}-{}-{test}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Runs the binary in `dir` to the end, with its reconstruction-matrix cache in `dir/cache`.
pub fn skinflow(dir: &Path, args: &[&str]) -> Output {
    output(
        Command::new(bin())
            .args(args)
            .current_dir(dir)
            .env("XDG_CACHE_HOME", dir.join("cache"))
            .env("RUST_LOG", "warn"),
    )
}

/// Spawning a child and opening an HDF5 file in this process exclude each other.
///
/// A child inherits every descriptor not marked close-on-exec, and the HDF5 library opens its
/// files without that flag. Its file lock (a `flock`) belongs to the open file, which the
/// child then shares: a child spawned, by any test thread, while a test here has a recording
/// open holds that recording's lock until the child exits, and a `skinflow` run on it finds it
/// "being written by another process". So children are spawned under the shared side of this
/// lock (for the spawn only, not the child's run) and in-process HDF5 work runs under the
/// exclusive side ([`hdf5_io`]).
static SPAWN_OR_HDF5: RwLock<()> = RwLock::new(());

/// `cmd` spawned while no HDF5 file is open in this process (see [`SPAWN_OR_HDF5`]).
pub fn spawn(cmd: &mut Command) -> Child {
    let _no_hdf5_open = SPAWN_OR_HDF5.read().unwrap_or_else(PoisonError::into_inner);
    cmd.spawn().unwrap_or_else(|e| panic!("cannot spawn {:?}: {e}", cmd.get_program()))
}

/// Waits until `path` exists (a spawned run's socket or file), polling every 20 ms; fails the
/// test with `what` once `within` has passed.
pub fn wait_for_file(path: &Path, within: std::time::Duration, what: &str) {
    let t0 = std::time::Instant::now();
    while !path.exists() {
        assert!(t0.elapsed() < within, "{what}");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

/// `cmd` run to the end as [`Command::output`] does (stdin empty, stdout and stderr captured),
/// spawned by [`spawn`].
pub fn output(cmd: &mut Command) -> Output {
    spawn(cmd.stdin(Stdio::null()).stdout(Stdio::piped()).stderr(Stdio::piped())).wait_with_output().unwrap()
}

/// `cmd` run to the end as [`Command::status`] does (standard streams inherited), spawned by
/// [`spawn`].
pub fn status(cmd: &mut Command) -> ExitStatus {
    spawn(cmd).wait().unwrap()
}

/// Runs `f`, which opens, reads or writes HDF5 files in this process and closes them all
/// before it returns, while no child is being spawned (see [`SPAWN_OR_HDF5`]). `f` must not
/// spawn a child itself.
pub fn hdf5_io<T>(f: impl FnOnce() -> T) -> T {
    let _no_spawn = SPAWN_OR_HDF5.write().unwrap_or_else(PoisonError::into_inner);
    f()
}

/// A recording read whole into memory (the file is closed again), under [`hdf5_io`].
pub fn read_recording(path: impl AsRef<Path>) -> skinflow_record::Recording {
    let path = path.as_ref();
    hdf5_io(|| skinflow_record::Recording::open(path))
        .unwrap_or_else(|e| panic!("cannot read recording {}: {e}", path.display()))
}

/// Bytes of an output stream as text.
pub fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// The stderr of a run, as text.
pub fn stderr(out: &Output) -> String {
    text(&out.stderr)
}

/// The stdout of a successful run; fails the test with both streams otherwise.
pub fn ok(out: &Output) -> String {
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "exit {:?}\nstdout:\n{stdout}\nstderr:\n{}", out.status, text(&out.stderr));
    stdout
}

/// Copies the EIT frames and truth of recording `src` into a new recording `dst`, with each
/// pressure sample `(row, t_s, kpa)` mapped by `pressure` (`None` leaves it out), under
/// [`hdf5_io`].
pub fn rewrite_pressure(src: &Path, dst: &Path, pressure: impl FnMut(usize, f64, f64) -> Option<(f64, f64)>) {
    rewrite_recording(src, dst, 0.0, pressure);
}

/// [`rewrite_pressure`], and then every time of `/eit`, `/pressure` and `/truth` moved by
/// `shift_s`.
pub fn rewrite_recording(
    src: &Path,
    dst: &Path,
    shift_s: f64,
    mut pressure: impl FnMut(usize, f64, f64) -> Option<(f64, f64)>,
) {
    hdf5_io(|| {
        let rec = skinflow_record::Recording::open(src).unwrap();
        let mut opts = skinflow_record::WriterOptions::new(rec.sensor_toml.clone());
        opts.streams =
            skinflow_record::Streams { eit: true, pressure: true, truth: true, ..skinflow_record::Streams::default() };
        opts.truth_max_contacts = rec.truth.as_ref().unwrap().max_contacts;
        let mut w = skinflow_record::RecordingWriter::create(dst, &opts).unwrap();
        let eit = rec.eit.as_ref().unwrap();
        for i in 0..eit.len() {
            w.append_eit(eit.t_s[i] + shift_s, eit.seq[i], eit.frame(i)).unwrap();
        }
        let p = rec.pressure.as_ref().unwrap();
        for i in 0..p.len() {
            if let Some((t, kpa)) = pressure(i, p.t_s[i], p.kpa[i]) {
                w.append_pressure(t + shift_s, kpa).unwrap();
            }
        }
        let truth = rec.truth.as_ref().unwrap();
        for i in 0..truth.len() {
            let row = truth.row(i);
            let contacts: Vec<skinflow_record::TruthContact> = row.contacts().collect();
            w.append_truth(truth.t_s[i] + shift_s, &contacts).unwrap();
        }
        w.close().unwrap();
    });
}
