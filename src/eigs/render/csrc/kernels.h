// Plain C++ entry points of the rasterizer kernels (no torch headers: ops.cpp wraps them for Python).
// All arrays are dense, row-major, of scalar type S (float or double) unless stated otherwise.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "tile_geom.h"

namespace eigs {

// Camera: world-to-camera rotation R (row-major 3x3), translation t, pinhole intrinsics, image size.
template <typename S>
struct Camera {
    S R[9];
    S t[3];
    S fx, fy, cx, cy;
    int64_t width, height;
};

// Projection of N Gaussians.  Outputs for culled Gaussians: radii = 0, extents = 0, other outputs 0.
//   means (N,3), quats (N,4) wxyz, scales (N,3), opacities (N), colors (N,D) (only checked: a Gaussian with a
//   non-finite colour is culled)
//   -> means2d (N,2) px, conics (N,3), depths (N), extents (N,2) px (float half-widths of the conservative box),
//      radii (N,2) int32 (ceil of extents, 0 when culled or off-image)
template <typename S>
void project_forward(int64_t n, const S* means, const S* quats, const S* scales, const S* opacities,
                     const S* colors, int64_t d, const Camera<S>& cam, S* means2d, S* conics, S* depths,
                     S* extents, int32_t* radii, int nthreads);

// VJP of the projection for Gaussians with radii > 0.
//   v_means2d (N,2), v_conics (N,3) -> v_means (N,3), v_quats (N,4), v_scales (N,3) (overwritten)
template <typename S>
void project_backward(int64_t n, const S* means, const S* quats, const S* scales, const Camera<S>& cam,
                      const int32_t* radii, const S* v_means2d, const S* v_conics, S* v_means, S* v_quats,
                      S* v_scales, int nthreads);

// Tile binning, in two steps so that the caller can allocate flatten_ids in between.
// isect_plan: for the Gaussians with radii > 0, the order (ascending depth, ties by index), their tile
// rectangles (with BinInputs::conics, the tiles their ellipse reaches: tile_geom.h) and the pair counts; writes
// tile_offsets (n_tiles + 1, exclusive prefix sum) and returns n_isects.
// isect_fill: flatten_ids (n_isects): per tile (row-major tile order), the Gaussian ids in that order.
// Parallel over nthreads chunks (sort per chunk + pairwise merges, each merge split among the threads at
// co-ranks; per-chunk tile cursors): the result is the same for any thread count.
// The buffers are left uninitialised on allocation (every entry read is written first): no serial memsets.
struct IsectPlan {
    std::unique_ptr<int64_t[]> order;  // visible Gaussians in (depth, index) order (n_visible entries)
    std::unique_ptr<int32_t[]> rect;   // per Gaussian: tile columns [0], [1], tile rows [2], [3] (inclusive)
    std::unique_ptr<uint64_t[]> masks;  // when the binning culls (tile_geom.h): per Gaussian its tile_mask,
    std::unique_ptr<EllipseRows[]> ellipses;  // or, for a rectangle of over 64 tiles, its ellipse_rows
    std::vector<int64_t> cursor;       // nchunks x n_tiles: where chunk c writes into tile t
    int nchunks = 1;
    int64_t n_visible = 0, n_tiles = 0, tiles_x = 0;
};

// What the binning reads of the N projected Gaussians: means2d (N,2), extents (N,2) and, for the tile culling
// (tile_geom.h, tile_row_span), conics (N,3) and opacities (N); conics == nullptr bins every tile of each box.
template <typename S>
struct BinInputs {
    int64_t n;
    const S *means2d, *extents, *conics, *opacities;
    int64_t width, height;
};

template <typename S>
int64_t isect_plan(const BinInputs<S>& b, const S* depths, const int32_t* radii,
                   int64_t* tile_offsets /* (n_tiles + 1) */, IsectPlan& plan, int nthreads);

void isect_fill(IsectPlan& plan, int64_t* flatten_ids);

// Forward compositing.  colors (N,D), background (D) -> image (H,W,D) = C + T bg, alpha (H,W) = 1 - T,
// trans (H,W) = final T, last (H,W) int32 = position (within its tile's list) of the last contributing Gaussian
// (-1 if none), tile_work (n_tiles) = the tile's work units (Gaussians visited + kRowWork per row evaluated),
// the backward's schedule.
// isa: 0 = best available, 1 = baseline (SSE2), 2 = AVX2, 3 = AVX-512.
template <typename S>
void rasterize_forward(const S* means2d, const S* conics, const S* colors, const S* opacities,
                       const S* extents, const S* background, int64_t d, int64_t width, int64_t height,
                       const int64_t* tile_offsets, const int64_t* flatten_ids, S* image, S* alpha, S* trans,
                       int32_t* last, int64_t* tile_work, int nthreads, int isa);

// Backward compositing.  v_image (H,W,D), v_alpha (H,W) -> per-pair gradients pair_grads (n_isects, 6 + D)
// in the order (v_mean2d x, y, v_conic a, b, c, v_opacity, v_color...), stored grouped by Gaussian (its tiles in
// row-major order, i.e. its isect order), then summed per Gaussian in that fixed order (deterministic for any
// thread count) into v_means2d (N,2), v_conics (N,3), v_opacities (N), v_colors (N,D) (overwritten);
// v_background (D) = sum over pixels of T_final v_image, summed per tile (row-major pixels) and then over tiles
// in tile order (deterministic too).  The grouping is a counting sort of flatten_ids, so any binning of the
// forward's works (the tile culling's too).  Throws std::runtime_error if flatten_ids names no Gaussian of 0..n-1.
template <typename S>
void rasterize_backward(int64_t n, const S* means2d, const S* conics, const S* colors, const S* opacities,
                        const S* extents, const S* background, int64_t d, int64_t width, int64_t height,
                        const int64_t* tile_offsets, const int64_t* flatten_ids, const S* trans,
                        const int32_t* last, const int64_t* tile_work, const S* v_image, const S* v_alpha,
                        S* pair_grads, S* v_means2d, S* v_conics, S* v_opacities, S* v_colors, S* v_background,
                        int nthreads, int isa);

// ISA support of this CPU: bit 0 AVX2, bit 1 AVX-512 (F, VL, BW, DQ).
int cpu_isa_flags();

}  // namespace eigs
