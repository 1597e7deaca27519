//! Buffer assignment: values become buffers, and short-lived values share them.
//!
//! Pooled values live from the launch that writes them to the last launch that reads
//! them, over the prologue followed by one step (no pooled value outlives a step: only
//! states and persistent outputs do, and they have buffers of their own). Intervals are
//! packed greedily in launch order: a value takes the smallest free buffer that holds it,
//! else grows the largest free one, else gets a new one. A launch's outputs are placed
//! before the inputs it reads last are freed, so no launch reads and writes one buffer,
//! except by choice: an output declared in place of an input (`PortSpec::in_place_of`)
//! takes that input's buffer where nothing reads the input after it (`in_place_pairs`
//! says when), and the node, seeing the two buffers equal, writes it in place.

use std::collections::{HashMap, HashSet};

use super::{BufferId, BufferRole, InPlace, Launch, Plan, PlanBuffer, Storage, ValueId};
use crate::ids::IdVec;

/// Smallest buffer: bindings of zero bytes are invalid, and a value may be empty (N = 0).
const MIN_BYTES: u64 = 16;

fn padded(bytes: u64) -> u64 {
    bytes.max(MIN_BYTES).next_multiple_of(16)
}

pub fn assign(plan: &mut Plan, in_place: bool) {
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

    let aliases = if in_place {
        in_place_pairs(plan, &launches, &last)
    } else {
        Vec::new()
    };
    // Output -> the input whose buffer it takes; the inputs so handed over are not freed
    // when they die (their output now holds the buffer).
    let alias_of: HashMap<ValueId, ValueId> = aliases.iter().map(|a| (a.output, a.input)).collect();
    let handed: HashSet<ValueId> = aliases.iter().map(|a| a.input).collect();

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
            // The input is written earlier in launch order (before the launch, or, in a
            // loop, by the loop node or an earlier body launch): it has its buffer.
            if let Some(input) = alias_of.get(&v) {
                let b = assigned[input];
                buffers[b].holds.push(format!("{} (in place)", val.name));
                assigned.insert(v, b);
                continue;
            }
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
                && !handed.contains(&v)
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
    plan.in_place = aliases;
}

/// The in-place outputs that may take their input's buffer, in launch order. An output
/// declared in place of an input (`Launch::Node::in_place`) may where
/// - both are pooled values of one type (not a graph input, a state, a requested output
///   or a persistent value, which others read or keep), and the launch reads the input
///   through that port only;
/// - at the top level, no later launch reads the input;
/// - in a loop body, no later launch of the body and nothing after the loop reads it,
///   the loop node does not read it, and it is made inside the loop, where the body
///   rewrites it every iteration: by an earlier launch of the body, or as the loop
///   node's iterate output that the node refills after every body run
///   (`Launch::Loop::refills`: `repeat`'s `current`), provided the node reads the
///   output through that refill's input only (there it sees the buffers shared). A
///   value from outside the loop is read again the next iteration, and no other output
///   of the loop node is the body's to overwrite.
fn in_place_pairs(
    plan: &Plan,
    launches: &[&Launch],
    last: &HashMap<ValueId, usize>,
) -> Vec<InPlace> {
    let pooled = |v: ValueId| plan.values[v].storage == Storage::Pending(BufferRole::Pool);
    // The candidates of a node launch: (node, input, output) where the launch itself
    // allows it.
    let candidates = |l: &Launch| -> Vec<InPlace> {
        let Launch::Node {
            node,
            inputs,
            outputs,
            in_place,
            ..
        } = l
        else {
            return Vec::new();
        };
        in_place
            .iter()
            .filter_map(|&(o, i)| {
                let (input, output) = (inputs[i]?, outputs[o]);
                let once = inputs.iter().filter(|v| **v == Some(input)).count() == 1;
                (once
                    && pooled(input)
                    && pooled(output)
                    && plan.values[input].ty == plan.values[output].ty)
                    .then_some(InPlace {
                        node: *node,
                        input,
                        output,
                    })
            })
            .collect()
    };
    let mut pairs: Vec<InPlace> = Vec::new();
    let mut taken: HashSet<ValueId> = HashSet::new();
    let mut take = |a: InPlace, pairs: &mut Vec<InPlace>| {
        if taken.insert(a.input) {
            pairs.push(a);
        }
    };
    for (i, l) in launches.iter().enumerate() {
        match l {
            Launch::Node { .. } => {
                for a in candidates(l) {
                    if last.get(&a.input) == Some(&i) {
                        take(a, &mut pairs);
                    }
                }
            }
            Launch::Loop {
                inputs: node_inputs,
                outputs: node_outputs,
                body,
                refills,
                ..
            } => {
                for (j, b) in body.iter().enumerate() {
                    for a in candidates(b) {
                        let read_later = body[j + 1..].iter().any(|k| k.reads().contains(&a.input));
                        let read_by_node = node_inputs.contains(&Some(a.input));
                        let made_before = body[..j].iter().any(|k| k.writes().contains(&a.input));
                        let refilled = refills.iter().any(|&(o, r)| {
                            node_outputs[o] == a.input
                                && node_inputs
                                    .iter()
                                    .enumerate()
                                    .all(|(s, v)| *v != Some(a.output) || s == r)
                        });
                        if last.get(&a.input) == Some(&i)
                            && !read_later
                            && !read_by_node
                            && (made_before || refilled)
                        {
                            take(a, &mut pairs);
                        }
                    }
                }
            }
            _ => {}
        }
    }
    pairs
}
