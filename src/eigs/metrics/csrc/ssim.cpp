// The SSIM map of the 3DGS lineage (separable Gaussian window, zero padding, cov_norm 1) and its gradient with
// respect to the first image, fused: one pass per axis over the five windowed moments, the map and its three partial
// derivatives in the same loop, and a backward that filters three maps instead of differentiating a graph of ~30
// whole-image tensor ops (eigs.metrics.pixel.ssim_torch, the reference this is tested against).
//
// Shapes: x, y (P, H, W) float32 contiguous, P planes (images x channels); window (11,) float32.
// Forward: map (P, H, W); with need_grad also partials (P, 3, H, W) = dS/dmu_x, dS/dE[x^2], dS/dE[xy] per pixel.
// Backward: v_x (P, H, W) = G*(v dS/dmu_x) + 2x G*(v dS/dE[x^2]) + y G*(v dS/dE[xy]), G* the same zero-padded
// separable filter with the window reversed (the transpose of the forward's correlation).
// Precision: float32 throughout, every sum in a fixed order; within 2e-6 of the float64 reference per pixel for
// images in [0, 1] (tests/metrics/test_fused_ssim.py). The row loops are compiled for AVX-512, AVX2 and the
// baseline (target_clones, picked at load); -ffp-contract=off and no reassociation keep the variants bit-identical.
#include <torch/extension.h>

#include <ATen/Parallel.h>

#include <algorithm>
#include <cmath>
#include <vector>

namespace {

constexpr int kTaps = 11;  // the 3DGS window (11 taps, sigma 1.5): fixed, so the tap loops unroll into registers
constexpr int kR = kTaps / 2;

#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define EIGS_ROW_CLONES __attribute__((target_clones("avx512f", "avx2", "default")))
#else
#define EIGS_ROW_CLONES
#endif

// Horizontal pass of one row: out_m[j] = sum_k w[k] in_m[j + k] for each map m; in_m padded by kR zeros each side.
EIGS_ROW_CLONES void filter_row(const float* const* __restrict__ in, float* const* __restrict__ out, int maps,
                                int64_t n, const float* __restrict__ w) {
    for (int m = 0; m < maps; ++m) {
        const float* __restrict__ a = in[m];
        float* __restrict__ o = out[m];
        for (int64_t j = 0; j < n; ++j) {
            float s = w[0] * a[j];
            for (int k = 1; k < kTaps; ++k) s += w[k] * a[j + k];
            o[j] = s;
        }
    }
}

// Vertical pass of one output row: out_m[j] = sum_k w[k] rows[m * kTaps + k][j], rows[m * kTaps + k] being row
// i + k - kR of map m (a zero row outside the image).
EIGS_ROW_CLONES void vertical_row(const float* const* __restrict__ rows, float* const* __restrict__ out, int maps,
                                  int64_t n, const float* __restrict__ w) {
    for (int m = 0; m < maps; ++m) {
        float* __restrict__ o = out[m];
        const float* __restrict__ r0 = rows[m * kTaps];
        for (int64_t j = 0; j < n; ++j) o[j] = w[0] * r0[j];
        for (int k = 1; k < kTaps; ++k) {
            const float wk = w[k];
            const float* __restrict__ rk = rows[m * kTaps + k];
            for (int64_t j = 0; j < n; ++j) o[j] += wk * rk[j];
        }
    }
}

// The SSIM's four factors at one pixel from its five moments: S = (A1 B1) / (A2 B2), B2 the floored B2raw.
struct Terms {
    float a1, b1, a2, b2raw, b2;
};

inline Terms ssim_terms(float mx, float my, float exx, float eyy, float exy, float c1, float c2) {
    const float vx = exx - mx * mx;
    const float vy = eyy - my * my;
    const float cv = exy - mx * my;
    const float b2raw = vx + vy + c2;
    // var_x + var_y can round to a tiny negative value; the floor keeps the denominator >= c1 c2 / 2 > 0
    const float floor = c2 / 2;
    return {2 * mx * my + c1, 2 * cv + c2, mx * mx + my * my + c1, b2raw, b2raw >= floor ? b2raw : floor};
}

// The SSIM of one row from its five moments (mom[0..4]: mu_x, mu_y, E[x^2], E[y^2], E[xy]) and, when d_mx is not
// null, its three partial derivatives.
EIGS_ROW_CLONES void ssim_row(const float* const* __restrict__ mom, int64_t n, float c1, float c2,
                              float* __restrict__ s, float* __restrict__ d_mx, float* __restrict__ d_exx,
                              float* __restrict__ d_exy) {
    const float* __restrict__ mx = mom[0];
    const float* __restrict__ my = mom[1];
    const float* __restrict__ exx = mom[2];
    const float* __restrict__ eyy = mom[3];
    const float* __restrict__ exy = mom[4];
    for (int64_t j = 0; j < n; ++j) {
        const Terms q = ssim_terms(mx[j], my[j], exx[j], eyy[j], exy[j], c1, c2);
        s[j] = (q.a1 * q.b1) / (q.a2 * q.b2);
    }
    if (d_mx == nullptr) return;
    for (int64_t j = 0; j < n; ++j) {
        const Terms q = ssim_terms(mx[j], my[j], exx[j], eyy[j], exy[j], c1, c2);
        const float open = q.b2raw >= c2 / 2 ? 1.0f : 0.0f;  // the clamp passes the gradient where it does not bind
        const float den = q.a2 * q.b2;
        const float sj = s[j];
        // D = A2 B2: dD/dmu_x = 2 mu_x B2 - 2 mu_x A2 [open], dD/dE[x^2] = A2 [open]; N = A1 B1: dN/dE[xy] = 2 A1
        d_mx[j] = (2 * my[j] * (q.b1 - q.a1) - sj * (2 * mx[j] * (q.b2 - q.a2 * open))) / den;
        d_exx[j] = -sj * (q.a2 * open) / den;
        d_exy[j] = 2 * q.a1 / den;
    }
}

// Vertical pass of one row of the backward fused with its last step: v_x = F0 + 2 x F1 + y F2, F_m the filtered maps
// (rows as in ssim_row, three maps).
EIGS_ROW_CLONES void grad_row(const float* const* __restrict__ rows, int64_t n, const float* __restrict__ w,
                              const float* __restrict__ x, const float* __restrict__ y, float* __restrict__ out) {
    for (int64_t j = 0; j < n; ++j) {
        float f[3];
        for (int m = 0; m < 3; ++m) {
            float acc = w[0] * rows[m * kTaps][j];
            for (int k = 1; k < kTaps; ++k) acc += w[k] * rows[m * kTaps + k][j];
            f[m] = acc;
        }
        out[j] = f[0] + 2 * x[j] * f[1] + y[j] * f[2];
    }
}

void check_planes(const torch::Tensor& t, const char* name) {
    TORCH_CHECK(t.dim() == 3, name, " must be (P, H, W), got ", t.sizes());
    TORCH_CHECK(t.scalar_type() == torch::kFloat32, name, " must be float32");
    TORCH_CHECK(t.device().is_cpu() && t.is_contiguous(), name, " must be a contiguous CPU tensor");
}

void check_partials(const torch::Tensor& partials, int64_t planes, int64_t h, int64_t w) {
    TORCH_CHECK(partials.dim() == 4 && partials.size(0) == planes && partials.size(1) == 3 && partials.size(2) == h &&
                    partials.size(3) == w && partials.is_contiguous() && partials.scalar_type() == torch::kFloat32,
                "partials must be (planes, 3, H, W) float32 contiguous, got ", partials.sizes());
}

std::vector<float> window_of(const torch::Tensor& window, bool reversed) {
    TORCH_CHECK(window.dim() == 1 && window.numel() == kTaps && window.scalar_type() == torch::kFloat32 &&
                    window.device().is_cpu(),
                "window must be a (", kTaps, ",) float32 CPU tensor, got ", window.sizes());
    auto w = window.contiguous();
    std::vector<float> out(w.data_ptr<float>(), w.data_ptr<float>() + kTaps);
    if (reversed) std::reverse(out.begin(), out.end());
    return out;
}

// Horizontal pass of M maps over every (plane, row): make_row(plane, row, rows) fills the M padded input rows; the
// filtered rows go to tmp (P, M, H, W).
template <int M, typename MakeRow>
void horizontal_pass(int64_t planes, int64_t h, int64_t w, const std::vector<float>& win, float* tmp,
                     MakeRow make_row) {
    const int64_t wp = w + 2 * kR;
    at::parallel_for(0, planes * h, 16, [&](int64_t begin, int64_t end) {
        std::vector<float> pad(size_t(M * wp), 0.0f);
        const float* in[M];
        float* out[M];
        float* rows[M];
        for (int m = 0; m < M; ++m) rows[m] = pad.data() + m * wp + kR;
        for (int64_t pr = begin; pr < end; ++pr) {
            const int64_t p = pr / h, i = pr % h;
            make_row(p, i, rows);
            for (int m = 0; m < M; ++m) {
                in[m] = rows[m] - kR;
                out[m] = tmp + ((p * M + m) * h + i) * w;
            }
            filter_row(in, out, M, w, win.data());
        }
    });
}

// Vertical pass over every (plane, row): row_fn(plane, row, rows) gets the M x kTaps row pointers of tmp
// (P, M, H, W) around the row, a zero row where the window leaves the image.
template <int M, typename RowFn>
void vertical_pass(int64_t planes, int64_t h, int64_t w, const float* tmp, RowFn row_fn) {
    at::parallel_for(0, planes * h, 16, [&](int64_t begin, int64_t end) {
        const std::vector<float> zeros(size_t(w), 0.0f);
        const float* rows[M * kTaps];
        for (int64_t pr = begin; pr < end; ++pr) {
            const int64_t p = pr / h, i = pr % h;
            for (int k = 0; k < kTaps; ++k) {
                const int64_t row = i + k - kR;
                for (int m = 0; m < M; ++m)
                    rows[m * kTaps + k] = (row < 0 || row >= h) ? zeros.data() : tmp + ((p * M + m) * h + row) * w;
            }
            row_fn(p, i, rows);
        }
    });
}

// The SSIM of output row i of plane p from the kTaps filtered moment rows around it (vertical_pass's rows): into s
// (w values) and, when d is not null, into that row of the partials d (P, 3, H, W).
void ssim_output_row(const float* const* rows, int64_t p, int64_t i, int64_t h, int64_t w,
                     const std::vector<float>& win, float c1, float c2, float* d, float* s) {
    thread_local std::vector<float> buf;
    buf.resize(size_t(5 * w));
    float* mom[5];
    for (int m = 0; m < 5; ++m) mom[m] = buf.data() + m * w;
    vertical_row(rows, mom, 5, w, win.data());
    float* dm = d ? d + ((p * 3 + 0) * h + i) * w : nullptr;
    float* dxx = d ? d + ((p * 3 + 1) * h + i) * w : nullptr;
    float* dxy = d ? d + ((p * 3 + 2) * h + i) * w : nullptr;
    ssim_row(mom, w, c1, c2, s, dm, dxx, dxy);
}

std::vector<torch::Tensor> ssim_map_fwd(const torch::Tensor& x, const torch::Tensor& y, const torch::Tensor& window,
                                        double c1, double c2, bool need_grad) {
    check_planes(x, "x");
    check_planes(y, "y");
    TORCH_CHECK(x.sizes() == y.sizes(), "x and y differ: ", x.sizes(), " vs ", y.sizes());
    TORCH_CHECK(c1 > 0 && c2 > 0, "c1 and c2 must be > 0");
    const auto win = window_of(window, false);
    const int64_t planes = x.size(0), h = x.size(1), w = x.size(2);
    auto smap = torch::empty_like(x);
    auto partials = need_grad ? torch::empty({planes, 3, h, w}, x.options()) : torch::empty({0}, x.options());
    if (x.numel() == 0) return {smap, partials};
    auto tmp = torch::empty({planes, 5, h, w}, x.options());
    const float* xs = x.data_ptr<float>();
    const float* ys = y.data_ptr<float>();
    horizontal_pass<5>(planes, h, w, win, tmp.data_ptr<float>(), [&](int64_t p, int64_t i, float** rows) {
        const float* xr = xs + (p * h + i) * w;
        const float* yr = ys + (p * h + i) * w;
        for (int64_t j = 0; j < w; ++j) {
            rows[0][j] = xr[j];
            rows[1][j] = yr[j];
            rows[2][j] = xr[j] * xr[j];
            rows[3][j] = yr[j] * yr[j];
            rows[4][j] = xr[j] * yr[j];
        }
    });
    float* s = smap.data_ptr<float>();
    float* d = need_grad ? partials.data_ptr<float>() : nullptr;
    const float fc1 = float(c1), fc2 = float(c2);
    vertical_pass<5>(planes, h, w, tmp.data_ptr<float>(), [&](int64_t p, int64_t i, const float* const* rows) {
        ssim_output_row(rows, p, i, h, w, win, fc1, fc2, d, s + (p * h + i) * w);
    });
    return {smap, partials};
}

torch::Tensor ssim_map_bwd(const torch::Tensor& v_map, const torch::Tensor& x, const torch::Tensor& y,
                           const torch::Tensor& partials, const torch::Tensor& window) {
    check_planes(v_map, "v_map");
    check_planes(x, "x");
    check_planes(y, "y");
    const int64_t planes = x.size(0), h = x.size(1), w = x.size(2);
    TORCH_CHECK(v_map.sizes() == x.sizes() && y.sizes() == x.sizes(), "v_map, x and y must have one shape");
    check_partials(partials, planes, h, w);
    const auto win = window_of(window, true);
    auto v_x = torch::empty_like(x);
    if (x.numel() == 0) return v_x;
    auto tmp = torch::empty({planes, 3, h, w}, x.options());
    const float* vs = v_map.data_ptr<float>();
    const float* ds = partials.data_ptr<float>();
    horizontal_pass<3>(planes, h, w, win, tmp.data_ptr<float>(), [&](int64_t p, int64_t i, float** rows) {
        const float* vr = vs + (p * h + i) * w;
        for (int m = 0; m < 3; ++m) {
            const float* dr = ds + ((p * 3 + m) * h + i) * w;
            for (int64_t j = 0; j < w; ++j) rows[m][j] = vr[j] * dr[j];
        }
    });
    const float* xs = x.data_ptr<float>();
    const float* ys = y.data_ptr<float>();
    float* out = v_x.data_ptr<float>();
    vertical_pass<3>(planes, h, w, tmp.data_ptr<float>(), [&](int64_t p, int64_t i, const float* const* rows) {
        const int64_t o = (p * h + i) * w;
        grad_row(rows, w, win.data(), xs + o, ys + o, out + o);
    });
    return v_x;
}

// The photometric loss's two means over channels-last images, fused (eigs.losses.photometric): x, y (K, H, W, C)
// float32 contiguous, plane p = k C + c. Forward: the sums of |x - y| and of the SSIM map (each in double, per-row
// partial sums added in a fixed order) and, with need_grad, the partials (P, 3, H, W) as ssim_map_fwd makes them.
// Backward, for upstream gradients g_l1 and g_ssim of the two means over n = K H W C values: v_x (K, H, W, C) =
// (g_l1 / n) sgn(x - y) + the SSIM map's gradient for the cotangent g_ssim / n at every pixel (ssim_map_bwd's), the
// same float32 operations as the autograd graph of mean(|x - y|) and mean(ssim map) with the kernels above.
struct ChannelsLast {
    int64_t k, h, w, c;
    int64_t base(int64_t p, int64_t i) const { return ((p / c * h + i) * w) * c + p % c; }  // (plane, row) -> x[.., 0]
};

ChannelsLast check_channels_last(const torch::Tensor& t, const char* name) {
    TORCH_CHECK(t.dim() == 4, name, " must be (K, H, W, C), got ", t.sizes());
    TORCH_CHECK(t.scalar_type() == torch::kFloat32, name, " must be float32");
    TORCH_CHECK(t.device().is_cpu() && t.is_contiguous(), name, " must be a contiguous CPU tensor");
    return {t.size(0), t.size(1), t.size(2), t.size(3)};
}

std::vector<torch::Tensor> l1_ssim_fwd(const torch::Tensor& x, const torch::Tensor& y, const torch::Tensor& window,
                                       double c1, double c2, bool need_grad) {
    const ChannelsLast L = check_channels_last(x, "x");
    check_channels_last(y, "y");
    TORCH_CHECK(x.sizes() == y.sizes(), "x and y differ: ", x.sizes(), " vs ", y.sizes());
    TORCH_CHECK(c1 > 0 && c2 > 0, "c1 and c2 must be > 0");
    const auto win = window_of(window, false);
    const int64_t planes = L.k * L.c, h = L.h, w = L.w;
    auto sums = torch::zeros({2}, x.options().dtype(torch::kFloat64));
    auto partials = need_grad ? torch::empty({planes, 3, h, w}, x.options()) : torch::empty({0}, x.options());
    if (x.numel() == 0) return {sums, partials};
    std::vector<double> l1_rows(size_t(planes * h)), s_rows(size_t(planes * h));
    auto tmp = torch::empty({planes, 5, h, w}, x.options());
    const float* xs = x.data_ptr<float>();
    const float* ys = y.data_ptr<float>();
    horizontal_pass<5>(planes, h, w, win, tmp.data_ptr<float>(), [&](int64_t p, int64_t i, float** rows) {
        const float* xr = xs + L.base(p, i);
        const float* yr = ys + L.base(p, i);
        double l1 = 0.0;
        for (int64_t j = 0; j < w; ++j) {
            const float a = xr[j * L.c], b = yr[j * L.c];
            rows[0][j] = a;
            rows[1][j] = b;
            rows[2][j] = a * a;
            rows[3][j] = b * b;
            rows[4][j] = a * b;
            l1 += double(std::fabs(a - b));
        }
        l1_rows[size_t(p * h + i)] = l1;
    });
    float* d = need_grad ? partials.data_ptr<float>() : nullptr;
    const float fc1 = float(c1), fc2 = float(c2);
    vertical_pass<5>(planes, h, w, tmp.data_ptr<float>(), [&](int64_t p, int64_t i, const float* const* rows) {
        thread_local std::vector<float> row;
        row.resize(size_t(w));
        float* srow = row.data();
        ssim_output_row(rows, p, i, h, w, win, fc1, fc2, d, srow);
        double acc = 0.0;
        for (int64_t j = 0; j < w; ++j) acc += double(srow[j]);
        s_rows[size_t(p * h + i)] = acc;
    });
    double l1 = 0.0, s = 0.0;
    for (size_t r = 0; r < l1_rows.size(); ++r) {
        l1 += l1_rows[r];
        s += s_rows[r];
    }
    auto acc = sums.accessor<double, 1>();
    acc[0] = l1;
    acc[1] = s;
    return {sums, partials};
}

torch::Tensor l1_ssim_bwd(const torch::Tensor& x, const torch::Tensor& y, const torch::Tensor& partials,
                          const torch::Tensor& window, double g_l1, double g_ssim) {
    const ChannelsLast L = check_channels_last(x, "x");
    check_channels_last(y, "y");
    TORCH_CHECK(x.sizes() == y.sizes(), "x and y differ: ", x.sizes(), " vs ", y.sizes());
    const int64_t planes = L.k * L.c, h = L.h, w = L.w;
    check_partials(partials, planes, h, w);
    const auto win = window_of(window, true);
    auto v_x = torch::empty_like(x);
    if (x.numel() == 0) return v_x;
    // the per-value cotangents of the two means, as autograd's mean backward makes them: float32 g / float32(n)
    const float n = float(x.numel());
    const float v_l1 = float(g_l1) / n, v_s = float(g_ssim) / n;
    auto tmp = torch::empty({planes, 3, h, w}, x.options());
    const float* ds = partials.data_ptr<float>();
    horizontal_pass<3>(planes, h, w, win, tmp.data_ptr<float>(), [&](int64_t p, int64_t i, float** rows) {
        for (int m = 0; m < 3; ++m) {
            const float* dr = ds + ((p * 3 + m) * h + i) * w;
            for (int64_t j = 0; j < w; ++j) rows[m][j] = v_s * dr[j];
        }
    });
    const float* xs = x.data_ptr<float>();
    const float* ys = y.data_ptr<float>();
    float* out = v_x.data_ptr<float>();
    vertical_pass<3>(planes, h, w, tmp.data_ptr<float>(), [&](int64_t p, int64_t i, const float* const* rows) {
        thread_local std::vector<float> buf;
        buf.resize(size_t(3 * w));
        float *xr = buf.data(), *yr = buf.data() + w, *g = buf.data() + 2 * w;
        const int64_t o = L.base(p, i);
        for (int64_t j = 0; j < w; ++j) {
            xr[j] = xs[o + j * L.c];
            yr[j] = ys[o + j * L.c];
        }
        grad_row(rows, w, win.data(), xr, yr, g);
        for (int64_t j = 0; j < w; ++j) {
            const float diff = xr[j] - yr[j];
            const float sgn = diff > 0.0f ? 1.0f : diff < 0.0f ? -1.0f : 0.0f;  // as torch.sgn: +0 for ±0 and NaN
            out[o + j * L.c] = v_l1 * sgn + g[j];
        }
    });
    return v_x;
}

}  // namespace

PYBIND11_MODULE(TORCH_EXTENSION_NAME, m) {
    m.def("ssim_map_fwd", &ssim_map_fwd, "SSIM map (P, H, W) and, with need_grad, its partials (P, 3, H, W)");
    m.def("ssim_map_bwd", &ssim_map_bwd, "gradient of the SSIM map with respect to x, (P, H, W)");
    m.def("l1_ssim_fwd", &l1_ssim_fwd, "sums of |x - y| and of the SSIM map of (K, H, W, C) images, and the partials");
    m.def("l1_ssim_bwd", &l1_ssim_bwd, "gradient of mean |x - y| and mean SSIM with respect to x, (K, H, W, C)");
}
