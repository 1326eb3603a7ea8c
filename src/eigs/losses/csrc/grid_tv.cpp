// The gradient of a voxel grid's total variation (mean squared differences of neighbouring voxels, per channel
// group), added in place in one pass over a channels-last grid. Each entry gets the float32 operations of
// eigs.train.field.factors.tv_grad_channels_last_, the tensor-op reference, in its order: along each spatial axis
// in turn, + (x[i] - x[i-1]) * twice then - (x[i+1] - x[i]) * twice, where twice = 2 * scale is the channel's float32
// factor for that axis (tests/train/test_field_model.py checks the gradient bit for bit). The value (for the log) is
// summed in float64, so it differs from the reference's float32 dot product at float32 rounding.
//
// Shapes: x, gx (Z, Y, X, C) float32 contiguous; twice (3, C) float32 (axis z, y, x; a channel whose factors are all
// zero and which is not `live` is left untouched); live (C,) uint8.
#include <torch/extension.h>

#include <ATen/Parallel.h>

#include <vector>

namespace {

double grid_tv_grad(const torch::Tensor& x, const torch::Tensor& gx, const torch::Tensor& twice,
                    const torch::Tensor& live) {
    TORCH_CHECK(x.dim() == 4 && x.scalar_type() == torch::kFloat32 && x.is_contiguous() && x.device().is_cpu(),
                "x must be a contiguous (Z, Y, X, C) float32 CPU tensor");
    TORCH_CHECK(gx.sizes() == x.sizes() && gx.scalar_type() == torch::kFloat32 && gx.is_contiguous() &&
                    gx.device().is_cpu(),
                "gx must be a contiguous float32 CPU tensor of x's shape");
    const int64_t nz = x.size(0), ny = x.size(1), nx = x.size(2), c = x.size(3);
    TORCH_CHECK(twice.dim() == 2 && twice.size(0) == 3 && twice.size(1) == c && twice.is_contiguous() &&
                    twice.scalar_type() == torch::kFloat32,
                "twice must be a contiguous (3, C) float32 tensor");
    TORCH_CHECK(live.dim() == 1 && live.size(0) == c && live.scalar_type() == torch::kUInt8 && live.is_contiguous(),
                "live must be a (C,) uint8 tensor");
    const float* xp = x.data_ptr<float>();
    float* gp = gx.data_ptr<float>();
    const float* tw = twice.data_ptr<float>();
    const uint8_t* lv = live.data_ptr<uint8_t>();
    const int64_t n[3] = {nz, ny, nx};
    const int64_t stride[3] = {ny * nx * c, nx * c, c};
    // per z slice: every entry's own gradient reads only x, so slices run in any order; the value's partial sums
    // are kept per slice and added in slice order (independent of the thread count)
    std::vector<double> part(size_t(nz), 0.0);
    at::parallel_for(0, nz, 1, [&](int64_t z0, int64_t z1) {
        for (int64_t z = z0; z < z1; ++z) {
            double acc = 0.0;
            for (int64_t y = 0; y < ny; ++y)
                for (int64_t xi = 0; xi < nx; ++xi) {
                    const int64_t idx[3] = {z, y, xi};
                    const int64_t base = ((z * ny + y) * nx + xi) * c;
                    for (int64_t ch = 0; ch < c; ++ch) {
                        if (!lv[ch]) continue;
                        const int64_t k = base + ch;
                        float g = gp[k];
                        for (int d = 0; d < 3; ++d) {
                            const float t = tw[d * c + ch];
                            if (idx[d] >= 1) {
                                const float diff = xp[k] - xp[k - stride[d]];
                                const float scaled = diff * t;
                                g = g + scaled;
                                acc += 0.5 * double(diff) * double(scaled);  // each difference counted once
                            }
                            if (idx[d] < n[d] - 1) g = g - (xp[k + stride[d]] - xp[k]) * t;
                        }
                        gp[k] = g;
                    }
                }
            part[size_t(z)] = acc;
        }
    });
    double total = 0.0;
    for (double p : part) total += p;
    return total;
}

}  // namespace

PYBIND11_MODULE(TORCH_EXTENSION_NAME, m) {
    using release = py::call_guard<py::gil_scoped_release>;
    m.def("grid_tv_grad", &grid_tv_grad, release(),
          "x, gx (Z, Y, X, C) float32, twice (3, C) float32, live (C,) uint8 -> the value; gx += the gradient");
}
