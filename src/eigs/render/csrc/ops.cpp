// The kernels as checked tensor ops (declared in ops.h): every function takes contiguous CPU tensors of one
// floating dtype (checked here) and returns new tensors.
#include "ops.h"

#include <ATen/Dispatch.h>
#include <ATen/Parallel.h>

#include <algorithm>
#include <string>
#include <tuple>
#include <vector>

#include "kernels.h"

namespace eigs::ops {
namespace {

void check(const Tensor& t, const char* name, at::ScalarType dtype) {
    TORCH_CHECK(t.device().is_cpu(), name, " must be a CPU tensor");
    TORCH_CHECK(t.scalar_type() == dtype, name, " must have dtype ", dtype, ", got ", t.scalar_type());
    TORCH_CHECK(t.is_contiguous(), name, " must be contiguous");
}

template <typename S>
eigs::Camera<S> make_camera(const std::vector<double>& cam_in, int64_t width, int64_t height) {
    TORCH_CHECK(cam_in.size() == 25, "cam must hold the 16 viewmat and 9 K entries, got ", cam_in.size());
    const double* V = cam_in.data();
    const double* k = cam_in.data() + 16;
    eigs::Camera<S> cam;
    for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) cam.R[i * 3 + j] = S(V[i * 4 + j]);
        cam.t[i] = S(V[i * 4 + 3]);
    }
    cam.fx = S(k[0]);
    cam.fy = S(k[4]);
    cam.cx = S(k[2]);
    cam.cy = S(k[5]);
    cam.width = width;
    cam.height = height;
    return cam;
}

// Threads for a parallel loop of `work` units: at most torch's setting, and one thread per `grain` units
// (waking a team costs far more than a small loop, notably on a loaded machine).
int threads(int64_t work, int64_t grain) {
    const int64_t by_work = std::max<int64_t>(1, work / std::max<int64_t>(1, grain));
    return int(std::max<int64_t>(1, std::min<int64_t>(at::get_num_threads(), by_work)));
}

// Gaussians per thread below which projection (and its backward) and binning run on fewer threads.
constexpr int64_t kProjectGrain = 256;
constexpr int64_t kIsectGrain = 1024;

int64_t n_tiles_of(int64_t width, int64_t height) { return ((width + 15) / 16) * ((height + 15) / 16); }

}  // namespace

std::tuple<Tensor, Tensor, Tensor, Tensor, Tensor> project_fwd(const Tensor& means, const Tensor& quats,
                                                                const Tensor& scales, const Tensor& opacities,
                                                                const Tensor& colors,
                                                                const std::vector<double>& cam_in, int64_t width,
                                                                int64_t height) {
    const auto dt = means.scalar_type();
    for (const auto& [t, name] : {std::pair<const Tensor&, const char*>{means, "means"}, {quats, "quats"},
                            {scales, "scales"}, {opacities, "opacities"}, {colors, "colors"}})
        check(t, name, dt);
    const int64_t n = means.size(0);
    auto opt = means.options();
    Tensor means2d = at::empty({n, 2}, opt), conics = at::empty({n, 3}, opt);
    Tensor depths = at::empty({n}, opt), extents = at::empty({n, 2}, opt);
    Tensor radii = at::empty({n, 2}, opt.dtype(at::kInt));
    AT_DISPATCH_FLOATING_TYPES(dt, "project_fwd", [&] {
        const auto cam = make_camera<scalar_t>(cam_in, width, height);
        eigs::project_forward<scalar_t>(n, means.data_ptr<scalar_t>(), quats.data_ptr<scalar_t>(),
                                        scales.data_ptr<scalar_t>(), opacities.data_ptr<scalar_t>(),
                                        colors.data_ptr<scalar_t>(), colors.size(1), cam,
                                        means2d.data_ptr<scalar_t>(), conics.data_ptr<scalar_t>(),
                                        depths.data_ptr<scalar_t>(), extents.data_ptr<scalar_t>(),
                                        radii.data_ptr<int32_t>(), threads(n, kProjectGrain));
    });
    return {means2d, conics, depths, extents, radii};
}

std::tuple<Tensor, Tensor, Tensor> project_bwd(const Tensor& means, const Tensor& quats, const Tensor& scales,
                                               const std::vector<double>& cam_in, int64_t width, int64_t height,
                                               const Tensor& radii, const Tensor& v_means2d,
                                               const Tensor& v_conics) {
    const auto dt = means.scalar_type();
    for (const auto& [t, name] : {std::pair<const Tensor&, const char*>{means, "means"}, {quats, "quats"},
                            {scales, "scales"}, {v_means2d, "v_means2d"}, {v_conics, "v_conics"}})
        check(t, name, dt);
    check(radii, "radii", at::kInt);
    const int64_t n = means.size(0);
    Tensor v_means = at::empty({n, 3}, means.options()), v_quats = at::empty({n, 4}, means.options());
    Tensor v_scales = at::empty({n, 3}, means.options());
    AT_DISPATCH_FLOATING_TYPES(dt, "project_bwd", [&] {
        const auto cam = make_camera<scalar_t>(cam_in, width, height);
        eigs::project_backward<scalar_t>(n, means.data_ptr<scalar_t>(), quats.data_ptr<scalar_t>(),
                                         scales.data_ptr<scalar_t>(), cam, radii.data_ptr<int32_t>(),
                                         v_means2d.data_ptr<scalar_t>(), v_conics.data_ptr<scalar_t>(),
                                         v_means.data_ptr<scalar_t>(), v_quats.data_ptr<scalar_t>(),
                                         v_scales.data_ptr<scalar_t>(), threads(n, kProjectGrain));
    });
    return {v_means, v_quats, v_scales};
}

std::tuple<Tensor, Tensor> isect_tiles(const Tensor& means2d, const Tensor& extents, const Tensor& depths,
                                       const Tensor& radii, int64_t width, int64_t height, const Tensor& conics,
                                       const Tensor& opacities) {
    const auto dt = means2d.scalar_type();
    check(means2d, "means2d", dt);
    check(extents, "extents", dt);
    check(depths, "depths", dt);
    check(radii, "radii", at::kInt);
    const int64_t n = means2d.size(0);
    const bool cull = conics.defined();
    TORCH_CHECK(cull == opacities.defined(), "isect_tiles: give conics and opacities together, or neither");
    if (cull) {
        check(conics, "conics", dt);
        check(opacities, "opacities", dt);
        TORCH_CHECK(conics.size(0) == n && opacities.size(0) == n, "isect_tiles: conics and opacities need ", n,
                    " rows");
    }
    const int64_t n_tiles = ((width + 15) / 16) * ((height + 15) / 16);
    Tensor offsets = at::empty({n_tiles + 1}, means2d.options().dtype(at::kLong));
    eigs::IsectPlan plan;
    int64_t total = 0;
    Tensor ids;
    AT_DISPATCH_FLOATING_TYPES(dt, "isect_tiles", [&] {
        const eigs::BinInputs<scalar_t> b{n, means2d.data_ptr<scalar_t>(), extents.data_ptr<scalar_t>(),
                                          cull ? conics.data_ptr<scalar_t>() : nullptr,
                                          cull ? opacities.data_ptr<scalar_t>() : nullptr, width, height};
        total = eigs::isect_plan<scalar_t>(b, depths.data_ptr<scalar_t>(), radii.data_ptr<int32_t>(),
                                           offsets.data_ptr<int64_t>(), plan, threads(n, kIsectGrain));
        ids = at::empty({total}, means2d.options().dtype(at::kLong));
        eigs::isect_fill(plan, ids.data_ptr<int64_t>());
    });
    return {offsets, ids};
}

std::tuple<Tensor, Tensor, Tensor, Tensor, Tensor> rasterize_fwd(const Tensor& means2d, const Tensor& conics,
                                                         const Tensor& colors, const Tensor& opacities,
                                                         const Tensor& extents, const Tensor& background,
                                                         const Tensor& tile_offsets, const Tensor& flatten_ids,
                                                         int64_t width, int64_t height, int64_t isa) {
    const auto dt = means2d.scalar_type();
    for (const auto& [t, name] : {std::pair<const Tensor&, const char*>{means2d, "means2d"}, {conics, "conics"},
                            {colors, "colors"}, {opacities, "opacities"}, {extents, "extents"},
                            {background, "background"}})
        check(t, name, dt);
    check(tile_offsets, "tile_offsets", at::kLong);
    check(flatten_ids, "flatten_ids", at::kLong);
    const int64_t n_tiles = n_tiles_of(width, height);
    TORCH_CHECK(tile_offsets.numel() == n_tiles + 1, "tile_offsets must have ", n_tiles + 1, " entries");
    const int64_t d = colors.size(1);
    auto opt = means2d.options();
    Tensor tile_work = at::empty({n_tiles}, opt.dtype(at::kLong));
    Tensor image = at::empty({height, width, d}, opt), alpha = at::empty({height, width}, opt);
    Tensor trans = at::empty({height, width}, opt);
    Tensor last = at::empty({height, width}, opt.dtype(at::kInt));
    AT_DISPATCH_FLOATING_TYPES(dt, "rasterize_fwd", [&] {
        eigs::rasterize_forward<scalar_t>(
            means2d.data_ptr<scalar_t>(), conics.data_ptr<scalar_t>(), colors.data_ptr<scalar_t>(),
            opacities.data_ptr<scalar_t>(), extents.data_ptr<scalar_t>(), background.data_ptr<scalar_t>(), d,
            width, height, tile_offsets.data_ptr<int64_t>(), flatten_ids.data_ptr<int64_t>(),
            image.data_ptr<scalar_t>(), alpha.data_ptr<scalar_t>(), trans.data_ptr<scalar_t>(),
            last.data_ptr<int32_t>(), tile_work.data_ptr<int64_t>(),
            threads(std::min(n_tiles, flatten_ids.size(0) / 16 + 1), 1), int(isa));
    });
    return {image, alpha, trans, last, tile_work};
}

std::tuple<Tensor, Tensor, Tensor, Tensor, Tensor> rasterize_bwd(
    const Tensor& means2d, const Tensor& conics, const Tensor& colors, const Tensor& opacities,
    const Tensor& extents, const Tensor& background, const Tensor& tile_offsets, const Tensor& flatten_ids,
    int64_t width, int64_t height, const Tensor& trans, const Tensor& last, const Tensor& tile_work,
    const Tensor& v_image, const Tensor& v_alpha, int64_t isa) {
    const auto dt = means2d.scalar_type();
    for (const auto& [t, name] : {std::pair<const Tensor&, const char*>{means2d, "means2d"}, {conics, "conics"},
                            {colors, "colors"}, {opacities, "opacities"}, {extents, "extents"},
                            {background, "background"}, {trans, "trans"}, {v_image, "v_image"},
                            {v_alpha, "v_alpha"}})
        check(t, name, dt);
    check(tile_offsets, "tile_offsets", at::kLong);
    check(flatten_ids, "flatten_ids", at::kLong);
    check(last, "last", at::kInt);
    check(tile_work, "tile_work", at::kLong);
    const int64_t n_tiles = n_tiles_of(width, height);
    TORCH_CHECK(tile_offsets.numel() == n_tiles + 1, "tile_offsets must have ", n_tiles + 1, " entries");
    TORCH_CHECK(tile_work.numel() == n_tiles, "tile_work must have ", n_tiles, " entries");
    const int64_t n = means2d.size(0), d = colors.size(1);
    const int64_t n_isects = flatten_ids.size(0);
    auto opt = means2d.options();
    Tensor pair_grads = at::empty({n_isects, 6 + d}, opt);
    // Not zeroed: the kernel writes every entry.
    Tensor v_means2d = at::empty({n, 2}, opt), v_conics = at::empty({n, 3}, opt);
    Tensor v_opacities = at::empty({n}, opt), v_colors = at::empty({n, d}, opt);
    Tensor v_background = at::empty({d}, opt);
    AT_DISPATCH_FLOATING_TYPES(dt, "rasterize_bwd", [&] {
        eigs::rasterize_backward<scalar_t>(
            n, means2d.data_ptr<scalar_t>(), conics.data_ptr<scalar_t>(), colors.data_ptr<scalar_t>(),
            opacities.data_ptr<scalar_t>(), extents.data_ptr<scalar_t>(), background.data_ptr<scalar_t>(), d,
            width, height, tile_offsets.data_ptr<int64_t>(), flatten_ids.data_ptr<int64_t>(),
            trans.data_ptr<scalar_t>(), last.data_ptr<int32_t>(), tile_work.data_ptr<int64_t>(),
            v_image.data_ptr<scalar_t>(),
            v_alpha.data_ptr<scalar_t>(), pair_grads.data_ptr<scalar_t>(), v_means2d.data_ptr<scalar_t>(),
            v_conics.data_ptr<scalar_t>(), v_opacities.data_ptr<scalar_t>(), v_colors.data_ptr<scalar_t>(),
            v_background.data_ptr<scalar_t>(), threads(std::min(n_tiles, n_isects / 16 + 1), 1), int(isa));
    });
    return {v_means2d, v_conics, v_opacities, v_colors, v_background};
}

}  // namespace eigs::ops
