//! Emulator -> pseudo-terminal -> reader, clean streams: every record arrives intact, in order.

use crate::feeds;

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
    let mut eit = SerialReader::open(feeds::config(path), EitDecoder::new(m), origin).expect("open eit");
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
        SerialReader::open(feeds::config(path), PressureDecoder::try_new(Some(50)).unwrap(), origin).unwrap();
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
    let mut force = SerialReader::open(feeds::config(path), ForceDecoder::new(), origin).unwrap();
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
    let mut eit = SerialReader::open(feeds::config(path), EitDecoder::new(8), Instant::now()).unwrap();
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
    let mut eit = SerialReader::open(feeds::config(path), EitDecoder::new(120), Instant::now()).unwrap();
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

nix::ioctl_read_bad!(bytes_queued, nix::libc::FIONREAD, nix::libc::c_int);

/// A raw pty pair whose slave path a reader opens; the test writes the master.
fn raw_pty() -> (std::os::fd::OwnedFd, std::os::fd::OwnedFd, std::path::PathBuf) {
    use nix::sys::termios::{SetArg, cfmakeraw, tcgetattr, tcsetattr};
    let pty = nix::pty::openpty(None, None).unwrap();
    for fd in [&pty.master, &pty.slave] {
        let mut t = tcgetattr(fd).unwrap();
        cfmakeraw(&mut t);
        tcsetattr(fd, SetArg::TCSANOW, &t).unwrap();
    }
    let path = nix::unistd::ttyname(&pty.slave).unwrap();
    (pty.master, pty.slave, path)
}

/// Waits until the slave's input queue holds `n` bytes (the kernel moves written bytes there
/// asynchronously); a hang guard, not a timing assertion.
fn wait_queued(slave: &std::os::fd::OwnedFd, n: usize) {
    use std::os::fd::AsRawFd;
    let until = Instant::now() + LIMIT;
    loop {
        let mut queued: nix::libc::c_int = 0;
        // SAFETY: FIONREAD writes one c_int through the pointer, which points to a live local;
        // the descriptor is an open tty.
        unsafe { bytes_queued(slave.as_raw_fd(), &mut queued) }.unwrap();
        if usize::try_from(queued).unwrap() >= n {
            return;
        }
        assert!(Instant::now() < until, "only {queued} of {n} bytes queued");
        std::thread::sleep(Duration::from_millis(2));
    }
}

/// Bytes a board sent before the run (the reader opens later) are cleared at open and counted;
/// records that arrive together keep their device spacing (their device time on the host clock),
/// also right after a device restart.
#[test]
fn stale_input_is_cleared_at_open_and_a_burst_keeps_its_device_spacing() {
    use skinflow_serial::encode::encode_eit_frame;
    const M: usize = 4;
    let (master, slave, path) = raw_pty();
    let frame = |counter: u32, time_us: u32| {
        let mut out = Vec::new();
        encode_eit_frame(&mut out, counter, time_us, &[0.5; M]);
        out
    };
    let stale: Vec<u8> = (0..3).flat_map(|c| frame(c, 1000 * c)).collect();
    nix::unistd::write(&master, &stale).unwrap();
    wait_queued(&slave, stale.len());

    let mut eit = SerialReader::open(ReaderConfig::new(&path), EitDecoder::new(M), Instant::now()).unwrap();
    assert_eq!(eit.link_stats().cleared_bytes, stale.len() as u64);

    // The anchor: device time 100 s. Then five frames 1 µs apart in one write, which arrive
    // later than that after it on the host clock (the write follows the anchor's read, and a
    // pty round trip takes longer than 5 µs): they are stamped by their device time, before
    // their read.
    let until = Instant::now() + LIMIT;
    nix::unistd::write(&master, &frame(10, 100_000_000)).unwrap();
    let anchor = eit.poll_next(until).unwrap().map(|r| (r.record.counter, r.t_s, r.host_t_s)).expect("anchor frame");
    assert_eq!(anchor.0, 10, "the stale frames 0..3 were cleared");
    assert_eq!(anchor.1, anchor.2, "the first record anchors the map at its read time");
    let burst: Vec<u8> = (1..=5).flat_map(|k| frame(10 + k, 100_000_000 + k)).collect();
    nix::unistd::write(&master, &burst).unwrap();
    let mut got = Vec::new();
    feeds::read_n(&mut eit, 5, LIMIT, |r| got.push((r.record.counter, r.t_s, r.host_t_s)));
    assert_eq!(got.iter().map(|g| g.0).collect::<Vec<_>>(), vec![11, 12, 13, 14, 15]);
    for (k, (_, t_s, host_t_s)) in got.iter().enumerate() {
        // The device spacing, plus the drift the map allows inside a burst.
        let expected_us = (k + 1) as f64 * (1.0 + skinflow_serial::read::MAX_DRIFT);
        let spacing_us = (t_s - anchor.1) * 1e6;
        assert!((spacing_us - expected_us).abs() < 1e-3, "frame {k}: {spacing_us} µs after the anchor");
        assert!(t_s < host_t_s, "frame {k}: stamped {t_s}, read at {host_t_s}");
    }

    // The board restarts: five frames counted from 0 with device times 1 .. 5 µs, in one write
    // (less device time than the host time since the last frame, as for a real restart). The
    // records of one read are stamped back from its last one by their device spacing (the
    // reader decodes each read ahead), never after their read nor before earlier stamps.
    let restart: Vec<u8> = (0..5).flat_map(|k| frame(k, k + 1)).collect();
    nix::unistd::write(&master, &restart).unwrap();
    let mut after = Vec::new();
    feeds::read_n(&mut eit, 5, LIMIT, |r| after.push((r.record.counter, r.t_s, r.host_t_s)));
    assert_eq!(after.iter().map(|g| g.0).collect::<Vec<_>>(), vec![0, 1, 2, 3, 4]);
    assert!(after[0].1 >= got[4].1, "stamps go on increasing across the restart");
    for w in after.windows(2) {
        assert!(w[1].1 > w[0].1 && w[1].1 <= w[1].2, "{w:?}");
        if w[0].2 == w[1].2 {
            // One read (the usual case for one write): 1 µs apart, as sent.
            assert!(((w[1].1 - w[0].1) * 1e6 - 1.0).abs() < 1e-3, "{w:?}");
        }
    }
    let reads = after.iter().map(|g| g.2.to_bits()).collect::<std::collections::BTreeSet<_>>().len();
    eprintln!("the restart's five frames came in {reads} read(s)");
    let s = eit.decode_stats();
    assert_eq!((s.frames, s.discarded_bytes, s.lost_frames, s.counter_resets), (11, 0, 0, 1));
    drop(slave);
}

/// At fast pacing a small feed fits the pty before any reader opens it: the emulator has
/// finished, but has not delivered until a reader took every byte (stopping it earlier would
/// lose them); once read, it has.
#[test]
fn a_fast_feed_is_delivered_only_once_a_reader_took_every_byte() {
    let frames = feeds::busy_frames(8, 30, 0.0);
    let config = EmulatorConfig { pacing: Pacing::AsFastAsPossible, ..Default::default() };
    let emulator = Emulator::spawn(config, EmulatorFeed::default().with_eit(frames), FaultPlan::default()).unwrap();
    assert!(emulator.wait_finished(LIMIT), "30 small frames fit the pty");
    std::thread::sleep(Duration::from_millis(300));
    assert!(!emulator.delivered(), "no reader yet: {:?}", emulator.stats(Device::Eit));
    let path = emulator.path(Device::Eit).unwrap();
    let mut eit = SerialReader::open(feeds::config(path), EitDecoder::new(8), Instant::now()).unwrap();
    let mut counters = Vec::new();
    feeds::read_n(&mut eit, 30, LIMIT, |r| counters.push(r.record.counter));
    assert_eq!(counters, (0..30).collect::<Vec<u32>>());
    let t0 = Instant::now();
    while !emulator.delivered() {
        assert!(t0.elapsed() < LIMIT, "never delivered: {:?}", emulator.stats(Device::Eit));
        std::thread::sleep(Duration::from_millis(10));
    }
    assert!(emulator.stats(Device::Eit).unwrap().delivered);
    emulator.stop().unwrap();
}

/// EIT frames at 9600 baud through a bridge-like pty (16-byte pieces at the wire rate): a
/// 494-byte frame is 0.51 s on the wire. Each reading's stamp is bounded by the read of its
/// first byte, which came before the read that completed it. The skew is printed, not asserted
/// (no timing assertions); the exact stamps are proven in `read::timer`'s unit tests.
#[test]
fn frames_slow_on_the_wire_are_stamped_by_their_first_byte() {
    let frames = feeds::busy_frames(120, 3, 0.6);
    let config = EmulatorConfig { pacing: Pacing::Wire { baud: 9600 }, ..Default::default() };
    let emulator = Emulator::spawn(config, EmulatorFeed::default().with_eit(frames), FaultPlan::default()).unwrap();
    let path = emulator.path(Device::Eit).unwrap();
    let mut eit = SerialReader::open(feeds::config(path), EitDecoder::new(120), Instant::now()).unwrap();
    let mut got = Vec::new();
    feeds::read_n(&mut eit, 3, LIMIT, |r| got.push((r.record.counter, r.t_s, r.first_host_t_s, r.host_t_s)));
    assert_eq!(got.iter().map(|g| g.0).collect::<Vec<_>>(), vec![0, 1, 2]);
    for &(counter, t_s, first, host) in &got {
        assert!(t_s <= first && first <= host, "frame {counter}: t_s {t_s}, first byte read {first}, completed {host}");
        eprintln!("frame {counter}: completed {:.3} s after its stamp", host - t_s);
    }
    // 31 pieces over 0.51 s per frame: the reader saw each frame over several reads.
    assert!(got.iter().any(|&(_, _, first, host)| first < host), "{got:?}");
    assert!(eit.link_stats().bytes >= 3 * 494);
}
