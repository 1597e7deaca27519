// Peskin's 4-point window, in units of h; no params.
fn window_phi(r_in: f32, p: vec4<f32>) -> f32 {
    let r = abs(r_in);
    if (r < 1.0) {
        return (3.0 - 2.0 * r + sqrt(1.0 + 4.0 * r * (1.0 - r))) / 8.0;
    }
    if (r < 2.0) {
        return (5.0 - 2.0 * r - sqrt(max(0.0, -7.0 + 12.0 * r - 4.0 * r * r))) / 8.0;
    }
    return 0.0;
}
