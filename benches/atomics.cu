// Global and shared atomic-add rates on the GPU machine, by access pattern: what bounds
// spreading (particles to grid), whose every grid write is an atomic add.
//
// Each warp instruction adds 1.0 to `rows` runs of `len` consecutive floats (lane l: run
// l / len, element l % len), each run at a random start: len 8 and 4 runs is one particle's
// support-8 column block, len 5 the support-5 rows of FCM at 1e-2, len 15 the same rows
// with three components interleaved per cell. If the L2 applies one request per 32-byte
// sector whatever number of lanes it carries, the rate in adds per second grows with the
// adds per sector; if each add costs the same, it does not.
//
// Built and run on the GPU machine: nvcc -O3 -arch=sm_90 atomics.cu -o atomics && ./atomics
#include <cstdio>
#include <cstdlib>
#include <cstdint>
#include <cuda_runtime.h>

#define CHECK(x) do { cudaError_t e = (x); if (e != cudaSuccess) { \
    fprintf(stderr, "%s:%d %s\n", __FILE__, __LINE__, cudaGetErrorString(e)); exit(1); } } while (0)

__device__ __forceinline__ uint32_t hash(uint32_t x) {
    x ^= x >> 16; x *= 0x7feb352dU; x ^= x >> 15; x *= 0x846ca68bU; x ^= x >> 16;
    return x;
}

// mode 0: f32 add, 1: u32 add, 2: u64 add, 3: f32 add with its result used (ATOM, not RED)
template <int MODE>
__global__ void global_rows(float* grid, uint32_t cells, uint32_t len, uint32_t rows,
                            uint32_t align, uint32_t iters, uint32_t seed, float* sink) {
    uint32_t lane = threadIdx.x & 31;
    uint32_t warp = (blockIdx.x * blockDim.x + threadIdx.x) >> 5;
    uint32_t run = lane / len, k = lane % len;
    bool active = run < rows;
    float acc = 0.0f;
    for (uint32_t it = 0; it < iters; ++it) {
        uint32_t start = hash(seed ^ (warp * 7919u + it * 104729u + run * 31u)) % cells;
        start -= start % align;
        uint32_t a = start + k;
        if (a >= cells) a -= cells;
        if (active) {
            if (MODE == 0) atomicAdd(&grid[a], 1.0f);
            if (MODE == 1) atomicAdd(reinterpret_cast<uint32_t*>(grid) + a, 1u);
            if (MODE == 2) atomicAdd(reinterpret_cast<unsigned long long*>(grid) + (a >> 1), 1ull);
            if (MODE == 3) acc += atomicAdd(&grid[a], 1.0f);
        }
    }
    if (MODE == 3 && acc == -1.0f) sink[0] = acc;
}

// Shared memory: a padded tile of `tile` words; mode 0: u32 atomicAdd, 1: f32 CAS loop
// (what WGSL can do: no workgroup float atomics), 2: native f32 atomicAdd (CUDA only).
template <int MODE>
__global__ void shared_rows(float* out, uint32_t tile, uint32_t len, uint32_t rows,
                            uint32_t iters, uint32_t seed) {
    extern __shared__ uint32_t sh[];
    for (uint32_t i = threadIdx.x; i < tile; i += blockDim.x) sh[i] = 0;
    __syncthreads();
    uint32_t lane = threadIdx.x & 31;
    uint32_t warp = (blockIdx.x * blockDim.x + threadIdx.x) >> 5;
    uint32_t run = lane / len, k = lane % len;
    bool active = run < rows;
    for (uint32_t it = 0; it < iters; ++it) {
        uint32_t start = hash(seed ^ (warp * 7919u + it * 104729u + run * 31u)) % (tile - len);
        uint32_t a = start + k;
        if (active) {
            if (MODE == 0) atomicAdd(&sh[a], 1u);
            if (MODE == 1) {
                uint32_t old = sh[a], assumed;
                do {
                    assumed = old;
                    old = atomicCAS(&sh[a], assumed, __float_as_uint(__uint_as_float(assumed) + 1.0f));
                } while (old != assumed);
            }
            if (MODE == 2) atomicAdd(reinterpret_cast<float*>(sh) + a, 1.0f);
        }
    }
    __syncthreads();
    for (uint32_t i = threadIdx.x; i < tile; i += blockDim.x)
        if (sh[i] == 0xffffffffu) out[i] = 1.0f;
}


// The same patterns with almost no address arithmetic (a run's start advances by a fixed
// odd step under a power-of-two mask, 4 adds per loop trip), so that the atomics, not the
// integer work around them, set the rate.
template <int SHARED>
__global__ void light_rows(float* grid, uint32_t mask, uint32_t len, uint32_t rows,
                           uint32_t align, uint32_t iters, uint32_t seed) {
    extern __shared__ uint32_t sh[];
    if (SHARED) {
        for (uint32_t i = threadIdx.x; i <= mask + 32; i += blockDim.x) sh[i] = 0;
        __syncthreads();
    }
    uint32_t lane = threadIdx.x & 31;
    uint32_t warp = (blockIdx.x * blockDim.x + threadIdx.x) >> 5;
    uint32_t run = lane / len, k = lane % len;
    bool active = run < rows;
    uint32_t start = hash(seed ^ (warp * 7919u + run * 31u));
    const uint32_t step = 0x9E3779B1u;
    uint32_t am = ~(align - 1u);
    if (active) {
        for (uint32_t it = 0; it < iters; ++it) {
#pragma unroll
            for (int u = 0; u < 4; ++u) {
                uint32_t a = ((start & mask) & am) + k;
                start += step;
                if (SHARED == 1) atomicAdd(&sh[a], 1u);
                else if (SHARED == 2) atomicAdd(reinterpret_cast<float*>(sh) + a, 1.0f);
                else atomicAdd(&grid[a], 1.0f);
            }
        }
    }
    if (SHARED) {
        __syncthreads();
        for (uint32_t i = threadIdx.x; i <= mask; i += blockDim.x)
            if (sh[i] == 0xffffffffu) grid[i] = 1.0f;
    }
}

struct Timer {
    cudaEvent_t a, b;
    Timer() { CHECK(cudaEventCreate(&a)); CHECK(cudaEventCreate(&b)); }
    void start() { CHECK(cudaEventRecord(a)); }
    float stop() { CHECK(cudaEventRecord(b)); CHECK(cudaEventSynchronize(b)); float ms; CHECK(cudaEventElapsedTime(&ms, a, b)); return ms; }
};

int main(int argc, char** argv) {
    // `once`: each global case once on the first grid (for ncu's counters), no timing.
    bool once = argc > 1 && argv[1][0] == 'o';
    cudaDeviceProp p;
    CHECK(cudaGetDeviceProperties(&p, 0));
    printf("device: %s, %d SMs, L2 %d MB\n", p.name, p.multiProcessorCount, p.l2CacheSize >> 20);
    const uint32_t blocks = p.multiProcessorCount * 16, threads = 256;
    const uint32_t warps = blocks * threads / 32;
    float* grid; float* sink;
    const uint32_t max_cells = 384u * 384u * 384u;
    CHECK(cudaMalloc(&grid, sizeof(float) * (size_t)max_cells));
    CHECK(cudaMalloc(&sink, sizeof(float) * 65536));
    CHECK(cudaMemset(grid, 0, sizeof(float) * (size_t)max_cells));
    Timer t;
    struct Case { const char* name; uint32_t len, rows, align; int mode; };
    const Case cases[] = {
        {"scattered (1 lane a run)", 1, 32, 1, 0},
        {"support 4: 4 runs of 4 (x2 particles)", 4, 8, 1, 0},
        {"support 5: 5 runs of 5 (a component)", 5, 5, 1, 0},
        {"support 5, 3 comps interleaved: 2 runs of 15", 15, 2, 1, 0},
        {"support 6: 5 runs of 6", 6, 5, 1, 0},
        {"support 6, interleaved: 1 run of 18 + ... (1 run)", 18, 1, 1, 0},
        {"support 8: 4 runs of 8", 8, 4, 1, 0},
        {"support 8, runs sector-aligned", 8, 4, 8, 0},
        {"support 8, interleaved 3 comps: 1 run of 24", 24, 1, 1, 0},
        {"32 consecutive", 32, 1, 1, 0},
        {"32 consecutive, aligned", 32, 1, 32, 0},
        {"support 8, u32 add", 8, 4, 1, 1},
        {"support 8, u64 add (pairs of words)", 8, 4, 1, 2},
        {"support 8, f32 add with result (ATOM)", 8, 4, 1, 3},
        {"support 5, u64 add", 5, 5, 1, 2},
    };
    const uint32_t cell_sizes[] = {128u * 128u * 128u, 162u * 162u * 162u, 384u * 384u * 384u};
    printf("\n%-52s %10s %10s %10s %10s\n", "global pattern", "cells", "Gadd/s", "Ginstr/s", "ms");
    for (uint32_t cells : cell_sizes) {
        if (once && cells != cell_sizes[0]) break;
        for (const Case& c : cases) {
            uint32_t active = c.len * c.rows;
            uint32_t iters = (uint32_t)((1ull << 28) / ((uint64_t)warps * active)) + 1;
            auto launch = [&](uint32_t seed) {
                if (c.mode == 0) global_rows<0><<<blocks, threads>>>(grid, cells, c.len, c.rows, c.align, iters, seed, sink);
                if (c.mode == 1) global_rows<1><<<blocks, threads>>>(grid, cells, c.len, c.rows, c.align, iters, seed, sink);
                if (c.mode == 2) global_rows<2><<<blocks, threads>>>(grid, cells / 2 * 2 - 2, c.len, c.rows, c.align, iters, seed, sink);
                if (c.mode == 3) global_rows<3><<<blocks, threads>>>(grid, cells, c.len, c.rows, c.align, iters, seed, sink);
            };
            launch(1); CHECK(cudaGetLastError()); CHECK(cudaDeviceSynchronize());
            if (once) continue;
            float best = 1e30f;
            for (int r = 0; r < 5; ++r) { t.start(); launch(r + 2); float ms = t.stop(); if (ms < best) best = ms; }
            double adds = (double)warps * iters * active, instr = (double)warps * iters;
            printf("%-52s %10u %10.1f %10.2f %10.3f\n", c.name, cells, adds / best / 1e6, instr / best / 1e6, best);
        }
    }

    {
        struct LCase { const char* name; uint32_t len, rows, align; int shared; };
        const LCase lcases[] = {
            {"light global: scattered", 1, 32, 1, 0},
            {"light global: 4 runs of 8", 8, 4, 1, 0},
            {"light global: 4 runs of 8, aligned", 8, 4, 8, 0},
            {"light global: 5 runs of 5", 5, 5, 1, 0},
            {"light global: 2 runs of 15", 15, 2, 1, 0},
            {"light global: 2 runs of 16, aligned", 16, 2, 16, 0},
            {"light global: 1 run of 32", 32, 1, 1, 0},
            {"light global: 1 run of 32, aligned", 32, 1, 32, 0},
            {"light global: 1 run of 16 (16 lanes)", 16, 1, 1, 0},
            {"light shared u32: 4 runs of 8", 8, 4, 1, 1},
            {"light shared u32: 1 run of 32, aligned", 32, 1, 32, 1},
            {"light shared u32: scattered", 1, 32, 1, 1},
            {"light shared f32 native: 4 runs of 8", 8, 4, 1, 2},
        };
        printf("\n%-52s %10s %10s %10s %10s\n", "light pattern", "words", "Gadd/s", "Ginstr/s", "ms");
        for (const LCase& c : lcases) {
            uint32_t mask = c.shared ? 4095u : (1u << 21) - 1u;
            uint32_t active = c.len * c.rows;
            uint32_t iters = (uint32_t)((1ull << (c.shared ? 31 : 29)) / ((uint64_t)warps * active * 4)) + 1;
            size_t shbytes = c.shared ? (4096 + 64) * 4 : 0;
            auto launch = [&](uint32_t seed) {
                if (c.shared == 0) light_rows<0><<<blocks, threads, shbytes>>>(grid, mask, c.len, c.rows, c.align, iters, seed);
                if (c.shared == 1) light_rows<1><<<blocks, threads, shbytes>>>(grid, mask, c.len, c.rows, c.align, iters, seed);
                if (c.shared == 2) light_rows<2><<<blocks, threads, shbytes>>>(grid, mask, c.len, c.rows, c.align, iters, seed);
            };
            launch(1); CHECK(cudaGetLastError()); CHECK(cudaDeviceSynchronize());
            float best = 1e30f;
            for (int r = 0; r < 5; ++r) { t.start(); launch(r + 2); float ms = t.stop(); if (ms < best) best = ms; }
            double adds = (double)warps * iters * 4 * active, instr = (double)warps * iters * 4;
            printf("%-52s %10u %10.1f %10.2f %10.3f\n", c.name, mask + 1, adds / best / 1e6, instr / best / 1e6, best);
        }
    }
    if (once) return 0;
    struct SCase { const char* name; uint32_t len, rows; int mode; };
    const SCase scases[] = {
        {"shared u32 add, 4 runs of 8", 8, 4, 0},
        {"shared f32 CAS loop, 4 runs of 8", 8, 4, 1},
        {"shared f32 native add, 4 runs of 8", 8, 4, 2},
        {"shared u32 add, scattered", 1, 32, 0},
        {"shared f32 CAS loop, scattered", 1, 32, 1},
    };
    printf("\n%-52s %10s %10s %10s %10s\n", "shared pattern", "words", "Gadd/s", "Ginstr/s", "ms");
    const uint32_t tile = 15u * 15u * 15u;
    for (const SCase& c : scases) {
        uint32_t active = c.len * c.rows;
        uint32_t iters = (uint32_t)((1ull << 30) / ((uint64_t)warps * active)) + 1;
        size_t shbytes = tile * 4;
        auto launch = [&](uint32_t seed) {
            if (c.mode == 0) shared_rows<0><<<blocks, threads, shbytes>>>(sink, tile, c.len, c.rows, iters, seed);
            if (c.mode == 1) shared_rows<1><<<blocks, threads, shbytes>>>(sink, tile, c.len, c.rows, iters, seed);
            if (c.mode == 2) shared_rows<2><<<blocks, threads, shbytes>>>(sink, tile, c.len, c.rows, iters, seed);
        };
        launch(1); CHECK(cudaGetLastError()); CHECK(cudaDeviceSynchronize());
        float best = 1e30f;
        for (int r = 0; r < 5; ++r) { t.start(); launch(r + 2); float ms = t.stop(); if (ms < best) best = ms; }
        double adds = (double)warps * iters * active, instr = (double)warps * iters;
        printf("%-52s %10u %10.1f %10.2f %10.3f\n", c.name, tile, adds / best / 1e6, instr / best / 1e6, best);
    }
    return 0;
}
