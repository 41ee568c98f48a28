//! `skinflow emulate SCENE.toml`: pseudo-terminals that speak the three boards' protocols
//! (nodes/serial/PROTOCOLS.md) from a simulated scene, at the real rates (or `--fast`), with
//! optional faults. Prints the device paths, then runs until the scene ends or Ctrl-C. With
//! `--fast` a device sends only as fast as it is read, so serve only the devices a graph reads
//! (`--devices eit,pressure`): an unread one would never finish.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::Result;
use skinflow_serial::{
    Device, Emulator, EmulatorConfig, EmulatorFeed, Fault, FaultPlan, Pacing, TimedForce, TimedFrame, TimedPressure,
};
use skinflow_sim::{EventKind, Scene, Simulator};

/// The options of `skinflow emulate`.
#[derive(Debug, Clone, clap::Args)]
pub struct EmulateArgs {
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Send as fast as the readers take the bytes instead of at the real rates.
    #[arg(long)]
    pub fast: bool,
    /// Directory for the stable device links (default: a fresh temporary directory).
    #[arg(long)]
    pub dir: Option<PathBuf>,
    /// Inject a fault before the record at index (0-based, per device): device:index:kind[=S].
    /// Kinds: garbage, crc (eit), drop, truncate, skip, unplug=S (gone S seconds, back at the
    /// same path), stall=S (silent S seconds), restart=S (eit, pressure: the board resets and
    /// boots for S seconds, making none of the records due meanwhile, then goes on with its
    /// frame counter and clock from the reset, as firmware after a reset). E.g. eit:10:crc,
    /// eit:20:unplug=0.5, eit:30:restart=2.
    #[arg(long = "fault")]
    pub faults: Vec<String>,
    /// The devices to serve, comma-separated (with --fast, only those a graph reads: an
    /// unread device never finishes).
    #[arg(long, default_value = "eit,pressure,loadcell")]
    pub devices: String,
    /// The load cell prints its reading this many times a second, as a gauge in continuous
    /// mode does (default: one line per change of the load).
    #[arg(long, value_name = "HZ")]
    pub loadcell_hz: Option<f64>,
}

/// A gauge in continuous mode: the force in effect (0 N before the first change) at every
/// multiple of `1 / hz` from 0 s through `end_s`.
pub fn stream_at(changes: &[TimedForce], hz: f64, end_s: f64) -> Vec<TimedForce> {
    let mut out = Vec::new();
    let mut next = 0;
    let mut force_n = 0.0;
    for k in 0u64.. {
        let t_s = k as f64 / hz;
        if t_s > end_s {
            break;
        }
        while changes.get(next).is_some_and(|c| c.t_s <= t_s) {
            force_n = changes[next].force_n;
            next += 1;
        }
        out.push(TimedForce { t_s, force_n });
    }
    out
}

/// The scene's streams as the boards would send them: an EIT frame at the end of its window.
pub fn feed(scene_path: &Path, seed: u64) -> Result<(Vec<TimedFrame>, Vec<TimedPressure>, Vec<TimedForce>)> {
    let scene = Scene::from_file(scene_path).map_err(anyhow::Error::msg)?;
    let mut sim = Simulator::new(&scene, seed).map_err(anyhow::Error::msg)?;
    let half = 0.5 / sim.rates().eit_fps;
    let (mut eit, mut pressure, mut force) = (Vec::new(), Vec::new(), Vec::new());
    // Reused from event to event; a frame is copied out, as the feed owns its frames.
    let mut v = vec![0.0; sim.measurement_count()];
    let mut contacts = Vec::with_capacity(sim.max_contacts());
    while let Some(e) = sim.next_into(&mut v, &mut contacts).map_err(anyhow::Error::msg)? {
        match e {
            EventKind::Eit { t_s, .. } => eit.push(TimedFrame { t_s: t_s + half, volts: v.clone() }),
            EventKind::Pressure { t_s, kpa } => pressure.push(TimedPressure { t_s, kpa }),
            EventKind::Truth { t_s } => {
                force.push(TimedForce { t_s, force_n: contacts.iter().map(|c| c.force_n).sum() })
            }
        }
    }
    Ok((eit, pressure, force))
}

/// Parses `--fault device:index:kind[=value]`, e.g. `eit:10:crc`, `eit:20:unplug=0.5`,
/// `pressure:5:garbage`, `loadcell:3:stall=2`, `eit:30:restart=2`.
fn parse_fault(s: &str) -> Result<(Device, usize, Fault)> {
    let bad = || {
        anyhow::anyhow!(
            "--fault \"{s}\": expected device:index:kind[=value] (kinds: garbage, crc, drop, truncate, skip, unplug=S, \
             stall=S, restart=S)"
        )
    };
    let mut it = s.splitn(3, ':');
    let (dev, idx, kind) = (it.next().ok_or_else(bad)?, it.next().ok_or_else(bad)?, it.next().ok_or_else(bad)?);
    let device = parse_device(dev).map_err(|e| anyhow::anyhow!("--fault \"{s}\": {e}"))?;
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
        "restart" => Fault::Restart { down_s: secs()? },
        _ => return Err(bad()),
    };
    Ok((device, index, fault))
}

/// A device by its name on the command line ([`Device::name`]).
fn parse_device(name: &str) -> Result<Device> {
    Device::ALL.into_iter().find(|d| d.name() == name).ok_or_else(|| {
        let names: Vec<&str> = Device::ALL.iter().map(|d| d.name()).collect();
        anyhow::anyhow!("unknown device {name:?} (devices: {})", names.join(", "))
    })
}

/// Parses `--devices eit,pressure` (the devices to serve).
fn parse_devices(list: &str) -> Result<Vec<Device>> {
    let mut devices = Vec::new();
    for name in list.split(',').map(str::trim) {
        let d = parse_device(name).map_err(|e| anyhow::anyhow!("--devices {list:?}: {e}"))?;
        if !devices.contains(&d) {
            devices.push(d);
        }
    }
    Ok(devices)
}

pub fn run(scene: &Path, options: EmulateArgs, stop: Arc<AtomicBool>) -> Result<()> {
    let EmulateArgs { seed, fast, dir, faults, devices, loadcell_hz } = options;
    // Every option is checked before the simulation, which takes seconds.
    let devices = parse_devices(&devices)?;
    if let Some(hz) = loadcell_hz
        && !(hz.is_finite() && hz > 0.0 && hz <= 1000.0)
    {
        anyhow::bail!("--loadcell-hz {hz}: must be a rate in (0, 1000] Hz");
    }
    let mut plan = FaultPlan::default();
    // Each fault's argument, device and record index: checked against the feeds once simulated.
    let mut at: Vec<(&str, Device, usize)> = Vec::new();
    for f in &faults {
        let (device, index, fault) = parse_fault(f)?;
        at.push((f, device, index));
        if !devices.contains(&device) {
            anyhow::bail!("--fault \"{f}\": device {} is not served (see --devices)", device.name());
        }
        match device {
            Device::Eit => plan.eit.push((index, fault)),
            Device::Pressure => plan.pressure.push((index, fault)),
            Device::Loadcell => plan.loadcell.push((index, fault)),
        }
        // A fault the device cannot have (crc or restart on the load cell), or a silence out of
        // range: the faults before it passed, so this one is at fault.
        plan.validate().map_err(|e| anyhow::anyhow!("--fault \"{f}\": {e}"))?;
    }
    eprintln!("simulating {} (seed {seed}) before the devices open...", scene.display());
    let t0 = std::time::Instant::now();
    let (eit, pressure, mut force) = feed(scene, seed)?;
    eprintln!("simulated in {:.1} s", t0.elapsed().as_secs_f64());
    // Ctrl-C during the simulation: no device was opened yet.
    if stop.load(Ordering::SeqCst) {
        return Ok(());
    }
    if let Some(hz) = loadcell_hz {
        let end_s = [eit.last().map(|e| e.t_s), pressure.last().map(|p| p.t_s), force.last().map(|f| f.t_s)]
            .into_iter()
            .flatten()
            .fold(0.0f64, f64::max);
        force = stream_at(&force, hz, end_s);
    }
    // A fault at a record the feed does not have would never be applied.
    for (f, device, index) in at {
        let records = match device {
            Device::Eit => eit.len(),
            Device::Pressure => pressure.len(),
            Device::Loadcell => force.len(),
        };
        if index >= records {
            let holds = match records {
                0 => "no record".to_owned(),
                1 => "1 record (index 0)".to_owned(),
                n => format!("{n} records (indices 0 to {})", n - 1),
            };
            anyhow::bail!(
                "--fault \"{f}\": the {} feed of {} holds {holds}: the fault would never apply",
                device.name(),
                scene.display()
            );
        }
    }
    let serves = |d: Device| devices.contains(&d);
    let last_s = [
        eit.last().filter(|_| serves(Device::Eit)).map(|e| e.t_s),
        pressure.last().filter(|_| serves(Device::Pressure)).map(|p| p.t_s),
        force.last().filter(|_| serves(Device::Loadcell)).map(|f| f.t_s),
    ]
    .into_iter()
    .flatten()
    .fold(0.0f64, f64::max);
    let config = EmulatorConfig {
        dir,
        pacing: if fast { Pacing::AsFastAsPossible } else { Pacing::RealTime },
        first_counter: 0,
    };
    let mut feed = EmulatorFeed::default();
    let mut served = Vec::new();
    if serves(Device::Eit) {
        served.push(format!("{} EIT frames", eit.len()));
        feed = feed.with_eit(eit);
    }
    if serves(Device::Pressure) {
        served.push(format!("{} pressure samples", pressure.len()));
        feed = feed.with_pressure(pressure);
    }
    if serves(Device::Loadcell) {
        served.push(format!("{} load-cell readings", force.len()));
        feed = feed.with_loadcell(force);
    }
    let emu = Emulator::spawn(config, feed, plan).map_err(anyhow::Error::msg)?;
    for (device, path) in emu.paths() {
        super::print_or_warn(&format!("{} {}\n", device.name(), path.display()), "a device's path");
    }
    let until = if fast {
        "as fast as the readers take them (every served device must be read to the end; a source reading it \
         needs `clear_input_at_open = false`, or what was sent before it opened the port is cleared)"
            .to_string()
    } else {
        format!("in real time, {last_s:.1} s")
    };
    eprintln!("emulating {}: {}, {until}; ends with the scene or at Ctrl-C", scene.display(), served.join(", "));
    // Until each device's reader took every byte (stopping closes the ptys, losing the rest).
    while !emu.delivered() && !stop.load(Ordering::SeqCst) {
        std::thread::sleep(Duration::from_millis(50));
    }
    for d in devices {
        if let Some(s) = emu.stats(d) {
            eprintln!("{}: {s:?}", d.name());
        }
    }
    emu.stop().map_err(anyhow::Error::msg)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_restart_fault_parses_with_its_silence() {
        let (device, index, fault) = parse_fault("eit:30:restart=0.3").unwrap();
        assert_eq!((device, index, fault), (Device::Eit, 30, Fault::Restart { down_s: 0.3 }));
        let (device, _, fault) = parse_fault("pressure:4:restart=2").unwrap();
        assert_eq!((device, fault), (Device::Pressure, Fault::Restart { down_s: 2.0 }));
        for bad in ["eit:30:restart", "eit:30:restart=soon"] {
            let e = parse_fault(bad).unwrap_err().to_string();
            assert!(e.contains(&format!("--fault \"{bad}\"")) && e.contains("restart=S"), "{e}");
        }
    }

    /// Refused before the scene is even read (it does not exist here), naming the argument.
    #[test]
    fn a_fault_a_device_cannot_have_is_refused_before_the_simulation() {
        let refused = |fault: &str| {
            let args = EmulateArgs {
                seed: 1,
                fast: false,
                dir: None,
                faults: vec!["eit:2:crc".into(), fault.into()],
                devices: "eit,pressure,loadcell".into(),
                loadcell_hz: None,
            };
            run(Path::new("no-such-scene.toml"), args, Arc::new(AtomicBool::new(false))).unwrap_err().to_string()
        };
        let e = refused("loadcell:4:restart=1");
        assert!(
            e.starts_with(
                "--fault \"loadcell:4:restart=1\": fault plan: loadcell record 4: fault restart applies to boards \
                 with a frame counter or clock"
            ),
            "{e}"
        );
        let e = refused("pressure:1:crc");
        assert!(
            e.starts_with("--fault \"pressure:1:crc\": fault plan: pressure record 1: fault crc applies to"),
            "{e}"
        );
        let e = refused("eit:3:restart=-1");
        assert!(e.starts_with("--fault \"eit:3:restart=-1\": fault plan: eit record 3: param \"down_s\""), "{e}");
    }

    #[test]
    fn a_continuous_gauge_repeats_the_force_in_effect() {
        let changes = [TimedForce { t_s: 0.25, force_n: 2.0 }, TimedForce { t_s: 0.5, force_n: 0.0 }];
        let got: Vec<(f64, f64)> = stream_at(&changes, 10.0, 0.62).iter().map(|f| (f.t_s, f.force_n)).collect();
        let want: Vec<(f64, f64)> =
            (0..=6).map(|k| (k as f64 / 10.0, if (3..5).contains(&k) { 2.0 } else { 0.0 })).collect();
        assert_eq!(got, want);
    }
}
