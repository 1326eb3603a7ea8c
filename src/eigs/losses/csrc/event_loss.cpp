// The event-integration loss (Eq. 9-10) over consecutive log-intensity renders, fused: for the L renders' logs of one
// view and its cumulative counts, the mean over the K = L - 1 intervals and the kept pixels of
// |(l_{k+1} - l_k) / C - E_k|, C = C+ where the log rose (>= 0), else C-, E_k = cum_{k+1} - cum_k. What
// eigs.losses.events.event_integration_loss computes (without its dead zone) from the stack's slices, as one pass
// forward and one backward instead of ~20 whole-image tensor ops; the backward is the same float32 operations as
// that graph's autograd (g / n, times the kept mask, times sgn, divided by C, + to l_{k+1} and - to l_k, the two
// slices' gradients added with zeros at the ends), tested bit for bit.
//
// Shapes: logs (L, H, W) float32 contiguous; cum (L, H, W) int32 contiguous; c_pos, c_neg (H, W) float32 maps;
// keep (H, W) bool (the pixels whose events count; all true without a mask).
// Forward: {sum of the terms (float64, per-pixel-row partial sums in a fixed order), n} with n the number of terms
// averaged (K times the kept pixels). Backward: v_logs (L, H, W) for the upstream gradient g of the mean sum / n.
#include <torch/extension.h>

#include <ATen/Parallel.h>

#include <cmath>
#include <vector>

namespace {

#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define EIGS_ROW_CLONES __attribute__((target_clones("avx512f", "avx2", "default")))
#else
#define EIGS_ROW_CLONES
#endif

constexpr int64_t kChunk = 4096;  // pixels per task
constexpr int kSumLanes = 8;      // independent float64 partial sums (one serial chain is latency-bound)

struct Inputs {
    const float* logs;
    const int32_t* cum;
    const float *cp, *cn;  // (H, W)
    const bool* keep;      // (H, W)
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
        TORCH_CHECK(c->scalar_type() == torch::kFloat32 && c->is_contiguous() && c->numel() == hw,
                    "thresholds must be (H, W) float32 maps");
    TORCH_CHECK(keep.scalar_type() == torch::kBool && keep.numel() == hw && keep.is_contiguous(),
                "keep must be an (H, W) bool tensor");
    return {logs.data_ptr<float>(), cum.data_ptr<int32_t>(), c_pos.data_ptr<float>(), c_neg.data_ptr<float>(),
            keep.data_ptr<bool>(), logs.size(0), hw};
}

// The terms of one interval over n pixels: out[p] = |(lb - la) / C - (cb - ca)| times the kept mask (1 or 0; a NaN
// term stays NaN, as the tensor ops' product). Branch-free, so that it vectorises.
EIGS_ROW_CLONES void terms_row(const float* __restrict__ la, const float* __restrict__ lb,
                               const int32_t* __restrict__ ca, const int32_t* __restrict__ cb,
                               const float* __restrict__ cp, const float* __restrict__ cn,
                               const bool* __restrict__ keep, int64_t n, float* __restrict__ out) {
    for (int64_t p = 0; p < n; ++p) {
        const float diff = lb[p] - la[p];
        const float c_up = cp[p], c_down = cn[p];  // both loaded: the select then vectorises
        const float c = diff >= 0.0f ? c_up : c_down;
        const float r = diff / c - float(cb[p] - ca[p]);
        out[p] = std::fabs(r) * float(keep[p]);
    }
}

// The gradient at the interval's end over n pixels, autograd's operations in its order: ((g k) sgn(r)) / C, k the
// kept mask as 1 or 0 (all 1 without a mask: g 1 = g), sgn as torch.sgn (+0 for 0 and NaN).
EIGS_ROW_CLONES void grad_end_row(const float* __restrict__ la, const float* __restrict__ lb,
                                  const int32_t* __restrict__ ca, const int32_t* __restrict__ cb,
                                  const float* __restrict__ cp, const float* __restrict__ cn,
                                  const bool* __restrict__ keep, float g, int64_t n, float* __restrict__ out) {
    for (int64_t p = 0; p < n; ++p) {
        const float diff = lb[p] - la[p];
        const float c_up = cp[p], c_down = cn[p];  // both loaded: the select then vectorises
        const float c = diff >= 0.0f ? c_up : c_down;
        const float r = diff / c - float(cb[p] - ca[p]);
        const float sgn = r > 0.0f ? 1.0f : (r < 0.0f ? -1.0f : 0.0f);
        out[p] = ((g * float(keep[p])) * sgn) / c;
    }
}

// v_l at one render's pixels: the gradient from the interval it ends plus minus the one from the interval it starts,
// a zero (+0) where there is none (the first and last render), as the two slices' gradients are added.
EIGS_ROW_CLONES void combine_row(const float* __restrict__ end_prev, const float* __restrict__ end_this, int64_t n,
                                 float* __restrict__ out) {
    if (end_prev == nullptr) {
        for (int64_t p = 0; p < n; ++p) out[p] = 0.0f + -end_this[p];
    } else if (end_this == nullptr) {
        for (int64_t p = 0; p < n; ++p) out[p] = end_prev[p] + 0.0f;
    } else {
        for (int64_t p = 0; p < n; ++p) out[p] = end_prev[p] + -end_this[p];
    }
}

std::vector<torch::Tensor> event_loss_fwd(const torch::Tensor& logs, const torch::Tensor& cum,
                                          const torch::Tensor& c_pos, const torch::Tensor& c_neg,
                                          const torch::Tensor& keep) {
    const Inputs in = check(logs, cum, c_pos, c_neg, keep);
    const int64_t K = in.L - 1, chunks = (in.HW + kChunk - 1) / kChunk;
    std::vector<double> sums(size_t(K * chunks), 0.0);
    at::parallel_for(0, K * chunks, 1, [&](int64_t begin, int64_t end) {
        std::vector<float> terms(static_cast<size_t>(kChunk));
        for (int64_t t = begin; t < end; ++t) {
            const int64_t k = t / chunks, p0 = (t % chunks) * kChunk, n = std::min(in.HW, p0 + kChunk) - p0;
            const int64_t a = k * in.HW + p0, b = a + in.HW;
            terms_row(in.logs + a, in.logs + b, in.cum + a, in.cum + b, in.cp + p0, in.cn + p0, in.keep + p0, n,
                      terms.data());
            double lanes[kSumLanes] = {};
            const float* tp = terms.data();
            int64_t p = 0;
            for (; p + kSumLanes <= n; p += kSumLanes)
                for (int l = 0; l < kSumLanes; ++l) lanes[l] += double(tp[p + l]);
            for (; p < n; ++p) lanes[p % kSumLanes] += double(tp[p]);
            double s = 0.0;
            for (int l = 0; l < kSumLanes; ++l) s += lanes[l];
            sums[size_t(t)] = s;
        }
    });
    double total = 0.0;
    for (const double s : sums) total += s;
    int64_t kept = 0;
    for (int64_t p = 0; p < in.HW; ++p) kept += in.keep[p] ? 1 : 0;
    auto out = torch::empty({2}, logs.options().dtype(torch::kFloat64));
    auto acc = out.accessor<double, 1>();
    acc[0] = total;
    acc[1] = double(kept * K);
    return {out};
}

torch::Tensor event_loss_bwd(const torch::Tensor& logs, const torch::Tensor& cum, const torch::Tensor& c_pos,
                             const torch::Tensor& c_neg, const torch::Tensor& keep, double g, int64_t n) {
    const Inputs in = check(logs, cum, c_pos, c_neg, keep);
    const int64_t K = in.L - 1, chunks = (in.HW + kChunk - 1) / kChunk;
    auto v_logs = torch::empty_like(logs);
    auto ends = torch::empty({K, in.HW}, logs.options());  // the gradient at each interval's end
    float* out = v_logs.data_ptr<float>();
    float* e = ends.data_ptr<float>();
    const float gs = float(g) / float(n < 1 ? 1 : n);  // the mean's backward: g / n in float32, as autograd's
    at::parallel_for(0, K * chunks, 1, [&](int64_t begin, int64_t end) {
        for (int64_t t = begin; t < end; ++t) {
            const int64_t k = t / chunks, p0 = (t % chunks) * kChunk, m = std::min(in.HW, p0 + kChunk) - p0;
            const int64_t a = k * in.HW + p0, b = a + in.HW;
            grad_end_row(in.logs + a, in.logs + b, in.cum + a, in.cum + b, in.cp + p0, in.cn + p0, in.keep + p0, gs,
                         m, e + a);
        }
    });
    at::parallel_for(0, in.L * chunks, 1, [&](int64_t begin, int64_t end) {
        for (int64_t t = begin; t < end; ++t) {
            const int64_t k = t / chunks, p0 = (t % chunks) * kChunk, m = std::min(in.HW, p0 + kChunk) - p0;
            combine_row(k >= 1 ? e + (k - 1) * in.HW + p0 : nullptr, k < K ? e + k * in.HW + p0 : nullptr, m,
                        out + k * in.HW + p0);
        }
    });
    return v_logs;
}

}  // namespace

PYBIND11_MODULE(TORCH_EXTENSION_NAME, m) {
    m.def("event_loss_fwd", &event_loss_fwd, "sum and count of the event-integration terms of a view's renders");
    m.def("event_loss_bwd", &event_loss_bwd, "gradient of their mean with respect to the logs, (L, H, W)");
}
