//! Emulator -> pseudo-terminal -> reader, clean streams: every record arrives intact, in order.

mod feeds;

use std::time::{Duration, Instant};

use skinflow_serial::read::{ReaderConfig, SerialReader};
use skinflow_serial::{
    Device, EitDecoder, Emulator, EmulatorConfig, EmulatorFeed, FaultPlan, ForceDecoder, Pacing, PressureDecoder,
    SerialError,
};

const LIMIT: Duration = Duration::from_secs(30);

#[test]
fn three_devices_fast_roundtrip_exact() {
    let m = 120;
    let frames = feeds::busy_frames(m, 150, 0.77);
    let pressures = feeds::pressures(400, 0.05);
    let forces = feeds::forces(300, 0.1);
    let feed =
        EmulatorFeed::default().with_eit(frames.clone()).with_pressure(pressures.clone()).with_loadcell(forces.clone());
    let config =
        EmulatorConfig { pacing: Pacing::AsFastAsPossible, first_counter: u32::MAX - 70, ..Default::default() };
    let emulator = Emulator::spawn(config, feed, FaultPlan::default()).expect("spawn");
    let origin = Instant::now();

    let path = emulator.path(Device::Eit).expect("eit path");
    assert!(std::fs::read_link(path).expect("a symlink").starts_with("/dev/pts"));
    let mut eit = SerialReader::open(ReaderConfig::new(path), EitDecoder::new(m), origin).expect("open eit");
    let mut k = 0usize;
    let got = feeds::read_n(&mut eit, frames.len(), LIMIT, |r| {
        assert_eq!(r.record.counter, (u32::MAX - 70).wrapping_add(k as u32));
        for (got, sent) in r.record.volts.iter().zip(&frames[k].volts) {
            assert_eq!(*got, f64::from(*sent as f32));
        }
        assert!((r.record.device_t_s - frames[k].t_s).abs() <= 0.5e-6);
        assert!(r.host_t_s >= 0.0);
        k += 1;
    });
    assert_eq!(got, frames.len());
    let s = eit.decode_stats();
    assert_eq!((s.frames, s.discarded_bytes, s.lost_frames, s.crc_errors, s.counter_resets), (150, 0, 0, 0, 0));

    let path = emulator.path(Device::Pressure).expect("pressure path");
    let mut pressure =
        SerialReader::open(ReaderConfig::new(path), PressureDecoder::try_new(Some(50)).unwrap(), origin).unwrap();
    let mut k = 0usize;
    let got = feeds::read_n(&mut pressure, pressures.len(), LIMIT, |r| {
        // Four decimals on the wire.
        assert!((r.record.kpa - pressures[k].kpa).abs() <= 0.5e-4 + 1e-12);
        assert_eq!(r.record.device_time_ms, (pressures[k].t_s * 1e3).round() as u32);
        k += 1;
    });
    assert_eq!(got, pressures.len());
    assert_eq!((pressure.decode_stats().lost_frames, pressure.decode_stats().bad_lines), (0, 0));

    let path = emulator.path(Device::Loadcell).expect("loadcell path");
    let mut force = SerialReader::open(ReaderConfig::new(path), ForceDecoder::new(), origin).unwrap();
    let mut k = 0usize;
    let got = feeds::read_n(&mut force, forces.len(), LIMIT, |r| {
        assert!((r.record.force_n - forces[k].force_n).abs() <= 0.5e-3 + 1e-12);
        k += 1;
    });
    assert_eq!(got, forces.len());
    assert_eq!(force.decode_stats().bad_lines, 0);

    assert!(emulator.wait_finished(LIMIT));
    assert_eq!(emulator.stats(Device::Eit).unwrap().records_sent, 150);
    let dir = emulator.dir().to_path_buf();
    emulator.stop().expect("clean stop");
    assert!(!dir.exists(), "emulator directory removed on stop");
}

#[test]
fn real_time_pacing_delivers_every_frame() {
    // 20 frames at 100 Hz: paced by the samples' times, still every frame arrives in order.
    let frames = feeds::busy_frames(8, 20, 0.01);
    let emulator =
        Emulator::spawn(EmulatorConfig::default(), EmulatorFeed::default().with_eit(frames), FaultPlan::default())
            .unwrap();
    let path = emulator.path(Device::Eit).unwrap();
    let mut eit = SerialReader::open(ReaderConfig::new(path), EitDecoder::new(8), Instant::now()).unwrap();
    let mut counters = Vec::new();
    feeds::read_n(&mut eit, 20, LIMIT, |r| counters.push(r.record.counter));
    assert_eq!(counters, (0..20).collect::<Vec<u32>>());
}

#[test]
fn real_time_board_drops_what_nobody_reads() {
    // 200 frames of 494 bytes (~99 kB), all due at once, no reader: a Linux pty takes about
    // 64 kB + 4 kB, the rest is dropped (as a board's full transmit buffer would) and the
    // emulator does not block.
    let frames = feeds::busy_frames(120, 200, 0.0);
    let emulator = Emulator::spawn(
        EmulatorConfig::default(),
        EmulatorFeed::default().with_eit(frames.clone()),
        FaultPlan::default(),
    )
    .unwrap();
    assert!(emulator.wait_finished(LIMIT));
    let s = emulator.stats(Device::Eit).unwrap();
    assert!(s.bytes_dropped > 0);
    assert_eq!(s.bytes_written + s.bytes_dropped, 200 * 494);

    // A reader arriving late gets the frames that fit, intact and in order.
    let path = emulator.path(Device::Eit).unwrap();
    let mut eit = SerialReader::open(ReaderConfig::new(path), EitDecoder::new(120), Instant::now()).unwrap();
    let mut counters = Vec::new();
    feeds::read_until_idle(&mut eit, &emulator, LIMIT, |r| {
        let k = r.record.counter as usize;
        assert!(r.record.volts.iter().zip(&frames[k].volts).all(|(g, s)| *g == f64::from(*s as f32)));
        counters.push(r.record.counter);
    });
    assert!(!counters.is_empty());
    assert_eq!(counters, (0..counters.len() as u32).collect::<Vec<_>>());
    assert!(eit.decode_stats().frames * 494 <= s.bytes_written);
}

#[test]
fn missing_port_is_a_clear_error_at_start() {
    let path = std::env::temp_dir().join("skinflow-no-such-board");
    let err = SerialReader::open(ReaderConfig::new(&path), EitDecoder::new(120), Instant::now()).unwrap_err();
    assert!(matches!(&err, SerialError::PortNotFound { path: p } if *p == path), "{err}");
    let msg = err.to_string();
    assert!(msg.contains("skinflow-no-such-board") && msg.contains("does not exist"), "{msg}");
}

#[test]
fn a_path_that_is_not_a_tty_is_an_open_error() {
    let dir = std::env::temp_dir().join(format!("skinflow-serial-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("plain-file");
    std::fs::write(&file, b"not a tty").unwrap();
    let err = SerialReader::open(ReaderConfig::new(&file), ForceDecoder::new(), Instant::now()).unwrap_err();
    assert!(matches!(err, SerialError::Open { .. }), "{err}");
    assert!(err.to_string().contains("plain-file"), "{err}");

    // The emulator refuses to replace a regular file with its link.
    let config = EmulatorConfig { dir: Some(dir.clone()), ..Default::default() };
    std::fs::write(dir.join("eit"), b"mine").unwrap();
    let feed = EmulatorFeed::default().with_eit(feeds::plain_frames(4, 1));
    let err = Emulator::spawn(config, feed, FaultPlan::default()).unwrap_err();
    assert!(err.to_string().contains("not a symlink"), "{err}");
    assert_eq!(std::fs::read(dir.join("eit")).unwrap(), b"mine");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn bad_reader_params_are_rejected() {
    let mut config = ReaderConfig::new("/dev/null");
    config.backoff_max_s = f64::NAN;
    let err = SerialReader::open(config, ForceDecoder::new(), Instant::now()).unwrap_err();
    assert!(err.to_string().contains("backoff_max_s"), "{err}");
}
