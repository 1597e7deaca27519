//! Buffer assignment: values become buffers, and short-lived values share them.
//!
//! Pooled values live from the launch that writes them to the last launch that reads
//! them, over the prologue followed by one step (no pooled value outlives a step: only
//! states and persistent outputs do, and they have buffers of their own). Intervals are
//! packed greedily in launch order: a value takes the smallest free buffer that holds it,
//! else grows the largest free one, else gets a new one. A launch's outputs are placed
//! before the inputs it reads last are freed, so no launch reads and writes one buffer,
//! except by choice (`in_place_pairs` says when): an output declared in place of an
//! input (`PortSpec::in_place_of`) takes that input's buffer where nothing reads the
//! input after it, and the node, seeing the two buffers equal, writes it in place; a
//! loop starts where its initial value lies (`PortSpec::started_from`) and ends where
//! its carried value lies (`PortSpec::final_of`). Values so linked form a class that
//! holds one buffer from its first value's write to its last value's last read; a class
//! that ends in a value with a buffer of its own (a loop's final value that is a state's
//! next value or a requested output) lives in that buffer throughout.

use std::collections::{HashMap, HashSet};

use super::{BufferId, BufferRole, InPlace, Launch, Plan, PlanBuffer, Storage, ValueId, Via};
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
    // Classes of values sharing a buffer: each alias puts its output in its input's
    // class (aliases come in launch order, so an input's class is settled before it is
    // handed on); a class is named by its first value.
    let mut root: HashMap<ValueId, ValueId> = HashMap::new();
    for a in &aliases {
        let r = root.get(&a.input).copied().unwrap_or(a.input);
        root.insert(a.input, r);
        root.insert(a.output, r);
    }
    // A class's end: the last read of any of its values (its buffer is freed there).
    let mut end: HashMap<ValueId, usize> = HashMap::new();
    for (v, r) in &root {
        let e = end.entry(*r).or_insert(0);
        *e = (*e).max(last[v]);
    }
    // A class's home: its value with a buffer of its own (only a loop's final value,
    // `Via::Finish`, may be one; `in_place_pairs` checks that no one else uses it).
    let home: HashMap<ValueId, ValueId> = aliases
        .iter()
        .filter(|a| plan.values[a.output].storage != Storage::Pending(BufferRole::Pool))
        .map(|a| (root[&a.output], a.output))
        .collect();
    for (v, r) in &root {
        if let Some(&h) = home.get(r)
            && let st @ Storage::State { .. } = plan.values[h].storage
        {
            plan.values[*v].storage = st;
        }
    }

    let mut buffers: IdVec<BufferId, PlanBuffer> = IdVec::new();
    let mut assigned: HashMap<ValueId, BufferId> = HashMap::new();
    // Own buffers first: outputs and persistent values are never shared, except with the
    // values of a class they are the home of.
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
    let mut class_buffer: HashMap<ValueId, BufferId> = HashMap::new();
    for (r, h) in &home {
        if let Some(&b) = assigned.get(h) {
            class_buffer.insert(*r, b);
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
            // A class's buffer, taken by its first value written (in launch order; in a
            // loop, its values are all written by the loop's launch).
            let class = root.get(&v).copied();
            if let Some(b) = class.and_then(|r| class_buffer.get(&r).copied()) {
                buffers[b].bytes = buffers[b].bytes.max(need);
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
            if let Some(r) = class {
                class_buffer.insert(r, b);
            }
        }
        for v in launch.reads().into_iter().chain(launch.writes()) {
            if last.get(&v) == Some(&i)
                && root.get(&v).is_none_or(|r| end[r] == i)
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

/// The values that may take the buffer of a value read for the last time where they are
/// written, in launch order:
/// - an output declared in place of an input (`Launch::Node::in_place`, [`Via::Node`])
///   where both are pooled values of one type (not a graph input, a state, a requested
///   output or a persistent value, which others read or keep), and the launch reads the
///   input through that port only; at the top level, where no later launch reads the
///   input; in a loop body, where no later launch of the body and nothing after the loop
///   reads it, the loop node does not read it, and it is made inside the loop, where the
///   body rewrites it every iteration: by an earlier launch of the body, or as the loop
///   node's iterate output that the node refills after every body run
///   (`Launch::Loop::refills`: `repeat`'s `current`), provided the node reads the output
///   through that refill's input only (there it sees the buffers shared). A value from
///   outside the loop is read again the next iteration, and no other output of the loop
///   node is the body's to overwrite;
/// - a loop's iterate output that the node starts from a plain input
///   (`Launch::Loop::starts`, [`Via::Start`]: `repeat`'s `current` from `initial`)
///   where both are pooled values of one type, the loop is the input's last reader and
///   reads it through that port only, its body not at all (the body would see it
///   overwritten). So never a state (a step the `halt` check stops keeps it as it was),
///   a graph input or a requested output;
/// - a loop's output that the node sets from an iterate output after the last iteration
///   (`Launch::Loop::finals`, [`Via::Finish`]: `repeat`'s `out` from `current`) where
///   the iterate output is pooled, of the output's type, read by nothing after the loop
///   nor by the loop node as an input; the output pooled, a requested output or a
///   state's next value that no other launch value shares (its buffer then holds the
///   whole class: every value before it is dead when the loop finishes, and the state's
///   next buffer holds nothing else during a step).
fn in_place_pairs(
    plan: &Plan,
    launches: &[&Launch],
    last: &HashMap<ValueId, usize>,
) -> Vec<InPlace> {
    let pooled = |v: ValueId| plan.values[v].storage == Storage::Pending(BufferRole::Pool);
    let same_type = |a: ValueId, b: ValueId| plan.values[a].ty == plan.values[b].ty;
    // Every value a launch reads or writes (a loop's body included).
    let used: HashSet<ValueId> = launches
        .iter()
        .flat_map(|l| l.reads().into_iter().chain(l.writes()))
        .collect();
    // A loop's final value may hold its class where its storage is its own.
    let home_for_class = |out: ValueId| match plan.values[out].storage {
        Storage::Pending(BufferRole::Pool | BufferRole::Output) => true,
        st @ Storage::State { next: true, .. } => used
            .iter()
            .all(|&v| v == out || plan.values[v].storage != st),
        _ => false,
    };
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
                (once && pooled(input) && pooled(output) && same_type(input, output)).then_some(
                    InPlace {
                        node: *node,
                        input,
                        output,
                        via: Via::Node,
                    },
                )
            })
            .collect()
    };
    let mut pairs: Vec<InPlace> = Vec::new();
    // Values handed on to a value written after them (each to one only, except a loop's
    // carried value, handed to its body and then to the loop's final value: the body's
    // values are dead when the loop finishes).
    let mut taken: HashSet<ValueId> = HashSet::new();
    let take = |a: InPlace, pairs: &mut Vec<InPlace>, taken: &mut HashSet<ValueId>| {
        if taken.insert(a.input) || a.via == Via::Finish {
            pairs.push(a);
        }
    };
    for (i, l) in launches.iter().enumerate() {
        match l {
            Launch::Node { .. } => {
                for a in candidates(l) {
                    if last.get(&a.input) == Some(&i) {
                        take(a, &mut pairs, &mut taken);
                    }
                }
            }
            Launch::Loop {
                node,
                inputs: node_inputs,
                outputs: node_outputs,
                body,
                refills,
                starts,
                finals,
                ..
            } => {
                for &(o, r) in starts {
                    let (Some(initial), current) = (node_inputs[r], node_outputs[o]) else {
                        continue;
                    };
                    let once = node_inputs.iter().filter(|v| **v == Some(initial)).count() == 1;
                    let body_reads = body.iter().any(|k| k.reads().contains(&initial));
                    if pooled(initial)
                        && pooled(current)
                        && same_type(initial, current)
                        && last.get(&initial) == Some(&i)
                        && once
                        && !body_reads
                    {
                        let a = InPlace {
                            node: *node,
                            input: initial,
                            output: current,
                            via: Via::Start,
                        };
                        take(a, &mut pairs, &mut taken);
                    }
                }
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
                            take(a, &mut pairs, &mut taken);
                        }
                    }
                }
                for &(o, c) in finals {
                    let (out, current) = (node_outputs[o], node_outputs[c]);
                    if pooled(current)
                        && home_for_class(out)
                        && same_type(current, out)
                        && last.get(&current) == Some(&i)
                        && !node_inputs.contains(&Some(current))
                    {
                        let a = InPlace {
                            node: *node,
                            input: current,
                            output: out,
                            via: Via::Finish,
                        };
                        take(a, &mut pairs, &mut taken);
                    }
                }
            }
            _ => {}
        }
    }
    pairs
}
