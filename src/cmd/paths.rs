//! Checks of the files a command writes, done before any work: an output must not be one of
//! the command's inputs (the same file under another name included), and it must be creatable
//! (its directory exists, it is no directory).

use std::path::Path;

use anyhow::{Result, bail};

/// Whether `a` and `b` name the same existing file (after resolving links and `..`).
pub fn same_file(a: &Path, b: &Path) -> bool {
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    }
}

/// Refuses an output (`flag`, `out`) that is the same file as an input (`name`, path) or as
/// another output, and an output whose directory does not exist.
pub fn check_outputs(inputs: &[(&str, &Path)], outputs: &[(&str, &Path)]) -> Result<()> {
    for (k, &(flag, out)) in outputs.iter().enumerate() {
        for &(name, input) in inputs {
            if same_file(out, input) {
                bail!("{flag} {}: is the {name} {}; refusing to overwrite an input", out.display(), input.display());
            }
        }
        for &(other, path) in &outputs[..k] {
            if out == path || same_file(out, path) {
                bail!("{flag} {} and {other} {} name the same file", out.display(), path.display());
            }
        }
        if let Some(why) = skinflow_nodes::output::unwritable(out) {
            bail!("{flag} {}: {why}", out.display());
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_output_naming_an_input_or_a_missing_directory_is_refused() {
        let d = std::env::temp_dir().join(format!("skinflow-paths-{}", std::process::id()));
        std::fs::create_dir_all(d.join("sub")).unwrap();
        let rec = d.join("rec.h5");
        std::fs::write(&rec, "x").unwrap();
        let other_name = d.join("sub/../rec.h5");
        let e = check_outputs(&[("recording", &rec)], &[("--out", &other_name)]).unwrap_err().to_string();
        assert!(e.contains("--out") && e.contains("is the recording") && e.contains("refusing"), "{e}");
        let e = check_outputs(&[], &[("--json", &d.join("nope/x.json"))]).unwrap_err().to_string();
        assert!(e.contains("--json") && e.contains("nope") && e.contains("does not exist"), "{e}");
        let x = d.join("x.json");
        let e = check_outputs(&[], &[("--json", &x), ("--contacts-csv", &x)]).unwrap_err().to_string();
        assert!(e.contains("name the same file"), "{e}");
        check_outputs(&[("recording", &rec)], &[("--out", &d.join("calib.toml"))]).unwrap();
        assert_eq!(std::fs::read_to_string(&rec).unwrap(), "x");
    }
}
