// Timing harness of bench/kernel_phases.py: the backward compositing kernel of namespace `eigs` (a variant with
// phases removed) against the whole kernel of namespace `eigs_old`, interleaved round by round on one scene of the
// benchmark distribution (bench/rasterizer.py's make_scene, drawn here with its own generator), 1 thread.
// Prints one line: n_isects, then the minimum CPU ns per pair-lane of the forward, the whole kernel and the
// variant, then the median over the rounds of (variant / whole kernel).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <vector>

#include <time.h>

#include "kernels.h"

namespace eigs_old {
template <typename S>
void rasterize_backward(int64_t, const S*, const S*, const S*, const S*, const S*, const S*, int64_t, int64_t,
                        int64_t, const int64_t*, const int64_t*, const S*, const int32_t*, const int64_t*, const S*,
                        const S*, S*, S*, S*, S*, S*, S*, int, int);
}

static double cpu_now() {
    timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

int main(int argc, char** argv) {
    const int size = argc > 1 ? atoi(argv[1]) : 256;
    const int n = argc > 2 ? atoi(argv[2]) : 64000;
    const int rounds = argc > 3 ? atoi(argv[3]) : 8;
    const int D = 3, W = size, H = size;
    std::mt19937_64 rng(1234);
    std::uniform_real_distribution<double> U(0, 1);
    std::normal_distribution<double> N01(0, 1);
    const double f = 0.8 * W;
    std::vector<float> means(3 * n), quats(4 * n), scales(3 * n), opac(n), colors(D * n), bg(D, 0.f);
    for (int i = 0; i < n; ++i) {
        const double z = 2 + 4 * U(rng);
        const double px = -8 + (W + 16) * U(rng), py = -8 + (H + 16) * U(rng);
        means[3 * i] = float((px - W / 2.0) * z / f);
        means[3 * i + 1] = float((py - H / 2.0) * z / f);
        means[3 * i + 2] = float(z);
        for (int k = 0; k < 3; ++k)
            scales[3 * i + k] = float(std::exp(std::log(0.5) + (std::log(4.0) - std::log(0.5)) * U(rng)) * z / f);
        for (int k = 0; k < 4; ++k) quats[4 * i + k] = float(N01(rng));
        opac[i] = float(0.05 + 0.9 * U(rng));
        for (int k = 0; k < D; ++k) colors[D * i + k] = float(U(rng));
    }
    eigs::Camera<float> cam{};
    cam.R[0] = cam.R[4] = cam.R[8] = 1.f;
    cam.fx = cam.fy = float(f);
    cam.cx = float(W) / 2.f;
    cam.cy = float(H) / 2.f;
    cam.width = W;
    cam.height = H;
    std::vector<float> m2(2 * n), con(3 * n), dep(n), ext(2 * n);
    std::vector<int32_t> radii(2 * n);
    eigs::project_forward<float>(n, means.data(), quats.data(), scales.data(), opac.data(), colors.data(), D, cam,
                                 m2.data(), con.data(), dep.data(), ext.data(), radii.data(), 1);
    const int64_t n_tiles = int64_t((W + 15) / 16) * ((H + 15) / 16);
    std::vector<int64_t> offs(n_tiles + 1);
    eigs::IsectPlan plan;
    const eigs::BinInputs<float> bin{n, m2.data(), ext.data(), con.data(), opac.data(), W, H};
    const int64_t ni = eigs::isect_plan<float>(bin, dep.data(), radii.data(), offs.data(), plan, 1);
    std::vector<int64_t> ids(ni);
    eigs::isect_fill(plan, ids.data());
    std::vector<float> image(H * W * D), alpha(H * W), trans(H * W), vimg(H * W * D), valpha(H * W);
    std::vector<int32_t> last(H * W);
    std::vector<int64_t> work(n_tiles);
    for (auto& v : vimg) v = float(N01(rng));
    for (auto& v : valpha) v = float(N01(rng));
    std::vector<float> pg(ni * (6 + D)), o0(2 * n), o1(3 * n), o2(n), o3(D * n), o4(D);
    double best_f = 1e30, best[2] = {1e30, 1e30};
    std::vector<double> ratios;
    for (int r = 0; r <= rounds; ++r) {
        const double c0 = cpu_now();
        eigs::rasterize_forward<float>(m2.data(), con.data(), colors.data(), opac.data(), ext.data(), bg.data(), D,
                                       W, H, offs.data(), ids.data(), image.data(), alpha.data(), trans.data(),
                                       last.data(), work.data(), 1, 0);
        if (r > 0) best_f = std::min(best_f, cpu_now() - c0);
        double t[2];
        for (int kk = 0; kk < 2; ++kk) {
            const int k = (r & 1) ? 1 - kk : kk;  // alternate which build goes first
            const double a0 = cpu_now();
            auto fn = k == 0 ? &eigs_old::rasterize_backward<float> : &eigs::rasterize_backward<float>;
            fn(n, m2.data(), con.data(), colors.data(), opac.data(), ext.data(), bg.data(), D, W, H, offs.data(),
               ids.data(), trans.data(), last.data(), work.data(), vimg.data(), valpha.data(), pg.data(), o0.data(),
               o1.data(), o2.data(), o3.data(), o4.data(), 1, 0);
            t[k] = cpu_now() - a0;
            if (r > 0) best[k] = std::min(best[k], t[k]);
        }
        if (r > 0) ratios.push_back(t[1] / t[0]);
    }
    std::sort(ratios.begin(), ratios.end());
    const double lanes = double(ni) * 256 / 1e9;
    printf("%lld %.4f %.4f %.4f %.4f\n", (long long)ni, best_f / lanes, best[0] / lanes, best[1] / lanes,
           ratios[ratios.size() / 2]);
    return 0;
}
