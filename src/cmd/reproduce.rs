//! `skinflow reproduce --out DIR`: the paper's experiments end to end on the simulated skin
//! (`paper` profile): simulate the calibration, single-contact, cross-diameter and
//! multi-contact protocols, calibrate, evaluate every strategy, and write `DIR/report.md`
//! with the paper's numbers beside ours (plus each evaluation's JSON and plots).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context as _, Result, bail};
use skinflow_contact::correct::{CalibParams, FFit, calibrate};
use skinflow_contact::eval::EvalReport;

use super::pipeline::PipelineArgs;

/// The paper's figures (Tables II and III, section IV).
mod paper {
    pub const R2_EIT: (f64, f64) = (0.935, 0.781);
    pub const R2_PNEUMATIC: (f64, f64) = (0.996, 0.923);
    /// Cross-diameter RMSE +- SD, N.
    pub const RMSE: [(&str, f64, f64); 4] = [
        ("eit-nocal", 1.45, 0.89),
        ("pneumatic-nocal", 0.91, 0.62),
        ("eit-locaware", 1.48, 0.83),
        ("pneumatic-locaware", 0.59, 0.43),
    ];
    /// Pneumatic-LocAware per diameter, N.
    pub const PER_DIAMETER: [(&str, f64); 3] = [("10", 0.47), ("20", 0.43), ("25", 0.80)];
    pub const LOCALIZATION_MM: (f64, f64) = (4.4, 1.9);
    pub const RES50: f64 = 69.61;
    pub const RES75: f64 = 80.00;
    /// Multi-contact per-contact RMSE, N.
    pub const MULTI: [(&str, f64); 2] = [("pneumatic-nocal", 0.91), ("pneumatic-locaware", 0.55)];
    /// Issue #5 goals: Pneumatic-LocAware cross-diameter RMSE, localization, multi-contact
    /// per-contact RMSE (the paper's figures).
    pub const GOAL_RMSE_N: f64 = RMSE[3].1;
    pub const GOAL_LOCALIZATION_MM: f64 = LOCALIZATION_MM.0;
    pub const GOAL_MULTI_N: f64 = MULTI[1].1;
    /// Multi-contact relative error, %.
    pub const MULTI_REL: [(&str, f64); 2] = [("pneumatic-nocal", 26.64), ("pneumatic-locaware", 15.32)];
}

const SCENES: [&str; 4] = ["calibration", "single-contact", "cross-diameter", "multi-contact"];

/// The scene of the two-size calibration (see [`two_size_calibration`]), read after the others.
const TWO_SIZES: &str = "calibration-two-sizes";

/// The scene files this build ships, as the report's section titles describe them.
const SHIPPED: [(&str, &str); 5] = [
    ("calibration", include_str!("../../graphs/scenes/calibration.toml")),
    ("single-contact", include_str!("../../graphs/scenes/single-contact.toml")),
    ("cross-diameter", include_str!("../../graphs/scenes/cross-diameter.toml")),
    ("multi-contact", include_str!("../../graphs/scenes/multi-contact.toml")),
    (TWO_SIZES, include_str!("../../graphs/scenes/calibration-two-sizes.toml")),
];

/// The scenes of `dir` whose text is not the shipped one's, by name (`calibration.toml`).
fn changed_scenes(dir: &Path) -> Vec<String> {
    SHIPPED
        .iter()
        .filter(|(name, text)| std::fs::read_to_string(dir.join(format!("{name}.toml"))).ok().as_deref() != Some(*text))
        .map(|(name, _)| format!("{name}.toml"))
        .collect()
}

fn f(v: Option<f64>, p: usize) -> String {
    v.filter(|x| x.is_finite()).map_or_else(|| "-".into(), |v| format!("{v:.p$}"))
}

/// The `--scenes` default: the scenes the report's section titles describe.
pub const DEFAULT_SCENES: &str = "graphs/scenes";

/// This process's command line as a shell would take it back (`skinflow` for the program,
/// arguments quoted where needed), so the report names every option it was run with.
fn command_line() -> String {
    let quote = |a: String| {
        let plain = !a.is_empty() && a.bytes().all(|b| b.is_ascii_alphanumeric() || b"_./=:,+-@%".contains(&b));
        if plain { a } else { format!("'{}'", a.replace('\'', "'\\''")) }
    };
    std::iter::once("skinflow".to_owned())
        .chain(std::env::args_os().skip(1).map(|a| quote(a.to_string_lossy().into_owned())))
        .collect::<Vec<_>>()
        .join(" ")
}

pub fn run(scenes_dir: &Path, out: &Path, seed: u64, fit_toml: &str, args: &PipelineArgs) -> Result<()> {
    let params = super::calibrate::fit_params(fit_toml)?;
    args.validate()?;
    // Before anything is created: every scene file is there and valid (the last one is read
    // only after the other experiments, minutes in).
    let scenes: Vec<PathBuf> =
        SCENES.iter().chain([&TWO_SIZES]).map(|s| scenes_dir.join(format!("{s}.toml"))).collect();
    let missing: Vec<String> = scenes.iter().filter(|p| !p.is_file()).map(|p| p.display().to_string()).collect();
    if !missing.is_empty() {
        bail!(
            "--scenes {}: missing scene file(s) {} (run from the repository root, or pass --scenes DIR with the scenes of graphs/scenes)",
            scenes_dir.display(),
            missing.join(", ")
        );
    }
    for scene in &scenes {
        skinflow_sim::Scene::from_file(scene).map_err(|e| anyhow::anyhow!("--scenes {}: {e}", scenes_dir.display()))?;
    }
    super::paths::check_output_dir("--out", out)?;
    let t0 = Instant::now();
    std::fs::create_dir_all(out).with_context(|| format!("--out {}: cannot create", out.display()))?;
    let ctx = Run { scenes_dir, out, seed, params: &params, args };
    let rec = |s: &str| ctx.rec(s);
    for s in SCENES {
        super::simulate::run(&scenes_dir.join(format!("{s}.toml")), &rec(s), seed, true)?;
    }
    let calib_path = out.join("calib.toml");
    let (samples, provenance) = super::calibrate::collect(&[rec("calibration")], args)?;
    let fitted = super::calibrate::fit_samples(&[rec("calibration")], &samples, &params, provenance.clone())?;
    fitted.calibration.write(&calib_path).map_err(anyhow::Error::msg)?;
    let cal = &fitted.calibration;
    let report_of = |scene: &str, calib: &Path| ctx.report(scene, calib);
    let mut reports: Vec<(&str, EvalReport)> = Vec::new();
    for s in &SCENES[1..] {
        let r = report_of(s, &calib_path)?;
        let json = out.join(format!("{s}.json"));
        super::paths::write_file(&json.display().to_string(), &json, r.to_json().as_bytes())?;
        super::print_or_warn(&format!("== {s}\n{r}\n"), &format!("the {s} tables (in {} too)", json.display()));
        reports.push((s, r));
    }
    let get = |name: &str| &reports.iter().find(|(n, _)| *n == name).expect("evaluated above").1;
    let (single, cross, multi) = (get("single-contact"), get("cross-diameter"), get("multi-contact"));

    let mut md = String::new();
    let _ = writeln!(md, "## Signal-force correlation R^2 (paper Table II; calibration scene)\n");
    let _ =
        writeln!(md, "| signal | centre (paper) | centre (ours) | all (paper) | all (ours) |\n|---|---|---|---|---|");
    let _ = writeln!(
        md,
        "| EIT conductivity sum | {:.3} | {} | {:.3} | {} |",
        paper::R2_EIT.0,
        f(cal.r2.eit_center, 3),
        paper::R2_EIT.1,
        f(cal.r2.eit_all, 3)
    );
    let _ = writeln!(
        md,
        "| pneumatic pressure | {:.3} | {} | {:.3} | {} |\n",
        paper::R2_PNEUMATIC.0,
        f(cal.r2.pneumatic_center, 3),
        paper::R2_PNEUMATIC.1,
        f(cal.r2.pneumatic_all, 3)
    );
    let t = &cal.training;
    if t.holdout_folds > 0 {
        let _ = writeln!(md, "## Calibration fit: training and held-out locations (calibration scene)\n");
        let _ = writeln!(
            md,
            "RMSE on the {} calibration samples, and on the same samples predicted by fits made without \
             their location ({} folds of the {} locations; the whole fit repeated per fold).\n",
            t.samples, t.holdout_folds, t.locations
        );
        let _ = writeln!(md, "| strategy | training, N | held-out locations, N |\n|---|---|---|");
        for (name, train) in &t.train_rmse_n {
            let _ = writeln!(md, "| {name} | {train:.3} | {} |", f(t.holdout_rmse_n.get(name).copied(), 3));
        }
        let _ = writeln!(md);
    }
    let _ = writeln!(md, "## Cross-diameter force RMSE, N (paper Table III; 10/20/25 mm indenters)\n");
    let _ = writeln!(
        md,
        "| strategy | paper | ours | ours: 10 mm | 20 mm | 25 mm | rel. err % | latency p50 / p99 us |\n|---|---|---|---|---|---|---|---|"
    );
    for (name, s) in &cross.strategies {
        let p = paper::RMSE
            .iter()
            .find(|(n, _, _)| n == name)
            .map_or("-".to_string(), |(_, m, sd)| format!("{m:.2} ± {sd:.2}"));
        let d = |k: &str| s.per_diameter_rmse_n.get(k).copied().flatten().map_or("-".into(), |v| format!("{v:.2}"));
        let _ = writeln!(
            md,
            "| {name} | {p} | {} ± {} | {} | {} | {} | {} | {} / {} |",
            f(s.rmse_n, 2),
            f(s.rmse_sd_n, 2),
            d("10"),
            d("20"),
            d("25"),
            f(s.relative_error_pct, 1),
            f(s.latency_us_p50, 0),
            f(s.latency_us_p99, 0)
        );
    }
    let pd: Vec<String> = paper::PER_DIAMETER.iter().map(|(d, v)| format!("{d} mm {v:.2}")).collect();
    let _ = writeln!(md, "\nPaper, Pneumatic-LocAware per diameter: {} N.\n", pd.join(", "));
    let _ = writeln!(md, "## Single contact (paper section IV-A; 7 x 7 grid at 5 N)\n");
    let _ = writeln!(md, "| metric | paper | ours |\n|---|---|---|");
    let l = &single.localization;
    let _ = writeln!(
        md,
        "| localization error, mm | {:.1} ± {:.1} | {} ± {} (matched {}, missed {}, spurious {}) |",
        paper::LOCALIZATION_MM.0,
        paper::LOCALIZATION_MM.1,
        f(l.mean_mm, 1),
        f(l.sd_mm, 1),
        l.matched,
        l.missed,
        l.spurious
    );
    let _ = writeln!(md, "| RES50, % | {:.2} | {} |", paper::RES50, f(single.resolution.res50_pct, 2));
    let _ = writeln!(md, "| RES75, % | {:.2} | {} |", paper::RES75, f(single.resolution.res75_pct, 2));
    for name in ["pneumatic-locaware", "pneumatic-forward"] {
        if let Some(s) = single.strategies.get(name) {
            let _ = writeln!(md, "| {name} RMSE at 5 N, N | - | {} |", f(s.rmse_n, 2));
        }
    }
    let _ = writeln!(md, "\n## Multi-contact (paper section IV-B; its eight cases)\n");
    let _ = writeln!(
        md,
        "| strategy | per-contact RMSE, N (paper) | ours | rel. err % (paper) | ours |\n|---|---|---|---|---|"
    );
    for (name, s) in &multi.strategies {
        let pm = paper::MULTI.iter().find(|(n, _)| n == name).map_or("-".into(), |(_, v)| format!("{v:.2}"));
        let pr = paper::MULTI_REL.iter().find(|(n, _)| n == name).map_or("-".into(), |(_, v)| format!("{v:.2}"));
        let ours = per_contact(multi, name);
        let _ = writeln!(md, "| {name} | {pm} | {} | {pr} | {} |", f(ours, 2), f(s.relative_error_pct, 1));
    }
    let l = &multi.localization;
    let _ = writeln!(
        md,
        "\nMulti-contact localization: {} ± {} mm (matched {}, missed {}, spurious {}).",
        f(l.mean_mm, 1),
        f(l.sd_mm, 1),
        l.matched,
        l.missed,
        l.spurious
    );
    let (prop, comp) = (per_contact(multi, "pneumatic-locaware"), per_contact(multi, "pneumatic-locaware-sensitivity"));
    if let (Some(prop), Some(comp)) = (prop, comp) {
        let verdict = if comp < prop {
            format!("the proportional split costs {:.2} N of per-contact RMSE on this data", prop - comp)
        } else {
            format!("the compensated split does not help on this data ({:.2} N worse)", comp - prop)
        };
        let _ = writeln!(
            md,
            "\nPneumatic-LocAware and pneumatic-locaware-sensitivity share one calibration and differ only in \
             how dP is split across contacts: in proportion to C_i (the paper), or to the force equivalents \
             (C_i / k(x_i, y_i))^(1/gamma) of the EIT response C = k F^gamma learned from the calibration. \
             Their per-contact RMSE is {prop:.2} against {comp:.2} N: {verdict}."
        );
    }
    if params.f_fit == FFit::Joint {
        // The same run with the paper's fitting order, so the joint fit's effect is on record.
        let seq_params = CalibParams { f_fit: FFit::Sequential, ..params.clone() };
        let seq_path = out.join("calib-sequential.toml");
        calibrate(&samples, &seq_params, provenance)
            .map_err(anyhow::Error::msg)?
            .calibration
            .write(&seq_path)
            .map_err(anyhow::Error::msg)?;
        let (seq_cross, seq_multi) = (report_of("cross-diameter", &seq_path)?, report_of("multi-contact", &seq_path)?);
        let la = "pneumatic-locaware";
        let _ = writeln!(md, "\n## Pneumatic-LocAware: joint f fit against the paper's fitting order\n");
        let _ = writeln!(
            md,
            "This run fits f together with g and b (`f_fit = \"joint\"`, the default). The paper fits f on \
             all locations pooled first, then g and b; `calib-sequential.toml` is that fit \
             (`skinflow reproduce --fit 'f_fit = \"sequential\"'` gives the whole report with it).\n"
        );
        let _ =
            writeln!(md, "| f fit | cross-diameter RMSE, N | 10 / 20 / 25 mm | multi-contact per-contact RMSE, N |");
        let _ = writeln!(md, "|---|---|---|---|");
        for (name, c, m) in [("joint", cross, multi), ("sequential (paper's order)", &seq_cross, &seq_multi)] {
            let _ = writeln!(md, "| {name} | {} | {} |", cross_cells(c, la), f(per_contact(m, la), 3));
        }
    }
    papers_method(&ctx, &mut md, single, cross, multi)?;
    size_ablation(&ctx, &mut md, cross)?;
    two_size_calibration(&ctx, &mut md, cross, multi)?;
    goals(&mut md, cross, single, multi);
    if !fitted.warnings.is_empty() {
        let _ = writeln!(md, "\n## Calibration warnings\n");
        for w in &fitted.warnings {
            let _ = writeln!(md, "- {w}");
        }
    }
    // The header goes last so that its time covers every run above.
    let mut head = String::new();
    let _ = writeln!(head, "# skinflow reproduction of the paper (simulated skin, `paper` profile)\n");
    let _ = writeln!(
        head,
        "Generated by `{}` (seed {seed}) in {:.0} s. Recordings, the calibration, per-scene JSON (CONTRACTS.md \
         section 4) are in the same directory.\n",
        command_line(),
        t0.elapsed().as_secs_f64()
    );
    let changed = changed_scenes(scenes_dir);
    if !changed.is_empty() {
        let _ = writeln!(
            head,
            "The scenes {} of `{}` differ from those this build ships ({DEFAULT_SCENES}), which the section titles \
             below describe.\n",
            changed.join(", "),
            scenes_dir.display()
        );
    }
    md.insert_str(0, &head);
    let report = out.join("report.md");
    std::fs::write(&report, &md).with_context(|| format!("{}: cannot write", report.display()))?;
    super::note(&format!("report written to {}", report.display()));
    Ok(())
}

/// What every stage of a reproduction shares.
struct Run<'a> {
    scenes_dir: &'a Path,
    out: &'a Path,
    seed: u64,
    params: &'a CalibParams,
    args: &'a PipelineArgs,
}

impl Run<'_> {
    /// The recording of a scene.
    fn rec(&self, scene: &str) -> PathBuf {
        self.out.join(format!("{scene}.h5"))
    }

    /// Simulates `scene_file` into the recording of `scene`.
    fn simulate(&self, scene_file: &Path, scene: &str) -> Result<PathBuf> {
        let rec = self.rec(scene);
        super::simulate::run(scene_file, &rec, self.seed, true)?;
        Ok(rec)
    }

    /// Evaluates the recording of `scene` with a calibration.
    fn report(&self, scene: &str, calib: &Path) -> Result<EvalReport> {
        let rec = self.rec(scene);
        Ok(super::eval::evaluate(std::slice::from_ref(&rec), calib, self.args, false)?
            .evaluator
            .report(&rec.display().to_string()))
    }

    /// Evaluates as [`Run::report`] and writes the JSON as `OUT/{json}.json`.
    fn report_to_json(&self, scene: &str, calib: &Path, json: &str) -> Result<EvalReport> {
        let r = self.report(scene, calib)?;
        let path = self.out.join(format!("{json}.json"));
        std::fs::write(&path, r.to_json()).with_context(|| format!("{}: cannot write", path.display()))?;
        Ok(r)
    }
}

/// The paper's segmentation: one global Otsu cut, plain connected components, no sidelobe
/// removal (skinflow's three additions off).
const PAPER_SEGMENTATION: &str = "separation = 0.0, weak_peak = 0.0, ghost_share = 0.0";

/// The paper's method end to end on the same recordings: its segmentation and its fitting
/// order (f on all locations pooled first, then g and b), calibrated and evaluated beside this
/// report's pipeline, so the figures labelled with the paper's strategy names above can be
/// told from a strict reproduction.
fn papers_method(
    ctx: &Run,
    md: &mut String,
    single: &EvalReport,
    cross: &EvalReport,
    multi: &EvalReport,
) -> Result<()> {
    let _ = writeln!(md, "\n## The paper's method end to end\n");
    if !ctx.args.segment.trim().is_empty() {
        let _ = writeln!(
            md,
            "Not run: this report's segmentation was set with `--segment`, so the comparison with the paper's \
             segmentation (`{PAPER_SEGMENTATION}`) would mix two changes."
        );
        return Ok(());
    }
    let args = PipelineArgs { segment: PAPER_SEGMENTATION.into(), ..ctx.args.clone() };
    let params = CalibParams { f_fit: FFit::Sequential, ..ctx.params.clone() };
    let paper_run = Run { scenes_dir: ctx.scenes_dir, out: ctx.out, seed: ctx.seed, params: &params, args: &args };
    let (samples, provenance) = super::calibrate::collect(&[ctx.rec("calibration")], &args)?;
    let calib = ctx.out.join("calib-paper-method.toml");
    calibrate(&samples, &params, provenance)
        .map_err(anyhow::Error::msg)?
        .calibration
        .write(&calib)
        .map_err(anyhow::Error::msg)?;
    let single2 = paper_run.report_to_json("single-contact", &calib, "single-contact-paper-method")?;
    let cross2 = paper_run.report_to_json("cross-diameter", &calib, "cross-diameter-paper-method")?;
    let multi2 = paper_run.report_to_json("multi-contact", &calib, "multi-contact-paper-method")?;
    let ours = match ctx.params.f_fit {
        FFit::Joint => "f fitted jointly with g and b",
        FFit::Sequential => "f pooled first",
    };
    let _ = writeln!(
        md,
        "The rows named after the paper's strategies above run them on skinflow's pipeline: its segmentation \
         adds a saddle split, weak-contact regions and sidelobe removal, and this run's f fit is `{}`. Here the \
         same recordings go through the paper's method as written: one Otsu cut (`--segment '{PAPER_SEGMENTATION}'`) \
         and f pooled over all locations first (`f_fit = \"sequential\"`); `calib-paper-method.toml` and the \
         `*-paper-method.json` files are that run.\n",
        match ctx.params.f_fit {
            FFit::Joint => "joint",
            FFit::Sequential => "sequential",
        }
    );
    let _ = writeln!(
        md,
        "| pipeline | Pneumatic-LocAware cross-diameter RMSE, N | 10 / 20 / 25 mm | multi-contact per-contact RMSE, N | \
         localization, mm (single contact) | multi-contact contacts matched / missed / spurious |\n|---|---|---|---|---|---|"
    );
    let paper_diameters: Vec<String> = paper::PER_DIAMETER.iter().map(|(_, v)| format!("{v:.2}")).collect();
    let _ = writeln!(
        md,
        "| the paper (its own data) | {:.2} | {} | {:.2} | {:.1} | - |",
        paper::GOAL_RMSE_N,
        paper_diameters.join(" / "),
        paper::GOAL_MULTI_N,
        paper::GOAL_LOCALIZATION_MM
    );
    let la = "pneumatic-locaware";
    for (name, s, c, m) in [
        (format!("this report: skinflow's segmentation, {ours}"), single, cross, multi),
        ("the paper's method: one Otsu cut, f pooled first".to_owned(), &single2, &cross2, &multi2),
    ] {
        let l = &m.localization;
        let _ = writeln!(
            md,
            "| {name} | {} | {} | {} | {} / {} / {} |",
            cross_cells(c, la),
            f(per_contact(m, la), 3),
            f(s.localization.mean_mm, 2),
            l.matched,
            l.missed,
            l.spurious
        );
    }
    Ok(())
}

/// The pneumatic strategies the two extra experiments compare.
const PNEUMATIC_ROWS: [&str; 4] =
    ["pneumatic-nocal", "pneumatic-locaware", "pneumatic-area-aware", "pneumatic-forward"];

/// Scene name of the size ablation (the cross-diameter scene with `area_exponent = 0`).
const SAME_RESPONSE: &str = "cross-diameter-same-response";

/// Writes the cross-diameter scene with the simulated indenter-size effect switched off
/// (`[model] area_exponent = 0`: every indenter saturates like the calibration one), so the
/// report can show how much of the cross-diameter error that one effect causes.
fn same_response_scene(scene: &Path, out: &Path) -> Result<f64> {
    let text = std::fs::read_to_string(scene).with_context(|| format!("{}: cannot read", scene.display()))?;
    let mut table: toml::Table = toml::from_str(&text).with_context(|| format!("{}: not TOML", scene.display()))?;
    let q = skinflow_sim::Scene::from_file(scene).map_err(anyhow::Error::msg)?.profile.area_exponent;
    let section = |table: &mut toml::Table, key: &str| -> Result<toml::Table> {
        match table.remove(key) {
            None => Ok(toml::Table::new()),
            Some(toml::Value::Table(t)) => Ok(t),
            Some(_) => anyhow::bail!("{}: `{key}` is not a table", scene.display()),
        }
    };
    let mut header = section(&mut table, "scene")?;
    header.insert("name".into(), toml::Value::String(SAME_RESPONSE.into()));
    table.insert("scene".into(), toml::Value::Table(header));
    let mut model = section(&mut table, "model")?;
    model.insert("area_exponent".into(), toml::Value::Float(0.0));
    table.insert("model".into(), toml::Value::Table(model));
    let derived = format!(
        "# Written by `skinflow reproduce`: {} with the indenter-size effect off\n\
         # ([model] area_exponent = 0, was {q}).\n{}",
        scene.display(),
        toml::to_string(&table)?
    );
    std::fs::write(out, derived).with_context(|| format!("{}: cannot write", out.display()))?;
    Ok(q)
}

/// The size ablation: simulates, evaluates and reports the cross-diameter scene without the
/// indenter-size effect beside the scene as shipped.
fn size_ablation(ctx: &Run, md: &mut String, cross: &EvalReport) -> Result<()> {
    let scene = ctx.out.join(format!("{SAME_RESPONSE}.toml"));
    let q = same_response_scene(&ctx.scenes_dir.join("cross-diameter.toml"), &scene)?;
    ctx.simulate(&scene, SAME_RESPONSE)?;
    let ablated = ctx.report_to_json(SAME_RESPONSE, &ctx.out.join("calib.toml"), SAME_RESPONSE)?;
    let _ = writeln!(md, "\n## Where the cross-diameter error comes from: the indenter-size effect\n");
    let _ = writeln!(
        md,
        "The simulated pressure response saturates sooner for indenters larger than the calibration \
         one: F_nl(d) = F_nl min(1, (d_ref / d)^q) with q = {q} (`area_exponent`), the effect the paper \
         gives for its 25 mm result. A strategy that sees only dP and the centroid cannot correct it \
         from a one-indenter calibration. `{SAME_RESPONSE}.toml` is the same scene (same seed, \
         locations and loads) with q = 0, evaluated with the same calibration (a diagnostic, not a goal).\n"
    );
    let _ = writeln!(md, "| strategy | as shipped, N | 10 / 20 / 25 mm | q = 0, N | 10 / 20 / 25 mm |");
    let _ = writeln!(md, "|---|---|---|---|---|");
    for name in PNEUMATIC_ROWS {
        let _ = writeln!(md, "| {name} | {} | {} |", cross_cells(cross, name), cross_cells(&ablated, name));
    }
    Ok(())
}

/// Beyond the paper's protocol: the calibration scene again with a second indenter size
/// (`calibration-two-sizes.toml`), its calibration evaluated on the same cross-diameter and
/// multi-contact recordings beside the paper's one-size calibration.
fn two_size_calibration(ctx: &Run, md: &mut String, cross: &EvalReport, multi: &EvalReport) -> Result<()> {
    let name = TWO_SIZES;
    let rec = ctx.simulate(&ctx.scenes_dir.join(format!("{name}.toml")), name)?;
    let fitted = super::calibrate::fit(&rec, ctx.params, ctx.args)
        .with_context(|| format!("{}: calibration failed", rec.display()))?;
    let calib = ctx.out.join("calib-two-sizes.toml");
    fitted.calibration.write(&calib).map_err(anyhow::Error::msg)?;
    let sizes = &fitted.calibration.training.diameters_mm;
    let sizes_text: Vec<String> = sizes.iter().map(|d| format!("{d:.0}")).collect();
    let tested: Vec<f64> =
        cross.strategies.values().flat_map(|s| s.per_diameter_rmse_n.keys()).filter_map(|k| k.parse().ok()).collect();
    let unseen = sizes.iter().all(|d| tested.iter().all(|t| (t - d).abs() >= 0.5));
    let cross2 = ctx.report_to_json("cross-diameter", &calib, "cross-diameter-two-sizes")?;
    let multi2 = ctx.report_to_json("multi-contact", &calib, "multi-contact-two-sizes")?;
    let _ = writeln!(md, "\n## Beyond the paper's protocol: calibrating with two indenter sizes\n");
    let _ = writeln!(
        md,
        "The paper calibrates with one 15 mm indenter. `{name}.toml` runs the same protocol with {} mm \
         indenters ({}); `calib-two-sizes.toml` is its calibration, evaluated on the same test recordings \
         (not a goal).\n",
        sizes_text.join(" and "),
        if unseen { "none of them a test size" } else { "one of them also a test size" }
    );
    let _ = writeln!(
        md,
        "| strategy | cross-diameter, one size, N | 10 / 20 / 25 mm | two sizes, N | 10 / 20 / 25 mm | multi-contact per-contact, one / two sizes, N |"
    );
    let _ = writeln!(md, "|---|---|---|---|---|---|");
    for s in PNEUMATIC_ROWS {
        let _ = writeln!(
            md,
            "| {s} | {} | {} | {} / {} |",
            cross_cells(cross, s),
            cross_cells(&cross2, s),
            f(per_contact(multi, s), 3),
            f(per_contact(&multi2, s), 3)
        );
    }
    if !fitted.warnings.is_empty() {
        let _ = writeln!(md, "\nWarnings of this calibration:\n");
        for w in &fitted.warnings {
            let _ = writeln!(md, "- {w}");
        }
    }
    Ok(())
}

/// Two table cells of a strategy on a cross-diameter report: its RMSE and its per-diameter
/// RMSE in "10 / 20 / 25 mm" order, N.
fn cross_cells(r: &EvalReport, name: &str) -> String {
    let per_diameter = r.strategies.get(name).map_or("-".into(), |s| {
        paper::PER_DIAMETER.map(|(k, _)| f(s.per_diameter_rmse_n.get(k).copied().flatten(), 2)).join(" / ")
    });
    format!("{} | {per_diameter}", f(rmse(r, name), 3))
}

/// A strategy's RMSE on a report, N.
fn rmse(r: &EvalReport, name: &str) -> Option<f64> {
    r.strategies.get(name).and_then(|s| s.rmse_n)
}

/// A strategy's multi-contact per-contact RMSE on a report, N.
fn per_contact(r: &EvalReport, name: &str) -> Option<f64> {
    r.multi_contact.as_ref().and_then(|m| m.per_contact_rmse_n.get(name).copied().flatten())
}

/// The goals for this report, each checked against the figures above.
fn goals(md: &mut String, cross: &EvalReport, single: &EvalReport, multi: &EvalReport) {
    let per_contact = |name: &str| per_contact(multi, name);
    // Best of skinflow's strategies (those the paper does not have) on a figure.
    let best = |fig: &dyn Fn(&str) -> Option<f64>| {
        cross
            .strategies
            .keys()
            .filter(|n| !paper::RMSE.iter().any(|(p, _, _)| p == n))
            .filter_map(|n| fig(n).map(|v| (n.clone(), v)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
    };
    let verdict = |v: Option<f64>, goal: f64| match v {
        Some(v) if v <= goal => format!("{v:.3}: met"),
        Some(v) => format!("{v:.3}: not met"),
        None => "-: not computed".into(),
    };
    let _ = writeln!(md, "\n## Goals (issue #5), checked on this run\n");
    let _ = writeln!(
        md,
        "\"Best new strategy\" is the lowest of skinflow's strategies on this run, picked on the \
         data it is judged on (a selection among a handful; the README gives three seeds).\n"
    );
    let _ = writeln!(md, "| goal | result |\n|---|---|");
    let _ = writeln!(
        md,
        "| Pneumatic-LocAware cross-diameter RMSE <= {} N | {} |",
        paper::GOAL_RMSE_N,
        verdict(rmse(cross, "pneumatic-locaware"), paper::GOAL_RMSE_N)
    );
    let best_cross = best(&|n| rmse(cross, n));
    if let Some((n, v)) = &best_cross {
        let _ = writeln!(
            md,
            "| best new strategy, cross-diameter RMSE <= {} N | {n}, {} |",
            paper::GOAL_RMSE_N,
            verdict(Some(*v), paper::GOAL_RMSE_N)
        );
    }
    let _ = writeln!(
        md,
        "| mean localization error <= {} mm (single contact) | {} |",
        paper::GOAL_LOCALIZATION_MM,
        verdict(single.localization.mean_mm, paper::GOAL_LOCALIZATION_MM)
    );
    let _ = writeln!(
        md,
        "| Pneumatic-LocAware multi-contact per-contact RMSE <= {} N | {} |",
        paper::GOAL_MULTI_N,
        verdict(per_contact("pneumatic-locaware"), paper::GOAL_MULTI_N)
    );
    let best_multi = best(&per_contact);
    if let Some((n, v)) = &best_multi {
        let _ = writeln!(
            md,
            "| best new strategy, multi-contact per-contact RMSE <= {} N | {n}, {} |",
            paper::GOAL_MULTI_N,
            verdict(Some(*v), paper::GOAL_MULTI_N)
        );
    }
    let beats = |ours: Option<(String, f64)>, paper: Option<f64>| match (ours, paper) {
        (Some((n, o)), Some(p)) if o < p => format!("yes: {n} {o:.3} N < {p:.3} N"),
        (Some((n, o)), Some(p)) => format!("no: {n} {o:.3} N >= {p:.3} N"),
        _ => "-".into(),
    };
    let _ = writeln!(
        md,
        "| a new strategy beats Pneumatic-LocAware, cross-diameter | {} |",
        beats(best_cross, rmse(cross, "pneumatic-locaware"))
    );
    let _ = writeln!(
        md,
        "| a new strategy beats Pneumatic-LocAware, multi-contact | {} |",
        beats(best_multi, per_contact("pneumatic-locaware"))
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The shipped scenes read as unchanged; an edited or missing one is named.
    #[test]
    fn changed_scenes_are_named_by_their_text_not_their_path() {
        let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join(DEFAULT_SCENES);
        assert_eq!(changed_scenes(&shipped), Vec::<String>::new());
        let dir = std::env::temp_dir().join(format!("skinflow-reproduce-scenes-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        for (name, text) in SHIPPED {
            std::fs::write(dir.join(format!("{name}.toml")), text).unwrap();
        }
        assert!(changed_scenes(&dir).is_empty(), "copies elsewhere are the shipped scenes");
        std::fs::write(dir.join("multi-contact.toml"), "[scene]\n").unwrap();
        std::fs::remove_file(dir.join("calibration.toml")).unwrap();
        assert_eq!(changed_scenes(&dir), ["calibration.toml", "multi-contact.toml"]);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
