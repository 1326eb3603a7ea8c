// Which pixels and tiles a Gaussian's conservative box covers (the binning in projection.cpp, the kernels' rows and
// columns in raster_common.h), and which tiles of a box row its ellipse can reach (the binning's tile culling).
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

// Which tiles of its rectangle a Gaussian can reach: the tiles whose pixel centres, inside its box, include one with
// sigma <= ln(o / kAlphaMin), the largest sigma at which the kernels find alpha >= kAlphaMin.  The other tiles of
// the rectangle hold no such pixel: the kernels would skip every pixel of those pairs, so leaving the pairs out of
// the binning changes no output.  Per tile row, the exact x-range of the ellipse over the band of the row's
// pixel-centre rows (the per-row tile test of Speedy-Splat, arXiv:2412.00578), in double, with margins for the
// kernels' float rounding.  ellipse_rows does the per-Gaussian part once, tile_row_span the per-row part, and
// tile_mask puts the result in one word.
constexpr double kSpanPad = 1e-3;  // px added to every ellipse edge, for the kernels' float pixel offsets

struct EllipseRows {
    double mx, my, a, b, det, q;  // centre (px), conic a, b, det = a c - b^2, q = 2 a tau
    double ymax, yr, yl;          // half-height of the ellipse; dy of its rightmost and leftmost points
    int64_t j0, j1, i0, i1;       // the box's pixel columns and rows (pixel_range)
    bool whole;                   // keep the whole rectangle (a conic that is not positive definite)
};

template <typename S>
inline EllipseRows ellipse_rows(const S* mean2d, const S* extent, const S* conic, S opacity, int64_t width,
                                int64_t height) {
    EllipseRows e{};
    e.mx = double(mean2d[0]);
    e.my = double(mean2d[1]);
    e.a = double(conic[0]);
    e.b = double(conic[1]);
    const double c = double(conic[2]);
    e.det = e.a * c - e.b * e.b;
    // sigma <= tau on the ellipse; the relative margin grows with the conic's condition (the kernels' float sigma
    // sums terms up to (a c / det) times sigma), the absolute one covers tiny opacities (tau -> 0)
    const double tau =
        std::max(0.0, std::log(double(opacity) / kAlphaMin)) * (1.0 + 1e-4 + 1e-6 * (e.a * c / e.det)) + 1e-4;
    if (!(e.a > 0 && c > 0 && e.det > 0) || !std::isfinite(e.det) || !std::isfinite(tau)) {
        e.whole = true;
        return e;
    }
    e.q = 2.0 * e.a * tau;
    e.ymax = std::sqrt(e.q / e.det) + kSpanPad;
    const double xw = std::sqrt(2.0 * c * tau / e.det);  // half-width
    e.yr = -e.b * xw / c;
    e.yl = e.b * xw / c;
    pixel_range(e.mx, double(extent[0]), width, e.j0, e.j1);
    pixel_range(e.my, double(extent[1]), height, e.i0, e.i1);
    return e;
}

// Tile columns [c0, c1] of tile row ty of rect that the Gaussian of e can reach; false when none.  x(dy) on the
// ellipse is (-b dy +- sqrt(q - det dy^2)) / a: the right edge is concave in dy and the left convex, so over the
// band their extremes are at the vertices yr, yl clamped to it.
inline bool tile_row_span(const EllipseRows& e, const int32_t* rect, int64_t ty, int32_t& c0, int32_t& c1) {
    c0 = rect[0];
    c1 = rect[1];
    if (e.whole) return true;
    const int64_t i0 = std::max<int64_t>(e.i0, ty * kTile), i1 = std::min<int64_t>(e.i1, ty * kTile + kTile - 1);
    if (i0 > i1) return false;
    const double y0 = std::max(double(i0) + 0.5 - e.my, -e.ymax), y1 = std::min(double(i1) + 0.5 - e.my, e.ymax);
    if (y0 > y1) return false;
    const double yr = std::clamp(e.yr, y0, y1), yl = std::clamp(e.yl, y0, y1);
    const double xr = (-e.b * yr + std::sqrt(std::max(0.0, e.q - e.det * yr * yr))) / e.a + kSpanPad;
    const double xl = (-e.b * yl - std::sqrt(std::max(0.0, e.q - e.det * yl * yl))) / e.a - kSpanPad;
    const double fj0 = std::ceil(e.mx + xl - 0.5), fj1 = std::floor(e.mx + xr - 0.5);
    const int64_t j0 = fj0 > double(e.j0) ? int64_t(fj0) : e.j0;
    const int64_t j1 = fj1 < double(e.j1) ? int64_t(fj1) : e.j1;
    if (j0 > j1) return false;
    c0 = std::max<int32_t>(rect[0], int32_t(j0 / kTile));
    c1 = std::min<int32_t>(rect[1], int32_t(j1 / kTile));
    return c0 <= c1;
}

// Whether a rectangle's tiles are culled through a tile_mask (2..64 tiles in both directions), row by row from its
// EllipseRows (a larger one), or not at all (one row or one column of tiles: nothing to gain).
enum class TileCull { kNone, kMask, kRows };

inline TileCull tile_cull_kind(const int32_t* rect) {
    const int64_t nx = rect[1] - rect[0] + 1, ny = rect[3] - rect[2] + 1;
    return nx < 2 || ny < 2 ? TileCull::kNone : nx * ny <= 64 ? TileCull::kMask : TileCull::kRows;
}

// The tiles of a rectangle of kind kMask that its Gaussian can reach (e: its ellipse_rows), as bits (tile row -
// rect[2]) * columns + (tile column - rect[0]), set when reached: row-major order is ascending bit order.
// kAllTiles when the conic is not positive definite.
constexpr uint64_t kAllTiles = ~uint64_t(0);

inline uint64_t tile_mask(const EllipseRows& e, const int32_t* rect) {
    const int64_t nx = rect[1] - rect[0] + 1;
    if (e.whole) return kAllTiles;
    uint64_t m = 0;
    for (int64_t ty = rect[2]; ty <= rect[3]; ++ty) {
        int32_t c0, c1;
        if (!tile_row_span(e, rect, ty, c0, c1)) continue;
        const int64_t row = (ty - rect[2]) * nx - rect[0];
        for (int64_t tx = c0; tx <= c1; ++tx) m |= uint64_t(1) << (row + tx);
    }
    return m;
}

}  // namespace eigs
