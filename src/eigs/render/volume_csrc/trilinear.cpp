// Trilinear interpolation of a voxel grid at normalised points, and its backward: what
// torch.nn.functional.grid_sample(grid, 2u - 1, mode="bilinear", padding_mode="border", align_corners=True) computes
// for a (1, C, D, H, W) grid and points (N, 3) in [0, 1] (x along W, y along H, z along D), the reference this is
// tested against (tests/render/test_trilinear.py). PyTorch's CPU backward of grid_sample takes ~180 ns per 3-D point
// and four channels; this one scatters each point's eight corners into a per-thread copy of the gradient grid and sums
// the copies, and computes the points' gradient only when asked. The grid is taken channels-last, so a corner's channels
// share a cache line.
//
// Shapes: grid (D, H, W, C) float32 contiguous (channels last); u (N, 3) float32 contiguous; out (N, C); v_out (N, C).
// Coordinates: p = u (size - 1), clamped to [0, size - 1] (border padding); the gradient with respect to a
// coordinate is zero where p <= 0 or p >= size - 1, as grid_sample's border padding sets it.
// Precision: float32, the eight corner products summed in a fixed order; the grid gradient summed per slice of the
// points (one per thread, at most 256 MB of gradient grids) and then over the slices, so it depends on the slice
// count at the float32 rounding level and not on the scheduling.
#include <torch/extension.h>

#include <ATen/Parallel.h>

#include <algorithm>
#include <cmath>
#include <vector>

namespace {

constexpr int64_t kScratchBytes = int64_t(256) << 20;  // the backward's per-slice gradient grids, at most

struct Corner {
    int64_t i0, i1;  // the two neighbours along the axis
    float f;         // weight of i1 (1 - f of i0)
    float inside;    // 1 where the coordinate's gradient passes (0 < p < size - 1), else 0
};

inline Corner axis(float u, int64_t size) {
    const float hi = float(size - 1);
    float p = u * hi;
    const float inside = (p > 0.0f && p < hi) ? 1.0f : 0.0f;
    p = std::min(std::max(p, 0.0f), hi);  // border padding (also maps NaN to 0)
    const int64_t i0 = std::min(int64_t(std::floor(p)), size - 1);
    const int64_t i1 = std::min(i0 + 1, size - 1);
    return {i0, i1, p - float(i0), inside};
}

// The eight corners of point i's cell (flat voxel indices, z-major) and their trilinear weights.
struct Cell {
    Corner x, y, z;
    int64_t k[8];
    float wt[8];
};

inline Cell cell_of(const float* up, int64_t i, int64_t d, int64_t h, int64_t w) {
    Cell c;
    c.x = axis(up[3 * i], w);
    c.y = axis(up[3 * i + 1], h);
    c.z = axis(up[3 * i + 2], d);
    const Corner& x = c.x;
    const Corner& y = c.y;
    const Corner& z = c.z;
    const float gx = 1.0f - x.f, gy = 1.0f - y.f, gz = 1.0f - z.f;
    int q = 0;
    for (int a = 0; a < 2; ++a)
        for (int b = 0; b < 2; ++b)
            for (int e = 0; e < 2; ++e, ++q) {
                c.k[q] = ((a ? z.i1 : z.i0) * h + (b ? y.i1 : y.i0)) * w + (e ? x.i1 : x.i0);
                c.wt[q] = (a ? z.f : gz) * (b ? y.f : gy) * (e ? x.f : gx);
            }
    return c;
}

void check(const torch::Tensor& grid, const torch::Tensor& u) {
    TORCH_CHECK(grid.dim() == 4 && grid.scalar_type() == torch::kFloat32 && grid.device().is_cpu() &&
                    grid.is_contiguous(),
                "grid must be a contiguous (D, H, W, C) float32 CPU tensor, got ", grid.sizes());
    TORCH_CHECK(u.dim() == 2 && u.size(1) == 3 && u.scalar_type() == torch::kFloat32 && u.device().is_cpu() &&
                    u.is_contiguous(),
                "u must be a contiguous (N, 3) float32 CPU tensor, got ", u.sizes());
    TORCH_CHECK(grid.numel() > 0, "grid must not be empty");
}

// -> (N, channels): the first `channels` channels of the grid (all when channels < 0) at the points
torch::Tensor trilinear_fwd(const torch::Tensor& grid, const torch::Tensor& u, int64_t channels) {
    check(grid, u);
    const int64_t d = grid.size(0), h = grid.size(1), w = grid.size(2), c = grid.size(3), n = u.size(0);
    const int64_t k = channels < 0 ? c : channels;
    TORCH_CHECK(k >= 1 && k <= c, "channels must lie in [1, ", c, "], got ", channels);
    auto out = torch::empty({n, k}, grid.options());
    const float* g = grid.data_ptr<float>();
    const float* up = u.data_ptr<float>();
    float* o = out.data_ptr<float>();
    at::parallel_for(0, n, 2048, [&](int64_t begin, int64_t end) {
        for (int64_t i = begin; i < end; ++i) {
            const Cell cl = cell_of(up, i, d, h, w);
            for (int64_t ch = 0; ch < k; ++ch) {
                float s = 0.0f;
                for (int q = 0; q < 8; ++q) s += cl.wt[q] * g[cl.k[q] * c + ch];
                o[i * k + ch] = s;
            }
        }
    });
    return out;
}

// -> v_grid (D, H, W, C) (empty when not need_grid), v_u (N, 3) (empty when not need_u)
std::vector<torch::Tensor> trilinear_bwd(const torch::Tensor& grid, const torch::Tensor& u,
                                         const torch::Tensor& v_out, bool need_grid, bool need_u) {
    check(grid, u);
    const int64_t d = grid.size(0), h = grid.size(1), w = grid.size(2), c = grid.size(3), n = u.size(0);
    TORCH_CHECK(v_out.dim() == 2 && v_out.size(0) == n && v_out.size(1) == c && v_out.is_contiguous() &&
                    v_out.scalar_type() == torch::kFloat32,
                "v_out must be a contiguous (N, C) float32 tensor");
    const float* g = grid.data_ptr<float>();
    const float* up = u.data_ptr<float>();
    const float* vo = v_out.data_ptr<float>();
    auto v_u = need_u ? torch::zeros({n, 3}, u.options()) : torch::empty({0}, u.options());
    float* vu = need_u ? v_u.data_ptr<float>() : nullptr;
    // The points split into `slices` contiguous ranges, one task each; with need_grid each slice scatters into its own
    // gradient grid (slice 0's is the output) and the grids are summed at the end. At most one slice per thread, and
    // no more than kScratchBytes of grids: the sum does not depend on the scheduling, only on the slice count.
    const int64_t grid_bytes = grid.numel() * int64_t(sizeof(float));
    int64_t slices = std::max<int64_t>(1, std::min<int64_t>(at::get_num_threads(), (n + 2047) / 2048));
    if (need_grid) slices = std::max<int64_t>(1, std::min(slices, kScratchBytes / std::max<int64_t>(grid_bytes, 1)));
    std::vector<torch::Tensor> parts;
    if (need_grid)
        for (int64_t s = 0; s < slices; ++s) parts.push_back(torch::zeros({d, h, w, c}, grid.options()));
    const float sx = float(w - 1), sy = float(h - 1), sz = float(d - 1);
    at::parallel_for(0, slices, 1, [&](int64_t s_begin, int64_t s_end) {
        for (int64_t s = s_begin; s < s_end; ++s) {
            float* vg = need_grid ? parts[size_t(s)].data_ptr<float>() : nullptr;
            for (int64_t i = n * s / slices; i < n * (s + 1) / slices; ++i) {
                const Cell cl = cell_of(up, i, d, h, w);
                const Corner &x = cl.x, &y = cl.y, &z = cl.z;
                const int64_t* k = cl.k;
                const float gx = 1.0f - x.f, gy = 1.0f - y.f, gz = 1.0f - z.f;
                if (vg != nullptr) {
                    for (int q = 0; q < 8; ++q) {
                        float* vgk = vg + k[q] * c;
                        for (int64_t ch = 0; ch < c; ++ch) vgk[ch] += cl.wt[q] * vo[i * c + ch];
                    }
                }
                if (vu != nullptr) {
                    float dx = 0.0f, dy = 0.0f, dz = 0.0f;
                    for (int64_t ch = 0; ch < c; ++ch) {
                        const float v = vo[i * c + ch];
                        const float c000 = g[k[0] * c + ch], c001 = g[k[1] * c + ch], c010 = g[k[2] * c + ch];
                        const float c011 = g[k[3] * c + ch], c100 = g[k[4] * c + ch], c101 = g[k[5] * c + ch];
                        const float c110 = g[k[6] * c + ch], c111 = g[k[7] * c + ch];
                        dx += v * (gz * (gy * (c001 - c000) + y.f * (c011 - c010)) +
                                   z.f * (gy * (c101 - c100) + y.f * (c111 - c110)));
                        dy += v * (gz * (gx * (c010 - c000) + x.f * (c011 - c001)) +
                                   z.f * (gx * (c110 - c100) + x.f * (c111 - c101)));
                        dz += v * (gy * (gx * (c100 - c000) + x.f * (c101 - c001)) +
                                   y.f * (gx * (c110 - c010) + x.f * (c111 - c011)));
                    }
                    vu[3 * i] = dx * sx * x.inside;
                    vu[3 * i + 1] = dy * sy * y.inside;
                    vu[3 * i + 2] = dz * sz * z.inside;
                }
            }
        }
    });
    torch::Tensor v_grid = torch::empty({0}, grid.options());
    if (need_grid) {
        v_grid = parts[0];
        for (int64_t s = 1; s < slices; ++s) v_grid.add_(parts[size_t(s)]);
    }
    return {v_grid, v_u};
}

}  // namespace

PYBIND11_MODULE(TORCH_EXTENSION_NAME, m) {
    using release = py::call_guard<py::gil_scoped_release>;
    m.def("trilinear_fwd", &trilinear_fwd, release(),
          "grid (D, H, W, C), u (N, 3) in [0, 1], channels (the first ones; -1: all) -> (N, channels)");
    m.def("trilinear_bwd", &trilinear_bwd, release(), "-> v_grid (D, H, W, C), v_u (N, 3)");
}
