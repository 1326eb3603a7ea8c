// Backward compositing: per tile, the tile's Gaussian list back to front, one lane group of a tile row per vector
// (bwd_tile).  Rebuilds the transmittance in front of each Gaussian with T <- T / max(1e-6, 1 - alpha), starting
// from the forward's final T, and one scalar per pixel for everything behind it (colour, background, alpha
// output).  Per-lane accumulators are reduced once per (tile, Gaussian) into that pair's slot.  The slots are
// grouped by Gaussian (each Gaussian's tiles in row-major order, which is its isect order), so the final
// per-Gaussian sums run in parallel over Gaussians, each over a contiguous range in a fixed order: the result does
// not depend on the thread count or schedule (no atomics), nor on the ISA variant.
#include <algorithm>
#include <atomic>
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
    const int32_t* rect;   // (N, 4) tile rectangle of each Gaussian (as binned)
    const int64_t* slot0;  // (N + 1) first pair slot of each Gaussian
    std::atomic<bool>* mismatch;  // set when a Gaussian is binned to a tile outside its rectangle
    S *pair_grads, *tile_bg;  // tile_bg (n_tiles, D): per tile, sum over its pixels of T_final v_image
    int64_t n_isects;         // pair slots in pair_grads
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

template <typename V, typename S>
EIGS_INLINE V load_v(const S* p) {
    V v;
    __builtin_memcpy(&v, p, sizeof(V));
    return v;
}

template <typename V, typename S>
EIGS_INLINE void store_v(S* p, V v) {
    __builtin_memcpy(p, &v, sizeof(V));
}

// Sum of the 16 lanes of a tile row held as NG groups of LW = 16 / NG lanes (group g = lanes g LW .. g LW + LW - 1),
// of which only groups g0..g1 were computed (the others count as zero), in one fixed pairwise order over the 16
// lanes: lane l + 8 onto lane l, then l + 4, l + 2, l + 1.  The first log2(NG) steps add whole groups, the rest
// work inside the group, so every group width gives the same sum, bit for bit.
template <typename S, typename V, int NG>
EIGS_INLINE S sum_lanes(const V* per_group, int g0, int g1) {
    constexpr int LW = int(sizeof(V) / sizeof(S));
    V v[NG];
    for (int g = 0; g < NG; ++g) v[g] = (g >= g0 && g <= g1) ? per_group[g] : V{};
    for (int h = NG / 2; h >= 1; h /= 2)
        for (int g = 0; g < h; ++g) v[g] = v[g] + v[g + h];
    S t[LW];
    __builtin_memcpy(t, &v[0], sizeof(V));
    for (int w = LW / 2; w >= 1; w /= 2)
        for (int l = 0; l < w; ++l) t[l] = t[l] + t[l + w];
    return t[0];
}

// One tile, its Gaussians back to front.  Lane groups of LW pixels of a row are one vector (LW = the ISA's
// width: 4 floats for SSE2, 8 for AVX2, 16 for AVX-512, 2 doubles); per Gaussian the kernel visits only the
// groups and rows inside its conservative box (whose pixels outside have alpha < 1/255, the binning's guarantee,
// as for the forward's rows) and skips a (row, group) once every pixel in it has its last contributor in front.
//
// Per pixel it carries T (see the scratch) and the scalar sv_k = sum_ch B_k,ch v_C,ch - v_A U_k, where B_k is the
// colour behind Gaussian k including the background and U_k = prod_{j > k} (1 - alpha_j) the transmittance behind
// it (so that d alpha_out / d alpha_k = T_k U_k): sv starts at <bg, v_C> - v_A and is updated as
// sv <- alpha cg + (1 - alpha) sv with cg = sum_ch c_ch v_C,ch, and then
//   dL/dalpha_k = T_k (cg - sv_k)   (colour through C and the background, and the alpha output),
// one scalar per pixel instead of d colour channels.  The per-pair gradients through sigma are accumulated as
// moments of v_sigma (sigma_moments_vjp): per lane the sums over rows of v_sigma, dy v_sigma and dy^2 v_sigma,
// multiplied by the lane's dx (constant along a column) once per Gaussian.
template <typename S, int DC, int LW>
EIGS_INLINE void bwd_tile(const BwdCtx<S>& A, int64_t tile, BwdScratch<S>& ws) {
    using V = typename LaneVec<S, LW>::type;
    using M = decltype(V{} < V{});  // lane mask: integers of the width of S
    using I32 = typename LaneVec<int32_t, LW>::type;
    constexpr int NG = kTile / LW;  // lane groups per tile row
    static_assert(NG * LW == kTile, "LW must divide the tile width");
    const int64_t D = DC > 0 ? DC : A.d;
    const int64_t P = 6 + D;
    const TileGeom tg = tile_geom(tile, A.width, A.height);
    const int64_t start = A.tile_offsets[tile], count = A.tile_offsets[tile + 1] - start;
    S* __restrict__ T = ws.T.data();
    S* __restrict__ SV = ws.sv.data();
    S* __restrict__ G = ws.G.data();
    S* __restrict__ vcol = ws.vcol.data();
    S* __restrict__ vcol16 = ws.vcol16.data();
    int32_t* __restrict__ last = ws.last.data();
    int32_t* __restrict__ gmax = ws.gmax.data();

    int32_t row_max_last[kTile];
    int32_t tile_max_last = -1;
    S* __restrict__ bg_sum = A.tile_bg + tile * D;
    std::fill(bg_sum, bg_sum + D, S(0));
    for (int r = 0; r < kTile; ++r) {
        row_max_last[r] = -1;
        for (int l = 0; l < kTile; ++l) {
            const int q = r * kTile + l;
            if (r < tg.rows && l < tg.cols) {
                const int64_t pix = (tg.y0 + r) * A.width + (tg.x0 + l);
                const S tf = A.trans[pix];
                S bgdot = S(0);
                for (int64_t ch = 0; ch < D; ++ch) {
                    const S gv = A.v_image[pix * D + ch];
                    G[ch * kTilePix + q] = gv;
                    bgdot += A.background[ch] * gv;
                    bg_sum[ch] += tf * gv;
                }
                T[q] = tf;
                SV[q] = bgdot - A.v_alpha[pix];
                last[q] = A.last[pix];
            } else {
                for (int64_t ch = 0; ch < D; ++ch) G[ch * kTilePix + q] = S(0);
                T[q] = S(1);
                SV[q] = S(0);
                last[q] = -1;
            }
        }
        for (int grp = 0; grp < NG; ++grp) {
            int32_t m = -1;
            for (int l = grp * LW; l < (grp + 1) * LW; ++l) m = std::max(m, last[r * kTile + l]);
            gmax[r * NG + grp] = m;
            row_max_last[r] = std::max(row_max_last[r], m);
        }
        tile_max_last = std::max(tile_max_last, row_max_last[r]);
    }
    V pxv[NG];
    for (int grp = 0; grp < NG; ++grp)
        for (int l = 0; l < LW; ++l) pxv[grp][l] = S(tg.x0 + grp * LW + l) + S(0.5);
    const int32_t tx = int32_t(tg.x0 / kTile), ty = int32_t(tg.y0 / kTile);

    for (int64_t k = count - 1; k >= 0; --k) {
        // prefetch (raster_common.h): the parameters kPrefetch Gaussians ahead, the next Gaussian's pair slot (which
        // needs its rectangle) for writing
        if (k >= kPrefetch) {
            const int64_t h = A.flatten_ids[start + k - kPrefetch];
            __builtin_prefetch(A.means2d + 2 * h);
            __builtin_prefetch(A.conics + 3 * h);
            __builtin_prefetch(A.opacities + h);
            __builtin_prefetch(A.extents + 2 * h);
            __builtin_prefetch(A.colors + h * D);
            __builtin_prefetch(A.rect + 4 * h);
            __builtin_prefetch(A.slot0 + h);
        }
        if (k >= 1) {
            const int64_t h = A.flatten_ids[start + k - 1];
            const int32_t* rh = A.rect + 4 * h;
            const int64_t sl = A.slot0[h] + int64_t(ty - rh[2]) * (rh[1] - rh[0] + 1) + (tx - rh[0]);
            if (sl >= 0 && sl < A.n_isects) __builtin_prefetch(A.pair_grads + sl * P, 1);
        }
        const int64_t g = A.flatten_ids[start + k];
        const int32_t* rc = A.rect + 4 * g;
        if (tx < rc[0] || tx > rc[1] || ty < rc[2] || ty > rc[3]) {  // binning inconsistent with the rects
            A.mismatch->store(true, std::memory_order_relaxed);
            continue;
        }
        const int64_t slot = A.slot0[g] + int64_t(ty - rc[2]) * (rc[1] - rc[0] + 1) + (tx - rc[0]);
        S* __restrict__ out = A.pair_grads + slot * P;
        std::fill(out, out + P, S(0));
        if (k > tile_max_last) continue;
        const S mx = A.means2d[2 * g], my = A.means2d[2 * g + 1];
        const S ca = A.conics[3 * g], cb = A.conics[3 * g + 1], cc = A.conics[3 * g + 2];
        const S op = A.opacities[g];
        const S* __restrict__ col = A.colors + g * D;
        int r0, r1, c0, c1;
        box_rows(double(my), double(A.extents[2 * g + 1]), tg.y0, tg.rows, r0, r1);
        box_rows(double(mx), double(A.extents[2 * g]), tg.x0, tg.cols, c0, c1);  // the same range, on columns
        if (r0 > r1 || c0 > c1) continue;
        const int32_t kk = int32_t(k);
        const M kkv = M{} + kk;
        const V opv = V{} + op;
        V colv[DC > 0 ? DC : 1];
        if constexpr (DC > 0)
            for (int ch = 0; ch < DC; ++ch) colv[ch] = V{} + col[ch];
        // Per lane group, per lane: the sums over the Gaussian's rows of dx^2 v_sigma, dx v_sigma, dx dy v_sigma,
        // dy v_sigma, dy^2 v_sigma, v_opacity and (DC > 0) v_color, kept per group so that the lanes are summed
        // in one fixed order over the 16 lanes of the tile row (lane_sum), whatever the ISA's group width: the
        // gradients are bit-identical across the baseline, AVX2 and AVX-512 variants.
        const int gl0 = c0 / LW, gl1 = c1 / LW;
        V gq[6 + (DC > 0 ? DC : 0)][NG];
        for (int grp = gl0; grp <= gl1; ++grp) {
            const V dx = pxv[grp] - mx;
            const V cadxdx = ca * dx * dx;
            const V cbdx = cb * dx;
            V s0{}, s1{}, s2{}, so{};  // sums over rows of v_sigma, dy v_sigma, dy^2 v_sigma, v_opacity
            V sc[DC > 0 ? DC : 1];     // and of v_color
            if constexpr (DC > 0)
                for (int ch = 0; ch < DC; ++ch) sc[ch] = V{};
            else
                std::fill(vcol, vcol + D * LW, S(0));
            for (int r = r0; r <= r1; ++r) {
                if (kk > gmax[r * NG + grp]) continue;
                const S dy = (S(tg.y0 + r) + S(0.5)) - my;
                const int q = r * kTile + grp * LW;
                const V sigma = pair_sigma_parts(cadxdx, cc * dy * dy, cbdx, dy);
                const V f = pair_falloff(sigma);
                const V raw = pair_raw_alpha(opv, f);
                const V a = pair_alpha(raw);
                const M lastv = __builtin_convertvector(load_v<I32>(last + q), M);
                const M valid = pair_valid(sigma, raw) & (kkv <= lastv);
                const V Tv = load_v<V>(T + q);
                const V Tk = valid ? Tv * pair_inv_one_minus(a) : Tv;  // transmittance in front of k
                const V sv = load_v<V>(SV + q);
                V cg;
                if constexpr (DC > 0) {
                    cg = colv[0] * load_v<V>(G + q);
                    for (int ch = 1; ch < DC; ++ch) cg = cg + colv[ch] * load_v<V>(G + ch * kTilePix + q);
                } else {
                    cg = col[0] * load_v<V>(G + q);
                    for (int64_t ch = 1; ch < D; ++ch) cg = cg + col[ch] * load_v<V>(G + ch * kTilePix + q);
                }
                const V v_alpha = Tk * (cg - sv);
                store_v(SV + q, valid ? a * cg + (cst<V>(1) - a) * sv : sv);
                store_v(T + q, Tk);
                // v_color += w v_C with w = alpha T the pair's weight in C; selected after the product (as every
                // masked term here), so that a non-finite v_C reaches only the Gaussians composited at its pixel
                const V w = a * Tk;
                if constexpr (DC > 0) {
                    for (int ch = 0; ch < DC; ++ch) sc[ch] += valid ? w * load_v<V>(G + ch * kTilePix + q) : V{};
                } else {
                    for (int64_t ch = 0; ch < D; ++ch)
                        store_v(vcol + ch * LW, load_v<V>(vcol + ch * LW) +
                                                    (valid ? w * load_v<V>(G + ch * kTilePix + q) : V{}));
                }
                V v_sigma, v_o;
                pair_alpha_vjp(raw, f, v_alpha, valid & pair_unclamped(raw), v_sigma, v_o);
                s0 += v_sigma;
                s1 += dy * v_sigma;
                s2 += (dy * dy) * v_sigma;
                so += v_o;
            }
            gq[0][grp] = (dx * dx) * s0;
            gq[1][grp] = dx * s0;
            gq[2][grp] = dx * s1;
            gq[3][grp] = s1;
            gq[4][grp] = s2;
            gq[5][grp] = so;
            if constexpr (DC > 0) {
                for (int ch = 0; ch < DC; ++ch) gq[6 + ch][grp] = sc[ch];
            } else {
                for (int64_t ch = 0; ch < D; ++ch)
                    for (int l = 0; l < LW; ++l) vcol16[ch * kTile + grp * LW + l] = vcol[ch * LW + l];
            }
        }
        auto lane_sum = [&](const V* per_group) { return sum_lanes<S, V, NG>(per_group, gl0, gl1); };
        sigma_moments_vjp(ca, cb, cc, lane_sum(gq[0]), lane_sum(gq[2]), lane_sum(gq[4]), lane_sum(gq[1]),
                          lane_sum(gq[3]), out);
        out[5] = lane_sum(gq[5]);
        if constexpr (DC > 0) {
            for (int ch = 0; ch < DC; ++ch) out[6 + ch] = lane_sum(gq[6 + ch]);
        } else {
            for (int64_t ch = 0; ch < D; ++ch) {
                V pg[NG];
                for (int grp = gl0; grp <= gl1; ++grp) pg[grp] = load_v<V>(vcol16 + ch * kTile + grp * LW);
                out[6 + ch] = lane_sum(pg);
            }
        }
    }
}

template <typename S>
using BwdFn = void (*)(const BwdCtx<S>&, int64_t, BwdScratch<S>&);

#define EIGS_BWD_VARIANT(NAME, TARGET, S, DC, LW) \
    TARGET void NAME(const BwdCtx<S>& a, int64_t t, BwdScratch<S>& ws) { bwd_tile<S, DC, LW>(a, t, ws); }

EIGS_BWD_VARIANT(bwd_f32_c1_base, EIGS_TARGET_BASE, float, 1, 4)
EIGS_BWD_VARIANT(bwd_f32_c3_base, EIGS_TARGET_BASE, float, 3, 4)
EIGS_BWD_VARIANT(bwd_f32_cd_base, EIGS_TARGET_BASE, float, 0, 4)
EIGS_BWD_VARIANT(bwd_f32_c1_avx2, EIGS_TARGET_AVX2, float, 1, 8)
EIGS_BWD_VARIANT(bwd_f32_c3_avx2, EIGS_TARGET_AVX2, float, 3, 8)
EIGS_BWD_VARIANT(bwd_f32_cd_avx2, EIGS_TARGET_AVX2, float, 0, 8)
EIGS_BWD_VARIANT(bwd_f32_c1_avx512, EIGS_TARGET_AVX512, float, 1, 16)
EIGS_BWD_VARIANT(bwd_f32_c3_avx512, EIGS_TARGET_AVX512, float, 3, 16)
EIGS_BWD_VARIANT(bwd_f32_cd_avx512, EIGS_TARGET_AVX512, float, 0, 16)
EIGS_BWD_VARIANT(bwd_f64_cd_base, EIGS_TARGET_BASE, double, 0, 2)

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
    // Pair slots grouped by Gaussian: slot0[g] = sum of the tile counts of the Gaussians before g.
    const size_t n1 = size_t(std::max<int64_t>(n, 1));
    std::unique_ptr<int32_t[]> rect(new int32_t[4 * n1]);
    std::unique_ptr<int64_t[]> slot0(new int64_t[n1 + 1]);
    std::vector<int64_t> chunk(size_t(nthreads) + 1, 0);
#pragma omp parallel num_threads(nthreads)
    {
        const int nt = omp_get_num_threads(), tid = omp_get_thread_num();
        const int64_t lo = n * tid / nt, hi = n * (tid + 1) / nt;
        int64_t run = 0;
        for (int64_t g = lo; g < hi; ++g) {
            int32_t* r = rect.get() + 4 * g;
            slot0[g] = run;
            if (tile_rect(means2d + 2 * g, extents + 2 * g, width, height, r))
                run += int64_t(r[1] - r[0] + 1) * int64_t(r[3] - r[2] + 1);
        }
        chunk[size_t(tid) + 1] = run;
#pragma omp barrier
        int64_t base = 0;
        for (int c = 0; c < tid; ++c) base += chunk[size_t(c) + 1];
        for (int64_t g = lo; g < hi; ++g) slot0[g] += base;
        if (tid == nt - 1) slot0[n] = base + run;
    }
    if (slot0[n] != n_isects)
        throw std::runtime_error("rasterize_backward: the tile binning does not match means2d/extents (" +
                                 std::to_string(slot0[n]) + " vs " + std::to_string(n_isects) + " pairs)");
    std::vector<S> tile_bg(size_t(n_tiles * d));
    std::atomic<bool> mismatch{false};
    const BwdCtx<S> A{means2d,      conics,      colors, opacities, extents, background, d,
                      width,        height,      tile_offsets, flatten_ids, trans, last, v_image,
                      v_alpha,      rect.get(),  slot0.get(), &mismatch, pair_grads, tile_bg.data(),
                      n_isects};
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
    if (mismatch.load())
        throw std::runtime_error("rasterize_backward: the tile binning does not match means2d/extents (a "
                                 "Gaussian binned to a tile outside its box)");
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
