//! Pins the EIT side of the `paper` profile, measured with the project's own reconstruction
//! (skinflow-eit defaults) and segmentation (skinflow-contact), seed 1: conductivity-sum R^2
//! 0.935 at the centre and 0.781 over all calibration positions (Table II), EIT-NoCal RMSE
//! 1.45 N on the cross-diameter test (Table III). Bands: R^2 +- 0.03, RMSE +- 25 %.
//! Localisation on the calibration frames is pinned to this simulator's own seed-1 figure,
//! 2.24 +- 0.92 mm (mean and sd each +- 25 %), not to the paper's 4.4 +- 1.9 mm, which it beats
//! by about 2 x (MODEL.md says why); it must stay better than the paper's, and at most 5 % of
//! the calibration frames (40 of 1,132 today) may find no contact.
//! Other seeds spread wider (MODEL.md); this pins the simulator with the pipeline of today, so
//! a change on either side that moves these figures shows up here.
//!
//! Ignored by default: it reconstructs ~2,300 frames and precomputes a reconstruction matrix,
//! minutes in a debug build. Run: `cargo test --release -p skinflow-sim --test tests -- eit_baselines --ignored`.

#[path = "../examples/baselines.rs"]
mod baselines;

#[test]
#[ignore = "release-only: cargo test --release -p skinflow-sim --test tests -- eit_baselines --ignored"]
fn paper_profile_eit_baselines_are_pinned() {
    let f = baselines::measure(1, &[]);
    let (loc_mean, loc_sd) = f.localisation_mm;
    eprintln!(
        "R2 centre {:.3} (0.935), R2 all {:.3} (0.781), EIT-NoCal {:.3} N (1.45), localisation {loc_mean:.2} +- \
         {loc_sd:.2} mm (2.24 +- 0.92), {} of {} frames without contact",
        f.r2_centre, f.r2_all, f.nocal_rmse_n, f.missed, f.calibration_frames
    );
    assert!((f.r2_centre - 0.935).abs() <= 0.03, "centre R^2 {}", f.r2_centre);
    assert!((f.r2_all - 0.781).abs() <= 0.03, "all-positions R^2 {}", f.r2_all);
    assert!((f.nocal_rmse_n / 1.45 - 1.0).abs() <= 0.25, "EIT-NoCal RMSE {} N", f.nocal_rmse_n);
    assert!((loc_mean / 2.24 - 1.0).abs() <= 0.25 && loc_mean < 4.4, "localisation error {loc_mean} mm");
    assert!((loc_sd / 0.92 - 1.0).abs() <= 0.25, "localisation error sd {loc_sd} mm");
    assert!(
        f.missed * 20 <= f.calibration_frames,
        "{} of {} calibration frames without contact",
        f.missed,
        f.calibration_frames
    );
}
