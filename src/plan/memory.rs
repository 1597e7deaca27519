//! Buffer assignment: values become buffers, and short-lived values share them.
//!
//! Pooled values live from the launch that writes them to the last launch that reads
//! them, over the prologue followed by one step (no pooled value outlives a step: only
//! states and persistent outputs do, and they have buffers of their own). Intervals are
//! packed greedily in launch order: a value takes the smallest free buffer that holds it,
//! else grows the largest free one, else gets a new one. A launch's outputs are placed
//! before the inputs it reads last are freed, so no launch reads and writes one buffer.

use std::collections::HashMap;

use super::{BufferId, BufferRole, Plan, PlanBuffer, Storage, ValueId};
use crate::ids::IdVec;

/// Smallest buffer: bindings of zero bytes are invalid, and a value may be empty (N = 0).
const MIN_BYTES: u64 = 16;

fn padded(bytes: u64) -> u64 {
    bytes.max(MIN_BYTES).next_multiple_of(16)
}

pub fn assign(plan: &mut Plan) {
    let launches: Vec<_> = plan.prologue.iter().chain(plan.step.iter()).collect();
    let mut def: HashMap<ValueId, usize> = HashMap::new();
    let mut last: HashMap<ValueId, usize> = HashMap::new();
    for (i, l) in launches.iter().enumerate() {
        for v in l.writes() {
            def.entry(v).or_insert(i);
            last.entry(v).or_insert(i);
        }
        for v in l.reads() {
            last.insert(v, i);
        }
    }

    let mut buffers: IdVec<BufferId, PlanBuffer> = IdVec::new();
    let mut assigned: HashMap<ValueId, BufferId> = HashMap::new();
    // Own buffers first: outputs and persistent values are never shared.
    for (v, val) in plan.values.iter_enumerated() {
        if let Storage::Pending(role @ (BufferRole::Output | BufferRole::Persistent)) = val.storage
        {
            let b = buffers.push(PlanBuffer {
                bytes: padded(val.ty.bytes()),
                role,
                holds: vec![val.name.clone()],
            });
            assigned.insert(v, b);
        }
    }
    // Pooled values by interval.
    let mut free: Vec<BufferId> = Vec::new();
    let mut pool_without_reuse = 0;
    for (i, launch) in launches.iter().enumerate() {
        for v in launch.writes() {
            let val = &plan.values[v];
            if val.storage != Storage::Pending(BufferRole::Pool)
                || def[&v] != i
                || assigned.contains_key(&v)
            {
                continue;
            }
            let need = padded(val.ty.bytes());
            pool_without_reuse += need;
            let best = free
                .iter()
                .enumerate()
                .filter(|(_, b)| buffers[**b].bytes >= need)
                .min_by_key(|(_, b)| buffers[**b].bytes);
            let pick = match best {
                Some((slot, _)) => Some(free.swap_remove(slot)),
                None => free
                    .iter()
                    .enumerate()
                    .max_by_key(|(_, b)| buffers[**b].bytes)
                    .map(|(slot, _)| slot)
                    .map(|slot| free.swap_remove(slot)),
            };
            let b = match pick {
                Some(b) => {
                    buffers[b].bytes = buffers[b].bytes.max(need);
                    b
                }
                None => buffers.push(PlanBuffer {
                    bytes: need,
                    role: BufferRole::Pool,
                    holds: Vec::new(),
                }),
            };
            buffers[b].holds.push(val.name.clone());
            assigned.insert(v, b);
        }
        for v in launch.reads().into_iter().chain(launch.writes()) {
            if last.get(&v) == Some(&i)
                && let Some(&b) = assigned.get(&v)
                && buffers[b].role == BufferRole::Pool
                && !free.contains(&b)
            {
                free.push(b);
            }
        }
    }
    for (v, b) in &assigned {
        plan.values[*v].storage = Storage::Buffer(*b);
    }
    debug_assert!(
        plan.values
            .iter()
            .all(|v| !matches!(v.storage, Storage::Pending(_))),
        "every pending value is written by some launch"
    );

    let m = &mut plan.memory;
    m.inputs = plan.inputs.iter().map(|(_, t)| padded(t.bytes())).sum();
    m.states = plan.states.iter().map(|s| 2 * padded(s.ty.bytes())).sum();
    m.pool = buffers
        .iter()
        .filter(|b| b.role == BufferRole::Pool)
        .map(|b| b.bytes)
        .sum();
    m.outputs = buffers
        .iter()
        .filter(|b| b.role == BufferRole::Output)
        .map(|b| b.bytes)
        .sum();
    m.persistent = buffers
        .iter()
        .filter(|b| b.role == BufferRole::Persistent)
        .map(|b| b.bytes)
        .sum();
    m.pool_without_reuse = pool_without_reuse;
    plan.buffers = buffers;
}
