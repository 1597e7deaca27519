// The fused `slab_solve` kernel of three lines a thread (shaders/chebyshev/slab_solve.wgsl
// with slab_lines.wgsl, slab_fused.wgsl and stokes_slab/wall_flow.wgsl, as landed on
// 2026-12-07; bottom wall) ported line for line to CUDA, to see through nvcc and Nsight
// Compute what the Vulkan path hides: registers, local memory, occupancy and where its
// warps stall, at the bottom wall's 10^5 grid (175 x 175, 30 points: 15400 wave numbers,
// about 230 threads a multiprocessor) and 10^6 grid (560 x 560, 31 points). Two threads a
// wave number (one per part), each with its part's x, y, z lines side by side (L3, the
// WGSL's vec3 lanes); the pressure solved whole by both; the inverse transform by parity
// with the matrix's entries as constants (the WGSL writes them out as literals; here a
// __constant__ array read by fully unrolled loops, so every read is a constant operand).
// The tables are random (the time does not depend on their values); the numbers it
// writes are not checked against the WGSL kernel.
//
// On the GPU machine (benches/profile_slab.sh runs all of it):
//   nvcc -O3 -arch=sm_90 -Xptxas -v -DPOINTS=30 benches/slab_solve_three_lines.cu -o slab30
//   ./slab30 175 175
//   ncu --section Occupancy --section WarpStateStats --section SchedulerStats
//       --section LaunchStats -k slab_solve -c 1 ./slab30 175 175
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstdint>
#include <vector>
#include <cuda_runtime.h>

#define CHECK(x) do { cudaError_t e = (x); if (e != cudaSuccess) { \
    fprintf(stderr, "%s:%d %s\n", __FILE__, __LINE__, cudaGetErrorString(e)); exit(1); } } while (0)

#ifndef POINTS
#define POINTS 31
#endif
constexpr unsigned N = POINTS;   // Chebyshev points
constexpr unsigned KS = 32;      // wave numbers a block (THREE_LINES_KS)
constexpr unsigned WG = 2 * KS;  // threads a block

struct Slab {
    unsigned nx, ny, nk;
    float kx_unit, ky_unit, inv_eta, height, f_scale, bc_scale, dz_scale;
};

// The inverse transform's matrix (chebyshev::matrix(n, false)), the WGSL's literals.
__constant__ float T[N * N];

struct L3 { float x, y, z; };
__device__ __forceinline__ L3 l3(float v) { return {v, v, v}; }
__device__ __forceinline__ L3 operator+(L3 a, L3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
__device__ __forceinline__ L3 operator-(L3 a, L3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
__device__ __forceinline__ L3 operator-(L3 a) { return {-a.x, -a.y, -a.z}; }
__device__ __forceinline__ L3 operator*(float s, L3 a) { return {s * a.x, s * a.y, s * a.z}; }
__device__ __forceinline__ L3 operator*(L3 a, L3 b) { return {a.x * b.x, a.y * b.y, a.z * b.z}; }
__device__ __forceinline__ L3 operator/(L3 a, float s) { return {a.x / s, a.y / s, a.z / s}; }
__device__ __forceinline__ void operator+=(L3& a, L3 b) { a = a + b; }
__device__ __forceinline__ void operator-=(L3& a, L3 b) { a = a - b; }
__device__ __forceinline__ float lane(L3 a, unsigned c) { return c == 0 ? a.x : (c == 1 ? a.y : a.z); }
__device__ __forceinline__ float2 times_i(float2 z) { return make_float2(-z.y, z.x); }
__device__ __forceinline__ float part_of(float2 z, unsigned part) { return part == 0 ? z.x : z.y; }

__device__ __forceinline__ float entry(const float* __restrict__ bvp, unsigned nk, unsigned row, unsigned k) {
    return bvp[row * nk + k];
}

__device__ __forceinline__ void differentiate(L3* line, float dz) {
    L3 next = l3(0.f), here = l3(0.f);
#pragma unroll
    for (unsigned i = 0; i < N - 1; i++) {
        unsigned m = N - 1 - i;
        L3 cm = line[m];
        line[m] = dz * here;
        L3 prev = next + (2.f * float(m)) * cm;
        next = here;
        here = prev;
    }
    line[0] = (dz * 0.5f) * here;
}

__device__ __forceinline__ L3 a_at(const L3* line, unsigned j) { return j >= N ? l3(0.f) : line[j]; }

__device__ __forceinline__ L3 deriv(const L3* line, unsigned m, L3 p0) {
    if (m >= N) return l3(0.f);
    if (m == 0) return p0;
    if (m == 1) return a_at(line, 0) - 0.5f * a_at(line, 2);
    return (a_at(line, m - 1) - a_at(line, m + 1)) / (2.f * float(m));
}

__device__ __forceinline__ void solve(L3* line, L3* coef, const float* __restrict__ bvp, unsigned nk,
                                      unsigned k, L3 alpha, L3 beta) {
    L3 r0 = -alpha, r1 = -beta;
#pragma unroll
    for (unsigned z = 0; z < N; z++) {
        r0 += entry(bvp, nk, 3 * N + z, k) * line[z];
        r1 += entry(bvp, nk, 4 * N + z, k) * line[z];
    }
    L3 y0 = entry(bvp, nk, 5 * N, k) * r0 + entry(bvp, nk, 5 * N + 1, k) * r1;
    L3 p0 = entry(bvp, nk, 5 * N + 2, k) * r0 + entry(bvp, nk, 5 * N + 3, k) * r1;
    float kappa2 = entry(bvp, nk, 5 * N + 4, k);
    line[0] += kappa2 * y0;
    line[1] += kappa2 * p0;
#pragma unroll
    for (unsigned z = 2; z < N; z++) line[z] -= entry(bvp, nk, z, k) * line[z - 2];
#pragma unroll
    for (unsigned i = 0; i < N; i++) {
        unsigned z = N - 1 - i;
        L3 up = z + 2 < N ? entry(bvp, nk, 2 * N + z, k) * line[z + 2] : l3(0.f);
        line[z] = entry(bvp, nk, N + z, k) * (line[z] - up);
    }
#pragma unroll
    for (unsigned m = 0; m < N; m++) {
        L3 v;
        if (m == 0) v = y0;
        else if (m == 1) v = p0 - 0.5f * deriv(line, 2, p0);
        else v = (deriv(line, m - 1, p0) - deriv(line, m + 1, p0)) / (2.f * float(m));
        coef[m] = v;
    }
}

// The output's state (slab_fused.wgsl's private variables).
struct Out {
    unsigned word;
    L3 keep, a1, b1;
    float kabs;
    bool walls;
};

__device__ __forceinline__ void put(float* __restrict__ out, const float* __restrict__ points, const Out& o,
                                    unsigned nk, float height, unsigned j, L3 v) {
    L3 x = v;
    if (o.walls) {
        float zeta = points[N * N + j];
        float decay = expf(-o.kabs * zeta);
        float grow = expf(o.kabs * (zeta - height));
        // The bottom wall's a2 = b2 = 0: the WGSL computes the term all the same.
        x = o.keep * v + decay * (zeta * o.a1 + o.b1) + grow * l3(0.f);
    }
    unsigned w = o.word + 2u * j * nk;
    unsigned component = 2u * N * nk;
    out[w] = x.x;
    out[w + component] = x.y;
    out[w + 2u * component] = x.z;
}

__global__ void __launch_bounds__(WG) slab_solve(const float2* __restrict__ f, float* __restrict__ out,
                                                 const float* __restrict__ bvp,
                                                 const float* __restrict__ points, Slab s) {
    __shared__ float velocity_ends[KS * 12];
    L3 line[N], coef[N];
    const unsigned nk = s.nk, lid = threadIdx.x;
    const unsigned part = lid % 2, slot = lid / 2;
    const unsigned k = blockIdx.x * KS + slot;
    const bool valid = k < nk;
    const float sign = part == 1 ? 1.f : -1.f;
    const unsigned hx = s.nx / 2 + 1, x = k % hx, y = k / hx;
    const float fy = y > s.ny / 2 ? float(y) - float(s.ny) : float(y);
    const float kx = float(x) * s.kx_unit, ky = fy * s.ky_unit;
    const float qx = (s.nx % 2 == 0 && x == s.nx / 2) ? 0.f : kx;
    const float qy = (s.ny % 2 == 0 && y == s.ny / 2) ? 0.f : ky;
    const float kabs = sqrtf(kx * kx + ky * ky);
    auto forcing = [&](unsigned c, unsigned z) { return f[(c * N + z) * nk + k]; };
    L3 top = l3(0.f), bottom = l3(0.f);
    if (valid) {
        // The pressure, both parts (lanes x, y).
#pragma unroll
        for (unsigned z = 0; z < N; z++) {
            float2 fz = forcing(2, z);
            line[z] = {fz.x, fz.y, 0.f};
        }
        differentiate(line, s.dz_scale);
#pragma unroll
        for (unsigned z = 0; z < N; z++) {
            float2 fx = forcing(0, z), fy2 = forcing(1, z);
            float2 ikf = times_i(make_float2(qx * fx.x + qy * fy2.x, qx * fx.y + qy * fy2.y));
            line[z] = s.f_scale * (L3{ikf.x, ikf.y, 0.f} + line[z]);
        }
        solve(line, coef, bvp, nk, k, l3(0.f), l3(0.f));
        L3 p_top = l3(0.f), p_bottom = l3(0.f);
#pragma unroll
        for (unsigned z = 0; z < N; z++) {
            p_top += coef[z];
            p_bottom += (z % 2 == 1) ? -coef[z] : coef[z];
        }
        // The velocity's sources from the pressure's coefficients, from the top down.
        const float scale = s.f_scale * s.inv_eta;
        float next = 0.f, here = 0.f;
#pragma unroll
        for (unsigned i = 0; i < N; i++) {
            unsigned m = N - 1 - i;
            L3 p = coef[m];
            float own = part == 1 ? p.y : p.x;
            float other = part == 1 ? p.x : p.y;
            float dp = s.dz_scale * here;
            if (m == 0) {
                dp = 0.5f * dp;
            } else {
                float prev = next + 2.f * float(m) * own;
                next = here;
                here = prev;
            }
            float fxp = part_of(forcing(0, m), part), fyp = part_of(forcing(1, m), part),
                  fzp = part_of(forcing(2, m), part);
            line[m] = scale * L3{sign * qx * other - fxp, sign * qy * other - fyp, dp - fzp};
        }
        L3 alpha = l3(0.f), beta = l3(0.f);
        if (kabs != 0.f) {
            float h = 0.5f * s.inv_eta * s.bc_scale;
            float own_top = part == 1 ? p_top.y : p_top.x, own_bottom = part == 1 ? p_bottom.y : p_bottom.x;
            float other_top = part == 1 ? p_top.x : p_top.y, other_bottom = part == 1 ? p_bottom.x : p_bottom.y;
            float gx = sign * qx * h / kabs, gy = sign * qy * h / kabs;
            alpha = {-gx * other_top, -gy * other_top, h * own_top};
            beta = {gx * other_bottom, gy * other_bottom, h * own_bottom};
        }
        solve(line, coef, bvp, nk, k, alpha, beta);
        L3 even = l3(0.f), odd = l3(0.f);
#pragma unroll
        for (unsigned m = 0; m < N; m += 2) even += coef[m];
#pragma unroll
        for (unsigned m = 1; m < N; m += 2) odd += coef[m];
        top = even + odd;
        bottom = even - odd;
#pragma unroll
        for (unsigned c = 0; c < 3; c++) {
            unsigned e = ((slot * 2 + part) * 3 + c) * 2;
            velocity_ends[e] = lane(top, c);
            velocity_ends[e + 1] = lane(bottom, c);
        }
    }
    __syncthreads();
    if (!valid) return;

    Out o;
    o.word = 2u * k + part;
    o.kabs = kabs;
    o.keep = l3(1.f);
    o.a1 = l3(0.f);
    o.b1 = l3(0.f);
    o.walls = true;
    if (kabs == 0.f) {
        o.keep = {1.f, 1.f, 0.f};
        o.b1 = {-bottom.x, -bottom.y, 0.f};
        L3 slope = l3(0.f);
#pragma unroll
        for (unsigned m = 1; m < N; m++) slope -= float(m * m) * coef[m];
        o.a1 = {s.dz_scale * slope.x, s.dz_scale * slope.y, 0.f};
    } else {
        // The bottom wall: C = -v(bottom) (both parts, from workgroup memory), D = 0.
        float2 c[3];
#pragma unroll
        for (unsigned i = 0; i < 3; i++)
            c[i] = make_float2(-velocity_ends[((slot * 2) * 3 + i) * 2 + 1],
                               -velocity_ends[((slot * 2 + 1) * 3 + i) * 2 + 1]);
        float2 dot = make_float2(kx * c[0].x + ky * c[1].x, kx * c[0].y + ky * c[1].y);
        float2 ti = times_i(dot);
        float2 a = make_float2(c[2].x - ti.x / kabs, c[2].y - ti.y / kabs);
        o.b1 = {part_of(c[0], part), part_of(c[1], part), part_of(c[2], part)};
        o.a1 = {part_of(times_i(make_float2(-kx * a.x, -kx * a.y)), part),
                part_of(times_i(make_float2(-ky * a.x, -ky * a.y)), part), kabs * part_of(a, part)};
    }
    // The inverse transform by parity, the matrix's entries as constant operands.
#pragma unroll
    for (unsigned j = 0; j < (N + 1) / 2; j++) {
        L3 ev = l3(0.f), od = l3(0.f);
#pragma unroll
        for (unsigned m = 0; m < N; m += 2) ev += T[j * N + m] * coef[m];
#pragma unroll
        for (unsigned m = 1; m < N; m += 2) od += T[j * N + m] * coef[m];
        put(out, points, o, nk, s.height, j, ev + od);
        if (N - 1 - j != j) put(out, points, o, nk, s.height, N - 1 - j, ev - od);
    }
}

__global__ void copy(const float4* __restrict__ a, float4* __restrict__ b, size_t n) {
    for (size_t i = blockIdx.x * (size_t)blockDim.x + threadIdx.x; i < n; i += (size_t)gridDim.x * blockDim.x)
        b[i] = a[i];
}

int main(int argc, char** argv) {
    const unsigned nx = argc > 1 ? atoi(argv[1]) : 560, ny = argc > 2 ? atoi(argv[2]) : nx;
    const unsigned hx = nx / 2 + 1, nk = hx * ny;
    const size_t line_words = (size_t)6 * N * nk, table_words = (size_t)(5 * N + 6) * nk;
    std::vector<float> host(line_words), tables(table_words), pts(N * N + N + N), mat(N * N);
    uint32_t r = 12345;
    auto rnd = [&]() { r = r * 1664525u + 1013904223u; return float(r >> 8) / float(1 << 24); };
    for (auto& v : host) v = rnd() - 0.5f;
    for (auto& v : tables) v = 0.1f + 0.4f * rnd();
    for (unsigned i = 0; i < N * N; i++)
        mat[i] = cosf(3.14159265f * float((i / N) * (i % N) % (2 * (N - 1))) / float(N - 1));
    for (unsigned i = 0; i < pts.size(); i++) pts[i] = i < N * N ? mat[i] : 11.5f * rnd();
    CHECK(cudaMemcpyToSymbol(T, mat.data(), N * N * 4));
    float *f, *o, *t, *p;
    CHECK(cudaMalloc(&f, line_words * 4));
    CHECK(cudaMalloc(&o, (line_words + table_words) * 4));
    CHECK(cudaMalloc(&t, table_words * 4));
    CHECK(cudaMalloc(&p, pts.size() * 4));
    CHECK(cudaMemcpy(f, host.data(), line_words * 4, cudaMemcpyHostToDevice));
    CHECK(cudaMemcpy(t, tables.data(), table_words * 4, cudaMemcpyHostToDevice));
    CHECK(cudaMemcpy(p, pts.data(), pts.size() * 4, cudaMemcpyHostToDevice));
    const float L = 128.f * float(nx) / 175.f, H = 11.5f;
    Slab s{nx, ny, nk, 2 * 3.14159265f / L, 2 * 3.14159265f / L, 1.f, H, H * H / 4, H / 2, 2 / H};
    cudaFuncAttributes attr;
    CHECK(cudaFuncGetAttributes(&attr, slab_solve));
    int blocks_per_sm = 0;
    CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(&blocks_per_sm, slab_solve, WG, 0));
    printf("slab_solve three lines (CUDA port), %u points: %d registers a thread, %zu bytes local memory a thread, %zu bytes shared, %d blocks of %u a multiprocessor\n",
           N, attr.numRegs, attr.localSizeBytes, attr.sharedSizeBytes, blocks_per_sm, WG);
    cudaEvent_t a, b;
    CHECK(cudaEventCreate(&a));
    CHECK(cudaEventCreate(&b));
    const unsigned grid = (nk + KS - 1) / KS;
    float best = 1e9f;
    for (int rep = 0; rep < 20; rep++) {
        CHECK(cudaEventRecord(a));
        slab_solve<<<grid, WG>>>((const float2*)f, o, t, p, s);
        CHECK(cudaEventRecord(b));
        CHECK(cudaEventSynchronize(b));
        float ms;
        CHECK(cudaEventElapsedTime(&ms, a, b));
        if (rep > 2 && ms < best) best = ms;
    }
    CHECK(cudaGetLastError());
    const double bytes = (2.0 * line_words + table_words) * 4;
    printf("slab_solve three lines (CUDA port) at %ux%u (%u wave numbers), %u points: %.4f ms, %.0f GB/s of %.1f MB\n",
           nx, ny, nk, N, best, bytes / best / 1e6, bytes / 1e6);
    // A copy of the same bytes: half of them read, half written.
    float bestc = 1e9f;
    const size_t copy_words = (2 * line_words + table_words) / 8 * 4;
    size_t n4 = copy_words / 4;
    float* src;
    CHECK(cudaMalloc(&src, copy_words * 4));
    CHECK(cudaMemset(src, 0, copy_words * 4));
    for (int rep = 0; rep < 20; rep++) {
        CHECK(cudaEventRecord(a));
        copy<<<132 * 8, 256>>>((const float4*)src, (float4*)o, n4);
        CHECK(cudaEventRecord(b));
        CHECK(cudaEventSynchronize(b));
        float ms;
        CHECK(cudaEventElapsedTime(&ms, a, b));
        if (rep > 2 && ms < bestc) bestc = ms;
    }
    printf("copy of %.1f MB (read + write): %.4f ms, %.0f GB/s; the solve %.2fx\n", 2.0 * copy_words * 4 / 1e6,
           bestc, 2.0 * copy_words * 4 / bestc / 1e6, best / bestc);
    return 0;
}
