// Which pixels and tiles a Gaussian's conservative box covers: one definition for the binning (projection.cpp)
// and the backward's per-Gaussian pair slots (rasterize_bwd.cpp), so that both see the same rectangles.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "pair_math.h"

namespace eigs {

// Pixel-index range [lo, hi] of pixel centres k + 0.5 inside [c - r, c + r], clamped to [0, size - 1];
// lo > hi when empty.  Computed in double so that large coordinates cannot overflow an int.
inline void pixel_range(double c, double r, int64_t size, int64_t& lo, int64_t& hi) {
    double a = std::ceil(c - r - 0.5), b = std::floor(c + r - 0.5);
    a = std::max(a, 0.0);
    b = std::min(b, double(size - 1));
    if (!(a <= b)) {
        lo = 1;
        hi = 0;
        return;
    }
    lo = int64_t(a);
    hi = int64_t(b);
}

// Tile rectangle of the box of half-widths extent (2) around mean2d (2) px: tile columns rect[0]..rect[1] and
// rows rect[2]..rect[3], inclusive.  Returns false (rect untouched) when the box covers no pixel centre.
template <typename S>
inline bool tile_rect(const S* mean2d, const S* extent, int64_t width, int64_t height, int32_t* rect) {
    int64_t j0, j1, i0, i1;
    pixel_range(double(mean2d[0]), double(extent[0]), width, j0, j1);
    pixel_range(double(mean2d[1]), double(extent[1]), height, i0, i1);
    if (j0 > j1 || i0 > i1) return false;
    rect[0] = int32_t(j0 / kTile);
    rect[1] = int32_t(j1 / kTile);
    rect[2] = int32_t(i0 / kTile);
    rect[3] = int32_t(i1 / kTile);
    return true;
}

}  // namespace eigs
