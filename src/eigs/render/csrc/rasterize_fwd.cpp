// Forward compositing: per 16x16 tile, Gaussian-major, one tile row (16 pixels) per vector.
// Semantics (docs/rasterizer.md): for each pixel, Gaussians in ascending depth; alpha = min(0.99, o G);
// skip alpha < 1/255; stop before a Gaussian with T (1 - alpha) < 1e-4; C += c alpha T; T *= 1 - alpha.
#include <algorithm>
#include <cstdint>
#include <vector>

#include "kernels.h"
#include "raster_common.h"

namespace eigs {
namespace {

template <typename S>
struct FwdCtx {
    const S *means2d, *conics, *colors, *opacities, *extents, *background;
    int64_t d, width, height;
    const int64_t *tile_offsets, *flatten_ids;
    S *image, *alpha, *trans;
    int32_t* last;
    int64_t* tile_work;
};

// Per-thread scratch: T, done flag, colour accumulators (d x 256), weights of one row, last index.
template <typename S>
struct FwdScratch {
    std::vector<S> T, done, C, w;
    std::vector<int32_t> last;
    explicit FwdScratch(int64_t d)
        : T(kTilePix), done(kTilePix), C(size_t(d) * kTilePix), w(kTile), last(kTilePix) {}
};

template <typename S, int DC>
EIGS_INLINE void fwd_tile(const FwdCtx<S>& A, int64_t tile, FwdScratch<S>& ws) {
    const int64_t D = DC > 0 ? DC : A.d;
    const TileGeom tg = tile_geom(tile, A.width, A.height);
    const int64_t start = A.tile_offsets[tile], count = A.tile_offsets[tile + 1] - start;
    S* __restrict__ T = ws.T.data();
    S* __restrict__ done = ws.done.data();
    S* __restrict__ C = ws.C.data();
    S* __restrict__ w = ws.w.data();
    int32_t* __restrict__ last = ws.last.data();
    bool row_alive[kTile];
    for (int r = 0; r < kTile; ++r) {
        row_alive[r] = r < tg.rows;
        for (int l = 0; l < kTile; ++l) {
            T[r * kTile + l] = S(1);
            done[r * kTile + l] = (r < tg.rows && l < tg.cols) ? S(0) : S(1);
            last[r * kTile + l] = -1;
        }
    }
    std::fill(C, C + D * kTilePix, S(0));
    S px[kTile];
    for (int l = 0; l < kTile; ++l) px[l] = S(tg.x0 + l) + S(0.5);
    int64_t work = 0;

    for (int64_t k = 0; k < count; ++k) {
        if ((k & 15) == 15) {  // refresh the per-row "all lanes done" flags
            bool any = false;
            for (int r = 0; r < tg.rows; ++r) {
                if (!row_alive[r]) continue;
                S mn = S(1);
                for (int l = 0; l < kTile; ++l) mn = done[r * kTile + l] < mn ? done[r * kTile + l] : mn;
                row_alive[r] = mn < S(1);
                any |= row_alive[r];
            }
            if (!any) break;
        }
        if (k + kPrefetch < count) {  // the tile list is in depth order: its Gaussians are scattered in memory
            const int64_t h = A.flatten_ids[start + k + kPrefetch];
            __builtin_prefetch(A.means2d + 2 * h);
            __builtin_prefetch(A.conics + 3 * h);
            __builtin_prefetch(A.opacities + h);
            __builtin_prefetch(A.extents + 2 * h);
            __builtin_prefetch(A.colors + h * D);
        }
        const int64_t g = A.flatten_ids[start + k];
        const S mx = A.means2d[2 * g], my = A.means2d[2 * g + 1];
        const S ca = A.conics[3 * g], cb = A.conics[3 * g + 1], cc = A.conics[3 * g + 2];
        const S op = A.opacities[g];
        const S* __restrict__ col = A.colors + g * D;
        int r0, r1;
        box_rows(double(my), double(A.extents[2 * g + 1]), tg.y0, tg.rows, r0, r1);
        const int32_t kk = int32_t(k);
        ++work;
        for (int r = r0; r <= r1; ++r) {
            if (!row_alive[r]) continue;
            work += kRowWork;
            const S dy = (S(tg.y0 + r) + S(0.5)) - my;
            S* __restrict__ Tr = T + r * kTile;
            S* __restrict__ Dr = done + r * kTile;
            int32_t* __restrict__ Lr = last + r * kTile;
#pragma omp simd
            for (int l = 0; l < kTile; ++l) {
                const S dx = px[l] - mx;
                const S sigma = pair_sigma(ca, cb, cc, dx, dy);
                const S raw = pair_raw_alpha(op, pair_falloff(sigma));
                const S alpha = pair_alpha(raw);
                const bool valid = pair_valid(sigma, raw) & (Dr[l] == S(0));
                const bool term = valid & pair_terminates(Tr[l], alpha);
                const bool contrib = valid & !term;
                w[l] = contrib ? alpha * Tr[l] : S(0);
                Dr[l] = term ? S(1) : Dr[l];
                Tr[l] = contrib ? Tr[l] * (S(1) - alpha) : Tr[l];
                Lr[l] = contrib ? kk : Lr[l];
            }
            for (int64_t ch = 0; ch < D; ++ch) {
                S* __restrict__ Cr = C + ch * kTilePix + r * kTile;
                const S cv = col[ch];
#pragma omp simd
                for (int l = 0; l < kTile; ++l) Cr[l] += w[l] * cv;
            }
        }
    }

    A.tile_work[tile] = work;
    for (int r = 0; r < tg.rows; ++r) {
        for (int l = 0; l < tg.cols; ++l) {
            const int64_t pix = (tg.y0 + r) * A.width + (tg.x0 + l);
            const int q = r * kTile + l;
            for (int64_t ch = 0; ch < D; ++ch)
                A.image[pix * D + ch] = C[ch * kTilePix + q] + T[q] * A.background[ch];
            A.alpha[pix] = S(1) - T[q];
            A.trans[pix] = T[q];
            A.last[pix] = last[q];
        }
    }
}

template <typename S>
using FwdFn = void (*)(const FwdCtx<S>&, int64_t, FwdScratch<S>&);

#define EIGS_FWD_VARIANT(NAME, TARGET, S, DC) \
    TARGET void NAME(const FwdCtx<S>& a, int64_t t, FwdScratch<S>& ws) { fwd_tile<S, DC>(a, t, ws); }

EIGS_FWD_VARIANT(fwd_f32_c1_base, EIGS_TARGET_BASE, float, 1)
EIGS_FWD_VARIANT(fwd_f32_c3_base, EIGS_TARGET_BASE, float, 3)
EIGS_FWD_VARIANT(fwd_f32_cd_base, EIGS_TARGET_BASE, float, 0)
EIGS_FWD_VARIANT(fwd_f32_c1_avx2, EIGS_TARGET_AVX2, float, 1)
EIGS_FWD_VARIANT(fwd_f32_c3_avx2, EIGS_TARGET_AVX2, float, 3)
EIGS_FWD_VARIANT(fwd_f32_cd_avx2, EIGS_TARGET_AVX2, float, 0)
EIGS_FWD_VARIANT(fwd_f32_c1_avx512, EIGS_TARGET_AVX512, float, 1)
EIGS_FWD_VARIANT(fwd_f32_c3_avx512, EIGS_TARGET_AVX512, float, 3)
EIGS_FWD_VARIANT(fwd_f32_cd_avx512, EIGS_TARGET_AVX512, float, 0)
EIGS_FWD_VARIANT(fwd_f64_cd_base, EIGS_TARGET_BASE, double, 0)

FwdFn<float> pick_fwd(const float*, int64_t d, int isa) {
    const int c = d == 1 ? 0 : d == 3 ? 1 : 2;
    static const FwdFn<float> table[3][3] = {
        {fwd_f32_c1_base, fwd_f32_c3_base, fwd_f32_cd_base},
        {fwd_f32_c1_avx2, fwd_f32_c3_avx2, fwd_f32_cd_avx2},
        {fwd_f32_c1_avx512, fwd_f32_c3_avx512, fwd_f32_cd_avx512},
    };
    return table[isa - kIsaBase][c];
}

FwdFn<double> pick_fwd(const double*, int64_t, int) { return fwd_f64_cd_base; }

}  // namespace

int cpu_isa_flags() {
    __builtin_cpu_init();
    int f = 0;
    if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) f |= 1;
    if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") &&
        __builtin_cpu_supports("avx512bw") && __builtin_cpu_supports("avx512dq"))
        f |= 2;
    return f;
}

int resolve_isa(int requested) {
    const int f = cpu_isa_flags();
    const int best = (f & 2) ? kIsaAvx512 : (f & 1) ? kIsaAvx2 : kIsaBase;
    if (requested == kIsaAuto || requested > best) return best;
    return requested < kIsaBase ? kIsaBase : requested;
}

template <typename S>
void rasterize_forward(const S* means2d, const S* conics, const S* colors, const S* opacities,
                       const S* extents, const S* background, int64_t d, int64_t width, int64_t height,
                       const int64_t* tile_offsets, const int64_t* flatten_ids, S* image, S* alpha, S* trans,
                       int32_t* last, int64_t* tile_work, int nthreads, int isa) {
    const FwdCtx<S> A{means2d, conics,      colors, opacities, extents, background, d,   width, height,
                      tile_offsets, flatten_ids, image, alpha,     trans,   last,   tile_work};
    const FwdFn<S> fn = pick_fwd(means2d, d, resolve_isa(isa));
    const int64_t n_tiles = ((width + kTile - 1) / kTile) * ((height + kTile - 1) / kTile);
    // Longest lists first (the forward's cost is not known before it runs).
    const std::vector<int64_t> order =
        tile_schedule(n_tiles, nthreads, [tile_offsets](int64_t t) { return tile_offsets[t + 1] - tile_offsets[t]; });
#pragma omp parallel num_threads(nthreads)
    {
        FwdScratch<S> ws(d);
#pragma omp for schedule(dynamic, 1)
        for (int64_t t = 0; t < n_tiles; ++t) fn(A, order[size_t(t)], ws);
    }
}

template void rasterize_forward<float>(const float*, const float*, const float*, const float*, const float*,
                                       const float*, int64_t, int64_t, int64_t, const int64_t*, const int64_t*,
                                       float*, float*, float*, int32_t*, int64_t*, int, int);
template void rasterize_forward<double>(const double*, const double*, const double*, const double*,
                                        const double*, const double*, int64_t, int64_t, int64_t,
                                        const int64_t*, const int64_t*, double*, double*, double*, int32_t*,
                                        int64_t*, int, int);

}  // namespace eigs
