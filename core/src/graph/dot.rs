//! Graphviz rendering of a validated graph (`skinflow dot`).

use std::fmt::Write;

use super::{GraphSpec, Policy};

/// The graph as a Graphviz `digraph`: nodes labelled `id\nkind`, edges labelled with ports,
/// dashed when the policy is `drop_oldest`.
pub fn to_dot(g: &GraphSpec) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "digraph \"{}\" {{\n  rankdir=LR;\n  node [shape=box, style=rounded];", esc(&g.name));
    for n in &g.nodes {
        let _ = writeln!(s, "  \"{}\" [label=\"{}\\n{}\"];", esc(&n.id), esc(&n.id), esc(&n.kind));
    }
    for e in &g.edges {
        let from = &g.nodes[e.from_node];
        let to = &g.nodes[e.to_node];
        let fp = &from.factory.info().outputs[e.from_port].name;
        let tp = &to.factory.info().inputs[e.to_port].name;
        let style = if e.policy == Policy::DropOldest { ", style=dashed" } else { "" };
        let _ = writeln!(
            s,
            "  \"{}\" -> \"{}\" [label=\"{} -> {} ({})\"{}];",
            esc(&from.id),
            esc(&to.id),
            esc(fp),
            esc(tp),
            e.capacity,
            style
        );
    }
    s.push_str("}\n");
    s
}

fn esc(s: &str) -> String {
    s.replace('\\', "\\\\").replace('"', "\\\"")
}
