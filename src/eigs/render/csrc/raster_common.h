// Shared tile geometry and ISA plumbing of the compositing kernels (rasterize_fwd.cpp, rasterize_bwd.cpp).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <vector>

#include "pair_math.h"

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

// Rows [r0, r1] of the tile whose pixel centres lie inside the Gaussian's conservative box
// (the same double-precision rule as the tile binning); r0 > r1 when none.
inline void box_rows(double my, double ey, int64_t y0, int rows, int& r0, int& r1) {
    double a = std::ceil(my - ey - 0.5 - double(y0)), b = std::floor(my + ey - 0.5 - double(y0));
    a = std::max(a, 0.0);
    b = std::min(b, double(rows - 1));
    if (!(a <= b)) {
        r0 = 1;
        r1 = 0;
        return;
    }
    r0 = int(a);
    r1 = int(b);
}

// Tiles in the order the threads pick them up: with one thread row-major; with several the longest lists
// first (ties by index), so that the dynamic schedule does not end with one thread on a long tile while the
// others idle.  Tiles are independent, so the order never changes the results.
inline std::vector<int64_t> tile_schedule(const int64_t* tile_offsets, int64_t n_tiles, int nthreads) {
    std::vector<int64_t> order(static_cast<size_t>(n_tiles));
    std::iota(order.begin(), order.end(), int64_t(0));
    if (nthreads > 1)
        std::sort(order.begin(), order.end(), [tile_offsets](int64_t a, int64_t b) {
            const int64_t ca = tile_offsets[a + 1] - tile_offsets[a], cb = tile_offsets[b + 1] - tile_offsets[b];
            return ca > cb || (ca == cb && a < b);
        });
    return order;
}

}  // namespace eigs
