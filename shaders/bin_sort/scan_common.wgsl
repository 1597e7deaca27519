// bin_sort, step 3 (nodes/bin_sort.rs): the exclusive scan of the first `len` bin
// counters by one workgroup of WG threads, in one dispatch: thread t owns `quads`
// consecutive vec4 of counters (at most 8: 32 counters), sums them, the thread sums are
// scanned across the workgroup (scan_subgroup.wgsl or scan_portable.wgsl), and each
// thread writes its counters' prefix sums to `start` and the counters themselves to
// `count`. The counter buffer is padded to whole vec4 (the host sizes it so), so loads
// of the last quad stay inside it; elements at or past `len` read as zero and are not
// written.

// Threads of the workgroup: 1024 where the device allows, else 256 (set by the host).
override WG: u32 = 1024u;

struct Shape {
    // Bins to scan.
    len: u32,
    // vec4 of counters per thread.
    quads: u32,
}

@group(0) @binding(0) var<storage, read> counter: array<vec4<u32>>;
@group(0) @binding(1) var<storage, read_write> count: array<vec4<u32>>;
@group(0) @binding(2) var<storage, read_write> start: array<vec4<u32>>;
@group(0) @binding(3) var<uniform> shape: Shape;

// The q-th group of four counters, zero at and past `len`.
fn load4(q: u32) -> vec4<u32> {
    let i = 4u * q;
    if (i + 4u <= shape.len) {
        return counter[q];
    }
    var v = vec4<u32>(0u);
    if (i < shape.len) {
        let w = counter[q];
        for (var c = 0u; c < 3u; c++) {
            if (i + c < shape.len) {
                v[c] = w[c];
            }
        }
    }
    return v;
}

// Writes four counters and their prefix sums, none at or past `len`.
fn store4(q: u32, v: vec4<u32>, p: vec4<u32>) {
    let i = 4u * q;
    if (i + 4u <= shape.len) {
        count[q] = v;
        start[q] = p;
        return;
    }
    for (var c = 0u; c < 3u; c++) {
        if (i + c < shape.len) {
            count[q][c] = v[c];
            start[q][c] = p[c];
        }
    }
}

// The sum of thread t's counters.
fn thread_sum(t: u32) -> u32 {
    var s = 0u;
    for (var j = 0u; j < shape.quads; j++) {
        let v = load4(t * shape.quads + j);
        s += (v.x + v.y) + (v.z + v.w);
    }
    return s;
}

// Writes thread t's counters and their prefix sums, starting from `base`, the sum of
// every counter before them.
fn write_prefix(t: u32, base: u32) {
    var p = base;
    for (var j = 0u; j < shape.quads; j++) {
        let q = t * shape.quads + j;
        let v = load4(q);
        let y = p + v.x;
        let z = y + v.y;
        let w = z + v.z;
        store4(q, v, vec4<u32>(p, y, z, w));
        p = w + v.w;
    }
}
