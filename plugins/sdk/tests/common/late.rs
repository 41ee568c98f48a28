//! A plugin processor for the provenance tests (`provenance.rs`, `alloc.rs`): kind `t-late`
//! holds its inputs and emits each one `lag` calls later under that input's header (plus
//! `shift`), as a derived payload; at flush, the rest.

use std::collections::VecDeque;
use std::path::Path;

use serde::Deserialize;
use skinflow_plugin_sdk::{Columns, Flush, KindSpec, Outputs, PluginNode};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LateParams {
    /// Emits each input `lag` calls after it arrived (the rest at flush).
    lag: usize,
    /// Added to the seq of every header it writes (> 0: a header no input has).
    #[serde(default)]
    shift: u64,
}

/// Holds inputs (seq, t_ns) and emits each `lag` calls later, under its own header (plus
/// `shift`), as a derived payload; at flush, the rest, one per call.
pub struct Late {
    p: LateParams,
    held: VecDeque<(u64, u64)>,
}

impl Late {
    fn emit(&mut self, out: &mut Outputs) {
        if let Some((seq, t_ns)) = self.held.pop_front() {
            out.port(0).header(seq + self.p.shift, t_ns);
            out.port(0).scalar("from", 0.0); // the host takes the value from the provenance
        }
    }
}

impl PluginNode for Late {
    type Params = LateParams;

    fn spec() -> KindSpec {
        KindSpec::new("t-late", "emits each input lag calls later, as a derived payload")
            .input("in", "count", "values")
            .output("out", "derived", "the value of the input it was made from")
            .param("lag", "integer", "", "calls an input is held")
            .param("shift", "integer", "0", "added to the seq of written headers")
    }

    fn new(p: LateParams, _: &Path) -> Result<Self, String> {
        Ok(Late { held: VecDeque::with_capacity(p.lag + 1), p })
    }

    fn process(&mut self, inputs: &[Columns<'_>], out: &mut Outputs) -> Result<(), String> {
        self.held.push_back((inputs[0].seq(), inputs[0].t_ns()));
        if self.held.len() > self.p.lag {
            self.emit(out);
        }
        Ok(())
    }

    fn flush(&mut self, out: &mut Outputs) -> Result<Flush, String> {
        self.emit(out);
        Ok(if self.held.is_empty() { Flush::Done } else { Flush::More })
    }

    fn held(&self) -> u64 {
        self.held.len() as u64
    }
}
