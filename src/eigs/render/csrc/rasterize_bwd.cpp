// Backward compositing: per tile, the tile's Gaussian list back to front, one lane group of a tile row per vector
// (bwd_tile).  Rebuilds the transmittance in front of each Gaussian with T <- T / max(1e-6, 1 - alpha), starting
// from the forward's final T, and one scalar per pixel for everything behind it (colour, background, alpha
// output).  Per-lane accumulators are reduced once per (tile, Gaussian) into that pair's slot.  The slots are
// grouped by Gaussian (each Gaussian's pairs in isect order, which is row-major tile order), so the final
// per-Gaussian sums run in parallel over Gaussians, each over a contiguous range in a fixed order: the result does
// not depend on the thread count or schedule (no atomics), nor on the ISA variant.  The slots come from the
// binning itself (a counting sort of flatten_ids), so any binning works, the tile culling's included.
#include <algorithm>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include <omp.h>

#include "kernels.h"
#include "raster_common.h"
#include "tile_geom.h"

namespace eigs {
namespace {

template <typename S>
struct BwdCtx {
    const S *means2d, *conics, *colors, *opacities, *extents, *background;
    int64_t d, width, height;
    const int64_t *tile_offsets, *flatten_ids;
    const S* trans;
    const int32_t* last;
    const S *v_image, *v_alpha;
    const int64_t* slot;      // (n_isects) pair i's slot in pair_grads (slots grouped by Gaussian)
    S *pair_grads, *tile_bg;  // tile_bg (n_tiles, D): per tile, sum over its pixels of T_final v_image
};

template <typename S>
struct BwdScratch {
    // Per pixel of the tile: T (the transmittance in front of the Gaussians not yet visited, i.e. behind the
    // current one), sv (below), v_C (d x 256), last index; per row and lane group, the largest last index;
    // when d is not a compile-time constant, the colour gradient accumulators of the current lane group
    // (d x LW) and their per-lane totals over the tile row (d x 16).
    std::vector<S> T, sv, G, vcol, vcol16;
    std::vector<int32_t> last, gmax;
    explicit BwdScratch(int64_t d)
        : T(kTilePix), sv(kTilePix), G(size_t(d) * kTilePix), vcol(size_t(d) * kTile), vcol16(size_t(d) * kTile),
          last(kTilePix), gmax(kTilePix) {}
};

// The tile kernel and the lane math it inlines, once per ISA (rasterize_bwd_tile.inc, pair_lanes.inc).
namespace isa_base {
#define EIGS_LANE_TARGET EIGS_TARGET_BASE
#include "pair_lanes.inc"
#include "rasterize_bwd_tile.inc"
#undef EIGS_LANE_TARGET
}  // namespace isa_base
namespace isa_avx2 {
#define EIGS_LANE_TARGET EIGS_TARGET_AVX2
#include "pair_lanes.inc"
#include "rasterize_bwd_tile.inc"
#undef EIGS_LANE_TARGET
}  // namespace isa_avx2
namespace isa_avx512 {
#define EIGS_LANE_TARGET EIGS_TARGET_AVX512
#include "pair_lanes.inc"
#include "rasterize_bwd_tile.inc"
#undef EIGS_LANE_TARGET
}  // namespace isa_avx512

template <typename S>
using BwdFn = void (*)(const BwdCtx<S>&, int64_t, BwdScratch<S>&);

#define EIGS_BWD_VARIANT(NAME, TARGET, NS, S, DC, LW) \
    TARGET void NAME(const BwdCtx<S>& a, int64_t t, BwdScratch<S>& ws) { NS::bwd_tile<S, DC, LW>(a, t, ws); }

EIGS_BWD_VARIANT(bwd_f32_c1_base, EIGS_TARGET_BASE, isa_base, float, 1, 4)
EIGS_BWD_VARIANT(bwd_f32_c3_base, EIGS_TARGET_BASE, isa_base, float, 3, 4)
EIGS_BWD_VARIANT(bwd_f32_cd_base, EIGS_TARGET_BASE, isa_base, float, 0, 4)
EIGS_BWD_VARIANT(bwd_f32_c1_avx2, EIGS_TARGET_AVX2, isa_avx2, float, 1, 8)
EIGS_BWD_VARIANT(bwd_f32_c3_avx2, EIGS_TARGET_AVX2, isa_avx2, float, 3, 8)
EIGS_BWD_VARIANT(bwd_f32_cd_avx2, EIGS_TARGET_AVX2, isa_avx2, float, 0, 8)
EIGS_BWD_VARIANT(bwd_f32_c1_avx512, EIGS_TARGET_AVX512, isa_avx512, float, 1, 16)
EIGS_BWD_VARIANT(bwd_f32_c3_avx512, EIGS_TARGET_AVX512, isa_avx512, float, 3, 16)
EIGS_BWD_VARIANT(bwd_f32_cd_avx512, EIGS_TARGET_AVX512, isa_avx512, float, 0, 16)
EIGS_BWD_VARIANT(bwd_f64_cd_base, EIGS_TARGET_BASE, isa_base, double, 0, 2)

BwdFn<float> pick_bwd(const float*, int64_t d, int isa) {
    const int c = d == 1 ? 0 : d == 3 ? 1 : 2;
    static const BwdFn<float> table[3][3] = {
        {bwd_f32_c1_base, bwd_f32_c3_base, bwd_f32_cd_base},
        {bwd_f32_c1_avx2, bwd_f32_c3_avx2, bwd_f32_cd_avx2},
        {bwd_f32_c1_avx512, bwd_f32_c3_avx512, bwd_f32_cd_avx512},
    };
    return table[isa - kIsaBase][c];
}

BwdFn<double> pick_bwd(const double*, int64_t, int) { return bwd_f64_cd_base; }

}  // namespace

template <typename S>
void rasterize_backward(int64_t n, const S* means2d, const S* conics, const S* colors, const S* opacities,
                        const S* extents, const S* background, int64_t d, int64_t width, int64_t height,
                        const int64_t* tile_offsets, const int64_t* flatten_ids, const S* trans,
                        const int32_t* last, const int64_t* tile_work, const S* v_image, const S* v_alpha,
                        S* pair_grads, S* v_means2d, S* v_conics, S* v_opacities, S* v_colors, S* v_background,
                        int nthreads, int isa) {
    const int64_t n_tiles = ((width + kTile - 1) / kTile) * ((height + kTile - 1) / kTile);
    const int64_t n_isects = tile_offsets[n_tiles];
    const int64_t P = 6 + d;
    // Pair slots grouped by Gaussian, each Gaussian's pairs in isect order: a counting sort of flatten_ids.
    // slot0[g] = the pairs of the Gaussians before g; slot[i] = slot0[g] + (g's pairs before pair i).
    const size_t n1 = size_t(std::max<int64_t>(n, 1));
    std::unique_ptr<int64_t[]> slot0(new int64_t[n1 + 1]());
    std::unique_ptr<int64_t[]> slot(new int64_t[size_t(std::max<int64_t>(n_isects, 1))]);
    for (int64_t i = 0; i < n_isects; ++i) {
        const int64_t g = flatten_ids[i];
        if (g < 0 || g >= n)
            throw std::runtime_error("rasterize_backward: flatten_ids holds " + std::to_string(g) +
                                     ", not a Gaussian of " + std::to_string(n));
        ++slot0[g + 1];
    }
    for (int64_t g = 0; g < n; ++g) slot0[g + 1] += slot0[g];
    {
        std::vector<int64_t> cur(slot0.get(), slot0.get() + n);
        for (int64_t i = 0; i < n_isects; ++i) slot[i] = cur[size_t(flatten_ids[i])]++;
    }
    std::vector<S> tile_bg(size_t(n_tiles * d));
    const BwdCtx<S> A{means2d, conics,      colors, opacities, extents, background, d,          width,
                      height,  tile_offsets, flatten_ids, trans, last, v_image, v_alpha, slot.get(),
                      pair_grads, tile_bg.data()};
    const BwdFn<S> fn = pick_bwd(means2d, d, resolve_isa(isa));
    // Costliest tiles first, by the work the forward counted there (a far better estimate than list lengths).
    const std::vector<int64_t> order =
        tile_schedule(n_tiles, nthreads, [tile_work](int64_t t) { return tile_work[t]; });
#pragma omp parallel num_threads(nthreads)
    {
        {
            BwdScratch<S> ws(d);
#pragma omp for schedule(dynamic, 1)
            for (int64_t t = 0; t < n_tiles; ++t) fn(A, order[size_t(t)], ws);
        }
        // Per-Gaussian sums over its contiguous slots, in slot order (= its isect order): parallel over
        // Gaussians, the same sums for any thread count.
#pragma omp for schedule(static)
        for (int64_t g = 0; g < n; ++g) {
            S m0 = S(0), m1 = S(0), c0 = S(0), c1 = S(0), c2 = S(0), o = S(0);
            for (int64_t sl = slot0[g]; sl < slot0[g + 1]; ++sl) {
                const S* pg = pair_grads + sl * P;
                m0 += pg[0];
                m1 += pg[1];
                c0 += pg[2];
                c1 += pg[3];
                c2 += pg[4];
                o += pg[5];
            }
            v_means2d[2 * g] = m0;
            v_means2d[2 * g + 1] = m1;
            v_conics[3 * g] = c0;
            v_conics[3 * g + 1] = c1;
            v_conics[3 * g + 2] = c2;
            v_opacities[g] = o;
            for (int64_t ch = 0; ch < d; ++ch) {
                S c = S(0);
                for (int64_t sl = slot0[g]; sl < slot0[g + 1]; ++sl) c += pair_grads[sl * P + 6 + ch];
                v_colors[g * d + ch] = c;
            }
        }
    }
    for (int64_t ch = 0; ch < d; ++ch) v_background[ch] = S(0);
    for (int64_t t = 0; t < n_tiles; ++t)
        for (int64_t ch = 0; ch < d; ++ch) v_background[ch] += tile_bg[size_t(t * d + ch)];
}

template void rasterize_backward<float>(int64_t, const float*, const float*, const float*, const float*,
                                        const float*, const float*, int64_t, int64_t, int64_t, const int64_t*,
                                        const int64_t*, const float*, const int32_t*, const int64_t*, const float*,
                                        const float*, float*, float*, float*, float*, float*, float*, int, int);
template void rasterize_backward<double>(int64_t, const double*, const double*, const double*, const double*,
                                         const double*, const double*, int64_t, int64_t, int64_t,
                                         const int64_t*, const int64_t*, const double*, const int32_t*,
                                         const int64_t*, const double*, const double*, double*, double*, double*,
                                         double*, double*, double*, int, int);

}  // namespace eigs
