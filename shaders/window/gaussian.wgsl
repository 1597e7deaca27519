// Gaussian window, per axis, in units of the cell size h: r = distance / h, and
// p.x = sigma / h. Returns phi(r) per unit h (normalised over the real line).
fn window_phi(r: f32, p: vec4<f32>) -> f32 {
    let s = p.x;
    return 0.3989422804014327 / s * exp(-0.5 * r * r / (s * s));
}
