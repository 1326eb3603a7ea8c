// The differentiable pipeline, one autograd Function per op (project -> tile intersect -> rasterize to pixels),
// and the Python bindings.  The Functions live in C++ so that a forward + backward costs no Python frames:
// at small images the per-call overhead, not the kernels, bounds the multi-thread scaling (docs/rasterizer.md).
// Shapes: N Gaussians, D colour channels, an H x W image, n_isects (Gaussian, tile) pairs.
// Not <torch/extension.h>: that pulls in the whole C++ frontend (nn, optim, data); these three are what the file
// uses (autograd Functions, torch::zeros, the pybind11 casters) and parse in 53 s instead of 75 s (docs/rasterizer.md).
#include <torch/csrc/autograd/custom_function.h>
#include <torch/csrc/autograd/generated/variable_factories.h>
#include <torch/python.h>

#include <torch/csrc/autograd/functions/basic_ops.h>

#include <string>
#include <tuple>
#include <vector>

#include "kernels.h"
#include "ops.h"

namespace {

using torch::Tensor;
using torch::autograd::AutogradContext;
using torch::autograd::variable_list;

// Like Python's @once_differentiable: under create_graph the gradients carry a node that raises when they are
// differentiated again, instead of silently acting as constants.
variable_list once_differentiable(variable_list grads) {
    if (!torch::autograd::GradMode::is_enabled()) return grads;
    variable_list fake;
    fake.reserve(grads.size());
    for (const auto& g : grads) fake.push_back(g.defined() ? g.detach().requires_grad_(true) : g);
    torch::autograd::DelayedError err("the eigs rasterizer's backward is not differentiable (no double backward)",
                                      int64_t(fake.size()));
    return err.apply(std::move(fake));
}

Tensor or_zeros(const Tensor& g, at::IntArrayRef shape, const Tensor& like) {
    return g.defined() ? g.contiguous() : torch::zeros(shape, like.options());
}

// means (N,3), quats (N,4), scales (N,3), opacities (N), colors (N,D) -> means2d (N,2), conics (N,3),
// depths (N), extents (N,2), radii (N,2) int32.  Differentiable in means2d and conics; opacities and colors only
// take part in the culling (a non-finite colour culls its Gaussian); cam (16 viewmat + 9 K entries) is constant.
struct ProjectGaussians : public torch::autograd::Function<ProjectGaussians> {
    static variable_list forward(AutogradContext* ctx, const Tensor& means, const Tensor& quats,
                                 const Tensor& scales, const Tensor& opacities, const Tensor& colors,
                                 const std::vector<double>& cam, int64_t width, int64_t height) {
        auto [means2d, conics, depths, extents, radii] =
            eigs::ops::project_fwd(means, quats, scales, opacities, colors, cam, width, height);
        ctx->save_for_backward({means, quats, scales, radii});
        ctx->saved_data["cam"] = cam;
        ctx->saved_data["width"] = width;
        ctx->saved_data["height"] = height;
        ctx->mark_non_differentiable({depths, extents, radii});
        return {means2d, conics, depths, extents, radii};
    }

    static variable_list backward(AutogradContext* ctx, variable_list grads) {
        const auto saved = ctx->get_saved_variables();
        const Tensor &means = saved[0], &quats = saved[1], &scales = saved[2], &radii = saved[3];
        const int64_t n = means.size(0);
        const Tensor v_means2d = or_zeros(grads[0], {n, 2}, means), v_conics = or_zeros(grads[1], {n, 3}, means);
        auto [v_means, v_quats, v_scales] = eigs::ops::project_bwd(
            means, quats, scales, ctx->saved_data["cam"].toDoubleVector(), ctx->saved_data["width"].toInt(),
            ctx->saved_data["height"].toInt(), radii, v_means2d, v_conics);
        return once_differentiable({v_means, v_quats, v_scales, Tensor(), Tensor(), Tensor(), Tensor(), Tensor()});
    }
};

// means2d (N,2), conics (N,3), colors (N,D), opacities (N), background (D) -> image (H,W,D), alpha (H,W).
// extents, tile_offsets and flatten_ids (the binning) are constants.
struct RasterizeToPixels : public torch::autograd::Function<RasterizeToPixels> {
    static variable_list forward(AutogradContext* ctx, const Tensor& means2d, const Tensor& conics,
                                 const Tensor& colors, const Tensor& opacities, const Tensor& background,
                                 const Tensor& extents, const Tensor& tile_offsets, const Tensor& flatten_ids,
                                 int64_t width, int64_t height, int64_t isa) {
        auto [image, alpha, trans, last, tile_work] =
            eigs::ops::rasterize_fwd(means2d, conics, colors, opacities, extents, background, tile_offsets,
                                     flatten_ids, width, height, isa);
        ctx->save_for_backward({means2d, conics, colors, opacities, background, extents, tile_offsets, flatten_ids,
                                trans, last, tile_work});
        ctx->saved_data["width"] = width;
        ctx->saved_data["height"] = height;
        ctx->saved_data["isa"] = isa;
        return {image, alpha};
    }

    static variable_list backward(AutogradContext* ctx, variable_list grads) {
        const auto s = ctx->get_saved_variables();
        const int64_t W = ctx->saved_data["width"].toInt(), H = ctx->saved_data["height"].toInt();
        const int64_t D = s[2].size(1);
        const Tensor v_image = or_zeros(grads[0], {H, W, D}, s[0]), v_alpha = or_zeros(grads[1], {H, W}, s[0]);
        auto [v_means2d, v_conics, v_opacities, v_colors, v_background] = eigs::ops::rasterize_bwd(
            s[0], s[1], s[2], s[3], s[5], s[4], s[6], s[7], W, H, s[8], s[9], s[10], v_image, v_alpha,
            ctx->saved_data["isa"].toInt());
        return once_differentiable({v_means2d, v_conics, v_colors, v_opacities, v_background, Tensor(), Tensor(),
                                    Tensor(), Tensor(), Tensor(), Tensor()});
    }
};

std::tuple<Tensor, Tensor, Tensor, Tensor, Tensor> project(const Tensor& means, const Tensor& quats,
                                                            const Tensor& scales, const Tensor& opacities,
                                                            const Tensor& colors, const std::vector<double>& cam,
                                                            int64_t width, int64_t height) {
    auto out = ProjectGaussians::apply(means, quats, scales, opacities, colors, cam, width, height);
    return {out[0], out[1], out[2], out[3], out[4]};
}

// Tile binning (not differentiable): see ops.h.  conics and opacities: None bins every tile of each box.
std::tuple<Tensor, Tensor> isect_tiles(const Tensor& means2d, const Tensor& extents, const Tensor& depths,
                                       const Tensor& radii, int64_t width, int64_t height,
                                       const std::optional<Tensor>& conics, const std::optional<Tensor>& opacities) {
    return eigs::ops::isect_tiles(means2d.detach(), extents, depths, radii, width, height,
                                  conics ? conics->detach() : Tensor(), opacities ? opacities->detach() : Tensor());
}

std::tuple<Tensor, Tensor> rasterize_to_pixels(const Tensor& means2d, const Tensor& conics, const Tensor& colors,
                                               const Tensor& opacities, const Tensor& background,
                                               const Tensor& extents, const Tensor& tile_offsets,
                                               const Tensor& flatten_ids, int64_t width, int64_t height,
                                               int64_t isa) {
    auto out = RasterizeToPixels::apply(means2d, conics, colors, opacities, background, extents, tile_offsets,
                                        flatten_ids, width, height, isa);
    return {out[0], out[1]};
}

// The three ops chained: -> image (H,W,D), alpha (H,W), means2d (N,2), conics (N,3), depths (N),
// radii (N,2) int32, tile_offsets (n_tiles + 1), flatten_ids (n_isects).
std::tuple<Tensor, Tensor, Tensor, Tensor, Tensor, Tensor, Tensor, Tensor> rasterize(
    const Tensor& means, const Tensor& quats, const Tensor& scales, const Tensor& opacities, const Tensor& colors,
    const std::vector<double>& cam, int64_t width, int64_t height, const Tensor& background, int64_t isa) {
    auto [means2d, conics, depths, extents, radii] =
        project(means, quats, scales, opacities, colors, cam, width, height);
    auto [tile_offsets, flatten_ids] = isect_tiles(means2d, extents, depths, radii, width, height, conics, opacities);
    auto [image, alpha] = rasterize_to_pixels(means2d, conics, colors, opacities, background, extents,
                                              tile_offsets, flatten_ids, width, height, isa);
    return {image, alpha, means2d, conics, depths, radii, tile_offsets, flatten_ids};
}

}  // namespace

PYBIND11_MODULE(TORCH_EXTENSION_NAME, m) {
    m.doc() = "eigs CPU Gaussian rasterizer: differentiable ops (project, isect_tiles, rasterize_to_pixels, "
              "rasterize) and the raw kernels (*_fwd, *_bwd)";
    using release = py::call_guard<py::gil_scoped_release>;
    m.def("project", &project, release());
    m.def("isect_tiles", &isect_tiles, py::arg("means2d"), py::arg("extents"), py::arg("depths"), py::arg("radii"),
          py::arg("width"), py::arg("height"), py::arg("conics") = py::none(), py::arg("opacities") = py::none(),
          release());
    m.def("rasterize_to_pixels", &rasterize_to_pixels, release());
    m.def("rasterize", &rasterize, release());
    m.def("project_fwd", &eigs::ops::project_fwd, release());
    m.def("project_bwd", &eigs::ops::project_bwd, release());
    m.def("rasterize_fwd", &eigs::ops::rasterize_fwd, release());
    m.def("rasterize_bwd", &eigs::ops::rasterize_bwd, release());
    m.def("cpu_isa_flags", &eigs::cpu_isa_flags);
}
