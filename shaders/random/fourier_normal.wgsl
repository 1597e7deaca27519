// Complex standard normals for the stored modes of a half spectrum (the output of rfft),
// three components per mode, such that their inverse transform is real white noise:
// a mode and its conjugate partner, both stored on the planes kx = 0 and kx = nx/2,
// get conjugate values, and self-conjugate modes get real values of variance 1; all
// others have real and imaginary parts of variance 1/2 each.
//
// The draw of mode m (its canonical stored index: the smaller of the pair's) is the
// normals 8m .. 8m+5 of mesoflow's Philox convention (common/philox.wgsl): lanes of the
// blocks 2m and 2m+1, so the Rust twin is `nodes::spectral::fourier_normal`.
#import common/philox.wgsl

fn fourier_normal(k: vec3<i32>, n: vec3<u32>, step: u32, seed_lo: u32, seed_hi: u32, stream: u32) -> array<vec2<f32>, 3> {
    let sx = n.x / 2u + 1u;
    let ix = u32(k.x);
    let iy = u32((k.y + i32(n.y)) % i32(n.y));
    let iz = u32((k.z + i32(n.z)) % i32(n.z));
    var m = ix + sx * (iy + n.y * iz);
    var conj = false;
    var real = false;
    if (ix == 0u || (n.x % 2u == 0u && ix == n.x / 2u)) {
        let pm = ix + sx * ((n.y - iy) % n.y + n.y * ((n.z - iz) % n.z));
        real = pm == m;
        conj = pm < m;
        m = min(m, pm);
    }
    let b0 = philox4x32_10(vec4<u32>(2u * m, step, seed_hi, 0u), vec2<u32>(seed_lo, stream));
    let b1 = philox4x32_10(vec4<u32>(2u * m + 1u, step, seed_hi, 0u), vec2<u32>(seed_lo, stream));
    var out: array<vec2<f32>, 3>;
    let pairs = array<vec2<u32>, 3>(b0.xy, b0.zw, b1.xy);
    for (var c = 0u; c < 3u; c++) {
        let r = sqrt(-2.0 * log(philox_open01(pairs[c].x)));
        let theta = 6.283185307179586 * philox_open01(pairs[c].y);
        var z = vec2<f32>(r * cos(theta), r * sin(theta));
        if (real) {
            z = vec2<f32>(z.x, 0.0);
        } else {
            z = z * 0.7071067811865476;
        }
        if (conj) {
            z.y = -z.y;
        }
        out[c] = z;
    }
    return out;
}
