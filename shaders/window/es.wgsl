// "Exponential of semicircle" window (Barnett, Magland, af Klinteberg 2019), per axis, in
// units of h: phi(r) = exp(beta (sqrt(1 - (r/alpha)^2) - 1)) / S for |r| < alpha, with
// p = (beta, alpha, 1/S, 0) and S its integral, computed on the host in f64.
fn window_phi(r: f32, p: vec4<f32>) -> f32 {
    let z = r / p.y;
    if (abs(z) >= 1.0) {
        return 0.0;
    }
    return p.z * exp(p.x * (sqrt(1.0 - z * z) - 1.0));
}
