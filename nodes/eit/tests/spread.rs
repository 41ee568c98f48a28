//! The point spread against the reconstruction itself: a frame made from the Jacobian's own
//! prediction of a disc must image exactly as the point spread says (normalized and plain
//! difference modes, all channels and with a dead electrode), and the mirror sidelobe of a press
//! near a corner (the reason the point spread exists) is there.

use skinflow_eit::mask::ChannelMask;
use skinflow_eit::{DifferenceMode, MeshParams, ReconParams, Reconstructor, Sensor};

fn recon(mode: DifferenceMode) -> Reconstructor {
    let params = ReconParams { mesh: MeshParams { elements: 1500, ..Default::default() }, mode, ..Default::default() };
    Reconstructor::new(&Sensor::paper_100mm(), &params).unwrap()
}

/// The decrease image (S/m, positive = press) of a relative decrease `depth` on the disc of
/// radius `r` at `c`, with data made exactly linear: dv = J x.
fn linear_decrease_image(r: &mut Reconstructor, c: [f64; 2], radius: f64, depth: f64) -> Vec<f64> {
    let mode = r.params().mode;
    let model = r.model().unwrap();
    let x: Vec<f64> = model
        .mesh
        .element_centroids_mm()
        .iter()
        .map(|p| if (p[0] - c[0]).hypot(p[1] - c[1]) <= radius { -depth } else { 0.0 })
        .collect();
    let j = &model.jacobian;
    let v_ref = model.v0.clone();
    let v: Vec<f64> = (0..j.nrows())
        .map(|k| {
            let dv: f64 = (0..j.ncols()).map(|e| j[(k, e)] * x[e]).sum();
            match mode {
                DifferenceMode::Normalized => v_ref[k] * (1.0 + dv),
                DifferenceMode::Plain => v_ref[k] + dv,
            }
        })
        .collect();
    let mut img = vec![0.0; r.pixel_count()];
    r.reconstruct_image_into(&v, &v_ref, &mut img).unwrap();
    img.iter().map(|p| -p).collect()
}

fn predicted(r: &mut Reconstructor, c: [f64; 2], radius: f64, depth: f64) -> Vec<f64> {
    let s = r.point_spread(radius).unwrap();
    let m = s.measurement_count();
    let mut u = vec![0.0; m];
    s.source_into(c[0], c[1], &mut u);
    (0..s.pixel_count())
        .map(|q| {
            let mut row = vec![0.0; m];
            s.add_pixel_row(q, &mut row);
            depth * row.iter().zip(&u).map(|(a, b)| a * b).sum::<f64>()
        })
        .collect()
}

fn assert_same(a: &[f64], b: &[f64], what: &str) {
    let peak = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(peak > 0.0, "{what}: empty image");
    let worst = a.iter().zip(b).fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
    // Rows are differences of f64 running sums: agreement to ~1e-12 of the running sums.
    assert!(worst <= 1e-9 * peak, "{what}: worst pixel differs by {worst:e} (peak {peak:e})");
}

#[test]
fn the_point_spread_is_what_the_reconstruction_makes_of_linear_data() {
    for mode in [DifferenceMode::Normalized, DifferenceMode::Plain] {
        let mut r = recon(mode);
        for c in [[0.0, 0.0], [-30.0, -45.0], [42.0, 40.0]] {
            let seen = linear_decrease_image(&mut r, c, 5.0, 0.2);
            assert_same(&seen, &predicted(&mut r, c, 5.0, 0.2), &format!("{mode:?} at {c:?}"));
        }
    }
}

#[test]
fn a_run_of_pixels_sums_what_the_reconstruction_images_over_it() {
    let mut r = recon(DifferenceMode::Normalized);
    let (c, depth) = ([12.0, -20.0], 0.2);
    let seen = linear_decrease_image(&mut r, c, 5.0, depth);
    let s = r.point_spread(5.0).unwrap();
    let mut u = vec![0.0; s.measurement_count()];
    s.source_into(c[0], c[1], &mut u);
    let n = s.pixel_count();
    let width = r.grid().nx;
    // Empty, single pixel, within one image row, across several rows, the whole image.
    for (first, end) in [(100, 100), (1000, 1001), (3 * width + 5, 4 * width - 2), (1500, 1500 + 3 * width + 7), (0, n)]
    {
        let mut w = vec![0.0; s.measurement_count()];
        s.add_pixel_run(first, end, &mut w);
        let predicted = depth * w.iter().zip(&u).map(|(a, b)| a * b).sum::<f64>();
        let summed: f64 = seen[first..end].iter().sum();
        let scale = seen.iter().map(|v| v.abs()).sum::<f64>();
        assert!((predicted - summed).abs() <= 1e-9 * scale, "run {first}..{end}: {predicted:e} against {summed:e}");
    }
}

#[test]
fn the_point_spread_follows_the_channel_mask() {
    let mut r = recon(DifferenceMode::Normalized);
    let s = Sensor::paper_100mm();
    let mask = ChannelMask::from_dead_electrodes(&s.measurements(), s.electrode_count(), &[6]);
    assert!(r.set_mask(&mask).unwrap());
    let c = [20.0, -10.0];
    let seen = linear_decrease_image(&mut r, c, 5.0, 0.2);
    assert_same(&seen, &predicted(&mut r, c, 5.0, 0.2), "dead electrode 6");
    // The masked channels carry no weight in any row.
    let spread = r.point_spread(5.0).unwrap();
    let mut row = vec![0.0; spread.measurement_count()];
    for q in (0..spread.pixel_count()).step_by(97) {
        spread.add_pixel_row(q, &mut row);
    }
    for k in mask.excluded_channels() {
        assert_eq!(row[k], 0.0, "masked channel {k}");
    }
}

#[test]
fn a_press_near_a_corner_has_a_mirror_sidelobe() {
    // 5 mm from the bottom side, 20 mm from the left: the linear image has a second maximum
    // across the corner's diagonal, at about (-45, -30) mm.
    let mut r = recon(DifferenceMode::Normalized);
    let img = predicted(&mut r, [-30.0, -45.0], 5.0, 0.2);
    let grid = *r.grid();
    let peak = img.iter().fold(0.0f64, |m, &v| m.max(v));
    let near = |x: f64, y: f64| {
        (0..img.len())
            .filter(|&q| {
                let p = grid.pixel_centre_mm(q);
                (p[0] - x).hypot(p[1] - y) <= 6.0
            })
            .map(|q| img[q])
            .fold(f64::NEG_INFINITY, f64::max)
    };
    let mirror = near(-46.0, -30.0);
    let far = near(30.0, 45.0);
    assert!(mirror > 0.1 * peak, "mirror sidelobe {mirror:e} against peak {peak:e}");
    assert!(far < 0.5 * mirror, "the far corner {far:e} is quieter than the mirror {mirror:e}");
    // A source with no element centroid inside its disc takes the nearest element.
    let spread = r.point_spread(1e-6).unwrap();
    let mut u = vec![0.0; spread.measurement_count()];
    spread.source_into(3.3, -7.1, &mut u);
    assert!(u.iter().any(|&v| v != 0.0), "a tiny disc still has a source");
    assert!(r.point_spread(0.0).is_err() && r.point_spread(f64::NAN).is_err());
}
