// Complex arithmetic on vec2<f32> (re, im) for the generated FFT passes (nodes/fft).
fn cmul(a: vec2<f32>, b: vec2<f32>) -> vec2<f32> {
    return vec2<f32>(a.x * b.x - a.y * b.y, a.x * b.y + a.y * b.x);
}

// a * i
fn mul_i(a: vec2<f32>) -> vec2<f32> {
    return vec2<f32>(-a.y, a.x);
}

// a * (-i)
fn mul_ni(a: vec2<f32>) -> vec2<f32> {
    return vec2<f32>(a.y, -a.x);
}
