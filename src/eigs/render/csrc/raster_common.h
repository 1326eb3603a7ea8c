// Shared tile geometry and ISA plumbing of the compositing kernels (rasterize_fwd.cpp, rasterize_bwd.cpp).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <vector>

#include "pair_math.h"
#include "tile_geom.h"

// Per-ISA wrappers: the kernel bodies are always-inline templates, instantiated inside functions compiled for
// each target, so one source gives a baseline (SSE2), an AVX2 and an AVX-512 version; the choice is made at
// run time from the CPU's features (cpu_isa_flags) or forced by the caller (tests run all of them).
#define EIGS_TARGET_BASE
#define EIGS_TARGET_AVX2 __attribute__((target("avx2,fma")))
#define EIGS_TARGET_AVX512 __attribute__((target("avx512f,avx512vl,avx512bw,avx512dq,avx2,fma")))

namespace eigs {

enum Isa : int { kIsaAuto = 0, kIsaBase = 1, kIsaAvx2 = 2, kIsaAvx512 = 3 };

// Resolve the requested ISA against the CPU (an unsupported request falls back to the best supported one).
int resolve_isa(int requested);

// Geometry shared by forward and backward for one tile.
struct TileGeom {
    int64_t x0, y0;      // pixel coordinates of the tile's top-left pixel
    int cols, rows;      // pixels of the tile inside the image (<= kTile)
};

inline TileGeom tile_geom(int64_t tile, int64_t width, int64_t height) {
    const int64_t tiles_x = (width + kTile - 1) / kTile;
    TileGeom t;
    t.x0 = (tile % tiles_x) * kTile;
    t.y0 = (tile / tiles_x) * kTile;
    t.cols = int(std::min<int64_t>(kTile, width - t.x0));
    t.rows = int(std::min<int64_t>(kTile, height - t.y0));
    return t;
}

// Rows [r0, r1] of the tile whose pixel centres lie inside the Gaussian's conservative box: the binning's own
// pixel range (tile_geom.h), clipped to the tile with integer arithmetic; r0 > r1 when none.
inline void box_rows(double my, double ey, int64_t y0, int rows, int& r0, int& r1) {
    int64_t lo, hi;
    pixel_range(my, ey, y0 + rows, lo, hi);  // absolute rows, clamped to [0, y0 + rows - 1]
    lo = std::max(lo, y0);
    if (lo > hi) {
        r0 = 1;
        r1 = 0;
        return;
    }
    r0 = int(lo - y0);
    r1 = int(hi - y0);
}

// Tiles in the order the threads pick them up: with one thread row-major; with several the costliest first
// (ties by index), so that the dynamic schedule ends on small tiles instead of one thread finishing a large tile
// while the others idle (with 16 tiles on 2 threads the order decides the final imbalance).  cost(t) estimates
// tile t's work.  Tiles are independent, so the order never changes the results.
template <typename Cost>
std::vector<int64_t> tile_schedule(int64_t n_tiles, int nthreads, Cost cost) {
    std::vector<int64_t> order(static_cast<size_t>(n_tiles));
    std::iota(order.begin(), order.end(), int64_t(0));
    if (nthreads > 1) {
        std::vector<int64_t> c(static_cast<size_t>(n_tiles));
        for (int64_t t = 0; t < n_tiles; ++t) c[size_t(t)] = cost(t);
        std::sort(order.begin(), order.end(), [&c](int64_t a, int64_t b) {
            return c[size_t(a)] > c[size_t(b)] || (c[size_t(a)] == c[size_t(b)] && a < b);
        });
    }
    return order;
}

// Gaussians ahead in a tile's list whose parameters the kernels prefetch: the list is in depth order, so its
// Gaussians sit at random places in the parameter arrays (and the backward's pair-gradient buffer), and without
// the prefetch each Gaussian starts with cache misses (perf: ~15 % of the backward's samples, and the forward
// is ~1.4x faster with it at 256^2 / 64k).  The work per Gaussian hides several Gaussians' worth of misses.
constexpr int64_t kPrefetch = 4;

// Work units of one tile as the forward counts them (tile_work): one per Gaussian visited and kRowWork per
// tile row evaluated for it.  The backward, whose per-row work is ~4x its per-Gaussian setup, schedules by it.
constexpr int64_t kRowWork = 4;

}  // namespace eigs
