//! `skinflow emulate SCENE.toml`: pseudo-terminals that speak the three boards' protocols
//! (nodes/serial/PROTOCOLS.md) from a simulated scene, at the real rates (or `--fast`), with
//! optional faults. Prints the device paths, then runs until the scene ends or Ctrl-C.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::Result;
use skinflow_serial::{
    Device, Emulator, EmulatorConfig, EmulatorFeed, Fault, FaultPlan, Pacing, TimedForce, TimedFrame, TimedPressure,
};
use skinflow_sim::{Scene, SimEvent, Simulator};

/// The scene's streams as the boards would send them: an EIT frame at the end of its window.
pub fn feed(scene_path: &Path, seed: u64) -> Result<(Vec<TimedFrame>, Vec<TimedPressure>, Vec<TimedForce>)> {
    let scene = Scene::from_file(scene_path).map_err(anyhow::Error::msg)?;
    let mut sim = Simulator::new(&scene, seed).map_err(anyhow::Error::msg)?;
    let half = 0.5 / sim.rates().eit_fps;
    let (mut eit, mut pressure, mut force) = (Vec::new(), Vec::new(), Vec::new());
    while let Some(e) = sim.next_event().map_err(anyhow::Error::msg)? {
        match e {
            SimEvent::Eit { t_s, v, .. } => eit.push(TimedFrame { t_s: t_s + half, volts: v }),
            SimEvent::Pressure { t_s, kpa } => pressure.push(TimedPressure { t_s, kpa }),
            SimEvent::Truth { t_s, contacts } => {
                force.push(TimedForce { t_s, force_n: contacts.iter().map(|c| c.force_n).sum() })
            }
        }
    }
    Ok((eit, pressure, force))
}

/// Parses `--fault device:index:kind[=value]`, e.g. `eit:10:crc`, `eit:20:unplug=0.5`,
/// `pressure:5:garbage`, `loadcell:3:stall=2`.
fn parse_fault(s: &str) -> Result<(Device, usize, Fault)> {
    let bad = || {
        anyhow::anyhow!(
            "--fault \"{s}\": expected device:index:kind[=value] (kinds: garbage, crc, drop, truncate, skip, unplug=S, stall=S)"
        )
    };
    let mut it = s.splitn(3, ':');
    let (dev, idx, kind) = (it.next().ok_or_else(bad)?, it.next().ok_or_else(bad)?, it.next().ok_or_else(bad)?);
    let device = match dev {
        "eit" => Device::Eit,
        "pressure" => Device::Pressure,
        "loadcell" => Device::Loadcell,
        _ => return Err(bad()),
    };
    let index: usize = idx.parse().map_err(|_| bad())?;
    let (k, v) = kind.split_once('=').map_or((kind, None), |(k, v)| (k, Some(v)));
    let secs = || v.and_then(|v| v.parse::<f64>().ok()).ok_or_else(bad);
    let fault = match k {
        "garbage" => Fault::Garbage(b"\x00\xff garbage \xaa".to_vec()),
        "crc" => Fault::CorruptCrc,
        "drop" => Fault::DropBytes { offset: 3, len: 5 },
        "truncate" => Fault::Truncate { keep: 7 },
        "skip" => Fault::Skip,
        "unplug" => Fault::Unplug { down_s: secs()? },
        "stall" => Fault::Stall { silent_s: secs()? },
        _ => return Err(bad()),
    };
    Ok((device, index, fault))
}

pub fn run(
    scene: &Path,
    seed: u64,
    fast: bool,
    dir: Option<PathBuf>,
    faults: &[String],
    stop: Arc<AtomicBool>,
) -> Result<()> {
    eprintln!("simulating {} (seed {seed}) before the devices open...", scene.display());
    let t0 = std::time::Instant::now();
    let (eit, pressure, force) = feed(scene, seed)?;
    eprintln!("simulated in {:.1} s", t0.elapsed().as_secs_f64());
    let last_s = [eit.last().map(|e| e.t_s), pressure.last().map(|p| p.t_s), force.last().map(|f| f.t_s)]
        .into_iter()
        .flatten()
        .fold(0.0f64, f64::max);
    let mut plan = FaultPlan::default();
    for f in faults {
        let (device, index, fault) = parse_fault(f)?;
        match device {
            Device::Eit => plan.eit.push((index, fault)),
            Device::Pressure => plan.pressure.push((index, fault)),
            Device::Loadcell => plan.loadcell.push((index, fault)),
        }
    }
    let config = EmulatorConfig {
        dir,
        pacing: if fast { Pacing::AsFastAsPossible } else { Pacing::RealTime },
        first_counter: 0,
    };
    let (n_eit, n_p, n_f) = (eit.len(), pressure.len(), force.len());
    let emu = Emulator::spawn(
        config,
        EmulatorFeed::default().with_eit(eit).with_pressure(pressure).with_loadcell(force),
        plan,
    )
    .map_err(anyhow::Error::msg)?;
    for (device, path) in emu.paths() {
        println!("{} {}", device.name(), path.display());
    }
    let until =
        if fast { "as fast as the readers take them".to_string() } else { format!("in real time, {last_s:.1} s") };
    eprintln!(
        "emulating {}: {n_eit} EIT frames, {n_p} pressure samples, {n_f} load-cell readings, {until}; ends with the \
         scene or at Ctrl-C",
        scene.display()
    );
    while !emu.finished() && !stop.load(Ordering::SeqCst) {
        std::thread::sleep(Duration::from_millis(50));
    }
    for d in [Device::Eit, Device::Pressure, Device::Loadcell] {
        if let Some(s) = emu.stats(d) {
            eprintln!("{}: {s:?}", d.name());
        }
    }
    emu.stop().map_err(anyhow::Error::msg)?;
    Ok(())
}
