// Indirect dispatch arguments written on the GPU, so that work the executor records ahead
// of a loop's end runs only where it should (exec/run.rs).
// - `main`, a gated loop's gate: each dispatch of its iteration gets its static workgroup
//   counts while the loop runs, zeros once the loop node's `stopped` word is set (or the
//   step's chain is broken: a loop before it in the step did not finish), so an iteration
//   the executor runs past the stop costs only its launches.
// - `tail`, a chained step's gate after a loop's batch: the dispatches from the loop's
//   `finish` to the next loop's `start` (or the step's end) get their static counts where
//   the loop is done (its node's `done` word) and the chain unbroken, zeros otherwise; the
//   chain word keeps the verdict for the gates after it. The host sets the chain word to 1
//   before a submission that runs loops where a tail gate may have cleared it.
// `counts` holds the static counts as (x, y, z) per dispatch, written at compile time.
#import common/index.wgsl

// main: `words` of args from 0, stopped when status[stopped_word] != 0;
// tail: `words` of args from word `first`, run when status[done_word] != 0 (its
// stopped_word unread).
struct Gate { words: u32, stopped_word: u32, first: u32, done_word: u32 }

@group(0) @binding(0) var<storage, read> counts: array<u32>;
@group(0) @binding(1) var<storage, read> status: array<u32>;
@group(0) @binding(2) var<storage, read_write> args: array<u32>;
@group(0) @binding(3) var<uniform> gate: Gate;
@group(0) @binding(4) var<storage, read_write> chain: array<u32>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, 256u);
    if (i < gate.words) {
        let run = status[gate.stopped_word] == 0u && chain[0] != 0u;
        args[i] = select(0u, counts[i], run);
    }
}

// One workgroup: every thread reads the chain word before the first writes it.
@compute @workgroup_size(64)
fn tail(@builtin(local_invocation_index) lid: u32) {
    let go = chain[0] != 0u && status[gate.done_word] != 0u;
    for (var i = lid; i < gate.words; i += 64u) {
        args[gate.first + i] = select(0u, counts[gate.first + i], go);
    }
    storageBarrier();
    if (lid == 0u) {
        chain[0] = select(0u, 1u, go);
    }
}
