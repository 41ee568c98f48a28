//! The eval report: CONTRACTS.md §4 JSON (exact keys, `null` where not computable) and the
//! printed comparison in the layout of the paper's Table III, extended with per-diameter
//! RMSE, relative error and latency (speed against error), localization, multi-contact and
//! resolution lines. Strategy objects are keyed by name (JSON objects are unordered; they are
//! printed in evaluator order).

use super::metrics::{Evaluator, mean, percentile, rms, sd};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fmt;

/// Metrics of one strategy.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StrategyReport {
    /// RMSE over all matched contacts, N.
    pub rmse_n: Option<f64>,
    /// Standard deviation of the absolute errors, N.
    pub rmse_sd_n: Option<f64>,
    /// RMSE per indenter diameter (key: diameter in mm as written, "10" when whole), N.
    pub per_diameter_rmse_n: BTreeMap<String, Option<f64>>,
    /// Mean of 100 |F_est - F_true| / F_true over matched contacts.
    pub relative_error_pct: Option<f64>,
    /// Median per-frame latency, us.
    pub latency_us_p50: Option<f64>,
    /// 99th percentile per-frame latency, us.
    pub latency_us_p99: Option<f64>,
}

/// Localization over all matched contacts.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LocalizationReport {
    /// Mean centroid error, mm.
    pub mean_mm: Option<f64>,
    /// Its standard deviation, mm.
    pub sd_mm: Option<f64>,
    /// Matched true contacts.
    pub matched: usize,
    /// Unmatched true contacts.
    pub missed: usize,
    /// Unmatched detections.
    pub spurious: usize,
}

/// Frames with two or more true contacts.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MultiContactReport {
    /// Number of such frames.
    pub frames: usize,
    /// Per strategy, RMSE pooled over their matched contacts, N.
    pub per_contact_rmse_n: BTreeMap<String, Option<f64>>,
}

/// Mean image sharpness over single-contact frames.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ResolutionReport {
    /// Mean RES50, %.
    pub res50_pct: Option<f64>,
    /// Mean RES75, %.
    pub res75_pct: Option<f64>,
}

/// The whole report (serializes to the CONTRACTS.md §4 JSON).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EvalReport {
    /// Recording path (the first, when several were pooled).
    pub recording: String,
    /// The other recordings pooled into this report, in the order given (`skinflow eval A.h5
    /// B.h5 ...`); absent from the JSON when there are none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub more_recordings: Vec<String>,
    /// Evaluated frames.
    pub frames: usize,
    /// Per strategy name.
    pub strategies: BTreeMap<String, StrategyReport>,
    /// Localization.
    pub localization: LocalizationReport,
    /// `null` when the recording has no multi-contact frame.
    pub multi_contact: Option<MultiContactReport>,
    /// RES50 / RES75.
    pub resolution: ResolutionReport,
    /// Strategy (name, label) in evaluator order, for printing only.
    #[serde(skip)]
    pub order: Vec<(String, String)>,
}

/// Diameter as a JSON key: "10" when whole, else the shortest decimal ("12.5").
pub fn diameter_key(d_mm: f64) -> String {
    if d_mm.fract() == 0.0 && d_mm.abs() < 1e15 { format!("{}", d_mm as i64) } else { format!("{d_mm}") }
}

fn finite(v: Option<f64>) -> Option<f64> {
    v.filter(|x| x.is_finite())
}

impl Evaluator {
    /// Reduces everything pushed so far.
    pub fn report(&self, recording: &str) -> EvalReport {
        let mut strategies = BTreeMap::new();
        for (s, name) in self.names.iter().enumerate() {
            let err = |r: &super::metrics::MatchRecord| r.forces_n[s] - r.truth.force_n;
            let abs: Vec<f64> = self.records.iter().map(|r| err(r).abs()).collect();
            let mut per_diameter = BTreeMap::new();
            // Every diameter of the truth keeps its key: `null` where the RMSE is not finite or
            // none of its contacts was matched (CONTRACTS.md section 4), rather than the
            // diameter vanishing from the report.
            for &d in &self.diameters_mm {
                let v = finite(rms(self.records.iter().filter(|r| r.truth.diameter_mm == d).map(err)));
                per_diameter.insert(diameter_key(d), v);
            }
            let rel = mean(
                self.records.iter().filter(|r| r.truth.force_n > 0.0).map(|r| 100.0 * err(r).abs() / r.truth.force_n),
            );
            strategies.insert(
                name.clone(),
                StrategyReport {
                    rmse_n: finite(rms(self.records.iter().map(err))),
                    rmse_sd_n: finite(sd(&abs)),
                    per_diameter_rmse_n: per_diameter,
                    relative_error_pct: finite(rel),
                    latency_us_p50: finite(percentile(&self.latencies_us[s], 50.0)),
                    latency_us_p99: finite(percentile(&self.latencies_us[s], 99.0)),
                },
            );
        }
        let dists: Vec<f64> = self.records.iter().map(|r| r.dist_mm).collect();
        let multi_contact = (self.multi_frames > 0).then(|| MultiContactReport {
            frames: self.multi_frames,
            per_contact_rmse_n: self
                .names
                .iter()
                .enumerate()
                .map(|(s, n)| {
                    let e =
                        self.records.iter().filter(|r| r.truth_in_frame >= 2).map(|r| r.forces_n[s] - r.truth.force_n);
                    (n.clone(), finite(rms(e)))
                })
                .collect(),
        });
        EvalReport {
            recording: recording.to_string(),
            more_recordings: Vec::new(),
            frames: self.frames,
            strategies,
            localization: LocalizationReport {
                mean_mm: finite(mean(dists.iter().copied())),
                sd_mm: finite(sd(&dists)),
                matched: self.records.len(),
                missed: self.missed,
                spurious: self.spurious,
            },
            multi_contact,
            resolution: ResolutionReport {
                res50_pct: finite(mean(self.resolutions.iter().map(|r| r.res50_pct))),
                res75_pct: finite(mean(self.resolutions.iter().map(|r| r.res75_pct))),
            },
            order: self.names.iter().cloned().zip(self.labels.iter().cloned()).collect(),
        }
    }
}

impl EvalReport {
    /// The CONTRACTS.md §4 JSON text.
    pub fn to_json(&self) -> String {
        // Plain maps with string keys, strings and numbers cannot fail to serialize.
        let mut s = serde_json::to_string_pretty(self).expect("the eval report serializes");
        // A text file ends in a newline (and `--json /dev/stdout` leaves the next line its own).
        s.push('\n');
        s
    }
}

/// A table cell: `prec` decimals, or scientific notation for a magnitude of 1e9 or more (a
/// unit error in the truth), which would otherwise print hundreds of digits and break the
/// table.
fn num(v: Option<f64>, prec: usize) -> String {
    v.map_or_else(|| "-".to_string(), |v| if v.abs() >= 1e9 { format!("{v:.2e}") } else { format!("{v:.prec$}") })
}

impl fmt::Display for EvalReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let order: Vec<(String, String)> = if self.order.is_empty() {
            self.strategies.keys().map(|k| (k.clone(), k.clone())).collect()
        } else {
            self.order.clone()
        };
        let matched = self.localization.matched;
        // The label column: 38 wide, or as wide as the longest label (`eval --lane` sets any).
        let w = order.iter().map(|(_, l)| l.chars().count()).max().unwrap_or(0).max(38);
        if !self.more_recordings.is_empty() {
            writeln!(
                f,
                "Pooled over {} recordings: {}, {}",
                1 + self.more_recordings.len(),
                self.recording,
                self.more_recordings.join(", ")
            )?;
        }
        writeln!(f, "Force estimation ({} frames, {matched} matched contacts). Lower is better.", self.frames)?;
        writeln!(
            f,
            "{:<w$} {:>14} {:>13} {:>10} {:>10}",
            "Method", "RMSE [N]", "rel. err [%]", "p50 [us]", "p99 [us]"
        )?;
        for (name, label) in &order {
            let Some(s) = self.strategies.get(name) else {
                continue;
            };
            let rmse = match (s.rmse_n, s.rmse_sd_n) {
                (Some(r), Some(d)) => format!("{} ± {}", num(Some(r), 2), num(Some(d), 2)),
                _ => "-".to_string(),
            };
            writeln!(
                f,
                "{label:<w$} {rmse:>14} {:>13} {:>10} {:>10}",
                num(s.relative_error_pct, 1),
                num(s.latency_us_p50, 1),
                num(s.latency_us_p99, 1)
            )?;
        }
        let mut diameters: Vec<&String> = self.strategies.values().flat_map(|s| s.per_diameter_rmse_n.keys()).collect();
        diameters.sort_by(|a, b| a.parse::<f64>().unwrap_or(f64::NAN).total_cmp(&b.parse::<f64>().unwrap_or(f64::NAN)));
        diameters.dedup();
        if !diameters.is_empty() {
            writeln!(f)?;
            write!(f, "{:<w$}", "Per-diameter RMSE [N]")?;
            for d in &diameters {
                write!(f, " {:>9}", format!("{d} mm"))?;
            }
            writeln!(f)?;
            for (name, label) in &order {
                let Some(s) = self.strategies.get(name) else {
                    continue;
                };
                write!(f, "{label:<w$}")?;
                for d in &diameters {
                    write!(f, " {:>9}", num(s.per_diameter_rmse_n.get(*d).copied().flatten(), 2))?;
                }
                writeln!(f)?;
            }
        }
        writeln!(f)?;
        let l = &self.localization;
        writeln!(
            f,
            "Localization: {} ± {} mm over {} matched contacts ({} missed, {} spurious)",
            num(l.mean_mm, 1),
            num(l.sd_mm, 1),
            l.matched,
            l.missed,
            l.spurious
        )?;
        match &self.multi_contact {
            None => writeln!(f, "Multi-contact: no frame with two or more true contacts")?,
            Some(m) => {
                write!(f, "Multi-contact ({} frames), per-contact RMSE [N]:", m.frames)?;
                for (name, label) in &order {
                    if let Some(v) = m.per_contact_rmse_n.get(name) {
                        write!(f, "\n  {label:<w$} {}", num(*v, 2))?;
                    }
                }
                writeln!(f)?;
            }
        }
        write!(
            f,
            "Resolution: RES50 = {} %, RES75 = {} %",
            num(self.resolution.res50_pct, 2),
            num(self.resolution.res75_pct, 2)
        )
    }
}
