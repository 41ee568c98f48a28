//! Real-time thread settings: CPU pinning and SCHED_FIFO priority, each falling back to a
//! warning when the OS refuses (no privilege, CPU absent).

use thread_priority::{
    RealtimeThreadSchedulePolicy, ThreadPriority, ThreadPriorityValue, ThreadSchedulePolicy,
    set_thread_priority_and_policy, thread_native_id,
};

/// Applies the node's `cpu` and `rt_priority` to the calling thread.
pub(crate) fn apply(node: &str, cpu: Option<usize>, rt_priority: Option<u8>) {
    if let Some(cpu) = cpu {
        let ok = core_affinity::get_core_ids().is_some_and(|ids| ids.iter().any(|c| c.id == cpu))
            && core_affinity::set_for_current(core_affinity::CoreId { id: cpu });
        if ok {
            tracing::info!(node, cpu, "pinned to CPU");
        } else {
            tracing::warn!(node, cpu, "cannot pin to CPU {cpu}; running unpinned");
        }
    }
    if let Some(p) = rt_priority {
        let result = ThreadPriorityValue::try_from(p).map_err(|e| e.to_string()).and_then(|v| {
            set_thread_priority_and_policy(
                thread_native_id(),
                ThreadPriority::Crossplatform(v),
                ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::Fifo),
            )
            .map_err(|e| format!("{e:?}"))
        });
        match result {
            Ok(()) => tracing::info!(node, priority = p, "running with SCHED_FIFO"),
            Err(e) => tracing::warn!(
                node,
                priority = p,
                "cannot set SCHED_FIFO priority {p} ({e}); running with normal priority"
            ),
        }
    }
}
