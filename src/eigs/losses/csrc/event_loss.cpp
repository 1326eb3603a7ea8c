// The event-integration loss (Eq. 9-10) over consecutive log-intensity renders, fused: for the L renders' logs of one
// view and its cumulative counts, the mean over the K = L - 1 intervals and the kept pixels of
// |(l_{k+1} - l_k) / C - E_k|, C = C+ where the log rose (>= 0), else C-, E_k = cum_{k+1} - cum_k. What
// eigs.losses.events.event_integration_loss computes (without its dead zone) from the stack's slices, as one pass
// forward and one backward instead of ~20 whole-image tensor ops; the backward is the same float32 operations as
// that graph's autograd (g / n, times the kept mask, times sgn, divided by C, + to l_{k+1} and - to l_k, the two
// slices' gradients added with zeros at the ends), tested bit for bit.
//
// Shapes: logs (L, H, W) float32 contiguous; cum (L, H, W) int32 contiguous; c_pos, c_neg (H, W) float32 maps or
// one-element tensors; keep (H, W) bool (the pixels whose events count) or an empty tensor (every pixel).
// Forward: {sum of the terms (float64, per-pixel-row partial sums in a fixed order), n} with n the number of terms
// averaged (K times the kept pixels). Backward: v_logs (L, H, W) for the upstream gradient g of the mean sum / n.
#include <torch/extension.h>

#include <ATen/Parallel.h>

#include <cmath>
#include <vector>

namespace {

struct Inputs {
    const float* logs;
    const int32_t* cum;
    const float *cp, *cn;  // per pixel, or one value (stride 0)
    int64_t cstride;
    const bool* keep;  // nullptr: every pixel
    int64_t L, HW;
};

Inputs check(const torch::Tensor& logs, const torch::Tensor& cum, const torch::Tensor& c_pos,
             const torch::Tensor& c_neg, const torch::Tensor& keep) {
    TORCH_CHECK(logs.dim() == 3 && logs.scalar_type() == torch::kFloat32 && logs.is_contiguous() && logs.device().is_cpu(),
                "logs must be a contiguous (L, H, W) float32 CPU tensor, got ", logs.sizes());
    TORCH_CHECK(logs.size(0) >= 2, "logs need at least two renders, got ", logs.size(0));
    TORCH_CHECK(cum.sizes() == logs.sizes() && cum.scalar_type() == torch::kInt32 && cum.is_contiguous(),
                "cum must be a contiguous int32 tensor shaped as logs, got ", cum.sizes());
    const int64_t hw = logs.size(1) * logs.size(2);
    for (const auto* c : {&c_pos, &c_neg})
        TORCH_CHECK(c->scalar_type() == torch::kFloat32 && c->is_contiguous() && (c->numel() == 1 || c->numel() == hw),
                    "thresholds must be float32, one value or one per pixel");
    TORCH_CHECK(c_pos.numel() == c_neg.numel(), "c_pos and c_neg must both be maps or both one value");
    TORCH_CHECK(keep.numel() == 0 || (keep.scalar_type() == torch::kBool && keep.numel() == hw && keep.is_contiguous()),
                "keep must be an (H, W) bool tensor or empty");
    return {logs.data_ptr<float>(), cum.data_ptr<int32_t>(), c_pos.data_ptr<float>(), c_neg.data_ptr<float>(),
            c_pos.numel() == 1 ? 0 : 1, keep.numel() ? keep.data_ptr<bool>() : nullptr, logs.size(0), hw};
}

// One interval's term at pixel p: r = (l_b - l_a) / C - E, and the C it used.
inline float residual(const Inputs& in, int64_t k, int64_t p, float& c) {
    const float diff = in.logs[(k + 1) * in.HW + p] - in.logs[k * in.HW + p];
    c = diff >= 0.0f ? in.cp[p * in.cstride] : in.cn[p * in.cstride];
    const float e = float(in.cum[(k + 1) * in.HW + p] - in.cum[k * in.HW + p]);
    return diff / c - e;
}

std::vector<torch::Tensor> event_loss_fwd(const torch::Tensor& logs, const torch::Tensor& cum,
                                          const torch::Tensor& c_pos, const torch::Tensor& c_neg,
                                          const torch::Tensor& keep) {
    const Inputs in = check(logs, cum, c_pos, c_neg, keep);
    const int64_t K = in.L - 1, chunk = 4096, chunks = (in.HW + chunk - 1) / chunk;
    std::vector<double> sums(size_t(K * chunks), 0.0);
    std::vector<int64_t> kept(size_t(chunks), 0);
    at::parallel_for(0, K * chunks, 1, [&](int64_t begin, int64_t end) {
        for (int64_t t = begin; t < end; ++t) {
            const int64_t k = t / chunks, p0 = (t % chunks) * chunk, p1 = std::min(in.HW, p0 + chunk);
            double s = 0.0;
            int64_t n = 0;
            for (int64_t p = p0; p < p1; ++p) {
                if (in.keep && !in.keep[p]) continue;
                float c;
                s += double(std::fabs(residual(in, k, p, c)));
                ++n;
            }
            sums[size_t(t)] = s;
            if (k == 0) kept[size_t(t % chunks)] = n;
        }
    });
    double total = 0.0;
    for (const double s : sums) total += s;
    int64_t n = 0;
    for (const int64_t c : kept) n += c;
    auto out = torch::empty({2}, logs.options().dtype(torch::kFloat64));
    auto acc = out.accessor<double, 1>();
    acc[0] = total;
    acc[1] = double(n * K);
    return {out};
}

torch::Tensor event_loss_bwd(const torch::Tensor& logs, const torch::Tensor& cum, const torch::Tensor& c_pos,
                             const torch::Tensor& c_neg, const torch::Tensor& keep, double g, int64_t n) {
    const Inputs in = check(logs, cum, c_pos, c_neg, keep);
    const int64_t K = in.L - 1;
    auto v_logs = torch::empty_like(logs);
    float* out = v_logs.data_ptr<float>();
    const float gs = float(g) / float(n < 1 ? 1 : n);  // the mean's backward: g / n in float32, as autograd's
    at::parallel_for(0, in.HW, 2048, [&](int64_t p0, int64_t p1) {
        for (int64_t p = p0; p < p1; ++p) {
            const float gk = in.keep ? gs * (in.keep[p] ? 1.0f : 0.0f) : gs;  // times the kept mask
            float from_b = 0.0f;  // the gradient at l_k from interval k - 1 (where l_k is its end)
            for (int64_t k = 0; k <= K; ++k) {
                float from_a = 0.0f;  // from interval k (where l_k is its start)
                float grad_b = 0.0f;
                if (k < K) {
                    float c;
                    const float r = residual(in, k, p, c);
                    const float sgn = r > 0.0f ? 1.0f : r < 0.0f ? -1.0f : 0.0f;  // as torch.sgn (+0 for 0 and NaN)
                    grad_b = (gk * sgn) / c;
                    from_a = -grad_b;
                }
                out[k * in.HW + p] = from_b + from_a;
                from_b = grad_b;
            }
        }
    });
    return v_logs;
}

}  // namespace

PYBIND11_MODULE(TORCH_EXTENSION_NAME, m) {
    m.def("event_loss_fwd", &event_loss_fwd, "sum and count of the event-integration terms of a view's renders");
    m.def("event_loss_bwd", &event_loss_bwd, "gradient of their mean with respect to the logs, (L, H, W)");
}
