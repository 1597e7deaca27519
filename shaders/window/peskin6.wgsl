// The 6-point Peskin-like window of Bao, Kaye and Peskin (2016), C3, moments to third
// order, in units of h; no params. As in the UAMMD source (IBM_kernels.cuh): with
// K = 59/60 - sqrt(29)/20, each unit piece is a polynomial plus a multiple of chi(R), the
// root of a quadratic in the position R within the piece (r, r - 1 or r - 2).
const PESKIN6_K: f32 = 0.7140750929766081;

fn peskin6_chi(rr: f32) -> f32 {
    let k = PESKIN6_K;
    let r2 = rr * rr;
    let alpha = 28.0;
    let beta = 9.0 / 4.0 - 1.5 * (k + r2) + (22.0 / 3.0 - 7.0 * k) * rr - (7.0 / 3.0) * r2 * rr;
    let gamma = 0.25 * (0.5 * (161.0 / 36.0 - (59.0 / 6.0) * k + 5.0 * k * k) * r2
        + (1.0 / 3.0) * (-109.0 / 24.0 + 5.0 * k) * r2 * r2 + (5.0 / 18.0) * r2 * r2 * r2);
    let disc = max(0.0, beta * beta - 4.0 * alpha * gamma);
    // sgn(3/2 - K) = +1 for this K.
    return (-beta + sqrt(disc)) / (2.0 * alpha);
}

fn window_phi(r_in: f32, p: vec4<f32>) -> f32 {
    let r = abs(r_in);
    let k = PESKIN6_K;
    if (r >= 3.0) {
        return 0.0;
    }
    if (r <= 1.0) {
        return 2.0 * peskin6_chi(r) + 5.0 / 8.0 - 0.25 * (k + r * r);
    }
    if (r <= 2.0) {
        let s = r - 1.0;
        return -3.0 * peskin6_chi(s) + 0.25 - (1.0 / 6.0) * (4.0 - 3.0 * k) * s + (1.0 / 6.0) * s * s * s;
    }
    let s = r - 2.0;
    return peskin6_chi(s) - 1.0 / 16.0 + 0.125 * (k + s * s) - (1.0 / 12.0) * (3.0 * k - 1.0) * s - (1.0 / 12.0) * s * s * s;
}
