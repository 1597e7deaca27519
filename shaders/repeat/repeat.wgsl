// `repeat`: a value carried through a loop body until the body's count is zero (or for a
// fixed number of iterations). The words are copied as bits, whatever their type.
// status: [iterations, stopped, last count, total of the counts, halt, done]; done is set
// with stopped where the loop ended as the host will accept (its count 0 or the fixed
// number reached, no halt): what the executor's chained steps run the rest of the step on
// (exec/run.rs). Entries:
// - `start`: current = initial (unless copy_start is 0: the plan gave both one buffer,
//   binding 0 then a stand-in, unread), status = 0, status[4] = the `halt` check's first
//   word (when one is bound: a nonzero halt stops the loop at once and the host reports
//   it);
// - `advance` (after every body run): current = next, unless the loop has stopped; not
//   dispatched where the plan gave `next` the buffer of `current` (the body wrote it in
//   place: nodes/repeat.rs; binding 1 then stands in, unread). The body runs no
//   iteration past the stop (the executor gates it), so `current` holds the last value
//   either way;
// - `tally` (one thread, after `advance`): unless stopped, count the iteration, add the
//   body's count (word 0) to the total, and stop when its word stop_word is 0, at
//   max_iterations (the host then reports the loop unconverged) or at the fixed count; on
//   the first iteration, copy every word of the count to `first` (0 without one). An
//   iteration the executor runs past the stop (speculatively, while the host reads the
//   status) therefore changes nothing;
// - `finish`: out = current (unless copy_finish is 0: the plan gave both one buffer,
//   binding 4 then a stand-in, unwritten), the iteration count and the total to their
//   outputs.
#import common/index.wgsl

// counted: 0 for a fixed loop without a count (binding 2 then stands in, unread);
// halts: 1 where a halt check is bound (binding 9; else a stand-in, unread).
// max_iterations: the stop when the count never reaches 0 (the host reports it);
// stop_word: the word of `count` whose 0 stops the loop (the total sums word 0);
// copy_start, copy_finish: 0 where `start` and `finish` copy nothing (nodes/repeat.rs);
// first_words: the words of `first` (those of the count, or 1).
struct Params { words: u32, fixed: u32, counted: u32, halts: u32, max_iterations: u32,
                stop_word: u32, copy_start: u32, copy_finish: u32, first_words: u32 }

@group(0) @binding(0) var<storage, read> initial: array<u32>;
@group(0) @binding(1) var<storage, read> next: array<u32>;
@group(0) @binding(2) var<storage, read> count: array<u32>;
@group(0) @binding(3) var<storage, read_write> current: array<u32>;
@group(0) @binding(4) var<storage, read_write> out: array<u32>;
@group(0) @binding(5) var<storage, read_write> iterations: array<u32>;
@group(0) @binding(6) var<storage, read_write> total: array<u32>;
@group(0) @binding(7) var<storage, read_write> status: array<u32>;
@group(0) @binding(8) var<uniform> params: Params;
@group(0) @binding(9) var<storage, read> halt: array<u32>;
@group(0) @binding(10) var<storage, read_write> first: array<u32>;

@compute @workgroup_size(256)
fn start(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
         @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, 256u);
    if (params.copy_start == 1u && i < params.words) {
        current[i] = initial[i];
    }
    if (i < 4u || i == 5u) {
        status[i] = 0u;
    }
    if (i == 4u) {
        var h = 0u;
        if (params.halts == 1u) {
            h = halt[0];
        }
        status[4] = h;
    }
}

@compute @workgroup_size(256)
fn advance(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
           @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, 256u);
    if (i < params.words && status[1] == 0u) {
        current[i] = next[i];
    }
}

@compute @workgroup_size(1)
fn tally() {
    if (status[1] != 0u) {
        return;
    }
    if (status[4] != 0u) {
        status[1] = 1u;
        return;
    }
    var c = 0u;
    var tallied = 0u;
    if (params.counted == 1u) {
        c = count[params.stop_word];
        tallied = count[0];
    }
    let k = status[0] + 1u;
    status[0] = k;
    if (k == 1u) {
        for (var j = 0u; j < params.first_words; j = j + 1u) {
            first[j] = select(0u, count[j], params.counted == 1u);
        }
    }
    status[2] = c;
    status[3] = status[3] + tallied;
    if ((params.fixed == 0u && (c == 0u || k >= params.max_iterations)) || k == params.fixed) {
        status[1] = 1u;
        // At max_iterations with the count still nonzero the host reports the loop
        // unconverged: stopped, not done.
        if (c == 0u || k == params.fixed) {
            status[5] = 1u;
        }
    }
}

@compute @workgroup_size(256)
fn finish(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
          @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, 256u);
    if (params.copy_finish == 1u && i < params.words) {
        out[i] = current[i];
    }
    if (i == 0u) {
        iterations[0] = status[0];
        total[0] = status[3];
    }
}
