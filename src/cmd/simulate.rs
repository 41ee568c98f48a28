//! `skinflow simulate SCENE.toml --out REC.h5`: a scene's simulated streams written as a
//! recording (CONTRACTS.md section 2), as fast as they compute.
//!
//! The recording is built under the writer's hidden staging name beside `--out`
//! (`.NAME.PID.partial`) and given its name only when the whole scene is written
//! (`WriterOptions::name_at_close`), so an interrupted or failed run never leaves a shorter
//! recording that looks complete under the requested name. A failure or a Ctrl-C (SIGINT)
//! removes the hidden file too (`RecordingWriter::discard`); only a process killed outright
//! leaves it (`.NAME.PID.partial`, safe to delete).

use std::path::Path;
use std::sync::OnceLock;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use anyhow::Result;
use skinflow_record::write::{RecordingWriter, Streams, TruthContact, WriterOptions};
use skinflow_sim::{EventKind, Scene, Simulator};

pub fn run(scene_path: &Path, out: &Path, seed: u64, overwrite: bool) -> Result<()> {
    super::paths::check_recording_outputs(&[("scene", scene_path)], &[("--out", out)])?;
    if !overwrite && std::fs::symlink_metadata(out).is_ok() {
        anyhow::bail!("--out {}: exists (pass --overwrite to replace it)", out.display());
    }
    if overwrite && let Some(why) = skinflow_nodes::output::not_a_recording(out) {
        anyhow::bail!("--out {}: {why}", out.display());
    }
    let t0 = Instant::now();
    let scene = Scene::from_file(scene_path).map_err(anyhow::Error::msg)?;
    let mut sim =
        // The error's message ends with its cause: as one line, not followed by the cause again.
        Simulator::new(&scene, seed)
            .map_err(|e| anyhow::anyhow!("{}: preparing the simulation: {e}", scene_path.display()))?;
    check_space(&sim, scene.channels.eit, scene.channels.pressure, out)?;
    let mut o = WriterOptions::new(sim.sensor().toml.clone());
    o.software_version = concat!("skinflow ", env!("CARGO_PKG_VERSION")).to_owned();
    o.overwrite = overwrite;
    o.truth_max_contacts = sim.max_contacts().max(1);
    o.streams =
        Streams { eit: scene.channels.eit, pressure: scene.channels.pressure, truth: true, ..Streams::default() };
    o.graph_toml = Some(format!("# skinflow simulate {} --seed {seed}\n", scene_path.display()));
    o.name_at_close = true;
    let (frames, samples, rows) = write(&mut sim, out, &o)?;
    eprintln!(
        "{}: {frames} EIT frames, {samples} pressure samples, {rows} truth rows ({:.1} s simulated) in {:.2} s -> {}",
        scene_path.display(),
        sim.duration_s(),
        t0.elapsed().as_secs_f64(),
        out.display()
    );
    Ok(())
}

/// Writes every event of `sim` to a new recording at `path`; returns the EIT frame, pressure
/// sample and truth row counts. The frame and truth row buffers are reused from event to event
/// (`Simulator::next_into`): the writer copies what it is given.
fn write(sim: &mut Simulator, path: &Path, o: &WriterOptions) -> Result<(u64, u64, u64)> {
    let interrupted = interrupted()?;
    let mut w = RecordingWriter::create(path, o).map_err(anyhow::Error::msg)?;
    match append_all(sim, &mut w, interrupted) {
        Ok(counts) => {
            w.close().map_err(anyhow::Error::msg)?;
            Ok(counts)
        }
        Err(e) => {
            let what = match w.discard() {
                Ok(()) => "nothing written".to_owned(),
                Err(d) => format!("the unfinished file not removed: {d}"),
            };
            Err(anyhow::anyhow!("{e:#} (--out {}: {what})", path.display()))
        }
    }
}

/// Set by Ctrl-C (SIGINT). Installed once per process: `reproduce` simulates several scenes.
fn interrupted() -> Result<&'static AtomicBool> {
    static FLAG: OnceLock<Result<(), String>> = OnceLock::new();
    static INTERRUPTED: AtomicBool = AtomicBool::new(false);
    FLAG.get_or_init(|| ctrlc::set_handler(|| INTERRUPTED.store(true, Ordering::SeqCst)).map_err(|e| e.to_string()))
        .as_ref()
        .map_err(|e| anyhow::anyhow!("installing the Ctrl-C handler: {e}"))?;
    Ok(&INTERRUPTED)
}

/// Appends every event of `sim` to `w` until the scene ends, an append fails, or `interrupted`
/// is set.
fn append_all(sim: &mut Simulator, w: &mut RecordingWriter, interrupted: &AtomicBool) -> Result<(u64, u64, u64)> {
    let mut v = vec![0.0; sim.measurement_count()];
    let mut contacts = Vec::with_capacity(sim.max_contacts());
    let mut truth = Vec::with_capacity(sim.max_contacts());
    let (mut frames, mut samples, mut rows) = (0u64, 0u64, 0u64);
    while let Some(e) = sim.next_into(&mut v, &mut contacts).map_err(anyhow::Error::msg)? {
        if interrupted.load(Ordering::Relaxed) {
            anyhow::bail!("interrupted");
        }
        match e {
            EventKind::Eit { t_s, seq } => {
                w.append_eit(t_s, seq, &v).map_err(anyhow::Error::msg)?;
                frames += 1;
            }
            EventKind::Pressure { t_s, kpa } => {
                w.append_pressure(t_s, kpa).map_err(anyhow::Error::msg)?;
                samples += 1;
            }
            EventKind::Truth { t_s } => {
                truth.clear();
                truth.extend(contacts.iter().map(|c| TruthContact {
                    x_mm: c.x_mm,
                    y_mm: c.y_mm,
                    force_n: c.force_n,
                    diameter_mm: c.diameter_mm,
                }));
                w.append_truth(t_s, &truth).map_err(anyhow::Error::msg)?;
                rows += 1;
            }
        }
    }
    Ok((frames, samples, rows))
}

/// Refuses a scene whose recording cannot fit in the free space of `--out`'s file system,
/// before anything is simulated: the EIT frames (8 bytes per value, plus time and sequence
/// number) and pressure samples (time and value) it will write. Truth rows and HDF5's own
/// structure are left out, so this is a lower bound on the file's size.
fn check_space(sim: &Simulator, eit: bool, pressure: bool, out: &Path) -> Result<()> {
    let (rates, duration_s) = (sim.rates(), sim.duration_s());
    let frames = if eit { (duration_s * rates.eit_fps).ceil() } else { 0.0 };
    let samples = if pressure { (duration_s * rates.pressure_hz).ceil() } else { 0.0 };
    let need = frames * (sim.measurement_count() as f64 * 8.0 + 16.0) + samples * 16.0;
    let dir = out.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let Some(free) = free_bytes(dir) else { return Ok(()) };
    if need > free as f64 {
        anyhow::bail!(
            "--out {}: the scene's recording needs at least {} ({frames} EIT frames, {samples} pressure samples \
             over {duration_s} s), but {} has {} free",
            out.display(),
            size(need),
            dir.display(),
            size(free as f64)
        );
    }
    Ok(())
}

/// A byte count in the unit that shows it (GB, MB or kB, 2 decimals).
fn size(bytes: f64) -> String {
    match bytes {
        b if b >= 1e9 => format!("{:.2} GB", b / 1e9),
        b if b >= 1e6 => format!("{:.2} MB", b / 1e6),
        b => format!("{:.2} kB", b / 1e3),
    }
}

/// Bytes an unprivileged process may still write in the file system holding `dir` (None when
/// it cannot be asked).
fn free_bytes(dir: &Path) -> Option<u64> {
    let st = nix::sys::statvfs::statvfs(dir).ok()?;
    Some((st.blocks_available() as u64).saturating_mul(st.fragment_size() as u64))
}

#[cfg(test)]
mod tests {
    /// The audit's case: a small disk read "needs at least 0.00 GB ... has 0.00 GB free".
    #[test]
    fn sizes_are_shown_in_the_unit_that_shows_them() {
        assert_eq!(super::size(2.5e9), "2.50 GB");
        assert_eq!(super::size(3.2e7), "32.00 MB");
        assert_eq!(super::size(131_072.0), "131.07 kB");
        assert_eq!(super::size(0.0), "0.00 kB");
    }
}
