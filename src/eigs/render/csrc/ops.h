// The kernels as checked tensor ops (ops.cpp): contiguous CPU tensors of one floating dtype in, new tensors out.
// autograd.cpp builds the differentiable Functions and the Python bindings on top of these.
#pragma once

#include <ATen/ATen.h>

#include <cstdint>
#include <tuple>
#include <vector>

namespace eigs::ops {

using at::Tensor;

// cam: the 16 entries of viewmat (row-major 4x4, world-to-camera) then the 9 of K (row-major 3x3), already
// rounded to the tensors' dtype by the caller.

// means (N,3), quats (N,4), scales (N,3), opacities (N), colors (N,D)
//   -> means2d (N,2), conics (N,3), depths (N), extents (N,2), radii (N,2) int32
std::tuple<Tensor, Tensor, Tensor, Tensor, Tensor> project_fwd(const Tensor& means, const Tensor& quats,
                                                                const Tensor& scales, const Tensor& opacities,
                                                                const Tensor& colors, const std::vector<double>& cam,
                                                                int64_t width, int64_t height);

// v_means2d (N,2), v_conics (N,3) -> v_means (N,3), v_quats (N,4), v_scales (N,3)
std::tuple<Tensor, Tensor, Tensor> project_bwd(const Tensor& means, const Tensor& quats, const Tensor& scales,
                                               const std::vector<double>& cam, int64_t width, int64_t height,
                                               const Tensor& radii, const Tensor& v_means2d, const Tensor& v_conics);

// -> tile_offsets (n_tiles + 1) int64, flatten_ids (n_isects) int64.  With conics (N,3) and opacities (N) given,
// a box's tiles that its ellipse cannot reach are left out (kernels.h, BinInputs); undefined tensors: every tile.
std::tuple<Tensor, Tensor> isect_tiles(const Tensor& means2d, const Tensor& extents, const Tensor& depths,
                                       const Tensor& radii, int64_t width, int64_t height, const Tensor& conics,
                                       const Tensor& opacities);

// -> image (H,W,D), alpha (H,W), trans (H,W) final transmittance, last (H,W) int32, tile_work (n_tiles) int64
std::tuple<Tensor, Tensor, Tensor, Tensor, Tensor> rasterize_fwd(const Tensor& means2d, const Tensor& conics,
                                                         const Tensor& colors, const Tensor& opacities,
                                                         const Tensor& extents, const Tensor& background,
                                                         const Tensor& tile_offsets, const Tensor& flatten_ids,
                                                         int64_t width, int64_t height, int64_t isa);

// v_image (H,W,D), v_alpha (H,W) -> v_means2d (N,2), v_conics (N,3), v_opacities (N), v_colors (N,D),
// v_background (D)
std::tuple<Tensor, Tensor, Tensor, Tensor, Tensor> rasterize_bwd(
    const Tensor& means2d, const Tensor& conics, const Tensor& colors, const Tensor& opacities,
    const Tensor& extents, const Tensor& background, const Tensor& tile_offsets, const Tensor& flatten_ids,
    int64_t width, int64_t height, const Tensor& trans, const Tensor& last, const Tensor& tile_work,
    const Tensor& v_image, const Tensor& v_alpha, int64_t isa);

}  // namespace eigs::ops
