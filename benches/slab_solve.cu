// The fused `slab_solve` kernel as it was before 2026-12-07 (shaders/chebyshev/
// slab_solve.wgsl with slab_lines.wgsl, bottom wall: the inverse transform by a loop over
// the matrix, the values' line kept across the barrier for the walls) ported line for
// line to CUDA, to see through nvcc what the Vulkan path hides: registers per thread,
// per-thread local memory, occupancy, and its time beside a copy of the same bytes, at the
// bottom wall's 10^6 grid (560 x 560 x 31: 157360 wave numbers). The tables are random
// (the time does not depend on their values); the numbers it writes are not checked.
//
// On the GPU machine: nvcc -O3 -arch=sm_90 -Xptxas -v benches/slab_solve.cu -o slab &&
// ./slab, and `ncu --section Occupancy --section WarpStateStats --section
// SchedulerStats -k slab_solve -c 1 ./slab`. On an H100, 2026-12-07 02:20Z: 168 registers,
// 4 blocks of 96 a multiprocessor (18.75 % occupancy), 0.349 ms against 0.089 ms for a
// copy of the lines; 0.37 instructions issued per scheduler per cycle (BENCHMARKS.md,
// DP Stokes). The landed kernel has changed since; this port stays as the profile's source.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstdint>
#include <vector>
#include <cuda_runtime.h>

#define CHECK(x) do { cudaError_t e = (x); if (e != cudaSuccess) { \
    fprintf(stderr, "%s:%d %s\n", __FILE__, __LINE__, cudaGetErrorString(e)); exit(1); } } while (0)

constexpr unsigned N = 31;       // Chebyshev points
constexpr unsigned KS = 16;      // wave numbers a block
constexpr unsigned WG = 6 * KS;  // threads a block

struct Slab {
    unsigned nx, ny, nk;
    float kx_unit, ky_unit, inv_eta, height, f_scale, bc_scale, dz_scale;
};

__device__ __forceinline__ float entry(const float* bvp, unsigned nk, unsigned row, unsigned k) {
    return bvp[row * nk + k];
}

__device__ __forceinline__ unsigned word(unsigned c, unsigned z, unsigned k, unsigned nk) {
    return 2u * ((c * N + z) * nk + k);
}

__device__ void differentiate(float* line, float dz) {
    float next = 0.f, here = 0.f;
    for (unsigned i = 0; i + 1 < N; i++) {
        unsigned m = N - 1 - i;
        float cm = line[m];
        line[m] = dz * here;
        float prev = next + 2.f * float(m) * cm;
        next = here;
        here = prev;
    }
    line[0] = dz * 0.5f * here;
}

__device__ __forceinline__ float a_at(const float* line, unsigned j) { return j >= N ? 0.f : line[j]; }

__device__ __forceinline__ float deriv(const float* line, unsigned m, float p0) {
    if (m >= N) return 0.f;
    if (m == 0) return p0;
    if (m == 1) return a_at(line, 0) - 0.5f * a_at(line, 2);
    return (a_at(line, m - 1) - a_at(line, m + 1)) / (2.f * float(m));
}

__device__ void solve(float* line, float* coef, const float* bvp, unsigned nk, unsigned k,
                      float alpha, float beta) {
    float r0 = -alpha, r1 = -beta;
    for (unsigned z = 0; z < N; z++) {
        r0 += entry(bvp, nk, 3 * N + z, k) * line[z];
        r1 += entry(bvp, nk, 4 * N + z, k) * line[z];
    }
    float y0 = entry(bvp, nk, 5 * N, k) * r0 + entry(bvp, nk, 5 * N + 1, k) * r1;
    float p0 = entry(bvp, nk, 5 * N + 2, k) * r0 + entry(bvp, nk, 5 * N + 3, k) * r1;
    float kappa2 = entry(bvp, nk, 5 * N + 4, k);
    line[0] += kappa2 * y0;
    line[1] += kappa2 * p0;
    for (unsigned z = 2; z < N; z++) line[z] -= entry(bvp, nk, z, k) * line[z - 2];
    for (unsigned i = 0; i < N; i++) {
        unsigned z = N - 1 - i;
        float up = z + 2 < N ? entry(bvp, nk, 2 * N + z, k) * line[z + 2] : 0.f;
        line[z] = (line[z] - up) * entry(bvp, nk, N + z, k);
    }
    for (unsigned m = 0; m < N; m++) {
        float v;
        if (m == 0) v = y0;
        else if (m == 1) v = p0 - 0.5f * deriv(line, 2, p0);
        else v = (deriv(line, m - 1, p0) - deriv(line, m + 1, p0)) / (2.f * float(m));
        coef[m] = v;
    }
}

__global__ void __launch_bounds__(WG) slab_solve(const float* __restrict__ f, float* __restrict__ out,
                                                 const float* __restrict__ bvp,
                                                 const float* __restrict__ points, Slab s) {
    __shared__ float pressure[KS * 2 * N];
    __shared__ float pressure_ends[KS * 4];
    __shared__ float velocity_ends[KS * 12];
    float line[N], coef[N];
    unsigned lid = threadIdx.x, nk = s.nk;
    unsigned part = lid % 2, slot = (lid / 2) % KS, c = lid / (2 * KS);
    unsigned k = blockIdx.x * KS + slot;
    bool valid = k < nk;
    unsigned other = 1 - part;
    float sign = part == 1 ? 1.f : -1.f;
    unsigned hx = s.nx / 2 + 1, x = k % hx, y = k / hx;
    float fy = y > s.ny / 2 ? float(y) - float(s.ny) : float(y);
    float kx = float(x) * s.kx_unit, ky = fy * s.ky_unit;
    float qx = (x == s.nx / 2) ? 0.f : kx, qy = ky;
    float kabs = sqrtf(kx * kx + ky * ky);
    if (c == 0 && valid) {
        for (unsigned z = 0; z < N; z++) line[z] = f[word(2, z, k, nk) + part];
        differentiate(line, s.dz_scale);
        for (unsigned z = 0; z < N; z++) {
            float ikf = sign * (qx * f[word(0, z, k, nk) + other] + qy * f[word(1, z, k, nk) + other]);
            line[z] = s.f_scale * (ikf + line[z]);
        }
        solve(line, coef, bvp, nk, k, 0.f, 0.f);
        float top = 0.f, bottom = 0.f;
        unsigned base = (slot * 2 + part) * N;
        for (unsigned z = 0; z < N; z++) {
            float p = coef[z];
            pressure[base + z] = p;
            top += p;
            bottom += (z % 2 == 1) ? -p : p;
        }
        pressure_ends[(slot * 2 + part) * 2] = top;
        pressure_ends[(slot * 2 + part) * 2 + 1] = bottom;
    }
    __syncthreads();
    if (valid) {
        float scale = s.f_scale * s.inv_eta;
        if (c == 2) {
            unsigned base = (slot * 2 + part) * N;
            for (unsigned z = 0; z < N; z++) line[z] = pressure[base + z];
            differentiate(line, s.dz_scale);
            for (unsigned z = 0; z < N; z++) line[z] = scale * (line[z] - f[word(2, z, k, nk) + part]);
        } else {
            unsigned base = (slot * 2 + other) * N;
            float qc = c == 0 ? qx : qy;
            for (unsigned z = 0; z < N; z++)
                line[z] = scale * (sign * qc * pressure[base + z] - f[word(c, z, k, nk) + part]);
        }
        float alpha = 0.f, beta = 0.f;
        if (kabs != 0.f) {
            float h = 0.5f * s.inv_eta * s.bc_scale;
            if (c == 2) {
                alpha = h * pressure_ends[(slot * 2 + part) * 2];
                beta = h * pressure_ends[(slot * 2 + part) * 2 + 1];
            } else {
                float g = sign * (c == 0 ? qx : qy) * h / kabs;
                alpha = -g * pressure_ends[(slot * 2 + other) * 2];
                beta = g * pressure_ends[(slot * 2 + other) * 2 + 1];
            }
        }
        solve(line, coef, bvp, nk, k, alpha, beta);
        for (unsigned j = 0; j < (N + 1) / 2; j++) {
            float even = 0.f, odd = 0.f;
            for (unsigned m = 0; m < N; m += 2) even += points[j * N + m] * coef[m];
            for (unsigned m = 1; m < N; m += 2) odd += points[j * N + m] * coef[m];
            line[j] = even + odd;
            line[N - 1 - j] = even - odd;
        }
        unsigned e = (slot * 6 + c * 2 + part) * 2;
        velocity_ends[e] = line[0];
        velocity_ends[e + 1] = line[N - 1];
    }
    __syncthreads();
    if (!valid) return;
    // The bottom wall (walls 1), k != 0.
    if (kabs == 0.f) {
        for (unsigned j = 0; j < N; j++) out[word(c, j, k, nk) + part] = line[j];
        return;
    }
    float cre[3], cim[3];
    for (unsigned i = 0; i < 3; i++) {
        unsigned b = slot * 6 + i * 2;
        cre[i] = -velocity_ends[b * 2 + 1];
        cim[i] = -velocity_ends[(b + 1) * 2 + 1];
    }
    // a = C_z - i (k . C_xy) / |k|
    float are = cre[2] + (kx * cim[0] + ky * cim[1]) / kabs;
    float aim = cim[2] - (kx * cre[0] + ky * cre[1]) / kabs;
    float ccr = cre[c], cci = cim[c];
    const float* zeta = points + N * N;
    for (unsigned j = 0; j < N; j++) {
        float zt = zeta[j];
        float decay = expf(-kabs * zt);
        float azr = are * zt, azi = aim * zt;
        float cr, ci;
        if (c == 2) {
            cr = (kabs * azr + ccr) * decay;
            ci = (kabs * azi + cci) * decay;
        } else {
            float kc = c == 0 ? kx : ky;
            // times_i(-kc az) = (kc azi, -kc azr)
            cr = (kc * azi + ccr) * decay;
            ci = (-kc * azr + cci) * decay;
        }
        out[word(c, j, k, nk) + part] = line[j] + (part == 0 ? cr : ci);
    }
}

__global__ void copy(const float4* __restrict__ a, float4* __restrict__ b, size_t n) {
    for (size_t i = blockIdx.x * (size_t)blockDim.x + threadIdx.x; i < n; i += (size_t)gridDim.x * blockDim.x)
        b[i] = a[i];
}

int main() {
    const unsigned nx = 560, ny = 560, hx = nx / 2 + 1, nk = hx * ny;
    const size_t line_words = (size_t)6 * N * nk, table_words = (size_t)(5 * N + 6) * nk;
    std::vector<float> host(line_words), tables(table_words), pts(N * N + N + N);
    uint32_t r = 12345;
    auto rnd = [&]() { r = r * 1664525u + 1013904223u; return float(r >> 8) / float(1 << 24); };
    for (auto& v : host) v = rnd() - 0.5f;
    for (auto& v : tables) v = 0.1f + 0.4f * rnd();
    for (unsigned i = 0; i < pts.size(); i++) pts[i] = i < N * N ? cosf(3.14159265f * ((i / N) * (i % N) % (2 * (N - 1))) / (N - 1)) : rnd();
    float *f, *o, *t, *p;
    CHECK(cudaMalloc(&f, line_words * 4));
    CHECK(cudaMalloc(&o, line_words * 4));
    CHECK(cudaMalloc(&t, table_words * 4));
    CHECK(cudaMalloc(&p, pts.size() * 4));
    CHECK(cudaMemcpy(f, host.data(), line_words * 4, cudaMemcpyHostToDevice));
    CHECK(cudaMemcpy(t, tables.data(), table_words * 4, cudaMemcpyHostToDevice));
    CHECK(cudaMemcpy(p, pts.data(), pts.size() * 4, cudaMemcpyHostToDevice));
    Slab s{nx, ny, nk, 2 * 3.14159265f / 404.8f, 2 * 3.14159265f / 404.8f, 1.f, 11.5f, 33.06f, 5.75f, 0.1739f};
    cudaFuncAttributes attr;
    CHECK(cudaFuncGetAttributes(&attr, slab_solve));
    int blocks_per_sm = 0;
    CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(&blocks_per_sm, slab_solve, WG, 0));
    printf("slab_solve (CUDA port): %d registers a thread, %zu bytes local memory a thread, %zu bytes shared, %d blocks of %u a multiprocessor\n",
           attr.numRegs, attr.localSizeBytes, attr.sharedSizeBytes, blocks_per_sm, WG);
    cudaEvent_t a, b;
    CHECK(cudaEventCreate(&a));
    CHECK(cudaEventCreate(&b));
    const unsigned grid = (nk + KS - 1) / KS;
    float best = 1e9f;
    for (int rep = 0; rep < 20; rep++) {
        CHECK(cudaEventRecord(a));
        slab_solve<<<grid, WG>>>(f, o, t, p, s);
        CHECK(cudaEventRecord(b));
        CHECK(cudaEventSynchronize(b));
        float ms;
        CHECK(cudaEventElapsedTime(&ms, a, b));
        if (rep > 2 && ms < best) best = ms;
    }
    CHECK(cudaGetLastError());
    const double bytes = (2.0 * line_words + table_words) * 4;
    printf("slab_solve (CUDA port) at %u wave numbers, %u points: %.4f ms, %.0f GB/s of %.1f MB\n", nk, N, best,
           bytes / best / 1e6, bytes / 1e6);
    // A copy of the lines (read + write), the same bytes' floor.
    float bestc = 1e9f;
    size_t n4 = line_words / 4;
    for (int rep = 0; rep < 20; rep++) {
        CHECK(cudaEventRecord(a));
        copy<<<132 * 8, 256>>>((const float4*)f, (float4*)o, n4);
        CHECK(cudaEventRecord(b));
        CHECK(cudaEventSynchronize(b));
        float ms;
        CHECK(cudaEventElapsedTime(&ms, a, b));
        if (rep > 2 && ms < bestc) bestc = ms;
    }
    printf("copy of the lines: %.4f ms, %.0f GB/s (read + write)\n", bestc, 2.0 * line_words * 4 / bestc / 1e6);
    return 0;
}
