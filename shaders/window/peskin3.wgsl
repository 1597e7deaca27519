// Peskin's 3-point window (Roma, Peskin, Berger 1999), in units of h; no params.
fn window_phi(r_in: f32, p: vec4<f32>) -> f32 {
    let r = abs(r_in);
    if (r < 0.5) {
        return (1.0 + sqrt(1.0 - 3.0 * r * r)) / 3.0;
    }
    if (r < 1.5) {
        let s = 1.0 - r;
        return (5.0 - 3.0 * r - sqrt(max(0.0, 1.0 - 3.0 * s * s))) / 6.0;
    }
    return 0.0;
}
