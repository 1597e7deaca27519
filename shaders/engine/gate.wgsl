// A gated loop's indirect dispatch arguments, written after each iteration's decision:
// each dispatch's static workgroup counts while the loop runs, zeros once the loop node's
// `stopped` word is set, so an iteration the executor runs past the stop (speculatively,
// while the host reads the status) costs only its launches. `counts` holds the static
// counts as (x, y, z) per dispatch, written when the program is compiled.
#import common/index.wgsl

struct Gate { words: u32, stopped_word: u32 }

@group(0) @binding(0) var<storage, read> counts: array<u32>;
@group(0) @binding(1) var<storage, read> status: array<u32>;
@group(0) @binding(2) var<storage, read_write> args: array<u32>;
@group(0) @binding(3) var<uniform> gate: Gate;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, 256u);
    if (i < gate.words) {
        args[i] = select(counts[i], 0u, status[gate.stopped_word] != 0u);
    }
}
