// Backward compositing: per tile, the tile's Gaussian list back to front, one tile row per vector.
// Rebuilds the transmittance in front of each Gaussian with T <- T / max(1e-6, 1 - alpha), starting from the
// forward's final T, and the colour composited behind it with S <- alpha c + (1 - alpha) S.  Per-lane
// accumulators are reduced once per (tile, Gaussian) into that pair's slot.  The slots are grouped by Gaussian
// (each Gaussian's tiles in row-major order, which is its isect order), so the final per-Gaussian sums run in
// parallel over Gaussians, each over a contiguous range in a fixed order: the result does not depend on the
// thread count or schedule (no atomics).
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
};

template <typename S>
struct BwdScratch {
    // T (transmittance behind the current Gaussian), Q = T_final (<bg, v_C> - v_alpha), colour behind (d x 256),
    // v_C (d x 256), per-row temporaries, per-lane accumulators ((6 + d) x 16), last index.
    std::vector<S> T, Q, Sb, G, alpha, fall, Tk, inv_om, valid, dot, acc;
    std::vector<int32_t> last;
    explicit BwdScratch(int64_t d)
        : T(kTilePix), Q(kTilePix), Sb(size_t(d) * kTilePix), G(size_t(d) * kTilePix), alpha(kTile),
          fall(kTile), Tk(kTile), inv_om(kTile), valid(kTile), dot(kTile), acc(size_t(6 + d) * kTile),
          last(kTilePix) {}
};

template <typename S, int DC>
EIGS_INLINE void bwd_tile(const BwdCtx<S>& A, int64_t tile, BwdScratch<S>& ws) {
    const int64_t D = DC > 0 ? DC : A.d;
    const int64_t P = 6 + D;
    const TileGeom tg = tile_geom(tile, A.width, A.height);
    const int64_t start = A.tile_offsets[tile], count = A.tile_offsets[tile + 1] - start;
    S* __restrict__ T = ws.T.data();
    S* __restrict__ Q = ws.Q.data();
    S* __restrict__ Sb = ws.Sb.data();
    S* __restrict__ G = ws.G.data();
    S* __restrict__ alpha = ws.alpha.data();
    S* __restrict__ fall = ws.fall.data();
    S* __restrict__ Tk = ws.Tk.data();
    S* __restrict__ inv_om = ws.inv_om.data();
    S* __restrict__ valid = ws.valid.data();
    S* __restrict__ dot = ws.dot.data();
    S* __restrict__ acc = ws.acc.data();
    int32_t* __restrict__ last = ws.last.data();

    int32_t row_max_last[kTile];
    int32_t tile_max_last = -1;
    std::fill(Sb, Sb + D * kTilePix, S(0));
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
                Q[q] = tf * (bgdot - A.v_alpha[pix]);
                last[q] = A.last[pix];
            } else {
                for (int64_t ch = 0; ch < D; ++ch) G[ch * kTilePix + q] = S(0);
                T[q] = S(1);
                Q[q] = S(0);
                last[q] = -1;
            }
            row_max_last[r] = std::max(row_max_last[r], last[q]);
        }
        tile_max_last = std::max(tile_max_last, row_max_last[r]);
    }
    S px[kTile];
    for (int l = 0; l < kTile; ++l) px[l] = S(tg.x0 + l) + S(0.5);
    const int32_t tx = int32_t(tg.x0 / kTile), ty = int32_t(tg.y0 / kTile);

    for (int64_t k = count - 1; k >= 0; --k) {
        const int64_t g = A.flatten_ids[start + k];
        const int32_t* rc = A.rect + 4 * g;
        if (tx < rc[0] || tx > rc[1] || ty < rc[2] || ty > rc[3]) {  // binning inconsistent with the rects
            A.mismatch->store(true, std::memory_order_relaxed);
            continue;
        }
        const int64_t slot = A.slot0[g] + int64_t(ty - rc[2]) * (rc[1] - rc[0] + 1) + (tx - rc[0]);
        S* __restrict__ out = A.pair_grads + slot * P;
        if (k > tile_max_last) {
            std::fill(out, out + P, S(0));
            continue;
        }
        const S mx = A.means2d[2 * g], my = A.means2d[2 * g + 1];
        const S ca = A.conics[3 * g], cb = A.conics[3 * g + 1], cc = A.conics[3 * g + 2];
        const S op = A.opacities[g];
        const S* __restrict__ col = A.colors + g * D;
        int r0, r1;
        box_rows(double(my), double(A.extents[2 * g + 1]), tg.y0, tg.rows, r0, r1);
        const int32_t kk = int32_t(k);
        std::fill(acc, acc + P * kTile, S(0));
        for (int r = r0; r <= r1; ++r) {
            if (kk > row_max_last[r]) continue;
            const S dy = (S(tg.y0 + r) + S(0.5)) - my;
            S* __restrict__ Tr = T + r * kTile;
            const S* __restrict__ Qr = Q + r * kTile;
            const int32_t* __restrict__ Lr = last + r * kTile;
            // pass 1: alpha, validity, transmittance in front of the Gaussian
#pragma omp simd
            for (int l = 0; l < kTile; ++l) {
                const S dx = px[l] - mx;
                const S sigma = pair_sigma(ca, cb, cc, dx, dy);
                const S f = pair_falloff(sigma);
                const S raw = pair_raw_alpha(op, f);
                const S a = pair_alpha(raw);
                const bool v = pair_valid(sigma, raw) & (kk <= Lr[l]);
                const S io = pair_inv_one_minus(a);
                fall[l] = f;
                alpha[l] = a;
                valid[l] = v ? S(1) : S(0);
                inv_om[l] = io;
                Tk[l] = v ? Tr[l] * io : Tr[l];
                dot[l] = S(0);
            }
            // pass 2 (per channel): v_color, sum_ch (c - S) v_C, and the colour behind
            for (int64_t ch = 0; ch < D; ++ch) {
                const S cv = col[ch];
                S* __restrict__ Sr = Sb + ch * kTilePix + r * kTile;
                const S* __restrict__ Gr = G + ch * kTilePix + r * kTile;
                S* __restrict__ vcol = acc + (6 + ch) * kTile;
#pragma omp simd
                for (int l = 0; l < kTile; ++l) {
                    const bool v = valid[l] != S(0);
                    dot[l] += v ? (cv - Sr[l]) * Gr[l] : S(0);
                    vcol[l] += v ? alpha[l] * Tk[l] * Gr[l] : S(0);
                    Sr[l] = v ? alpha[l] * cv + (S(1) - alpha[l]) * Sr[l] : Sr[l];
                }
            }
            // pass 3: v_alpha -> conic, mean2d, opacity
            S* __restrict__ a_mx = acc;
            S* __restrict__ a_my = acc + kTile;
            S* __restrict__ a_a = acc + 2 * kTile;
            S* __restrict__ a_b = acc + 3 * kTile;
            S* __restrict__ a_c = acc + 4 * kTile;
            S* __restrict__ a_o = acc + 5 * kTile;
#pragma omp simd
            for (int l = 0; l < kTile; ++l) {
                const bool v = valid[l] != S(0);
                const S dx = px[l] - mx;
                const S v_alpha = dot[l] * Tk[l] - Qr[l] * inv_om[l];
                const S raw = pair_raw_alpha(op, fall[l]);
                const bool unclamped = v & pair_unclamped(raw);
                const PairGrad<S> pg = pair_backward(ca, cb, cc, raw, fall[l], dx, dy, v_alpha, unclamped);
                a_mx[l] += pg.v_mx;
                a_my[l] += pg.v_my;
                a_a[l] += pg.v_a;
                a_b[l] += pg.v_b;
                a_c[l] += pg.v_c;
                a_o[l] += pg.v_o;
                Tr[l] = Tk[l];
            }
        }
        for (int64_t j = 0; j < P; ++j) {
            S s = S(0);
            for (int l = 0; l < kTile; ++l) s += acc[j * kTile + l];
            out[j] = s;
        }
    }
}

template <typename S>
using BwdFn = void (*)(const BwdCtx<S>&, int64_t, BwdScratch<S>&);

#define EIGS_BWD_VARIANT(NAME, TARGET, S, DC) \
    TARGET void NAME(const BwdCtx<S>& a, int64_t t, BwdScratch<S>& ws) { bwd_tile<S, DC>(a, t, ws); }

EIGS_BWD_VARIANT(bwd_f32_c1_base, EIGS_TARGET_BASE, float, 1)
EIGS_BWD_VARIANT(bwd_f32_c3_base, EIGS_TARGET_BASE, float, 3)
EIGS_BWD_VARIANT(bwd_f32_cd_base, EIGS_TARGET_BASE, float, 0)
EIGS_BWD_VARIANT(bwd_f32_c1_avx2, EIGS_TARGET_AVX2, float, 1)
EIGS_BWD_VARIANT(bwd_f32_c3_avx2, EIGS_TARGET_AVX2, float, 3)
EIGS_BWD_VARIANT(bwd_f32_cd_avx2, EIGS_TARGET_AVX2, float, 0)
EIGS_BWD_VARIANT(bwd_f32_c1_avx512, EIGS_TARGET_AVX512, float, 1)
EIGS_BWD_VARIANT(bwd_f32_c3_avx512, EIGS_TARGET_AVX512, float, 3)
EIGS_BWD_VARIANT(bwd_f32_cd_avx512, EIGS_TARGET_AVX512, float, 0)
EIGS_BWD_VARIANT(bwd_f64_cd_base, EIGS_TARGET_BASE, double, 0)

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
                      v_alpha,      rect.get(),  slot0.get(), &mismatch, pair_grads, tile_bg.data()};
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
